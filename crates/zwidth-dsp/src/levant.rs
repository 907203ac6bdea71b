//! Levant's first-order robust exact differentiator (super-twisting).
//!
//! Units: `alpha` in m/s², `lambda` in m^½/s (2011 paper eqs. 4–5).
//!
//! Discretizations:
//! - `Explicit` — exactly the 2011 paper's eqs. 6–8 with explicit Euler:
//!   `e = x − y_k; u = u1 − λ·√|e|·sign(e)`; output `u`; then
//!   `x += T·u; u1 −= T·α·sign(e)`; start `x = y_0, u1 = 0`; `sign(0) = 0`.
//! - `Implicit` — the implicit (backward) Euler discretization of the same
//!   differential inclusion (Mojallizadeh, Brogliato & Acary 2021; Brogliato &
//!   Polyakov 2015), with the set-valued sign solved exactly. With the
//!   predicted error `w = x_k + T·u1_k − y_{k+1}`:
//!   if `|w| ≤ T²α`: `e_{k+1} = 0`, `s = w/(T²α)` (sliding, s ∈ [−1, 1]);
//!   else `s = sign(w)` and `r = √|e_{k+1}|` solves `r² + Tλr = |w| − T²α`.
//!   Then `u1_{k+1} = u1_k − Tαs`, `x_{k+1} = y_{k+1} + s·r²`, and the output
//!   is `u1_{k+1}` ([`ImplicitOutput::State`]) or the 2011 paper's eq. 7 at
//!   the new state, `u1_{k+1} − λ·√|e_{k+1}|·sign(e_{k+1})` ([`ImplicitOutput::Eq7`]).
//!
//! Subnormals: the integrator state u1 is flushed below [`crate::FLUSH`].

use crate::math::flush;
use crate::math::{abs, sqrt};
use crate::Error;

/// Range of α and λ accepted.
pub const GAIN_MIN: f64 = 1e-12;
pub const GAIN_MAX: f64 = 1e12;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Discretization {
    #[default]
    Explicit,
    Implicit,
}

/// What the implicit scheme outputs (the explicit one always outputs eq. 7's u).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum ImplicitOutput {
    /// `u1_{k+1}`, the integrator state (Levant's later z1).
    #[default]
    State,
    /// The 2011 paper's eq. 7 at the new state.
    Eq7,
}

/// sign with sign(0) = 0 (Rust's `f64::signum(0.0)` is 1).
#[inline]
fn sign(e: f64) -> f64 {
    if e > 0.0 {
        1.0
    } else if e < 0.0 {
        -1.0
    } else {
        0.0
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct Levant {
    alpha: f64,
    lambda: f64,
    discretization: Discretization,
    output: ImplicitOutput,
    t: f64,
    x: f64,
    u1: f64,
    started: bool,
}

impl Levant {
    /// α and λ within [`GAIN_MIN`]…[`GAIN_MAX`]; the sample period `t` > 0 (s).
    pub fn new(
        alpha: f64,
        lambda: f64,
        discretization: Discretization,
        output: ImplicitOutput,
        t: f64,
    ) -> Result<Self, Error> {
        for (name, v) in [("alpha", alpha), ("lambda", lambda)] {
            if !(v.is_finite() && (GAIN_MIN..=GAIN_MAX).contains(&v)) {
                return Err(Error::Parameter {
                    name,
                    value: v,
                    allowed: "must be from 1e-12 to 1e12",
                });
            }
        }
        crate::error::positive("period", t)?;
        Ok(Self::from_validated(
            alpha,
            lambda,
            discretization,
            output,
            t,
        ))
    }

    /// The same from values the caller has checked as [`Levant::new`] does
    /// (`zwidth-core` validates the JSON spec with its own messages).
    pub fn from_validated(
        alpha: f64,
        lambda: f64,
        discretization: Discretization,
        output: ImplicitOutput,
        t: f64,
    ) -> Self {
        Self {
            alpha,
            lambda,
            discretization,
            output,
            t,
            x: 0.0,
            u1: 0.0,
            started: false,
        }
    }

    pub fn gains(&self) -> (f64, f64) {
        (self.alpha, self.lambda)
    }

    pub fn scheme(&self) -> (Discretization, ImplicitOutput) {
        (self.discretization, self.output)
    }

    pub fn period(&self) -> f64 {
        self.t
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        let (a, l, t) = (self.alpha, self.lambda, self.t);
        if !self.started {
            self.started = true;
            self.x = y;
            self.u1 = 0.0;
            if self.discretization == Discretization::Implicit {
                return 0.0;
            }
        }
        match self.discretization {
            Discretization::Explicit => {
                // 2011 paper eqs. 6–8, explicit Euler.
                let e = self.x - y;
                let s = sign(e);
                let u = self.u1 - l * sqrt(abs(e)) * s;
                self.x += t * u;
                self.u1 = flush(self.u1 - t * a * s);
                u
            }
            Discretization::Implicit => {
                let band = t * t * a;
                let w = self.x + t * self.u1 - y;
                let (s, r2) = if abs(w) <= band {
                    (w / band, 0.0)
                } else {
                    // r² + Tλ r − c = 0, c = |w| − T²α > 0, in the cancellation-free form.
                    let c = abs(w) - band;
                    let r = 2.0 * c / (t * l + sqrt(t * t * l * l + 4.0 * c));
                    (sign(w), r * r)
                };
                self.u1 = flush(self.u1 - t * a * s);
                self.x = y + s * r2;
                match self.output {
                    ImplicitOutput::State => self.u1,
                    // e_{k+1} = x_{k+1} − y_{k+1} = s·r², so √|e|·sign(e) = s·√r².
                    ImplicitOutput::Eq7 => self.u1 - l * sqrt(r2) * s,
                }
            }
        }
    }

    pub fn reset(&mut self) {
        self.started = false;
        self.x = 0.0;
        self.u1 = 0.0;
    }

    /// The integrator state u1 (m/s), for the subnormal test.
    pub fn state(&self) -> (f64, f64) {
        (self.x, self.u1)
    }
}
