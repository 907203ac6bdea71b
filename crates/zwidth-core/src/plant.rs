//! The device `m ẍ + b ẋ = F − f_c·sign(ẋ)` advanced exactly over intervals
//! where the applied force F is constant (zero-order hold).
//!
//! Exact solution with `a = b·t/m` (DESIGN.md, "Plant between force updates"):
//! `v(t) = v0·e^{−a} + (F/m)·t·φ(a)`, `x(t) = x0 + v0·t·φ(a) + (F/m)·t²·ψ(a)`,
//! `φ(a) = (1 − e^{−a})/a`, `ψ(a) = (a − 1 + e^{−a})/a²`. Written this way
//! there is no `1/b²`: φ and ψ use `expm1` and, for small a, their Taylor
//! series, so b = 0 (a pure mass) is exact too.
//!
//! An amplifier (current loop) with bandwidth f_a, when the scene names one,
//! lags the motor force behind its command: `τ Ḟ_a = F_cmd − F_a`,
//! `τ = 1/(2π f_a)`: a current loop closed to bandwidth f_a, as the 2011
//! paper's device drives its motor (a PWM amplifier in current mode, §3),
//! modelled by its dominant pole. External forces act on the handle
//! directly. Without friction the three states (x, v, F_a) step exactly
//! (`linalg::zoh`); with friction the step uses the lagged force's mean over
//! the interval, `F_cmd + (F_a − F_cmd)·φ(T/τ)` (its impulse exact), as the
//! constant force of the stick–slip step below.
//!
//! Coulomb friction with real stick–slip (static = kinetic, 2018 paper §V):
//! while moving, friction is `−f_c·sign(v)`; when v reaches 0 inside an
//! interval (found exactly from the closed form) the handle sticks if
//! `|F| ≤ f_c`, else slips on in the direction of F.

use crate::linalg::{self, Mat};

/// φ(a) = (1 − e^{−a})/a.
#[inline]
pub fn phi(a: f64) -> f64 {
    if a < 1e-8 {
        1.0 - 0.5 * a
    } else {
        -(-a).exp_m1() / a
    }
}

/// ψ(a) = (a − 1 + e^{−a})/a², → 1/2 as a → 0.
#[inline]
pub fn psi(a: f64) -> f64 {
    if a < 1e-3 {
        0.5 - a / 6.0 + a * a / 24.0 - a * a * a / 120.0
    } else {
        (a + (-a).exp_m1()) / (a * a)
    }
}

/// Position (m), velocity (m/s) and the motor force the actuator delivered
/// over the last step (N; with an amplifier lag, its value at the step's end).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    pub x: f64,
    pub v: f64,
    pub f: f64,
}

/// The amplifier's first-order lag stepped exactly over one interval.
#[derive(Debug, Clone)]
struct Lag {
    /// e^{−T/τ} and φ(T/τ): the force's decay and its mean over a step.
    decay: f64,
    mean: f64,
    /// The exact step of (x, v, F_a) with inputs (F_cmd, F_ext).
    phi: Mat,
    gamma: Mat,
}

/// The plant with its step constants for one fixed interval `dt`.
#[derive(Debug, Clone)]
pub struct Plant {
    pub mass: f64,
    pub damping: f64,
    pub coulomb: f64,
    dt: f64,
    /// x += v·c_xv + F·c_xf; v = v·c_vv + F·c_vf.
    c_xv: f64,
    c_xf: f64,
    c_vv: f64,
    c_vf: f64,
    lag: Option<Lag>,
}

impl Plant {
    /// `mass` > 0, `damping` ≥ 0, `coulomb` ≥ 0, `dt` > 0 (validated by the scene).
    pub fn new(mass: f64, damping: f64, coulomb: f64, dt: f64) -> Self {
        let a = damping * dt / mass;
        Self {
            mass,
            damping,
            coulomb,
            dt,
            c_xv: dt * phi(a),
            c_xf: dt * dt * psi(a) / mass,
            c_vv: (-a).exp(),
            c_vf: dt * phi(a) / mass,
            lag: None,
        }
    }

    /// The same plant behind an amplifier of bandwidth `hz` (None: ideal).
    pub fn with_amplifier(mut self, hz: Option<f64>) -> Self {
        self.lag = hz.map(|hz| {
            let tau = 1.0 / (2.0 * std::f64::consts::PI * hz);
            let (m, b) = (self.mass, self.damping);
            // ẋ = v, m v̇ = −b v + F_a + F_ext, τ Ḟ_a = F_cmd − F_a.
            let a = vec![
                vec![0.0, 1.0, 0.0],
                vec![0.0, -b / m, 1.0 / m],
                vec![0.0, 0.0, -1.0 / tau],
            ];
            let bm = vec![vec![0.0, 0.0], vec![0.0, 1.0 / m], vec![1.0 / tau, 0.0]];
            let (phi_m, gamma) = linalg::zoh(&a, &bm, self.dt);
            Lag {
                decay: (-self.dt / tau).exp(),
                mean: phi(self.dt / tau),
                phi: phi_m,
                gamma,
            }
        });
        self
    }

