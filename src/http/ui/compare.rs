//! Compare runs: pick them; every map as a small multiple on shared axes
//! with one fidelity colour scale; the boundaries overlaid; the table of
//! differences; the specs side by side, differences only by default.

use std::collections::BTreeMap;

use axum::extract::{RawQuery, State};
use axum::response::Response;
use maud::{html, Markup};
use serde_json::Value;

use super::run::map_panels;
use super::{run_link, state_badge, Nav};
use crate::http::compare::{budgeted_maps, run_ids};
use crate::http::experiments::no_plot;
use crate::http::{AppState, Problem};
use crate::plot::MapPlotPoint;
use crate::report;
use crate::store::dashboard::ListFilter;

pub async fn page(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
) -> Result<Response, Problem> {
    // `runs=a,b` (a link) or `run=a&run=b` (the run list's checkboxes).
    let pairs: Vec<(String, String)> = serde_urlencoded::from_str(query.as_deref().unwrap_or(""))
        .map_err(|e| {
        Problem::from(crate::error::SpecError::new(
            "query",
            query.clone().unwrap_or_default(),
            format!("not a query string: {e}"),
        ))
    })?;
    let mut joined = Vec::new();
    let mut all = false;
    let mut page = 1;
    for (k, v) in &pairs {
        match k.as_str() {
            "runs" | "run" => joined.push(v.clone()),
            "all" => all = v == "1" || v == "true",
            "page" => {
                page = v
                    .parse::<usize>()
                    .ok()
                    .filter(|p| (1..=10_000).contains(p))
                    .ok_or_else(|| {
                        crate::error::SpecError::new("page", format!("{v:?}"), "a whole number 1 to 10000")
                    })?
            }
            other => {
                return Err(crate::error::SpecError::new(
                    other,
                    format!("{v:?}"),
                    "not a parameter of /compare: runs (comma-separated ids), run (repeated), all (1: every spec field) and page (of the maps drawn)",
                )
                .into())
            }
        }
    }
    let joined = joined.join(",");
    if joined.trim().is_empty() {
        return picker(&st).await;
    }
    let ids = run_ids(&joined)?;
    let (specs, maps) = budgeted_maps(&st, &ids).await?;
    let specs: Vec<Value> = specs
        .iter()
        .map(|s| serde_json::to_value(s).unwrap_or(Value::Null))
        .collect();
    let c = report::compare(ids.clone(), maps)?;
    // Runs by letter (A, B, …): short and unlike each other.
    let letter = |run: &str| letter(ids.iter().position(|i| i == run).unwrap_or(0));
    let shown = super::run::page_range(c.rows.len(), page)?;
    let panels: Vec<_> = c.rows[shown]
        .iter()
        .map(|r| {
            let m = &r.map;
            (
                format!("{} {}", letter(&m.run), m.label),
                m.points
                    .iter()
                    .map(MapPlotPoint::from_json)
                    .collect::<Vec<_>>(),
                m.boundary.clone(),
                m.criterion.clone(),
            )
        })
        .collect();
    let figure = map_panels(&panels, true, &[])?;
    let overlay = c
        .svg_named(|m| format!("{} {}", letter(&m.run), m.label))
        .map_err(no_plot)?;
    let pct = |p: Option<f64>| p.map_or("–".into(), |p| format!("{p:+.1} %"));
    let best = |i: usize, j: Option<usize>| if Some(i) == j { "best" } else { "" };
    // K-width and B-width: best only where the intervals rank it above
    // every other row (on exact verdicts, always).
    let k_best = c.best.k_width_resolved.then_some(c.best.k_width);
    let b_best = c.best.b_width_resolved.then_some(c.best.b_width);
    let interval = |i: Option<[f64; 2]>, prec: usize| {
        html! { @if let Some([lo, hi]) = i { br; span class="muted small" { "[" (format!("{lo:.prec$}")) ", " (format!("{hi:.prec$}")) "]" } } }
    };
    let name = |i: usize| {
        let m = &c.rows[i].map;
        format!("{} {}", letter(&m.run), m.label)
    };
    // The best in words too (not by weight and colour alone).
    let mark =
        |i: usize, j: Option<usize>| html! { @if Some(i) == j { span class="sr" { " (best)" } } };
    let here = format!("/compare?runs={}", ids.join(","));
    Ok(super::layout(
        "Compare",
        Nav::Compare,
        html! {
            h1 { "Compare " (ids.len()) " runs" }
            ul class="runs-key" {
                @for id in &ids { li { strong { (letter(id)) } " " (run_link(id)) } }
            }
            @for n in &c.notes { p class="warn" { (n) } }
            table class="figures" {
                caption { "Differences from the first map (A " (c.rows.first().map_or("", |r| r.map.label.as_str())) "); best of each column marked, the K-width's and B-width's only where their intervals rank it above every other map" }
                thead { tr { th { "run" } th { "map" } th { "K-width (N/m)" } th { "ΔK" } th { "B-width (N·s/m)" } th { "ΔB" } th { "max fidelity error (N·s/m)" } th { "area" } th { "Δarea" } } }
                tbody {
                    @for (i, r) in c.rows.iter().enumerate() {
                        tr {
                            td { strong { (letter(&r.map.run)) } " " (run_link(&r.map.run)) }
                            td { (r.map.label) }
                            td class={"num " (best(i, k_best))} { (format!("{:.0}", r.map.k_width)) (mark(i, k_best)) (interval(r.map.k_width_interval, 0)) }
                            td class="num" { (pct(r.k_width_diff_pct)) }
                            td class={"num " (best(i, b_best))} { (format!("{:.2}", r.map.b_width)) (mark(i, b_best)) (interval(r.map.b_width_interval, 2)) }
                            td class="num" { (pct(r.b_width_diff_pct)) }
                            td class={"num " (best(i, c.best.max_fidelity_error))} { (r.map.max_fidelity_error.map_or("–".into(), |f| format!("{f:.3}"))) (mark(i, c.best.max_fidelity_error)) }
                            td class={"num " (best(i, Some(c.best.area)))} { (format!("{:.4e}", r.map.area)) (mark(i, Some(c.best.area))) }
                            td class="num" { (pct(r.area_diff_pct)) }
                        }
                    }
                }
            }
            @if !c.order.is_empty() {
                h2 { "Which is wider" }
                p class="muted small" {
                    "Each pair's order by its intervals: resolved when the wider map's interval lies wholly above the other's, wrong with probability at most "
                    (format!("{:.0} %", 100.0 * c.order[0].error_at_most)) "."
                }
                @for (label, width) in [("K-width", "k_width"), ("B-width", "b_width")] {
                    @let chain = ranking(&c.order, width);
                    @if !chain.is_empty() {
                        p { strong { (label) ": " } @for (i, (row, next)) in chain.iter().enumerate() {
                            @if i > 0 { " " }
                            (name(*row))
                            @match next { Some(true) => " >", Some(false) => " ≈", None => "" }
                        } }
                    }
                }
                p class="muted small" { "> resolved, ≈ the intervals overlap, each between neighbours in the order of the estimates." }
                details {
                    summary { "Every pair (" (c.order.len()) ")" }
                    table class="orders" {
                        thead { tr { th { "width" } th { "wider" } th { "narrower" } th { "order" } } }
                        tbody {
                            @for o in &c.order {
                                tr {
                                    td { (if o.width == "k_width" { "K-width" } else { "B-width" }) }
                                    td { (name(o.wider)) }
                                    td { (name(o.narrower)) }
                                    td { @if o.resolved { "resolved" } @else { span class="warn" { "not resolved (the intervals overlap)" } } }
                                }
                            }
                        }
                    }
                }
            }
            h2 { "The maps" }
            p class="muted small" { "One axis range and one fidelity colour scale for every map." }
            (super::run::pager(c.rows.len(), page, &format!("{here}{}&", if all { "&all=1" } else { "" })))
            (figure)
            h2 { "The boundaries" }
            figure class="overlay" { (super::chart("every map's boundary, K against B", &overlay)) }
            h2 { "The specs" }
            p {
                @if all { a href=(here) { "Show differences only" } } @else { "Differences only. " a href={(here) "&all=1"} { "Show every field" } }
            }
            (spec_table(&ids, &specs, all))
        },
    ))
}

