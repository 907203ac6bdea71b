//! FDM cascaded with a digital Butterworth low-pass (2011 paper §2.1,
//! 2018 paper §II-A): the analog prototype at the prewarped cutoff
//! `ω_a = 2·fs·tan(π·fc/fs)`, the bilinear transform, second-order sections
//! paired "nearest", so the coefficients equal
//! `scipy.signal.butter(order, fc, fs=fs, output='sos')` and the filtering
//! `scipy.signal.sosfilt`. The design and the filter are
//! `zwidth_dsp::butterworth` (one implementation, here and on the rig); this
//! module checks the spec with the service's messages.

use super::streaming::{spec_error, Sampling, VelocityEstimator};
use crate::error::SpecError;

pub use zwidth_dsp::butterworth::{sos_step, Sos, MAX_ORDER};

/// Check `order` and `cutoff_hz` against the sample rate `fs`.
fn check(order: u32, cutoff_hz: f64, fs: f64) -> Result<(), SpecError> {
    if !(1..=MAX_ORDER).contains(&order) {
        return Err(SpecError::new(
            "order",
            order,
            format!("must be a whole number from 1 to {MAX_ORDER}"),
        ));
    }
    let nyq = fs / 2.0;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyq) {
        return Err(SpecError::new(
            "cutoff_hz",
            cutoff_hz,
            format!("must be > 0 and below the Nyquist frequency {nyq} Hz (half the sample rate {fs} Hz)"),
        ));
    }
    Ok(())
}

/// Design the low-pass (see module doc). `cutoff_hz` in (0, fs/2), `order` in 1..=MAX_ORDER.
pub fn design_lowpass(order: u32, cutoff_hz: f64, fs: f64) -> Result<Vec<Sos>, SpecError> {
    check(order, cutoff_hz, fs)?;
    let (sos, n) =
        zwidth_dsp::butterworth::design_lowpass(order, cutoff_hz, fs).map_err(spec_error)?;
    Ok(sos[..n].to_vec())
}

/// The estimator: FDM, then the sections in cascade.
#[derive(Debug, Clone)]
pub struct Butterworth(zwidth_dsp::Butterworth);

impl Butterworth {
    pub fn new(cutoff_hz: f64, order: u32, s: Sampling) -> Result<Self, SpecError> {
        check(order, cutoff_hz, s.rate_hz)?;
        zwidth_dsp::Butterworth::new(cutoff_hz, order, s.rate_hz)
            .map(Self)
            .map_err(spec_error)
    }

    pub fn sections(&self) -> &[Sos] {
        self.0.sections()
    }
}

impl VelocityEstimator for Butterworth {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        self.0.step(y)
    }

    fn reset(&mut self) {
        self.0.reset();
    }
}

#[cfg(test)]
// Reference values are kept exactly as scipy printed them.
#[allow(clippy::excessive_precision)]
mod tests {
    use super::*;

    // scipy.signal.sosfilt(butter(2, 100, fs=1000, output='sos'), x) for
    // x = [0,1,3,2,5,4,4,6,7,9.5] (scipy 1.17.1).
    #[test]
    fn filtering_matches_scipy_sosfilt() {
        let sos = design_lowpass(2, 100.0, 1000.0).unwrap();
        let mut st = vec![[0.0; 2]; sos.len()];
        let x = [0.0, 1.0, 3.0, 2.0, 5.0, 4.0, 4.0, 6.0, 7.0, 9.5];
        let want = [
            0.0,
            0.0674552738890719,
            0.4143764322940575,
            1.0528760029643751,
            1.8418247761849027,
            2.74982529387859,
            3.529428141386221,
            4.113130204924982,
            4.795745350955962,
            5.773467289245923,
        ];
        for (xi, wi) in x.iter().zip(want) {
            let y = sos_step(&sos, &mut st, *xi);
            assert!((y - wi).abs() < 1e-12, "{y} vs {wi}");
        }
    }

    #[test]
    fn rejects_cutoff_at_nyquist_and_bad_order() {
        let e = design_lowpass(2, 500.0, 1000.0).unwrap_err();
        assert_eq!(e.field, "cutoff_hz");
        assert!(e.allowed.contains("Nyquist frequency 500 Hz"));
        assert_eq!(design_lowpass(0, 10.0, 1000.0).unwrap_err().field, "order");
        assert_eq!(design_lowpass(11, 10.0, 1000.0).unwrap_err().field, "order");
        assert_eq!(
            design_lowpass(2, f64::NAN, 1000.0).unwrap_err().field,
            "cutoff_hz"
        );
        // Zero is not a cutoff (a filter that passes nothing).
        assert_eq!(
            design_lowpass(2, 0.0, 1000.0).unwrap_err().field,
            "cutoff_hz"
        );
        // Just inside both ends is a filter.
        assert!(design_lowpass(2, 1e-3, 1000.0).is_ok());
        assert!(design_lowpass(2, 499.999, 1000.0).is_ok());
    }
}