    /// The exact step `(x, v, F_a) ← Φ·(x, v, F_a) + Γ·(F_cmd, F_ext)` of
    /// a plant with an amplifier lag (None without one).
    pub fn lag_zoh(&self) -> Option<(&Mat, &Mat)> {
        self.lag.as_ref().map(|l| (&l.phi, &l.gamma))
    }

    /// One fixed interval with the motor commanded to `motor` (through the
    /// amplifier, if any) and `ext` acting on the handle; `friction`: with
    /// Coulomb friction and stick–slip (module doc).
    #[inline]
    pub fn step_driven(&self, s: &mut PlantState, motor: f64, ext: f64, friction: bool) {
        match &self.lag {
            None => {
                s.f = motor;
                if friction {
                    self.step_friction(s, motor + ext);
                } else {
                    self.step_linear(s, motor + ext);
                }
            }
            Some(l) if !friction => {
                let st = [s.x, s.v, s.f];
                let next = |i: usize| {
                    l.phi[i].iter().zip(st).map(|(p, x)| p * x).sum::<f64>()
                        + l.gamma[i][0] * motor
                        + l.gamma[i][1] * ext
                };
                (s.x, s.v, s.f) = (next(0), next(1), next(2));
            }
            Some(l) => {
                let mean = motor + (s.f - motor) * l.mean;
                self.step_friction(s, mean + ext);
                s.f = motor + (s.f - motor) * l.decay;
            }
        }
    }

    /// The ZOH-discretized plant `x_{k+1} = A x_k + B F_k` for the fixed dt:
    /// `A = [[1, c_xv], [0, c_vv]]`, `B = [c_xf, c_vf]`.
    pub fn zoh(&self) -> ([[f64; 2]; 2], [f64; 2]) {
        ([[1.0, self.c_xv], [0.0, self.c_vv]], [self.c_xf, self.c_vf])
    }

    /// One fixed interval, no friction: the exact ZOH step.
    #[inline]
    pub fn step_linear(&self, s: &mut PlantState, f: f64) {
        let x = s.x + s.v * self.c_xv + f * self.c_xf;
        s.v = s.v * self.c_vv + f * self.c_vf;
        s.x = x;
    }

    /// Advance by an arbitrary `t` under constant net force `f`, no friction.
    #[inline]
    fn advance(&self, s: &mut PlantState, f: f64, t: f64) {
        let a = self.damping * t / self.mass;
        let (ph, ps) = (phi(a), psi(a));
        s.x += s.v * t * ph + f / self.mass * t * t * ps;
        s.v = s.v * (-a).exp() + f / self.mass * t * ph;
    }

    /// Time for the velocity to reach 0 from `v0 ≠ 0` under net force `f`
    /// opposing it (closed form of v(t) = 0).
    #[inline]
    fn time_to_stop(&self, v0: f64, f: f64) -> f64 {
        if self.damping == 0.0 {
            -v0 * self.mass / f
        } else {
            // v(t) = v∞ + (v0 − v∞)e^{−t/τ}, v∞ = f/b: zero at t = τ·ln(1 − v0/v∞).
            let tau = self.mass / self.damping;
            tau * (-v0 * self.damping / f).ln_1p()
        }
    }