/// The rows that have `width`'s orders, widest estimate first (the orders
/// name the wider of each pair: a row is above every row it is wider
/// than), each with whether its order over the next is resolved (`None`
/// for the last).
fn ranking(orders: &[report::RowOrder], width: &str) -> Vec<(usize, Option<bool>)> {
    let of: Vec<&report::RowOrder> = orders.iter().filter(|o| o.width == width).collect();
    let mut rows: Vec<usize> = of.iter().flat_map(|o| [o.wider, o.narrower]).collect();
    rows.sort_unstable();
    rows.dedup();
    // Wider than more rows: higher (the orders are by estimate, ties to the
    // earlier row, so this is the estimates' order).
    let wins = |r: usize| of.iter().filter(|o| o.wider == r).count();
    rows.sort_by_key(|&r| (std::cmp::Reverse(wins(r)), r));
    (0..rows.len())
        .map(|i| {
            let next = rows.get(i + 1).map(|&n| {
                of.iter()
                    .any(|o| o.wider == rows[i] && o.narrower == n && o.resolved)
            });
            (rows[i], next)
        })
        .collect()
}

/// Each spec flattened to `path = value`; with `all` false only the paths
/// whose values differ between runs.
fn spec_table(ids: &[String], specs: &[Value], all: bool) -> Markup {
    let flat: Vec<BTreeMap<String, String>> = specs.iter().map(flatten).collect();
    let mut paths: Vec<&String> = flat.iter().flat_map(|f| f.keys()).collect();
    paths.sort();
    paths.dedup();
    let rows: Vec<(&String, Vec<String>)> = paths
        .into_iter()
        .map(|p| {
            (
                p,
                flat.iter()
                    .map(|f| f.get(p).cloned().unwrap_or_else(|| "–".into()))
                    .collect::<Vec<_>>(),
            )
        })
        .filter(|(_, vals)| all || vals.iter().any(|v| v != &vals[0]))
        .collect();
    html! {
        @if rows.is_empty() {
            p class="muted" { "The specs are the same." }
        } @else {
            table class="spec-diff" {
                thead { tr { th { "field" } @for (i, id) in ids.iter().enumerate() { th { strong { (letter(i)) } " " (run_link(id)) } } } }
                tbody {
                    @for (p, vals) in &rows {
                        @let differ = vals.iter().any(|v| v != &vals[0]);
                        tr class=(if differ { "differs" } else { "" }) {
                            th scope="row" class="mono small" { (p) }
                            @for v in vals { td class="mono small" { (v) } }
                        }
                    }
                }
            }
        }
    }
}

