//! The device part of a scene: the haptic device (mass, damping, Coulomb
//! friction, encoder, force limit, amplifier), its transmission and LuGre
//! friction, their defaults (the seeds' values), the plant they build, and
//! the friction fields' checks.

use serde::{Deserialize, Serialize};

use crate::error::{require_range, SpecError};
use crate::friction::{lugre_substeps, LuGre};
use crate::plant::{Plant, Transmission};

/// Most LuGre substeps in one encoder sample (`plant::lugre_substeps`).
pub const MAX_FRICTION_SUBSTEPS: f64 = 1000.0;
/// The haptic device: `m ẍ + b ẋ = F − f_c·sign(ẋ)` (2018 paper §V: m = 0.52 kg,
/// b = 13.2 N·s/m, f_c = 0.19 N, 1 µm encoder).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct DeviceSpec {
    /// Moving mass (kg).
    #[serde(default = "d_mass")]
    pub mass: f64,
    /// Viscous damping b (N·s/m).
    #[serde(default = "d_damping")]
    pub damping: f64,
    /// Coulomb friction f_c (N): the kinetic level. Static equals kinetic
    /// with ideal stick–slip, as the 2018 paper assumes, unless `friction`
    /// names a LuGre model.
    #[serde(default = "d_coulomb")]
    pub coulomb: f64,
    /// Encoder step (m); 0 is an ideal sensor.
    #[serde(default = "d_quantization")]
    pub quantization: f64,
    /// Motor force saturation (N), or null for none.
    #[serde(default)]
    pub force_limit: Option<f64>,
    /// Force command resolution (N): the DAC's step, the commanded force
    /// rounded to a whole number of steps each render; null for none.
    /// Off unless named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_resolution: Option<f64>,
    /// Amplifier (current-loop) bandwidth f_a (Hz): the motor force lags its
    /// command by a first-order pole at f_a (`plant.rs`); null for an ideal
    /// amplifier. At most the Nyquist frequency of `loop.sample_hz`. Off
    /// unless named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub amplifier_hz: Option<f64>,
    /// A compliant transmission (two-mass model): the motor side coupled
    /// to the handle (whose mass and damping are `mass` and `damping`)
    /// by a cable's stiffness and damping; null for a rigid device. Off
    /// unless named; needs `coulomb: 0` (friction is modelled on the rigid
    /// device only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub transmission: Option<TransmissionSpec>,
    /// Friction beyond ideal Coulomb: the LuGre model (static above
    /// kinetic, a Stribeck curve, pre-sliding bristles; `plant.rs`), with
    /// `coulomb` as its kinetic level; null for ideal Coulomb stick–slip.
    /// Off unless named.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub friction: Option<FrictionSpec>,
}

/// LuGre friction (Canudas de Wit, Olsson, Åström & Lischinsky 1995). The
/// defaults are that paper's example values (σ0 = 1e5 N/m, σ1 = √1e5 N·s/m,
/// v_s = 1 mm/s) with static = kinetic.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FrictionSpec {
    /// Static (breakaway) friction F_s (N), at least `device.coulomb`;
    /// null for `device.coulomb` (no Stribeck dip).
    #[serde(rename = "static", default, skip_serializing_if = "Option::is_none")]
    pub static_force: Option<f64>,
    /// Stribeck velocity v_s (m/s): friction falls from F_s to F_c over it.
    #[serde(default = "d_stribeck_velocity")]
    pub stribeck_velocity: f64,
    /// Bristle stiffness σ0 (N/m): the pre-sliding spring.
    #[serde(default = "d_bristle_stiffness")]
    pub bristle_stiffness: f64,
    /// Bristle damping σ1 (N·s/m).
    #[serde(default = "d_bristle_damping")]
    pub bristle_damping: f64,
    /// Where it acts: `handle`, or `motor` (the motor side of a
    /// transmission: bearings, brushes).
    #[serde(default)]
    pub on: FrictionSide,
}

impl Default for FrictionSpec {
    /// The defaults above, static = kinetic, on the handle.
    fn default() -> Self {
        Self {
            static_force: None,
            stribeck_velocity: d_stribeck_velocity(),
            bristle_stiffness: d_bristle_stiffness(),
            bristle_damping: d_bristle_damping(),
            on: FrictionSide::Handle,
        }
    }
}

/// The body friction acts on.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FrictionSide {
    #[default]
    Handle,
    Motor,
}

fn d_stribeck_velocity() -> f64 {
    1e-3
}
fn d_bristle_stiffness() -> f64 {
    1e5
}
fn d_bristle_damping() -> f64 {
    1e5f64.sqrt()
}

