//! What a map will cost before it runs: damping columns, stiffness steps,
//! trials, stored rows and bytes, from the search's own arithmetic. Every
//! request is checked against the limits below when it is validated, so an
//! accepted request never builds an unbounded range or runs without end;
//! a run that overshoots its estimate by a wide margin is stopped (see
//! [`Cost::trial_limit`]).

use serde::Serialize;

use super::settings::{MapSpec, Resolved, SearchKind};
use crate::error::SpecError;

/// Most damping values (B columns) one map visits.
pub const MAX_B_COLUMNS: u64 = 2_000;
/// Most stiffness steps (`k_max / accuracy.k_step`) a trace or grid walks.
pub const MAX_K_STEPS: u64 = 100_000;
/// Largest `k_max / accuracy.k_step` for any search (the first K tried is
/// one step; a bisection brackets from there by doubling).
pub const MAX_K_RATIO: f64 = 1e12;
/// Finest relative K resolution a bisection may ask for (f64 has ~1e-16;
/// below 1e-6 each halving buys nothing a haptic device can show).
pub const MIN_K_REL_TOL: f64 = 1e-6;
/// Most trials one experiment may plan (each is a stored row).
pub const MAX_TRIALS: u64 = 2_000_000;
/// Bytes one stored trial takes, measured: 10 000 trial rows of the
/// `trials` table with its primary-key index, 229 B each (docs/service.md).
pub const BYTES_PER_TRIAL: u64 = 230;

/// The planned work of one map or a whole experiment.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct Cost {
    /// Maps (Z-width searches) the experiment runs.
    pub maps: u64,
    /// Damping values searched, over all maps.
    pub b_columns: u64,
    /// Trials expected at most, over all maps (a bisection's count is a
    /// bound; a trace's assumes a boundary that falls with B).
    pub trials: u64,
    /// Rows stored: one per trial.
    pub stored_rows: u64,
    /// Bytes those rows take in the database (estimate).
    pub stored_bytes: u64,
}

impl Cost {
    fn of_trials(b_columns: u64, trials: u64) -> Self {
        Self {
            maps: 1,
            b_columns,
            trials,
            stored_rows: trials,
            stored_bytes: trials.saturating_mul(BYTES_PER_TRIAL),
        }
    }

    /// `n` copies of this work (a tune's evaluations, a compare's estimators).
    pub fn times(self, n: u64) -> Self {
        Self {
            maps: self.maps.saturating_mul(n),
            b_columns: self.b_columns.saturating_mul(n),
            trials: self.trials.saturating_mul(n),
            stored_rows: self.stored_rows.saturating_mul(n),
            stored_bytes: self.stored_bytes.saturating_mul(n),
        }
    }

    pub fn plus(self, o: Self) -> Self {
        Self {
            maps: self.maps.saturating_add(o.maps),
            b_columns: self.b_columns.saturating_add(o.b_columns),
            trials: self.trials.saturating_add(o.trials),
            stored_rows: self.stored_rows.saturating_add(o.stored_rows),
            stored_bytes: self.stored_bytes.saturating_add(o.stored_bytes),
        }
    }

    /// Refuse a plan over [`MAX_TRIALS`], naming `field`.
    pub fn check(self, field: &str) -> Result<Self, SpecError> {
        if self.trials > MAX_TRIALS {
            return Err(SpecError::new(
                field,
                format!("{} trials planned", self.trials),
                format!(
                    "an experiment may plan at most {MAX_TRIALS} trials (~{} MB stored): use fewer damping values (b, b_max, accuracy.b_step), a coarser accuracy, or fewer maps",
                    MAX_TRIALS * BYTES_PER_TRIAL / 1_000_000
                ),
            ));
        }
        Ok(self)
    }

    /// Trials after which a run is stopped as runaway: four times the
    /// estimate, plus slack for tiny plans.
    pub fn trial_limit(self) -> u64 {
        self.trials.saturating_mul(4).saturating_add(1_000)
    }
}

