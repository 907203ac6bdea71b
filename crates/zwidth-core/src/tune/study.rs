//! `zwidth bench tune`: the figures issue 5 asks for, on the seed device
//! (the 2018 paper's simulated device at 1 kHz, `examples/seed_2018.json`).
//!
//! 1. Butterworth cutoff 10…499 Hz for K-width: the tuner (auto, a coarse
//!    grid then Brent) against a brute-force scan in 1 Hz steps (490 maps),
//!    both at the same accuracy, so the only difference is the search.
//! 2. Levant gains (μ1, μ2 with the paper's C estimate) tuned for K-width
//!    against the `hba_sc` rule gains on the same scene, and how long that
//!    tune takes at `standard` accuracy.

use serde::Serialize;
use std::collections::BTreeMap;
use std::time::Instant;

use super::{Bounds, Metric, Objective, SolverKind, TuneSpec};
use crate::error::SpecError;
use crate::zwidth::compare::{estimate_c, seed_2018_scene};
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::map;
use crate::zwidth::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
use crate::zwidth::sweep::Scale;

#[derive(Debug, Clone, Serialize)]
pub struct CutoffStudy {
    pub accuracy: String,
    pub scan_evaluations: usize,
    pub scan_best_cutoff_hz: f64,
    pub scan_best_k_width: f64,
    pub scan_s: f64,
    pub tune_evaluations: usize,
    pub tune_cutoff_hz: f64,
    pub tune_k_width: f64,
    pub tune_s: f64,
    /// (tune − scan)/scan, %.
    pub k_width_gap_pct: f64,
    /// tune evaluations / scan evaluations.
    pub evaluation_ratio: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct LevantStudy {
    pub accuracy: String,
    pub lipschitz: f64,
    pub rule_k_width: f64,
    pub rule_gains: String,
    pub tuned_params: BTreeMap<String, f64>,
    pub tuned_k_width: f64,
    pub tuned_gains: String,
    pub tune_evaluations: usize,
    pub tune_s: f64,
}

#[derive(Debug, Clone, Serialize)]
pub struct Study {
    pub cutoff: CutoffStudy,
    pub levant: LevantStudy,
}

fn seed_with(estimator: &str) -> Result<SceneSpec, SpecError> {
    let mut s = seed_2018_scene();
    s.estimator = serde_json::from_str(estimator)
        .map_err(|e| SpecError::new("estimator", estimator, e.to_string()))?;
    Ok(s)
}

fn tune_spec(
    scene: SceneSpec,
    params: &[(&str, f64, f64, Scale, Option<f64>)],
    solver: SolverKind,
    evals: usize,
    acc: Preset,
) -> TuneSpec {
    TuneSpec {
        scene,
        params: params
            .iter()
            .map(|&(n, min, max, scale, step)| {
                (
                    n.to_string(),
                    Bounds {
                        min,
                        max,
                        scale,
                        step,
                    },
                )
            })
            .collect(),
        objective: Objective::Single(Metric::KWidth),
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::RobustBisect,
        accuracy: Accuracy::Preset(acc),
        final_accuracy: Accuracy::Preset(acc),
        finalists: 3,
        // The study compares searches: one map per finalist.
        replicates: 1,
        solver,
        seed: 0,
        max_evaluations: evals,
        constraint: None,
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
    }
}

/// The Butterworth study at `acc` (`scan_points` = 490 for 1 Hz steps).
pub fn cutoff(acc: Preset, scan_points: usize) -> Result<CutoffStudy, SpecError> {
    let scene = seed_with(r#"{"kind":"butterworth","cutoff_hz":100,"order":2}"#)?;
    cutoff_on(scene, acc, scan_points)
}

/// The Butterworth study on `scene` (its estimator a Butterworth filter).
fn cutoff_on(scene: SceneSpec, acc: Preset, scan_points: usize) -> Result<CutoffStudy, SpecError> {
    // Whole hertz for both: the scan's resolution.
    let p = [("cutoff_hz", 10.0, 499.0, Scale::Linear, Some(1.0))];
    let t = Instant::now();
    let scan = tune_spec(scene.clone(), &p, SolverKind::Grid, scan_points, acc)
        .validate()?
        .run(None)?;
    let scan_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let tuned = tune_spec(scene, &p, SolverKind::Auto, scan_points / 5, acc)
        .validate()?
        .run(None)?;
    let tune_s = t.elapsed().as_secs_f64();
    let k = |r: &super::TuneResult| r.best.objectives["k_width"].unwrap_or(0.0);
    Ok(CutoffStudy {
        accuracy: format!("{acc:?}").to_lowercase(),
        scan_evaluations: scan.evaluations,
        scan_best_cutoff_hz: scan.best.params["cutoff_hz"],
        scan_best_k_width: k(&scan),
        scan_s,
        tune_evaluations: tuned.evaluations,
        tune_cutoff_hz: tuned.best.params["cutoff_hz"],
        tune_k_width: k(&tuned),
        tune_s,
        k_width_gap_pct: 100.0 * (k(&tuned) - k(&scan)) / k(&scan).max(1e-300),
        evaluation_ratio: tuned.evaluations as f64 / scan.evaluations.max(1) as f64,
    })
}

/// The Levant study at `acc` with at most `evals` evaluations.
pub fn levant(acc: Preset, evals: usize) -> Result<LevantStudy, SpecError> {
    let c = estimate_c(&seed_2018_scene())?.estimate.lipschitz;
    let rule = seed_with(&format!(
        r#"{{"kind":"levant","rule":"hba_sc","lipschitz":{c}}}"#
    ))?;
    let rule_map = map(&MapSpec {
        scene: rule.clone(),
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::RobustBisect,
        accuracy: Accuracy::Preset(acc),
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    })?;
    let gains = |s: &SceneSpec| match &s.estimator.kind {
        crate::estimators::EstimatorKind::Levant(l) => l
            .gains()
            .map(|g| g.report().to_string())
            .unwrap_or_default(),
        _ => String::new(),
    };
    let t = Instant::now();
    let p = [
        ("mu1", 1.0, 40.0, Scale::Log, None),
        ("mu2", 0.5, 60.0, Scale::Log, None),
    ];
    let tuned = tune_spec(rule.clone(), &p, SolverKind::Auto, evals, acc)
        .validate()?
        .run(None)?;
    let tune_s = t.elapsed().as_secs_f64();
    Ok(LevantStudy {
        accuracy: format!("{acc:?}").to_lowercase(),
        lipschitz: c,
        rule_k_width: rule_map.k_width,
        rule_gains: gains(&rule),
        tuned_params: tuned.best.params.clone(),
        tuned_k_width: tuned.best.objectives["k_width"].unwrap_or(0.0),
        tuned_gains: tuned.best.gains.clone().unwrap_or_default(),
        tune_evaluations: tuned.evaluations,
        tune_s,
    })
}

impl Study {
    pub fn table(&self) -> String {
        let c = &self.cutoff;
        let l = &self.levant;
        format!(
            "Butterworth cutoff for K-width on the seed device ({} accuracy, robust bisection):\n\
             \x20 brute-force scan, 1 Hz steps: {} maps, best {:.0} Hz -> K-width {:.4e} N/m ({:.1} s)\n\
             \x20 tuner (auto):                 {} maps, best {:.2} Hz -> K-width {:.4e} N/m ({:.1} s)\n\
             \x20 gap {:+.2} %, evaluations {:.3} of the scan's\n\
             Levant gains for K-width on the seed device ({} accuracy), C = {:.3} m/s²:\n\
             \x20 rule hba_sc: K-width {:.4e} N/m ({})\n\
             \x20 tuned {}: K-width {:.4e} N/m ({}); {} maps in {:.1} s\n",
            c.accuracy, c.scan_evaluations, c.scan_best_cutoff_hz, c.scan_best_k_width, c.scan_s,
            c.tune_evaluations, c.tune_cutoff_hz, c.tune_k_width, c.tune_s,
            c.k_width_gap_pct, c.evaluation_ratio,
            l.accuracy, l.lipschitz, l.rule_k_width, l.rule_gains,
            l.tuned_params.iter().map(|(n, x)| format!("{n} = {x:.3}")).collect::<Vec<_>>().join(", "),
            l.tuned_k_width, l.tuned_gains, l.tune_evaluations, l.tune_s,
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_cutoff_study_reports_its_gap_and_ratio_from_its_own_maps() {
        // A linear scene (analytic engine: cheap, deterministic). Scan of 5
        // points (10, 132.25, …, 499 Hz); the tuner gets 5/5 = 1 map, the
        // first of its coarse grid (u = 0: 10 Hz). Gap and ratio by their
        // definitions, (tune − scan)/scan in % and 1/5.
        let scene: SceneSpec = serde_json::from_value(serde_json::json!({
            "device": {"coulomb": 0, "quantization": 0},
            "loop": {"sample_hz": 1000, "render_hz": 1000},
            "estimator": {"kind": "butterworth", "cutoff_hz": 100, "order": 2}
        }))
        .unwrap();
        let c = cutoff_on(scene, Preset::Draft, 5).unwrap();
        assert_eq!((c.scan_evaluations, c.tune_evaluations), (5, 1));
        assert_eq!(c.tune_cutoff_hz, 10.0);
        assert!(c.scan_best_k_width > c.tune_k_width);
        let gap = 100.0 * (c.tune_k_width - c.scan_best_k_width) / c.scan_best_k_width;
        assert_eq!(c.k_width_gap_pct, gap);
        assert!(gap < 0.0);
        assert_eq!(c.evaluation_ratio, 0.2);
        assert_eq!(c.accuracy, "draft");
    }
}
