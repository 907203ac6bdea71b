//! What a tune looks like: the objective against the parameter (every
//! evaluation; the finalists re-evaluated at the final accuracy marked; the
//! best ringed), and for two or more objectives the Pareto front over all
//! search evaluations. Drawn from the evaluations so far, so a running
//! tune's page and its finished SVG are the same picture.

use super::{metric_name, Evaluation, Metric, Objective, TuneResult};
use crate::plot::{scatter_svg, Mark, Scatter};

/// A metric on an axis, with its unit.
pub fn metric_axis(m: Metric) -> &'static str {
    match m {
        Metric::KWidth => "K-width (N/m)",
        Metric::BWidth => "B-width (N·s/m)",
        Metric::MaxFidelityError => "max fidelity error (N·s/m)",
        Metric::Area => "area (N/m · N·s/m)",
    }
}

/// An evaluation in words (its tooltip).
pub fn describe(e: &Evaluation) -> String {
    let params: Vec<String> = e
        .params
        .iter()
        .map(|(k, v)| format!("{k} = {v:.4}"))
        .collect();
    let objs: Vec<String> = [
        Metric::KWidth,
        Metric::BWidth,
        Metric::MaxFidelityError,
        Metric::Area,
    ]
    .iter()
    .filter_map(|&m| Some(format!("{} = {:.4}", metric_name(m), e.metrics.get(m)?)))
    .collect();
    // An infeasible evaluation's score is a stand-in far below every real
    // one (`run::infeasible_score`): not a number to read.
    let score = if e.feasible {
        format!("score {:.4}", e.score)
    } else {
        "infeasible".to_string()
    };
    format!(
        "#{} ({}): {}; {}; {score}",
        e.index,
        e.phase,
        params.join(", "),
        objs.join(", ")
    )
}

/// The evaluation the tune would report now: the best feasible final
/// one, else the best feasible search one (by score).
pub fn best_so_far(history: &[Evaluation]) -> Option<&Evaluation> {
    let best = |phase: &str| {
        history
            .iter()
            .filter(|e| e.phase == phase && e.feasible && e.score.is_finite())
            .max_by(|a, b| a.score.total_cmp(&b.score))
    };
    best("final").or_else(|| best("search"))
}

/// The objective as plotted: a single metric's value, else the score.
fn value(objective: &Objective, e: &Evaluation) -> f64 {
    match objective {
        Objective::Single(m) => e.metrics.get(*m).unwrap_or(f64::NAN),
        _ => e.score,
    }
}

/// One parameter: the objective against it, each evaluation a point
/// (search at `accuracy.0`, finalists at `accuracy.1` as diamonds, the best
/// ringed). Several: the objective against the evaluation's number.
pub fn landscape_svg(
    params: &[String],
    objective: &Objective,
    history: &[Evaluation],
    accuracy: (&str, &str),
) -> Result<String, String> {
    let y_label = match objective {
        Objective::Single(m) => metric_axis(*m),
        _ => "score (higher is better)",
    };
    let one = (params.len() == 1).then(|| params[0].as_str());
    let x = |e: &Evaluation| match one {
        Some(p) => e.params.get(p).copied().unwrap_or(f64::NAN),
        None => e.index as f64,
    };
    let group = |name: String, mark: Mark, keep: &dyn Fn(&Evaluation) -> bool| {
        let kept: Vec<&Evaluation> = history.iter().filter(|e| keep(e)).collect();
        Scatter {
            name,
            mark,
            points: kept.iter().map(|e| (x(e), value(objective, e))).collect(),
            tips: kept.iter().map(|e| describe(e)).collect(),
        }
    };
    let best = best_so_far(history);
    // Infeasible gains are left out: their scores stand far below every
    // feasible one and would flatten the axis; the legend counts them.
    let infeasible = history.iter().filter(|e| !e.feasible).count();
    let groups = vec![
        group(
            if infeasible > 0 {
                format!("search ({}; {infeasible} infeasible not drawn)", accuracy.0)
            } else {
                format!("search ({})", accuracy.0)
            },
            Mark::Dot(40, 120, 200),
            &|e| e.phase == "search" && e.feasible,
        ),
        group(
            format!("finalists ({})", accuracy.1),
            Mark::Diamond(200, 30, 30),
            &|e| e.phase == "final" && e.feasible,
        ),
        Scatter {
            name: "best".into(),
            mark: Mark::Ring(0, 0, 0),
            points: best
                .map(|e| vec![(x(e), value(objective, e))])
                .unwrap_or_default(),
            tips: best
                .map(|e| vec![format!("best: {}", describe(e))])
                .unwrap_or_default(),
        },
    ];
    match one {
        Some(p) => scatter_svg(
            &format!("{y_label} against {p}"),
            p,
            y_label,
            &groups,
            (900, 540),
        ),
        None => scatter_svg(
            &format!("{y_label} by evaluation ({} parameters)", params.len()),
            "evaluation",
            y_label,
            &groups,
            (900, 540),
        ),
    }
}

