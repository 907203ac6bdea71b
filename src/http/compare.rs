//! `/v1/compare`: K-width, B-width, fidelity and area of finished runs on
//! one scene, side by side.

use axum::extract::{RawQuery, State};
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::Json;

use super::experiments::{finished_maps, no_plot};
use super::problem::{Problem, ProblemBody, QueryArgs};
use super::AppState;
use crate::error::SpecError;
use crate::report::{self, Comparison};

/// Most runs one comparison takes.
pub const COMPARE_MAX_RUNS: usize = 50;
/// Most maps one comparison holds, over all its runs (docs/service.md,
/// "Budgets and timeouts"): a page of 40 panels, a JSON of ~20 KB.
pub const COMPARE_MAX_MAPS: usize = 40;
/// Most stored points (trials) those maps may hold together.
pub const COMPARE_MAX_POINTS: usize = 100_000;

#[utoipa::path(get, path = "/v1/compare",
    params(("runs" = String, Query, description = "comma-separated ids of succeeded experiments on one scene"),
           ("format" = Option<String>, Query, description = "json (default), svg (every boundary on one chart) or text (a table)")),
    responses((status = 200, description = "K-width, B-width, max fidelity error and area per map, with differences from the first", body = Comparison),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "a run has not succeeded", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "bad runs or format, or different scenes", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn compare_runs(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
) -> Result<Response, Problem> {
    let q = QueryArgs::parse(query.as_deref(), &["runs", "format"])?;
    let format = q.str("format").unwrap_or("json");
    if !["json", "svg", "text"].contains(&format) {
        return Err(
            SpecError::new("format", format!("{format:?}"), "must be json, svg or text").into(),
        );
    }
    let ids = run_ids(q.str("runs").unwrap_or(""))?;
    let (_, all) = budgeted_maps(&st, &ids).await?;
    let c = report::compare(ids, all)?;
    Ok(match format {
        "svg" => (
            [(header::CONTENT_TYPE, "image/svg+xml")],
            c.svg().map_err(no_plot)?,
        )
            .into_response(),
        "text" => (
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            c.table(),
        )
            .into_response(),
        _ => Json(c).into_response(),
    })
}

/// The specs and maps of runs `ids`, read one run at a time and refused
/// (422 naming `runs`) as soon as they hold more than [`COMPARE_MAX_MAPS`]
/// maps or [`COMPARE_MAX_POINTS`] points: what a comparison holds in
/// memory is bounded whatever runs it is given.
pub async fn budgeted_maps(
    st: &AppState,
    ids: &[String],
) -> Result<
    (
        Vec<crate::experiment::ExperimentSpec>,
        Vec<report::MapSummary>,
    ),
    Problem,
> {
    let (mut specs, mut all) = (Vec::new(), Vec::new());
    let mut points = 0;
    for (i, id) in ids.iter().enumerate() {
        let (spec, _, maps) = finished_maps(st, id)
            .await
            .map_err(|p| p.with_field("runs"))?;
        points += maps.iter().map(|m| m.points.len()).sum::<usize>();
        let n = all.len() + maps.len();
        if n > COMPARE_MAX_MAPS || points > COMPARE_MAX_POINTS {
            return Err(SpecError::new(
                "runs",
                format!(
                    "{} runs: the first {} hold {n} maps and {points} points",
                    ids.len(),
                    i + 1
                ),
                format!(
                    "a comparison holds at most {COMPARE_MAX_MAPS} maps and {COMPARE_MAX_POINTS} points: compare fewer runs"
                ),
            )
            .into());
        }
        specs.push(spec);
        all.extend(maps);
    }
    Ok((specs, all))
}

/// The ids in `runs` (comma-separated), each once, in the order given:
/// 1 to [`COMPARE_MAX_RUNS`] of them.
pub fn run_ids(runs: &str) -> Result<Vec<String>, Problem> {
    let mut ids: Vec<String> = runs
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
        .collect();
    // Each run once, in the order given.
    let mut seen = std::collections::HashSet::new();
    ids.retain(|id| seen.insert(id.clone()));
    if ids.is_empty() || ids.len() > COMPARE_MAX_RUNS {
        return Err(SpecError::new(
            "runs",
            if runs.len() > 80 {
                format!(
                    "{}… ({} characters)",
                    &runs[..runs.char_indices().nth(60).map_or(runs.len(), |(i, _)| i)],
                    runs.len()
                )
            } else {
                runs.to_string()
            },
            format!("give 1 to {COMPARE_MAX_RUNS} experiment ids, comma-separated"),
        )
        .into());
    }
    Ok(ids)
}
