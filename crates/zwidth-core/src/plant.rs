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
//! paper's device drives its motor (a PWM amplifier in current mode, §2.3),
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
//!
//! LuGre friction, when the scene names it (Canudas de Wit, Olsson, Åström
//! & Lischinsky 1995, IEEE TAC 40(3), eqs. 1–3): a bristle deflection z
//! with `ż = v − σ0·|v|·z / g(v)`, friction `F_f = σ0 z + σ1 ż` (their σ2 v
//! is the device's viscous damping), and the Stribeck curve
//! `g(v) = F_c + (F_s − F_c)·e^{−(v/v_s)²}`. Static friction above kinetic,
//! and a pre-sliding spring σ0: a force below breakaway moves the handle
//! by F/σ0 instead of holding it exactly still. Stepped in substeps h: z
//! exactly for v held over h (an exponential toward `sign(v)·g(v)/σ0` at
//! rate `σ0|v|/g(v)`), then F_f from z and its mean rate held over h while
//! the linear part steps exactly (`linalg::zoh`), predicted with the
//! velocity at the substep's start and corrected with its mean (Heun:
//! second order). h is 3 % of the pre-sliding mode's `√(m/σ0)` and a tenth
//! of `m/σ1` ([`lugre_substeps`]).

use crate::friction::{lugre_substeps, LuGre};
use crate::linalg::{self, Mat};

/// Σ a_i·b_i over the shorter of the two.
#[inline]
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// An exact step `z ← Φ z + Γ u` (state of order n ≤ 5, m ≤ 3 inputs) in
/// fixed-size arrays, without the `Vec<Vec<f64>>` rows' indirection (1.5 %
/// of the 10 kHz frequency engine's time, issue 34; the step is latency
/// bound, not load bound). Each row is summed over the same terms in the
/// same order as before, so the step is the same bit for bit.
#[derive(Debug, Clone)]
struct ZohStep {
    phi: [[f64; 5]; 5],
    gamma: [[f64; 3]; 5],
    n: usize,
    m: usize,
}

impl ZohStep {
    fn new(phi: &Mat, gamma: &Mat) -> Self {
        let mut s = Self {
            phi: [[0.0; 5]; 5],
            gamma: [[0.0; 3]; 5],
            n: phi.len().min(5),
            m: gamma.first().map_or(0, Vec::len).min(3),
        };
        for i in 0..s.n {
            s.phi[i][..s.n].copy_from_slice(&phi[i][..s.n]);
            s.gamma[i][..s.m].copy_from_slice(&gamma[i][..s.m]);
        }
        s
    }

    /// The whole step: [`ZohStep::partial`] then [`ZohStep::finish`] with
    /// the last input (the same sums, so the same bits as `Φz + Γu` row by
    /// row; every plant has m ≥ 2 inputs).
    #[inline]
    fn step(&self, z: &[f64; 5], u: &[f64]) -> [f64; 5] {
        let (a, p) = self.partial(z, &u[..self.m - 1]);
        self.finish(&a, &p, u[self.m - 1])
    }

    /// The parts of [`ZohStep::step`] that do not depend on the last input:
    /// per row, `Φ z` and the sum over the other inputs `u_head`, each
    /// summed as `step` sums it, so that [`ZohStep::row`] and
    /// [`ZohStep::finish`] complete it to the same bits. LuGre's predictor
    /// and corrector differ only in the friction force (the last input):
    /// they share these, and the predictor needs one row (issue 34).
    #[inline]
    fn partial(&self, z: &[f64; 5], u_head: &[f64]) -> ([f64; 5], [f64; 5]) {
        let (mut a, mut p) = ([0.0; 5], [0.0; 5]);
        let head = self.m.saturating_sub(1);
        for i in 0..self.n {
            a[i] = dot(&self.phi[i][..self.n], z);
            p[i] = dot(&self.gamma[i][..head], u_head);
        }
        (a, p)
    }

    /// Row `i` of the step from its [`ZohStep::partial`] parts and the last
    /// input.
    #[inline]
    fn row(&self, i: usize, a: &[f64; 5], p: &[f64; 5], last: f64) -> f64 {
        a[i] + (p[i] + self.gamma[i][self.m - 1] * last)
    }

