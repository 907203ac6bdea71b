//! A tune's page: the objective against the parameter (every evaluation;
//! the finalists re-evaluated at the final accuracy marked; the best so far
//! ringed), for two or more objectives the Pareto front over all
//! evaluations, and the finalists' table.

use maud::{html, Markup};
use serde_json::Value;

use super::svg;
use crate::plot::{scatter_svg, Mark, Scatter};
use crate::tune::{Metric, Objective, TuneSpec};
use crate::zwidth::observer::StoredEvaluation;

/// A metric's JSON name and what it is on an axis.
fn axis(m: Metric) -> (&'static str, &'static str, bool) {
    // (name, axis label, larger is better)
    match m {
        Metric::KWidth => ("k_width", "K-width (N/m)", true),
        Metric::BWidth => ("b_width", "B-width (N·s/m)", true),
        Metric::MaxFidelityError => ("max_fidelity_error", "max fidelity error (N·s/m)", false),
        Metric::Area => ("area", "area (N/m · N·s/m)", true),
    }
}

/// An accuracy in words: a preset's name, else its JSON.
fn accuracy<T: serde::Serialize>(a: &T) -> String {
    serde_json::to_string(a)
        .unwrap_or_default()
        .trim_matches('"')
        .to_string()
}

struct Eval {
    index: usize,
    phase: String,
    params: Vec<(String, f64)>,
    objectives: Value,
    score: f64,
    feasible: bool,
}

fn evals(stored: &[StoredEvaluation]) -> Vec<Eval> {
    stored
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let r = &e.record;
            Eval {
                index: r["index"].as_u64().map_or(i, |n| n as usize),
                phase: r["phase"].as_str().unwrap_or("search").to_string(),
                params: r["params"]
                    .as_object()
                    .map(|m| m.iter().filter_map(|(k, v)| Some((k.clone(), v.as_f64()?))).collect())
                    .unwrap_or_default(),
                objectives: r["objectives"].clone(),
                score: r["score"].as_f64().unwrap_or(f64::NAN),
                feasible: r["feasible"].as_bool().unwrap_or(true),
            }
        })
        .collect()
}

fn tip(e: &Eval) -> String {
    let params: Vec<String> = e.params.iter().map(|(k, v)| format!("{k} = {v:.4}")).collect();
    let objs: Vec<String> = e
        .objectives
        .as_object()
        .map(|m| m.iter().filter_map(|(k, v)| Some(format!("{k} = {:.4}", v.as_f64()?))).collect())
        .unwrap_or_default();
    format!(
        "#{} ({}{}): {}; {}",
        e.index,
        e.phase,
        if e.feasible { "" } else { ", infeasible" },
        params.join(", "),
        objs.join(", ")
    )
}

/// Indices of the non-dominated evaluations over `metrics`.
pub fn pareto_front(points: &[Vec<f64>], larger_better: &[bool]) -> Vec<usize> {
    let better_eq = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).zip(larger_better).all(|((x, y), up)| if *up { x >= y } else { x <= y })
    };
    let strictly = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).zip(larger_better).any(|((x, y), up)| if *up { x > y } else { x < y })
    };
    (0..points.len())
        .filter(|&i| {
            points[i].iter().all(|v| v.is_finite())
                && !points
                    .iter()
                    .enumerate()
                    .any(|(j, q)| j != i && q.iter().all(|v| v.is_finite()) && better_eq(q, &points[i]) && strictly(q, &points[i]))
        })
        .collect()
}

