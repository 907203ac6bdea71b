//! Every estimator on one scene, as the 2018 paper's Table I: K-width,
//! B-width, tunable parameters and maximum fidelity error.
//!
//! Default scene: the paper's simulated device (§V): m = 0.52 kg,
//! b = 13.2 N·s/m, f_c = 0.19 N, 1 µm encoder, simulated at 1 kHz, with the
//! paper's tuned parameters: Butterworth ωc = 499 Hz, AKF q = 2.5e4, Levant
//! μ1 = 6.6, μ2 = 2.45. Levant's gains need C, which the papers estimated from
//! a wall hit rendered with FDM + Butterworth; we do the same (`estimate_c`).

use rayon::prelude::*;
use serde::Serialize;

use super::hit::{wall_hit, HitKnobs, TraceRow};
use super::scene::SceneSpec;
use super::search::{map_observed, MapResult, Observer};
use super::settings::{
    Accuracy, Criterion, MapSpec, Method, SearchKind, MAX_REALIZATIONS, MAX_TRIAL_PERIODS,
    PAPER_B_STEP, PAPER_K_STEP,
};
use crate::error::SpecError;
use crate::estimators::{EstimatorKind, EstimatorSpec, FoawFit, FoawSpec, LevantSpec, QModel};
use crate::lipschitz::{self, LipschitzEstimate};

/// The 2018 paper's simulated device at 1 kHz.
pub fn seed_2018_scene() -> SceneSpec {
    SceneSpec::from_json(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#).expect("static scene")
}

/// The wall the Lipschitz constant is estimated on: 5 K steps, 2 B steps of
/// the 2011 paper's grid (a mid-range wall that renders with FDM + filter).
pub const C_WALL_K: f64 = 5.0 * PAPER_K_STEP;
pub const C_WALL_B: f64 = 2.0 * PAPER_B_STEP;

#[derive(Debug, Clone, Serialize)]
pub struct CEstimate {
    pub wall_k: f64,
    pub wall_b: f64,
    pub estimator: EstimatorSpec,
    pub estimate: LipschitzEstimate,
}

/// The 2018 paper's Butterworth cutoff, 499 Hz (its 1 kHz loop), or just
/// below Nyquist (0.499·f_s) on a slower loop.
pub fn paper_cutoff_hz(sample_hz: f64) -> f64 {
    499.0f64.min(0.499 * sample_hz)
}

/// C as the papers measured it: a wall hit with FDM + Butterworth (499 Hz, or
/// just below Nyquist), the encoder positions from first contact for 1 s, and
/// the largest |ẍ| of a smooth fit (see `lipschitz`).
pub fn estimate_c(scene: &SceneSpec) -> Result<CEstimate, SpecError> {
    let fc = paper_cutoff_hz(scene.control.sample_hz);
    let estimator: EstimatorSpec = EstimatorKind::Butterworth {
        cutoff_hz: fc,
        order: 2,
    }
    .into();
    let sc = SceneSpec {
        estimator: estimator.clone(),
        ..scene.clone()
    }
    .validate()?;
    let mut trace: Vec<TraceRow> = Vec::new();
    let knobs = HitKnobs {
        settle_s: 1.0,
        measure_s: 0.1,
    };
    wall_hit(&sc, C_WALL_K, C_WALL_B, knobs, &mut trace);
    let wall = scene.wall.position;
    let first = trace.iter().position(|r| r.y > wall).unwrap_or(0);
    let n = (1.0 / sc.dt) as usize;
    let ys: Vec<f64> = trace[first.saturating_sub(n / 10)..(first + n).min(trace.len())]
        .iter()
        .map(|r| r.y)
        .collect();
    let q = (scene.device.quantization > 0.0).then_some(scene.device.quantization);
    let estimate = lipschitz::estimate(&ys, scene.control.sample_hz, q)?;
    Ok(CEstimate {
        wall_k: C_WALL_K,
        wall_b: C_WALL_B,
        estimator,
        estimate,
    })
}

#[derive(Debug, Clone, Serialize)]
pub struct CompareRow {
    pub name: String,
    pub parameters: String,
    pub estimator: EstimatorSpec,
    pub map: MapResult,
    /// How the parameters were tuned (a tuned comparison), or absent when
    /// they are the paper's fixed values.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tuning: Option<RowTuning>,
    /// Absent: one map. Present: the row was mapped again, finer, to
    /// resolve its K-width orders (`resolve_orders`); `map` is the last.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub refined: Option<Refined>,
}

/// A row's refinement maps (`resolve_orders`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Refined {
    /// Maps after the first.
    pub maps: u32,
    /// The last map's K resolution (relative) and per-verdict confidence.
    pub k_rel_tol: f64,
    pub confidence: f64,
    /// The most realizations its verdicts could take.
    pub realizations: u32,
    /// Σ α over every map of the row (1 − its confidence each): the chance
    /// that any of the row's intervals missed on one side, by the union
    /// bound over the looks.
    pub alpha_spent: f64,
}

