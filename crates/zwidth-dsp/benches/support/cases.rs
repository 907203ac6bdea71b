//! The estimators at the rig's caps, as `benches/step.rs` times them and
//! `examples/step_cost.rs` counts their instructions (`.ci/callgrind-dsp`).

use zwidth_dsp::estimator::{KindSpec, Spec, RIG_FOAW_WINDOW, RIG_MEDIAN};
use zwidth_dsp::{Discretization, FoawFit, ImplicitOutput, QModel};

/// The worst case of each kind at the rig's caps: the longest FOAW window
/// with best-R and outlier tolerance on a constant input (the window always
/// fills, every residual is checked), Butterworth at the highest order, the
/// longest velocity median.
pub fn case(kind: &str) -> Option<(Spec, bool)> {
    let spec = |k| Spec::from(k);
    Some(match kind {
        "bare" => (spec(KindSpec::Fdm), false),
        "fdm" => (spec(KindSpec::Fdm), false),
        "butterworth_10" => (
            spec(KindSpec::Butterworth {
                cutoff_hz: 500.0,
                order: 10,
            }),
            false,
        ),
        "kalman" => (
            spec(KindSpec::Kalman {
                q: 2.5e4,
                model: QModel::WhiteJerk,
                rho: None,
            }),
            false,
        ),
        "adaptive_kalman" => (
            spec(KindSpec::Kalman {
                q: 2.5e4,
                model: QModel::WhiteJerk,
                rho: Some(0.95),
            }),
            false,
        ),
        "levant_implicit" => (
            spec(KindSpec::Levant {
                alpha: 11.1,
                lambda: 3.2,
                discretization: Discretization::Implicit,
                output: ImplicitOutput::Eq7,
            }),
            false,
        ),
        "foaw_best_r_64_tolerant" => (
            spec(KindSpec::Foaw {
                fit: FoawFit::BestR,
                d: None,
                max_window: RIG_FOAW_WINDOW,
                outlier_tolerance: true,
            }),
            true,
        ),
        "fdm_median_63" => (
            Spec {
                kind: KindSpec::Fdm,
                median_position: None,
                median_velocity: Some(RIG_MEDIAN),
            },
            false,
        ),
        _ => return None,
    })
}

pub const CASES: [&str; 8] = [
    "bare",
    "fdm",
    "butterworth_10",
    "kalman",
    "adaptive_kalman",
    "levant_implicit",
    "foaw_best_r_64_tolerant",
    "fdm_median_63",
];

/// 10 000 samples at `rate` (Hz) of the 2011 paper's eq. 11 signal
/// (0.5·(1 − e^(−0.15 t)·cos 2t) m) quantized to `q` (m), or a constant.
pub fn signal(constant: bool, rate: f64, q: f64) -> Vec<f64> {
    (0..10_000)
        .map(|k| {
            if constant {
                return 0.0123;
            }
            let t = k as f64 / rate;
            let x = 0.5 * (1.0 - (-0.15 * t).exp() * (2.0 * t).cos());
            (x / q).round() * q
        })
        .collect()
}
