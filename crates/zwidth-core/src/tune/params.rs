//! The parameters a tune may vary, per estimator kind, their bounds and
//! scale, and how a point of the search space becomes a scene.
//!
//! Solvers work in the unit cube u ∈ [0, 1]ⁿ; `linear` maps u to
//! min + u(max − min), `log` to min·(max/min)^u; integer parameters
//! (FOAW `max_window`, Butterworth `order`) are rounded, so distinct u may
//! name the same point (the evaluation cache catches those).

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

use crate::error::SpecError;
use crate::estimators::EstimatorKind;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::sweep::Scale;

/// Bounds and scale of one parameter: `{"min":10,"max":500,"scale":"log"}`,
/// optionally on a lattice `min + k·step` (e.g. whole hertz: `"step":1`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct Bounds {
    pub min: f64,
    pub max: f64,
    #[serde(default)]
    pub scale: Scale,
    /// Resolution: values are snapped to min + k·step (same unit as the parameter).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub step: Option<f64>,
}

/// The tunable parameters of an estimator kind: (name, integer?).
pub fn tunable(kind: &EstimatorKind) -> &'static [(&'static str, bool)] {
    match kind {
        EstimatorKind::Fdm {} => &[],
        EstimatorKind::Butterworth { .. } => &[("cutoff_hz", false), ("order", true)],
        EstimatorKind::Kalman { .. } => &[("q", false)],
        EstimatorKind::AdaptiveKalman { .. } => &[("q", false), ("rho", false)],
        EstimatorKind::Foaw(_) => &[("d", false), ("max_window", true)],
        EstimatorKind::Levant(_) => &[
            ("alpha", false),
            ("lambda", false),
            ("mu1", false),
            ("mu2", false),
        ],
    }
}

/// A validated parameter space over one base scene.
#[derive(Debug, Clone)]
pub struct Space {
    pub base: SceneSpec,
    /// (name, bounds, integer) in name order.
    pub params: Vec<(String, Bounds, bool)>,
}

impl Space {
    pub fn new(base: &SceneSpec, params: &BTreeMap<String, Bounds>) -> Result<Self, SpecError> {
        let kind = &base.estimator.kind;
        let allowed = tunable(kind);
        let kind_name = base.estimator.label();
        if params.is_empty() {
            return Err(SpecError::new(
                "params",
                "{}",
                format!(
                    "name at least one parameter to tune; {kind_name} has: {}",
                    names(allowed)
                ),
            ));
        }
        let mut out = Vec::new();
        for (name, b) in params {
            let field = format!("params.{name}");
            let Some(&(_, integer)) = allowed.iter().find(|(n, _)| n == name) else {
                return Err(SpecError::new(
                    field,
                    format!("{name:?}"),
                    format!(
                        "is not a parameter of {kind_name}; tunable: {}",
                        names(allowed)
                    ),
                ));
            };
            if !(b.min.is_finite() && b.max.is_finite()) {
                return Err(SpecError::new(
                    format!("{field}.min"),
                    b.min,
                    "bounds must be finite",
                ));
            }
            if b.min >= b.max {
                return Err(SpecError::new(
                    format!("{field}.max"),
                    b.max,
                    format!("must be above {field}.min = {}", b.min),
                ));
            }
            if b.scale == Scale::Log && b.min <= 0.0 {
                return Err(SpecError::new(
                    format!("{field}.min"),
                    b.min,
                    "must be > 0 on a log scale",
                ));
            }
            out.push((name.clone(), b.clone(), integer));
        }
        let has = |n: &str| params.contains_key(n);
        if (has("alpha") || has("lambda")) && (has("mu1") || has("mu2")) {
            return Err(SpecError::new(
                "params",
                "alpha/lambda and mu1/mu2",
                "tune Levant gains either as alpha, lambda or as normalized mu1, mu2, not both",
            ));
        }
        let space = Self {
            base: base.clone(),
            params: out,
        };
        // Both corners must make valid scenes (e.g. a cutoff below Nyquist).
        for u in [0.0, 1.0] {
            space.scene(&vec![u; space.params.len()])?;
        }
        Ok(space)
    }

    pub fn dim(&self) -> usize {
        self.params.len()
    }

    /// The parameter values at u (clamped into the cube), by name.
    pub fn values(&self, u: &[f64]) -> BTreeMap<String, f64> {
        self.params
            .iter()
            .zip(u)
            .map(|((name, b, integer), &u)| {
                let u = if u.is_finite() {
                    u.clamp(0.0, 1.0)
                } else {
                    0.5
                };
                let x = match b.scale {
                    Scale::Linear => b.min + u * (b.max - b.min),
                    Scale::Log => b.min * (b.max / b.min).powf(u),
                };
                let x = match b.step {
                    Some(st) => b.min + ((x - b.min) / st).round() * st,
                    None => x,
                };
                // Keep inside the bounds despite rounding.
                let x = if *integer { x.round() } else { x };
                (name.clone(), x.clamp(b.min, b.max))
            })
            .collect()
    }