/// A run's letter by its place: A … Z, then AA, AB, …
pub fn letter(i: usize) -> String {
    const L: &[u8] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZ";
    if i < 26 {
        (L[i] as char).to_string()
    } else {
        format!("{}{}", L[i / 26 - 1] as char, L[i % 26] as char)
    }
}

/// `{"a":{"b":1}}` → `a.b = 1`; arrays by index.
pub fn flatten(v: &Value) -> BTreeMap<String, String> {
    fn walk(prefix: &str, v: &Value, out: &mut BTreeMap<String, String>) {
        match v {
            Value::Object(m) if !m.is_empty() => {
                for (k, x) in m {
                    let p = if prefix.is_empty() {
                        k.clone()
                    } else {
                        format!("{prefix}.{k}")
                    };
                    walk(&p, x, out);
                }
            }
            Value::Array(a) if !a.is_empty() => {
                for (i, x) in a.iter().enumerate() {
                    walk(&format!("{prefix}[{i}]"), x, out);
                }
            }
            Value::String(s) => {
                out.insert(prefix.to_string(), s.clone());
            }
            other => {
                out.insert(prefix.to_string(), other.to_string());
            }
        }
    }
    let mut out = BTreeMap::new();
    walk("", v, &mut out);
    out
}

/// No runs picked: the latest succeeded runs to pick from.
async fn picker(st: &AppState) -> Result<Response, Problem> {
    let f = ListFilter {
        state: "succeeded".into(),
        ..ListFilter::default()
    };
    let (rows, total) = st
        .store
        .list_filtered(&f, 50, 0)
        .await
        .map_err(|e| st.fail(e))?;
    Ok(super::layout(
        "Compare",
        Nav::Compare,
        html! {
            h1 { "Compare runs" }
            p { "Pick runs on the same scene (device, loop, wall, protocol); their maps are compared. The latest " (rows.len()) " of " (total) " succeeded runs; " a href="/runs?state=succeeded" { "all of them" } "." }
            form method="get" action="/compare" {
                table class="runs" {
                    thead { tr { th { span class="sr" { "pick" } } th { "run" } th { "kind" } th { "state" } th { "rig" } th { "trials" } } }
                    tbody {
                        @for r in rows.iter().filter(|r| r.kind != "tune") {
                            tr {
                                td { input type="checkbox" name="run" value=(r.id) aria-label={"compare " (r.id)}; }
                                td { (run_link(&r.id)) }
                                td { (r.kind) }
                                td { (state_badge(r.state)) }
                                td { (r.rig) }
                                td class="num" { (r.trials_done) }
                            }
                        }
                    }
                }
                button type="submit" { "Compare" }
            }
        },
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ranking_follows_the_estimates_and_marks_each_neighbour_s_order() {
        // The README compare's K-widths (docs/zwidth.md): AKF (row 2) over
        // FDM+filter (0) unresolved, FDM+filter over FOAW (1) resolved, AKF
        // over FOAW resolved; the B-widths' orders are left out.
        let o = |wider, narrower, resolved, width| report::RowOrder {
            width,
            wider,
            narrower,
            resolved,
            error_at_most: 0.1,
        };
        let orders = [
            o(0, 1, true, "k_width"),
            o(2, 0, false, "k_width"),
            o(2, 1, true, "k_width"),
            o(1, 0, true, "b_width"),
        ];
        assert_eq!(
            ranking(&orders, "k_width"),
            [(2, Some(false)), (0, Some(true)), (1, None)]
        );
        assert_eq!(ranking(&orders, "b_width"), [(1, Some(true)), (0, None)]);
        assert!(ranking(&[], "k_width").is_empty());
    }
}
