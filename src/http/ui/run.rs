//! A run's page: its spec (collapsible), state and progress, its maps in
//! the 2018 paper's Fig. 7 style drawn from the stored trials (so they grow
//! while it runs), the figures of its result, downloads. A tune's page is
//! `tune`.

use std::collections::BTreeMap;

use axum::extract::{Path, RawQuery, State};
use axum::response::Response;
use maud::{html, Markup};
use serde_json::Value;

use super::{action, duration, fragment, live_part, short, state_badge, unchanged, utc, Nav};
use crate::experiment::ExperimentSpec;
use crate::http::problem::QueryArgs;
use crate::http::{AppState, Problem};
use crate::plot::{map_extent, zwidth_map_svg_styled, FidelityScale, MapPlotPoint, MapStyle};
use crate::report::{self, MapSummary};
use crate::store::{ExperimentRow, ExperimentState};
use crate::zwidth::search::BoundaryPoint;

/// Points drawn one by one with a tooltip, over all maps of a page; past
/// it a map is drawn compactly (a 20 000-trial run page stays under 1 MB).
pub const TOOLTIP_BUDGET: usize = 3000;
/// Maps drawn on one page (a run's page shows the rest on further pages:
/// `?page=2`, …); docs/dashboard.md, "Budgets".
pub const PAGE_MAPS: usize = 12;
/// Points drawn on one page over all its maps: past it every map's points
/// are thinned alike (1 in n drawn, said under the maps; the boundaries
/// and the figures stay whole).
pub const PAGE_POINTS: usize = 8_000;

async fn row(st: &AppState, id: &str) -> Result<ExperimentRow, Problem> {
    st.store
        .get(id)
        .await
        .map_err(|e| st.fail(e))?
        .ok_or_else(|| Problem::not_found("experiment", id))
}

/// What changes the live part: state, trials stored and done, progress,
/// the end, a tune's best, and (known only to this process) whether its
/// trials are held or it waits for its rig.
pub(super) fn token(r: &ExperimentRow, stored: i64, st: &AppState) -> String {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    r.best.hash(&mut h);
    if let Some(o) = st
        .running
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .get(&r.id)
    {
        (o.held(), o.waiting()).hash(&mut h);
    }
    if r.state == ExperimentState::Queued {
        st.unserved(&r.rig).hash(&mut h);
    }
    format!(
        "{}.{}.{}.{:.4}.{}.{:x}",
        r.state,
        r.trials_done,
        stored,
        r.progress,
        r.finished_ms.unwrap_or(0),
        h.finish()
    )
}

async fn current_token(st: &AppState, r: &ExperimentRow) -> Result<String, Problem> {
    let stored = st.store.trial_count(&r.id).await.map_err(|e| st.fail(e))?;
    Ok(token(r, stored, st))
}

/// `?page=` of a run's page: which [`PAGE_MAPS`] maps are drawn (1: the first).
fn page_arg(q: &QueryArgs) -> Result<usize, Problem> {
    Ok(q.int("page", 1..=10_000)?.unwrap_or(1) as usize)
}

pub async fn page(
    State(st): State<AppState>,
    Path(id): Path<String>,
    RawQuery(q): RawQuery,
) -> Result<Response, Problem> {
    let page = page_arg(&QueryArgs::parse(q.as_deref(), &["page"])?)?;
    let r = row(&st, &id).await?;
    let spec: Option<Value> = serde_json::from_str(&r.spec).ok();
    let live = live_markup(&st, &r, page).await?;
    let pretty = spec
        .as_ref()
        .and_then(|s| serde_json::to_string_pretty(s).ok())
        .unwrap_or_default();
    Ok(super::layout(
        &format!("{} {}", r.kind, short(&r.id)),
        Nav::None,
        html! {
            h1 { (r.kind) " " span class="mono id" { (r.id) } }
            dl class="facts" {
                dt { "rig" } dd { (r.rig) }
                @if let Some(check) = estimator_check(&st, &r.rig) {
                    dt { "estimators" }
                    dd class=(if check.identical { "" } else { "warn" }) { (check.summary) }
                }
                dt { "priority" } dd { (r.priority) }
                dt { "submitted" } dd class="volatile" { (utc(r.created_ms)) }
                @if let Some(t) = r.not_before_ms { dt { "not before" } dd class="volatile" { (utc(t)) } }
                dt { "more like it" } dd { a href={"/runs?kind=" (r.kind)} { "runs of this kind" } " · " a href={"/runs?rig=" (r.rig)} { "runs on this rig" } }
            }
            details class="spec" {
                summary { "Spec" }
                pre { code { (pretty) } }
            }
            (live)
        },
    ))
}

