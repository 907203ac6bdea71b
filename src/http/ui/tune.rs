//! A tune's page: the objective against the parameter (every evaluation;
//! the finalists re-evaluated at the final accuracy marked; the best so far
//! ringed), for two or more objectives the Pareto front over all
//! evaluations, and the finalists' table. Drawn from the evaluations stored
//! so far (`zwidth::tune::plots`), so it grows while the tune runs.

use maud::{html, Markup};
use serde_json::Value;

use crate::tune::plots::{best_so_far, describe, landscape_svg, metric_axis, pareto_svg};
use crate::tune::{Evaluation, Metric, Objective, TuneSpec};
use crate::zwidth::observer::StoredEvaluation;

/// An accuracy in words: a preset's name, else its JSON.
fn accuracy<T: serde::Serialize>(a: &T) -> String {
    serde_json::to_string(a)
        .unwrap_or_default()
        .trim_matches('"')
        .to_string()
}

pub fn render(spec: &TuneSpec, stored: &[StoredEvaluation], result: Option<&Value>) -> Markup {
    let all: Vec<Evaluation> = stored
        .iter()
        .filter_map(|e| serde_json::from_value(e.record.clone()).ok())
        .collect();
    let metrics: Vec<Metric> = match &spec.objective {
        Objective::Single(m) => vec![*m],
        Objective::Weighted(w) => w.keys().copied().collect(),
        Objective::Pareto(ms) => ms.clone(),
    };
    let params: Vec<String> = spec.params.keys().cloned().collect();
    let acc = (accuracy(&spec.accuracy), accuracy(&spec.final_accuracy));
    let landscape = (!all.is_empty())
        .then(|| landscape_svg(&params, &spec.objective, &all, (&acc.0, &acc.1)).ok())
        .flatten();
    let front = match &spec.objective {
        Objective::Pareto(ms) if ms.len() >= 2 && !all.is_empty() => pareto_svg(ms, &all).ok(),
        _ => None,
    };
    let best = best_so_far(&all);
    let reported = result.map(|r| r["best"].clone()).filter(|b| !b.is_null());
    let finals: Vec<&Evaluation> = all.iter().filter(|e| e.phase == "final").collect();
    html! {
        p { (all.len()) " evaluations stored; " (finals.len()) " at the final accuracy (" (acc.1) "). Objective: "
            code { (serde_json::to_string(&spec.objective).unwrap_or_default()) } "." }
        @if let (Some(e), None) = (best, &reported) {
            p class="best" { strong { "Best so far: " } (describe(e)) }
        }
        @if let Some(b) = &reported {
            p class="best" { strong { "Result: " } code { (b["params"]) } " · objectives " code { (b["objectives"]) }
                @if let Some(iv) = b["interval"].as_array() { " · score interval " code { (Value::Array(iv.clone())) } }
                @if let Some(h) = result.and_then(|r| r["ranking_held"].as_bool()) { " · ranking held: " (h) }
            }
        }
        @if let Some(s) = &landscape { figure class="tune" { (super::chart("the objective of every evaluation against the parameter", s)) } } @else { p class="muted" { "No evaluations stored yet." } }
        @if let Some((s, n)) = &front {
            figure class="tune" { (super::chart("the Pareto front over all search evaluations", s)) figcaption { (n) " evaluations on the front" } }
        }
        @if !finals.is_empty() {
            table class="figures" {
                caption { "Finalists at the final accuracy" }
                thead { tr { th { "#" } th { "parameters" } @for m in &metrics { th { (metric_axis(*m)) } } th { "score" } } }
                tbody {
                    @for e in &finals {
                        tr {
                            td class="num" { (e.index) }
                            td class="mono small" { @for (k, v) in &e.params { (k) " = " (format!("{v:.4}")) " " } }
                            @for m in &metrics { td class="num" { (metric_value(e, *m)) } }
                            td class="num" { @if e.feasible { (format!("{:.4}", e.score)) } @else { "infeasible" } }
                        }
                    }
                }
            }
        }
    }
}

fn metric_value(e: &Evaluation, m: Metric) -> String {
    e.metrics.get(m).map_or("–".into(), |v| format!("{v:.4}"))
}
