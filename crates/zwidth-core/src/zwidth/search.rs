//! Searches over (K, B) and the map result.
//!
//! - `trace`: the 2011 paper's §2.4 protocol. Start at B = 0, K = one step;
//!   at each B, raise K by steps while the wall renders, or lower it until it
//!   does; record the largest K that rendered; carry the first K that did
//!   not to the next B (one step up); stop when K reaches 0 or B passes b_max.
//! - `bisect`: for each B, bracket K by doubling/halving from one step, then
//!   bisect to the relative tolerance `k_rel_tol`; B values run in parallel.
//! - `grid`: every (K, B) on the step grid, in parallel.
//!
//! "Renders" is the criterion: stable, passive (impedance test) or strictly
//! passive. Strict passivity on the analytic engine is solved directly.

use rayon::prelude::*;
use serde::Serialize;
use std::time::Instant;

use super::classify::{whole_map_unit, Classifier};
use super::columns::{column_units, farmed_batches, in_order, planned_b};
use super::cost::Cost;
pub use super::evaluator::{noisy_verdicts, Evaluator};
use super::farm::Unit;
pub use super::observer::{Observer, StoredEvaluation};
pub use super::point::{BoundaryPoint, Point, StoredTrial};
use super::prior::{Prediction, Prior, PriorReport};
use super::scene::validate_wall;
use super::settings::{Criterion, MapSpec, Method, Resolved, SearchKind};
use crate::error::SpecError;

#[derive(Debug, Clone, Serialize)]
pub struct MapResult {
    /// Which model produced the result, in words.
    pub model: String,
    pub method: Method,
    pub criterion: Criterion,
    pub search: SearchKind,
    pub accuracy: Resolved,
    /// Resolution of the boundary, in words.
    pub resolution: String,
    pub boundary: Vec<BoundaryPoint>,
    /// Largest K on the boundary (N/m).
    pub k_width: f64,
    /// Largest B with a K that renders (N·s/m).
    pub b_width: f64,
    /// Noisy scenes: confidence intervals of the K-width (N/m) and B-width
    /// (N·s/m) from the boundary's intervals, at the scene's confidence
    /// per verdict (docs/zwidth.md).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_width_interval: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub b_width_interval: Option<[f64; 2]>,
    /// Largest fidelity error over the passive points (N·s/m); impedance criteria only.
    pub max_fidelity_error: Option<f64>,
    /// Area of the region that renders, ∫ K_max dB over the boundary
    /// (trapezoids; N/m · N·s/m).
    pub area: f64,
    pub points: Vec<Point>,
    pub trials: usize,
    /// Trials in which the device's force limit clipped the wall force
    /// (0 without a limit; their verdicts reflect the actuator too).
    pub saturated_trials: usize,
    /// When any trial saturated: which, in words.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub saturation: Option<String>,
    /// With a `prior`: the prediction beside the map's boundary, column by
    /// column, and where they disagree.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub prior: Option<PriorReport>,
    pub elapsed_s: f64,
}

/// Run a map.
pub fn map(spec: &MapSpec) -> Result<MapResult, SpecError> {
    map_observed(spec, None, 0)
}

/// Whether a map's verdicts are noisy (friction or quantization probed in
/// the frequency domain: the BLA verdict with intervals).
pub fn noisy(spec: &MapSpec) -> Result<bool, SpecError> {
    prepare(spec).map(|(ev, _)| ev.noisy())
}

/// Validate a map request completely without running it; what it will cost.
pub fn validate(spec: &MapSpec) -> Result<Cost, SpecError> {
    prepare(spec).map(|(_, cost)| cost)
}