/// Whether an attached rig's agent (as connected now) runs this build's
/// estimators to the bit; None for the simulator or before any hello.
fn estimator_check(st: &AppState, rig: &str) -> Option<crate::rig::protocol::EstimatorCheck> {
    st.rig(rig)?.attached()?.view().estimators
}

/// `GET /ui/runs/{id}/live?since=…`: the live part, or 204 when unchanged.
pub async fn live(
    State(st): State<AppState>,
    Path(id): Path<String>,
    RawQuery(q): RawQuery,
) -> Result<Response, Problem> {
    let page = page_arg(&QueryArgs::parse(q.as_deref(), &["page", "since"])?)?;
    let r = row(&st, &id).await?;
    if let Some(resp) = unchanged(q.as_deref(), &current_token(&st, &r).await?) {
        return Ok(resp);
    }
    Ok(fragment(live_markup(&st, &r, page).await?))
}

async fn live_markup(st: &AppState, r: &ExperimentRow, page: usize) -> Result<Markup, Problem> {
    let spec: Option<ExperimentSpec> = serde_json::from_str(&r.spec).ok();
    let result: Option<Value> = r
        .result
        .as_deref()
        .and_then(|s| serde_json::from_str(s).ok());
    let v = st.view(r.clone());
    let ended = r.state.ended();
    let status = html! {
        div class="status" {
            (state_badge(r.state))
            @if !ended {
                " " progress class="volatile" value=(format!("{:.3}", r.progress)) max="1" aria-label="progress" {}
                " " span class="num volatile" { (format!("{:.0} %", 100.0 * r.progress)) }
            }
            " " span class="num trials" { (r.trials_done) " trials" }
            @if let Some(e) = v.progress["elapsed_s"].as_f64() { " · " span class="volatile" { (duration(e)) " elapsed" } }
            @if let Some(e) = v.progress["eta_s"].as_f64() { " · " span class="volatile" { "ETA " (duration(e)) } }
            @if let Some(why) = v.progress["waiting_for_rig"].as_str() { " · " span class="warn" { "waiting for the rig: " (why) } }
            @if let Some(why) = v.progress["held"].as_str() { " · " span class="warn" { "held: " (why) } }
            @if let (Some(a), Some(b)) = (r.started_ms, r.finished_ms) { " · " span class="volatile" { "took " (duration((b - a) as f64 / 1000.0)) } }
            @if let Some(w) = &r.worker { " · " span class="mono small volatile" { (w) } }
            @if !ended { " " (action("POST", &format!("/v1/experiments/{}/cancel", r.id), "Cancel", "this run")) }
        }
        @if let Some(e) = &r.error { p class="error" { strong { "Error: " } (e) } }
    };
    let body = match &spec {
        Some(ExperimentSpec::Tune(t)) => {
            let evals = st.store.evaluations(&r.id).await.map_err(|e| st.fail(e))?;
            super::tune::render(t, &evals, result.as_ref())
        }
        Some(s) => maps_markup(st, r, s, result.as_ref(), page).await?,
        None => html! { p class="error" { "The stored spec cannot be read by this version." } },
    };
    let downloads = html! {
        @if r.state == ExperimentState::Succeeded {
            p class="downloads" { "Download: "
                a href={"/v1/experiments/" (r.id) "/points.csv"} download { "CSV" } " · "
                a href={"/v1/experiments/" (r.id) "/plot.svg"} download { "SVG" } " · "
                a href={"/v1/experiments/" (r.id)} { "JSON" } " · "
                a href={"/v1/experiments/" (r.id) "/trials"} { "trials (JSON)" }
            }
        }
    };
    Ok(live_part(
        "live",
        &if page > 1 {
            format!("/ui/runs/{}/live?page={page}", r.id)
        } else {
            format!("/ui/runs/{}/live", r.id)
        },
        &current_token(st, r).await?,
        !ended,
        html! { (status) (body) (downloads) },
    ))
}