    /// The whole step from its [`ZohStep::partial`] parts and the last input.
    #[inline]
    fn finish(&self, a: &[f64; 5], p: &[f64; 5], last: f64) -> [f64; 5] {
        let mut next = [0.0; 5];
        for (i, zi) in next.iter_mut().enumerate().take(self.n) {
            *zi = self.row(i, a, p, last);
        }
        next
    }
}

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

/// The handle's position (m) and velocity (m/s), the motor force the
/// actuator delivered over the last step (N; with an amplifier lag, its
/// value at the step's end), and with a transmission the motor side's
/// position and velocity (else unused).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PlantState {
    pub x: f64,
    pub v: f64,
    pub f: f64,
    pub xm: f64,
    pub vm: f64,
    /// LuGre bristle deflection z (m); 0 without LuGre friction.
    pub z: f64,
}

/// The substepped plant with LuGre friction.
#[derive(Debug, Clone)]
struct LuGreStep {
    model: LuGre,
    n: usize,
    h: f64,
    /// The state's velocity the friction acts on.
    body: usize,
    /// z ← Φ z + Γ·(F_cmd, F_ext, F_f) over h.
    zoh: ZohStep,
}

/// A cable (capstan) transmission: the motor side is a second mass coupled
/// to the handle by a spring and a damper (a two-mass model).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Transmission {
    /// Motor-side mass (kg; its inertia reflected to the handle's axis).
    pub motor_mass: f64,
    /// Motor-side viscous damping (N·s/m).
    pub motor_damping: f64,
    /// Cable stiffness (N/m) and damping (N·s/m) between the two masses.
    pub stiffness: f64,
    pub damping: f64,
    /// The encoder reads the motor side (true) or the handle (false).
    pub encoder_on_motor: bool,
}

/// The device as a continuous linear system `ż = A z + B·(F_cmd, F_ext)`:
/// states (x, v) of the handle, then (x_m, v_m) of the motor side with a
/// transmission, then F_a with an amplifier lag; the handle's and the
/// encoder's positions are `handle·z` and `encoder·z`.
#[derive(Debug, Clone)]
pub struct StateSpace {
    pub a: Mat,
    pub b: Mat,
    pub handle: Vec<f64>,
    pub encoder: Vec<f64>,
}

