//! Velocity estimators: one quantized position sample in (m), one velocity
//! estimate out (m/s). Every estimator is built from [`EstimatorSpec`], the
//! serde type the CLI, the API and the store share; building validates the
//! spec once and the per-sample code then trusts its values, allocates nothing
//! and dispatches on an enum (no trait objects in the inner loop).

pub mod butterworth;
pub mod fdm;
pub mod foaw;
pub mod identity;
pub mod kalman;
pub mod levant;
pub mod median;
pub mod streaming;

use serde::{Deserialize, Serialize};

use crate::error::{require_non_negative, SpecError};
pub use butterworth::Butterworth;
pub use fdm::Fdm;
pub use foaw::{Foaw, FoawFit, FoawSpec};
pub use kalman::{Kalman, QModel};
pub use levant::{Discretization, GainReport, GainRule, Levant, LevantGains, LevantSpec};
pub use median::RunningMedian;
pub use streaming::{Sampling, VelocityEstimator, MAX_MEDIAN_WINDOW};

/// What every estimator has in common: the kind and its parameters, plus
/// optional median smoothing of input positions and output velocities
/// (Janabi-Sharifi et al. 2000, §III-B).
///
/// JSON: `{"kind":"butterworth","cutoff_hz":100,"order":2,"median_velocity":5}`.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct EstimatorSpec {
    #[serde(flatten)]
    pub kind: EstimatorKind,
    /// Median of the last W input positions (samples), applied before the estimator.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub median_position: Option<usize>,
    /// Median of the last W velocity estimates (samples), applied after it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub median_velocity: Option<usize>,
}

/// The estimator kinds, tagged by `"kind"`. The JSON forms are a contract.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum EstimatorKind {
    /// Backward difference `(y_k − y_{k−1})/T` (2011 paper eq. 2).
    Fdm {},
    /// FDM followed by a Butterworth low-pass (bilinear transform with prewarping).
    Butterworth {
        /// Cutoff frequency (Hz), strictly between 0 and the Nyquist frequency.
        cutoff_hz: f64,
        /// Filter order, 1 to 10.
        #[serde(default = "default_butterworth_order")]
        order: u32,
    },
    /// Triple-integrator Kalman filter (Janabi-Sharifi et al. 2000, eqs. 3–7).
    Kalman {
        /// Process-noise intensity: m²/s⁵ (white jerk) or m²/s⁶ per sample (diagonal).
        q: f64,
        #[serde(default)]
        q_model: QModel,
    },
    /// The same filter with an optimal fading factor λ_k ≥ 1 (eqs. 8–10, see `kalman`).
    AdaptiveKalman {
        q: f64,
        #[serde(default)]
        q_model: QModel,
        /// Forgetting factor ρ of the innovation-covariance estimate, 0 < ρ < 1.
        #[serde(default = "default_rho")]
        rho: f64,
    },
    /// First-order adaptive windowing (Janabi-Sharifi et al. 2000, §III).
    Foaw(FoawSpec),
    /// Levant's super-twisting differentiator (2011 paper eqs. 6–8).
    Levant(LevantSpec),
}

fn default_butterworth_order() -> u32 {
    2
}

fn default_rho() -> f64 {
    kalman::DEFAULT_RHO
}

impl<'de> Deserialize<'de> for EstimatorSpec {
    // Hand-written so that unknown fields are still rejected: serde's
    // `flatten` would silently swallow a typo such as `cuttoff_hz`.
    fn deserialize<D: serde::Deserializer<'de>>(de: D) -> Result<Self, D::Error> {
        use serde::de::Error;
        let mut map = serde_json::Map::<String, serde_json::Value>::deserialize(de)?;
        let mut take_window = |name: &str| -> Result<Option<usize>, D::Error> {
            match map.remove(name) {
                None | Some(serde_json::Value::Null) => Ok(None),
                Some(v) => serde_json::from_value::<usize>(v.clone())
                    .map(Some)
                    .map_err(|_| {
                        D::Error::custom(format!(
                            "{name} = {v} is not allowed: must be a whole number of samples >= 1"
                        ))
                    }),
            }
        };
        let median_position = take_window("median_position")?;
        let median_velocity = take_window("median_velocity")?;
        // Read through a reference: the map stays for the error's search
        // without a copy on the way that succeeds.
        let value = serde_json::Value::Object(map);
        let kind = EstimatorKind::deserialize(&value).map_err(|e| {
            let why = value
                .as_object()
                .map_or_else(|| e.to_string(), |map| kind_error(map, &e));
            D::Error::custom(why)
        })?;
        Ok(Self {
            kind,
            median_position,
            median_velocity,
        })
    }
}