fn prepare(spec: &MapSpec) -> Result<(Evaluator, Cost), SpecError> {
    let scene = spec.scene.validate().map_err(|e| e.within("scene"))?;
    let res = spec.accuracy.resolve(&scene)?;
    if !(spec.b_max.is_finite() && spec.b_max > 0.0 && spec.b_max <= 1e6) {
        return Err(SpecError::new(
            "b_max",
            spec.b_max,
            "must be a damping > 0 and at most 1e6 N·s/m",
        ));
    }
    if !(spec.k_max.is_finite() && spec.k_max > 0.0 && spec.k_max <= 1e9) {
        return Err(SpecError::new(
            "k_max",
            spec.k_max,
            "must be > 0 and at most 1e9 N/m",
        ));
    }
    // The lattice searches step K by k_step: a k_max below one step leaves
    // them nothing to search (and used to report a K-width above k_max).
    if matches!(spec.search, SearchKind::Trace | SearchKind::Grid) && spec.k_max < res.k_step {
        return Err(SpecError::new(
            "k_max",
            spec.k_max,
            format!(
                "must be at least the K step of the {} search, {} N/m at this accuracy (or search by bisection)",
                spec.search.name(),
                res.k_step
            ),
        ));
    }
    if let Some(bs) = &spec.b {
        if bs.is_empty() {
            return Err(SpecError::new(
                "b",
                "[]",
                "give at least one damping value, or leave b out",
            ));
        }
        for (i, &b) in bs.iter().enumerate() {
            validate_wall(0.0, b)?;
            // Each B once: a column is where its B is in the list.
            if bs[..i].iter().any(|&a| a.to_bits() == b.to_bits()) {
                return Err(SpecError::new(
                    "b",
                    b,
                    "appears twice in the list; give each damping value once",
                ));
            }
        }
    }
    check_prior(spec)?;
    let mut ev = Evaluator::new(scene, spec.method, spec.criterion, res)?;
    if defined_by_its_trial(spec, &ev) {
        let trial = spec.accuracy.standard_trial().resolve(&ev.scene)?;
        (ev.res.probe, ev.res.hit) = (trial.probe, trial.hit);
    }
    let exact = ev.criterion == Criterion::StrictPassivity && ev.model.is_some();
    if exact && spec.prior.is_some() {
        return Err(SpecError::new(
            "prior",
            "(given)",
            "no search to seed: strict passivity on the analytic model is solved per B exactly",
        ));
    }
    // Planned as the search that runs: Psi where verdicts are random
    // draws, the bisection for a Psi map elsewhere (`Evaluator::runs_psi`).
    let cost = if spec.search == SearchKind::Psi && !ev.runs_psi(spec.search) {
        let runs = MapSpec {
            search: SearchKind::Bisect,
            ..spec.clone()
        };
        super::cost::of_map(&runs, &ev.res, exact)?
    } else {
        super::cost::of_map(spec, &ev.res, exact)?
    };
    Ok((ev, cost.plus(prior_cost(spec)?)))
}

/// What simulating a scene prior costs (its map's trials, run in this
/// process and not stored); nothing for any other prior.
fn prior_cost(spec: &MapSpec) -> Result<Cost, SpecError> {
    let Some(Prior::Scene(scene)) = &spec.prior else {
        return Ok(Cost::default());
    };
    let predicting = MapSpec {
        scene: (**scene).clone(),
        prior: None,
        ..spec.clone()
    };
    let (_, c) = prepare(&predicting).map_err(|e| e.within("prior"))?;
    Ok(Cost {
        stored_rows: 0,
        stored_bytes: 0,
        ..c
    })
}

/// Whether the map's boundary is defined by its trial (the Psi search on
/// random verdicts): every preset then runs the standard preset's trial.
fn defined_by_its_trial(spec: &MapSpec, ev: &Evaluator) -> bool {
    ev.runs_psi(spec.search)
}

/// A prior is for the bisection searches, and its scene or boundary must
/// be valid; a run's id is the service's to read (`Prior::Run`).
fn check_prior(spec: &MapSpec) -> Result<(), SpecError> {
    let Some(prior) = &spec.prior else {
        return Ok(());
    };
    if !matches!(spec.search, SearchKind::Bisect | SearchKind::RobustBisect) {
        return Err(SpecError::new(
            "prior",
            spec.search.name(),
            "a prior seeds the bisection searches (search bisect or robust_bisect)",
        ));
    }
    match prior {
        Prior::Scene(s) => s.validate().map(|_| ()).map_err(|e| e.within("prior.scene")),
        Prior::Boundary(points) => Prediction::new(points.clone()).map(|_| ()),
        Prior::Run(id) => Err(SpecError::new(
            "prior.run",
            id,
            "a run's map is read by the service (POST /v1/experiments); here give its boundary (prior.boundary, or `zwidth map --prior-map FILE`)",
        )),
    }
}

