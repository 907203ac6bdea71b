//! The analytic engine, exact for linear single-rate scenes (DESIGN.md,
//! "Analytic anchors"): device `G(s) = 1/(m s² + b s)`, ZOH force held for T,
//! wall `H(z) = (K + B·V(z))·z^{−d}` with the estimator's exact transfer
//! function `V(z)` from position to velocity, `G_d(z)` the ZOH pulse transfer
//! function of G.
//!
//! - Impedance at the excitation frequency (what the 2018 paper's multisine
//!   test measures): `X/F(jω) = G(jω)·[1 − L·Z_h(jω)·H·G(jω) / (T·(1 + H·G_d))]`,
//!   with an amplifier lag `L(jω) = 1/(1 + jωτ)` on the motor's path only
//!   (L = 1 without one; then `G_d` is the pulse transfer function of L·G),
//!   `Z_h(s) = (1 − e^{−sT})/s`, `Z = 1/(jω·X/F)`; passive on the band iff
//!   `Re Z ≥ 0` there (phase within ±90°).
//! - Strict passivity (Colgate & Schenkel 1994): passive iff
//!   `b ≥ (T/2)·Re{(1 − e^{−jθ})H(e^{jθ})}/(1 − cos θ)` for all θ ∈ (0, π].
//!   The right side is linear in K and B, so for a given B the passive K form
//!   an interval, found exactly over a dense θ grid refined at its minimum.
//! - Stability: the closed-loop characteristic polynomial
//!   `z^d·D_g·D_v + N_g·(K·D_v + B·N_v)` (from `1 + z^{−d}·H·G_d = 0`), its
//!   roots (the closed-loop eigenvalues) inside the unit circle.
//!
//! V(z): FDM `(z − 1)/(T z)`; Butterworth FDM times its sections; Kalman the
//! steady-state filter `x̂_k = (I − K_∞H)A·x̂_{k−1} + K_∞·y_k` (the time-varying
//! filter of the simulation converges to it), its transfer function by the
//! Faddeev–LeVerrier algorithm.

use num_complex::Complex64 as C;
use serde::Serialize;

use super::poly::{self, Poly};
use super::scene::Scene;
use crate::error::SpecError;
use crate::estimators::butterworth::design_lowpass;
use crate::estimators::{EstimatorKind, QModel};
use crate::linalg;
use crate::plant::StateSpace;

#[derive(Debug, Clone)]
pub struct LinearModel {
    pub mass: f64,
    pub damping: f64,
    /// Sample (= render) period T (s).
    pub t: f64,
    pub delay: usize,
    /// The continuous device with an amplifier lag or a transmission
    /// (None: the rigid device `1/(ms² + bs)`).
    ss: Option<StateSpace>,
    v_num: Poly,
    v_den: Poly,
    g_num: Poly,
    g_den: Poly,
    /// Excited lines (rad/s).
    pub omegas: Vec<f64>,
}

/// The impedance test at one (K, B).
#[derive(Debug, Clone, Serialize)]
pub struct ImpedanceCurve {
    pub freq_hz: Vec<f64>,
    pub magnitude: Vec<f64>,
    pub phase_deg: Vec<f64>,
    pub passive: bool,
    /// RMS over the band of |Z| − |B + K/(jω)| (N·s/m), 2018 paper §V.
    pub fidelity: f64,
}

impl ImpedanceCurve {
    /// Build from complex Z at the lines; shared with the frequency engine.
    pub fn from_z(omegas: &[f64], z: &[C], k: f64, b: f64) -> Self {
        // |B + K/(jω)| = √(B² + (K/ω)²).
        let ideal = |w: f64| b.hypot(k / w);
        let fidelity = (omegas
            .iter()
            .zip(z)
            .map(|(&w, z)| (z.norm() - ideal(w)).powi(2))
            .sum::<f64>()
            / omegas.len() as f64)
            .sqrt();
        Self {
            freq_hz: omegas
                .iter()
                .map(|w| w / (2.0 * std::f64::consts::PI))
                .collect(),
            magnitude: z.iter().map(|z| z.norm()).collect(),
            phase_deg: z.iter().map(|z| z.arg().to_degrees()).collect(),
            passive: z.iter().all(|z| z.re >= 0.0),
            fidelity,
        }
    }
}

