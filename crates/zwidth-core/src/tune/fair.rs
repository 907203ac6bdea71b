//! A fair comparison: each of the 2018 paper's estimators tuned for one
//! objective before the comparison, as the paper did in simulation (§V:
//! "the parameters of each method were tuned … to maximize the Z-width"),
//! instead of the paper's fixed values taken over to another scene.
//!
//! What is tuned (the paper's tunable parameters, Table I): FDM + filter
//! the Butterworth cutoff (10 Hz to 0.499·f_s), AKF its q (1e2–1e9, log),
//! Levant μ1 and μ2 with the paper's C (1–40 and 0.5–60, log, as
//! `bench tune`); FOAW has none and keeps its fixed row. Each tune searches
//! at `draft` and re-maps its three finalists at the comparison's accuracy
//! (one map each: the comparison's own map then gives the row's interval).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Instant;

use super::{Bounds, Objective, SolverKind, TuneResult, TuneSpec};
use crate::error::SpecError;
use crate::estimators::{EstimatorKind, EstimatorSpec};
use crate::zwidth::compare::{self, CompareResult, RowTuning};
use crate::zwidth::cost::Cost;
use crate::zwidth::observer::Observer;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::settings::{Accuracy, Criterion, Method, Preset, SearchKind};
use crate::zwidth::sweep::Scale;

/// `"tuned": {"objective": "k_width", "max_evaluations": 24}` on a compare.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TunedCompare {
    /// What each estimator is tuned for: a metric or a weighted sum (not a
    /// Pareto front: a comparison needs one best per estimator).
    pub objective: Objective,
    /// Maps each estimator's search may make (1–200; default 24).
    #[serde(default = "d_evaluations")]
    pub max_evaluations: usize,
    /// Seeds the searches' designs: same seed, same result.
    #[serde(default)]
    pub seed: u64,
}

fn d_evaluations() -> usize {
    24
}

/// Most search maps per estimator in a tuned comparison.
pub const MAX_COMPARE_EVALUATIONS: usize = 200;

/// The parameters a comparison tunes for `estimator`, or None (nothing to tune).
pub fn tunable(estimator: &EstimatorSpec, sample_hz: f64) -> Option<BTreeMap<String, Bounds>> {
    let b = |min, max, scale| Bounds {
        min,
        max,
        scale,
        step: None,
    };
    let list = match &estimator.kind {
        EstimatorKind::Butterworth { .. } => {
            vec![("cutoff_hz", b(10.0, 0.499 * sample_hz, Scale::Linear))]
        }
        EstimatorKind::AdaptiveKalman { .. } | EstimatorKind::Kalman { .. } => {
            vec![("q", b(1e2, 1e9, Scale::Log))]
        }
        EstimatorKind::Levant(_) => vec![
            ("mu1", b(1.0, 40.0, Scale::Log)),
            ("mu2", b(0.5, 60.0, Scale::Log)),
        ],
        _ => return None,
    };
    Some(list.into_iter().map(|(n, b)| (n.to_string(), b)).collect())
}

fn objective_name(o: &Objective) -> String {
    serde_json::to_string(o)
        .unwrap_or_default()
        .trim_matches('"')
        .to_string()
}

impl TunedCompare {
    pub fn validate(&self) -> Result<(), SpecError> {
        if let Objective::Pareto(_) = self.objective {
            return Err(SpecError::new(
                "tuned.objective",
                objective_name(&self.objective),
                "must be one metric or a weighted sum: a comparison needs one best per estimator",
            ));
        }
        if !(1..=MAX_COMPARE_EVALUATIONS).contains(&self.max_evaluations) {
            return Err(SpecError::new(
                "tuned.max_evaluations",
                self.max_evaluations,
                format!("must be 1 to {MAX_COMPARE_EVALUATIONS}"),
            ));
        }
        Ok(())
    }

    /// The tune for one estimator of the comparison.
    fn spec(
        &self,
        scene: &SceneSpec,
        estimator: &EstimatorSpec,
        accuracy: &Accuracy,
        criterion: Criterion,
    ) -> Option<TuneSpec> {
        let params = tunable(estimator, scene.control.sample_hz)?;
        let m = compare::map_spec(scene.clone(), accuracy, criterion);
        Some(TuneSpec {
            scene: SceneSpec {
                estimator: estimator.clone(),
                ..scene.clone()
            },
            params,
            objective: self.objective.clone(),
            method: Method::Auto,
            criterion,
            search: SearchKind::RobustBisect,
            accuracy: Accuracy::Preset(Preset::Draft),
            final_accuracy: accuracy.clone(),
            finalists: 3,
            replicates: 1,
            solver: SolverKind::Auto,
            seed: self.seed,
            max_evaluations: self.max_evaluations,
            constraint: None,
            b: None,
            b_max: m.b_max,
            k_max: m.k_max,
        })
    }