/// One map's name per scope.
fn labels(spec: &ExperimentSpec, finished: &[MapSummary], n: usize) -> Vec<String> {
    if !finished.is_empty() {
        return finished.iter().map(|m| m.label.clone()).collect();
    }
    let mut out: Vec<String> = match spec {
        ExperimentSpec::Map(m) => vec![m.scene.estimator.label()],
        ExperimentSpec::Sweep(s) => s
            .variant_specs()
            .map(|v| v.into_iter().map(|(l, _, _)| l).collect())
            .unwrap_or_default(),
        ExperimentSpec::Compare(c) => match &c.estimators {
            Some(e) => e.iter().map(|e| e.label()).collect(),
            // The paper's four, named as the result will name them (their
            // names do not depend on Levant's C).
            None => crate::zwidth::compare::paper_estimators(
                &c.scene
                    .clone()
                    .unwrap_or_else(crate::zwidth::compare::seed_2018_scene),
                1.0,
            )
            .into_iter()
            .map(|(name, _, _)| name)
            .collect(),
        },
        ExperimentSpec::Tune(_) => Vec::new(),
    };
    while out.len() < n {
        out.push(format!("map {}", out.len()));
    }
    out
}

/// The boundary so far of a running map: per B, the largest K decided to
/// render (a bisection's lower bracket).
fn boundary_so_far(points: &[MapPlotPoint]) -> Vec<BoundaryPoint> {
    let mut by_b: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
    for p in points.iter().filter(|p| p.ok && p.decided) {
        let e = by_b.entry(p.b.to_bits()).or_insert((p.b, p.k));
        e.1 = e.1.max(p.k);
    }
    let mut out: Vec<BoundaryPoint> = by_b
        .into_values()
        .map(|(b, k)| BoundaryPoint::new(b, k))
        .collect();
    out.sort_by(|a, b| a.b.total_cmp(&b.b));
    out
}

/// The run's maps from its stored trials, on shared axes with one colour
/// scale, and the table of its result's figures.
async fn maps_markup(
    st: &AppState,
    r: &ExperimentRow,
    spec: &ExperimentSpec,
    result: Option<&Value>,
    page: usize,
) -> Result<Markup, Problem> {
    let mut scopes: BTreeMap<u32, Vec<MapPlotPoint>> = st
        .store
        .map_points(&r.id)
        .await
        .map_err(|e| st.fail(e))?
        .into_iter()
        .map(|(scope, points)| (scope, points.iter().map(MapPlotPoint::of).collect()))
        .collect();
    // A compare's refinement rounds map row i again as scope r·n + i
    // (`compare::scopes`): each row's panel shows its latest map, the one
    // its result row reports.
    if let ExperimentSpec::Compare(_) = spec {
        let rows = labels(spec, &[], 0).len().max(1) as u32;
        let mut latest: BTreeMap<u32, Vec<MapPlotPoint>> = BTreeMap::new();
        for (scope, points) in std::mem::take(&mut scopes) {
            latest.insert(scope % rows, points);
        }
        scopes = latest;
    }
    let finished: Vec<MapSummary> = match (result, r.state) {
        (Some(res), ExperimentState::Succeeded) => report::maps(&r.id, spec, res),
        _ => Vec::new(),
    };
    let n = scopes
        .keys()
        .next_back()
        .map_or(0, |s| *s as usize + 1)
        .max(finished.len());
    let names = labels(spec, &finished, n);
    let shown = page_range(n, page)?;
    let panels: Vec<(String, Vec<MapPlotPoint>, Vec<BoundaryPoint>, String)> = shown
        .clone()
        .map(|i| {
            let pts = scopes.remove(&(i as u32)).unwrap_or_default();
            let (boundary, criterion) = match finished.get(i) {
                Some(m) => (m.boundary.clone(), m.criterion.clone()),
                None => (boundary_so_far(&pts), String::new()),
            };
            (
                names.get(i).cloned().unwrap_or_default(),
                pts,
                boundary,
                criterion,
            )
        })
        .collect();
    let prediction = predicted(spec, result);
    let figure = map_panels(&panels, !finished.is_empty(), &prediction)?;
    let pager = pager(n, page, &format!("/runs/{}?", r.id));
    let table = html! {
        @if !finished.is_empty() {
            table class="figures" {
                caption { "The result" }
                thead { tr { th { "map" } th { "K-width (N/m)" } th { "B-width (N·s/m)" } th { "max fidelity error (N·s/m)" } th { "area (N/m · N·s/m)" } th { "model" } } }
                tbody {
                    @for (i, m) in finished.iter().enumerate().filter(|(i, _)| shown.contains(i)) {
                        @let map = result.map(|res| map_json(spec, res, i)).unwrap_or(Value::Null);
                        tr {
                            td { (m.label) }
                            td class="num" { (format!("{:.0}", m.k_width)) (interval(&map["k_width_interval"], 0)) }
                            td class="num" { (format!("{:.2}", m.b_width)) (interval(&map["b_width_interval"], 2)) }
                            td class="num" { (m.max_fidelity_error.map_or("–".into(), |f| format!("{f:.3}"))) }
                            td class="num" { (format!("{:.4e}", m.area)) }
                            td class="small" { details { summary { "model" } (map["model"].as_str().unwrap_or("–")) } }
                        }
                    }
                }
            }
        }
    };
    let against = prior_table(result);
    Ok(html! { (table) (against) (pager) (figure) })
}

