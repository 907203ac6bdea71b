//! LuGre friction (Canudas de Wit, Olsson, Åström & Lischinsky 1995, IEEE
//! TAC 40(3), eqs. 1–3): the Stribeck curve, the bristle's exact step for a
//! velocity held, and the substep size; `plant.rs` steps it with the device.

/// LuGre friction's parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LuGre {
    /// Kinetic (Coulomb) level F_c and static (breakaway) level F_s (N).
    pub kinetic: f64,
    pub static_force: f64,
    /// Stribeck velocity v_s (m/s).
    pub stribeck_velocity: f64,
    /// Bristle stiffness σ0 (N/m) and damping σ1 (N·s/m).
    pub stiffness: f64,
    pub damping: f64,
    /// It acts on the motor side of a transmission (true) or the handle.
    pub on_motor: bool,
}

impl LuGre {
    /// The Stribeck curve g(v) = F_c + (F_s − F_c)·e^{−(v/v_s)²} (N; 1995
    /// paper eq. 3).
    #[inline]
    pub fn level(&self, v: f64) -> f64 {
        let r = v / self.stribeck_velocity;
        self.kinetic + (self.static_force - self.kinetic) * (-r * r).exp()
    }

    /// The bristle deflection after `h` seconds at velocity `v` from `z`:
    /// `ż = v − (σ0|v|/g(v))·z` solved exactly for v constant.
    #[inline]
    pub fn bristle(&self, z: f64, v: f64, h: f64) -> f64 {
        if v == 0.0 {
            return z;
        }
        let g = self.level(v);
        let z_ss = v.signum() * g / self.stiffness;
        z_ss + (z - z_ss) * (-self.stiffness * v.abs() / g * h).exp()
    }
}

/// Substeps of one interval `dt` for LuGre friction on a body of mass `m`:
/// each at most 3 % of the pre-sliding mode's `1/ω0 = √(m/σ0)` (the
/// second-order step's phase error is then ≈ 0.1 % per cycle: a lightly
/// damped bristle ringing for seven cycles stays within 0.5 % of an RK4
/// reference, `friction_tests.rs`) and a tenth of the bristle damper's
/// `m/σ1` (`plant.rs` steps it).
pub fn lugre_substeps(m: f64, stiffness: f64, damping: f64, dt: f64) -> f64 {
    let mut h = 0.03 * (m / stiffness).sqrt();
    if damping > 0.0 {
        h = h.min(0.1 * m / damping);
    }
    (dt / h).ceil().max(1.0)
}

#[cfg(test)]
#[path = "friction_tests.rs"]
mod tests;
