//! The `zwidth` Python package's native module: the estimators through
//! zwidth-core (the JSON spec the API takes, with its messages), built
//! from zwidth-dsp: the same bits as the simulator and the C ABI; and the
//! engines (`engines.rs`).

use numpy::{PyArray1, PyReadonlyArray1};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyString};

use zwidth_core::estimators::{Estimator as Built, EstimatorSpec, Sampling, VelocityEstimator};

mod engines;
mod identify;
mod json;

/// How long `Estimator.run` computes between looks for Ctrl-C.
const POLL: std::time::Duration = std::time::Duration::from_millis(100);

/// A velocity estimator: `Estimator(spec, rate_hz, quantization)`.
///
/// `spec` is the API's JSON estimator spec, as a str or a dict
/// (`{"kind": "kalman", "q": 1e4}`); `rate_hz` the sample rate (Hz);
/// `quantization` the encoder step (m). `step(y)` takes one position (m)
/// and returns the velocity (m/s); `run(positions)` a 1-D array of them
/// (the GIL released); `reset()` forgets the history.
///
/// Threads: one Estimator is used by one thread at a time (it is one
/// filter's state); a call from a second thread while one runs raises
/// RuntimeError ("Already borrowed") and changes nothing. Estimators are
/// independent: one per thread run in parallel.
#[pyclass(module = "zwidth")]
struct Estimator {
    built: Built,
    label: String,
    fingerprint: u64,
}

/// The spec as JSON text: a str as it is, a dict written as JSON.
fn spec_text(spec: &Bound<'_, PyAny>) -> PyResult<String> {
    if spec.is_instance_of::<PyString>() {
        return spec.extract::<String>();
    }
    if spec.is_instance_of::<PyDict>() {
        return json::dumps(spec, "spec");
    }
    Err(PyValueError::new_err(format!(
        "spec = {} is not allowed: a JSON estimator spec, as a str or a dict",
        spec.get_type().name()?
    )))
}

/// Any error as a ValueError with its message (the spec errors name the field).
pub(crate) fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

/// `obj` as positions (m): a contiguous float64 array read as it is,
/// anything else through `zwidth._arrays.positions` (one conversion for
/// the package, naming `name` when it refuses).
fn positions_of(py: Python<'_>, name: &str, obj: &Bound<'_, PyAny>) -> PyResult<Vec<f64>> {
    if let Ok(a) = obj.extract::<PyReadonlyArray1<'_, f64>>() {
        if let Ok(s) = a.as_slice() {
            return Ok(s.to_vec());
        }
    }
    let converted = py
        .import("zwidth._arrays")?
        .call_method1("positions", (name, obj))?;
    let a: PyReadonlyArray1<'_, f64> = converted.extract()?;
    Ok(a.as_slice().map_err(value_error)?.to_vec())
}

/// A position that is not a finite number, named with its index.
fn check_finite(ys: &[f64]) -> PyResult<()> {
    match ys.iter().position(|y| !y.is_finite()) {
        None => Ok(()),
        Some(i) => Err(PyValueError::new_err(format!(
            "positions[{i}] is not allowed: every position must be a finite number (m)"
        ))),
    }
}

impl Estimator {
    /// Estimates `v` (the first at position index `from`) all finite, or a
    /// ValueError naming the position whose estimate overflowed, the
    /// estimator reset (as the C ABI does: a position far enough out,
    /// ±1e308 m into a difference, made every later estimate inf or NaN).
    fn overflowed(&mut self, v: &[f64], from: usize) -> PyResult<()> {
        match v.iter().position(|x| !x.is_finite()) {
            None => Ok(()),
            Some(i) => {
                self.built.reset();
                Err(PyValueError::new_err(format!(
                    "positions[{}] is not allowed: its estimate overflowed (not a finite number); the estimator was reset",
                    from + i
                )))
            }
        }
    }
}