/// A map's predicted boundary (its `prior`): the result's report once it
/// has one, else a boundary given in the spec; empty for anything else.
fn predicted(spec: &ExperimentSpec, result: Option<&Value>) -> Vec<BoundaryPoint> {
    let report = result.and_then(|r| {
        serde_json::from_value::<crate::zwidth::prior::PriorReport>(r["prior"].clone()).ok()
    });
    match (report, spec) {
        (Some(p), _) => p.predicted_boundary(),
        (None, ExperimentSpec::Map(m)) => match &m.prior {
            Some(crate::zwidth::prior::Prior::Boundary(b)) => b.clone(),
            _ => Vec::new(),
        },
        _ => Vec::new(),
    }
}

/// The prediction beside the map's own boundary, column by column (a map
/// with a `prior`, once finished).
fn prior_table(result: Option<&Value>) -> Markup {
    let Some(report) = result.map(|r| &r["prior"]).filter(|p| p.is_object()) else {
        return html! {};
    };
    let columns = report["columns"].as_array().cloned().unwrap_or_default();
    let boundary = result
        .and_then(|r| r["boundary"].as_array())
        .cloned()
        .unwrap_or_default();
    let k = |v: &Value| v.as_f64().map_or("–".to_string(), |x| format!("{x:.0}"));
    html! {
        table class="figures prior" {
            caption {
                "The prediction (" (report["source"].as_str().unwrap_or("prior")) ") against the map: "
                (report["disagreements"].as_u64().unwrap_or(0)) " of " (columns.len()) " columns disagree"
            }
            thead { tr { th { "B (N·s/m)" } th { "predicted K_max (N/m)" } th { "the map's K_max (N/m)" } th { "agrees" } } }
            tbody {
                @for c in &columns {
                    @let own = boundary.iter().find(|p| p["b"] == c["b"]).cloned().unwrap_or(Value::Null);
                    tr class=(if c["agrees"] == true { "" } else { "warn" }) {
                        td class="num" { (c["b"].as_f64().map_or("–".into(), |b| format!("{b:.2}"))) }
                        td class="num" { (k(&c["predicted_k_max"])) br; span class="small muted" { "[" (k(&c["predicted_k_lo"])) ", " (k(&c["predicted_k_hi"])) "]" } }
                        td class="num" { (k(&own["k_max"])) @if own["k_lo"].is_number() { br; span class="small muted" { "[" (k(&own["k_lo"])) ", " (k(&own["k_hi"])) "]" } } }
                        td { (if c["agrees"] == true { "yes" } else { "no" }) }
                    }
                }
            }
        }
    }
}

/// The maps page `page` (1-based) of `n` maps draws; a page past the last
/// is a 422 naming `page`.
pub fn page_range(n: usize, page: usize) -> Result<std::ops::Range<usize>, Problem> {
    let pages = n.div_ceil(PAGE_MAPS).max(1);
    if page > pages {
        return Err(crate::error::SpecError::new(
            "page",
            page,
            format!("1 to {pages}: {n} maps, {PAGE_MAPS} a page"),
        )
        .into());
    }
    Ok((page - 1) * PAGE_MAPS..(page * PAGE_MAPS).min(n))
}

