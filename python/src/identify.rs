//! Identification from Python: `record` a trace from a simulated device and
//! `identify` a device from a trace, as `zwidth record` and `zwidth
//! identify` do (the same functions of zwidth-core, the same CSV and JSON).
//! Traces cross as the CSV text the CLI reads and writes, so a trace from
//! Python meets exactly the CLI's checks and messages.

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::value_error;
use serde::Serialize;

use zwidth_core::error::parse_json;
use zwidth_core::identify::record::{record, Excitation};
use zwidth_core::identify::scene::identified_scene;
use zwidth_core::identify::{identify, with_mode, Identified, Model, Trace};
use zwidth_core::zwidth::scene::SceneSpec;

/// An open-loop trace of the scene's device under a multisine force (the
/// excitation as JSON: `period_s`, `f_max_hz`, `peak_force`,
/// `duration_s`, `band`), as the CSV `zwidth record` writes.
#[pyfunction]
pub fn record_csv(py: Python<'_>, scene: &str, excitation: &str) -> PyResult<String> {
    let sc = SceneSpec::from_json(scene)
        .and_then(|s| s.validate())
        .map_err(value_error)?;
    let ex: Excitation = parse_json(excitation, "excitation", "excitation").map_err(value_error)?;
    ex.validate(&sc).map_err(value_error)?;
    Ok(py.detach(|| record(&sc, &ex).to_csv()))
}

/// What `identify` found, and the scene it writes.
#[derive(Serialize)]
struct Found {
    identified: Identified,
    scene: SceneSpec,
}

/// The device from a trace (CSV text), as `zwidth identify --json` finds
/// it (`identified`) and writes it with `--out` (`scene`).
#[pyfunction]
#[pyo3(signature = (trace, model, mode_trace, scene))]
pub fn identify_json(
    py: Python<'_>,
    trace: &str,
    model: &str,
    mode_trace: Option<&str>,
    scene: Option<&str>,
) -> PyResult<String> {
    let model: Model =
        serde_json::from_value(serde_json::Value::String(model.into())).map_err(|_| {
            PyValueError::new_err(format!(
                "model = {model} is not allowed: mass_damper_coulomb, mass_damper or two_mass"
            ))
        })?;
    if mode_trace.is_some() && model != Model::TwoMass {
        return Err(PyValueError::new_err(format!(
            "mode_trace is not allowed with model = {}: it is read by two_mass only",
            serde_json::to_value(model)
                .map_err(value_error)?
                .as_str()
                .unwrap_or_default()
        )));
    }
    let base = scene
        .map(SceneSpec::from_json)
        .transpose()
        .map_err(value_error)?;
    let tr = Trace::parse_csv(trace).map_err(value_error)?;
    let band = mode_trace
        .map(|t| Trace::parse_csv(t).map_err(|e| value_error(format!("mode_trace: {e}"))))
        .transpose()?;
    let id = py
        .detach(|| match &band {
            Some(b) => identify(&tr, Model::MassDamperCoulomb).and_then(|r| with_mode(r, b)),
            None => identify(&tr, model),
        })
        .map_err(value_error)?;
    let spec = identified_scene(&id, base);
    spec.validate().map_err(|e| {
        PyValueError::new_err(format!(
            "trace: the identified device is not a valid scene ({e}); the trace does not determine it: excite a wider band or longer"
        ))
    })?;
    serde_json::to_string(&Found {
        identified: id,
        scene: spec,
    })
    .map_err(value_error)
}