/// `spec` with its prior's prediction at hand: a scene simulated now (in
/// this process, never on the map's rig; cancelled with the run
/// `observer` watches) and given to the columns as its boundary, so that a
/// farm's workers search from the same bits without simulating again. The
/// map's own spec is checked first, so its faults are named as its own.
fn with_prediction<'a>(
    spec: &'a MapSpec,
    observer: Option<&std::sync::Arc<Observer>>,
) -> Result<(std::borrow::Cow<'a, MapSpec>, Option<Prediction>), SpecError> {
    let Some(prior) = &spec.prior else {
        return Ok((std::borrow::Cow::Borrowed(spec), None));
    };
    prepare(spec)?;
    if observer.is_some_and(|o| o.cancelled()) {
        return Ok((std::borrow::Cow::Borrowed(spec), None));
    }
    let points = match prior {
        Prior::Scene(scene) => {
            let predicting = MapSpec {
                scene: (**scene).clone(),
                prior: None,
                ..spec.clone()
            };
            let sub = std::sync::Arc::new(Observer::default());
            let done = std::sync::atomic::AtomicBool::new(false);
            let predicted = std::thread::scope(|s| {
                if let Some(o) = observer {
                    s.spawn(|| {
                        while !done.load(std::sync::atomic::Ordering::Relaxed) {
                            if o.cancelled() {
                                sub.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
                                return;
                            }
                            std::thread::sleep(std::time::Duration::from_millis(20));
                        }
                    });
                }
                let r = map_observed(&predicting, Some(sub.clone()), 0);
                done.store(true, std::sync::atomic::Ordering::Relaxed);
                r
            })
            .map_err(|e| e.within("prior"))?;
            if sub.cancelled() {
                // The run was cancelled meanwhile: its map ends at once.
                return Ok((std::borrow::Cow::Borrowed(spec), None));
            }
            predicted.boundary
        }
        Prior::Boundary(points) => points.clone(),
        Prior::Run(_) => unreachable!("refused by prepare (check_prior)"),
    };
    let prediction = Prediction::new(points.clone())?;
    let resolved = MapSpec {
        prior: Some(Prior::Boundary(points)),
        ..spec.clone()
    };
    Ok((std::borrow::Cow::Owned(resolved), Some(prediction)))
}

/// Which trials the force limit clipped, and how many boundary points such
/// a trial decided (a boundary point is set by the first failure above its
/// `k_max`: limited by the actuator when that trial saturated). None when
/// no trial saturated.
fn saturation_note(points: &[Point], boundary: &[BoundaryPoint], limit: f64) -> Option<String> {
    let saturated: Vec<&Point> = points
        .iter()
        .filter(|p| p.saturated == Some(true))
        .collect();
    if saturated.is_empty() {
        return None;
    }
    let k_min = saturated.iter().map(|p| p.k).fold(f64::INFINITY, f64::min);
    let on_boundary = boundary
        .iter()
        .filter(|bp| {
            points
                .iter()
                .filter(|p| p.b == bp.b && p.k > bp.k_max && !p.ok())
                .min_by(|a, b| a.k.total_cmp(&b.k))
                .is_some_and(|p| p.saturated == Some(true))
        })
        .count();
    Some(format!(
        "the force limit ±{limit} N clipped the wall force in {} of {} trials (from K = {k_min:.4e} N/m); {on_boundary} of {} boundary points were decided by such a trial: there the actuator limits the width, not the estimator",
        saturated.len(),
        points.len(),
        boundary.len()
    ))
}

