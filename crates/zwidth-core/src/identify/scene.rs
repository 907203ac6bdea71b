//! The scene `identify` writes from what it found: one function the CLI,
//! the Python package and whoever else writes an identified device share.

use super::Identified;
use crate::zwidth::scene::{EncoderSide, SceneSpec, TransmissionSpec};

/// The scene `identify` writes: the base (or the default scene at the
/// trace's rate) with the identified device, which is rigid and driven
/// without lag, with ideal Coulomb friction (the fitted model): a base
/// scene's transmission, amplifier lag and LuGre friction are dropped, not
/// combined with it (its mass is the whole moving mass, its f_c the
/// kinetic level).
///
/// With `two_mass`, the device is the identified two-mass one: the handle's
/// mass and damping, a transmission with the encoder on the motor side,
/// the amplifier bandwidth where the fit resolved a lag,
/// and the friction as LuGre at the identified kinetic level (static =
/// kinetic unless the base's friction says more), on the base friction's
/// side or else the handle's.
pub fn identified_scene(id: &Identified, base: Option<SceneSpec>) -> SceneSpec {
    let base_friction = base.as_ref().and_then(|b| b.device.friction.clone());
    let mut spec = base.unwrap_or_else(|| {
        let mut s = SceneSpec::default();
        s.control.sample_hz = id.sample_hz;
        s.control.render_hz = id.sample_hz;
        s
    });
    spec.device.mass = id.mass.value;
    spec.device.damping = id.damping.value;
    // A negative kinetic friction is written as 0 (a frictionless device's
    // fit lands a little either side of it; friction cannot push).
    spec.device.coulomb = id.coulomb.value.max(0.0);
    spec.device.quantization = id.quantization;
    spec.device.transmission = None;
    spec.device.amplifier_hz = None;
    spec.device.friction = None;
    if let Some(mode) = &id.mode {
        spec.device.mass = mode.handle_mass.value;
        spec.device.damping = mode.handle_damping.value;
        // A lag the written scene's loop can hold (at most its Nyquist
        // frequency; a base scene may sample slower than the trace).
        spec.device.amplifier_hz = mode
            .amplifier_hz
            .filter(|f| *f <= 0.5 * spec.control.sample_hz);
        spec.device.transmission = Some(TransmissionSpec {
            motor_mass: mode.motor_mass.value,
            motor_damping: mode.motor_damping.value,
            stiffness: mode.stiffness.value,
            damping: mode.cable_damping.value,
            encoder: EncoderSide::Motor,
        });
        if spec.device.coulomb > 0.0 {
            // On the handle unless the base says otherwise: the mode fit
            // refuses a trace with friction on the motor side (it holds the
            // motor in pre-sliding), so a fit that succeeded had it on the
            // handle side or too small to matter.
            let mut friction = base_friction.unwrap_or_default();
            friction.static_force = friction.static_force.map(|s| s.max(spec.device.coulomb));
            spec.device.friction = Some(friction);
        }
    }
    spec
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::identify::{Estimate, Model};

    #[test]
    fn the_written_scene_is_the_identified_rigid_device() {
        // A base scene with a transmission, a lag and LuGre friction on the
        // motor side: the identified mass is the whole moving mass of a
        // rigid model driven without lag, with ideal Coulomb friction, so
        // all three are dropped (keeping the transmission would count the
        // motor side twice; the friction's side would not exist); the rest
        // of the base (its loop, its estimator) stays.
        let e = |value: f64| Estimate {
            value,
            std_error: 0.0,
            lo: value,
            hi: value,
        };
        let id = Identified {
            model: Model::MassDamperCoulomb,
            mass: e(0.52),
            damping: e(13.2),
            coulomb: e(0.19),
            quantization: 1e-6,
            sample_hz: 1000.0,
            duration_s: 20.0,
            windows_used: 1,
            windows_tried: 1,
            blocks: 10,
            residual_rms_n: 0.0,
            mode: None,
        };
        let base = SceneSpec::from_json(
            r#"{"device":{"amplifier_hz":300,"transmission":{"motor_mass":0.2,"stiffness":5e4},"friction":{"on":"motor","static":0.3}},"loop":{"sample_hz":2000,"render_hz":1000}}"#,
        )
        .unwrap();
        let s = identified_scene(&id, Some(base));
        assert_eq!(
            (
                &s.device.transmission,
                s.device.amplifier_hz,
                &s.device.friction
            ),
            (&None, None, &None)
        );
        assert_eq!((s.device.mass, s.device.coulomb), (0.52, 0.19));
        assert_eq!((s.control.sample_hz, s.control.render_hz), (2000.0, 1000.0));
        s.validate().unwrap();
    }
}