/// A row's tune: what it tuned, what it found, what it cost.
#[derive(Debug, Clone, Serialize)]
pub struct RowTuning {
    /// The tuned parameters' values.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Their bounds, as `name: min–max`.
    pub bounds: String,
    /// Maps the tune computed.
    pub evaluations: usize,
    pub elapsed_s: f64,
}

/// Two rows' K-widths in order, and whether the order is resolved.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairOrder {
    /// The row with the larger K-width estimate (of equal ones, the
    /// earlier), and the other (names).
    pub wider: String,
    pub narrower: String,
    /// The wider row's K-width interval lies wholly above the other's: the
    /// order is wrong only if the wider's lower bound or the narrower's
    /// upper bound is, each with probability at most α = 1 − the scene's
    /// confidence (docs/zwidth.md, "Boundaries with intervals").
    pub resolved: bool,
    /// Not resolved, but the two K-widths differ by less than the
    /// accuracy's resolution: the smallest interval holding both is no
    /// wider than one a bisection stops at (`equal_within`).
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub equal: bool,
    /// The bound on that verdict's error: a resolved order is wrong only
    /// if the wider row's lower bound or the narrower's upper bound is
    /// (α each, summed over each row's maps when it was refined); an
    /// "equal" only if one of the four bounds is (twice that). The measured
    /// coverage of one standard map's interval is in docs/zwidth.md.
    pub error_at_most: f64,
}

/// Every pair of rows whose maps have K-width intervals (noisy scenes), in
/// the rows' order: which is wider and whether the intervals say so.
pub fn pair_orders(rows: &[CompareRow], confidence: f64, k_rel_tol: f64) -> Vec<PairOrder> {
    let widths = widths(rows);
    let alpha = |r: &CompareRow| r.refined.map_or(1.0 - confidence, |f| f.alpha_spent);
    orders(&widths)
        .into_iter()
        .map(|o| {
            let (w, n) = (&rows[o.wider], &rows[o.narrower]);
            let equal =
                !o.resolved && equal_within(&widths[o.wider], &widths[o.narrower], k_rel_tol);
            let one_side = alpha(w) + alpha(n);
            PairOrder {
                wider: w.name.clone(),
                narrower: n.name.clone(),
                resolved: o.resolved,
                equal,
                error_at_most: if equal { 2.0 * one_side } else { one_side },
            }
        })
        .collect()
}

/// Whether two K-widths (estimate, interval) differ by less than the
/// resolution `k_rel_tol`: the smallest interval holding both intervals is
/// no wider than one a bisection stops at, hi − lo ≤ k_rel_tol·hi
/// (`bisect.rs`), so both true widths lie in it and differ by at most one
/// resolved interval's width.
pub fn equal_within(
    a: &(f64, Option<[f64; 2]>),
    b: &(f64, Option<[f64; 2]>),
    k_rel_tol: f64,
) -> bool {
    let (Some(ia), Some(ib)) = (a.1, b.1) else {
        return false;
    };
    relative_width(&(0.0, Some([ia[0].min(ib[0]), ia[1].max(ib[1])]))) <= k_rel_tol
}

/// Two widths in order, by their places in the list given to [`orders`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexOrder {
    pub wider: usize,
    pub narrower: usize,
    /// The wider one's interval lies wholly above the other's.
    pub resolved: bool,
}