/// The smallest θ (rad/sample) the strict-passivity scan looks at: θ = 0
/// itself is 0/0 in every term.
const THETA_MIN: f64 = std::f64::consts::PI * 1e-7;

/// Iterations of the Riccati recursion before giving up on convergence.
const RICCATI_CAP: usize = 2_000_000;

/// Steady-state gain of the scaled triple-integrator Kalman filter (see
/// `estimators::kalman`), by iterating the Riccati recursion to a fixed
/// point; with the iterations it took (`RICCATI_CAP`: not converged).
fn kalman_steady_gain(q: f64, model: QModel, t: f64, d: f64) -> ([f64; 3], usize) {
    let qs = match model {
        QModel::WhiteJerk => {
            let s5 = q * t.powi(5);
            [
                [s5 / 20.0, s5 / 8.0, s5 / 6.0],
                [s5 / 8.0, s5 / 3.0, s5 / 2.0],
                [s5 / 6.0, s5 / 2.0, s5],
            ]
        }
        QModel::Diagonal => [[0.0; 3], [0.0; 3], [0.0, 0.0, q * t.powi(4)]],
    };
    let a = [[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]];
    let r = d * d / 3.0;
    let mut p = [
        [d * d / 3.0, 0.0, 0.0],
        [0.0, 2.0 * d * d / 3.0, 0.0],
        [0.0, 0.0, 2.0 * d * d],
    ];
    let mut gain = [0.0; 3];
    for it in 0..RICCATI_CAP {
        let mut pp = [[0.0; 3]; 3];
        for i in 0..3 {
            for j in 0..3 {
                pp[i][j] = (0..3)
                    .map(|k| (0..3).map(|l| a[i][k] * p[k][l] * a[j][l]).sum::<f64>())
                    .sum::<f64>()
                    + qs[i][j];
            }
        }
        let s = pp[0][0] + r;
        let new_gain = [pp[0][0] / s, pp[1][0] / s, pp[2][0] / s];
        for i in 0..3 {
            for j in 0..3 {
                p[i][j] = pp[i][j] - new_gain[i] * pp[0][j];
            }
        }
        let change = (0..3)
            .map(|i| (new_gain[i] - gain[i]).abs() / new_gain[i].abs().max(1e-300))
            .fold(0.0, f64::max);
        gain = new_gain;
        if it > 10 && change < 1e-13 {
            return (gain, it + 1);
        }
    }
    (gain, RICCATI_CAP)
}

