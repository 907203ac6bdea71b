//! A sweep: one map per variant of a scene — a list of scenes, or one
//! scene number stepped over a range (e.g. Butterworth cutoffs 30…1000 Hz,
//! `{"path":"estimator.cutoff_hz","min":30,"max":1000,"count":12,"scale":"log"}`).
//! Each variant is map `scope` = its index, so a resumed sweep replays
//! every stored trial of every variant.

use serde::{Deserialize, Serialize};
use std::sync::Arc;

use super::cost::Cost;
use super::scene::SceneSpec;
use super::search::{map_observed, MapResult, Observer};
use super::settings::MapSpec;
use crate::error::SpecError;

/// Most variants one sweep may have.
pub const MAX_VARIANTS: usize = 200;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Scale {
    #[default]
    Linear,
    Log,
}

/// One scene number over a range: `values`, or `count` points from `min`
/// to `max` (both included) on a linear or log scale.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ParameterRange {
    /// Dot-separated path of the number in the scene, e.g. "estimator.cutoff_hz".
    pub path: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub values: Option<Vec<f64>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub count: Option<usize>,
    #[serde(default)]
    pub scale: Scale,
}

/// `{"kind":"sweep","map":{…MapSpec},"parameter":{…}}` or `…,"scenes":[…]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    /// The map each variant runs; its scene is the base the parameter varies.
    pub map: MapSpec,
    /// Run these scenes instead of `map.scene`, one map each.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scenes: Option<Vec<SceneSpec>>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parameter: Option<ParameterRange>,
}

#[derive(Debug, Clone, Serialize)]
pub struct SweepRow {
    pub label: String,
    /// The parameter's value (parameter sweeps).
    pub value: Option<f64>,
    pub k_width: f64,
    pub b_width: f64,
    pub max_fidelity_error: Option<f64>,
    pub area: f64,
    pub map: MapResult,
}

#[derive(Debug, Clone, Serialize)]
pub struct SweepResult {
    pub parameter: Option<String>,
    pub rows: Vec<SweepRow>,
    /// Index of the row with the largest K-width.
    pub best_k_width: usize,
    pub elapsed_s: f64,
}

impl ParameterRange {
    /// The values, checked.
    pub fn values(&self) -> Result<Vec<f64>, SpecError> {
        let vals = match (&self.values, self.min, self.max, self.count) {
            (Some(v), None, None, None) => v.clone(),
            (None, Some(lo), Some(hi), Some(n)) => {
                if !(lo.is_finite() && hi.is_finite() && lo < hi) {
                    return Err(SpecError::new(
                        "parameter.max",
                        hi,
                        format!("must be a finite number above parameter.min = {lo}"),
                    ));
                }
                if !(2..=MAX_VARIANTS).contains(&n) {
                    return Err(SpecError::new(
                        "parameter.count",
                        n,
                        format!("must be 2 to {MAX_VARIANTS}"),
                    ));
                }
                if self.scale == Scale::Log && lo <= 0.0 {
                    return Err(SpecError::new(
                        "parameter.min",
                        lo,
                        "must be > 0 on a log scale",
                    ));
                }
                (0..n)
                    .map(|i| {
                        let f = i as f64 / (n - 1) as f64;
                        match self.scale {
                            Scale::Linear => lo + f * (hi - lo),
                            // Geometric steps: lo·(hi/lo)^f.
                            Scale::Log => lo * (hi / lo).powf(f),
                        }
                    })
                    .collect()
            }
            _ => {
                return Err(SpecError::new(
                    "parameter",
                    "(fields)",
                    "give either values, or min, max and count",
                ))
            }
        };
        if vals.is_empty() || vals.len() > MAX_VARIANTS {
            return Err(SpecError::new(
                "parameter.values",
                vals.len(),
                format!("give 1 to {MAX_VARIANTS} values"),
            ));
        }
        Ok(vals)
    }
}

/// One variant of a sweep: its label, the swept value (if any), its map.
pub type Variant = (String, Option<f64>, MapSpec);

impl SweepSpec {
    /// Every variant as (label, value, map spec), validated.
    pub fn variants(&self) -> Result<Vec<Variant>, SpecError> {
        self.checked().map(|(v, _)| v)
    }