/// Run a map, reporting trials to and honouring cancellation from
/// `observer`; `scope` names this map within its experiment.
pub fn map_observed(
    spec: &MapSpec,
    observer: Option<std::sync::Arc<Observer>>,
    scope: u32,
) -> Result<MapResult, SpecError> {
    let start = Instant::now();
    let source = spec.prior.as_ref().map(Prior::source);
    let (spec, prediction) = with_prediction(spec, observer.as_ref())?;
    let spec = spec.as_ref();
    let (ev, b_auto) = map_evaluator(spec, observer, scope)?;
    let res = ev.res;
    // A trace (each B starts from the last) and the analytic engine (closed
    // forms) are one unit of work each: with a farm, the whole map is
    // computed elsewhere and replayed here.
    if whole_map_unit(spec, &ev) {
        ev.farm_units(spec, &[Unit::Map], &|_| {});
    }
    // The Psi search states the K-width as the largest K* over its columns.
    let mut psi_width: Option<(f64, [f64; 2])> = None;
    let (boundary, points) = match (spec.search, ev.criterion, &ev.model) {
        (_, Criterion::StrictPassivity, Some(m)) => {
            // Exact per B: no search needed.
            let mut boundary = Vec::new();
            let mut points = Vec::new();
            for &b in spec.b.as_ref().unwrap_or(&b_auto) {
                match m.strict_passivity_range(b) {
                    Some((_, hi)) => {
                        let k = hi.min(spec.k_max);
                        boundary.push(BoundaryPoint::new(b, k));
                        points.push(ev.classify(k, b));
                    }
                    None if spec.b.is_none() => break,
                    None => boundary.push(BoundaryPoint::new(b, 0.0)),
                }
            }
            (boundary, points)
        }
        (SearchKind::Psi, _, _) if ev.runs_psi(spec.search) => {
            let m = super::psi_search::psi_all(&ev, spec, &b_auto);
            psi_width = Some((m.k_width, m.k_width_interval));
            (m.boundary, m.points)
        }
        (SearchKind::Bisect | SearchKind::RobustBisect | SearchKind::Psi, _, _) => {
            bisect_all(&ev, spec, &b_auto, prediction.as_ref())
        }
        (SearchKind::Trace, _, _) => trace(&ev, spec, &b_auto),
        (SearchKind::Grid, _, _) => grid(&ev, spec, &b_auto),
    };
    let mut k_width = boundary.iter().map(|p| p.k_max).fold(0.0, f64::max);
    let b_width = boundary
        .iter()
        .filter(|p| p.k_max > 0.0)
        .map(|p| p.b)
        .fold(0.0, f64::max);
    let (mut k_width_interval, b_width_interval) = widths_interval(&boundary, res.k_step);
    if let Some((k, interval)) = psi_width {
        (k_width, k_width_interval) = (k, Some(interval));
    }
    let max_fidelity_error = points
        .iter()
        .filter(|p| p.passive == Some(true))
        .filter_map(|p| p.fidelity)
        .reduce(f64::max);
    // A cancelled map is not done: its progress stays where it stopped.
    if !ev.observer.as_ref().is_some_and(|o| o.cancelled()) {
        ev.report(1.0);
    }
    let area = area(&boundary);
    let resolution = match (spec.search, ev.criterion, ev.method) {
        (_, Criterion::StrictPassivity, _) => {
            "exact per B (θ grid of 8192 points, refined)".to_string()
        }
        (SearchKind::Psi, _, _) if ev.runs_psi(spec.search) => {
            super::psi_search::resolution(&ev)
        }
        (SearchKind::Bisect | SearchKind::Psi, _, _) => {
            format!("K to {:.2} % (bisection)", 100.0 * res.k_rel_tol)
        }
        (SearchKind::RobustBisect, _, _) => format!(
            "K to {:.2} % (bisection, checked at 0.3–0.9 of the result: the first failure from below)",
            100.0 * res.k_rel_tol
        ),
        _ => format!("K step {} N/m, B step {} N·s/m", res.k_step, res.b_step),
    };
    let saturation = saturation_note(
        &points,
        &boundary,
        ev.scene.spec.device.force_limit.unwrap_or(f64::INFINITY),
    );
    let saturated_trials = points.iter().filter(|p| p.saturated == Some(true)).count();
    let prior = prediction
        .as_ref()
        .zip(source)
        .map(|(p, source)| super::prior::report(source, p, &boundary, res.k_rel_tol, points.len()));
    Ok(MapResult {
        model: ev.model_description(),
        method: ev.method,
        criterion: ev.criterion,
        search: spec.search,
        accuracy: res,
        resolution,
        boundary,
        k_width,
        b_width,
        k_width_interval,
        b_width_interval,
        max_fidelity_error,
        area,
        trials: points.len(),
        saturated_trials,
        saturation,
        points,
        prior,
        elapsed_s: start.elapsed().as_secs_f64(),
    })
}