impl LinearModel {
    /// The model of a linear single-rate scene; otherwise an error saying why not.
    pub fn new(scene: &Scene) -> Result<Self, SpecError> {
        if let Some(why) = scene.linear_reason() {
            return Err(SpecError::new(
                "method",
                "analytic",
                format!("the analytic engine needs a linear single-rate scene; this one has {why} (use method time or frequency)"),
            ));
        }
        let s = &scene.spec;
        let t = scene.dt;
        let (v_num, v_den) = match &s.estimator.kind {
            EstimatorKind::Fdm {} => (vec![-1.0, 1.0], vec![0.0, t]),
            EstimatorKind::Butterworth { cutoff_hz, order } => {
                let sos = design_lowpass(*order, *cutoff_hz, s.control.sample_hz)
                    .map_err(|e| e.within("estimator"))?;
                let mut num = vec![-1.0, 1.0];
                let mut den = vec![0.0, t];
                for c in sos {
                    num = poly::mul(&num, &[c[2], c[1], c[0]]);
                    den = poly::mul(&den, &[c[5], c[4], 1.0]);
                }
                (num, den)
            }
            EstimatorKind::Kalman { q, q_model } => {
                let (g, _) = kalman_steady_gain(*q, *q_model, t, scene.sampling.quantization);
                let a = [[1.0, 1.0, 0.5], [0.0, 1.0, 1.0], [0.0, 0.0, 1.0]];
                let mut f = [[0.0; 3]; 3];
                for i in 0..3 {
                    for j in 0..3 {
                        f[i][j] = a[i][j] - g[i] * a[0][j];
                    }
                }
                // Output: velocity = (scaled state 1)/T, of
                // s_k = F s_{k−1} + g·y_k: c·(I − F z⁻¹)⁻¹·g = z·c·adj(zI − F)·g / det.
                let f: linalg::Mat = f.iter().map(|r| r.to_vec()).collect();
                let (num, den) = linalg::transfer_function(&f, &g, &[0.0, 1.0 / t, 0.0]);
                (poly::shift(&num, 1), den)
            }
            _ => unreachable!("linear_reason() admits only FDM, Butterworth and Kalman"),
        };
        let plant = s.device.plant(t);
        let ss = plant.linear_zoh().map(|_| plant.state_space());
        let (g_num, g_den) = match (plant.linear_zoh(), &ss) {
            // G_d(z) = c_enc·(zI − Φ)⁻¹·Γ_motor of the lagged or two-mass plant.
            (Some((phi, gamma)), Some(ss)) => {
                let g: Vec<f64> = gamma.iter().map(|r| r[0]).collect();
                linalg::transfer_function(phi, &g, &ss.encoder)
            }
            _ => {
                let (a, b) = plant.zoh();
                let e = a[1][1];
                // G_d(z) = (B0 z + (A01 B1 − e B0)) / ((z − 1)(z − e)).
                (
                    vec![a[0][1] * b[1] - e * b[0], b[0]],
                    poly::mul(&[-1.0, 1.0], &[-e, 1.0]),
                )
            }
        };
        let p = &s.probe;
        let lines = (p.f_max_hz / p.f_min_hz + 1e-9).floor() as usize;
        let omegas = (1..=lines)
            .map(|k| 2.0 * std::f64::consts::PI * p.f_min_hz * k as f64)
            .collect();
        Ok(Self {
            mass: s.device.mass,
            damping: s.device.damping,
            t,
            delay: s.control.delay_samples as usize,
            ss,
            v_num,
            v_den,
            g_num,
            g_den,
            omegas,
        })
    }

    /// V(e^{jθ}) (m/s per m).
    pub fn v(&self, theta: f64) -> C {
        let z = C::from_polar(1.0, theta);
        poly::eval(&self.v_num, z) / poly::eval(&self.v_den, z)
    }

    fn h(&self, k: f64, b: f64, theta: f64) -> C {
        (self.v(theta) * b + k) * C::from_polar(1.0, -(self.delay as f64) * theta)
    }

    /// Z(jω) by the DESIGN.md formula.
    pub fn impedance_at(&self, k: f64, b: f64, w: f64) -> C {
        let j = C::new(0.0, 1.0);
        let t = self.t;
        let theta = w * t;
        let zh = (C::new(1.0, 0.0) - C::from_polar(1.0, -theta)) / (j * w);
        let h = self.h(k, b, theta);
        let z = C::from_polar(1.0, theta);
        let gd = poly::eval(&self.g_num, z) / poly::eval(&self.g_den, z);
        let one = C::new(1.0, 0.0);
        let xf = match &self.ss {
            None => {
                let g = one / (j * w * (j * w * self.mass + self.damping));
                g * (one - zh * h * g / (t * (one + h * gd)))
            }
            // The excitation acts on the handle, the wall's force on the
            // motor (through the amplifier): X_h/F = G_he − Z_h·H·G_hm·G_ee
            // / (T(1 + H·G_d)) with G_ab the response of output a (handle,
            // encoder) to input b (motor command, external force).
            Some(ss) => {
                let col = |i: usize| -> Vec<f64> { ss.b.iter().map(|r| r[i]).collect() };
                let (cmd, ext) = (col(0), col(1));
                let resp = |c: &[f64], b: &[f64]| linalg::frequency_response(&ss.a, b, c, w);
                let (g_he, g_hm, g_ee) = (
                    resp(&ss.handle, &ext),
                    resp(&ss.handle, &cmd),
                    resp(&ss.encoder, &ext),
                );
                g_he - zh * h * g_hm * g_ee / (t * (one + h * gd))
            }
        };
        let z = one / (j * w * xf);
        // A line exactly on an undamped mode has no steady state (X/F is
        // infinite): not passive, as the frequency engine reads a loop
        // that never settles, and never NaN.
        if z.is_finite() {
            z
        } else {
            C::new(-1.0, 0.0)
        }
    }

