//! Triple-integrator Kalman filter (Bélanger; Janabi-Sharifi et al. 2000
//! eqs. 3–7, 2018 paper eqs. 2–4), optionally with an optimal fading factor
//! (Janabi-Sharifi eqs. 8–10, completed as below).
//!
//! Model: state `(x, ẋ, ẍ)`, `A = [[1,T,T²/2],[0,1,T],[0,0,1]]`, `H = [1,0,0]`,
//! measurement variance `r = d²/3` for an error uniform in ±d (eq. 1).
//! Process noise `Q`:
//! - `WhiteJerk`: `q·[[T⁵/20,T⁴/8,T³/6],[T⁴/8,T³/3,T²/2],[T³/6,T²/2,T]]`, the
//!   discretized white-jerk model (the 2018 paper's eq. after (4), with its
//!   misprinted factorial corrected; `q` in m²/s⁵);
//! - `Diagonal`: `diag(0, 0, q)` as Janabi-Sharifi eq. 6 (`q` in m²/s⁴ per step).
//!
//! Start-up: FDM output for the first two samples, then from samples 0..2
//! `x = y2, v = (y2−y1)/T, a = (y2−2y1+y0)/T²` with
//! `P0 = diag(d²/3, 2d²/(3T²), 2d²/T⁴)` (Janabi-Sharifi eq. 18).
//!
//! Numerics: the filter runs on the scaled state `z = (x, T·ẋ, T²·ẍ)` (all in
//! metres), where `A` becomes `[[1,1,½],[0,1,1],[0,0,1]]`, `P0` becomes
//! `diag(d²/3, 2d²/3, 2d²)` and `Q` becomes `q·T⁵·[[1/20,1/8,1/6],[1/8,1/3,1/2],[1/6,1/2,1]]`
//! (or `diag(0,0,q·T⁴)`): no `T⁵ ≈ 1e-30` next to `1/T⁴ ≈ 1e24`, so the
//! covariance stays well conditioned from 100 Hz to 1 MHz. The covariance is
//! stored as its upper triangle and updated as `P − P·Hᵀ·H·P/s`, which keeps it
//! exactly symmetric; the position variance uses the equivalent `p00·r/s`,
//! which cannot go negative.
//!
//! Fading factor (adaptive filter). Janabi-Sharifi's eq. 10 prints
//! `N_k = H P_{k,k−1} Hᵀ − H Q Hᵀ`, which has no measured quantity in it. We
//! use Xia, Rao & Ying's optimal fading factor (the reference [14] there):
//! the innovation `γ_k = y_k − H A x̂_{k−1}` feeds a covariance estimate
//! `C_1 = γ_1²`, `C_k = (ρ·C_{k−1} + γ_k²)/(1 + ρ)`, and
//! `N_k = C_k − H Q Hᵀ − r`, `M_k = H A P_{k−1} Aᵀ Hᵀ`,
//! `λ_k = max(1, N_k / M_k)` (eq. 9 with scalar N, M); then
//! `P_{k,k−1} = λ_k A P_{k−1} Aᵀ + Q` (eq. 8).
//!
//! Subnormals: the scaled velocity and acceleration, the covariance and
//! the innovation covariance are flushed below [`crate::FLUSH`] each step.

use crate::error::positive;
use crate::fdm::Fdm;
use crate::math::flush;
use crate::math::powi;
use crate::Error;

/// ρ's default: 0.95.
pub const DEFAULT_RHO: f64 = 0.95;

/// Which process-noise covariance (see module doc).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum QModel {
    #[default]
    WhiteJerk,
    Diagonal,
}

/// Upper triangle of a symmetric 3×3 matrix: `[p00, p01, p02, p11, p12, p22]`.
pub type Sym3 = [f64; 6];

#[derive(Debug, Clone, PartialEq)]
pub struct Kalman {
    t: f64,
    /// Scaled process noise.
    q: Sym3,
    /// Measurement variance r = d²/3 (m²).
    r: f64,
    /// Scaled initial covariance.
    p0: Sym3,
    /// Fading: forgetting factor ρ of the innovation covariance, if adaptive.
    rho: Option<f64>,
    // --- state ---
    fdm: Fdm,
    warmup: [f64; 3],
    count: u8,
    z: [f64; 3],
    p: Sym3,
    innovation_cov: Option<f64>,
    last_lambda: f64,
}

impl Kalman {
    /// `q` > 0; `rho` in (0, 1) for the adaptive filter; `rate_hz` and the
    /// encoder step `quantization` (m) > 0.
    pub fn new(
        q: f64,
        model: QModel,
        rho: Option<f64>,
        rate_hz: f64,
        quantization: f64,
    ) -> Result<Self, Error> {
        positive("q", q)?;
        positive("rate_hz", rate_hz)?;
        positive("quantization", quantization)?;
        if let Some(rho) = rho {
            if !(rho.is_finite() && rho > 0.0 && rho < 1.0) {
                return Err(Error::Parameter {
                    name: "rho",
                    value: rho,
                    allowed: "must be strictly between 0 and 1",
                });
            }
        }
        let t = 1.0 / rate_hz;
        let d2 = quantization * quantization;
        let q = match model {
            QModel::WhiteJerk => {
                let s5 = q * powi(t, 5);
                [s5 / 20.0, s5 / 8.0, s5 / 6.0, s5 / 3.0, s5 / 2.0, s5]
            }
            QModel::Diagonal => [0.0, 0.0, 0.0, 0.0, 0.0, q * powi(t, 4)],
        };
        if q.iter().any(|v| !v.is_finite()) || !(d2 > 0.0 && d2.is_finite()) {
            return Err(Error::Parameter {
                name: "q",
                value: q[5],
                allowed: "q·T⁵ (and d²) must be finite: use a smaller q",
            });
        }
        Ok(Self {
            t,
            q,
            r: d2 / 3.0,
            p0: [d2 / 3.0, 0.0, 0.0, 2.0 * d2 / 3.0, 0.0, 2.0 * d2],
            rho,
            fdm: Fdm::new(t),
            warmup: [0.0; 3],
            count: 0,
            z: [0.0; 3],
            p: [0.0; 6],
            innovation_cov: None,
            last_lambda: 1.0,
        })
    }

