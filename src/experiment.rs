//! What an experiment is: one spec type, as submitted to the API, read by
//! the CLI and stored as is; its validation (with what it will cost) and
//! its run. Pure: no I/O, no async.

use serde::{Deserialize, Serialize};
use std::sync::Arc;

use crate::error::SpecError;
use crate::tune::TuneSpec;
use crate::zwidth::compare;
use crate::zwidth::cost::Cost;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{self, map_observed, Observer};
use crate::zwidth::settings::Accuracy;
use crate::zwidth::settings::MapSpec;
use crate::zwidth::sweep::{sweep_observed, SweepSpec};

/// An experiment as submitted: `{"kind":"map", …MapSpec}`,
/// `{"kind":"compare","scene":{…},"accuracy":"draft"}` or
/// `{"kind":"sweep","map":{…},"parameter":{…}}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum ExperimentSpec {
    Map(MapSpec),
    Compare(CompareSpec),
    Sweep(SweepSpec),
    Tune(TuneSpec),
}

#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct CompareSpec {
    /// The scene (its estimator is ignored); default the 2018 paper's simulated device.
    #[serde(default)]
    pub scene: Option<SceneSpec>,
    #[serde(default)]
    pub accuracy: Accuracy,
    /// The estimators to compare; default the 2018 paper's four with its
    /// tuned parameters (Levant's C estimated from a wall hit).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub estimators: Option<Vec<crate::estimators::EstimatorSpec>>,
}

impl ExperimentSpec {
    pub fn kind(&self) -> &'static str {
        match self {
            ExperimentSpec::Map(_) => "map",
            ExperimentSpec::Compare(_) => "compare",
            ExperimentSpec::Sweep(_) => "sweep",
            ExperimentSpec::Tune(_) => "tune",
        }
    }

    /// Every scene the experiment runs, with the request field it came from.
    pub fn scenes(&self) -> Vec<(String, SceneSpec)> {
        match self {
            ExperimentSpec::Map(m) => vec![("scene".into(), m.scene.clone())],
            ExperimentSpec::Compare(c) => vec![(
                "scene".into(),
                c.scene.clone().unwrap_or_else(compare::seed_2018_scene),
            )],
            ExperimentSpec::Sweep(s) => match &s.scenes {
                Some(list) => list
                    .iter()
                    .enumerate()
                    .map(|(i, sc)| (format!("scenes[{i}]"), sc.clone()))
                    .collect(),
                None => vec![("map.scene".into(), s.map.scene.clone())],
            },
            ExperimentSpec::Tune(t) => vec![("scene".into(), t.scene.clone())],
        }
    }

    /// The engines' own validation, without running anything; what the
    /// experiment will cost (refused beyond the limits in `zwidth::cost`).
    pub fn validate(&self) -> Result<Cost, SpecError> {
        match self {
            ExperimentSpec::Map(m) => search::validate(m),
            ExperimentSpec::Compare(c) => {
                let scene = c.scene.clone().unwrap_or_else(compare::seed_2018_scene);
                let sc = scene.validate().map_err(|e| e.within("scene"))?;
                if let Some(list) = &c.estimators {
                    if list.is_empty() || list.len() > 20 {
                        return Err(SpecError::new(
                            "estimators",
                            list.len(),
                            "give 1 to 20 estimators, or leave it out for the paper's four",
                        ));
                    }
                    for (i, e) in list.iter().enumerate() {
                        sc.with_estimator(e.clone()).map_err(|err| SpecError {
                            field: err
                                .field
                                .replacen("estimator", &format!("estimators[{i}]"), 1),
                            ..err
                        })?;
                    }
                }
                let one = search::validate(&compare::map_spec(scene, &c.accuracy))?;
                let n = c.estimators.as_ref().map_or(4, Vec::len) as u64;
                one.times(n).check("estimators")
            }
            ExperimentSpec::Sweep(s) => s.checked().map(|(_, cost)| cost),
            ExperimentSpec::Tune(t) => t.validate().map(|t| t.cost),
        }
    }

    /// Run to completion (blocking; call off the async workers).
    pub fn run(&self, observer: Arc<Observer>) -> Result<serde_json::Value, SpecError> {
        // Results are plain data: serializing them cannot fail.
        match self {
            ExperimentSpec::Map(m) => map_observed(m, Some(observer), 0)
                .map(|r| serde_json::to_value(r).unwrap_or_default()),
            ExperimentSpec::Compare(c) => {
                let scene = c.scene.clone().unwrap_or_else(compare::seed_2018_scene);
                compare::compare_observed(
                    &scene,
                    &c.accuracy,
                    c.estimators.as_deref(),
                    Some(observer),
                )
                .map(|r| serde_json::to_value(r).unwrap_or_default())
            }
            ExperimentSpec::Sweep(s) => sweep_observed(s, Some(observer))
                .map(|r| serde_json::to_value(r).unwrap_or_default()),
            ExperimentSpec::Tune(t) => t
                .validate()?
                .run(Some(observer))
                .map(|r| serde_json::to_value(r).unwrap_or_default()),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::{Rig, RigInfo};

    /// A rig that samples at 100 Hz to 1 kHz and runs nothing.
    struct Bench(RigInfo);

    impl Rig for Bench {
        fn info(&self) -> &RigInfo {
            &self.0
        }
        fn run(
            &self,
            _: &ExperimentSpec,
            _: Arc<Observer>,
        ) -> Result<serde_json::Value, SpecError> {
            Err(SpecError::new("rig", "bench", "runs nothing"))
        }
    }

    #[test]
    fn scenes_name_the_field_each_came_from() {
        let sweep: ExperimentSpec = serde_json::from_str(
            r#"{"kind":"sweep","map":{"scene":{}},"scenes":[{"loop":{"sample_hz":1000,"render_hz":1000}},{"loop":{"sample_hz":5000,"render_hz":1000}}]}"#,
        )
        .unwrap();
        let s = sweep.scenes();
        assert_eq!(
            s.iter().map(|(f, _)| f.as_str()).collect::<Vec<_>>(),
            ["scenes[0]", "scenes[1]"]
        );
        assert_eq!(s[1].1.control.sample_hz, 5000.0);
        // A rig that samples at 1 kHz at most refuses the second, by name
        // (what an attached rig's check does).
        let rig = Bench(RigInfo {
            id: "bench".into(),
            kind: "test".into(),
            description: String::new(),
            sample_hz: [100.0, 1000.0],
            force_limit_n: None,
            parallelism: 1,
        });
        assert_eq!(
            rig.check(&sweep).unwrap_err().field,
            "scenes[1].loop.sample_hz"
        );
        let compare: ExperimentSpec = serde_json::from_str(r#"{"kind":"compare"}"#).unwrap();
        let c = compare.scenes();
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].0, "scene");
        // The default is the 2018 paper's device (m = 0.52 kg, b = 13.2 N·s/m).
        assert_eq!(c[0].1.device.mass, 0.52);
        assert_eq!(compare.kind(), "compare");
        assert_eq!(sweep.kind(), "sweep");
    }
}
