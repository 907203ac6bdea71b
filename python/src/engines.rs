//! The engines from Python: a map, a comparison, a tune, one wall hit and
//! the impedance at one (K, B), through zwidth-core with the same specs and
//! the same JSON results as the CLI's `--json` and the API (the Python
//! side, `zwidth/engines.py`, turns them into objects with numpy arrays).
//! The GIL is released while they run; Ctrl-C, or an exception raised in
//! the calling thread, cancels them within a tenth of a second.

use std::sync::atomic::Ordering;
use std::sync::mpsc::RecvTimeoutError;
use std::sync::Arc;
use std::time::Duration;

use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;

use crate::value_error;
use serde::Serialize;

use zwidth_core::error::parse_json;
use zwidth_core::estimators::EstimatorSpec;
use zwidth_core::tune::TuneSpec;
use zwidth_core::zwidth::compare::compare_observed;
use zwidth_core::zwidth::evaluator::Evaluator;
use zwidth_core::zwidth::hit::{wall_hit, HitKnobs, NoTrace};
use zwidth_core::zwidth::scene::{validate_wall, SceneSpec};
use zwidth_core::zwidth::search::{map_observed, Observer};
use zwidth_core::zwidth::settings::{Accuracy, AccuracyKnobs, Criterion, MapSpec, Method};
use zwidth_core::SpecError;

fn to_json(v: &impl Serialize) -> PyResult<String> {
    serde_json::to_string(v).map_err(value_error)
}

/// How often the waiting thread looks for Ctrl-C or a pending exception.
const POLL: Duration = Duration::from_millis(100);

/// Run `work` on its own thread with an observer, the GIL released; every
/// `POLL` take the GIL back to deliver Ctrl-C (`check_signals`, main
/// thread) or an exception another thread raised in this one (a line of
/// Python bytecode runs, which raises it): either cancels the work through
/// its observer, waits for it to stop, and raises.
fn cancellable<T: Send>(
    py: Python<'_>,
    work: impl FnOnce(Arc<Observer>) -> Result<T, SpecError> + Send,
) -> PyResult<T> {
    cancellable_with_progress(py, None, work)
}

/// [`cancellable`], calling `progress(fraction)` (0 to 1, the observer's)
/// at every poll; an exception it raises cancels the work like Ctrl-C.
fn cancellable_with_progress<T: Send>(
    py: Python<'_>,
    progress: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(Arc<Observer>) -> Result<T, SpecError> + Send,
) -> PyResult<T> {
    let observer = Arc::new(Observer::default());
    let (done, mut finished) = std::sync::mpsc::channel();
    std::thread::scope(|s| {
        {
            let observer = Arc::clone(&observer);
            // A panic drops `done` unsent: the receiver sees it disconnect.
            s.spawn(move || done.send(work(observer)));
        }
        loop {
            // The receiver is Send, not Sync: it goes into the GIL-free
            // closure and comes back out.
            let got;
            (got, finished) = py.detach(move || (finished.recv_timeout(POLL), finished));
            match got {
                Ok(r) => return r.map_err(value_error),
                Err(RecvTimeoutError::Disconnected) => {
                    return Err(pyo3::exceptions::PyRuntimeError::new_err(
                        "the engine stopped on an internal error (a bug: please report it)",
                    ))
                }
                Err(RecvTimeoutError::Timeout) => {}
            }
            let interrupted = py
                .check_signals()
                .and_then(|()| py.run(c"pass", None, None))
                .and_then(|()| match progress {
                    Some(f) => f.call1((observer.fraction(),)).map(drop),
                    None => Ok(()),
                });
            if let Err(e) = interrupted {
                observer.cancel.store(true, Ordering::Relaxed);
                // The scope joins the worker, which stops within one trial.
                return Err(e);
            }
        }
    })
}

/// A scene checked as the API checks it (JSON text in), with every
/// default filled in (JSON text out).
#[pyfunction]
pub fn scene_json(scene: &str) -> PyResult<String> {
    let spec = SceneSpec::from_json(scene).map_err(value_error)?;
    spec.validate()
        .map_err(|e| value_error(e.within("scene")))?;
    to_json(&spec)
}