/// Every pair of `widths` (estimate, interval) that both have intervals, in
/// the list's order: the one with the larger estimate first (of equal
/// ones, the earlier), resolved when its interval lies wholly above the
/// other's. A resolved order is wrong only if the wider one's lower bound
/// or the other's upper bound is: with probability at most 2α, α each
/// bound's error rate (docs/zwidth.md, "Boundaries with intervals").
pub fn orders(widths: &[(f64, Option<[f64; 2]>)]) -> Vec<IndexOrder> {
    let mut out = Vec::new();
    for (i, &(ea, ia)) in widths.iter().enumerate() {
        for (j, &(eb, ib)) in widths.iter().enumerate().skip(i + 1) {
            let (Some(ia), Some(ib)) = (ia, ib) else {
                continue;
            };
            let ((w, iw), (n, in_)) = if eb > ea {
                ((j, ib), (i, ia))
            } else {
                ((i, ia), (j, ib))
            };
            out.push(IndexOrder {
                wider: w,
                narrower: n,
                resolved: iw[0] > in_[1],
            });
        }
    }
    out
}

#[derive(Debug, Clone, Serialize)]
pub struct CompareResult {
    pub lipschitz: CEstimate,
    pub rows: Vec<CompareRow>,
    /// Noisy scenes: each pair of rows' K-widths in order, resolved or not
    /// by their intervals (`pair_orders`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub order: Vec<PairOrder>,
    /// The objective every row was tuned for, or absent: the paper's fixed
    /// parameters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tuned_for: Option<String>,
    /// What refining the rows of unresolved pairs did (`resolve_orders`),
    /// or absent: no refinement rounds were allowed.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub resolution: Option<Resolution>,
    pub elapsed_s: f64,
}

/// Most refinement rounds a comparison may take (`resolve_orders`): the
/// third maps at an eighth of the accuracy's K resolution.
pub const MAX_RESOLVE_ROUNDS: u32 = 3;

/// Refinement rounds a tuned comparison takes unless told otherwise: its
/// point is a ranking (issue 44's item 5).
pub const TUNED_RESOLVE_ROUNDS: u32 = 2;

/// What `resolve_orders` did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Resolution {
    /// Rounds allowed, and rounds that mapped rows.
    pub rounds: u32,
    pub rounds_run: u32,
    /// Pairs neither resolved nor equal within the resolution at the end.
    pub open_pairs: usize,
    /// It ended with pairs open because its rounds did (or because no
    /// finer round could part them), not because it was cancelled.
    pub budget_ended: bool,
    /// Every decided order (resolved or equal) at once is wrong with
    /// probability at most this: both bounds of every row with an
    /// interval, α spent over its maps each (the union bound), at most 1.
    pub joint_error_at_most: f64,
}

/// The refinement rounds a comparison takes: `given`, or 0 (a tuned one
/// `TUNED_RESOLVE_ROUNDS`).
pub fn rounds_or_default(given: Option<u32>, tuned: bool) -> u32 {
    given.unwrap_or(if tuned { TUNED_RESOLVE_ROUNDS } else { 0 })
}

/// `resolve_rounds` must be 0 to `MAX_RESOLVE_ROUNDS`.
pub fn check_rounds(rounds: u32) -> Result<(), SpecError> {
    if rounds > MAX_RESOLVE_ROUNDS {
        return Err(SpecError::new(
            "resolve_rounds",
            rounds,
            format!("must be 0 to {MAX_RESOLVE_ROUNDS} (each round halves the K resolution of the rows whose orders are open)"),
        ));
    }
    Ok(())
}

/// What `rounds` refinement rounds of `n` rows may cost at most (every row
/// mapped again each round).
pub fn refinement_cost(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    rounds: u32,
    n: u64,
) -> Result<super::cost::Cost, SpecError> {
    check_rounds(rounds)?;
    let sc = scene.validate().map_err(|e| e.within("scene"))?;
    let res = accuracy.resolve(&sc)?;
    let mut total = super::cost::Cost::default();
    for r in 1..=rounds {
        let round = Round::new(accuracy, &res, scene.probe.confidence, r);
        total = total.plus(super::search::validate(&round.map_spec(scene, criterion))?.times(n));
    }
    Ok(total)
}

/// Refinement round `r` (1, 2, …) of a comparison at `accuracy` (resolved
/// to `res` on its scene) whose verdicts hold at `confidence`: the K
/// resolution halved `r` times; 2^r times the realizations a verdict may
/// take, within the accuracy's limits (replicates: a row's interval is
/// often wide because verdicts near its boundary stay undecided at the
/// cap, not because the bisection stopped); and the per-verdict error rate α halved `r` times, so that a
/// row's error rates summed over all its maps stay below 2α (α + α/2 +
/// α/4 + …: the union bound over the looks, since whether a row is mapped
/// again depends on its earlier intervals).
#[derive(Debug, Clone, PartialEq)]
struct Round {
    accuracy: Accuracy,
    k_rel_tol: f64,
    realizations: u32,
    confidence: f64,
}

