//! `zwidth record` (an open-loop identification trace from the simulated
//! device) and `zwidth identify` (the device's m, b, f_c back from a trace,
//! written as a scene).

use std::io::Write;
use std::path::Path;

use crate::identify::record::{record, Excitation};
use crate::identify::{identify, with_mode, Estimate, Identified, Model, Trace};
use crate::zwidth::scene::{EncoderSide, SceneSpec, TransmissionSpec};

use super::common::*;
use super::CliError;

pub(super) fn run_record(
    scene: &Path,
    excitation: Excitation,
    out: &Path,
    stdout: &mut impl Write,
) -> Result<(), CliError> {
    let sc = read_scene(scene)?.validate()?;
    excitation.validate(&sc).map_err(|mut e| {
        // Name the flag the value came from.
        e.field = match e.field.as_str() {
            "period_s" => "--period",
            "f_max_hz" => "--f-max",
            "peak_force" => "--peak-force",
            "duration_s" => "--duration",
            "band.f_min_hz" => "--band-min",
            "band.f_max_hz" => "--band-max",
            "band.peak_force" => "--band-force",
            other => other,
        }
        .to_string();
        CliError::from(e)
    })?;
    let trace = record(&sc, &excitation);
    write_file(out, &trace.to_csv())?;
    writeln!(
        stdout,
        "wrote {} samples ({} s at {} Hz; multisine {}–{} Hz, peak {} N{}) to {}",
        trace.t.len(),
        excitation.duration_s,
        trace.sample_hz(),
        1.0 / excitation.period_s,
        excitation.f_max_hz,
        excitation.peak_force,
        excitation.band.as_ref().map_or(String::new(), |b| format!(
            "; band {}–{} Hz, peak {} N",
            b.f_min_hz, b.f_max_hz, b.peak_force
        )),
        out.display()
    )
    .map_err(io)
}

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
fn identified_scene(id: &Identified, base: Option<SceneSpec>) -> SceneSpec {
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

fn model_name(m: Model) -> &'static str {
    match m {
        Model::MassDamperCoulomb => "mass_damper_coulomb",
        Model::MassDamper => "mass_damper",
        Model::TwoMass => "two_mass",
    }
}

fn row(name: &str, e: &Estimate, unit: &str) -> String {
    format!(
        "  {name:<9} {:>11.5} {unit:<6} 95 % [{:.5}, {:.5}]  (± {:.2} %)\n",
        e.value,
        e.lo,
        e.hi,
        if e.value != 0.0 {
            100.0 * (e.hi - e.value) / e.value.abs()
        } else {
            0.0
        }
    )
}

pub(super) fn run_identify(
    trace: &Path,
    model: &str,
    mode_trace: Option<&Path>,
    base: Option<&Path>,
    out: Option<&Path>,
    json: bool,
    stdout: &mut impl Write,
) -> Result<(), CliError> {
    let model: Model = parse_choice("model", model)?;
    let base = base.map(read_scene).transpose()?;
    let read = |path: &Path| -> Result<Trace, CliError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| CliError::Input(format!("{} cannot be read: {e}", path.display())))?;
        Trace::parse_csv(&text).map_err(|e| CliError::Input(format!("{}: {e}", path.display())))
    };
    if let (false, Some(band)) = (model == Model::TwoMass, mode_trace) {
        return Err(CliError::Input(format!(
            "--mode-trace = {} is not allowed: it is read by --model two_mass only, not {}",
            band.display(),
            model_name(model)
        )));
    }
    let tr = read(trace)?;
    fn in_file(path: &Path) -> impl Fn(crate::error::SpecError) -> CliError + '_ {
        move |e| CliError::Input(format!("{}: {e}", path.display()))
    }
    // (A mode trace comes with two_mass only: checked above.)
    let id = match mode_trace {
        Some(band) => {
            let rigid = identify(&tr, Model::MassDamperCoulomb).map_err(in_file(trace))?;
            with_mode(rigid, &read(band)?).map_err(in_file(band))?
        }
        None => identify(&tr, model).map_err(in_file(trace))?,
    };
    let spec = identified_scene(&id, base);
    // The identified device must make a valid scene before anything is written.
    spec.validate().map_err(|e| {
        CliError::Input(format!(
            "{}: the identified device is not a valid scene ({e}); the trace does not determine it: excite a wider band or longer",
            trace.display()
        ))
    })?;
    if let Some(path) = out {
        let text =
            serde_json::to_string_pretty(&spec).map_err(|e| CliError::Failure(e.to_string()))?;
        write_file(path, &(text + "\n"))?;
    }
    write_either(stdout, json, &id, || {
        let mut s =
            format!(
            "{} from {} s at {} Hz ({} of {} windows moving one way; interval from {} blocks):\n",
            model_name(id.model),
            id.duration_s, id.sample_hz, id.windows_used, id.windows_tried, id.blocks
        );
        s += &row("mass", &id.mass, "kg");
        s += &row("damping", &id.damping, "N·s/m");
        if id.model != Model::MassDamper {
            s += &row("coulomb", &id.coulomb, "N");
        }
        if let Some(m) = &id.mode {
            s += &format!(
                "  mode: resonance {:.1} Hz, antiresonance {:.1} Hz, from {} lines {:.1}–{:.1} Hz over {} periods (misfit {:.2} %):\n",
                m.resonance_hz, m.antiresonance_hz, m.lines, m.band_hz[0], m.band_hz[1], m.periods, 100.0 * m.misfit
            );
            s += &row("m_handle", &m.handle_mass, "kg");
            s += &row("m_motor", &m.motor_mass, "kg");
            s += &row("k_cable", &m.stiffness, "N/m");
            s += &row("c_cable", &m.cable_damping, "N·s/m");
            s += &row("b_handle", &m.handle_damping, "N·s/m");
            s += &row("b_motor", &m.motor_damping, "N·s/m");
            let us = |v: f64| v * 1e6;
            let lag = Estimate {
                value: us(m.amplifier_lag_s.value),
                std_error: us(m.amplifier_lag_s.std_error),
                lo: us(m.amplifier_lag_s.lo),
                hi: us(m.amplifier_lag_s.hi),
            };
            s += &row("amp_lag", &lag, "µs");
            s += &match m.amplifier_hz {
                Some(f) => format!("  amplifier bandwidth {f:.0} Hz (1/(2π·τ))\n"),
                None => "  no amplifier lag resolved in the band\n".to_string(),
            };
        }
        s += &format!(
            "  encoder step {:e} m; fit residual {:.2e} N RMS\n",
            id.quantization, id.residual_rms_n
        );
        if let Some(p) = out {
            s += &format!("scene written to {}\n", p.display());
        }
        s
    })
}

#[cfg(test)]
mod tests {
    use super::*;

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
