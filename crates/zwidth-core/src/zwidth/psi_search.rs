//! The Psi search (`SearchKind::Psi`): each column's boundary from a
//! posterior told every trial of the column (`psi.rs`), each trial with
//! realizations of its own (`bla::trial_seed`).
//!
//! Two passes. The first locates every column to a few times the
//! resolution (its columns in parallel, the automatic B range ending as a
//! bisection map's does): every fourth column knowing nothing, then the
//! columns halfway between, then the rest, each of these from a prior
//! between its nearest located neighbours (`psi::Prior::between`, wide
//! enough that a jump between them is still found). The second refines,
//! to the resolution, the columns whose interval reaches the largest lower
//! end over the columns: those that may set the K-width. Each pass (and
//! each level of the first) depends only on the verdicts before it, so
//! the map is the same on any number of threads; the map is one unit of
//! work for a farm (`classify::whole_map_unit`).

use std::collections::HashMap;
use std::sync::Mutex;

use rayon::prelude::*;

use super::bla::trial_seed;
use super::classify::Classifier;
use super::point::{BoundaryPoint, Point};
use super::psi::{
    max_estimate, repeat_k, Outcome, Prior, PsiColumn, PsiMarginal, PsiModel, PsiState,
};
use super::settings::MapSpec;

/// Trials a column may take in all.
pub const BUDGET: usize = 100;

/// Trials a column may take in the first pass, and realizations: about
/// what a bisection spends on a column at standard (13–25 trials, 180–210
/// realizations on average over the seed device's and the mode-and-lag
/// scene's columns). A column whose verdicts barely change with K (a
/// shallow escape hazard, Re Z crossing zero slowly, each trial then its
/// full 24 realizations) would otherwise spend the whole budget on a
/// resolution nothing needs; it keeps the wider interval its trials give,
/// unless it may set the K-width (the second pass refines it then).
pub const FIRST_BUDGET: usize = 24;
pub const FIRST_REALIZATIONS: u64 = 240;

/// The first pass's resolution, as a multiple of the preset's (at most
/// ±25 %).
const COARSE: f64 = 4.0;

/// Rounds of the second pass at most: a refined column can raise the
/// largest lower end (and so the upper end every rival is held to), so a
/// round stops a column whose lower end passes the lead and the next one
/// starts from the new lead. The pass ends sooner, when a round runs no
/// trial (every column's budget is a bound on the rounds that do).
const ROUNDS: usize = 64;

/// One column's trials, in order, and what they told its posterior (the
/// posterior itself is rebuilt from them when a pass needs it: a map may
/// have thousands of columns).
#[derive(Default)]
struct Column {
    /// Its neighbours' estimate, or none (`levels`).
    prior: Option<Prior>,
    history: Vec<(usize, Outcome)>,
    points: Vec<Point>,
    /// The marginal posterior of K* after the last trial (from the prior).
    marginal: Option<PsiMarginal>,
    /// The same from the column's own trials alone: what the K-width is
    /// made of (`max_estimate` takes the columns as independent; two
    /// columns that share a neighbour's evidence are not).
    own: Option<PsiMarginal>,
    /// Its boundary point after the first pass.
    point: Option<BoundaryPoint>,
}

impl Column {
    /// Whether it has trials of its budget left.
    fn may_take_trials(&self) -> bool {
        self.history.len() < BUDGET
    }
}

/// Each end of a column's interval is wrong with posterior probability α,
/// the scene's per-verdict error rate.
fn alpha(ev: &Classifier) -> f64 {
    1.0 - ev.scene.spec.probe.confidence
}

fn coarse(ev: &Classifier) -> f64 {
    (COARSE * ev.res.k_rel_tol).min(0.25)
}

