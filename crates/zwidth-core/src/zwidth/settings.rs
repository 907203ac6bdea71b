//! How a map is searched and how accurately: the knobs users trade speed
//! for accuracy with, and the spec of a whole map request.

use serde::{Deserialize, Serialize};

use super::hit::HitKnobs;
use super::probe::ProbeKnobs;
use super::scene::{Scene, SceneSpec};
use crate::error::SpecError;

/// Which engine answers.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// The cheapest engine exact for the scene: analytic when it is linear.
    #[default]
    Auto,
    Analytic,
    Time,
    Frequency,
}

/// What "renders the wall" means.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Criterion {
    /// Closed-loop stability (time domain: the wall-hit RMS test; analytic: eigenvalues).
    Stability,
    /// The 2018 paper's passivity test: Re Z(jω) ≥ 0 over the probe band.
    #[default]
    Impedance,
    /// Colgate & Schenkel's strict passivity over the whole band (analytic only).
    StrictPassivity,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SearchKind {
    /// The 2011 paper's §2.4 boundary trace.
    Trace,
    /// Bisection on K for each B.
    #[default]
    Bisect,
    /// Bisection, then K values below the result are checked too; a
    /// failure among them restarts the bisection below it. Where the
    /// verdict is not monotone in K (friction, quantization: a lucky pass
    /// high up), this finds the first failure from below, as stepping K up
    /// does (2011 paper §2.4), at a fraction of the trials.
    RobustBisect,
    /// A full K × B grid.
    Grid,
    /// Noisy scenes: every trial of a column informs one posterior of its
    /// boundary (the Psi method, `psi.rs`), each trial with realizations
    /// of its own; the next K is where a verdict narrows it most. Columns
    /// are first located coarsely, every fourth from nothing and the rest
    /// from their neighbours, then those that may set the K-width to the
    /// resolution. Where verdicts are not random draws (a scene without
    /// noise, replicated wall hits), bisection.
    Psi,
}

impl SearchKind {
    /// The name a spec gives it.
    pub fn name(self) -> &'static str {
        match self {
            SearchKind::Trace => "trace",
            SearchKind::Bisect => "bisect",
            SearchKind::RobustBisect => "robust_bisect",
            SearchKind::Grid => "grid",
            SearchKind::Psi => "psi",
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Preset {
    Draft,
    #[default]
    Standard,
    Reference,
}

/// Explicit knobs; any left out come from `preset`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AccuracyKnobs {
    #[serde(default)]
    pub preset: Preset,
    /// Wall hit: settle and measure times (s).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_s: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub measure_s: Option<f64>,
    /// Probe: periods averaged, steady-state tolerance, period limit.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub periods: Option<u32>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle_tol: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_periods: Option<u32>,
    /// Noisy scenes: most random-phase realizations per point.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realizations: Option<u32>,
    /// Bisection: relative K resolution.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_rel_tol: Option<f64>,
    /// Trace and grid: K step (N/m) and B step (N·s/m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_step: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b_step: Option<f64>,
}

/// `"draft"` or `{"preset":"draft","k_rel_tol":0.02,…}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(untagged)]
pub enum Accuracy {
    Preset(Preset),
    Knobs(AccuracyKnobs),
}

impl Default for Accuracy {
    fn default() -> Self {
        Accuracy::Preset(Preset::Standard)
    }
}

/// Every knob resolved against the scene.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resolved {
    pub preset: Preset,
    pub hit: HitKnobs,
    pub probe: ProbeKnobs,
    pub k_rel_tol: f64,
    pub k_step: f64,
    pub b_step: f64,
}

/// Most random-phase realizations a noisy-scene verdict may take.
pub const MAX_REALIZATIONS: u32 = 1000;
/// Most probe periods one noisy-scene trial may run, realizations × (1 +
/// periods): the same bound as `max_periods`, so no accepted trial runs
/// for hours.
pub const MAX_TRIAL_PERIODS: u64 = 100_000;