/// The evaluator of map `scope` reporting to `observer`, and the automatic
/// B range (empty when the spec gives a list).
fn map_evaluator(
    spec: &MapSpec,
    observer: Option<std::sync::Arc<Observer>>,
    scope: u32,
) -> Result<(Classifier, Vec<f64>), SpecError> {
    let (ev, _) = prepare(spec)?;
    let mut ev = Classifier::new(ev);
    ev.accuracy = Some(if defined_by_its_trial(spec, &ev) {
        spec.accuracy.standard_trial()
    } else {
        spec.accuracy.clone()
    });
    ev.observer = observer;
    ev.scope = scope;
    // The automatic B range, only when no list is given (its length was
    // checked against the limits in `prepare`).
    let b_auto: Vec<f64> = match spec.b {
        Some(_) => Vec::new(),
        None => (0..)
            .map(|i| i as f64 * ev.res.b_step)
            .take_while(|&b| b <= spec.b_max + 1e-9)
            .collect(),
    };
    // Each B's column: its first place in the list.
    for (i, b) in spec.b.as_deref().unwrap_or(&b_auto).iter().enumerate() {
        ev.columns.entry(b.to_bits()).or_insert(i as u32);
    }
    Ok((ev, b_auto))
}

/// Compute one column of map `scope` (a farmed unit, see `farm.rs`): the
/// bisection of `b` (with its interval on a noisy scene), or the grid's K
/// values at `b`, trials going to `observer`. The trials, and their
/// places, are those the whole map computes for that column.
pub fn column_observed(
    spec: &MapSpec,
    b: f64,
    observer: std::sync::Arc<Observer>,
    scope: u32,
) -> Result<(), SpecError> {
    let (spec, prediction) = with_prediction(spec, Some(&observer))?;
    let spec = spec.as_ref();
    let (ev, b_auto) = map_evaluator(spec, Some(observer), scope)?;
    let in_map = spec.b.as_deref().unwrap_or(&b_auto);
    if whole_map_unit(spec, &ev) || !in_map.iter().any(|x| x.to_bits() == b.to_bits()) {
        return Err(SpecError::new(
            "b",
            b,
            "is not a column of this map that is computed on its own (a bisection or grid column of its B list)",
        ));
    }
    match spec.search {
        SearchKind::Grid => {
            for k in grid_ks(&ev, spec) {
                ev.classify(k, b);
            }
        }
        _ => {
            bisect_column(&ev, spec, b, prediction.as_ref());
        }
    }
    ev.report(1.0);
    Ok(())
}

/// Compute `unit` of map `scope` (the work of one claimed unit), its trials
/// going to `observer` (which replays what an earlier attempt stored):
/// the column's search, or the whole map.
pub fn run_unit(
    spec: &MapSpec,
    scope: u32,
    unit: Unit,
    observer: std::sync::Arc<Observer>,
) -> Result<(), SpecError> {
    match unit {
        Unit::Column { b, .. } => column_observed(spec, b, observer, scope),
        Unit::Map => map_observed(spec, Some(observer), scope).map(|_| ()),
    }
}

