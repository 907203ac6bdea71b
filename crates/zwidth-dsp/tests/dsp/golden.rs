//! The golden vectors (golden/vectors.txt) through this crate alone, bit
//! for bit: the rig's `RigEstimator` built from specs written here (the
//! file's JSON specs resolved by hand, as `EstimatorSpec::to_dsp` resolves
//! them in zwidth-core, whose tests/golden.rs checks the JSON way). A
//! mutation of this crate is caught by its own tests, without building
//! the service.

#[path = "../../golden/read.rs"]
mod read;

use read::{check, load};
use zwidth_dsp::estimator::{KindSpec, Spec};
use zwidth_dsp::{Discretization, FoawFit, ImplicitOutput, QModel, RigEstimator};

/// The file's estimator `name` as this crate's spec.
fn spec(name: &str) -> Spec {
    let foaw = |fit, d, max_window, outlier_tolerance| KindSpec::Foaw {
        fit,
        d,
        max_window,
        outlier_tolerance,
    };
    let kalman = |q, model, rho| KindSpec::Kalman { q, model, rho };
    let levant = |alpha, lambda, discretization, output| KindSpec::Levant {
        alpha,
        lambda,
        discretization,
        output,
    };
    let kind = match name {
        "fdm" | "fdm_medians" => KindSpec::Fdm,
        "butterworth_2" => KindSpec::Butterworth {
            cutoff_hz: 100.0,
            order: 2,
        },
        "butterworth_9" => KindSpec::Butterworth {
            cutoff_hz: 40.0,
            order: 9,
        },
        "kalman" => kalman(1e4, QModel::WhiteJerk, None),
        "kalman_diagonal" => kalman(1e4, QModel::Diagonal, None),
        "adaptive_kalman" => kalman(25000.0, QModel::WhiteJerk, Some(0.95)),
        "foaw_end" => foaw(FoawFit::End, None, 16, false),
        "foaw_best" => foaw(FoawFit::Best, None, 16, false),
        "foaw_best_r" => foaw(FoawFit::BestR, None, 16, false),
        "foaw_end_tolerant" => foaw(FoawFit::End, None, 16, true),
        "foaw_best_r_tolerant" => foaw(FoawFit::BestR, Some(2e-6), 32, true),
        "levant" => levant(13.2, 3.46, Discretization::Explicit, ImplicitOutput::State),
        "levant_implicit" => levant(13.2, 3.46, Discretization::Implicit, ImplicitOutput::State),
        // The 2018 paper's LFBA rule at C = 40 m/s²: α = μ1·C with
        // μ1 = 1.1·(3 + 2/4), λ = μ2·√C with μ2 = 2 (§III; zwidth-core's
        // `GainRule::normalized`).
        "levant_implicit_eq7" => levant(
            1.1 * (3.0 + 2.0 / 4.0) * 40.0,
            2.0 * sqrt(40.0),
            Discretization::Implicit,
            ImplicitOutput::Eq7,
        ),
        other => panic!("no spec for {other}"),
    };
    Spec {
        kind,
        median_position: (name == "fdm_medians").then_some(5),
        median_velocity: (name == "fdm_medians").then_some(4),
    }
}

/// √x, correctly rounded (IEEE 754: every library gives these bits).
fn sqrt(x: f64) -> f64 {
    x.sqrt()
}

#[test]
fn every_estimator_equals_its_golden_vectors_through_this_crate() {
    let (signals, cases) = load();
    assert_eq!(cases.len(), 90);
    for case in &cases {
        let s = signals.iter().find(|s| s.name == case.signal).unwrap();
        // The hand-written spec is of the file's kind.
        let kind = match spec(&case.estimator).kind {
            KindSpec::Fdm => "fdm",
            KindSpec::Butterworth { .. } => "butterworth",
            KindSpec::Kalman { rho: None, .. } => "kalman",
            KindSpec::Kalman { .. } => "adaptive_kalman",
            KindSpec::Foaw { .. } => "foaw",
            KindSpec::Levant { .. } => "levant",
        };
        assert!(
            case.spec.starts_with(&format!(r#"{{"kind":"{kind}""#)),
            "{}",
            case.spec
        );
        let mut rig = RigEstimator::new(&spec(&case.estimator), s.rate_hz, s.quantization)
            .unwrap_or_else(|e| panic!("{}: {e:?}", case.estimator));
        // One sample at a time, then the same through step_n after a reset.
        let v: Vec<f64> = s.positions.iter().map(|&y| rig.step(y)).collect();
        check(case, &v, "RigEstimator::step");
        rig.reset();
        let mut w = vec![0.0; s.positions.len()];
        rig.step_n(&s.positions, &mut w);
        check(case, &w, "RigEstimator::step_n after reset");
    }
}

/// The built coefficients' fingerprints of every case and the identity's
/// references equal golden/fingerprints.txt (written with the vectors):
/// built, computed without the state, and after a reset.
#[test]
fn every_fingerprint_equals_the_golden_file() {
    let (signals, _) = load();
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/golden/fingerprints.txt"
    ))
    .unwrap();
    let (mut cases, mut kinds) = (0, 0);
    for line in text.lines().filter(|l| !l.starts_with('#')).skip(1) {
        let w: Vec<&str> = line.split(' ').collect();
        match w[0] {
            "case" => {
                let s = signals.iter().find(|s| s.name == w[1]).unwrap();
                let want = read::hex(w[3]);
                let spec = spec(w[2]);
                let mut rig = RigEstimator::new(&spec, s.rate_hz, s.quantization).unwrap();
                assert_eq!(rig.fingerprint(), want, "{line}: built");
                rig.step(1e-3);
                rig.reset();
                assert_eq!(rig.fingerprint(), want, "{line}: after a reset");
                let stateless =
                    zwidth_dsp::estimator::fingerprint(&spec, s.rate_hz, s.quantization).unwrap();
                assert_eq!(stateless, want, "{line}: without the state");
                cases += 1;
            }
            "identity" => {
                assert_eq!(
                    zwidth_dsp::identity::reference_fingerprint(w[1]),
                    Some(read::hex(w[2])),
                    "{line}"
                );
                kinds += 1;
            }
            other => panic!("unknown line kind {other:?}"),
        }
    }
    assert_eq!((cases, kinds), (90, zwidth_dsp::identity::KINDS.len()));
}