    /// What the whole tuned comparison may cost: every tune, then the
    /// comparison's maps. (Validates the tunes with a stand-in C; the
    /// comparison estimates C from a wall hit when it runs.)
    pub fn cost(
        &self,
        scene: &SceneSpec,
        accuracy: &Accuracy,
        criterion: Criterion,
    ) -> Result<Cost, SpecError> {
        self.validate()?;
        let list = compare::paper_estimators(scene, 12.0);
        let one = crate::zwidth::search::validate(&compare::map_spec(
            scene.clone(),
            accuracy,
            criterion,
        ))?;
        let mut total = one.times(list.len() as u64);
        for (_, _, e) in &list {
            if let Some(spec) = self.spec(scene, e, accuracy, criterion) {
                total = total.plus(spec.validate()?.cost);
            }
        }
        Ok(total)
    }
}

/// Run `spec` with its own observer, forwarding a cancel from `parent` and
/// reporting the tune's progress to it as scope `scope` (the tune's
/// trials are not stored: a resumed comparison tunes again).
fn run_tune(
    spec: &TuneSpec,
    parent: Option<&Arc<Observer>>,
    scope: u32,
) -> Result<TuneResult, SpecError> {
    let tune = spec.validate()?;
    let Some(parent) = parent else {
        return tune.run(None);
    };
    let child = Arc::new(Observer::default());
    let done = AtomicBool::new(false);
    /// Ends the forwarding loop however the tune ends (a panic included:
    /// otherwise the scope would wait for the loop forever).
    struct Done<'a>(&'a AtomicBool);
    impl Drop for Done<'_> {
        fn drop(&mut self) {
            self.0.store(true, Ordering::Relaxed);
        }
    }
    std::thread::scope(|s| {
        s.spawn(|| {
            while !done.load(Ordering::Relaxed) {
                if parent.cancelled() {
                    child.cancel.store(true, Ordering::Relaxed);
                }
                parent.report(scope, child.fraction());
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
        });
        let _done = Done(&done);
        let r = tune.run(Some(child.clone()));
        parent.report(scope, 1.0);
        r
    })
}

fn describe(e: &EstimatorSpec, c: f64) -> String {
    match &e.kind {
        EstimatorKind::Butterworth { cutoff_hz, .. } => format!("ωc = {cutoff_hz:.1} Hz"),
        EstimatorKind::AdaptiveKalman { q, .. } | EstimatorKind::Kalman { q, .. } => {
            format!("q = {q:.3e}")
        }
        EstimatorKind::Levant(l) => match (l.mu1, l.mu2) {
            (Some(mu1), Some(mu2)) => format!(
                "α = {:.2} m/s², λ = {:.3} m^½/s (μ1 = {mu1:.3}, μ2 = {mu2:.3}, C = {c:.3})",
                mu1 * c,
                mu2 * c.sqrt()
            ),
            _ => e.label(),
        },
        _ => e.label(),
    }
}

/// Progress scopes of a tuned comparison of `list`: one per map (the
/// first maps and each refinement round's, `compare::compare_rows`), and
/// one per tune (the estimators with something to tune).
fn scopes(list: &[(String, String, EstimatorSpec)], sample_hz: f64, rounds: u32) -> usize {
    let tunes = list
        .iter()
        .filter(|(_, _, e)| tunable(e, sample_hz).is_some())
        .count();
    compare::scopes(list.len(), rounds) + tunes
}

