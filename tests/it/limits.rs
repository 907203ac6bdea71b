//! Every accepted request has a bounded, estimated cost (issue 9): a
//! property test over experiment specs, and the runaway stop.

use proptest::prelude::*;
use std::sync::Arc;

use zwidth::experiment::ExperimentSpec;
use zwidth::zwidth::cost::{Cost, MAX_B_COLUMNS, MAX_TRIALS};
use zwidth::zwidth::search::{map_observed, Observer};

/// The 2018 device without friction and quantization, single rate: the
/// analytic engine answers each trial in well under a millisecond.
const SCENE: &str =
    r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#;

fn search() -> impl Strategy<Value = &'static str> {
    prop_oneof![
        Just("bisect"),
        Just("robust_bisect"),
        Just("trace"),
        Just("grid")
    ]
}

fn criterion() -> impl Strategy<Value = &'static str> {
    prop_oneof![
        Just("impedance"),
        Just("stability"),
        Just("strict_passivity")
    ]
}

/// Numbers from 10^lo to 10^hi, log-uniform; now and then from far
/// beyond (1e-320 to 1e300), zero or negative.
fn wide(lo: f64, hi: f64) -> impl Strategy<Value = f64> {
    prop_oneof![
        24 => (lo..hi).prop_map(|e| 10f64.powf(e)),
        1 => (-320.0..300.0f64).prop_map(|e| 10f64.powf(e)),
        1 => Just(0.0),
        1 => Just(-1.0),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 96, .. ProptestConfig::default() })]

    /// Accepted ⇒ the estimate is within the documented limits; and a run
    /// of a modest estimate ends, within it, never stopped as runaway.
    #[test]
    fn accepted_maps_have_a_bounded_cost_and_end(
        search in search(),
        criterion in criterion(),
        b_max in wide(0.0, 5.0),
        b_step in wide(-1.0, 3.0),
        k_step in wide(1.0, 5.0),
        k_rel_tol in wide(-7.0, -0.4),
        k_max in wide(3.0, 9.0),
        n_b in prop_oneof![4 => 1usize..40, 1 => 0usize..3000],
        with_b in any::<bool>(),
    ) {
        let mut spec = serde_json::json!({
            "kind": "map", "scene": serde_json::from_str::<serde_json::Value>(SCENE).unwrap(),
            "search": search, "criterion": criterion, "b_max": b_max, "k_max": k_max,
            "accuracy": {"preset": "draft", "b_step": b_step, "k_step": k_step, "k_rel_tol": k_rel_tol},
        });
        if with_b {
            spec["b"] = (0..n_b).map(|i| i as f64).collect();
        }
        let e: ExperimentSpec = serde_json::from_value(spec).unwrap();
        let Ok(cost) = e.validate() else { return Ok(()) };
        prop_assert!(cost.trials <= MAX_TRIALS, "{cost:?}");
        prop_assert!(cost.b_columns <= MAX_B_COLUMNS, "{cost:?}");
        prop_assert!(cost.stored_rows == cost.trials);
        let ExperimentSpec::Map(m) = e else { unreachable!() };
        if cost.trials <= 4_000 {
            let obs = Arc::new(Observer::default());
            obs.limit_trials(cost.trial_limit() as usize);
            let r = map_observed(&m, Some(obs.clone()), 0).unwrap();
            prop_assert!(obs.runaway().is_none());
            prop_assert!(r.trials as u64 <= cost.trials, "{} trials, estimated {cost:?}", r.trials);
            prop_assert!(r.k_width.is_finite() && r.area.is_finite());
        }
    }
}

#[test]
fn a_run_beyond_its_trial_limit_is_stopped_with_the_reason() {
    let spec: ExperimentSpec = serde_json::from_str(&format!(
        r#"{{"kind":"map","scene":{SCENE},"b":[0,5,10,15,20,25,30]}}"#
    ))
    .unwrap();
    let cost = spec.validate().unwrap();
    let ExperimentSpec::Map(m) = spec else {
        unreachable!()
    };
    // Unlimited: it runs to the end within its estimate.
    let free = Arc::new(Observer::default());
    let full = map_observed(&m, Some(free.clone()), 0).unwrap();
    assert!(free.runaway().is_none());
    assert!(full.trials as u64 <= cost.trials);
    // A limit below what it needs: stopped right after the limit, with why.
    // On one thread exactly one trial past it; on `n` threads each column
    // running when the limit is crossed may finish the trial it started
    // (CI machines have more cores than this one: a flat `limit + 1` failed
    // there with 48 against 47).
    let limit = full.trials / 2;
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let tight = Arc::new(Observer::default());
        tight.limit_trials(limit);
        let _ = pool.install(|| map_observed(&m, Some(tight.clone()), 0));
        let why = tight.runaway().expect("stopped as runaway");
        assert!(why.contains(&format!("more than {limit}")), "{why}");
        assert!(tight.cancelled());
        let done = tight.trials.load(std::sync::atomic::Ordering::Relaxed);
        assert!(
            done > limit && done <= limit + threads,
            "{done} trials on {threads} threads, limit {limit}"
        );
        if threads == 1 {
            assert_eq!(done, limit + 1);
        }
    }
}

#[test]
fn an_experiment_may_plan_max_trials_and_not_one_more() {
    let at = Cost {
        trials: MAX_TRIALS,
        ..Cost::default()
    };
    assert_eq!(at.check("x").unwrap(), at);
    let over = Cost {
        trials: MAX_TRIALS + 1,
        ..Cost::default()
    };
    let e = over.check("max_evaluations").unwrap_err();
    assert_eq!(e.field, "max_evaluations");
    assert!(e.value.contains(&(MAX_TRIALS + 1).to_string()), "{e}");
}

#[test]
fn the_limit_is_four_times_the_estimate_plus_slack() {
    // The documented rule (docs/service.md): 4 × estimate + 1000.
    let c = Cost {
        trials: 2_500,
        ..Cost::default()
    };
    assert_eq!(c.trial_limit(), 11_000);
    let huge = Cost {
        trials: u64::MAX,
        ..Cost::default()
    };
    assert_eq!(huge.trial_limit(), u64::MAX);
}