    /// Every variant, validated, and what they cost together.
    pub fn checked(&self) -> Result<(Vec<Variant>, Cost), SpecError> {
        if self.map.prior.is_some() {
            return Err(SpecError::new(
                "map.prior",
                "(given)",
                "absent: a sweep's variants are different devices or estimators, one prediction fits none of them; submit maps with a prior instead",
            ));
        }
        let out = self.variant_specs()?;
        let mut cost = Cost::default();
        for (i, (_, _, m)) in out.iter().enumerate() {
            let field = if self.scenes.is_some() {
                format!("scenes[{i}]")
            } else {
                "map".into()
            };
            let c = super::search::validate(m).map_err(|e| match self.scenes {
                Some(_) => SpecError {
                    field: e.field.replacen("scene", &field, 1),
                    ..e
                },
                None => e.within(&field),
            })?;
            cost = cost.plus(c);
        }
        let field = if self.scenes.is_some() {
            "scenes"
        } else {
            "parameter"
        };
        Ok((out, cost.check(field)?))
    }

    /// The variants' labels, values and map specs without building their
    /// engines (for reading a stored result; `variants` checks them fully).
    pub fn variant_specs(&self) -> Result<Vec<(String, Option<f64>, MapSpec)>, SpecError> {
        let with_scene = |scene: SceneSpec| MapSpec {
            scene,
            ..self.map.clone()
        };
        let out: Vec<_> = match (&self.scenes, &self.parameter) {
            (Some(scenes), None) => {
                if scenes.is_empty() || scenes.len() > MAX_VARIANTS {
                    return Err(SpecError::new(
                        "scenes",
                        scenes.len(),
                        format!("give 1 to {MAX_VARIANTS} scenes"),
                    ));
                }
                scenes
                    .iter()
                    .enumerate()
                    .map(|(i, s)| {
                        (
                            format!("scene {i}: {}", s.estimator.label()),
                            None,
                            with_scene(s.clone()),
                        )
                    })
                    .collect()
            }
            (None, Some(p)) => {
                let mut v = Vec::new();
                for x in p.values()? {
                    let scene = self.map.scene.with_number(&p.path, x, "parameter.path")?;
                    v.push((format!("{} = {x}", p.path), Some(x), with_scene(scene)));
                }
                v
            }
            _ => {
                return Err(SpecError::new(
                    "sweep",
                    "(fields)",
                    "give exactly one of scenes (a list) or parameter (a range)",
                ))
            }
        };
        Ok(out)
    }
}