/// Why `map` is not an estimator kind, naming the field: serde's tagged
/// enums lose the path, so an invalid type or value (`"max_window": -1`,
/// `"order": 2.0`) said only "estimator = (as written)". The field is the
/// one whose removal changes the error; the refusal is written as
/// `SpecError` writes one (`error::parse_json` reads it back).
fn kind_error(map: &serde_json::Map<String, serde_json::Value>, e: &serde_json::Error) -> String {
    let text = e.to_string();
    if !(text.starts_with("invalid type") || text.starts_with("invalid value")) {
        return text;
    }
    let changes = |key: &str| {
        let mut rest = map.clone();
        rest.remove(key);
        match EstimatorKind::deserialize(serde_json::Value::Object(rest)) {
            Ok(_) => true,
            Err(other) => other.to_string() != text,
        }
    };
    let culprit = map
        .iter()
        .find(|(key, _)| key.as_str() != "kind" && changes(key));
    match culprit {
        Some((key, value)) => {
            let whole = if text.contains("expected u") {
                "must be a whole number"
            } else {
                "has the wrong type"
            };
            format!("{key} = {value} is not allowed: {whole} ({text})")
        }
        None => text,
    }
}

impl From<EstimatorKind> for EstimatorSpec {
    fn from(kind: EstimatorKind) -> Self {
        Self {
            kind,
            median_position: None,
            median_velocity: None,
        }
    }
}

impl EstimatorSpec {
    /// Parse the JSON form; the error text is serde's, which names the field.
    pub fn from_json(text: &str) -> Result<Self, SpecError> {
        crate::error::parse_json(text, "estimator", "estimator spec")
    }

    /// A short human label, e.g. `butterworth(100 Hz, order 2)`.
    pub fn label(&self) -> String {
        let base = match &self.kind {
            EstimatorKind::Fdm {} => "fdm".to_string(),
            EstimatorKind::Butterworth { cutoff_hz, order } => {
                format!("butterworth({cutoff_hz} Hz, order {order})")
            }
            EstimatorKind::Kalman { q, q_model } => format!("kalman(q={q:e}, {})", q_model.name()),
            EstimatorKind::AdaptiveKalman { q, q_model, .. } => {
                format!("adaptive_kalman(q={q:e}, {})", q_model.name())
            }
            EstimatorKind::Foaw(f) => {
                format!("foaw({}, max_window {})", f.fit.name(), f.max_window)
            }
            EstimatorKind::Levant(l) => format!("levant({})", l.label()),
        };
        let mut s = base;
        if let Some(w) = self.median_position {
            s.push_str(&format!(" +median_position {w}"));
        }
        if let Some(w) = self.median_velocity {
            s.push_str(&format!(" +median_velocity {w}"));
        }
        s
    }

    /// The plain spec `zwidth-dsp` builds from (the Levant gains resolved
    /// from their form): what a rig's controller runs for this spec.
    pub fn to_dsp(&self) -> Result<zwidth_dsp::Spec, SpecError> {
        use zwidth_dsp::KindSpec as K;
        let kind = match &self.kind {
            EstimatorKind::Fdm {} => K::Fdm,
            EstimatorKind::Butterworth { cutoff_hz, order } => K::Butterworth {
                cutoff_hz: *cutoff_hz,
                order: *order,
            },
            EstimatorKind::Kalman { q, q_model } => K::Kalman {
                q: *q,
                model: q_model.dsp(),
                rho: None,
            },
            EstimatorKind::AdaptiveKalman { q, q_model, rho } => K::Kalman {
                q: *q,
                model: q_model.dsp(),
                rho: Some(*rho),
            },
            EstimatorKind::Foaw(f) => K::Foaw {
                fit: f.fit.dsp(),
                d: f.d,
                max_window: f.max_window,
                outlier_tolerance: f.outlier_tolerance,
            },
            EstimatorKind::Levant(l) => {
                let g = l.gains()?;
                K::Levant {
                    alpha: g.alpha,
                    lambda: g.lambda,
                    discretization: l.discretization.dsp(),
                    output: l.implicit_output.dsp(),
                }
            }
        };
        Ok(zwidth_dsp::Spec {
            kind,
            median_position: self.median_position,
            median_velocity: self.median_velocity,
        })
    }