/// Trials one bisection at one B may take: bracketing by doubling from
/// `k_step` up to `k_max` (or halving down ten times), then halving the
/// bracket until it is within `k_rel_tol`.
fn bisect_trials(res: &Resolved, k_max: f64, robust: bool) -> u64 {
    // k_max / k_step ≤ MAX_K_RATIO (checked): at most ~40 doublings.
    let up = (k_max / res.k_step).log2().max(0.0).ceil() as u64 + 1;
    let bracket = up.max(11) + 1;
    let halvings = (1.0 / res.k_rel_tol).log2().ceil() as u64 + 1;
    // Robust: at most 8 rounds of 5 checks below and a new bisection.
    let checks = if robust { 8 * (5 + halvings) } else { 0 };
    bracket + halvings + checks
}

/// The cost of one map, checked against the per-map limits. `exact` is
/// true when the analytic engine solves the boundary per B directly.
pub fn of_map(spec: &MapSpec, res: &Resolved, exact: bool) -> Result<Cost, SpecError> {
    let b_columns = match &spec.b {
        Some(bs) => {
            let n = bs.len() as u64;
            if n > MAX_B_COLUMNS {
                return Err(SpecError::new(
                    "b",
                    format!("{n} values"),
                    format!("give at most {MAX_B_COLUMNS} damping values"),
                ));
            }
            n
        }
        None => {
            // As the search builds it: 0, b_step, … while b <= b_max + 1e-9.
            let n = ((spec.b_max + 1e-9) / res.b_step).floor();
            if n.is_nan() || n >= MAX_B_COLUMNS as f64 {
                let (field, value) = if spec.b_max > 1000.0 {
                    ("b_max", spec.b_max)
                } else {
                    ("accuracy.b_step", res.b_step)
                };
                return Err(SpecError::new(
                    field,
                    value,
                    format!(
                        "b_max / accuracy.b_step = {n:.3e} damping columns; at most {MAX_B_COLUMNS}: lower b_max or raise accuracy.b_step"
                    ),
                ));
            }
            n as u64 + 1
        }
    };
    if res.k_rel_tol < MIN_K_REL_TOL {
        return Err(SpecError::new(
            "accuracy.k_rel_tol",
            res.k_rel_tol,
            format!("must be {MIN_K_REL_TOL:e} to 0.5"),
        ));
    }
    let ratio = spec.k_max / res.k_step;
    if ratio.is_nan() || ratio > MAX_K_RATIO {
        return Err(SpecError::new(
            "accuracy.k_step",
            res.k_step,
            format!("k_max / accuracy.k_step = {ratio:.3e}; at most {MAX_K_RATIO:e}: raise accuracy.k_step"),
        ));
    }
    let k_steps = ratio.ceil();
    let walks_k = matches!(spec.search, SearchKind::Trace | SearchKind::Grid) && !exact;
    if walks_k && (k_steps.is_nan() || k_steps > MAX_K_STEPS as f64) {
        return Err(SpecError::new(
            "accuracy.k_step",
            res.k_step,
            format!(
                "k_max / accuracy.k_step = {k_steps:.3e} stiffness steps; a {} walks at most {MAX_K_STEPS}: raise accuracy.k_step or lower k_max",
                spec.search.name()
            ),
        ));
    }
    let k_steps = k_steps as u64;
    let trials = if exact {
        b_columns
    } else {
        match spec.search {
            SearchKind::Bisect | SearchKind::RobustBisect => b_columns.saturating_mul(
                bisect_trials(res, spec.k_max, spec.search == SearchKind::RobustBisect),
            ),
            // Automatic B (0 up, 2011 paper §2.4): up the boundary once,
            // then a step or two per B. A given list may jump up and down
            // the whole K range between columns.
            SearchKind::Trace if spec.b.is_none() => 2 * k_steps + 3 * b_columns,
            SearchKind::Trace => b_columns.saturating_mul(k_steps + 2),
            // At most the budget of a column's posterior (`psi_search.rs`).
            SearchKind::Psi => b_columns.saturating_mul(super::psi_search::BUDGET as u64),
            SearchKind::Grid => {
                let nb = if spec.b.is_some() {
                    b_columns
                } else {
                    b_columns.min(60)
                };
                nb.saturating_mul(k_steps.clamp(1, 60))
            }
        }
    };
    Cost::of_trials(b_columns, trials).check("accuracy")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::settings::{Accuracy, Criterion, Method, SearchKind};

    #[test]
    fn at_most_max_b_columns_damping_values() {
        let spec = |n: usize| MapSpec {
            scene: crate::zwidth::scene::SceneSpec::default(),
            method: Method::Analytic,
            criterion: Criterion::Stability,
            search: SearchKind::Bisect,
            accuracy: Accuracy::default(),
            b: Some((0..n).map(|i| i as f64 * 0.01).collect()),
            b_max: 1000.0,
            k_max: 1e7,
            prior: None,
        };
        let sc = spec(1).scene.validate().unwrap();
        let res = Accuracy::default().resolve(&sc).unwrap();
        let n = MAX_B_COLUMNS as usize;
        assert_eq!(
            of_map(&spec(n), &res, true).unwrap().b_columns,
            MAX_B_COLUMNS
        );
        assert_eq!(of_map(&spec(n + 1), &res, true).unwrap_err().field, "b");
    }

    /// The 2018 device without friction and quantization, single rate, one
    /// search over K (k_step 1000 N/m, k_rel_tol 0.01, draft).
    fn linear(search: SearchKind, b: Option<Vec<f64>>, b_max: f64, k_max: f64) -> MapSpec {
        MapSpec {
            scene: crate::zwidth::scene::SceneSpec::from_json(
                r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
            )
            .unwrap(),
            method: Method::Auto,
            criterion: Criterion::Impedance,
            search,
            accuracy: serde_json::from_str(
                r#"{"preset":"draft","k_step":1000,"k_rel_tol":0.01,"b_step":10}"#,
            )
            .unwrap(),
            b,
            b_max,
            k_max,
            prior: None,
        }
    }

    fn trials(search: SearchKind, k_max: f64) -> u64 {
        crate::zwidth::search::validate(&linear(search, Some(vec![0.0]), 1000.0, k_max))
            .unwrap()
            .trials
    }

    #[test]
    fn a_bisection_is_estimated_by_its_own_loop_bounds() {
        // One B column, k_max = 1024 k_step, k_rel_tol = 0.01 (search.rs):
        // bracketing doubles from k_step: log2(1024) + 1 = 11 tries (at least
        // the 11 of halving down ten times), plus one; the bisection halves a
        // bracket of width ≤ hi/2 until ≤ 0.01·hi: ceil(log2(100)) + 1 = 8.
        // Total 12 + 8 = 20. Robust: 8 rounds of 5 checks and 8 halvings more.
        assert_eq!(trials(SearchKind::Bisect, 1_024_000.0), 20);
        // k_max = 4096 k_step: 13 doublings (more than the 11 halvings), + 1, + 8.
        assert_eq!(trials(SearchKind::Bisect, 4_096_000.0), 22);
        assert_eq!(
            trials(SearchKind::RobustBisect, 1_024_000.0),
            20 + 8 * (5 + 8)
        );
        // A grid walks min(k_max / k_step, 60) stiffness values per column.
        assert_eq!(trials(SearchKind::Grid, 1_024_000.0), 60);
        // A trace over a given list may walk every K step at every column.
        assert_eq!(trials(SearchKind::Trace, 1_024_000.0), 1024 + 2);
    }

    #[test]
    fn the_automatic_b_range_is_counted_as_the_search_builds_it() {
        // B = 0, 10, …, while B ≤ b_max: 11 columns to 100, 10 to 95.
        let cols = |b_max: f64| {
            crate::zwidth::search::validate(&linear(SearchKind::Bisect, None, b_max, 1e6))
                .unwrap()
                .b_columns
        };
        assert_eq!(cols(100.0), 11);
        assert_eq!(cols(95.0), 10);
        assert_eq!(cols(9.0), 1);
    }

    #[test]
    fn only_searches_that_walk_k_are_limited_in_k_steps() {
        // k_max / k_step = 10·MAX_K_STEPS: a bisection halves its way there
        // (allowed), a grid or trace would walk every step (refused, naming
        // the field).
        let k_max = 10.0 * MAX_K_STEPS as f64 * 1000.0;
        assert!(trials(SearchKind::Bisect, k_max) > 0);
        for search in [SearchKind::Grid, SearchKind::Trace] {
            let e =
                crate::zwidth::search::validate(&linear(search, Some(vec![0.0]), 1000.0, k_max))
                    .unwrap_err();
            assert_eq!(e.field, "accuracy.k_step");
            assert!(e.to_string().contains("stiffness steps"), "{e}");
        }
    }

    #[test]
    fn a_trace_over_the_automatic_b_range_walks_k_once_down_and_once_up() {
        // search.rs's trace: one fall from k_max and one rise, each at most
        // k_max / k_step steps, plus three trials a column: 2·1024 + 3·10.
        let c =
            crate::zwidth::search::validate(&linear(SearchKind::Trace, None, 95.0, 1_024_000.0))
                .unwrap();
        assert_eq!((c.b_columns, c.trials), (10, 2 * 1024 + 3 * 10));
        assert_eq!(c.stored_bytes, c.trials * BYTES_PER_TRIAL);
    }

    #[test]
    fn the_map_limits_hold_at_their_documented_values() {
        let sc = crate::zwidth::scene::SceneSpec::default()
            .validate()
            .unwrap();
        let res = Accuracy::default().resolve(&sc).unwrap();
        let map = |b_step: f64, b_max: f64, k_step: f64, k_max: f64, search: SearchKind| {
            let spec = MapSpec {
                search,
                b: None,
                b_max,
                k_max,
                ..linear(search, None, b_max, k_max)
            };
            let r = Resolved {
                b_step,
                k_step,
                ..res
            };
            of_map(&spec, &r, false)
        };
        let bis = SearchKind::Bisect;
        // b_max / b_step < MAX_B_COLUMNS = 2000 steps (cost.rs), plus B = 0.
        assert_eq!(map(10.0, 19_990.0, 1.0, 1e6, bis).unwrap().b_columns, 2000);
        // 2000 columns from B = 0.5 steps to 1000: the step is at fault …
        assert_eq!(
            map(0.5, 1000.0, 1.0, 1e6, bis).unwrap_err().field,
            "accuracy.b_step"
        );
        // … from 10 steps to 30 000, b_max is.
        assert_eq!(
            map(10.0, 30_000.0, 1.0, 1e6, bis).unwrap_err().field,
            "b_max"
        );
        // k_max / k_step at most MAX_K_RATIO = 1e12.
        assert!(map(10.0, 100.0, 1.0, 1e12, bis).is_ok());
        assert_eq!(
            map(10.0, 100.0, 1.0, 2e12, bis).unwrap_err().field,
            "accuracy.k_step"
        );
        assert_eq!(
            map(10.0, 100.0, 0.0, 1e6, bis).unwrap_err().field,
            "accuracy.k_step"
        );
        // A grid walks at most MAX_K_STEPS = 100 000 stiffness steps.
        let grid = SearchKind::Grid;
        assert!(map(10.0, 100.0, 1000.0, 1e8, grid).is_ok());
        assert_eq!(
            map(10.0, 100.0, 1000.0, 100_001_000.0, grid)
                .unwrap_err()
                .field,
            "accuracy.k_step"
        );
    }

    #[test]
    fn at_most_max_trials_and_a_runaway_stop_at_four_times_the_plan() {
        let c = |trials: u64| Cost {
            trials,
            ..Cost::default()
        };
        assert_eq!(c(MAX_TRIALS).check("f").unwrap(), c(2_000_000));
        let e = c(MAX_TRIALS + 1).check("f").unwrap_err();
        assert_eq!(e.field, "f");
        assert!(e.to_string().contains("2000001 trials planned"), "{e}");
        // The observer stops a run past 4 × its plan + 1000 (module docs).
        assert_eq!(c(10).trial_limit(), 1040);
        assert_eq!(c(0).trial_limit(), 1000);
        assert_eq!(c(u64::MAX).trial_limit(), u64::MAX);
        // Sums and multiples add field by field.
        let one = Cost::of_trials(3, 7);
        assert_eq!(
            one.times(2).plus(one),
            Cost {
                maps: 3,
                b_columns: 9,
                trials: 21,
                stored_rows: 21,
                stored_bytes: 21 * BYTES_PER_TRIAL
            }
        );
    }
}