/// Two or more objectives: the first two metrics of every search
/// evaluation, the non-dominated ones (over all the metrics) highlighted.
/// Returns the SVG and the front's size.
pub fn pareto_svg(metrics: &[Metric], history: &[Evaluation]) -> Result<(String, usize), String> {
    let (Some(&mx), Some(&my)) = (metrics.first(), metrics.get(1)) else {
        return Err("a Pareto plot needs two metrics".into());
    };
    let front = super::run::pareto_front(history, metrics);
    let search: Vec<&Evaluation> = history.iter().filter(|e| e.phase == "search").collect();
    let group = |name: &str, mark: Mark, on_front: bool| {
        let kept: Vec<&&Evaluation> = search
            .iter()
            .filter(|e| front.contains(&e.index) == on_front)
            .collect();
        Scatter {
            name: name.into(),
            mark,
            points: kept
                .iter()
                .map(|e| {
                    (
                        e.metrics.get(mx).unwrap_or(f64::NAN),
                        e.metrics.get(my).unwrap_or(f64::NAN),
                    )
                })
                .collect(),
            tips: kept.iter().map(|e| describe(e)).collect(),
        }
    };
    let svg = scatter_svg(
        &format!(
            "Pareto front: {} against {}",
            metric_axis(my),
            metric_axis(mx)
        ),
        metric_axis(mx),
        metric_axis(my),
        &[
            group("dominated", Mark::Dot(150, 150, 150), false),
            group("Pareto front", Mark::Diamond(200, 30, 30), true),
        ],
        (900, 540),
    )?;
    Ok((svg, front.len()))
}

impl TuneResult {
    /// The objective against the parameter, every evaluation, the
    /// finalists marked (`landscape_svg`); with a Pareto objective,
    /// the front over all search evaluations (`pareto_svg`).
    pub fn svg(&self) -> Result<String, String> {
        if let Objective::Pareto(ms) = &self.objective {
            return pareto_svg(ms, &self.history).map(|(s, _)| s);
        }
        let params: Vec<String> = self.best.params.keys().cloned().collect();
        landscape_svg(&params, &self.objective, &self.history, ("search", "final"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::tune::Metrics;

    fn eval(index: usize, phase: &str, hz: f64, k: f64, fid: f64, feasible: bool) -> Evaluation {
        Evaluation {
            index,
            phase: phase.into(),
            params: [("cutoff_hz".to_string(), hz)].into(),
            objectives: Default::default(),
            metrics: Metrics {
                k_width: k,
                b_width: 1.0,
                max_fidelity_error: Some(fid),
                area: 1.0,
                k_width_interval: None,
                b_width_interval: None,
            },
            score: k,
            feasible,
            cached: false,
            trials: 1,
            elapsed_s: 0.0,
            replicate: 0,
        }
    }

    #[test]
    fn the_landscape_draws_each_evaluation_once_and_rings_the_best_final() {
        let h = vec![
            eval(0, "search", 100.0, 10.0, 1.0, true),
            eval(1, "search", 200.0, 30.0, 2.0, true),
            eval(2, "search", 300.0, 50.0, 2.0, false),
            eval(3, "final", 200.0, 25.0, 2.0, true),
            eval(4, "final", 100.0, 12.0, 2.0, true),
        ];
        // The best is the best feasible final (25 at 200 Hz), not the
        // larger search score (30) nor the infeasible 50.
        assert_eq!(best_so_far(&h).map(|e| e.index), Some(3));
        assert_eq!(best_so_far(&h[..3]).map(|e| e.index), Some(1));
        assert_eq!(best_so_far(&h[2..3]).map(|e| e.index), None);
        let svg = landscape_svg(
            &["cutoff_hz".into()],
            &Objective::Single(Metric::KWidth),
            &h,
            ("draft", "standard"),
        )
        .unwrap();
        // Every feasible evaluation once, plus the best's ring; the
        // infeasible one (its score a stand-in) is counted, not drawn.
        assert_eq!(svg.matches("class=\"pt\"").count(), h.len() - 1 + 1);
        assert!(svg.contains("1 infeasible not drawn"));
        assert!(svg.contains("K-width (N/m) against cutoff_hz"));
        assert!(
            svg.contains("finalists (standard)")
                && svg.contains("search (draft; 1 infeasible not drawn)")
        );
        assert!(svg.contains("<title>best: #3 (final): cutoff_hz = 200.0000;"));
        assert!(
            describe(&h[2]).ends_with("; infeasible"),
            "{}",
            describe(&h[2])
        );
        assert!(describe(&h[1]).ends_with("; score 30.0000"));
        // Two parameters: against the evaluation's number.
        let svg = landscape_svg(
            &["a".into(), "b".into()],
            &Objective::Weighted([(Metric::KWidth, 1.0)].into()),
            &h,
            ("draft", "draft"),
        )
        .unwrap();
        assert!(svg.contains("score (higher is better) by evaluation (2 parameters)"));
    }

    #[test]
    fn the_pareto_plot_highlights_the_non_dominated_search_evaluations() {
        // K-width up, fidelity error down: (10, 1) dominates (10, 3);
        // (20, 2) is on the front too; the final is not drawn.
        let h = vec![
            eval(0, "search", 1.0, 10.0, 1.0, true),
            eval(1, "search", 2.0, 20.0, 2.0, true),
            eval(2, "search", 3.0, 10.0, 3.0, true),
            eval(3, "final", 2.0, 99.0, 0.1, true),
        ];
        let (svg, n) = pareto_svg(&[Metric::KWidth, Metric::MaxFidelityError], &h).unwrap();
        assert_eq!(n, 2);
        assert_eq!(svg.matches("class=\"pt\"").count(), 3);
        // Diamonds (paths) for the front, dots for the dominated.
        assert_eq!(svg.matches("<path class=\"pt\"").count(), 2);
        assert_eq!(svg.matches("<circle class=\"pt\"").count(), 1);
        assert!(pareto_svg(&[Metric::KWidth], &h).is_err());
    }
}
