//! What a rig says about its estimators at hello: this library's version
//! and, for every kind, the fingerprint of one reference configuration's
//! built coefficients. A server built on the same coefficient maths
//! computes the same fingerprints; a rig whose library was rebuilt with
//! another maths library, a fused multiply–add or another version shows a
//! different one, so "bit-identical estimators" is checked, not assumed.
//!
//! The references exercise every piece of design-time maths: Butterworth's
//! prewarped tangent and its poles' sines and cosines, Kalman's powers of
//! the period and its square roots, the adaptive filter's fading factor,
//! FOAW's band, Levant's implicit scheme.

use crate::estimator::{fingerprint, KindSpec, Spec};
use crate::{Discretization, FoawFit, ImplicitOutput, QModel};

/// The sample rate (Hz) and encoder step (m) of the references.
pub const REFERENCE_RATE_HZ: f64 = 10_000.0;
pub const REFERENCE_QUANTIZATION_M: f64 = 1e-6;

/// Every estimator kind, by the name the API and the capabilities use.
pub const KINDS: [&str; 6] = [
    "fdm",
    "butterworth",
    "kalman",
    "adaptive_kalman",
    "foaw",
    "levant",
];

/// The reference configuration of `kind` (None for an unknown name).
pub fn reference_spec(kind: &str) -> Option<Spec> {
    let k = match kind {
        "fdm" => KindSpec::Fdm,
        "butterworth" => KindSpec::Butterworth {
            cutoff_hz: 250.0,
            order: 5,
        },
        "kalman" => KindSpec::Kalman {
            q: 1e6,
            model: QModel::WhiteJerk,
            rho: None,
        },
        "adaptive_kalman" => KindSpec::Kalman {
            q: 1e6,
            model: QModel::WhiteJerk,
            rho: Some(0.95),
        },
        "foaw" => KindSpec::Foaw {
            fit: FoawFit::BestR,
            d: None,
            max_window: 16,
            outlier_tolerance: true,
        },
        "levant" => KindSpec::Levant {
            alpha: 1.1,
            lambda: 1.5,
            discretization: Discretization::Implicit,
            output: ImplicitOutput::Eq7,
        },
        _ => return None,
    };
    Some(Spec {
        kind: k,
        median_position: None,
        median_velocity: Some(5),
    })
}

/// The fingerprint of `kind`'s reference built by this library (None for
/// an unknown name).
pub fn reference_fingerprint(kind: &str) -> Option<u64> {
    let spec = reference_spec(kind)?;
    fingerprint(&spec, REFERENCE_RATE_HZ, REFERENCE_QUANTIZATION_M).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_kind_has_a_reference_and_they_differ() {
        let mut prints = [0u64; KINDS.len()];
        for (i, kind) in KINDS.iter().enumerate() {
            prints[i] = reference_fingerprint(kind).unwrap();
        }
        for i in 0..prints.len() {
            for j in 0..i {
                assert_ne!(prints[i], prints[j], "{} and {}", KINDS[i], KINDS[j]);
            }
        }
        assert_eq!(reference_fingerprint("pid"), None);
    }
}