/// The 2011 paper's steps (§2.4).
pub const PAPER_K_STEP: f64 = 1488.24;
pub const PAPER_B_STEP: f64 = 14.88;

impl Accuracy {
    /// The accuracy of one trial where the trial defines the boundary
    /// (`SearchKind::Psi`: the boundary is where a trial fails with
    /// probability ½, so every preset runs the same trial and presets differ
    /// only in how narrowly they locate it): the standard preset's trial
    /// knobs, with those the spec names.
    pub fn standard_trial(&self) -> Accuracy {
        Accuracy::Knobs(AccuracyKnobs {
            preset: Preset::Standard,
            ..self.knobs()
        })
    }

    /// The accuracy as knobs: a preset's with none of them set.
    pub fn knobs(&self) -> AccuracyKnobs {
        match self {
            Accuracy::Preset(p) => AccuracyKnobs {
                preset: *p,
                ..Default::default()
            },
            Accuracy::Knobs(k) => k.clone(),
        }
    }

    pub fn resolve(&self, scene: &Scene) -> Result<Resolved, SpecError> {
        let knobs = self.knobs();
        let h = &scene.spec.hit;
        let p = &scene.spec.probe;
        // (time scale, periods ×, settle_tol, max_periods, k_rel_tol, step ÷)
        // (time scale, periods ×, settle_tol, max_periods, k_rel_tol, step ÷, realizations)
        let (scale, per, tol, maxp, krel, step_div, reals) = match knobs.preset {
            Preset::Draft => (0.25, 0.5, 1e-2, 40, 0.05, 0.5, 10),
            Preset::Standard => (1.0, 1.0, 1e-3, 150, 0.01, 1.0, 24),
            Preset::Reference => (2.0, 2.0, 1e-5, 600, 0.002, 2.0, 48),
        };
        let r = Resolved {
            preset: knobs.preset,
            hit: HitKnobs {
                settle_s: knobs.settle_s.unwrap_or(h.settle_s * scale),
                measure_s: knobs.measure_s.unwrap_or(h.measure_s * scale),
            },
            probe: ProbeKnobs {
                periods: knobs
                    .periods
                    .unwrap_or(((p.periods as f64 * per).round() as u32).max(1)),
                settle_tol: knobs.settle_tol.unwrap_or(tol),
                max_periods: knobs.max_periods.unwrap_or(maxp),
                realizations: knobs.realizations.unwrap_or(reals),
            },
            k_rel_tol: knobs.k_rel_tol.unwrap_or(krel),
            k_step: knobs.k_step.unwrap_or(PAPER_K_STEP / step_div),
            b_step: knobs.b_step.unwrap_or(PAPER_B_STEP / step_div),
        };
        let pos = |name: &str, v: f64| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(SpecError::new(
                    format!("accuracy.{name}"),
                    v,
                    "must be a finite number > 0",
                ))
            }
        };
        pos("settle_s", r.hit.settle_s)?;
        pos("measure_s", r.hit.measure_s)?;
        pos("settle_tol", r.probe.settle_tol)?;
        pos("k_step", r.k_step)?;
        pos("b_step", r.b_step)?;
        if !(r.k_rel_tol > 0.0 && r.k_rel_tol < 0.5) {
            return Err(SpecError::new(
                "accuracy.k_rel_tol",
                r.k_rel_tol,
                "must be between 0 and 0.5",
            ));
        }
        if !(1..=1000).contains(&r.probe.periods) {
            return Err(SpecError::new(
                "accuracy.periods",
                r.probe.periods,
                "must be 1 to 1000",
            ));
        }
        if !(1..=MAX_REALIZATIONS).contains(&r.probe.realizations) {
            return Err(SpecError::new(
                "accuracy.realizations",
                r.probe.realizations,
                format!("must be 1 to {MAX_REALIZATIONS}"),
            ));
        }
        // A noisy-scene trial runs up to realizations × (1 + periods) periods:
        // the same bound as max_periods, so no accepted trial runs for hours.
        let bla_periods = u64::from(r.probe.realizations) * (1 + u64::from(r.probe.periods));
        if bla_periods > MAX_TRIAL_PERIODS {
            return Err(SpecError::new(
                "accuracy.realizations",
                r.probe.realizations,
                format!(
                    "realizations × (1 + periods) = {bla_periods} probe periods per trial; at most {MAX_TRIAL_PERIODS}"
                ),
            ));
        }
        if !(2..=100_000).contains(&r.probe.max_periods) {
            return Err(SpecError::new(
                "accuracy.max_periods",
                r.probe.max_periods,
                "must be 2 to 100000",
            ));
        }
        if (r.hit.settle_s + r.hit.measure_s) * scene.spec.control.sample_hz > 1e9 {
            return Err(SpecError::new(
                "accuracy.settle_s",
                r.hit.settle_s,
                "a trial may have at most 1e9 samples",
            ));
        }
        Ok(r)
    }
}

