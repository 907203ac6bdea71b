//! Bisection along K at one B (the searches' inner loop), pure: it sees
//! only a verdict closure, so a scripted verdict can test it.

use super::point::Point;
use super::prior::Start;

/// Where a bisection along K starts, how far it may go and how fine it ends.
#[derive(Debug, Clone, Copy)]
pub(super) struct Bracket {
    pub k0: f64,
    pub k_cap: f64,
    pub rel_tol: f64,
}

/// Largest K whose verdict (`classify`, at one B) renders: bracket from
/// `k0` by doubling or halving (or from a predicted `start`, widened until
/// the verdicts bracket the boundary: `bisect_from`), then bisect to
/// `rel_tol`. With `robust`,
/// fractions of the result below it are checked, and a failure there moves
/// the search below it: the result is the first failure from below, not
/// whichever edge of a non-monotone verdict the bracket happened to find.
pub(super) fn bisect_k(
    mut classify: impl FnMut(f64) -> Point,
    bounds: Bracket,
    robust: bool,
    start: Option<Start>,
    points: &mut Vec<Point>,
) -> Option<f64> {
    let k0 = bounds.k0;
    let mut k = match start {
        None => bisect_once(&mut classify, bounds, points)?,
        Some(s) => bisect_from(&mut classify, bounds, s, points)?,
    };
    if !robust {
        return Some(k);
    }
    // Fractions of the result checked below it, lowest first.
    const CHECKS: [f64; 5] = [0.3, 0.45, 0.6, 0.75, 0.9];
    for _ in 0..8 {
        let below = CHECKS
            .iter()
            .map(|f| f * k)
            .filter(|&x| x >= k0)
            .find(|&x| {
                let p = classify(x);
                let ok = p.ok();
                points.push(p);
                !ok
            });
        let Some(fail) = below else { return Some(k) };
        // Bisect between the highest pass below the failure and it.
        let mut lo = points
            .iter()
            .filter(|p| p.ok() && p.k < fail)
            .map(|p| p.k)
            .fold(0.0, f64::max);
        if lo < k0 && start.is_some() {
            // From a prediction nothing below the bracket was tried (a
            // search from k0 passed k0, 2·k0, …): halve down from the
            // failure for a pass, as a search from k0 would have met one.
            let floor = k0.min(bounds.k_cap) / 1024.0;
            lo = halve_until(&mut classify, fail, floor, Point::ok, points);
            if lo == 0.0 {
                return None;
            }
        } else if lo < k0 {
            return None;
        }
        k = bisect_between(&mut classify, lo, fail, bounds.rel_tol, points);
    }
    Some(k)
}

/// The first K whose verdict `keep`s, halving down from `from`, never
/// below `floor` (0: none). `keep` is `Point::ok` for a pass,
/// `Point::surely_ok` for one decided passive.
fn halve_until(
    classify: &mut impl FnMut(f64) -> Point,
    from: f64,
    floor: f64,
    keep: impl Fn(&Point) -> bool,
    points: &mut Vec<Point>,
) -> f64 {
    let mut k = from;
    while k.is_finite() && k / 2.0 >= floor {
        k /= 2.0;
        let p = classify(k);
        let kept = keep(&p);
        points.push(p);
        if kept {
            return k;
        }
    }
    0.0
}

fn bisect_between(
    classify: &mut impl FnMut(f64) -> Point,
    lo: f64,
    hi: f64,
    rel_tol: f64,
    points: &mut Vec<Point>,
) -> f64 {
    bisect_edge(classify, lo, hi, rel_tol, points, Point::ok).0
}