/// The paper's estimators on `scene`, each tuned for `tuned.objective`
/// first, then mapped at `accuracy` side by side, the rows of unresolved
/// orders refined for up to `rounds` rounds. Progress: one scope per tune,
/// then one per map.
pub fn compare_tuned(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    tuned: &TunedCompare,
    rounds: u32,
    observer: Option<Arc<Observer>>,
) -> Result<CompareResult, SpecError> {
    tuned.validate()?;
    compare::check_rounds(rounds)?;
    let start = Instant::now();
    let c = compare::estimate_c(scene)?;
    let list = compare::paper_estimators(scene, c.estimate.lipschitz);
    if let Some(o) = &observer {
        o.set_scopes(scopes(&list, scene.control.sample_hz, rounds));
    }
    let mut rows = Vec::with_capacity(list.len());
    let mut tunings = Vec::with_capacity(list.len());
    for (i, (name, parameters, estimator)) in list.into_iter().enumerate() {
        match tuned.spec(scene, &estimator, accuracy, criterion) {
            Some(spec) => {
                let t = Instant::now();
                let r = run_tune(&spec, observer.as_ref(), 1000 + i as u32)?;
                let best = r.best.scene.estimator.clone();
                rows.push((
                    name,
                    describe(&best, c.estimate.lipschitz) + " (tuned)",
                    best,
                ));
                tunings.push(Some(RowTuning {
                    params: r.best.params.clone(),
                    bounds: spec
                        .params
                        .iter()
                        .map(|(n, b)| format!("{n}: {}–{}", b.min, b.max))
                        .collect::<Vec<_>>()
                        .join(", "),
                    evaluations: r.evaluations,
                    elapsed_s: t.elapsed().as_secs_f64(),
                }));
            }
            None => {
                rows.push((name, parameters + " (nothing to tune)", estimator));
                tunings.push(None);
            }
        }
    }
    let mut result = compare::compare_rows(scene, accuracy, criterion, c, rows, rounds, observer)?;
    for (row, tuning) in result.rows.iter_mut().zip(tunings) {
        row.tuning = tuning;
    }
    result.tuned_for = Some(objective_name(&tuned.objective));
    result.elapsed_s = start.elapsed().as_secs_f64();
    Ok(result)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_estimators_make_four_maps_and_three_tunes() {
        // FDM + Butterworth, AKF, FOAW, Levant (2018 paper §IV): FOAW has
        // nothing to tune, so 4 maps + 3 tunes = 7 progress scopes.
        let scene = compare::seed_2018_scene();
        let list = compare::paper_estimators(&scene, 1.1);
        assert_eq!(list.len(), 4);
        assert_eq!(scopes(&list, scene.control.sample_hz, 0), 7);
        // Each refinement round adds a scope per map: 4·(1 + 2) + 3.
        assert_eq!(scopes(&list, scene.control.sample_hz, 2), 15);
    }

    #[test]
    fn tuned_parameters_are_described_in_si_units() {
        let e = |j: &str| EstimatorSpec::from_json(j).unwrap();
        let bw = e(r#"{"kind":"butterworth","cutoff_hz":123.456}"#);
        assert_eq!(describe(&bw, 1.0), "ωc = 123.5 Hz");
        let k = e(r#"{"kind":"kalman","q":12345}"#);
        assert_eq!(describe(&k, 1.0), "q = 1.234e4");
        // α = μ1·C, λ = μ2·√C (the normalized gains, `LevantSpec::gains`), C = 4 m/s².
        let l = e(r#"{"kind":"levant","mu1":2,"mu2":3,"lipschitz":4}"#);
        assert_eq!(
            describe(&l, 4.0),
            "α = 8.00 m/s², λ = 6.000 m^½/s (μ1 = 2.000, μ2 = 3.000, C = 4.000)"
        );
        let fdm = e(r#"{"kind":"fdm"}"#);
        assert_eq!(describe(&fdm, 1.0), fdm.label());
    }

    #[test]
    fn a_tuned_compare_refuses_a_pareto_objective_and_budgets_outside_1_to_200() {
        let field = |j: &str| {
            serde_json::from_str::<TunedCompare>(j)
                .unwrap()
                .validate()
                .unwrap_err()
                .field
        };
        assert_eq!(
            field(r#"{"objective":{"pareto":["k_width","b_width"]}}"#),
            "tuned.objective"
        );
        assert_eq!(
            field(r#"{"objective":"k_width","max_evaluations":0}"#),
            "tuned.max_evaluations"
        );
        assert_eq!(
            field(r#"{"objective":"k_width","max_evaluations":201}"#),
            "tuned.max_evaluations"
        );
        let ok = r#"{"objective":"k_width","max_evaluations":200}"#;
        assert!(serde_json::from_str::<TunedCompare>(ok)
            .unwrap()
            .validate()
            .is_ok());
    }

    #[test]
    fn a_tuned_compare_defaults_to_24_maps_and_seed_0() {
        // The documented defaults (this struct's docs, the OpenAPI schema).
        let t: TunedCompare = serde_json::from_str(r#"{"objective":"k_width"}"#).unwrap();
        assert_eq!((t.max_evaluations, t.seed), (24, 0));
    }

    #[test]
    fn the_objective_is_named_as_the_user_wrote_it() {
        // `tuned_for` and the table say what was asked for: the metric's
        // JSON name, without quotes.
        let o: Objective = serde_json::from_str(r#""k_width""#).unwrap();
        assert_eq!(objective_name(&o), "k_width");
        let w: Objective = serde_json::from_str(r#"{"weighted":{"k_width":1}}"#).unwrap();
        assert_eq!(objective_name(&w), r#"{"weighted":{"k_width":1.0}}"#);
    }

    #[test]
    fn a_tuned_compare_costs_four_maps_and_three_tunes() {
        // The module doc: the four paper estimators mapped once each, and a
        // tune for each but FOAW (nothing to tune): its search budget plus
        // its finalists (3) mapped at the final accuracy.
        let mut scene = compare::seed_2018_scene();
        scene.device.coulomb = 0.0;
        scene.device.quantization = 0.0;
        let t: TunedCompare =
            serde_json::from_str(r#"{"objective":"k_width","max_evaluations":5}"#).unwrap();
        let c = t
            .cost(
                &scene,
                &Accuracy::Preset(Preset::Draft),
                Criterion::Impedance,
            )
            .unwrap();
        assert_eq!(c.maps, 4 + 3 * (5 + 3));
        // Each tune is of its own estimator, bounded below Nyquist.
        let bw = compare::paper_estimators(&scene, 1.0).remove(0).2;
        let s = t
            .spec(
                &scene,
                &bw,
                &Accuracy::Preset(Preset::Draft),
                Criterion::Impedance,
            )
            .unwrap();
        assert_eq!(s.scene.estimator, bw);
        assert_eq!(s.params["cutoff_hz"].max, 0.499 * 1000.0);
    }
}