    /// The base scene with the parameters at u, validated.
    pub fn scene(&self, u: &[f64]) -> Result<SceneSpec, SpecError> {
        self.scene_at(&self.values(u))
    }

    /// The base scene with these parameter values, validated. Tuning Levant
    /// gains replaces whichever gain form the base scene had.
    pub fn scene_at(&self, values: &BTreeMap<String, f64>) -> Result<SceneSpec, SpecError> {
        let mut remove: Vec<&str> = Vec::new();
        if matches!(self.base.estimator.kind, EstimatorKind::Levant(_)) {
            let explicit = values.contains_key("alpha") || values.contains_key("lambda");
            let normalized = values.contains_key("mu1") || values.contains_key("mu2");
            if explicit || normalized {
                // The rule and the other form's gains go; an untuned gain
                // of the tuned form keeps the base's value (a base without
                // it is refused by the scene's validation, naming it).
                remove.push("estimator.rule");
                let other: [&str; 2] = if explicit {
                    ["estimator.mu1", "estimator.mu2"]
                } else {
                    ["estimator.alpha", "estimator.lambda"]
                };
                remove.extend(other);
            }
        }
        let set: Vec<(String, f64)> = values
            .iter()
            .map(|(n, &x)| (format!("estimator.{n}"), x))
            .collect();
        let set_ref: Vec<(&str, f64)> = set.iter().map(|(p, x)| (p.as_str(), *x)).collect();
        self.base.with_numbers(&set_ref, &remove, "params")
    }
}