/// A cable (capstan) transmission between the motor and the handle.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TransmissionSpec {
    /// Motor-side mass (kg): the motor and capstan inertia reflected to the
    /// handle's axis, J/r².
    pub motor_mass: f64,
    /// Motor-side viscous damping (N·s/m).
    #[serde(default)]
    pub motor_damping: f64,
    /// Cable stiffness (N/m) and damping (N·s/m), handle to motor side.
    pub stiffness: f64,
    #[serde(default)]
    pub damping: f64,
    /// Where the encoder sits: `motor` (on the motor shaft, the common
    /// case) or `handle`.
    #[serde(default)]
    pub encoder: EncoderSide,
}

/// Which side of a transmission the encoder reads.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum EncoderSide {
    #[default]
    Motor,
    Handle,
}

impl DeviceSpec {
    /// The plant of this device for steps of `dt` (every engine's).
    pub fn plant(&self, dt: f64) -> Plant {
        Plant::new(self.mass, self.damping, self.coulomb, dt)
            .with_drive(
                self.amplifier_hz,
                self.transmission.as_ref().map(|t| Transmission {
                    motor_mass: t.motor_mass,
                    motor_damping: t.motor_damping,
                    stiffness: t.stiffness,
                    damping: t.damping,
                    encoder_on_motor: t.encoder == EncoderSide::Motor,
                }),
            )
            .with_lugre(self.lugre())
    }

    /// The LuGre model the scene names, if any.
    pub fn lugre(&self) -> Option<LuGre> {
        self.friction.as_ref().map(|f| LuGre {
            kinetic: self.coulomb,
            static_force: self.static_friction(),
            stribeck_velocity: f.stribeck_velocity,
            stiffness: f.bristle_stiffness,
            damping: f.bristle_damping,
            on_motor: f.on == FrictionSide::Motor,
        })
    }

    /// The force that breaks the device loose (N): LuGre's static level,
    /// else the Coulomb level.
    pub fn static_friction(&self) -> f64 {
        self.friction
            .as_ref()
            .and_then(|f| f.static_force)
            .unwrap_or(self.coulomb)
    }
}

fn d_mass() -> f64 {
    0.52
}
fn d_damping() -> f64 {
    13.2
}
fn d_coulomb() -> f64 {
    0.19
}
fn d_quantization() -> f64 {
    1e-6
}

impl Default for DeviceSpec {
    fn default() -> Self {
        Self {
            mass: d_mass(),
            damping: d_damping(),
            coulomb: d_coulomb(),
            quantization: d_quantization(),
            force_limit: None,
            force_resolution: None,
            amplifier_hz: None,
            transmission: None,
            friction: None,
        }
    }
}

/// LuGre friction's fields (`FrictionSpec`) against the device and the rate.
pub(super) fn validate_friction(
    d: &DeviceSpec,
    f: &FrictionSpec,
    sample_hz: f64,
) -> Result<(), SpecError> {
    let fp = |e: SpecError| e.within("device.friction");
    if d.coulomb <= 0.0 {
        return Err(SpecError::new(
            "device.coulomb",
            d.coulomb,
            "must be > 0 N with device.friction: it is the LuGre model's kinetic level F_c",
        ));
    }
    if let Some(fs) = f.static_force {
        if !(fs.is_finite() && fs >= d.coulomb && fs <= 1e4) {
            return Err(SpecError::new(
                "device.friction.static",
                fs,
                format!(
                    "must be at least the kinetic level device.coulomb = {} N and at most 1e4 N",
                    d.coulomb
                ),
            ));
        }
    }
    require_range(
        "stribeck_velocity",
        f.stribeck_velocity,
        1e-9,
        10.0,
        "m/s, > 0",
    )
    .map_err(fp)?;
    require_range("bristle_stiffness", f.bristle_stiffness, 1.0, 1e9, "N/m").map_err(fp)?;
    require_range("bristle_damping", f.bristle_damping, 0.0, 1e6, "N·s/m").map_err(fp)?;
    let body = match (&d.transmission, f.on) {
        (_, FrictionSide::Handle) => d.mass,
        (Some(t), FrictionSide::Motor) => t.motor_mass,
        (None, FrictionSide::Motor) => {
            return Err(SpecError::new(
                "device.friction.on",
                "motor",
                "must be handle on a rigid device (motor needs device.transmission)",
            ))
        }
    };
    let n = lugre_substeps(
        body,
        f.bristle_stiffness,
        f.bristle_damping,
        1.0 / sample_hz,
    );
    if n > MAX_FRICTION_SUBSTEPS {
        return Err(SpecError::new(
            "device.friction.bristle_stiffness",
            f.bristle_stiffness,
            format!("needs {n} substeps per sample at loop.sample_hz = {sample_hz} Hz with bristle_damping = {} N·s/m on {body} kg (each at most 3 % of √(m/σ0) and a tenth of m/σ1); at most {MAX_FRICTION_SUBSTEPS}: lower the bristles' stiffness or damping, or raise the rate", f.bristle_damping),
        ));
    }
    Ok(())
}
