//! A comparison's text table, shaped like the 2018 paper's Table I: the
//! rows' widths and intervals, each pair's K-width order with its error
//! bound, the refinement's rounds, the tunable parameters and where C came
//! from.

use super::compare::{CompareResult, CompareRow};
use super::settings::Criterion;
use crate::estimators::EstimatorKind;

impl CompareResult {
    /// Shaped like the 2018 paper's Table I.
    pub fn table(&self) -> String {
        let w = 14;
        let mut s = format!("{:<28}", "");
        for r in &self.rows {
            s.push_str(&format!("{:>w$}", r.name));
        }
        s.push('\n');
        let mut row = |label: &str, f: &dyn Fn(&CompareRow) -> String| {
            s.push_str(&format!("{label:<28}"));
            for r in &self.rows {
                s.push_str(&format!("{:>w$}", f(r)));
            }
            s.push('\n');
        };
        row("K-width (N/m)", &|r| format!("{:.3e}", r.map.k_width));
        if self.rows.iter().any(|r| r.map.k_width_interval.is_some()) {
            row("  interval low", &|r| {
                r.map
                    .k_width_interval
                    .map_or("-".into(), |i| format!("{:.3e}", i[0]))
            });
            row("  interval high", &|r| {
                r.map
                    .k_width_interval
                    .map_or("-".into(), |i| format!("{:.3e}", i[1]))
            });
        }
        row("B-width (N·s/m)", &|r| format!("{:.1}", r.map.b_width));
        row("Max. fidelity error (N·s/m)", &|r| {
            r.map
                .max_fidelity_error
                .map(|f| format!("{f:.2}"))
                .unwrap_or("-".into())
        });
        row("Trials", &|r| r.map.trials.to_string());
        if let Some(p) = self.order.first() {
            // One bound for every line only when all lines share it: no row
            // refined and no pair called equal (whose bound is twice).
            let per_line =
                self.rows.iter().any(|r| r.refined.is_some()) || self.order.iter().any(|p| p.equal);
            if per_line {
                s.push_str("K-width order (resolved: the intervals do not overlap; equal: one interval of the resolution holds both; each with its error bound):\n");
            } else {
                s.push_str(&format!(
                    "K-width order (resolved: the intervals do not overlap, wrong with probability at most {:.0} %):\n",
                    100.0 * p.error_at_most
                ));
            }
            for p in &self.order {
                let mut verdict = if p.resolved {
                    "resolved".to_string()
                } else if p.equal {
                    "equal within the resolution".to_string()
                } else {
                    "not resolved (the intervals overlap)".to_string()
                };
                if per_line && (p.resolved || p.equal) {
                    verdict.push_str(&format!(
                        " (wrong with probability at most {:.0} %)",
                        100.0 * p.error_at_most
                    ));
                }
                s.push_str(&format!(
                    "  {:<12} > {:<12} {verdict}\n",
                    p.wider, p.narrower
                ));
            }
        }
        if let Some(r) = &self.resolution {
            s.push_str(&format!(
                "Refinement: {} of {} rounds run{}; every decided order at once wrong with probability at most {:.0} %\n",
                r.rounds_run,
                r.rounds,
                if r.budget_ended {
                    format!(
                        ", {} pair orders still open: the rounds are spent (--resolve-rounds)",
                        r.open_pairs
                    )
                } else if r.open_pairs > 0 {
                    format!(", {} pair orders still open (cancelled)", r.open_pairs)
                } else {
                    ", every pair order decided".to_string()
                },
                100.0 * r.joint_error_at_most
            ));
            for row in self.rows.iter().filter(|r| r.refined.is_some()) {
                if let Some(f) = row.refined {
                    s.push_str(&format!(
                        "  {:<12} refinement maps: {}, the last at K to {:.3} %, {:.2} % confidence, {} realizations a verdict at most\n",
                        row.name,
                        f.maps,
                        100.0 * f.k_rel_tol,
                        100.0 * f.confidence,
                        f.realizations
                    ));
                }
            }
        }
        match &self.tuned_for {
            Some(objective) => s.push_str(&format!(
                "Tunable parameters, each tuned for {objective} (argmin, draft search, finalists re-mapped):\n"
            )),
            None => s.push_str(
                "Tunable parameters (the 2018 paper's fixed values; `compare --tuned OBJECTIVE` tunes each first):\n",
            ),
        }
        for r in &self.rows {
            s.push_str(&format!("  {:<12} {}\n", r.name, r.parameters));
            if let Some(t) = &r.tuning {
                s.push_str(&format!(
                    "  {:<12} tuned over {} in {} maps, {:.1} s\n",
                    "", t.bounds, t.evaluations, t.elapsed_s
                ));
            }
            if let EstimatorKind::Levant(l) = &r.estimator.kind {
                if let Ok(g) = l.gains() {
                    s.push_str(&format!("  {:<12} {}\n", "", g.report()));
                }
            }
        }
        let e = &self.lipschitz;
        s.push_str(&format!(
            "C = {:.3} m/s² from a wall hit at K = {:.1} N/m, B = {:.2} N·s/m with {} (local quadratic fit over {} samples)\n",
            e.estimate.lipschitz,
            e.wall_k,
            e.wall_b,
            e.estimator.label(),
            2 * e.estimate.half_window + 1
        ));
        if let Some(r) = self.rows.first() {
            let criterion = match r.map.criterion {
                Criterion::Impedance => "impedance (Re Z ≥ 0 over the probe band)",
                Criterion::Stability => {
                    "stability (the wall hit's RMS below its threshold; eigenvalues on a linear scene)"
                }
                Criterion::StrictPassivity => "strict passivity (Colgate & Schenkel)",
            };
            s.push_str(&format!(
                "model: {}\ncriterion: {criterion}, {}\n",
                r.map.model, r.map.resolution
            ));
        }
        s.push_str(&format!("elapsed: {:.2} s\n", self.elapsed_s));
        s
    }
}
