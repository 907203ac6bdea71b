//! Test signals with exact derivatives, and encoder quantization.

use serde::{Deserialize, Serialize};

/// `f(t) = A·e^{−a t}·sin(2π f0 t)` (m): the 2011 paper's eq. 11 is
/// A = 50 mm = 0.05 m, a = 1 1/s, f0 = 1 Hz.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct DampedSine {
    /// Amplitude A (m).
    pub amplitude: f64,
    /// Decay rate a (1/s).
    pub decay: f64,
    /// Frequency f0 (Hz).
    pub freq_hz: f64,
}

impl DampedSine {
    /// The 2011 paper's eq. 11 in SI units.
    pub fn chawda_2011() -> Self {
        Self {
            amplitude: 0.05,
            decay: 1.0,
            freq_hz: 1.0,
        }
    }

    fn w(&self) -> f64 {
        2.0 * std::f64::consts::PI * self.freq_hz
    }

    /// Position (m).
    pub fn position(&self, t: f64) -> f64 {
        self.amplitude * (-self.decay * t).exp() * (self.w() * t).sin()
    }

    /// Exact velocity (m/s): `A e^{−at} (ω cos ωt − a sin ωt)`.
    pub fn velocity(&self, t: f64) -> f64 {
        let w = self.w();
        self.amplitude * (-self.decay * t).exp() * (w * (w * t).cos() - self.decay * (w * t).sin())
    }

    /// Exact acceleration (m/s²): `A e^{−at} ((a² − ω²) sin ωt − 2aω cos ωt)`.
    pub fn acceleration(&self, t: f64) -> f64 {
        let (w, a) = (self.w(), self.decay);
        self.amplitude
            * (-a * t).exp()
            * ((a * a - w * w) * (w * t).sin() - 2.0 * a * w * (w * t).cos())
    }

    /// sup |f''| over [0, duration] (m/s²), the Lipschitz constant C of f'
    /// (2011 paper eq. 5), on a 1 µs grid: far finer than f's 1 s time scale.
    pub fn lipschitz(&self, duration: f64) -> f64 {
        let n = (duration / 1e-6).ceil() as usize;
        (0..=n)
            .map(|k| self.acceleration(k as f64 * 1e-6).abs())
            .fold(0.0, f64::max)
    }
}

/// Round to the nearest multiple of `step` (m): an ideal encoder.
#[inline]
pub fn quantize(x: f64, step: f64) -> f64 {
    (x / step).round() * step
}

/// Sample `signal` at `rate_hz` for `duration` s: quantized positions and
/// exact velocities.
pub fn sample(signal: &DampedSine, rate_hz: f64, duration: f64, step: f64) -> (Vec<f64>, Vec<f64>) {
    let n = (duration * rate_hz).round() as usize;
    (0..n)
        .map(|k| {
            let t = k as f64 / rate_hz;
            (quantize(signal.position(t), step), signal.velocity(t))
        })
        .unzip()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn derivatives_match_finite_differences() {
        let s = DampedSine::chawda_2011();
        let h = 1e-6;
        for t in [0.0, 0.3, 1.7, 4.2] {
            let v = (s.position(t + h) - s.position(t - h)) / (2.0 * h);
            let a = (s.velocity(t + h) - s.velocity(t - h)) / (2.0 * h);
            assert!((v - s.velocity(t)).abs() < 1e-8, "{t}");
            assert!((a - s.acceleration(t)).abs() < 1e-7, "{t}");
        }
        // |f''(0)| = 2aωA = 0.2π; the sup is a little later, below the
        // envelope A(a² + ω²) = 2.024 m/s².
        let c = s.lipschitz(5.0);
        assert!(
            c >= 0.2 * std::f64::consts::PI
                && c <= 0.05 * (1.0 + 4.0 * std::f64::consts::PI.powi(2)),
            "{c}"
        );
    }

    #[test]
    fn quantize_rounds_to_step() {
        assert_eq!(quantize(1.4e-6, 1e-6), 1e-6);
        assert_eq!(quantize(-1.6e-6, 1e-6), -2e-6);
    }
}
