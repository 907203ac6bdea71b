//! The run list: newest first, a page at a time (never every trial, never
//! every run), filtered by kind, state, rig and scene; pick runs to compare.

use axum::extract::{RawQuery, State};
use axum::response::Response;
use maud::html;

use super::{ago, run_link, state_badge, Nav};
use crate::clock::now_ms;
use crate::error::SpecError;
use crate::http::problem::QueryArgs;
use crate::http::{AppState, Problem};
use crate::store::dashboard::ListFilter;

/// Runs per page.
pub const PER_PAGE: i64 = 50;
const KINDS: [&str; 4] = ["map", "compare", "sweep", "tune"];
use crate::store::{ExperimentState, STATES};

/// The filter from the query, each value checked.
pub fn filter(q: &QueryArgs) -> Result<ListFilter, Problem> {
    let one_of = |name: &str, allowed: &[&str]| -> Result<String, Problem> {
        let v = q.str(name).unwrap_or("").trim();
        if v.is_empty() || allowed.contains(&v) {
            Ok(v.to_string())
        } else {
            Err(SpecError::new(
                name,
                format!("{v:?}"),
                format!("must be one of {} (or empty: any)", allowed.join(", ")),
            )
            .into())
        }
    };
    let text = |name: &str, max: usize| -> Result<String, Problem> {
        let v = q.str(name).unwrap_or("").trim();
        if v.chars().count() > max {
            Err(SpecError::new(
                name,
                format!("{} characters", v.chars().count()),
                format!("at most {max} characters"),
            )
            .into())
        } else {
            Ok(v.to_string())
        }
    };
    Ok(ListFilter {
        kind: one_of("kind", &KINDS)?,
        state: one_of("state", &STATES)?,
        rig: text("rig", 64)?,
        scene: text("scene", 200)?,
    })
}

pub async fn page(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
) -> Result<Response, Problem> {
    let q = QueryArgs::parse(query.as_deref(), &["kind", "state", "rig", "scene", "page"])?;
    let f = filter(&q)?;
    let n = q.int("page", 1..=1_000_000)?.unwrap_or(1);
    let (rows, total) = st
        .store
        .list_filtered(&f, PER_PAGE, (n - 1) * PER_PAGE)
        .await
        .map_err(|e| st.fail(e))?;
    let mut rigs = st.store.run_rigs().await.map_err(|e| st.fail(e))?;
    // A rig asked for that no run names is still the filter shown.
    if !f.rig.is_empty() && !rigs.contains(&f.rig) {
        rigs.push(f.rig.clone());
    }
    let pages = ((total + PER_PAGE - 1) / PER_PAGE).max(1);
    if n > pages {
        return Err(SpecError::new(
            "page",
            n.to_string(),
            format!("must be 1 to {pages}: {total} runs match, {PER_PAGE} a page"),
        )
        .into());
    }
    let now = now_ms();
    let link = |p: i64| {
        let mut pairs = vec![("page", p.to_string())];
        for (k, v) in [
            ("kind", &f.kind),
            ("state", &f.state),
            ("rig", &f.rig),
            ("scene", &f.scene),
        ] {
            if !v.is_empty() {
                pairs.push((k, v.clone()));
            }
        }
        format!(
            "/runs?{}",
            serde_urlencoded::to_string(&pairs).unwrap_or_default()
        )
    };
    let select = |name: &str, label: &str, options: &[String], cur: &str| {
        html! {
            label { (label) " "
                select name=(name) {
                    option value="" { "any" }
                    @for o in options {
                        @if o == cur { option value=(o) selected { (o) } } @else { option value=(o) { (o) } }
                    }
                }
            }
        }
    };
    let kinds: Vec<String> = KINDS.iter().map(|s| s.to_string()).collect();
    let states: Vec<String> = STATES.iter().map(|s| s.to_string()).collect();
    Ok(super::layout(
        "Runs",
        Nav::Runs,
        html! {
            h1 { "Runs" }
            form class="filters" method="get" action="/runs" role="search" {
                (select("kind", "kind", &kinds, &f.kind))
                (select("state", "state", &states, &f.state))
                (select("rig", "rig", &rigs, &f.rig))
                label { "scene " input name="scene" type="search" value=(f.scene) placeholder="text in the spec, e.g. butterworth"; }
                button type="submit" { "Filter" }
                a href="/runs" { "clear" }
            }
            p class="muted" { (total) " runs; page " (n) " of " (pages) "." }
            form method="get" action="/compare" {
                table class="runs" {
                    thead { tr { th { span class="sr" { "pick to compare" } } th { "run" } th { "kind" } th { "state" } th { "rig" } th { "progress" } th { "trials" } th { "submitted" } th { "message" } } }
                    tbody {
                        @for r in &rows {
                            tr {
                                td { @if r.state == ExperimentState::Succeeded && r.kind != "tune" {
                                    input type="checkbox" name="run" value=(r.id) aria-label={"compare " (r.id)};
                                } }
                                td { (run_link(&r.id)) }
                                td { (r.kind) }
                                td { (state_badge(r.state)) }
                                td { (r.rig) }
                                td class="num volatile" { (format!("{:.0} %", 100.0 * r.progress)) }
                                td class="num volatile" { (r.trials_done) }
                                td class="volatile" { (ago(r.created_ms, now)) }
                                td class="error small" { (r.error.as_deref().unwrap_or("")) }
                            }
                        }
                    }
                }
                button type="submit" { "Compare the runs picked" }
            }
            nav class="pages" aria-label="pages" {
                @if n > 1 { a href=(link(n - 1)) rel="prev" { "← newer" } }
                @if n < pages { a href=(link(n + 1)) rel="next" { "older →" } }
            }
        },
    ))
}
