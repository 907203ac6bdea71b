//! zwidth-dsp's golden vectors (crates/zwidth-dsp/golden/vectors.txt,
//! written by `cargo run --release -p zwidth-core --example
//! golden_vectors`), checked bit for bit through both ways in: the
//! service's `EstimatorSpec` (what the simulator runs) and the rig's
//! `zwidth_dsp::RigEstimator` built from `EstimatorSpec::to_dsp` (what a
//! controller runs through the C ABI).

use zwidth_core::estimators::{EstimatorSpec, Sampling, VelocityEstimator};
use zwidth_dsp::RigEstimator;

#[path = "../../../zwidth-dsp/golden/read.rs"]
mod read;
use read::{check, load};

#[test]
fn every_estimator_equals_its_golden_vectors_bit_for_bit_both_ways() {
    let (signals, cases) = load();
    // 6 signals × 15 estimators (the example's list).
    assert_eq!(signals.len(), 6);
    assert_eq!(cases.len(), 90);
    for case in &cases {
        let s = signals.iter().find(|s| s.name == case.signal).unwrap();
        let spec = EstimatorSpec::from_json(&case.spec).unwrap();
        let sampling = Sampling::new(s.rate_hz, s.quantization).unwrap();
        let mut service = spec.build(sampling).unwrap();
        let v: Vec<f64> = s.positions.iter().map(|&y| service.update(y)).collect();
        check(case, &v, "EstimatorSpec");
        let mut rig = RigEstimator::new(&spec.to_dsp().unwrap(), s.rate_hz, s.quantization)
            .unwrap_or_else(|e| panic!("{}: {e}", case.estimator));
        let mut v = vec![0.0; s.positions.len()];
        rig.step_n(&s.positions, &mut v);
        check(case, &v, "RigEstimator");
        // The fingerprint without the state (how the agent and Python name
        // it) is the built estimator's.
        let dsp = spec.to_dsp().unwrap();
        assert_eq!(
            zwidth_dsp::estimator::fingerprint(&dsp, s.rate_hz, s.quantization).unwrap(),
            rig.fingerprint(),
            "{}",
            case.estimator
        );
    }
}

/// The rest: 6 s of a held position. Without the flush the filter states
/// decay into the subnormal range; with it, no output is subnormal and
/// every estimator's velocity reaches exactly 0 (the policy of
/// zwidth-dsp's header, "Subnormals").
#[test]
fn a_long_rest_reaches_exactly_zero_and_never_a_subnormal() {
    let (signals, cases) = load();
    let rest = signals.iter().find(|s| s.name == "rest").unwrap();
    for case in cases.iter().filter(|c| c.signal == "rest") {
        let spec = EstimatorSpec::from_json(&case.spec).unwrap();
        let mut rig =
            RigEstimator::new(&spec.to_dsp().unwrap(), rest.rate_hz, rest.quantization).unwrap();
        let mut v = vec![0.0; rest.positions.len()];
        rig.step_n(&rest.positions, &mut v);
        assert!(
            v.iter().all(|x| !x.is_subnormal()),
            "{}: a subnormal output",
            case.estimator
        );
        // At the end: the filters' velocities exactly 0; the Kalman filters'
        // and implicit Levant's within rounding of 0 (their updates reach a
        // fixed point at 1e-16…1e-18 m/s, far above the subnormal range);
        // Levant's explicit
        // scheme chatters at rest by design (±Tα steps of u1 about 0, 2011
        // paper eq. 8).
        let last = *v.last().unwrap();
        match case.estimator.as_str() {
            "levant" => assert!(last.abs() < 1e-2, "{last}"), // measured 2.2e-3
            k if k.contains("kalman") || k.contains("implicit") => {
                assert!(last.abs() < 1e-12, "{k}: {last}")
            }
            k => assert_eq!(last, 0.0, "{k}"),
        }
    }
}

/// The 15 estimators of a signal have 15 fingerprints, and a spec's
/// fingerprint changes with the rate (its coefficients do).
#[test]
fn fingerprints_tell_the_estimators_apart() {
    let (signals, cases) = load();
    for s in &signals {
        let prints: std::collections::BTreeSet<u64> = cases
            .iter()
            .filter(|c| c.signal == s.name)
            .map(|c| {
                let spec = EstimatorSpec::from_json(&c.spec).unwrap().to_dsp().unwrap();
                zwidth_dsp::estimator::fingerprint(&spec, s.rate_hz, s.quantization).unwrap()
            })
            .collect();
        assert_eq!(prints.len(), 15, "{}", s.name);
    }
    let fdm = EstimatorSpec::from_json(r#"{"kind":"fdm"}"#)
        .unwrap()
        .to_dsp()
        .unwrap();
    let at = |rate| zwidth_dsp::estimator::fingerprint(&fdm, rate, 1e-6).unwrap();
    assert_ne!(at(1e3), at(1e4));
}