    /// Current covariance of `(x, ẋ, ẍ)` in SI units (m², m²/s², m²/s⁴), upper triangle.
    pub fn covariance(&self) -> Sym3 {
        let (t, t2) = (self.t, self.t * self.t);
        let p = &self.p;
        [
            p[0],
            p[1] / t,
            p[2] / t2,
            p[3] / t2,
            p[4] / (t * t2),
            p[5] / (t2 * t2),
        ]
    }

    /// The sample period T (s).
    pub fn period(&self) -> f64 {
        self.t
    }

    /// ρ of the adaptive filter (None: the plain filter).
    pub fn rho(&self) -> Option<f64> {
        self.rho
    }

    /// The fading factor used at the last step (1 for the plain filter).
    pub fn last_lambda(&self) -> f64 {
        self.last_lambda
    }

    /// The scaled process noise and measurement variance (the coefficients).
    pub fn coefficients(&self) -> (Sym3, f64, Sym3) {
        (self.q, self.r, self.p0)
    }

    #[inline]
    fn filter(&mut self, y: f64) -> f64 {
        let [z0, z1, z2] = self.z;
        let p = self.p;
        // Prediction x̂_{k,k−1} = A x̂ (scaled A).
        let zp = [z0 + z1 + 0.5 * z2, z1 + z2, z2];
        // M = A P Aᵀ, unrolled (rows of A: [1,1,½], [0,1,1], [0,0,1]).
        let b00 = p[0] + p[1] + 0.5 * p[2];
        let b01 = p[1] + p[3] + 0.5 * p[4];
        let b02 = p[2] + p[4] + 0.5 * p[5];
        let b11 = p[3] + p[4];
        let b12 = p[4] + p[5];
        let m = [b00 + b01 + 0.5 * b02, b01 + b02, b02, b11 + b12, b12, p[5]];
        let gamma = y - zp[0];
        let lambda = match self.rho {
            None => 1.0,
            Some(rho) => {
                let c = match self.innovation_cov {
                    None => gamma * gamma,
                    Some(c) => (rho * c + gamma * gamma) / (1.0 + rho),
                };
                self.innovation_cov = Some(flush(c));
                let n = c - self.q[0] - self.r;
                if m[0] > 0.0 && n > m[0] {
                    n / m[0]
                } else {
                    1.0
                }
            }
        };
        self.last_lambda = lambda;
        let mut pp = [0.0; 6];
        for i in 0..6 {
            pp[i] = lambda * m[i] + self.q[i];
        }
        // Update with scalar innovation variance s = H P Hᵀ + r.
        let s = pp[0] + self.r;
        let inv_s = 1.0 / s;
        let k = [pp[0] * inv_s, pp[1] * inv_s, pp[2] * inv_s];
        self.z = [
            zp[0] + k[0] * gamma,
            flush(zp[1] + k[1] * gamma),
            flush(zp[2] + k[2] * gamma),
        ];
        self.p = [
            flush(pp[0] * self.r * inv_s),
            flush(pp[1] - k[0] * pp[1]),
            flush(pp[2] - k[0] * pp[2]),
            flush(pp[3] - k[1] * pp[1]),
            flush(pp[4] - k[1] * pp[2]),
            flush(pp[5] - k[2] * pp[2]),
        ];
        self.z[1] / self.t
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        if self.count >= 3 {
            return self.filter(y);
        }
        let v = self.fdm.step(y);
        self.warmup[self.count as usize] = y;
        self.count += 1;
        if self.count == 3 {
            let [y0, y1, y2] = self.warmup;
            // Scaled initial state (x, T·v, T²·a) from eq. 18's estimates.
            self.z = [y2, y2 - y1, y2 - 2.0 * y1 + y0];
            self.p = self.p0;
        }
        v
    }

    pub fn reset(&mut self) {
        self.fdm.reset();
        self.warmup = [0.0; 3];
        self.count = 0;
        self.z = [0.0; 3];
        self.p = [0.0; 6];
        self.innovation_cov = None;
        self.last_lambda = 1.0;
    }

    /// The scaled state and covariance, for the subnormal test.
    pub fn state(&self) -> ([f64; 3], Sym3, Option<f64>) {
        (self.z, self.p, self.innovation_cov)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn covariance_is_reported_in_si_units() {
        // The filter's state is scaled (x, ẋT, ẍT²) (the 2018 paper's
        // white-jerk model in sample units), so its covariance entries
        // scale by T^{-(i+j)}: P_xv = p01/T, P_xa = p02/T², P_vv = p11/T²,
        // P_va = p12/T³, P_aa = p22/T⁴.
        let t = 0.01;
        let mut k = Kalman::new(1e4, QModel::WhiteJerk, None, 1.0 / t, 1e-6).unwrap();
        k.p = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0];
        let c = k.covariance();
        let want = [
            1.0,
            2.0 / t,
            3.0 / (t * t),
            4.0 / (t * t),
            5.0 / (t * t * t),
            6.0 / (t * t * t * t),
        ];
        for (g, w) in c.iter().zip(want) {
            assert!(crate::math::abs(g / w - 1.0) < 1e-12, "{c:?} vs {want:?}");
        }
    }
}