impl Round {
    fn new(accuracy: &Accuracy, res: &super::settings::Resolved, confidence: f64, r: u32) -> Self {
        let scale = 0.5_f64.powi(r as i32);
        let mut knobs = accuracy.knobs();
        // Within the accuracy's limits (`Accuracy::resolve`).
        let by_periods = u32::try_from(MAX_TRIAL_PERIODS / (1 + u64::from(res.probe.periods)))
            .unwrap_or(u32::MAX);
        let realizations = res
            .probe
            .realizations
            .saturating_mul(1 << r.min(16))
            .min(MAX_REALIZATIONS)
            .min(by_periods)
            .max(res.probe.realizations);
        knobs.k_rel_tol = Some(res.k_rel_tol * scale);
        knobs.realizations = Some(realizations);
        Round {
            accuracy: Accuracy::Knobs(knobs),
            k_rel_tol: res.k_rel_tol * scale,
            realizations,
            confidence: 1.0 - (1.0 - confidence) * scale,
        }
    }

    /// The map of `scene` (with its estimator) this round makes.
    fn map_spec(&self, scene: &SceneSpec, criterion: Criterion) -> MapSpec {
        let mut scene = scene.clone();
        scene.probe.confidence = self.confidence;
        map_spec(scene, &self.accuracy, criterion)
    }
}

/// (hi − lo)/hi, bisection's measure of an interval's width (`bisect.rs`
/// stops at hi − lo ≤ k_rel_tol·hi), or infinity without an interval.
fn relative_width(w: &(f64, Option<[f64; 2]>)) -> f64 {
    match w.1 {
        Some([lo, hi]) if hi > 0.0 => (hi - lo) / hi,
        _ => f64::INFINITY,
    }
}

/// The rows a round at resolution `round_tol` maps again: of each pair
/// neither resolved nor equal within `k_rel_tol`, the rows whose interval
/// is wider than `round_tol` (a row already narrower gains little from a
/// finer map), or both when neither is.
fn open_rows(rows: &[CompareRow], k_rel_tol: f64, round_tol: f64) -> Vec<usize> {
    let widths = widths(rows);
    let mut open = vec![false; rows.len()];
    for o in orders(&widths) {
        if o.resolved || equal_within(&widths[o.wider], &widths[o.narrower], k_rel_tol) {
            continue;
        }
        let wide: Vec<usize> = [o.wider, o.narrower]
            .into_iter()
            .filter(|&i| relative_width(&widths[i]) > round_tol)
            .collect();
        if wide.is_empty() {
            open[o.wider] = true;
            open[o.narrower] = true;
        }
        for i in wide {
            open[i] = true;
        }
    }
    (0..rows.len()).filter(|&i| open[i]).collect()
}

fn widths(rows: &[CompareRow]) -> Vec<(f64, Option<[f64; 2]>)> {
    rows.iter()
        .map(|r| (r.map.k_width, r.map.k_width_interval))
        .collect()
}

/// Progress scopes of a comparison of `n` rows with `rounds` refinement
/// rounds: the first maps 0…n−1, then round r's map of row i at r·n + i.
pub fn scopes(n: usize, rounds: u32) -> usize {
    n * (1 + rounds as usize)
}

/// The scope of round `r`'s map of row `i` of `n` (round 0: the first maps).
fn scope_of(n: usize, r: u32, i: usize) -> u32 {
    r * n as u32 + i as u32
}

impl Resolution {
    /// After `run` of `rounds` rounds, `open_pairs` left, `cancelled` or not.
    fn new(rounds: u32, run: u32, open_pairs: usize, cancelled: bool) -> Self {
        Resolution {
            rounds,
            rounds_run: run,
            open_pairs,
            budget_ended: open_pairs > 0 && !cancelled,
            joint_error_at_most: 0.0,
        }
    }
}