/// Run every variant in turn (each map parallel inside), reporting to
/// `observer`. With a farm (`farm.rs`) the variants go out at once, each
/// map's units beside the others' (the rows are the same, in the same
/// order: each map is its own scope).
pub fn sweep_observed(
    spec: &SweepSpec,
    observer: Option<Arc<Observer>>,
) -> Result<SweepResult, SpecError> {
    use rayon::prelude::*;
    let start = std::time::Instant::now();
    let variants = spec.variants()?;
    if let Some(o) = &observer {
        o.set_scopes(variants.len());
    }
    let row = |scope: usize, (label, value, m): (String, Option<f64>, MapSpec)| {
        map_observed(&m, observer.clone(), scope as u32).map(|map| SweepRow {
            label,
            value,
            k_width: map.k_width,
            b_width: map.b_width,
            max_fidelity_error: map.max_fidelity_error,
            area: map.area,
            map,
        })
    };
    let cancelled = || observer.as_ref().is_some_and(|o| o.cancelled());
    let rows = if observer.as_ref().is_some_and(|o| o.farm().is_some()) {
        variants
            .into_par_iter()
            .enumerate()
            .map(|(scope, v)| row(scope, v))
            .collect::<Result<Vec<_>, _>>()?
    } else {
        let mut rows = Vec::with_capacity(variants.len());
        for (scope, v) in variants.into_iter().enumerate() {
            let r = row(scope, v)?;
            if cancelled() {
                break;
            }
            rows.push(r);
        }
        rows
    };
    let best_k_width = rows
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.k_width.total_cmp(&b.1.k_width))
        .map_or(0, |(i, _)| i);
    Ok(SweepResult {
        parameter: spec.parameter.as_ref().map(|p| p.path.clone()),
        rows,
        best_k_width,
        elapsed_s: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base() -> MapSpec {
        serde_json::from_str(
            r#"{"scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":100}},"criterion":"strict_passivity","b":[0,5]}"#,
        )
        .unwrap()
    }

    #[test]
    fn ranges_give_the_documented_values() {
        let range = |json: &str| {
            serde_json::from_str::<ParameterRange>(json)
                .unwrap()
                .values()
                .unwrap()
        };
        // Linear: lo + (i/(n−1))·(hi − lo); log: lo·(hi/lo)^(i/(n−1)).
        assert_eq!(
            range(r#"{"path":"estimator.cutoff_hz","min":100,"max":300,"count":3}"#),
            [100.0, 200.0, 300.0]
        );
        let g = range(r#"{"path":"estimator.q","min":1,"max":100,"count":3,"scale":"log"}"#);
        assert!(
            (g[0] - 1.0).abs() < 1e-12
                && (g[1] - 10.0).abs() < 1e-12
                && (g[2] - 100.0).abs() < 1e-12,
            "{g:?}"
        );
    }

    #[test]
    fn log_range_is_geometric_and_sets_the_scene() {
        let s = SweepSpec {
            map: base(),
            scenes: None,
            parameter: Some(ParameterRange {
                path: "estimator.cutoff_hz".into(),
                values: None,
                min: Some(30.0),
                max: Some(480.0),
                count: Some(4),
                scale: Scale::Log,
            }),
        };
        let v = s.variants().unwrap();
        // 30·(480/30)^(i/3) = 30·16^(i/3): 30, 75.59, 190.5, 480 (by hand:
        // 16^(1/3) = 2.5198, 16^(2/3) = 6.3496).
        let want = [30.0, 75.595_263_0, 190.488_126_2, 480.0];
        for ((_, x, m), w) in v.iter().zip(want) {
            assert!((x.unwrap() - w).abs() < 1e-8 * w, "{x:?} vs {w}");
            match m.scene.estimator.kind {
                crate::estimators::EstimatorKind::Butterworth { cutoff_hz, order } => {
                    assert_eq!(cutoff_hz, x.unwrap());
                    assert_eq!(order, 2);
                }
                _ => panic!("estimator kind changed"),
            }
        }
    }

    #[test]
    fn bad_sweeps_name_the_field() {
        let mk = |p: &str| -> SweepSpec {
            serde_json::from_str(&format!(
                r#"{{"map":{{"scene":{{"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{{"kind":"butterworth","cutoff_hz":100}}}}}},"parameter":{p}}}"#
            ))
            .unwrap()
        };
        let field = |p: &str| mk(p).variants().unwrap_err().field;
        assert_eq!(
            field(r#"{"path":"estimator.nope","values":[1]}"#),
            "parameter.path"
        );
        assert_eq!(
            field(r#"{"path":"estimator","values":[1]}"#),
            "parameter.path"
        );
        assert_eq!(
            field(r#"{"path":"estimator.cutoff_hz","min":500,"max":30,"count":3}"#),
            "parameter.max"
        );
        assert_eq!(
            field(r#"{"path":"estimator.cutoff_hz","min":30,"max":500,"count":1000}"#),
            "parameter.count"
        );
        assert_eq!(
            field(r#"{"path":"estimator.cutoff_hz","min":30}"#),
            "parameter"
        );
        // 600 Hz is above Nyquist at the default 1 kHz: the scene validation says so.
        assert_eq!(
            field(r#"{"path":"estimator.cutoff_hz","values":[100,600]}"#),
            "scene.estimator.cutoff_hz"
        );
        let none: SweepSpec = serde_json::from_str(r#"{"map":{"scene":{}}}"#).unwrap();
        assert_eq!(none.variants().unwrap_err().field, "sweep");
        // A prediction fits one device: a sweep's maps take none.
        let seeded: SweepSpec = serde_json::from_str(
            r#"{"map":{"scene":{},"prior":{"boundary":[{"b":0,"k_max":1000}]}},"parameter":{"path":"device.mass","values":[0.1]}}"#,
        )
        .unwrap();
        assert_eq!(seeded.variants().unwrap_err().field, "map.prior");
    }

    #[test]
    fn range_limits_are_the_documented_ones() {
        // The documented limits: min < max, both finite; 2..=200 points; a
        // log scale needs min > 0; an explicit list holds 1 to 200 values.
        let range = |values: Option<Vec<f64>>, min: f64, max: f64, scale: Scale| ParameterRange {
            path: "estimator.cutoff_hz".into(),
            min: values.is_none().then_some(min),
            max: values.is_none().then_some(max),
            count: values.is_none().then_some(3),
            values,
            scale,
        };
        let field = |r: ParameterRange| r.values().unwrap_err().field;
        assert_eq!(
            field(range(None, 30.0, 30.0, Scale::Linear)),
            "parameter.max"
        );
        assert_eq!(
            field(range(None, 30.0, f64::INFINITY, Scale::Linear)),
            "parameter.max"
        );
        assert_eq!(
            field(range(None, f64::NEG_INFINITY, 30.0, Scale::Linear)),
            "parameter.max"
        );
        assert_eq!(field(range(None, 0.0, 30.0, Scale::Log)), "parameter.min");
        assert_eq!(field(range(None, -1.0, 30.0, Scale::Log)), "parameter.min");
        // A linear range may start below zero: lo + i/(n−1)·(hi − lo).
        assert_eq!(
            range(None, -1.0, 1.0, Scale::Linear).values().unwrap(),
            [-1.0, 0.0, 1.0]
        );
        assert_eq!(
            field(range(Some(vec![]), 0.0, 0.0, Scale::Linear)),
            "parameter.values"
        );
        let n = |k: usize| (1..=k).map(|i| i as f64).collect::<Vec<_>>();
        assert_eq!(
            range(Some(n(MAX_VARIANTS)), 0.0, 0.0, Scale::Linear)
                .values()
                .unwrap()
                .len(),
            200
        );
        assert_eq!(
            field(range(Some(n(MAX_VARIANTS + 1)), 0.0, 0.0, Scale::Linear)),
            "parameter.values"
        );
    }

    #[test]
    fn a_scene_list_sweep_labels_each_scene_and_names_the_bad_one() {
        let scenes = |list: &str| -> SweepSpec {
            serde_json::from_str(&format!(
                r#"{{"map":{{"scene":{{}},"b":[0]}},"scenes":[{list}]}}"#
            ))
            .unwrap()
        };
        let ok = r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#;
        let v = scenes(&[ok, ok].join(",")).variants().unwrap();
        let labels: Vec<_> = v.iter().map(|(l, x, _)| (l.as_str(), *x)).collect();
        assert_eq!(labels, [("scene 0: fdm", None), ("scene 1: fdm", None)]);
        assert_eq!(v[1].2.b, Some(vec![0.0]), "the map's settings kept");
        let bad = scenes(&format!(r#"{ok},{{"device":{{"mass":0}}}}"#));
        assert_eq!(bad.variants().unwrap_err().field, "scenes[1].device.mass");
        assert_eq!(scenes("").variant_specs().unwrap_err().field, "scenes");
        let many = |k: usize| scenes(&vec!["{}"; k].join(",")).variant_specs();
        assert_eq!(many(MAX_VARIANTS).unwrap().len(), 200);
        assert_eq!(many(MAX_VARIANTS + 1).unwrap_err().field, "scenes");
    }

    #[test]
    fn strict_passivity_sweep_matches_the_closed_form_for_fdm_damping() {
        // Colgate & Schenkel for FDM: K_max = 2(b − |B|)/T. Vary the device
        // damping b = 1, 2, 4 N·s/m at 1 kHz, B = 0: K = 2000, 4000, 8000 N/m.
        let s: SweepSpec = serde_json::from_str(
            r#"{"map":{"scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]},
                "parameter":{"path":"device.damping","values":[1,2,4]}}"#,
        )
        .unwrap();
        let r = sweep_observed(&s, None).unwrap();
        for (row, want) in r.rows.iter().zip([2000.0, 4000.0, 8000.0]) {
            assert!(
                (row.k_width - want).abs() < 1e-3 * want,
                "{} vs {want}",
                row.k_width
            );
        }
        assert_eq!(r.best_k_width, 2);
    }
}