    pub fn impedance(&self, k: f64, b: f64) -> ImpedanceCurve {
        let z: Vec<C> = self
            .omegas
            .iter()
            .map(|&w| self.impedance_at(k, b, w))
            .collect();
        let mut curve = ImpedanceCurve::from_z(&self.omegas, &z, k, b);
        // Z = F/V describes a loop that settles; an unstable one renders
        // nothing (the frequency engine sees it diverge), whatever Re Z the
        // formula gives on the band.
        curve.passive &= self.spectral_radius(k, b) < 1.0;
        curve
    }

    /// The closed-loop characteristic polynomial (ascending powers).
    pub fn characteristic(&self, k: f64, b: f64) -> Poly {
        let lhs = poly::shift(&poly::mul(&self.g_den, &self.v_den), self.delay);
        let wall = poly::add(&poly::scale(&self.v_den, k), &poly::scale(&self.v_num, b));
        poly::add(&lhs, &poly::mul(&self.g_num, &wall))
    }

    /// Largest closed-loop eigenvalue magnitude; stable iff < 1.
    pub fn spectral_radius(&self, k: f64, b: f64) -> f64 {
        poly::roots(&self.characteristic(k, b))
            .iter()
            .map(|z| z.norm())
            .fold(0.0, f64::max)
    }

    /// Per θ: (a, c, r) of the strict-passivity constraint `K·a + B·c ≤ r`.
    fn passivity_terms(&self, theta: f64) -> (f64, f64, f64) {
        // 1 − e^{−jθ} = 2j·sin(θ/2)·e^{−jθ/2}; 1 − cos θ = 2 sin²(θ/2): no cancellation at small θ.
        let s = (0.5 * theta).sin();
        let one_minus = C::new(0.0, 2.0 * s) * C::from_polar(1.0, -0.5 * theta);
        let ed = C::from_polar(1.0, -(self.delay as f64) * theta);
        let a = (one_minus * ed).re;
        let c = (one_minus * self.v(theta) * ed).re;
        let r = 2.0 * self.damping * 2.0 * s * s / self.t;
        (a, c, r)
    }

    /// The largest K the constraint at θ allows with damping B (∞ where it
    /// bounds K from below or not at all).
    fn k_bound(&self, theta: f64, b: f64) -> f64 {
        let (a, c, r) = self.passivity_terms(theta);
        if a > 0.0 {
            (r - b * c) / a
        } else {
            f64::INFINITY
        }
    }