    /// Validate against the sampling and build the streaming estimator.
    pub fn build(&self, sampling: Sampling) -> Result<Estimator, SpecError> {
        let core = self.kind.build(sampling)?;
        let median = |field: &str, w: Option<usize>| -> Result<Option<RunningMedian>, SpecError> {
            match w {
                None => Ok(None),
                Some(w) if (1..=MAX_MEDIAN_WINDOW).contains(&w) => RunningMedian::new(w).map(Some),
                Some(w) => Err(SpecError::new(
                    field,
                    w,
                    format!("median window must be 1 to {MAX_MEDIAN_WINDOW} samples"),
                )),
            }
        };
        Ok(Estimator {
            core,
            median_position: median("median_position", self.median_position)?,
            median_velocity: median("median_velocity", self.median_velocity)?,
        })
    }
}

impl EstimatorKind {
    fn build(&self, s: Sampling) -> Result<Core, SpecError> {
        let t = s.period();
        Ok(match self {
            EstimatorKind::Fdm {} => Core::Fdm(Fdm::new(t)),
            EstimatorKind::Butterworth { cutoff_hz, order } => {
                Core::Butterworth(Butterworth::new(*cutoff_hz, *order, s)?)
            }
            EstimatorKind::Kalman { q, q_model } => {
                Core::Kalman(Kalman::new(*q, *q_model, None, s)?)
            }
            EstimatorKind::AdaptiveKalman { q, q_model, rho } => {
                Core::Kalman(Kalman::new(*q, *q_model, Some(*rho), s)?)
            }
            EstimatorKind::Foaw(spec) => {
                let d = spec.d.unwrap_or(s.quantization);
                require_non_negative("d", d, "m")?;
                Core::Foaw(Foaw::new(spec, d, t)?)
            }
            EstimatorKind::Levant(spec) => Core::Levant(
                Levant::new(spec.gains()?, spec.discretization, t)
                    .with_output(spec.implicit_output),
            ),
        })
    }
}

/// The built estimator core; enum dispatch keeps the inner loop monomorphic.
#[derive(Debug, Clone)]
pub enum Core {
    Fdm(Fdm),
    Butterworth(Butterworth),
    Kalman(Kalman),
    Foaw(Foaw),
    Levant(Levant),
}

/// A built estimator: core plus optional median smoothing.
#[derive(Debug, Clone)]
pub struct Estimator {
    core: Core,
    median_position: Option<RunningMedian>,
    median_velocity: Option<RunningMedian>,
}

impl Estimator {
    pub fn core(&self) -> &Core {
        &self.core
    }

    /// Run over a whole trace (allocates the output only).
    pub fn run(&mut self, positions: &[f64]) -> Vec<f64> {
        positions.iter().map(|&y| self.update(y)).collect()
    }
}