/// Map the rows of open pairs again, finer (`Round`, `open_rows`), round after
/// round until every pair is resolved or equal within the first map's
/// resolution, or `rounds` have run. Round r maps row i as scope
/// r·n + i of `observer` (n rows, `scopes`), so a resumed run replays each
/// map; scopes a round does not map are reported done as the round starts
/// (those of rounds not run at the end, unless cancelled). A round cut
/// short by a cancel keeps the rows' earlier maps.
fn resolve_orders(
    ctx: &RowsContext<'_>,
    rows: &mut [CompareRow],
    rounds: u32,
) -> Result<(Vec<PairOrder>, Option<Resolution>), SpecError> {
    let confidence = ctx.scene.probe.confidence;
    let alpha = 1.0 - confidence;
    let tol = ctx.res.k_rel_tol;
    let n = rows.len();
    let mut run = 0;
    let cancelled = || ctx.observer.as_ref().is_some_and(|o| o.cancelled());
    let skip = |r: u32, rows: &[usize]| {
        if let Some(o) = &ctx.observer {
            for &i in rows {
                o.report(scope_of(n, r, i), 1.0);
            }
        }
    };
    for r in 1..=rounds {
        let round = Round::new(ctx.accuracy, &ctx.res, confidence, r);
        let open = open_rows(rows, tol, round.k_rel_tol);
        if open.is_empty() || cancelled() {
            break;
        }
        let idle: Vec<usize> = (0..n).filter(|i| !open.contains(i)).collect();
        skip(r, &idle);
        let maps = open
            .par_iter()
            .map(|&i| {
                let scene = SceneSpec {
                    estimator: rows[i].estimator.clone(),
                    ..ctx.scene.clone()
                };
                let spec = round.map_spec(&scene, ctx.criterion);
                map_observed(&spec, ctx.observer.clone(), scope_of(n, r, i)).map(|m| (i, m))
            })
            .collect::<Result<Vec<_>, SpecError>>()?;
        if cancelled() {
            break;
        }
        for (i, map) in maps {
            let before = rows[i].refined;
            rows[i].map = map;
            rows[i].refined = Some(Refined {
                maps: before.map_or(0, |f| f.maps) + 1,
                k_rel_tol: round.k_rel_tol,
                confidence: round.confidence,
                realizations: round.realizations,
                alpha_spent: before.map_or(alpha, |f| f.alpha_spent) + (1.0 - round.confidence),
            });
        }
        run = r;
    }
    if !cancelled() {
        let all: Vec<usize> = (0..n).collect();
        for r in run + 1..=rounds {
            skip(r, &all);
        }
    }
    let order = pair_orders(rows, confidence, tol);
    let open_pairs = order.iter().filter(|p| !p.resolved && !p.equal).count();
    let joint: f64 = rows
        .iter()
        .filter(|r| r.map.k_width_interval.is_some())
        .map(|r| 2.0 * r.refined.map_or(alpha, |f| f.alpha_spent))
        .sum();
    let resolution = (rounds > 0).then(|| Resolution {
        joint_error_at_most: joint.min(1.0),
        ..Resolution::new(rounds, run, open_pairs, cancelled())
    });
    Ok((order, resolution))
}

/// What every row of one comparison shares.
struct RowsContext<'a> {
    scene: &'a SceneSpec,
    accuracy: &'a Accuracy,
    criterion: Criterion,
    /// The accuracy resolved on the scene.
    res: super::settings::Resolved,
    observer: Option<std::sync::Arc<Observer>>,
}

/// The paper's four estimators with its tuned parameters.
pub fn paper_estimators(scene: &SceneSpec, c: f64) -> Vec<(String, String, EstimatorSpec)> {
    let fc = paper_cutoff_hz(scene.control.sample_hz);
    vec![
        (
            "FDM+filter".into(),
            format!("ωc = {fc} Hz"),
            EstimatorKind::Butterworth {
                cutoff_hz: fc,
                order: 2,
            }
            .into(),
        ),
        (
            "FOAW".into(),
            "none (best-fit, d = encoder step)".into(),
            EstimatorKind::Foaw(FoawSpec {
                fit: FoawFit::Best,
                d: None,
                max_window: 15,
                outlier_tolerance: false,
            })
            .into(),
        ),
        (
            "AKF".into(),
            "q = 2.5e4".into(),
            EstimatorKind::AdaptiveKalman {
                q: 2.5e4,
                q_model: QModel::WhiteJerk,
                rho: crate::estimators::kalman::DEFAULT_RHO,
            }
            .into(),
        ),
        (
            "Levant".into(),
            format!(
                "α = {:.2} m/s², λ = {:.3} m^½/s (μ1 = 6.6, μ2 = 2.45, C = {c:.3})",
                6.6 * c,
                2.45 * c.sqrt()
            ),
            EstimatorKind::Levant(LevantSpec {
                mu1: Some(6.6),
                mu2: Some(2.45),
                lipschitz: Some(c),
                ..Default::default()
            })
            .into(),
        ),
    ]
}

