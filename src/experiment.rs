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
use crate::zwidth::settings::MapSpec;
use crate::zwidth::settings::{Accuracy, Criterion};
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
    /// Tune each of the paper's estimators for this objective first (as the
    /// paper did in simulation); absent: the paper's fixed parameters.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tuned: Option<crate::tune::fair::TunedCompare>,
    /// What renders: `impedance` (the 2018 paper's test, the default:
    /// the frequency engine on a nonlinear scene) or `stability` (the 2011
    /// paper's wall hit: the time engine on a nonlinear scene).
    #[serde(default, skip_serializing_if = "is_impedance")]
    pub criterion: Criterion,
    /// Rounds that map the rows of unresolved K-width orders again, each
    /// at half the K resolution before (0–3; default 0, and 2 for a tuned
    /// comparison). The result says which pairs stayed open.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    #[schema(minimum = 0, maximum = 3)]
    pub resolve_rounds: Option<u32>,
}

impl CompareSpec {
    /// The refinement rounds this comparison takes (`resolve_rounds` or
    /// its default).
    pub fn rounds(&self) -> u32 {
        compare::rounds_or_default(self.resolve_rounds, self.tuned.is_some())
    }
}

fn is_impedance(c: &Criterion) -> bool {
    *c == Criterion::Impedance
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
                scene.validate().map_err(|e| e.within("scene"))?;
                if let Some(list) = &c.estimators {
                    compare::check_estimators(&scene, list)?;
                }
                if let Some(t) = &c.tuned {
                    if c.estimators.is_some() {
                        return Err(SpecError::new(
                            "tuned",
                            "(with estimators)",
                            "tunes the paper's four estimators: leave `estimators` out, or tune a list with one `tune` experiment each",
                        ));
                    }
                    // The rounds' own share of the plan is named apart.
                    let first = t.cost(&scene, &c.accuracy, c.criterion)?.check("tuned")?;
                    let refine =
                        compare::refinement_cost(&scene, &c.accuracy, c.criterion, c.rounds(), 4)?;
                    return first.plus(refine).check("resolve_rounds");
                }
                let n = c.estimators.as_ref().map_or(4, Vec::len) as u64;
                let refine =
                    compare::refinement_cost(&scene, &c.accuracy, c.criterion, c.rounds(), n)?;
                let one = search::validate(&compare::map_spec(scene, &c.accuracy, c.criterion))?;
                one.times(n)
                    .check("estimators")?
                    .plus(refine)
                    .check("resolve_rounds")
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
                match &c.tuned {
                    Some(t) => crate::tune::fair::compare_tuned(
                        &scene,
                        &c.accuracy,
                        c.criterion,
                        t,
                        c.rounds(),
                        Some(observer),
                    ),
                    None => compare::compare_observed(
                        &scene,
                        &c.accuracy,
                        c.criterion,
                        c.estimators.as_deref(),
                        c.rounds(),
                        Some(observer),
                    ),
                }
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
        let compare: ExperimentSpec = serde_json::from_str(r#"{"kind":"compare"}"#).unwrap();
        let c = compare.scenes();
        assert_eq!(c.len(), 1);
        assert_eq!(c[0].0, "scene");
        // The default is the 2018 paper's device (m = 0.52 kg, b = 13.2 N·s/m).
        assert_eq!(c[0].1.device.mass, 0.52);
        assert_eq!(compare.kind(), "compare");
        assert_eq!(sweep.kind(), "sweep");
    }

    #[test]
    fn a_tuned_compare_costs_its_tunes_and_names_bad_fields() {
        let spec = |json: &str| serde_json::from_str::<ExperimentSpec>(json).unwrap();
        let plain = spec(r#"{"kind":"compare","accuracy":"draft"}"#)
            .validate()
            .unwrap();
        let tuned = spec(r#"{"kind":"compare","accuracy":"draft","tuned":{"objective":"k_width","max_evaluations":6}}"#)
            .validate()
            .unwrap();
        // Three tunes (FOAW has nothing to tune), each up to 6 search maps
        // and 3 finalists, on top of the comparison's own 4 maps.
        assert!(tuned.maps >= plain.maps + 3 * 6, "{tuned:?} vs {plain:?}");
        // The defaults (standard accuracy, 24 search maps each) fit the limits.
        spec(r#"{"kind":"compare","tuned":{"objective":"k_width"}}"#)
            .validate()
            .unwrap();
        let bad = |json: &str, field: &str| {
            let e = spec(json).validate().unwrap_err();
            assert_eq!(e.field, field, "{e}");
        };
        bad(
            r#"{"kind":"compare","tuned":{"objective":{"pareto":["k_width","b_width"]}}}"#,
            "tuned.objective",
        );
        bad(
            r#"{"kind":"compare","tuned":{"objective":"k_width","max_evaluations":0}}"#,
            "tuned.max_evaluations",
        );
        bad(
            r#"{"kind":"compare","tuned":{"objective":"k_width","max_evaluations":201}}"#,
            "tuned.max_evaluations",
        );
        bad(
            r#"{"kind":"compare","tuned":{"objective":"k_width"},"estimators":[{"kind":"fdm"}]}"#,
            "tuned",
        );
        assert!(serde_json::from_str::<ExperimentSpec>(
            r#"{"kind":"compare","tuned":{"objective":"k_width","extra":1}}"#
        )
        .is_err());
    }

    /// Refinement rounds: 0 by default, 2 for a tuned compare
    /// (compare::TUNED_RESOLVE_ROUNDS), each planning every row once more
    /// (the estimate bounds the run's runaway limit, `Cost::trial_limit`).
    #[test]
    fn a_compare_plans_its_refinement_rounds() {
        let spec = |json: &str| match serde_json::from_str::<ExperimentSpec>(json).unwrap() {
            ExperimentSpec::Compare(c) => c,
            _ => unreachable!("a compare"),
        };
        let cost = |c: &CompareSpec| ExperimentSpec::Compare(c.clone()).validate().unwrap();
        let plain = spec(r#"{"kind":"compare","accuracy":"draft"}"#);
        let two = spec(r#"{"kind":"compare","accuracy":"draft","resolve_rounds":2}"#);
        assert_eq!((plain.rounds(), two.rounds()), (0, 2));
        // 4 rows, then 4 more maps a round.
        assert_eq!((cost(&plain).maps, cost(&two).maps), (4, 12));
        // Each round's maps take twice the realizations and half the K
        // resolution: more trials than the first maps.
        assert!(
            cost(&two).trials > 3 * cost(&plain).trials,
            "{:?} vs {:?}",
            cost(&two),
            cost(&plain)
        );
        let tuned = spec(
            r#"{"kind":"compare","accuracy":"draft","tuned":{"objective":"k_width","max_evaluations":6}}"#,
        );
        assert_eq!(tuned.rounds(), 2);
        let mut untuned_rounds = tuned.clone();
        untuned_rounds.resolve_rounds = Some(0);
        assert_eq!(untuned_rounds.rounds(), 0);
        assert_eq!(cost(&tuned).maps, cost(&untuned_rounds).maps + 8);
        let e = ExperimentSpec::Compare(spec(r#"{"kind":"compare","resolve_rounds":4}"#))
            .validate()
            .unwrap_err();
        assert_eq!(e.field, "resolve_rounds");
    }
}