/// The K-width and B-width intervals from the boundary's: K-width lies
/// between the largest lower and the largest upper bound; B-width between
/// the largest B whose lower bound renders and the largest B that is not
/// surely empty (its upper bound above the smallest K searched, `k_floor`).
/// The automatic B range runs until two columns are surely empty, so the
/// upper end is not cut short by the columns searched, except at `b_max`.
/// `None` when the boundary has no intervals.
fn widths_interval(
    boundary: &[BoundaryPoint],
    k_floor: f64,
) -> (Option<[f64; 2]>, Option<[f64; 2]>) {
    if boundary.is_empty()
        || boundary
            .iter()
            .any(|p| p.k_lo.is_none() || p.k_hi.is_none())
    {
        return (None, None);
    }
    let max_of = |f: &dyn Fn(&BoundaryPoint) -> f64| boundary.iter().map(f).fold(0.0, f64::max);
    let k = [
        max_of(&|p| p.k_lo.unwrap_or(0.0)),
        max_of(&|p| p.k_hi.unwrap_or(0.0)),
    ];
    let b_of = |f: &dyn Fn(&BoundaryPoint) -> f64| {
        boundary
            .iter()
            .filter(|p| f(p) > 0.0)
            .map(|p| p.b)
            .fold(0.0, f64::max)
    };
    let b = [
        b_of(&|p| p.k_lo.unwrap_or(0.0)),
        b_of(&|p| p.k_hi.map_or(0.0, |h| if h > k_floor { h } else { 0.0 })),
    ];
    (Some(k), Some(b))
}

/// ∫ K_max dB over a boundary, by trapezoids between successive B values
/// (sorted by B); a single point has no area.
pub fn area(boundary: &[BoundaryPoint]) -> f64 {
    let mut pts: Vec<(f64, f64)> = boundary.iter().map(|p| (p.b, p.k_max)).collect();
    pts.sort_by(|a, b| a.0.total_cmp(&b.0));
    pts.windows(2)
        .map(|w| 0.5 * (w[1].0 - w[0].0) * (w[0].1 + w[1].1))
        .sum()
}

/// One column of a bisection map: the largest K that renders at `b`, with
/// its interval on a noisy scene, and the trials that found it.
fn bisect_column(
    ev: &Classifier,
    spec: &MapSpec,
    b: f64,
    prediction: Option<&Prediction>,
) -> (BoundaryPoint, Vec<Point>) {
    let mut pts = Vec::new();
    let robust = spec.search == SearchKind::RobustBisect;
    let start = prediction.map(|p| p.start(b, ev.res.k_rel_tol));
    let k = ev.bisect_k(b, ev.res.k_step, spec.k_max, robust, start, &mut pts);
    let mut bp = BoundaryPoint::new(b, k.unwrap_or(0.0));
    if ev.noisy() {
        ev.interval(
            &mut bp,
            ev.res.k_step,
            spec.k_max,
            start.is_some(),
            &mut pts,
        );
    }
    (bp, pts)
}

fn bisect_all(
    ev: &Classifier,
    spec: &MapSpec,
    b_auto: &[f64],
    prediction: Option<&Prediction>,
) -> (Vec<BoundaryPoint>, Vec<Point>) {
    let one = |b: f64| bisect_column(ev, spec, b, prediction);
    if let Some(bs) = &spec.b {
        // With a farm, every column is computed elsewhere first (in
        // parallel), then replayed here.
        ev.farm_units(spec, &column_units(ev, bs), &|n| {
            ev.report(n as f64 / bs.len() as f64)
        });
        let finished = std::sync::atomic::AtomicUsize::new(0);
        let r: Vec<_> = bs
            .par_iter()
            .map(|&b| {
                let r = one(b);
                let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                ev.report(n as f64 / bs.len() as f64);
                r
            })
            .collect();
        let points = r.iter().flat_map(|(_, p)| p.clone()).collect();
        return (r.into_iter().map(|(b, _)| b).collect(), points);
    }
    // B in parallel; the map ends at the first two B values in a row that
    // surely render nothing (on a noisy scene, an empty column whose
    // verdicts at the smallest K were undecided does not count: B-width's
    // interval needs the columns beyond it). Columns run past that end are
    // dropped, trials and all, so the map is the same on any number of
    // threads (issue 14). Columns farmed out go in the farm's batches; a
    // map computed (or replayed whole) here takes its columns in order, one
    // per free thread.
    let k_floor = ev.res.k_step;
    let columns = match ev.farm() {
        Some(f) if !whole_map_unit(spec, ev) => {
            farmed_batches(ev, spec, b_auto, f.batch().max(2), &one)
        }
        _ => in_order(ev, b_auto, &one),
    };
    let points = columns
        .iter()
        .flat_map(|(_, p)| p.iter().cloned())
        .collect();
    let mut boundary: Vec<BoundaryPoint> = columns.into_iter().map(|(bp, _)| bp).collect();
    // Drop the trailing B values that render nothing but the first.
    while boundary.len() >= 2
        && boundary[boundary.len() - 1].surely_empty(k_floor)
        && boundary[boundary.len() - 2].surely_empty(k_floor)
    {
        boundary.pop();
    }
    (boundary, points)
}