fn names(list: &[(&str, bool)]) -> String {
    if list.is_empty() {
        return "none".into();
    }
    list.iter().map(|(n, _)| *n).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn space(est: &str, params: &str) -> Result<Space, SpecError> {
        let scene: SceneSpec = serde_json::from_str(&format!(
            r#"{{"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{est}}}"#
        ))
        .unwrap();
        let p: BTreeMap<String, Bounds> = serde_json::from_str(params).unwrap();
        Space::new(&scene, &p)
    }

    #[test]
    fn scales_map_the_unit_cube() {
        let s = space(
            r#"{"kind":"kalman","q":1}"#,
            r#"{"q":{"min":1e2,"max":1e8,"scale":"log"}}"#,
        )
        .unwrap();
        // log: 1e2·(1e6)^0.5 = 1e5.
        assert!((s.values(&[0.5])["q"] - 1e5).abs() < 1e-6);
        let s = space(
            r#"{"kind":"foaw","fit":"best","max_window":15}"#,
            r#"{"max_window":{"min":2,"max":32}}"#,
        )
        .unwrap();
        assert_eq!(s.values(&[0.51])["max_window"], 17.0); // 2 + 0.51·30 = 17.3 → 17
        let sc = s.scene(&[1.0]).unwrap();
        assert!(serde_json::to_string(&sc.estimator)
            .unwrap()
            .contains(r#""max_window":32"#));
    }

    #[test]
    fn levant_gain_forms_are_replaced() {
        let s = space(
            r#"{"kind":"levant","rule":"hba_sc","lipschitz":2}"#,
            r#"{"mu1":{"min":1.5,"max":10},"mu2":{"min":1,"max":8}}"#,
        )
        .unwrap();
        let sc = s.scene(&[0.0, 1.0]).unwrap();
        let t = serde_json::to_string(&sc.estimator).unwrap();
        assert!(
            t.contains(r#""mu1":1.5"#) && t.contains(r#""mu2":8"#) && !t.contains("rule"),
            "{t}"
        );
    }

    #[test]
    fn steps_round_to_the_lattice_and_explicit_gains_are_dropped() {
        // step 1 Hz over 10–499: u = 0.3 → 10 + 0.3·489 = 156.7 → 157 Hz.
        let s = space(
            r#"{"kind":"butterworth","cutoff_hz":100}"#,
            r#"{"cutoff_hz":{"min":10,"max":499,"step":1}}"#,
        )
        .unwrap();
        assert_eq!(s.values(&[0.3])["cutoff_hz"], 157.0);
        // A base with explicit α, λ tuned over μ1, μ2: both explicit gains go.
        let s = space(
            r#"{"kind":"levant","alpha":20,"lambda":5,"lipschitz":2}"#,
            r#"{"mu1":{"min":1.5,"max":10},"mu2":{"min":1,"max":8}}"#,
        )
        .unwrap();
        let t = serde_json::to_string(&s.scene(&[0.0, 1.0]).unwrap().estimator).unwrap();
        assert!(
            !t.contains("alpha") && !t.contains("lambda") && t.contains(r#""mu2":8"#),
            "{t}"
        );
    }

    #[test]
    fn one_explicit_gain_is_tuned_against_the_base_other() {
        // Tuning α alone on a base with α = 20, λ = 5 keeps λ = 5 (it was
        // dropped, and every scene refused, until 2026-12-02).
        let s = space(
            r#"{"kind":"levant","alpha":20,"lambda":5,"lipschitz":2}"#,
            r#"{"alpha":{"min":10,"max":30}}"#,
        )
        .unwrap();
        let t = serde_json::to_string(&s.scene(&[0.5]).unwrap().estimator).unwrap();
        assert!(
            t.contains(r#""alpha":20"#) && t.contains(r#""lambda":5"#),
            "{t}"
        );
        // A rule base has no λ to keep: refused, naming it.
        let e = space(
            r#"{"kind":"levant","rule":"hba_sc","lipschitz":2}"#,
            r#"{"alpha":{"min":10,"max":30}}"#,
        )
        .unwrap_err();
        assert_eq!(e.field, "scene.estimator.lambda", "{e}");
        // The same for the normalized form: μ1 alone on a μ1/μ2 base keeps
        // μ2; on a rule base there is no μ2 to keep.
        let s = space(
            r#"{"kind":"levant","mu1":2,"mu2":3,"lipschitz":2}"#,
            r#"{"mu1":{"min":1,"max":10}}"#,
        )
        .unwrap();
        let t = serde_json::to_string(&s.scene(&[0.0]).unwrap().estimator).unwrap();
        assert!(t.contains(r#""mu1":1"#) && t.contains(r#""mu2":3"#), "{t}");
        let e = space(
            r#"{"kind":"levant","rule":"hba_sc","lipschitz":2}"#,
            r#"{"mu1":{"min":1,"max":10}}"#,
        )
        .unwrap_err();
        assert_eq!(e.field, "scene.estimator.mu2", "{e}");
    }

    #[test]
    fn bad_spaces_name_the_field() {
        let f = |est: &str, p: &str| space(est, p).unwrap_err().field;
        let bw = r#"{"kind":"butterworth","cutoff_hz":100}"#;
        assert_eq!(
            f(bw, r#"{"cutoff_hz":{"min":500,"max":10}}"#),
            "params.cutoff_hz.max"
        );
        assert_eq!(f(bw, r#"{"q":{"min":1,"max":10}}"#), "params.q");
        assert_eq!(f(bw, r#"{}"#), "params");
        assert_eq!(
            f(bw, r#"{"cutoff_hz":{"min":0,"max":10,"scale":"log"}}"#),
            "params.cutoff_hz.min"
        );
        // 900 Hz is above Nyquist at 1 kHz: the scene validation says so.
        assert_eq!(
            f(bw, r#"{"cutoff_hz":{"min":10,"max":900}}"#),
            "scene.estimator.cutoff_hz"
        );
        let lv = r#"{"kind":"levant","rule":"hba_sc","lipschitz":2}"#;
        assert_eq!(
            f(lv, r#"{"alpha":{"min":1,"max":9},"mu2":{"min":1,"max":3}}"#),
            "params"
        );
    }

    #[test]
    fn bounds_must_be_finite_and_the_error_lists_what_is_tunable() {
        let scene: SceneSpec = serde_json::from_str(
            r#"{"loop":{"sample_hz":1000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":100}}"#,
        )
        .unwrap();
        let one = |b: Bounds| BTreeMap::from([("cutoff_hz".to_string(), b)]);
        let b = |min: f64, max: f64| Bounds {
            min,
            max,
            scale: Scale::Linear,
            step: None,
        };
        let field = |p| Space::new(&scene, &p).err().unwrap().field;
        assert_eq!(field(one(b(10.0, f64::INFINITY))), "params.cutoff_hz.min");
        assert_eq!(field(one(b(f64::NAN, 100.0))), "params.cutoff_hz.min");
        // docs/tuning.md's table: Butterworth tunes cutoff_hz and order; FDM nothing.
        let e = space(
            r#"{"kind":"butterworth","cutoff_hz":100}"#,
            r#"{"q":{"min":1,"max":10}}"#,
        )
        .err()
        .unwrap();
        assert!(e.allowed.ends_with("tunable: cutoff_hz, order"), "{e}");
        let e = space(r#"{"kind":"fdm"}"#, r#"{"q":{"min":1,"max":10}}"#)
            .err()
            .unwrap();
        assert!(e.allowed.ends_with("tunable: none"), "{e}");
    }
}