/// The map's resolution, in words.
pub(super) fn resolution(ev: &Classifier) -> String {
    format!(
        "K to ±{:.2} % where a column may set the K-width, ±{:.2} % elsewhere or what {FIRST_BUDGET} trials or {FIRST_REALIZATIONS} realizations give ({:.0} % credible intervals of a posterior told every trial of the column, the Psi method; at most {BUDGET} trials a column)",
        100.0 * ev.res.k_rel_tol,
        100.0 * coarse(ev),
        100.0 * (1.0 - 2.0 * alpha(ev)),
    )
}

/// When a column's trials stop, besides its state (`PsiColumn::state`).
#[derive(Clone, Copy)]
struct Stop {
    /// Resolved at this half-width (relative).
    rel_tol: f64,
    /// Or the column has this many trials, or has run this many
    /// realizations.
    budget: usize,
    realizations: u64,
    /// Or: P(K* > K at this lattice point) at most `tail`, unless the
    /// column's own lower end passes `lead` (N/m): it then leads.
    above: Option<(usize, f64, f64)>,
}

/// Tell `c` trials at `b` until `stop` holds, the column is resolved,
/// empty or above the cap, its budget is spent or the run is cancelled;
/// its boundary point.
fn run(
    ev: &Classifier,
    spec: &MapSpec,
    model: &PsiModel,
    b: f64,
    c: &mut Column,
    stop: Stop,
) -> BoundaryPoint {
    let column = ev.columns.get(&b.to_bits()).copied().unwrap_or(0);
    let cancelled = || ev.observer.as_ref().is_some_and(|o| o.cancelled());
    // The second pass refines a column from its own trials alone.
    let refining = stop.above.is_some();
    let prior = if refining { None } else { c.prior };
    let mut psi = PsiColumn::from_history(model, prior, &c.history);
    let alpha = alpha(ev);
    let mut spent: u64 = c
        .points
        .iter()
        .map(|p| u64::from(p.realizations_run()))
        .sum();
    let stopped = |psi: &PsiColumn, spent: u64| {
        spent >= stop.realizations
            || psi.state(model, alpha, stop.rel_tol, stop.budget) != PsiState::Open
            || stop.above.is_some_and(|(m, tail, lead)| {
                psi.marginal_of().tail(m) <= tail || psi.estimate(model, alpha).k_lo > lead
            })
    };
    while !stopped(&psi, spent) && !cancelled() {
        let m = psi.ask(model);
        let k = repeat_k(model.k(m).min(spec.k_max), psi.repeats(m));
        let index = u32::try_from(psi.trials()).unwrap_or(u32::MAX);
        let p = ev.classify_seeded(k, b, trial_seed(ev.scene.spec.probe.seed, column, index));
        psi.tell(model, m, outcome(&p));
        spent += u64::from(p.realizations_run());
        c.points.push(p);
    }
    c.history = psi.history().to_vec();
    c.marginal = Some(psi.marginal_of());
    if refining || c.prior.is_none() {
        c.own = c.marginal.clone();
    }
    boundary_point(ev, model, b, &psi)
}

/// What a trial's verdict tells the posterior.
fn outcome(p: &Point) -> Outcome {
    let realizations = p.realizations_run();
    match (p.diverged(), p.ok()) {
        (true, _) => Outcome::Escaped { at: realizations },
        (_, true) => Outcome::Survived { realizations },
        (_, false) => Outcome::Failed,
    }
}

fn boundary_point(ev: &Classifier, model: &PsiModel, b: f64, psi: &PsiColumn) -> BoundaryPoint {
    let e = psi.estimate(model, alpha(ev));
    BoundaryPoint {
        b,
        k_max: e.k_mid,
        k_lo: Some(e.k_lo),
        k_hi: Some(e.k_hi),
    }
}

/// The share of a Psi map's progress its first pass reports.
const FIRST_PASS: f64 = 0.6;

/// (hi − lo)/(hi + lo): an interval's half-width relative to its centre
/// (0 for an empty one).
fn relative_width(lo: f64, hi: f64) -> f64 {
    if hi + lo > 0.0 {
        (hi - lo) / (hi + lo)
    } else {
        0.0
    }
}