fn trace(ev: &Classifier, spec: &MapSpec, b_auto: &[f64]) -> (Vec<BoundaryPoint>, Vec<Point>) {
    let step = ev.res.k_step;
    let (mut boundary, mut points) = (Vec::new(), Vec::new());
    let mut eval = |k: f64, b: f64| {
        let p = ev.classify(k, b);
        let ok = p.ok();
        points.push(p);
        ok
    };
    let mut k = step;
    for &b in spec.b.as_deref().unwrap_or(b_auto) {
        let k_max;
        if eval(k, b) {
            while k + step <= spec.k_max && eval(k + step, b) {
                k += step;
            }
            k_max = k;
        } else {
            while k > step && !eval(k - step, b) {
                k -= step;
            }
            k -= step;
            if k < step * 0.5 {
                boundary.push(BoundaryPoint::new(b, 0.0));
                if spec.b.is_none() {
                    break; // K decreased to zero: the paper's termination
                }
                k = step;
                continue;
            }
            k_max = k;
        }
        boundary.push(BoundaryPoint::new(b, k_max));
        k = (k_max + step).min(spec.k_max);
        let planned = match &spec.b {
            Some(bs) => bs.len(),
            None => planned_b(&boundary, b_auto.len(), ev.res.b_step),
        };
        ev.report(boundary.len() as f64 / planned as f64);
    }
    (boundary, points)
}

/// The K values of a grid map's columns: up to 60 steps of `k_step`.
fn grid_ks(ev: &Classifier, spec: &MapSpec) -> Vec<f64> {
    let step = ev.res.k_step;
    let nk = ((spec.k_max / step).floor() as usize).clamp(1, 60);
    (1..=nk).map(|i| i as f64 * step).collect()
}

fn grid(ev: &Classifier, spec: &MapSpec, b_auto: &[f64]) -> (Vec<BoundaryPoint>, Vec<Point>) {
    let ks = grid_ks(ev, spec);
    let bs = spec
        .b
        .clone()
        .unwrap_or_else(|| b_auto.iter().copied().take(60).collect());
    ev.farm_units(spec, &column_units(ev, &bs), &|n| {
        ev.report(n as f64 / bs.len() as f64)
    });
    let total = (bs.len() * ks.len()).max(1);
    let finished = std::sync::atomic::AtomicUsize::new(0);
    let points: Vec<Point> = bs
        .par_iter()
        .flat_map_iter(|&b| ks.iter().map(move |&k| (k, b)))
        .map(|(k, b)| {
            let p = ev.classify(k, b);
            let n = finished.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if n.is_multiple_of(16) {
                ev.report(n as f64 / total as f64);
            }
            p
        })
        .collect();
    let boundary = bs
        .iter()
        .map(|&b| {
            let k_max = points
                .iter()
                .filter(|p| p.b == b && p.ok())
                .map(|p| p.k)
                .fold(0.0, f64::max);
            BoundaryPoint::new(b, k_max)
        })
        .collect();
    (boundary, points)
}

#[cfg(test)]
#[path = "in_order_tests.rs"]
mod in_order_tests;
#[cfg(test)]
#[path = "search_prior_tests.rs"]
mod prior_tests;
#[cfg(test)]
#[path = "search_tests.rs"]
mod tests;