/// The exact step of a plant with a lag or a transmission.
#[derive(Debug, Clone)]
struct LinearStep {
    /// e^{−T/τ} and φ(T/τ): the lagged force's decay and its mean over a
    /// step (rigid device with friction).
    decay: f64,
    mean: f64,
    /// z ← Φ z + Γ·(F_cmd, F_ext).
    phi: Mat,
    gamma: Mat,
    zoh: ZohStep,
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
    /// The amplifier's time constant τ = 1/(2π f_a) (s), if it lags.
    tau: Option<f64>,
    transmission: Option<Transmission>,
    linear: Option<LinearStep>,
    lugre: Option<LuGreStep>,
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
            tau: None,
            transmission: None,
            linear: None,
            lugre: None,
        }
    }

    /// The same plant behind an amplifier of bandwidth `amplifier_hz` and
    /// through a `transmission` (None: ideal, rigid).
    pub fn with_drive(
        mut self,
        amplifier_hz: Option<f64>,
        transmission: Option<Transmission>,
    ) -> Self {
        self.tau = amplifier_hz.map(|hz| 1.0 / (2.0 * std::f64::consts::PI * hz));
        self.transmission = transmission;
        if self.tau.is_some() || transmission.is_some() {
            let ss = self.state_space();
            let (phi_m, gamma) = linalg::zoh(&ss.a, &ss.b, self.dt);
            let r = self.tau.map_or(0.0, |tau| self.dt / tau);
            self.linear = Some(LinearStep {
                decay: (-r).exp(),
                mean: phi(r),
                zoh: ZohStep::new(&phi_m, &gamma),
                phi: phi_m,
                gamma,
            });
        }
        self
    }

    /// The same plant with LuGre friction (after [`Plant::with_drive`]; the
    /// scene bounds its substeps).
    pub fn with_lugre(mut self, model: Option<LuGre>) -> Self {
        let Some(model) = model else {
            return self;
        };
        let mut ss = self.state_space();
        let (body, m) = match self.transmission {
            Some(t) if model.on_motor => (3, t.motor_mass),
            _ => (1, self.mass),
        };
        for (i, row) in ss.b.iter_mut().enumerate() {
            row.push(if i == body { -1.0 / m } else { 0.0 });
        }
        let n = lugre_substeps(m, model.stiffness, model.damping, self.dt) as usize;
        let h = self.dt / n as f64;
        let (phi, gamma) = linalg::zoh(&ss.a, &ss.b, h);
        self.lugre = Some(LuGreStep {
            model,
            n,
            h,
            body,
            zoh: ZohStep::new(&phi, &gamma),
        });
        self
    }

    /// The continuous-time model (see [`StateSpace`]). Handle:
    /// `m ẍ = −b ẋ + F_ext (+ F_motor when rigid) + k(x_m − x) + c(ẋ_m − ẋ)`;
    /// motor side: `m_m ẍ_m = −b_m ẋ_m + F_motor − k(x_m − x) − c(ẋ_m − ẋ)`;
    /// amplifier: `τ Ḟ_a = F_cmd − F_a`, F_motor = F_a (F_cmd without one).
    pub fn state_space(&self) -> StateSpace {
        let (m, b) = (self.mass, self.damping);
        let n = self.order();
        let mut a = vec![vec![0.0; n]; n];
        let mut bm = vec![vec![0.0; 2]; n];
        let mut handle = vec![0.0; n];
        handle[0] = 1.0;
        let mut encoder = handle.clone();
        a[0][1] = 1.0;
        a[1][1] = -b / m;
        bm[1][1] = 1.0 / m;
        // Where the motor force acts: the handle (rigid) or the motor side.
        let motor_v = match self.transmission {
            None => 1,
            Some(t) => {
                let (k, c, mm) = (t.stiffness, t.damping, t.motor_mass);
                a[1][0] = -k / m;
                a[1][1] -= c / m;
                a[1][2] = k / m;
                a[1][3] = c / m;
                a[2][3] = 1.0;
                a[3][0] = k / mm;
                a[3][1] = c / mm;
                a[3][2] = -k / mm;
                a[3][3] = -(t.motor_damping + c) / mm;
                if t.encoder_on_motor {
                    encoder = vec![0.0; n];
                    encoder[2] = 1.0;
                }
                3
            }
        };
        // The mass the motor force accelerates: the handle, or the motor side.
        let scale = 1.0 / self.transmission.map_or(m, |t| t.motor_mass);
        match self.tau {
            None => bm[motor_v][0] = scale,
            Some(tau) => {
                let f = n - 1;
                a[motor_v][f] = scale;
                a[f][f] = -1.0 / tau;
                bm[f][0] = 1.0 / tau;
            }
        }
        StateSpace {
            a,
            b: bm,
            handle,
            encoder,
        }
    }

    /// The exact step `z ← Φ z + Γ·(F_cmd, F_ext)` of a plant with a lag or
    /// a transmission (None for the rigid, ideal device: see [`Plant::zoh`]).
    pub fn linear_zoh(&self) -> Option<(&Mat, &Mat)> {
        self.linear.as_ref().map(|l| (&l.phi, &l.gamma))
    }

    /// A state at rest at handle position `x` (an unstretched cable).
    pub fn at_rest(&self, x: f64) -> PlantState {
        PlantState {
            x,
            xm: x,
            ..PlantState::default()
        }
    }

    /// What the encoder reads (before quantization).
    #[inline]
    pub fn encoder(&self, s: &PlantState) -> f64 {
        match self.transmission {
            Some(t) if t.encoder_on_motor => s.xm,
            _ => s.x,
        }
    }

    /// One fixed interval with the motor commanded to `motor` (through the
    /// amplifier, if any) and `ext` acting on the handle; `friction`: with
    /// Coulomb friction and stick–slip (module doc; the scene allows
    /// friction on the rigid device only).
    #[inline]
    pub fn step_driven(&self, s: &mut PlantState, motor: f64, ext: f64, friction: bool) {
        if let (true, Some(l)) = (friction, &self.lugre) {
            self.step_lugre(l, s, motor, ext);
            return;
        }
        match &self.linear {
            None => {
                s.f = motor;
                if friction {
                    self.step_friction(s, motor + ext);
                } else {
                    self.step_linear(s, motor + ext);
                }
            }
            Some(l) if friction && self.transmission.is_none() => {
                let mean = motor + (s.f - motor) * l.mean;
                self.step_friction(s, mean + ext);
                s.f = motor + (s.f - motor) * l.decay;
            }
            Some(l) => {
                let next = l.zoh.step(&self.pack(s), &[motor, ext]);
                self.unpack(&next, motor, s);
            }
        }
    }

    /// The state as the state-space model's vector (see [`StateSpace`]).
    #[inline]
    fn pack(&self, s: &PlantState) -> [f64; 5] {
        let mut z = [s.x, s.v, 0.0, 0.0, 0.0];
        if self.transmission.is_some() {
            (z[2], z[3]) = (s.xm, s.vm);
        }
        if self.tau.is_some() {
            z[self.order() - 1] = s.f;
        }
        z
    }

    /// [`Plant::pack`] undone; the delivered force is `motor` without a lag.
    #[inline]
    fn unpack(&self, z: &[f64; 5], motor: f64, s: &mut PlantState) {
        (s.x, s.v) = (z[0], z[1]);
        if self.transmission.is_some() {
            (s.xm, s.vm) = (z[2], z[3]);
        }
        s.f = if self.tau.is_some() {
            z[self.order() - 1]
        } else {
            motor
        };
    }

    /// The state-space model's order.
    #[inline]
    fn order(&self) -> usize {
        2 + 2 * usize::from(self.transmission.is_some()) + usize::from(self.tau.is_some())
    }

    /// One interval with LuGre friction (module doc): per substep h, the
    /// bristle exactly for the velocity held, then the friction force
    /// `σ0 z + σ1 ż` (ż its mean over h) held while the rest steps exactly.
    #[inline]
    fn step_lugre(&self, l: &LuGreStep, s: &mut PlantState, motor: f64, ext: f64) {
        let mut z = self.pack(s);
        let (k0, k1) = (l.model.stiffness, l.model.damping);
        let u = [motor, ext];
        for _ in 0..l.n {
            // Predict with the velocity at the start, then correct with the
            // bristle stepped at the mean velocity and its spring force's
            // mean over h (trapezoid): second order in h (Heun). Both steps
            // start from z and differ in the friction force only.
            let (a, p) = l.zoh.partial(&z, &u);
            let v0 = z[l.body];
            let b = l.model.bristle(s.z, v0, l.h);
            let predicted = l.zoh.row(l.body, &a, &p, k0 * b + k1 * (b - s.z) / l.h);
            let vm = 0.5 * (v0 + predicted);
            let b = l.model.bristle(s.z, vm, l.h);
            z = l
                .zoh
                .finish(&a, &p, k0 * 0.5 * (s.z + b) + k1 * (b - s.z) / l.h);
            s.z = b;
        }
        self.unpack(&z, motor, s);
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

    /// Whether a velocity `v0` (sign `dir`) decelerated by the net force `f`
    /// surely keeps its sign over a whole interval: its value at the end
    /// (the exact step, `step_linear`) is on the same side of zero by more
    /// than a billionth of its terms, far beyond rounding, so the stopping
    /// time (a `ln_1p`, 12 % of a noisy map's time, issue 34) is surely past
    /// the interval and need not be computed. Where this is unsure, the
    /// caller computes it as before: the step is the same bit for bit.
    #[inline]
    fn keeps_sign(&self, v0: f64, f: f64, dir: f64) -> bool {
        let (a, b) = (v0 * self.c_vv, f * self.c_vf);
        (a + b) * dir > 1e-9 * (a.abs() + b.abs())
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
            if s.v != 0.0 && net * dir < 0.0 && !(full && self.keeps_sign(s.v, net, dir)) {
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
#[path = "plant_tests.rs"]
mod tests;