/// Bisect `[lo, hi]`, where `keep` holds at `lo` and not at `hi`, until
/// `hi − lo ≤ rel_tol·hi` (or no f64 lies between them); the final pair.
fn bisect_edge(
    classify: &mut impl FnMut(f64) -> Point,
    mut lo: f64,
    mut hi: f64,
    rel_tol: f64,
    points: &mut Vec<Point>,
    keep: impl Fn(&Point) -> bool,
) -> (f64, f64) {
    while (hi - lo) > rel_tol * hi {
        let mid = 0.5 * (lo + hi);
        if !(mid > lo && mid < hi) {
            break; // no f64 between them: as fine as it gets
        }
        let p = classify(mid);
        let kept = keep(&p);
        points.push(p);
        if kept {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (lo, hi)
}

fn bisect_once(
    classify: &mut impl FnMut(f64) -> Point,
    bounds: Bracket,
    points: &mut Vec<Point>,
) -> Option<f64> {
    let Bracket { k0, k_cap, rel_tol } = bounds;
    // Never past the cap, even when the cap is below the first step (a
    // map asked for K up to 1 000 N/m at a 2 976 N/m draft step).
    let k0 = k0.min(k_cap);
    let mut eval = |k: f64| {
        let p = classify(k);
        let ok = p.ok();
        points.push(p);
        ok
    };
    let (mut lo, mut hi);
    if eval(k0) {
        lo = k0;
        loop {
            let k = (lo * 2.0).min(k_cap);
            if k <= lo {
                return Some(lo);
            }
            if eval(k) {
                lo = k;
            } else {
                hi = k;
                break;
            }
        }
    } else {
        hi = k0;
        loop {
            let k = hi / 2.0;
            if k < k0 / 1024.0 {
                return None;
            }
            if eval(k) {
                lo = k;
                break;
            }
            hi = k;
        }
    }
    Some(bisect_between(classify, lo, hi, rel_tol, points))
}

/// The bisection from a predicted `start` (`prior.rs`): the verdicts at
/// the bracket's ends first; where they do not bracket the boundary, the
/// bracket moves out by galloping in ln K (steps of the bracket's own log
/// width w, then 2w, 4w, …) until they do, then bisection to `rel_tol`. A
/// prediction that is right costs two trials before the bisection; one that
/// is off by a factor r costs about 2·log2(|ln r| / w) more. Nothing
/// renders (None) when `k0 / 1024` does not, as from `k0` (`bisect_once`);
/// a column predicted empty checks `k0` and then that floor directly.
fn bisect_from(
    classify: &mut impl FnMut(f64) -> Point,
    bounds: Bracket,
    start: Start,
    points: &mut Vec<Point>,
) -> Option<f64> {
    let Bracket { k0, k_cap, rel_tol } = bounds;
    let floor = k0.min(k_cap) / 1024.0;
    let mut eval = |k: f64| {
        let p = classify(k);
        let ok = p.ok();
        points.push(p);
        ok
    };
    let (lo0, hi0) = match start {
        // A predicted bracket wider than a factor of 2 (an interval whose
        // upper end was never decided) is searched from its lower half:
        // the gallop finds the rest, bisection's midpoints are arithmetic.
        Start::Bracket { lo, hi } => {
            let lo = lo.clamp(floor, k_cap);
            (lo, hi.min(2.0 * lo).min(k_cap))
        }
        // Predicted empty: from the first step, as a search from k0 would.
        Start::Empty => {
            let k = k0.min(k_cap);
            (k, (2.0 * k).min(k_cap))
        }
    };
    // The gallop's first step: the predicted bracket's log width, at least
    // the resolution's.
    let w = (hi0 / lo0).ln().max(rel_tol.ln_1p());
    let (lo, hi);
    if eval(lo0) {
        // Up from lo0: hi0 first, then galloping.
        let mut ok_k = lo0;
        let mut k = if hi0 > lo0 {
            hi0
        } else {
            (lo0 * w.exp()).min(k_cap)
        };
        let mut step = w;
        loop {
            if k <= ok_k {
                return Some(ok_k); // the cap renders
            }
            if !eval(k) {
                (lo, hi) = (ok_k, k);
                break;
            }
            ok_k = k;
            step *= 2.0;
            k = (ok_k * step.exp()).min(k_cap);
        }
    } else {
        // Down from lo0, galloping, never below the floor.
        let mut fail_k = lo0;
        let mut step = if matches!(start, Start::Empty) {
            f64::INFINITY
        } else {
            w
        };
        loop {
            if fail_k <= floor {
                return None;
            }
            let k = (fail_k * (-step).exp()).max(floor);
            if eval(k) {
                (lo, hi) = (k, fail_k);
                break;
            }
            fail_k = k;
            step *= 2.0;
        }
    }
    Some(bisect_between(classify, lo, hi, rel_tol, points))
}

/// Before `interval` on a search that started from a prediction: a search
/// from `k0` has passed the low K where every verdict is decided passive,
/// one from a bracket near the boundary may not have, and `interval` would
/// then find no lower end (0). So when no K below the first decided
/// failure is decided passive, halve from the lowest K tried until one is
/// (or the floor `k0 / 1024` is passed, where the column stays without one).
pub(super) fn anchor_below(
    mut classify: impl FnMut(f64) -> Point,
    bounds: Bracket,
    points: &mut Vec<Point>,
) {
    let first_fail = points
        .iter()
        .filter(|p| p.surely_not_ok())
        .map(|p| p.k)
        .fold(f64::INFINITY, f64::min);
    if points.iter().any(|p| p.surely_ok() && p.k < first_fail) {
        return;
    }
    let floor = bounds.k0.min(bounds.k_cap) / 1024.0;
    let lowest = points.iter().map(|p| p.k).fold(first_fail, f64::min);
    halve_until(&mut classify, lowest, floor, Point::surely_ok, points);
}

/// A confidence interval around a boundary `k_est` found on a noisy
/// verdict (`Point::decided`). Taking the margin to fall with K (the
/// assumption bisection makes too), a K decided passive bounds the boundary
/// from below and one decided not passive from above: `lo` is the largest
/// K decided passive below every K decided not passive, `hi` the smallest
/// K decided not passive above `lo`, each refined by bisection to `rel_tol`
/// against the undecided points next to it. The boundary lies below `lo`
/// only if the verdict at `lo` was wrong, above `hi` only if that at `hi`
/// was: each with probability at most the scene's error rate. When nothing
/// was decided not passive, K doubles from the estimate until something is
/// or `k_cap` is reached (`hi` is then `None`).
pub(super) fn interval(
    mut classify: impl FnMut(f64) -> Point,
    k_est: f64,
    bounds: Bracket,
    points: &mut Vec<Point>,
) -> (f64, Option<f64>) {
    let rel_tol = bounds.rel_tol;
    let min_k = |pts: &[Point], keep: &dyn Fn(&Point) -> bool| {
        pts.iter()
            .filter(|p| keep(p))
            .map(|p| p.k)
            .fold(f64::INFINITY, f64::min)
    };
    let max_k = |pts: &[Point], keep: &dyn Fn(&Point) -> bool| {
        pts.iter()
            .filter(|p| keep(p))
            .map(|p| p.k)
            .fold(0.0, f64::max)
    };
    // Nothing decided not passive yet: look above the estimate.
    if min_k(points, &|p| p.surely_not_ok()).is_infinite() {
        let mut k = k_est.max(bounds.k0);
        while k < bounds.k_cap {
            k = (2.0 * k).min(bounds.k_cap);
            let p = classify(k);
            let stop = p.surely_not_ok();
            points.push(p);
            if stop {
                break;
            }
        }
    }
    let first_fail = min_k(points, &|p| p.surely_not_ok());
    let mut lo = max_k(points, &|p| p.surely_ok() && p.k < first_fail);
    // Refine: bisect between lo and the next point above it that is not
    // decided passive.
    let lo_top = min_k(points, &|p| !p.surely_ok() && p.k > lo);
    if lo > 0.0 && lo_top.is_finite() {
        lo = bisect_edge(&mut classify, lo, lo_top, rel_tol, points, Point::surely_ok).0;
    }
    let hi = min_k(points, &|p| p.surely_not_ok() && p.k > lo);
    if hi.is_infinite() {
        return (lo, None);
    }
    // Never below the smallest K searched: with nothing kept below `hi`
    // (every K decided not passive, an empty column) the edge would halve
    // towards 0 until f64 runs out (a thousand trials).
    let searched = min_k(points, &|_| true).min(hi);
    let hi_bottom = max_k(points, &|p| !p.surely_not_ok() && p.k < hi)
        .max(lo)
        .max(searched);
    let keep = |p: &Point| !p.surely_not_ok();
    let hi = bisect_edge(&mut classify, hi_bottom, hi, rel_tol, points, keep).1;
    (lo, Some(hi))
}

#[cfg(test)]
#[path = "bisect_prior_tests.rs"]
mod prior_tests;
#[cfg(test)]
#[path = "bisect_tests.rs"]
mod tests;