/// 1 point in this many is drawn when a page's maps hold `total` points.
fn stride(total: usize) -> usize {
    total.div_ceil(PAGE_POINTS).max(1)
}

/// Links to the other pages of `n` maps (`base` ends in `?` or `&`).
pub fn pager(n: usize, page: usize, base: &str) -> Markup {
    let pages = n.div_ceil(PAGE_MAPS).max(1);
    let shown = (page - 1) * PAGE_MAPS..(page * PAGE_MAPS).min(n);
    html! {
        @if pages > 1 {
            nav class="pager" aria-label="maps" {
                "Maps " (shown.start + 1) "–" (shown.end) " of " (n) " (" (PAGE_MAPS) " a page): "
                @for p in 1..=pages {
                    @if p == page { strong aria-current="page" { (p) } } @else { a href={(base) "page=" (p)} { (p) } }
                    " "
                }
            }
        }
    }
}

/// A map's own result JSON (a compare's or sweep's row's `map`).
fn map_json(spec: &ExperimentSpec, result: &Value, i: usize) -> Value {
    match spec {
        ExperimentSpec::Map(_) => result.clone(),
        _ => result["rows"][i]["map"].clone(),
    }
}

fn interval(v: &Value, digits: usize) -> Markup {
    match (v[0].as_f64(), v[1].as_f64()) {
        (Some(lo), Some(hi)) => {
            html! { br; span class="small muted" { "[" (format!("{lo:.digits$}")) ", " (format!("{hi:.digits$}")) "]" } }
        }
        _ => html! {},
    }
}