/// A whole map request: the one spec the CLI reads and the service will store.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct MapSpec {
    pub scene: SceneSpec,
    #[serde(default)]
    pub method: Method,
    #[serde(default)]
    pub criterion: Criterion,
    #[serde(default)]
    pub search: SearchKind,
    #[serde(default)]
    pub accuracy: Accuracy,
    /// Restrict the boundary to these damping values (N·s/m).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b: Option<Vec<f64>>,
    /// Largest damping searched (N·s/m) by trace and bisect when `b` is not given.
    #[serde(default = "default_b_max")]
    pub b_max: f64,
    /// Largest stiffness considered (N/m).
    #[serde(default = "default_k_max")]
    pub k_max: f64,
    /// A prediction of the boundary each column's bisection starts from
    /// (`{"scene": …}`, `{"run": "<id>"}` or `{"boundary": […]}`): on a
    /// rig, hardware trials go where the prediction is uncertain. The
    /// result is the map's own; `prior` in it sets the prediction beside.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prior: Option<super::prior::Prior>,
}

fn default_b_max() -> f64 {
    1000.0
}

fn default_k_max() -> f64 {
    1e7
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn accuracy_forms() {
        let a: Accuracy = serde_json::from_str(r#""draft""#).unwrap();
        assert_eq!(a, Accuracy::Preset(Preset::Draft));
        let a: Accuracy =
            serde_json::from_str(r#"{"preset":"reference","k_rel_tol":0.03}"#).unwrap();
        let sc = SceneSpec::default().validate().unwrap();
        let r = a.resolve(&sc).unwrap();
        assert_eq!(r.k_rel_tol, 0.03);
        assert_eq!(r.hit.settle_s, 8.0);
        let bad: Accuracy = serde_json::from_str(r#"{"k_rel_tol":0}"#).unwrap();
        assert_eq!(bad.resolve(&sc).unwrap_err().field, "accuracy.k_rel_tol");
        assert!(serde_json::from_str::<Accuracy>(r#""fast""#).is_err());
        // Realizations: the presets' (docs/zwidth.md), and 0 refused.
        let reals = |p: &str| {
            serde_json::from_str::<Accuracy>(p)
                .unwrap()
                .resolve(&sc)
                .map(|r| r.probe.realizations)
        };
        assert_eq!(reals(r#""draft""#).unwrap(), 10);
        assert_eq!(reals(r#""standard""#).unwrap(), 24);
        assert_eq!(reals(r#""reference""#).unwrap(), 48);
        assert_eq!(reals(r#"{"realizations":5}"#).unwrap(), 5);
        let e = reals(r#"{"realizations":0}"#).unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.to_string().contains("1 to 1000")),
            ("accuracy.realizations", true)
        );
    }

    #[test]
    fn search_names_are_the_spec_names() {
        use SearchKind::*;
        for k in [Trace, Bisect, RobustBisect, Grid, Psi] {
            assert_eq!(serde_json::to_value(k).unwrap(), k.name());
        }
    }

    #[test]
    fn a_trial_may_have_1e9_samples_and_not_more() {
        // The documented limit, (settle_s + measure_s)·sample_hz ≤ 1e9: at
        // the seed's 10 kHz, 99 998 + 2 s is exactly 1e9 samples.
        let sc = SceneSpec::default().validate().unwrap();
        assert_eq!(sc.spec.control.sample_hz, 1e4);
        let settle = |s: f64| {
            serde_json::from_value::<Accuracy>(serde_json::json!({"settle_s": s, "measure_s": 2.0}))
                .unwrap()
                .resolve(&sc)
        };
        assert_eq!(settle(99_998.0).unwrap().hit.settle_s, 99_998.0);
        let e = settle(99_998.5).unwrap_err();
        assert_eq!(e.field, "accuracy.settle_s");
        assert!(e.to_string().contains("1e9 samples"), "{e}");
    }

    #[test]
    fn the_presets_resolve_to_the_documented_table() {
        // docs/zwidth.md's preset table on the seed scene (hit settle 4 s,
        // measure 2 s, 4 probe periods): draft ×¼ time, ½ periods, twice the
        // 2011 paper's steps (1488.24 N/m, 14.88 N·s/m); reference ×2, ×2, half.
        let sc = SceneSpec::default().validate().unwrap();
        let row = |p: Preset| {
            let r = Accuracy::Preset(p).resolve(&sc).unwrap();
            (
                r.hit.settle_s,
                r.hit.measure_s,
                r.probe.periods,
                r.k_step,
                r.b_step,
            )
        };
        assert_eq!(row(Preset::Draft), (1.0, 0.5, 2, 2976.48, 29.76));
        assert_eq!(
            row(Preset::Standard),
            (4.0, 2.0, 4, PAPER_K_STEP, PAPER_B_STEP)
        );
        assert_eq!(row(Preset::Reference), (8.0, 4.0, 8, 744.12, 7.44));
        // A map without b_max or k_max: 1000 N·s/m and 1e7 N/m (the docs).
        let m: MapSpec = serde_json::from_str(r#"{"scene":{}}"#).unwrap();
        assert_eq!((m.b_max, m.k_max), (1000.0, 1e7));
    }

    #[test]
    fn every_knob_is_checked_at_its_documented_limit() {
        let sc = SceneSpec::default().validate().unwrap();
        let resolve =
            |j: serde_json::Value| serde_json::from_value::<Accuracy>(j).unwrap().resolve(&sc);
        let field = |j: serde_json::Value| resolve(j).unwrap_err().field;
        use serde_json::json;
        assert_eq!(field(json!({"k_step": 0})), "accuracy.k_step");
        assert_eq!(field(json!({"b_step": -1})), "accuracy.b_step");
        assert_eq!(field(json!({"settle_tol": 0})), "accuracy.settle_tol");
        assert_eq!(field(json!({"measure_s": 0})), "accuracy.measure_s");
        assert_eq!(field(json!({"k_rel_tol": 0.5})), "accuracy.k_rel_tol");
        assert!(resolve(json!({"k_rel_tol": 0.49})).is_ok());
        // realizations × (1 + periods) ≤ 100 000: 1000 × 100 is the limit.
        assert!(resolve(json!({"realizations": 1000, "periods": 99})).is_ok());
        assert_eq!(
            field(json!({"realizations": 1000, "periods": 100})),
            "accuracy.realizations"
        );
        assert_eq!(field(json!({"periods": 1001})), "accuracy.periods");
        assert_eq!(field(json!({"max_periods": 1})), "accuracy.max_periods");
        assert!(resolve(json!({"max_periods": 2})).is_ok());
    }
}