#[pymethods]
impl Estimator {
    #[new]
    fn new(spec: &Bound<'_, PyAny>, rate_hz: f64, quantization: f64) -> PyResult<Self> {
        let text = spec_text(spec)?;
        let sampling = Sampling::new(rate_hz, quantization).map_err(value_error)?;
        let spec = EstimatorSpec::from_json(&text).map_err(value_error)?;
        let built = spec.build(sampling).map_err(value_error)?;
        let dsp = spec.to_dsp().map_err(value_error)?;
        // The fingerprint a rig would report for this spec (the kind's
        // coefficients, as the C ABI and the agent compute it).
        let fingerprint =
            zwidth_dsp::estimator::fingerprint(&dsp, rate_hz, quantization).map_err(value_error)?;
        Ok(Self {
            built,
            label: spec.label(),
            fingerprint,
        })
    }

    /// One position (m) in, the velocity estimate (m/s) out.
    fn step(&mut self, y: f64) -> PyResult<f64> {
        check_finite(&[y])?;
        let v = self.built.update(y);
        self.overflowed(&[v], 0)?;
        Ok(v)
    }

    /// Velocities (m/s) for positions (m), in order: a 1-D array of any
    /// numeric dtype (converted), a list or tuple, a strided view (copied),
    /// or a table (structured or record array, DataFrame, dict) by its
    /// `position_m` column; anything else is a ValueError naming it.
    fn run<'py>(
        &mut self,
        py: Python<'py>,
        positions: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyArray1<f64>>> {
        let ys = positions_of(py, "positions", positions)?;
        check_finite(&ys)?;
        // In slices of about POLL, the GIL taken back between them to
        // deliver Ctrl-C: one sample can cost milliseconds (FOAW's best
        // fit over a long window), so a million took over an hour deaf to
        // it (issue 45). Interrupted, the estimator keeps the samples it
        // took.
        let mut out = Vec::with_capacity(ys.len());
        while out.len() < ys.len() {
            let built = &mut self.built;
            let rest = &ys[out.len()..];
            let slice = py.detach(move || {
                let start = std::time::Instant::now();
                let mut v = Vec::new();
                for chunk in rest.chunks(64) {
                    v.extend(chunk.iter().map(|&y| built.update(y)));
                    if start.elapsed() >= POLL {
                        break;
                    }
                }
                v
            });
            let from = out.len();
            out.extend(slice);
            self.overflowed(&out[from..], from)?;
            py.check_signals()?;
        }
        Ok(PyArray1::from_vec(py, out))
    }

    /// Forget all history, as if newly built.
    fn reset(&mut self) {
        self.built.reset();
    }

    /// FNV-1a of the built coefficients' bits (what a rig reports).
    #[getter]
    fn fingerprint(&self) -> u64 {
        self.fingerprint
    }

    fn __repr__(&self) -> String {
        format!("Estimator({})", self.label)
    }
}

/// The estimator library's identity, `{"version": …, "fingerprints":
/// {kind: 16 hex digits, …}}`: what a rig driver advertises under `"dsp"`
/// in its capabilities, so the server can tell whether the rig runs its
/// estimators to the bit (docs/rigs.md).
#[pyfunction]
fn dsp_identity(py: Python<'_>) -> PyResult<Py<PyAny>> {
    let text = serde_json::to_string(&zwidth_core::estimators::identity::DspIdentity::ours())
        .map_err(value_error)?;
    json::loads(py, &text)
}

#[pymodule]
fn _zwidth(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Estimator>()?;
    m.add_function(wrap_pyfunction!(dsp_identity, m)?)?;
    m.add_function(wrap_pyfunction!(engines::scene_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::map_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::compare_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::tune_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::accuracy_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::trial_json, m)?)?;
    m.add_function(wrap_pyfunction!(engines::impedance_json, m)?)?;
    m.add_function(wrap_pyfunction!(identify::record_csv, m)?)?;
    m.add_function(wrap_pyfunction!(identify::identify_json, m)?)?;
    m.add_function(wrap_pyfunction!(json::loads, m)?)?;
    m.add_function(wrap_pyfunction!(json::dumps, m)?)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("dsp_version", zwidth_dsp::VERSION)?;
    Ok(())
}