/// The map a comparison runs for each estimator: bisection over
/// B = 0 … 1000 N·s/m by `criterion` (the paper's impedance test, or the
/// time domain's stability), the engine `auto` picks for it.
pub fn map_spec(scene: SceneSpec, accuracy: &Accuracy, criterion: Criterion) -> MapSpec {
    MapSpec {
        scene,
        method: Method::Auto,
        criterion,
        search: SearchKind::Bisect,
        accuracy: accuracy.clone(),
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    }
}

pub fn compare(scene: &SceneSpec, accuracy: &Accuracy) -> Result<CompareResult, SpecError> {
    compare_observed(scene, accuracy, Criterion::Impedance, None, 0, None)
}

/// The same, each estimator's map reporting to `observer` as scope 0, 1, …
/// (its refinement maps after them, `resolve_orders`); `estimators`
/// replaces the paper's four (named by their labels); up to `rounds`
/// refinement rounds resolve the K-width orders.
pub fn compare_observed(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    estimators: Option<&[EstimatorSpec]>,
    rounds: u32,
    observer: Option<std::sync::Arc<Observer>>,
) -> Result<CompareResult, SpecError> {
    check_rounds(rounds)?;
    if let Some(list) = estimators {
        check_estimators(scene, list)?;
    }
    let c = estimate_c(scene)?;
    let estimators = match estimators {
        Some(list) => list
            .iter()
            .map(|e| (e.label(), e.label(), e.clone()))
            .collect(),
        None => paper_estimators(scene, c.estimate.lipschitz),
    };
    if let Some(o) = &observer {
        o.set_scopes(scopes(estimators.len(), rounds));
    }
    compare_rows(scene, accuracy, criterion, c, estimators, rounds, observer)
}

/// Most estimators one compare takes: the same limit in the API, the CLI
/// and Python.
pub const MAX_ESTIMATORS: usize = 20;

/// A compare's own estimator list: 1 to `MAX_ESTIMATORS`, each valid on
/// `scene` (its errors named `estimators[i].…`).
pub fn check_estimators(scene: &SceneSpec, list: &[EstimatorSpec]) -> Result<(), SpecError> {
    if list.is_empty() || list.len() > MAX_ESTIMATORS {
        return Err(SpecError::new(
            "estimators",
            list.len(),
            format!("give 1 to {MAX_ESTIMATORS} estimators, or leave it out for the paper's four"),
        ));
    }
    let sc = scene.validate().map_err(|e| e.within("scene"))?;
    for (i, e) in list.iter().enumerate() {
        sc.with_estimator(e.clone()).map_err(|err| SpecError {
            field: err
                .field
                .replacen("estimator", &format!("estimators[{i}]"), 1),
            ..err
        })?;
    }
    Ok(())
}

/// One map per (name, parameters, estimator), in parallel, as scopes 0, 1, …
/// of `observer` (whose scope count the caller sets).
pub fn compare_rows(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    c: CEstimate,
    estimators: Vec<(String, String, EstimatorSpec)>,
    rounds: u32,
    observer: Option<std::sync::Arc<Observer>>,
) -> Result<CompareResult, SpecError> {
    check_rounds(rounds)?;
    let start = std::time::Instant::now();
    let sc = scene.validate().map_err(|e| e.within("scene"))?;
    let ctx = RowsContext {
        scene,
        accuracy,
        criterion,
        res: accuracy.resolve(&sc)?,
        observer,
    };
    let mut rows = estimators
        .into_par_iter()
        .enumerate()
        .map(|(scope, (name, parameters, estimator))| {
            let spec = map_spec(
                SceneSpec {
                    estimator: estimator.clone(),
                    ..scene.clone()
                },
                accuracy,
                criterion,
            );
            Ok(CompareRow {
                name,
                parameters,
                estimator,
                map: map_observed(&spec, ctx.observer.clone(), scope as u32)?,
                tuning: None,
                refined: None,
            })
        })
        .collect::<Result<Vec<_>, SpecError>>()?;
    let (order, resolution) = resolve_orders(&ctx, &mut rows, rounds)?;
    Ok(CompareResult {
        lipschitz: c,
        order,
        rows,
        tuned_for: None,
        resolution,
        elapsed_s: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
#[path = "compare_tests.rs"]
mod tests;