/// How far the K-width's interval has come from `w0` to the resolution
/// `tol`, 0 to 1, on a log scale (each halving of the width counts alike).
fn narrowed(w0: f64, w: f64, tol: f64) -> f64 {
    if w <= tol || w0 <= tol {
        return 1.0;
    }
    ((w0 / w).ln() / (w0 / tol).ln()).clamp(0.0, 1.0)
}

/// The level τ that columns' tails above it are brought down to, so that
/// the tails sum to at most `alpha`: Σ_c min(t_c, τ) = α over the columns
/// that may still take trials, the others' tails counted as they are.
/// Columns already below τ need no trial: α is shared among those above it
/// alone (water-filling). Never below α/N for N columns, the equal share:
/// where spent columns hold most of α the sum cannot reach it without
/// every open column spending its budget, and the K-width's interval is
/// left wider than the resolution instead (`max_estimate` says how wide).
fn water_level(tails: &[(f64, bool)], alpha: f64) -> f64 {
    let equal = alpha / tails.len().max(1) as f64;
    let fixed: f64 = tails.iter().filter(|t| !t.1).map(|t| t.0).sum();
    let mut open: Vec<f64> = tails.iter().filter(|t| t.1).map(|t| t.0).collect();
    let budget = alpha - fixed;
    if open.is_empty() || budget <= 0.0 {
        return equal;
    }
    open.sort_by(|a, b| b.total_cmp(a));
    // The k largest brought to τ = (budget − the rest's sum)/k, the first k
    // for which τ is at least the next one's tail; all of them at last.
    let n = open.len();
    let mut rest: f64 = open.iter().sum();
    for k in 1..n {
        rest -= open[k - 1];
        let level = (budget - rest) / k as f64;
        if level >= open[k] {
            return level.max(equal);
        }
    }
    (budget / n as f64).max(equal)
}

/// Positions of the columns searched first, knowing nothing, among `n` in
/// B order: every fourth and the last.
fn seed_positions(n: usize) -> Vec<usize> {
    let mut seeds: Vec<usize> = (0..n).step_by(4).collect();
    if n > 0 && seeds.last() != Some(&(n - 1)) {
        seeds.push(n - 1);
    }
    seeds
}

/// The columns at `bs` (ascending) not among `seeds` (done), in two
/// levels: halfway between the seeds, then the rest; each starts from a
/// prior between its nearest done neighbours (`Prior::between`). Each level
/// depends only on the ones before it, so the map is the same on any
/// number of threads. Every column's boundary, in the order of `bs`.
fn levels(
    model: &PsiModel,
    bs: &[f64],
    seeds: &[usize],
    columns: &Mutex<HashMap<u64, Column>>,
    first: &(dyn Fn(f64, Option<Prior>) -> BoundaryPoint + Sync),
    report: &dyn Fn(f64),
) -> Vec<BoundaryPoint> {
    let mut done = vec![false; bs.len()];
    for &i in seeds {
        done[i] = true;
    }
    for stride in [2, 1] {
        let level: Vec<usize> = (0..bs.len())
            .filter(|&i| i % stride == 0 && !done[i])
            .collect();
        let priors: Vec<Option<Prior>> = {
            let cols = columns.lock().unwrap_or_else(|e| e.into_inner());
            let marginal = |i: usize| cols.get(&bs[i].to_bits()).and_then(|c| c.marginal.clone());
            level
                .iter()
                .map(|&i| {
                    let below = (0..i).rev().find(|&j| done[j]);
                    let above = (i + 1..bs.len()).find(|&j| done[j]);
                    match (below.and_then(marginal), above.and_then(marginal)) {
                        (Some(a), Some(b)) => Some(Prior::between(model, &a, &b)),
                        _ => None,
                    }
                })
                .collect()
        };
        level.par_iter().zip(priors).for_each(|(&i, prior)| {
            first(bs[i], prior);
        });
        for i in level {
            done[i] = true;
        }
        report(done.iter().filter(|&&d| d).count() as f64 / bs.len().max(1) as f64);
    }
    let cols = columns.lock().unwrap_or_else(|e| e.into_inner());
    bs.iter()
        .map(|&b| {
            cols.get(&b.to_bits())
                .and_then(|c| c.point)
                .unwrap_or(BoundaryPoint {
                    b,
                    k_max: 0.0,
                    k_lo: None,
                    k_hi: None,
                })
        })
        .collect()
}