impl VelocityEstimator for Estimator {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        let y = match &mut self.median_position {
            Some(m) => m.push(y),
            None => y,
        };
        let v = match &mut self.core {
            Core::Fdm(e) => e.update(y),
            Core::Butterworth(e) => e.update(y),
            Core::Kalman(e) => e.update(y),
            Core::Foaw(e) => e.update(y),
            Core::Levant(e) => e.update(y),
        };
        match &mut self.median_velocity {
            Some(m) => m.push(v),
            None => v,
        }
    }

    fn reset(&mut self) {
        match &mut self.core {
            Core::Fdm(e) => e.reset(),
            Core::Butterworth(e) => e.reset(),
            Core::Kalman(e) => e.reset(),
            Core::Foaw(e) => e.reset(),
            Core::Levant(e) => e.reset(),
        }
        if let Some(m) = &mut self.median_position {
            m.reset();
        }
        if let Some(m) = &mut self.median_velocity {
            m.reset();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<EstimatorSpec, SpecError> {
        EstimatorSpec::from_json(s)
    }

    /// A value of the wrong type or sign names its field, as a range error
    /// does (issue 45: `"max_window": -1` said "estimator = (as written)"),
    /// at the top level and inside a scene.
    #[test]
    fn a_wrong_type_or_sign_names_the_field() {
        for (text, field, value) in [
            (
                r#"{"kind":"foaw","fit":"end","max_window":-1}"#,
                "estimator.max_window",
                "-1",
            ),
            (
                r#"{"kind":"butterworth","cutoff_hz":100,"order":2.0}"#,
                "estimator.order",
                "2.0",
            ),
            (
                r#"{"kind":"butterworth","cutoff_hz":"100"}"#,
                "estimator.cutoff_hz",
                "\"100\"",
            ),
            (r#"{"kind":"kalman","q":true}"#, "estimator.q", "true"),
            (
                r#"{"kind":"fdm","median_velocity":-3}"#,
                "estimator.median_velocity",
                "-3",
            ),
        ] {
            let e = parse(text).unwrap_err();
            assert_eq!(
                (e.field.as_str(), e.value.as_str()),
                (field, value),
                "{text}: {e}"
            );
            assert!(!e.allowed.contains(" at line "), "{e}");
        }
        let whole = parse(r#"{"kind":"foaw","fit":"end","max_window":-1}"#).unwrap_err();
        assert!(
            whole.allowed.starts_with("must be a whole number"),
            "{whole}"
        );
        // Inside a scene the path continues from the scene's.
        let scene = r#"{"estimator":{"kind":"foaw","fit":"end","max_window":-1}}"#;
        let e = crate::zwidth::SceneSpec::from_json(scene).unwrap_err();
        assert_eq!(e.field, "scene.estimator.max_window", "{e}");
        // Unknown kinds and fields keep serde's own words.
        let e = parse(r#"{"kind":"nope"}"#).unwrap_err();
        assert!(e.allowed.contains("unknown variant"), "{e}");
    }

    #[test]
    fn contract_json_forms_parse() {
        for s in [
            r#"{"kind":"fdm"}"#,
            r#"{"kind":"butterworth","cutoff_hz":100,"order":2}"#,
            r#"{"kind":"kalman","q":1e4,"q_model":"white_jerk"}"#,
            r#"{"kind":"kalman","q":1e4,"q_model":"diagonal"}"#,
            r#"{"kind":"adaptive_kalman","q":2.5e4}"#,
            r#"{"kind":"foaw","fit":"end","d":1e-6,"max_window":16}"#,
            r#"{"kind":"foaw","fit":"best_r","outlier_tolerance":true}"#,
            r#"{"kind":"levant","alpha":13.2,"lambda":3.46}"#,
            r#"{"kind":"levant","rule":"hba_sc","lipschitz":12}"#,
            r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":12,"discretization":"implicit"}"#,
            r#"{"kind":"fdm","median_position":5,"median_velocity":3}"#,
        ] {
            let spec = parse(s).unwrap_or_else(|e| panic!("{s}: {e}"));
            // Round trip: what we serialize parses back to the same spec.
            let back = serde_json::to_string(&spec).unwrap();
            assert_eq!(parse(&back).unwrap(), spec, "{s} -> {back}");
            spec.build(Sampling::new(10_000.0, 1e-6).unwrap())
                .unwrap_or_else(|e| panic!("{s}: {e}"));
        }
    }

    const EVERY_KIND: [&str; 8] = [
        r#"{"kind":"fdm","median_position":5,"median_velocity":3}"#,
        r#"{"kind":"butterworth","cutoff_hz":100,"order":2}"#,
        r#"{"kind":"kalman","q":1e4,"q_model":"diagonal"}"#,
        r#"{"kind":"adaptive_kalman","q":2.5e4}"#,
        r#"{"kind":"foaw","fit":"best","max_window":16}"#,
        r#"{"kind":"foaw","fit":"end","d":1e-6,"max_window":16}"#,
        r#"{"kind":"levant","alpha":13.2,"lambda":3.46}"#,
        r#"{"kind":"levant","alpha":13.2,"lambda":3.46,"discretization":"implicit"}"#,
    ];

    #[test]
    fn run_is_update_per_sample_and_reset_makes_it_new() {
        // A quantized chirp: every estimator's state moves far from its start.
        let ys: Vec<f64> = (0..800)
            .map(|k| ((0.002 * (k as f64).powf(1.4)).sin() * 5e-3 / 1e-6).round() * 1e-6)
            .collect();
        let s = Sampling::new(10_000.0, 1e-6).unwrap();
        for j in EVERY_KIND {
            let spec = parse(j).unwrap();
            let mut fresh = spec.build(s).unwrap();
            let by_update: Vec<f64> = ys.iter().map(|&y| fresh.update(y)).collect();
            let mut e = spec.build(s).unwrap();
            let run = e.run(&ys);
            assert_eq!(run, by_update, "{j}");
            // After a reset, the same trace gives the same output again, bit
            // for bit: no state (filter, window, median, gain) survives.
            e.reset();
            assert_eq!(e.run(&ys), by_update, "{j}: reset");
            // And something moved: a constant output would pass the above.
            assert!(by_update.iter().any(|v| v.abs() > 1e-3), "{j}");
        }
    }

    #[test]
    fn labels_name_the_kind_and_its_parameters() {
        let label = |j: &str| parse(j).unwrap().label();
        assert_eq!(
            label(EVERY_KIND[0]),
            "fdm +median_position 5 +median_velocity 3"
        );
        assert_eq!(label(EVERY_KIND[1]), "butterworth(100 Hz, order 2)");
        assert_eq!(label(EVERY_KIND[2]), "kalman(q=1e4, diagonal)");
        assert_eq!(label(EVERY_KIND[3]), "adaptive_kalman(q=2.5e4, white_jerk)");
        assert_eq!(label(EVERY_KIND[4]), "foaw(best, max_window 16)");
        assert_eq!(label(EVERY_KIND[6]), "levant(alpha=13.2, lambda=3.46)");
        assert_eq!(
            label(EVERY_KIND[7]),
            "levant(alpha=13.2, lambda=3.46, implicit)"
        );
    }

    #[test]
    fn bad_specs_name_the_problem() {
        let s = Sampling::new(10_000.0, 1e-6).unwrap();
        let err = |j: &str| match parse(j) {
            Err(e) => e.to_string(),
            Ok(spec) => spec
                .build(s)
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default(),
        };
        assert!(err(r#"{"kind":"nope"}"#).contains("unknown variant `nope`"));
        assert!(err(r#"{"kind":"butterworth","cuttoff_hz":100}"#).contains("cuttoff_hz"));
        assert!(err(r#"{"kind":"butterworth","cutoff_hz":5000}"#).contains("cutoff_hz = 5000"));
        assert!(err(r#"{"kind":"kalman","q":0}"#).contains("q = 0"));
        assert!(err(r#"{"kind":"kalman","q":-1}"#).contains("q = -1"));
        assert!(err(r#"{"kind":"foaw","fit":"end","d":-1e-6}"#).contains("d = -0.000001"));
        assert!(err(r#"{"kind":"foaw","fit":"end","max_window":0}"#).contains("max_window = 0"));
        assert!(err(r#"{"kind":"fdm","median_velocity":0}"#).contains("median_velocity = 0"));
        assert!(err(r#"{"kind":"fdm","median_velocity":-3}"#).contains("median_velocity = -3"));
        assert!(err(r#"{"kind":"levant","alpha":1}"#).contains("lambda"));
        assert!(err(r#"{"kind":"levant","rule":"hba"}"#).contains("lipschitz"));
        assert!(err("not json").contains("not a valid estimator spec"));
        assert!(Sampling::new(0.0, 1e-6)
            .unwrap_err()
            .to_string()
            .contains("rate = 0"));
        assert!(Sampling::new(1e3, 0.0)
            .unwrap_err()
            .to_string()
            .contains("quantization = 0"));
    }
}
