//! Estimate of the Lipschitz constant C of a trace's derivative, i.e. a bound
//! on |ẍ| (2011 paper eqs. 4–5), from a recorded, quantized position trace.
//!
//! The papers fitted a sum of seven sines to a wall-hit trace and took the
//! largest |second derivative| of the fit (2011 paper §2.4, Fig. 4). We fit
//! a local quadratic instead (Savitzky–Golay): at each sample k, the least-
//! squares parabola through `y_{k−M} … y_{k+M}` has second derivative
//! `ẍ_k = 2·a2/T²`, `a2 = Σ (i² − m̄)·y_{k+i} / Σ (i² − m̄)²`, `m̄ = M(M+1)/3`.
//! Its noise, for a sample error of standard deviation σ, is
//! `σ_ẍ = 2σ/(T²·√S)`, `S = Σ (i² − m̄)²`, which falls as M^−5/2. M starts at 2
//! and grows by a quarter until three noise standard deviations are at most
//! 10 % of the largest |ẍ| found; C is that largest |ẍ|. σ is `d/√3` when the
//! quantization step d is given (error uniform in ±d, Janabi-Sharifi eq. 1),
//! otherwise the RMS residual of the local fits. A wide window smooths sharp
//! peaks (a wall impact), so C can come out low: the report says the window.

use serde::Serialize;

use crate::error::{require_positive, SpecError};

#[derive(Debug, Clone, Serialize)]
pub struct LipschitzEstimate {
    /// C = max |ẍ| (m/s²).
    pub lipschitz: f64,
    /// Time of the maximum (s from the first sample).
    pub at_s: f64,
    /// Half-width M of the fit window (samples) and the window length 2M+1 in seconds.
    pub half_window: usize,
    pub window_s: f64,
    /// Position noise σ assumed (m) and the resulting 1-σ noise of ẍ (m/s²).
    pub position_noise: f64,
    pub noise_floor: f64,
    pub method: &'static str,
}

const METHOD: &str = "local quadratic least-squares (Savitzky-Golay) second derivative, window widened until 3 noise sigma <= 10% of max|x''|";

/// Second derivatives by the local quadratic fit of half-width `m`, for k in m..len−m.
fn second_derivatives(y: &[f64], m: usize, t: f64) -> (Vec<f64>, f64, f64) {
    let mi = m as i64;
    let mbar = (m * (m + 1)) as f64 / 3.0;
    let w: Vec<f64> = (-mi..=mi).map(|i| (i * i) as f64 - mbar).collect();
    let s: f64 = w.iter().map(|v| v * v).sum();
    let scale = 2.0 / (s * t * t);
    let mut resid2 = 0.0;
    let mut count = 0usize;
    let acc: Vec<f64> = y
        .windows(2 * m + 1)
        .map(|win| {
            let a2 = win.iter().zip(&w).map(|(y, w)| y * w).sum::<f64>();
            // Residual of the fit at the centre: y_k − (mean-adjusted parabola at i = 0).
            let mean = win.iter().sum::<f64>() / win.len() as f64;
            let fit0 = mean - (a2 / s) * mbar;
            let r = win[m] - fit0;
            resid2 += r * r;
            count += 1;
            a2 * scale
        })
        .collect();
    (acc, s, (resid2 / count.max(1) as f64).sqrt())
}

/// Largest |position| accepted (m).
pub const POSITION_MAX: f64 = 1e6;

/// Estimate C from positions `y` (m) sampled at `rate_hz`; `quantization` (m) if known.
pub fn estimate(
    y: &[f64],
    rate_hz: f64,
    quantization: Option<f64>,
) -> Result<LipschitzEstimate, SpecError> {
    require_positive("rate", rate_hz, "Hz")?;
    if let Some(d) = quantization {
        require_positive("quantization", d, "m")?;
    }
    if y.len() < 5 {
        return Err(SpecError::new(
            "positions",
            y.len(),
            "need at least 5 samples",
        ));
    }
    // |y| ≤ 1e6 m and rate ≤ 1e9 Hz keep the second differences (y/T²)
    // finite: C is then at most ~1e25 m/s².
    if let Some(k) = y
        .iter()
        .position(|v| !(v.is_finite() && v.abs() <= POSITION_MAX))
    {
        return Err(SpecError::new(
            format!("positions[{k}]"),
            y[k],
            format!("every sample must be a finite position within ±{POSITION_MAX:e} m"),
        ));
    }
    if rate_hz > 1e9 {
        return Err(SpecError::new("rate", rate_hz, "must be at most 1e9 Hz"));
    }
    let t = 1.0 / rate_hz;
    let mut m = 2usize;
    let max_m = (y.len() - 1) / 2;
    loop {
        let (acc, s, resid) = second_derivatives(y, m, t);
        let sigma = quantization.map(|d| d / 3f64.sqrt()).unwrap_or(resid);
        let noise = 2.0 * sigma / (t * t * s.sqrt());
        let (k, c) = acc.iter().enumerate().fold((0, 0.0f64), |best, (k, a)| {
            if a.abs() > best.1 {
                (k, a.abs())
            } else {
                best
            }
        });
        let next = (m + m / 4).max(m + 1);
        if 3.0 * noise <= 0.1 * c || next > max_m {
            return Ok(LipschitzEstimate {
                lipschitz: c,
                at_s: (k + m) as f64 * t,
                half_window: m,
                window_s: (2 * m) as f64 * t,
                position_noise: sigma,
                noise_floor: noise,
                method: METHOD,
            });
        }
        m = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::signals::{sample, DampedSine};

    #[test]
    fn recovers_the_known_bound_of_a_damped_sine() {
        // The 2011 paper's eq. 11 signal, quantized to 1 µm at 10 kHz: its
        // exact sup|f''| comes from the closed-form second derivative.
        let sig = DampedSine::chawda_2011();
        let (y, _) = sample(&sig, 1e4, 5.0, 1e-6);
        let exact = sig.lipschitz(5.0);
        for q in [Some(1e-6), None] {
            let est = estimate(&y, 1e4, q).unwrap();
            assert!(
                (est.lipschitz / exact - 1.0).abs() < 0.1,
                "{q:?}: {est:?} vs {exact}"
            );
            assert!(
                est.noise_floor * 3.0 <= 0.1 * est.lipschitz
                    || est.half_window * 2 + 1 >= y.len() - 1
            );
        }
    }

    #[test]
    fn exact_parabola_gives_its_curvature() {
        // y = 0.5·a·t² with a = 3 m/s²: every local quadratic fit is exact.
        let y: Vec<f64> = (0..100)
            .map(|k| 0.5 * 3.0 * (k as f64 * 1e-3).powi(2))
            .collect();
        let est = estimate(&y, 1e3, Some(1e-12)).unwrap();
        assert!((est.lipschitz - 3.0).abs() < 1e-6, "{est:?}");
    }

    #[test]
    fn rejects_bad_input() {
        assert_eq!(
            estimate(&[0.0; 3], 1e3, None).unwrap_err().field,
            "positions"
        );
        assert_eq!(
            estimate(&[0.0, 1.0, f64::NAN, 0.0, 0.0], 1e3, None)
                .unwrap_err()
                .field,
            "positions[2]"
        );
        assert_eq!(estimate(&[0.0; 10], 0.0, None).unwrap_err().field, "rate");
    }
}
