//! What every estimator shares: the streaming interface (one position in,
//! one velocity out), where the samples come from, the median window's
//! bound, and how a refusal of `zwidth-dsp` reads as a spec error.

use crate::error::{require_positive, SpecError};

/// A refusal of `zwidth-dsp` (what the spec checks above it did not
/// already name: a capacity, a period) as the service's error.
pub(crate) fn spec_error(e: zwidth_dsp::Error) -> SpecError {
    match e {
        zwidth_dsp::Error::Parameter {
            name,
            value,
            allowed,
        } => SpecError::new(name, crate::error::shown(value), allowed),
        zwidth_dsp::Error::Capacity { name, value, cap } => {
            SpecError::new(name, value, format!("must be at most {cap}"))
        }
    }
}

/// A streaming velocity estimator.
pub trait VelocityEstimator {
    /// Feed the next position sample `y` (m); returns the velocity estimate (m/s).
    fn update(&mut self, y: f64) -> f64;
    /// Forget all history, as if newly built.
    fn reset(&mut self);
}

/// Largest median window accepted (samples). Median smoothing adds
/// (W-1)/2 samples of delay, so anything larger is a mistake.
pub const MAX_MEDIAN_WINDOW: usize = 1001;

/// Where the samples come from: the rate they arrive at and the encoder step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sampling {
    /// Sample rate (Hz).
    pub rate_hz: f64,
    /// Quantization step of the position sensor, `d` (m); the measurement error is
    /// taken as uniform in ±d, so `r = d²/3` (Janabi-Sharifi eq. 1).
    pub quantization: f64,
}

impl Sampling {
    pub fn new(rate_hz: f64, quantization: f64) -> Result<Self, SpecError> {
        require_positive("rate", rate_hz, "Hz")?;
        require_positive("quantization", quantization, "m")?;
        Ok(Self {
            rate_hz,
            quantization,
        })
    }

    /// Sample period T (s).
    pub fn period(&self) -> f64 {
        1.0 / self.rate_hz
    }
}