pub fn render(spec: &TuneSpec, stored: &[StoredEvaluation], result: Option<&Value>) -> Markup {
    let all = evals(stored);
    let (metrics, pareto): (Vec<Metric>, bool) = match &spec.objective {
        Objective::Single(m) => (vec![*m], false),
        Objective::Weighted(w) => (w.keys().copied().collect(), false),
        Objective::Pareto(ms) => (ms.clone(), true),
    };
    let single = match &spec.objective {
        Objective::Single(m) => Some(*m),
        _ => None,
    };
    // The value plotted against the parameter: the metric, or the score.
    let value = |e: &Eval| match single {
        Some(m) => e.objectives[axis(m).0].as_f64().unwrap_or(f64::NAN),
        None => e.score,
    };
    let y_label = single.map_or("score (weighted objective)", |m| axis(m).1);
    let best_idx = all
        .iter()
        .enumerate()
        .filter(|(_, e)| e.feasible && e.score.is_finite())
        .max_by(|a, b| {
            // Finals outrank search evaluations (they are what the tune reports).
            (a.1.phase == "final", a.1.score)
                .partial_cmp(&(b.1.phase == "final", b.1.score))
                .unwrap_or(std::cmp::Ordering::Equal)
        })
        .map(|(i, _)| i);
    let names: Vec<String> = spec.params.keys().cloned().collect();
    let landscape = if names.len() == 1 {
        let p = &names[0];
        let x = |e: &Eval| e.params.iter().find(|(k, _)| k == p).map_or(f64::NAN, |v| v.1);
        let group = |name: &str, mark: Mark, keep: &dyn Fn(&Eval) -> bool| Scatter {
            name: name.into(),
            mark,
            points: all.iter().filter(|e| keep(e)).map(|e| (x(e), value(e))).collect(),
            tips: all.iter().filter(|e| keep(e)).map(tip).collect(),
        };
        let groups = vec![
            group(&format!("search ({})", accuracy(&spec.accuracy)), Mark::Dot(40, 120, 200), &|e| e.phase == "search"),
            group(&format!("finalists at {}", accuracy(&spec.final_accuracy)), Mark::Diamond(200, 30, 30), &|e| e.phase == "final"),
            Scatter {
                name: "best so far".into(),
                mark: Mark::Ring(0, 0, 0),
                points: best_idx.map(|i| vec![(x(&all[i]), value(&all[i]))]).unwrap_or_default(),
                tips: best_idx.map(|i| vec![format!("best so far: {}", tip(&all[i]))]).unwrap_or_default(),
            },
        ];
        scatter_svg(&format!("{y_label} against {p}"), p, y_label, &groups, (900, 520)).ok()
    } else {
        // Several parameters: the objective in the order evaluated.
        let groups = vec![Scatter {
            name: "evaluations".into(),
            mark: Mark::Dot(40, 120, 200),
            points: all.iter().map(|e| (e.index as f64, value(e))).collect(),
            tips: all.iter().map(tip).collect(),
        }];
        scatter_svg(&format!("{y_label} by evaluation ({} parameters)", names.len()), "evaluation", y_label, &groups, (900, 480)).ok()
    };
    let front_plot = if pareto && metrics.len() >= 2 {
        let (a, b) = (axis(metrics[0]), axis(metrics[1]));
        let pts: Vec<Vec<f64>> = all
            .iter()
            .map(|e| metrics.iter().map(|m| e.objectives[axis(*m).0].as_f64().unwrap_or(f64::NAN)).collect())
            .collect();
        let ups: Vec<bool> = metrics.iter().map(|m| axis(*m).2).collect();
        let front = pareto_front(&pts, &ups);
        let group = |name: &str, mark: Mark, keep: &dyn Fn(usize) -> bool| Scatter {
            name: name.into(),
            mark,
            points: (0..all.len()).filter(|i| keep(*i)).map(|i| (pts[i][0], pts[i][1])).collect(),
            tips: (0..all.len()).filter(|i| keep(*i)).map(|i| tip(&all[i])).collect(),
        };
        let groups = vec![
            group("dominated", Mark::Dot(170, 170, 170), &|i| !front.contains(&i)),
            group("Pareto front", Mark::Diamond(200, 30, 30), &|i| front.contains(&i)),
        ];
        scatter_svg(&format!("Pareto front: {} against {}", b.1, a.1), a.1, b.1, &groups, (900, 520))
            .ok()
            .map(|s| (s, front.len()))
    } else {
        None
    };
    let best_json = result.map(|r| r["best"].clone()).filter(|b| !b.is_null());
    let finals: Vec<&Eval> = all.iter().filter(|e| e.phase == "final").collect();
    html! {
        p { (all.len()) " evaluations stored; " (finals.len()) " at the final accuracy. Objective: "
            code { (serde_json::to_string(&spec.objective).unwrap_or_default()) } "." }
        @if let Some(i) = best_idx {
            p class="best" { strong { "Best so far: " } (tip(&all[i])) }
        }
        @if let Some(b) = &best_json {
            p class="best" { strong { "Result: " } code { (b["params"]) } " · objectives " code { (b["objectives"]) }
                @if let Some(iv) = b["interval"].as_array() { " · score interval " code { (Value::Array(iv.clone())) } }
                @if let Some(h) = result.and_then(|r| r["ranking_held"].as_bool()) { " · ranking held: " (h) }
            }
        }
        @if let Some(s) = &landscape { figure class="tune" { (svg(s)) } } @else { p class="muted" { "No evaluations stored yet." } }
        @if let Some((s, n)) = &front_plot {
            figure class="tune" { (svg(s)) figcaption { (n) " of " (all.len()) " evaluations on the front" } }
        }
        @if !finals.is_empty() {
            table class="figures" {
                caption { "Finalists at the final accuracy" }
                thead { tr { th { "#" } th { "parameters" } @for m in &metrics { th { (axis(*m).1) } } th { "score" } } }
                tbody {
                    @for e in &finals {
                        tr {
                            td class="num" { (e.index) }
                            td class="mono small" { @for (k, v) in &e.params { (k) " = " (format!("{v:.4}")) " " } }
                            @for m in &metrics { td class="num" { (e.objectives[axis(*m).0].as_f64().map_or("–".into(), |v| format!("{v:.4}"))) } }
                            td class="num" { (format!("{:.4}", e.score)) }
                        }
                    }
                }
            }
        }
    }
}