/// A map: the API's map spec (JSON text) in, `zwidth map --json` out.
#[pyfunction]
pub fn map_json(py: Python<'_>, spec: &str) -> PyResult<String> {
    let spec: MapSpec = parse_json(spec, "spec", "map spec")
        .map_err(|e| as_arguments(e, spec))
        .map_err(value_error)?;
    let r = cancellable(py, |o| map_observed(&spec, Some(o), 0))?;
    to_json(&r)
}

/// A tune: the API's tune spec (JSON text) in, `zwidth tune --json` out;
/// `progress(fraction)` is called every tenth of a second while it runs.
#[pyfunction]
#[pyo3(signature = (spec, progress))]
pub fn tune_json(
    py: Python<'_>,
    spec: &str,
    progress: Option<Bound<'_, PyAny>>,
) -> PyResult<String> {
    let parsed: TuneSpec = parse_json(spec, "spec", "tune spec")
        .map_err(|e| as_arguments(e, spec))
        .map_err(value_error)?;
    let tune = parsed.validate().map_err(value_error)?;
    let r = cancellable_with_progress(py, progress.as_ref(), |o| tune.run(Some(o)))?;
    to_json(&r)
}

/// Every estimator of the 2018 paper (or `estimators`, a JSON list of
/// specs) on one scene (JSON text; None: the paper's simulated device),
/// `zwidth compare --json` out.
#[pyfunction]
#[pyo3(signature = (scene, accuracy, criterion, estimators, resolve_rounds = 0))]
pub fn compare_json(
    py: Python<'_>,
    scene: Option<&str>,
    accuracy: &str,
    criterion: &str,
    estimators: Option<&str>,
    resolve_rounds: i64,
) -> PyResult<String> {
    let rounds = u32::try_from(resolve_rounds)
        .map_err(|_| {
            SpecError::new(
                "resolve_rounds",
                resolve_rounds,
                format!(
                    "must be 0 to {}",
                    zwidth_core::zwidth::compare::MAX_RESOLVE_ROUNDS
                ),
            )
        })
        .and_then(|r| zwidth_core::zwidth::compare::check_rounds(r).map(|()| r))
        .map_err(value_error)?;
    let scene = match scene {
        Some(s) => SceneSpec::from_json(s).map_err(value_error)?,
        None => zwidth_core::zwidth::compare::seed_2018_scene(),
    };
    let accuracy: Accuracy = parse_json(accuracy, "accuracy", "accuracy")
        .map_err(|e| as_arguments(e, &format!(r#"{{"accuracy":{accuracy}}}"#)))
        .map_err(value_error)?;
    let criterion: Criterion = field("criterion", criterion)?;
    let estimators: Option<Vec<EstimatorSpec>> = estimators
        .map(|e| parse_json(e, "estimators", "list of estimator specs"))
        .transpose()
        .map_err(value_error)?;
    scene.validate().map_err(value_error)?;
    let r = cancellable(py, |o| {
        compare_observed(
            &scene,
            &accuracy,
            criterion,
            estimators.as_deref(),
            rounds,
            Some(o),
        )
    })?;
    to_json(&r)
}

/// One wall hit (time engine, the scene's own settle and measure times),
/// `zwidth trial --json` out.
#[pyfunction]
pub fn trial_json(py: Python<'_>, scene: &str, k: f64, b: f64) -> PyResult<String> {
    let sc = SceneSpec::from_json(scene)
        .and_then(|s| s.validate())
        .map_err(value_error)?;
    validate_wall(k, b).map_err(value_error)?;
    let knobs = HitKnobs {
        settle_s: sc.spec.hit.settle_s,
        measure_s: sc.spec.hit.measure_s,
    };
    let o = cancellable(py, |_| Ok(wall_hit(&sc, k, b, knobs, &mut NoTrace)))?;
    to_json(&o)
}

/// The rendered wall's impedance over the probe band (analytic when the
/// scene is linear, else simulated), `zwidth impedance --json` out.
#[pyfunction]
pub fn impedance_json(
    py: Python<'_>,
    scene: &str,
    k: f64,
    b: f64,
    method: &str,
    accuracy: &str,
) -> PyResult<String> {
    let sc = SceneSpec::from_json(scene)
        .and_then(|s| s.validate())
        .map_err(value_error)?;
    validate_wall(k, b).map_err(value_error)?;
    let method: Method = field("method", method)?;
    if method == Method::Time {
        return Err(PyValueError::new_err(
            "method = time is not allowed: the impedance needs auto, analytic or frequency",
        ));
    }
    let accuracy: Accuracy = parse_json(accuracy, "accuracy", "accuracy")
        .map_err(|e| as_arguments(e, &format!(r#"{{"accuracy":{accuracy}}}"#)))
        .map_err(value_error)?;
    let res = accuracy.resolve(&sc).map_err(value_error)?;
    let ev = Evaluator::new(sc, method, Criterion::Impedance, res).map_err(value_error)?;
    #[derive(Serialize)]
    struct Out {
        model: String,
        #[serde(flatten)]
        curve: zwidth_core::zwidth::analytic::ImpedanceCurve,
    }
    let curve = cancellable(py, |_| {
        ev.impedance(k, b).ok_or_else(|| {
            SpecError::new(
                "method",
                "time",
                "the impedance needs auto, analytic or frequency",
            )
        })
    })?;
    to_json(&Out {
        model: ev.model_description(),
        curve,
    })
}

/// A spec's parse error as the Python arguments it came from: the field
/// without the `spec.` prefix, and the value itself where it is a word or a
/// number (`method = nope`, not `(as written)`).
fn as_arguments(mut e: SpecError, text: &str) -> SpecError {
    e.field = e.field.trim_start_matches("spec.").to_string();
    if let Ok(doc) = serde_json::from_str::<serde_json::Value>(text) {
        let pointer = format!("/{}", e.field.replace('.', "/"));
        match doc.pointer(&pointer) {
            Some(serde_json::Value::String(v)) => e.value = v.clone(),
            Some(v @ (serde_json::Value::Number(_) | serde_json::Value::Bool(_))) => {
                e.value = v.to_string()
            }
            _ => {}
        }
    }
    e.allowed = e
        .allowed
        .split(" at line ")
        .next()
        .unwrap_or_default()
        .to_string();
    if e.field == "accuracy" && e.allowed.contains("untagged enum Accuracy") {
        e.allowed = r#"must be draft, standard, reference or a dict of knobs ({"preset": "draft", "k_rel_tol": 0.02, …})"#.into();
        // A dict of knobs: say which knob, read as knobs alone (the
        // untagged enum's error names none).
        let knobs = serde_json::from_str::<serde_json::Value>(text)
            .ok()
            .and_then(|d| {
                d.get("accuracy")
                    .filter(|a| a.is_object())
                    .map(|a| a.to_string())
            });
        if let Some(k) = knobs {
            if let Err(inner) = parse_json::<AccuracyKnobs>(&k, "accuracy", "accuracy") {
                return as_arguments(inner, &format!(r#"{{"accuracy":{k}}}"#));
            }
        }
    }
    e
}

/// The 2011 paper's Fig. 2 study: every estimator's RMS velocity error at
/// each sample rate (Hz) through an encoder of step `quantization` (m),
/// `zwidth accuracy --json` out.
#[pyfunction]
pub fn accuracy_json(py: Python<'_>, rates: Vec<f64>, quantization: f64) -> PyResult<String> {
    let cfg = zwidth_core::accuracy::AccuracyConfig {
        rates,
        quantization,
        ..Default::default()
    };
    let report = cancellable(py, |o| {
        zwidth_core::accuracy::run_cancellable(&cfg, &|| o.cancel.load(Ordering::Relaxed))
    })?;
    to_json(&report)
}

/// A choice (`"draft"`, `"impedance"`, …) read as the API reads it, or a
/// ValueError naming the field and the value.
fn field<T: serde::de::DeserializeOwned>(name: &str, value: &str) -> PyResult<T> {
    serde_json::from_value(serde_json::Value::String(value.to_string())).map_err(|e| {
        PyValueError::new_err(format!(
            "{name} = {value} is not allowed: {}",
            e.to_string().split(" at line").next().unwrap_or_default()
        ))
    })
}