/// A Psi map: its boundary, its trials in (column, index) order, and the
/// K-width with its interval, the largest K* over the columns
/// (`psi::max_estimate`).
pub(super) struct PsiMap {
    pub boundary: Vec<BoundaryPoint>,
    pub points: Vec<Point>,
    pub k_width: f64,
    pub k_width_interval: [f64; 2],
}

pub(super) fn psi_all(ev: &Classifier, spec: &MapSpec, b_auto: &[f64]) -> PsiMap {
    let model = PsiModel::new(ev.res.k_step, spec.k_max, ev.res.probe.realizations);
    let columns: Mutex<HashMap<u64, Column>> = Mutex::default();
    let coarse = Stop {
        rel_tol: coarse(ev),
        budget: FIRST_BUDGET,
        realizations: FIRST_REALIZATIONS,
        above: None,
    };
    let first = |b: f64, prior: Option<Prior>| {
        let mut c = Column {
            prior,
            ..Column::default()
        };
        let bp = run(ev, spec, &model, b, &mut c, coarse);
        c.point = Some(bp);
        columns
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(b.to_bits(), c);
        bp
    };
    // Progress: the first pass to FIRST_PASS by columns located (the seed
    // columns of the automatic range report their own share through
    // `in_order`), the second from there by the K-width interval's
    // narrowing (`narrowed`).
    let first_pass = |done: f64| ev.report(FIRST_PASS * done);
    let mut boundary: Vec<BoundaryPoint> = match &spec.b {
        Some(bs) => {
            // Each column's neighbours are the next B on either side.
            let mut sorted = bs.clone();
            sorted.sort_by(f64::total_cmp);
            let seeds = seed_positions(sorted.len());
            seeds.par_iter().for_each(|&i| {
                first(sorted[i], None);
            });
            first_pass(seeds.len() as f64 / sorted.len().max(1) as f64);
            let by_b = levels(&model, &sorted, &seeds, &columns, &first, &first_pass);
            bs.iter()
                .map(|b| by_b[sorted.partition_point(|s| s < b)])
                .collect()
        }
        None => {
            // Every fourth column of the automatic range (and the last)
            // until it ends, then those between from their neighbours.
            let seeds = seed_positions(b_auto.len());
            let seed_b: Vec<f64> = seeds.iter().map(|&i| b_auto[i]).collect();
            let done = super::columns::in_order(ev, &seed_b, &|b| (first(b, None), Vec::new()));
            let reach = done.len().checked_sub(1).map_or(0, |last| seeds[last] + 1);
            let seeds: Vec<usize> = seeds[..done.len()].to_vec();
            let mut all: Vec<(BoundaryPoint, Vec<Point>)> = levels(
                &model,
                &b_auto[..reach],
                &seeds,
                &columns,
                &first,
                &first_pass,
            )
            .into_iter()
            .map(|bp| (bp, Vec::new()))
            .collect();
            let cancelled = ev.observer.as_ref().is_some_and(|o| o.cancelled());
            if let Some(end) =
                super::columns::end_of_auto_range(&all, 0, ev.res.k_step).filter(|_| !cancelled)
            {
                super::columns::cut_at_end(ev, &mut all, b_auto, end);
            }
            all.into_iter().map(|(bp, _)| bp).collect()
        }
    };
    let mut columns = columns.into_inner().unwrap_or_else(|e| e.into_inner());
    // The columns that started from a prior, told their own trials alone.
    columns
        .values_mut()
        .filter(|c| c.own.is_none())
        .collect::<Vec<_>>()
        .into_par_iter()
        .for_each(|c| {
            c.own = Some(PsiColumn::from_history(&model, None, &c.history).marginal_of());
        });
    let alpha = alpha(ev);
    let tol = ev.res.k_rel_tol;
    let marginals =
        |columns: &HashMap<u64, Column>, boundary: &[BoundaryPoint]| -> Vec<PsiMarginal> {
            boundary
                .iter()
                .filter_map(|bp| columns.get(&bp.b.to_bits()).and_then(|c| c.own.clone()))
                .collect()
        };
    let mut width0: Option<f64> = None;
    for _ in 0..ROUNDS {
        // The K-width's interval is the largest K*'s: within ±tol once
        // P(max K* > upper) ≤ α, upper = lead·(1 + tol)/(1 − tol) for its
        // lower end `lead`; by the union bound, once Σ_c P(K*_c > upper)
        // ≤ α. The columns whose tail passes the water level (`water_level`)
        // take trials until it is at the level, or until they lead
        // themselves (the next round).
        let max = max_estimate(&model, &marginals(&columns, &boundary), alpha);
        let width = relative_width(max.k_lo, max.k_hi);
        let w0 = *width0.get_or_insert(width);
        ev.report(FIRST_PASS + (1.0 - FIRST_PASS) * narrowed(w0, width, tol));
        let lead = max.k_lo;
        let upper = lead * (1.0 + tol) / (1.0 - tol);
        let m_upper = model.lattice(upper);
        // P(K*_c > upper) per column, and whether it has trials left (a
        // column that cannot lower its tail otherwise, above the cap or
        // resolved, ends the pass through the rounds' `after == before`,
        // its interval as its trials left it).
        let tails: Vec<(usize, f64, bool)> = boundary
            .iter()
            .enumerate()
            .filter_map(|(i, bp)| {
                let c = columns.get(&bp.b.to_bits())?;
                let mg = c.own.as_ref()?;
                Some((i, mg.tail(m_upper), c.may_take_trials()))
            })
            .collect();
        let level: Vec<(f64, bool)> = tails.iter().map(|&(_, t, open)| (t, open)).collect();
        let tail = water_level(&level, alpha);
        let todo: Vec<usize> = tails
            .iter()
            .filter(|&&(_, t, open)| open && t > tail)
            .map(|&(i, _, _)| i)
            .collect();
        if todo.is_empty() || ev.observer.as_ref().is_some_and(|o| o.cancelled()) {
            break;
        }
        let stop = Stop {
            rel_tol: tol / 4.0,
            budget: BUDGET,
            realizations: u64::MAX,
            above: Some((m_upper, tail, lead)),
        };
        let mut taken: Vec<(usize, Column)> = todo
            .iter()
            .filter_map(|&i| columns.remove(&boundary[i].b.to_bits()).map(|c| (i, c)))
            .collect();
        let before: usize = taken.iter().map(|(_, c)| c.history.len()).sum();
        let refined: Vec<BoundaryPoint> = taken
            .par_iter_mut()
            .map(|(i, c)| run(ev, spec, &model, boundary[*i].b, c, stop))
            .collect();
        let after: usize = taken.iter().map(|(_, c)| c.history.len()).sum();
        for ((i, c), bp) in taken.into_iter().zip(refined) {
            boundary[i] = bp;
            columns.insert(bp.b.to_bits(), c);
        }
        if after == before {
            break;
        }
    }
    let max = max_estimate(&model, &marginals(&columns, &boundary), alpha);
    let points = boundary
        .iter()
        .flat_map(|bp| {
            columns
                .remove(&bp.b.to_bits())
                .map(|c| c.points)
                .unwrap_or_default()
        })
        .collect();
    PsiMap {
        boundary,
        points,
        k_width: max.k_mid,
        k_width_interval: [max.k_lo, max.k_hi],
    }
}

#[cfg(test)]
#[path = "psi_search_tests.rs"]
mod tests;