    /// One fixed interval with Coulomb friction and stick–slip; `f` is the
    /// applied (motor + external) force.
    #[inline]
    pub fn step_friction(&self, s: &mut PlantState, f: f64) {
        let fc = self.coulomb;
        let mut left = self.dt;
        let mut full = true; // the whole fixed interval: use the precomputed step
        for _ in 0..3 {
            let dir = if s.v != 0.0 {
                s.v.signum()
            } else if f.abs() <= fc {
                return; // sticks for the rest of the interval
            } else {
                f.signum()
            };
            let net = f - fc * dir;
            if s.v != 0.0 && net * dir < 0.0 {
                let t_stop = self.time_to_stop(s.v, net);
                if t_stop < left {
                    self.advance(s, net, t_stop);
                    s.v = 0.0;
                    left -= t_stop;
                    full = false;
                    continue;
                }
            }
            if full {
                self.step_linear(s, net);
            } else {
                self.advance(s, net, left);
            }
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_and_closed_forms_agree() {
        // Reference: the closed forms φ(a) = (1 − e^{−a})/a and
        // ψ(a) = (a − 1 + e^{−a})/a² where they are well conditioned (a ≥
        // 0.1), their Taylor series φ = Σ (−a)^n/(n+1)!, ψ = Σ (−a)^n/(n+2)!
        // (twelve terms: the rest is below 1e-16 for a ≤ 0.1) below.
        let series = |a: f64, shift: u32| {
            let (mut sum, mut term) = (0.0, 1.0);
            for i in 1..=shift {
                term /= i as f64;
            }
            for n in 0..12 {
                sum += term;
                term *= -a / (n + shift + 1) as f64;
            }
            sum
        };
        for a in [1e-9f64, 1e-6, 5e-4, 1.5e-3, 0.01, 0.1, 1.0, 30.0] {
            let (p, q) = if a >= 0.1 {
                ((1.0 - (-a).exp()) / a, (a - 1.0 + (-a).exp()) / (a * a))
            } else {
                (series(a, 1), series(a, 2))
            };
            assert!(
                (phi(a) - p).abs() <= 1e-13 * p,
                "phi {a}: {} vs {p}",
                phi(a)
            );
            assert!(
                (psi(a) - q).abs() <= 1e-13 * q,
                "psi {a}: {} vs {q}",
                psi(a)
            );
        }
        assert_eq!(psi(0.0), 0.5);
        assert_eq!(phi(0.0), 1.0);
    }

    #[test]
    fn exact_against_analytic_solution() {
        // m = 0.5, b = 2, F = 1 from rest: v(t) = (F/b)(1 − e^{−bt/m}),
        // x(t) = (F/b)(t − (m/b)(1 − e^{−bt/m})).
        let p = Plant::new(0.5, 2.0, 0.0, 1e-3);
        let mut s = PlantState::default();
        for _ in 0..1000 {
            p.step_linear(&mut s, 1.0);
        }
        let t: f64 = 1.0;
        let v = 0.5 * (1.0 - (-4.0 * t).exp());
        let x = 0.5 * (t - 0.25 * (1.0 - (-4.0 * t).exp()));
        assert!((s.v - v).abs() < 1e-12 && (s.x - x).abs() < 1e-12, "{s:?}");
        // b = 0: a pure mass, x = F t²/(2m).
        let p = Plant::new(2.0, 0.0, 0.0, 1e-2);
        let mut s = PlantState::default();
        for _ in 0..100 {
            p.step_linear(&mut s, 3.0);
        }
        assert!((s.x - 0.75).abs() < 1e-12 && (s.v - 1.5).abs() < 1e-12);
    }

    #[test]
    fn damped_stop_time_and_position_are_the_closed_form() {
        // m = 0.5, b = 2, f_c = 1, v0 = 1, no applied force: net force −1 N,
        // v∞ = −0.5 m/s, τ = m/b = 0.25 s. v(t) = v∞ + (v0 − v∞)e^{−t/τ} is
        // zero at t* = τ·ln(1 − v0/v∞) = 0.25·ln 3, where
        // x(t*) = v∞·t* + τ(v0 − v∞)(1 − e^{−t*/τ}) = −0.125 ln 3 + 0.25.
        let p = Plant::new(0.5, 2.0, 1.0, 1.0);
        let t_star = 0.25 * 3f64.ln();
        assert!((p.time_to_stop(1.0, -1.0) - t_star).abs() < 1e-14);
        // One 1 s interval: it stops at t* and sticks for the rest.
        let mut s = PlantState {
            x: 0.0,
            v: 1.0,
            f: 0.0,
        };
        p.step_friction(&mut s, 0.0);
        assert_eq!(s.v, 0.0);
        let x_star = -0.125 * 3f64.ln() + 0.25;
        assert!((s.x - x_star).abs() < 1e-12, "{s:?} vs {x_star}");
        // Moving the other way, pushed on by 0.5 N (< f_c): net −0.5 − 1·(−1)
        // = +0.5 N decelerates v0 = −1; v∞ = +0.25, t* = 0.25·ln(1 + 4).
        let mut s = PlantState {
            x: 0.0,
            v: -1.0,
            f: 0.0,
        };
        assert!((p.time_to_stop(-1.0, 0.5) - 0.25 * 5f64.ln()).abs() < 1e-14);
        p.step_friction(&mut s, -0.5);
        assert_eq!(s.v, 0.0);
        let t = 0.25 * 5f64.ln();
        let x = 0.25 * t + 0.25 * (-1.25) * (1.0 - (-t / 0.25).exp());
        assert!((s.x - x).abs() < 1e-12, "{s:?} vs {x}");
    }

    #[test]
    fn coulomb_stops_and_sticks() {
        // m = 1, b = 0, f_c = 1, v0 = 1, F = 0.5 (< f_c): decelerates at 0.5 m/s²,
        // stops at t = 2 s after x = v0²/(2·0.5) = 1 m, then sticks.
        let p = Plant::new(1.0, 0.0, 1.0, 0.3);
        let mut s = PlantState {
            x: 0.0,
            v: 1.0,
            f: 0.0,
        };
        for _ in 0..20 {
            p.step_friction(&mut s, 0.5);
        }
        assert_eq!(s.v, 0.0);
        assert!((s.x - 1.0).abs() < 1e-12, "{s:?}");
        // From rest, a force above f_c slips: F = 3 gives a = 2 m/s².
        let p = Plant::new(1.0, 0.0, 1.0, 0.5);
        let mut s = PlantState::default();
        p.step_friction(&mut s, 3.0);
        assert!((s.v - 1.0).abs() < 1e-12 && (s.x - 0.25).abs() < 1e-12);
        // Reversal: moving at −1 m/s with F = +3: stops after 0.25 s (net 4 N),
        // then slips forward with net 2 N for the remaining 0.25 s.
        let mut s = PlantState {
            x: 0.0,
            v: -1.0,
            f: 0.0,
        };
        p.step_friction(&mut s, 3.0);
        assert!((s.v - 0.5).abs() < 1e-12, "{s:?}");
        assert!((s.x - (-0.125 + 0.0625)).abs() < 1e-12, "{s:?}");
    }

    #[test]
    fn an_amplifier_lag_is_stepped_exactly() {
        // A pure mass (m = 2 kg, b = 0) from rest, command c = 3 N from
        // F_a = 0, τ = 1/(2π·50 Hz): F_a = c(1 − e^{−t/τ}),
        // v = (c/m)(t − τ(1 − e^{−t/τ})), x = (c/m)(t²/2 − τt + τ²(1 − e^{−t/τ})).
        let (m, c, dt) = (2.0, 3.0, 1e-3);
        let tau = 1.0 / (2.0 * std::f64::consts::PI * 50.0);
        let p = Plant::new(m, 0.0, 0.0, dt).with_amplifier(Some(50.0));
        let mut s = PlantState::default();
        for _ in 0..100 {
            p.step_driven(&mut s, c, 0.0, false);
        }
        let t: f64 = 0.1;
        let e = 1.0 - (-t / tau).exp();
        let (f, v, x) = (
            c * e,
            c / m * (t - tau * e),
            c / m * (t * t / 2.0 - tau * t + tau * tau * e),
        );
        assert!(
            (s.f - f).abs() < 1e-12 && (s.v - v).abs() < 1e-13 && (s.x - x).abs() < 1e-14,
            "{s:?} vs {x} {v} {f}"
        );
        // An external force acts at once, not through the lag: with the
        // motor off, as the plant without an amplifier.
        let (lagged, plain) = (p.clone(), Plant::new(m, 0.0, 0.0, dt));
        let (mut a, mut b) = (PlantState::default(), PlantState::default());
        for _ in 0..10 {
            lagged.step_driven(&mut a, 0.0, 1.0, false);
            plain.step_driven(&mut b, 0.0, 1.0, false);
        }
        assert!(
            (a.x - b.x).abs() < 1e-16 && (a.v - b.v).abs() < 1e-15,
            "{a:?} vs {b:?}"
        );
        // Without an amplifier the motor force is applied as commanded.
        plain.step_driven(&mut b, 2.5, 0.0, false);
        assert_eq!(b.f, 2.5);
    }

    #[test]
    fn with_friction_the_lagged_force_s_impulse_is_exact() {
        // The same mass sliding forward (never stopping) against f_c =
        // 0.5 N: each step applies the lagged force's mean, so the velocity
        // is the exact impulse, v = (c(t − τ(1 − e^{−t/τ})) − f_c·t)/m + v0.
        let (m, c, fc, dt, v0) = (2.0, 3.0, 0.5, 1e-3, 1.0);
        let tau = 1.0 / (2.0 * std::f64::consts::PI * 50.0);
        let p = Plant::new(m, 0.0, fc, dt).with_amplifier(Some(50.0));
        let mut s = PlantState {
            v: v0,
            ..PlantState::default()
        };
        for _ in 0..100 {
            p.step_driven(&mut s, c, 0.0, true);
        }
        let t: f64 = 0.1;
        let e = 1.0 - (-t / tau).exp();
        let v = v0 + (c * (t - tau * e) - fc * t) / m;
        assert!(
            (s.v - v).abs() < 1e-12 && (s.f - c * e).abs() < 1e-12,
            "{s:?} vs {v}"
        );
    }
}
