//! `zwidth record` (an open-loop identification trace from the simulated
//! device) and `zwidth identify` (the device's m, b, f_c back from a trace,
//! written as a scene).

use std::io::Write;
use std::path::Path;

use crate::identify::record::{record, Excitation};
use crate::identify::scene::identified_scene;
use crate::identify::{identify, with_mode, Estimate, Model, Trace};

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