/// Maps as small multiples: one axis range and one fidelity colour scale
/// for all, so positions and colours compare across panels.
pub fn map_panels(
    panels: &[(String, Vec<MapPlotPoint>, Vec<BoundaryPoint>, String)],
    finished: bool,
    prediction: &[BoundaryPoint],
) -> Result<Markup, Problem> {
    if panels.iter().all(|p| p.1.is_empty() && p.2.is_empty()) {
        return Ok(html! { p class="muted" { "No trials stored yet." } });
    }
    let extent = panels.iter().fold((1.0f64, 1.0f64), |acc, (_, pts, b, _)| {
        let drawn: Vec<BoundaryPoint> = b.iter().chain(prediction).copied().collect();
        let e = map_extent(pts, &drawn);
        (acc.0.max(e.0), acc.1.max(e.1))
    });
    let scale = panels.iter().fold(None, |acc, p| {
        FidelityScale::union(acc, FidelityScale::of(&p.1))
    });
    let single = panels.len() == 1;
    let per_map = TOOLTIP_BUDGET / panels.len().max(1);
    // Past the page's point budget, 1 point in `stride` of every map.
    let total: usize = panels.iter().map(|p| p.1.len()).sum();
    let stride = stride(total);
    let mut out = Vec::new();
    for (name, all, boundary, criterion) in panels {
        let thinned: Vec<MapPlotPoint>;
        let pts = if stride > 1 {
            thinned = all.iter().step_by(stride).cloned().collect();
            &thinned
        } else {
            all
        };
        let style = MapStyle {
            ok_label: if criterion == "stability" {
                "stable"
            } else {
                "passive"
            }
            .into(),
            scale,
            extent: Some(extent),
            size: if single { (900, 600) } else { (620, 440) },
            tooltip_limit: per_map,
            prediction: prediction.to_vec(),
        };
        let title = format!("{name} ({} trials)", all.len());
        let s = zwidth_map_svg_styled(&title, pts, boundary, &style).map_err(Problem::internal)?;
        out.push((name.clone(), all.len(), s));
    }
    Ok(html! {
        @if !finished { p class="muted small" { "Drawn from the trials stored so far; the line is the largest K decided to render at each B until the run ends." } }
        @if stride > 1 { p class="muted small" { "1 trial in " (stride) " drawn (" (total) " on this page, at most " (PAGE_POINTS) " are drawn); the boundaries and figures use them all." } }
        @if !single {
            p class="legend small" {
                span class="key dot" {} " renders (colour: fidelity error, one scale for all) "
                span class="key cross" { "×" } " does not "
                span class="key ring" {} " undecided "
                span class="key line" {} " boundary "
                span class="key bar" {} " its interval"
            }
        }
        div class={"maps" (if single { " single" } else { "" })} {
            @for (name, n, s) in &out {
                figure {
                    (super::chart(&format!("K–B map of {name}: {n} trials"), s))
                    figcaption { (name) ": " (n) " trials" }
                }
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A map spec with `prior` (JSON) and nothing else of note.
    fn map_spec(prior: &str) -> ExperimentSpec {
        serde_json::from_str(&format!(
            r#"{{"kind":"map","scene":{{}},"method":"time","criterion":"stability","prior":{prior}}}"#
        ))
        .unwrap()
    }

    #[test]
    fn a_map_s_prediction_comes_from_its_report_else_from_its_spec() {
        let spec = map_spec(r#"{"boundary":[{"b":0,"k_max":100}]}"#);
        // Before a result: the boundary the spec gives.
        assert_eq!(predicted(&spec, None), vec![BoundaryPoint::new(0.0, 100.0)]);
        // With one: the report's columns, intervals included.
        let result = serde_json::json!({"prior": {"source": "the boundary given", "disagreements": 1, "trials": 3, "columns": [
            {"b": 0.0, "predicted_k_max": 90.0, "predicted_k_lo": 80.0, "predicted_k_hi": 95.0, "agrees": false}
        ]}});
        let p = predicted(&spec, Some(&result));
        assert_eq!(
            p,
            vec![BoundaryPoint {
                b: 0.0,
                k_max: 90.0,
                k_lo: Some(80.0),
                k_hi: Some(95.0)
            }]
        );
        // A scene to simulate: nothing to draw until the report.
        assert!(predicted(&map_spec(r#"{"scene":{}}"#), None).is_empty());
    }

    #[test]
    fn the_prior_table_marks_the_columns_that_disagree() {
        let result = serde_json::json!({
            "boundary": [{"b": 0.0, "k_max": 1000.0, "k_lo": 990.0, "k_hi": 1010.0}, {"b": 10.0, "k_max": 500.0}],
            "prior": {"source": "the boundary given", "disagreements": 1, "trials": 9, "columns": [
                {"b": 0.0, "predicted_k_max": 1000.0, "predicted_k_lo": 995.0, "predicted_k_hi": 1005.0, "agrees": true},
                {"b": 10.0, "predicted_k_max": 800.0, "predicted_k_lo": 792.0, "predicted_k_hi": 808.0, "agrees": false}
            ]}
        });
        let html = prior_table(Some(&result)).into_string();
        assert!(
            html.contains(
                "The prediction (the boundary given) against the map: 1 of 2 columns disagree"
            ),
            "{html}"
        );
        assert_eq!(html.matches("<tr class=\"warn\">").count(), 1, "{html}");
        assert!(
            html.contains("[990, 1010]") && html.contains("800"),
            "{html}"
        );
        // No prior: no table.
        assert!(prior_table(Some(&serde_json::json!({"boundary": []})))
            .into_string()
            .is_empty());
        assert!(prior_table(None).into_string().is_empty());
    }

    proptest! {
        /// Issue 30: accepted ⇒ bounded. Any page a run accepts draws at
        /// most PAGE_MAPS maps, and at most PAGE_POINTS points (plus one
        /// per map, for the rounding of `step_by`) whatever they hold.
        #[test]
        fn a_page_draws_within_its_budgets(
            sizes in proptest::collection::vec(0usize..50_000, 0..400),
            page in 1usize..40,
        ) {
            let n = sizes.len();
            match page_range(n, page) {
                Ok(shown) => {
                    prop_assert!(shown.len() <= PAGE_MAPS);
                    prop_assert!(page == 1 || !shown.is_empty());
                    let total: usize = sizes[shown.clone()].iter().sum();
                    let s = stride(total);
                    let drawn: usize = sizes[shown.clone()].iter().map(|m| m.div_ceil(s)).sum();
                    prop_assert!(drawn <= PAGE_POINTS + shown.len(), "{drawn}");
                    prop_assert!(s == 1 || total > PAGE_POINTS);
                }
                Err(p) => {
                    prop_assert_eq!(p.field.as_deref(), Some("page"));
                    prop_assert!(page > n.div_ceil(PAGE_MAPS).max(1));
                }
            }
        }
    }
}