    /// The stiffnesses K ≥ 0 that are strictly passive with damping B, as
    /// `(k_min, k_max)`, or none. For FDM and no delay: `b > KT/2 + |B|`.
    pub fn strict_passivity_range(&self, b: f64) -> Option<(f64, f64)> {
        const N: usize = 8192;
        let (mut lo, mut hi) = (0.0f64, f64::INFINITY);
        let mut arg_hi = None;
        let thetas = std::iter::once(THETA_MIN)
            .chain((1..=N).map(|i| std::f64::consts::PI * i as f64 / N as f64));
        for (i, th) in thetas.enumerate() {
            let (a, c, r) = self.passivity_terms(th);
            let slack = r - b * c;
            if a > 0.0 {
                let kk = slack / a;
                if kk < hi {
                    hi = kk;
                    arg_hi = Some(i);
                }
            } else if a < 0.0 {
                lo = lo.max(slack / a);
            } else if slack < 0.0 {
                return None;
            }
        }
        // Refine the binding θ between its grid neighbours (golden section).
        if let Some(i) = arg_hi {
            let step = std::f64::consts::PI / N as f64;
            let centre = if i == 0 { THETA_MIN } else { step * i as f64 };
            let (mut x0, mut x1) = (
                (centre - step).max(THETA_MIN),
                (centre + step).min(std::f64::consts::PI),
            );
            let f = |th: f64| self.k_bound(th, b);
            let g = 0.5 * (5f64.sqrt() - 1.0);
            for _ in 0..60 {
                let (m0, m1) = (x1 - g * (x1 - x0), x0 + g * (x1 - x0));
                if f(m0) < f(m1) {
                    x1 = m1;
                } else {
                    x0 = m0;
                }
            }
            hi = hi.min(f(0.5 * (x0 + x1)));
        }
        (hi >= lo && hi >= 0.0).then_some((lo, hi))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::scene::SceneSpec;

    fn linear(extra: &str) -> Scene {
        let j = format!(
            r#"{{"device":{{"coulomb":0,"quantization":0}},"loop":{{"sample_hz":1000,"render_hz":1000{extra}}}}}"#
        );
        SceneSpec::from_json(&j).unwrap().validate().unwrap()
    }

    #[test]
    fn strict_passivity_refines_the_binding_frequency_between_grid_points() {
        // With a Butterworth filter the binding θ lies between the 8192-point
        // grid's points. The reference: a brute-force minimum of
        // (r − B·c)/a over 10⁵ θ in (0, π], then 10⁵ more within one coarse
        // step of the best (θ resolution 6e-10 rad). A delay of d samples
        // multiplies H by e^{−jdθ}, so the bound oscillates in θ with many
        // local minima: the refinement must stay next to the binding one.
        for (cutoff, b, delay) in [
            (50.0, 0.0, 0),
            (120.0, 3.0, 0),
            (300.0, -2.0, 0),
            (120.0, 3.0, 3),
            (300.0, 0.0, 7),
            // Three local minima per period, the binding one inside.
            (60.0, 10.0, 6),
            (80.0, 10.0, 6),
            (200.0, 10.0, 6),
        ] {
            let j = format!(
                r#"{{"device":{{"coulomb":0,"quantization":0}},"loop":{{"sample_hz":1000,"render_hz":1000,"delay_samples":{delay}}},"estimator":{{"kind":"butterworth","cutoff_hz":{cutoff},"order":2}}}}"#
            );
            let m =
                LinearModel::new(&SceneSpec::from_json(&j).unwrap().validate().unwrap()).unwrap();
            let f = |th: f64| m.k_bound(th, b);
            let n = 100_000;
            let pi = std::f64::consts::PI;
            let coarse = (1..=n)
                .map(|i| pi * i as f64 / n as f64)
                .min_by(|x, y| f(*x).total_cmp(&f(*y)))
                .unwrap();
            let want = (0..=n)
                .map(|i| {
                    (coarse - pi / n as f64 + 2.0 * pi * i as f64 / (n as f64).powi(2)).min(pi)
                })
                .map(f)
                .fold(f64::INFINITY, f64::min);
            let (_, hi) = m.strict_passivity_range(b).unwrap();
            assert!(
                (hi / want - 1.0).abs() < 1e-10,
                "cutoff {cutoff} B={b} delay {delay}: {hi} vs {want}"
            );
        }
    }

    #[test]
    fn strict_passivity_can_need_a_least_stiffness() {
        // A Kalman filter (q = 1e4) with one sample of delay and B = −4
        // N·s/m: where Re{(1 − e^{−jθ})e^{−jθ}} < 0 the constraint
        // K·a + B·c ≤ r bounds K from below. Checked against the constraint
        // itself on 10⁵ θ: just inside [lo, hi] it holds at every θ, 1 %
        // below lo it fails at some θ (found by the scan above, 2026-12-02:
        // the only estimator/delay/B combinations with a lower bound).
        let j = r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000,"delay_samples":1},"estimator":{"kind":"kalman","q":1e4}}"#;
        let m = LinearModel::new(&SceneSpec::from_json(j).unwrap().validate().unwrap()).unwrap();
        let b = -4.0;
        let (lo, hi) = m.strict_passivity_range(b).unwrap();
        assert!(lo > 2000.0 && hi > 1.5 * lo, "{lo} {hi}");
        let holds = |k: f64| {
            (1..=100_000).all(|i| {
                let th = std::f64::consts::PI * i as f64 / 1e5;
                let (a, c, r) = m.passivity_terms(th);
                k * a + b * c <= r
            })
        };
        assert!(holds(lo * 1.001) && holds(hi * 0.999));
        assert!(!holds(lo * 0.99));
        // Without the lower bound's θ (B = 0) nothing is required.
        assert_eq!(m.strict_passivity_range(0.0).unwrap().0, 0.0);
    }

    #[test]
    fn the_lines_are_the_multiples_of_f_min_up_to_f_max() {
        // The probe's lines (scene.rs): f_min, 2·f_min, … ≤ f_max; at
        // f_min = 2 Hz to 100 Hz, the 50 lines 2, 4, …, 100 Hz.
        let sc = SceneSpec::from_json(
            r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000},"probe":{"f_min_hz":2,"f_max_hz":100}}"#,
        )
        .unwrap()
        .validate()
        .unwrap();
        let f = LinearModel::new(&sc)
            .unwrap()
            .impedance(1000.0, 0.0)
            .freq_hz;
        assert_eq!(f.len(), 50);
        for (i, hz) in f.iter().enumerate() {
            assert!((hz - 2.0 * (i + 1) as f64).abs() < 1e-9, "line {i}: {hz}");
        }
    }

    #[test]
    fn fdm_strict_passivity_is_colgate() {
        // Colgate & Schenkel for FDM, no delay: passive iff b > KT/2 + |B|,
        // i.e. k_max = 2(b − |B|)/T.
        let m = LinearModel::new(&linear("")).unwrap();
        for bw in [0.0, 5.0, -5.0, 10.0, 13.0] {
            let (_, k) = m.strict_passivity_range(bw).unwrap();
            let want = 2.0 * (13.2 - bw.abs()) / 1e-3;
            assert!((k - want).abs() < 1e-6 * want, "B={bw}: {k} vs {want}");
        }
        assert!(m.strict_passivity_range(14.0).is_none());
    }

    #[test]
    fn design_md_figures_for_the_seed_device() {
        // DESIGN.md: seed device, 1 kHz, B = 5 N·s/m: strict 16 400 N/m;
        // impedance test over 1–100 Hz ≈ 35 400 N/m. And B = 0 gives 2b/T.
        let m = LinearModel::new(&linear("")).unwrap();
        let boundary = |b: f64| {
            let (mut lo, mut hi) = (1.0, 1e6);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if m.impedance(mid, b).passive {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            lo
        };
        let k5 = boundary(5.0);
        assert!((k5 / 35_400.0 - 1.0).abs() < 0.01, "{k5}");
        let k0 = boundary(0.0);
        assert!((k0 / 26_400.0 - 1.0).abs() < 1e-3, "{k0}");
        assert!((m.strict_passivity_range(5.0).unwrap().1 - 16_400.0).abs() < 1e-6);
    }

    #[test]
    fn eigenvalue_boundary_matches_small_damping_rule() {
        // DESIGN.md: for small (b+B)T/m the stability limit is
        // K < (b+B)/(T/2 + t_delay). Seed device at 1 kHz, B = 20:
        // (b+B)T/m = 0.064, so within a few percent of 33.2/(0.5e-3) = 66 400.
        for (delay, td) in [(0u32, 0.0), (1, 1e-3)] {
            let m = LinearModel::new(&linear(&format!(r#","delay_samples":{delay}"#))).unwrap();
            let (mut lo, mut hi) = (1.0, 1e7);
            for _ in 0..60 {
                let mid = 0.5 * (lo + hi);
                if m.spectral_radius(mid, 20.0) < 1.0 {
                    lo = mid
                } else {
                    hi = mid
                }
            }
            let rule = 33.2 / (0.5e-3 + td);
            assert!(
                (lo / rule - 1.0).abs() < 0.06,
                "delay {delay}: {lo} vs {rule}"
            );
            // Exactly: the Jury criterion on the characteristic polynomial
            // (FDM, B = 20), solved independently in Python/mpmath
            // (tests/engines.rs, JURY): 64 197.082… and 21 354.105… N/m.
            let jury = if delay == 0 {
                64_197.082_392_778_42
            } else {
                21_354.105_800_543_147
            };
            assert!(
                (lo / jury - 1.0).abs() < 1e-9,
                "delay {delay}: {lo} vs Jury {jury}"
            );
        }
    }

    #[test]
    fn kalman_transfer_function_matches_simulation() {
        // Drive the time-varying filter with a sinusoid long enough to reach
        // steady state; its output amplitude/phase must match V(e^{jθ}).
        // Two process noises on the ideal sensor (built for a 1 nm step, so
        // r = d²/3 = 3.3e-19 m²): q = 2.5e4 (q·T⁵ = 2.5e-11 ≫ r: the gain
        // hardly depends on q) and q = 1e-3 (q·T⁵ = 1e-18, comparable with
        // r: it does). And the diagonal model (jerk noise q·T⁴ on the third
        // state only) at q = 1e-6, where q·T⁴ = 1e-18 is comparable with r.
        use crate::estimators::{EstimatorSpec, Sampling, VelocityEstimator};
        for (q, model) in [
            (2.5e4, "white_jerk"),
            (1e-3, "white_jerk"),
            (1e-6, "diagonal"),
        ] {
            let est_json = format!(r#"{{"kind":"kalman","q":{q},"q_model":"{model}"}}"#);
            let sc = SceneSpec::from_json(&format!(r#"{{"device":{{"coulomb":0,"quantization":0}},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{est_json}}}"#))
                .unwrap()
                .validate()
                .unwrap();
            let m = LinearModel::new(&sc).unwrap();
            let spec = EstimatorSpec::from_json(&est_json).unwrap();
            // The fixed point was found by the convergence test, not the cap.
            let qm = if model == "diagonal" {
                QModel::Diagonal
            } else {
                QModel::WhiteJerk
            };
            let (_, iterations) = kalman_steady_gain(q, qm, 1e-3, sc.sampling.quantization);
            assert!(iterations < RICCATI_CAP, "q = {q}: {iterations}");
            let mut est = spec
                .build(Sampling::new(1000.0, sc.sampling.quantization).unwrap())
                .unwrap();
            let w = 2.0 * std::f64::consts::PI * 37.0;
            let theta = w * 1e-3;
            let v = m.v(theta);
            let n = 200_000;
            let (mut last, mut want) = (0.0, 0.0);
            for k in 0..n {
                let y = 1e-3 * (theta * k as f64).sin();
                last = est.update(y);
                // Steady-state response to Im(e^{jθk}) is Im(V e^{jθk}).
                want = 1e-3 * (v * C::from_polar(1.0, theta * k as f64)).im;
            }
            assert!(
                (last - want).abs() < 1e-6 * v.norm() * 1e-3 + 1e-9,
                "q = {q}: {last} vs {want}"
            );
        }
    }
}
