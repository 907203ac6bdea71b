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
            lo = pass_below(&mut classify, fail, k0.min(bounds.k_cap) / 1024.0, points);
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

/// The first K that renders halving down from `fail`, not below `floor`
/// (0: none).
fn pass_below(
    classify: &mut impl FnMut(f64) -> Point,
    fail: f64,
    floor: f64,
    points: &mut Vec<Point>,
) -> f64 {
    let mut k = fail;
    while k / 2.0 >= floor {
        k /= 2.0;
        let p = classify(k);
        let ok = p.ok();
        points.push(p);
        if ok {
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
    let mut k = points.iter().map(|p| p.k).fold(first_fail, f64::min);
    while k.is_finite() && k / 2.0 >= floor {
        k /= 2.0;
        let p = classify(k);
        let ok = p.surely_ok();
        points.push(p);
        if ok {
            return;
        }
    }
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
mod tests {
    use super::*;

    /// A scripted verdict at one B: renders below 1500 N/m, fails on
    /// [1500, 2000), renders again on [2000, 4000), fails from 4000.
    fn scripted(k: f64) -> Point {
        let ok = k < 1500.0 || (2000.0..4000.0).contains(&k);
        Point {
            k,
            b: 0.0,
            stable: Some(ok),
            ..Point::default()
        }
    }

    const BRACKET: Bracket = Bracket {
        k0: 10.0,
        k_cap: 1e7,
        rel_tol: 1e-3,
    };

    #[test]
    fn the_result_never_exceeds_the_cap() {
        // Everything renders below 1500 N/m; a cap of 1000 below the first
        // step of 2976: the largest K searched is the cap itself.
        let capped = Bracket {
            k0: 2976.0,
            k_cap: 1000.0,
            rel_tol: 1e-3,
        };
        for robust in [false, true] {
            let mut pts = Vec::new();
            let k = bisect_k(scripted, capped, robust, None, &mut pts).unwrap();
            assert_eq!(k, 1000.0, "robust {robust}");
            assert!(pts.iter().all(|p| p.k <= 1000.0), "{pts:?}");
        }
    }

    #[test]
    fn robust_bisection_returns_the_first_failure_from_below() {
        // Plain bisection doubles 10, 20, …, 2560 (all render: 1280 < 1500,
        // 2560 in the second band) and fails at 5120, so it finds the upper
        // edge, 4000, to 0.1 %.
        let mut pts = Vec::new();
        let plain = bisect_k(scripted, BRACKET, false, None, &mut pts).unwrap();
        assert!(plain < 4000.0 && plain > 4000.0 * (1.0 - 1e-3), "{plain}");
        // Robust: the check at 0.45 of that (≈ 1800) fails, so it bisects
        // between the highest pass below it (1280) and that failure, down to
        // the script's first failure, 1500; 0.3…0.9 of 1500 all render.
        let mut pts = Vec::new();
        let robust = bisect_k(scripted, BRACKET, true, None, &mut pts).unwrap();
        assert!(
            robust < 1500.0 && robust > 1500.0 * (1.0 - 1e-3),
            "{robust}"
        );
        // The check that found the failure is among the points.
        assert!(pts.iter().any(|p| p.k == 0.45 * plain && !p.ok()));
        for f in [0.3, 0.45, 0.6, 0.75, 0.9] {
            assert!(
                pts.iter().any(|p| p.k == f * robust && p.ok()),
                "check at {f} of the result"
            );
        }
        // Nothing between the result and the first failure is called good:
        // every point above the result that renders is in the second band.
        assert!(pts
            .iter()
            .all(|p| p.k <= robust || !p.ok() || p.k >= 2000.0));
    }

    #[test]
    fn bisection_brackets_down_and_gives_up_below_k0_over_1024() {
        // Renders below 70 N/m only, from k0 = 1000: halves 500, 250, 125,
        // 62.5 (renders), then bisects [62.5, 125] down to 70.
        let below_70 = |k: f64| Point {
            stable: Some(k < 70.0),
            ..scripted(k)
        };
        let b = Bracket {
            k0: 1000.0,
            ..BRACKET
        };
        let mut pts = Vec::new();
        let k = bisect_k(below_70, b, false, None, &mut pts).unwrap();
        assert!(k < 70.0 && k > 70.0 * (1.0 - 1e-3), "{k}");
        assert_eq!(
            pts[..5].iter().map(|p| p.k).collect::<Vec<_>>(),
            [1000.0, 500.0, 250.0, 125.0, 62.5]
        );
        // Nothing renders above k0/1024: no boundary, after exactly eleven
        // trials (k0 and ten halvings down to k0/1024).
        let never = |k: f64| Point {
            stable: Some(k < 1000.0 / 1024.0 * 0.99),
            ..scripted(k)
        };
        let mut pts = Vec::new();
        assert_eq!(bisect_k(never, b, false, None, &mut pts), None);
        assert_eq!(pts.len(), 11);
        // Everything renders: doubling stops at the cap, which is the result.
        let always = |k: f64| Point {
            stable: Some(true),
            ..scripted(k)
        };
        let capped = Bracket { k_cap: 3000.0, ..b };
        let mut pts = Vec::new();
        assert_eq!(bisect_k(always, capped, true, None, &mut pts), Some(3000.0));
        // 1000, 2000, 3000 (capped), then the robust checks at or above k0:
        // 0.45…0.9 of 3000 (0.3·3000 = 900 < k0 is not checked).
        assert_eq!(pts.len(), 3 + 4);
    }

    /// The bracket of the three-way tests below.
    const NOISY: Bracket = Bracket {
        k0: 100.0,
        k_cap: 1e6,
        rel_tol: 0.001,
    };

    /// A scripted three-way verdict: decided passive below 1000 N/m,
    /// undecided in [1000, 1200) with the estimate's sign changing at 1100,
    /// decided not passive from 1200.
    fn three_way(k: f64) -> Point {
        Point {
            k,
            passive: Some(k < 1100.0),
            decided: Some(!(1000.0..1200.0).contains(&k)),
            ..Point::default()
        }
    }

    #[test]
    fn interval_brackets_the_undecided_band() {
        let b = NOISY;
        let mut pts = Vec::new();
        let est = bisect_k(three_way, b, false, None, &mut pts).unwrap();
        assert!((est - 1100.0).abs() <= 1.1, "{est}");
        let (lo, hi) = interval(three_way, est, b, &mut pts);
        let hi = hi.unwrap();
        // Each edge to rel_tol: lo just below 1000, hi at or just above 1200.
        assert!(
            (1000.0 * (1.0 - 0.001) - 1e-9..1000.0).contains(&lo),
            "{lo}"
        );
        assert!((1200.0..=1200.0 * (1.0 + 0.0011)).contains(&hi), "{hi}");
        // Every point is a scripted one, and the new ones lie by the edges.
        assert!(pts.iter().all(|p| *p == three_way(p.k)));
    }

    #[test]
    fn interval_looks_above_when_nothing_was_refuted() {
        // Undecided (sign positive) from 1000 up to the cap: no upper bound.
        let never_refuted = |k: f64| Point {
            k,
            passive: Some(true),
            decided: Some(k < 1000.0),
            ..Point::default()
        };
        let b = Bracket {
            k0: 100.0,
            k_cap: 6400.0,
            rel_tol: 0.01,
        };
        let mut pts = Vec::new();
        let est = bisect_k(never_refuted, b, false, None, &mut pts).unwrap();
        assert_eq!(est, 6400.0);
        let (lo, hi) = interval(never_refuted, est, b, &mut pts);
        assert_eq!(hi, None);
        assert!(lo < 1000.0 && lo > 990.0 - 1e-9, "{lo}");
        // A refutation above the estimate is found by doubling from it.
        let refuted_at_2k = |k: f64| Point {
            decided: Some(!(1000.0..2000.0).contains(&k)),
            passive: Some(k < 1500.0),
            ..never_refuted(k)
        };
        let mut pts = vec![refuted_at_2k(1000.0), refuted_at_2k(1400.0)];
        let (_, hi) = interval(refuted_at_2k, 1400.0, b, &mut pts);
        let hi = hi.unwrap();
        assert!((2000.0..=2000.0 * 1.011).contains(&hi), "{hi}");
    }

    /// Undecided in [1013, 1234) with the sign changing at 1100, and an
    /// isolated undecided (positive) point at 400: neither edge lies on the
    /// bisection's dyadic points, so both must be refined.
    fn ragged(k: f64) -> Point {
        Point {
            k,
            passive: Some(k < 1100.0),
            decided: Some(!(1013.0..1234.0).contains(&k) && k != 400.0),
            ..Point::default()
        }
    }

    #[test]
    fn interval_refines_both_edges_past_undecided_points() {
        let b = NOISY;
        // The search visits 400 (undecided) on its way up.
        let mut pts = Vec::new();
        let est = bisect_k(ragged, b, false, None, &mut pts).unwrap();
        assert!(pts.iter().any(|p| p.k == 400.0 && p.decided == Some(false)));
        let before = pts.len();
        let (lo, hi) = interval(ragged, est, b, &mut pts);
        let hi = hi.unwrap();
        assert!((1013.0 * 0.999 - 1e-9..1013.0).contains(&lo), "{lo}");
        assert!((1234.0..=1234.0 * 1.0011).contains(&hi), "{hi}");
        // Each edge by bisection from the search's points: a handful of
        // trials, log2 of the gap over the tolerance.
        assert!(
            pts.len() - before <= 2 * 10,
            "{} new trials",
            pts.len() - before
        );
    }

    #[test]
    fn interval_has_no_lower_bound_when_nothing_was_decided_passive() {
        // Decided passive only below 50; the search starts at 100, where
        // everything up to 1234 is undecided: nothing bounds the boundary
        // from below among the points searched, and none is added below k0.
        let low = |k: f64| Point {
            k,
            passive: Some(k < 1100.0),
            decided: Some(!(50.0..1234.0).contains(&k)),
            ..Point::default()
        };
        let b = NOISY;
        let mut pts = Vec::new();
        let est = bisect_k(low, b, false, None, &mut pts).unwrap();
        let (lo, hi) = interval(low, est, b, &mut pts);
        assert_eq!(lo, 0.0);
        assert!(pts.iter().all(|p| p.k >= 100.0), "nothing below k0");
        assert!((1234.0..=1234.0 * 1.0011).contains(&hi.unwrap()));
    }

    #[test]
    fn an_empty_column_costs_no_trials_below_the_search() {
        // Decided not passive everywhere (a B no K renders at): bisection
        // gives up at k0/1024 (ten halvings), and the interval's upper edge
        // is the smallest K it tried, with no trial below it (the edge used
        // to halve on towards 0 until f64 ran out: 1 074 trials a column).
        let none = |k: f64| Point {
            k,
            passive: Some(false),
            decided: Some(true),
            ..Point::default()
        };
        let b = NOISY;
        let mut pts = Vec::new();
        assert_eq!(bisect_k(none, b, false, None, &mut pts), None);
        let floor = pts.iter().map(|p| p.k).fold(f64::INFINITY, f64::min);
        assert_eq!((pts.len(), floor), (11, b.k0 / 1024.0));
        let (lo, hi) = interval(none, 0.0, b, &mut pts);
        assert_eq!((lo, hi), (0.0, Some(floor)));
        assert_eq!(pts.len(), 11, "no trial added");
    }

    #[test]
    fn a_boundary_below_the_first_step_still_gets_a_refined_upper_edge() {
        // k0 = 1000: decided passive below 100, undecided (failing) on
        // [100, 200), decided not passive from 200. Bisection walks down
        // 1000, 500, 250, 125, 62.5; the upper edge is refined from the
        // undecided 125 up to the refutation at 250, to 200 (within 1 %),
        // not left at 250 (a second review found the floor at k0 did).
        let v = |k: f64| Point {
            k,
            passive: Some(k < 100.0),
            decided: Some(!(100.0..200.0).contains(&k)),
            ..Point::default()
        };
        let b = Bracket {
            k0: 1000.0,
            k_cap: 1e6,
            rel_tol: 0.01,
        };
        let mut pts = Vec::new();
        let est = bisect_k(v, b, false, None, &mut pts).unwrap();
        let (_, hi) = interval(v, est, b, &mut pts);
        let hi = hi.unwrap();
        assert!((200.0..=202.0).contains(&hi), "{hi}");
    }

    #[test]
    fn interval_doubles_up_to_a_refutation() {
        // Nothing refuted among the given points; refuted from 5000: the
        // look above doubles from the estimate 1400 (2800, 5600), so two
        // new points, then the edge is bisected between 2800 and 5600.
        let v = |k: f64| Point {
            k,
            passive: Some(k < 1500.0),
            decided: Some(!(1000.0..5000.0).contains(&k)),
            ..Point::default()
        };
        let b = Bracket {
            k0: 100.0,
            k_cap: 1e6,
            rel_tol: 0.01,
        };
        let mut pts = vec![v(1000.0), v(1400.0)];
        let (_, hi) = interval(v, 1400.0, b, &mut pts);
        assert_eq!((pts[2].k, pts[3].k), (2800.0, 5600.0));
        assert!((5000.0..=5000.0 * 1.011).contains(&hi.unwrap()));
        assert!(pts.len() <= 4 + 7, "{}", pts.len());
    }

    #[test]
    fn interval_bisects_each_edge_from_its_nearest_points() {
        // Given points close around both edges, the refinement starts from
        // them: the lower edge between 1012 (decided passive) and 1014
        // (undecided), the upper between 1233 (undecided) and 1240
        // (refuted): ⌈log2(7/1.24)⌉ = 3 trials for the upper edge, and one
        // for the lower (a gap of 2 against 0.001·1014). Starting from the
        // far bound instead (lo, or 0) would take 8 or more.
        let b = NOISY;
        // And an undecided island far above (3000): noise, not an edge.
        let v = |k: f64| Point {
            decided: Some(ragged(k).decided == Some(true) && k != 3000.0),
            ..ragged(k)
        };
        let mut pts: Vec<Point> = [
            500.0, 1012.0, 1014.0, 1100.0, 1233.0, 1240.0, 2000.0, 3000.0,
        ]
        .iter()
        .map(|&k| v(k))
        .collect();
        let (lo, hi) = interval(v, 1100.0, b, &mut pts);
        assert!((1012.0..1013.0).contains(&lo), "{lo}");
        assert!((1234.0..=1236.0).contains(&hi.unwrap()), "{hi:?}");
        assert_eq!(pts.len() - 8, 1 + 3, "{:?}", &pts[8..]);
    }
}

#[cfg(test)]
mod resolution_tests {
    use super::*;

    #[test]
    fn a_zero_tolerance_ends_at_neighbouring_floats() {
        // rel_tol = 0 (the service refuses anything below 1e-6, cost.rs; the
        // function must still end): the bisection runs until no f64 lies
        // between lo and hi, then stops with lo rendering and hi not, as
        // next-door floats. A run that classified more than 2 000 times
        // would be looping (the 1..2 bracket halves in ≤ 53 steps).
        for t in [1.1, 1.3, 1.37, 1.5 + 1e-9, 1.77, 1.999] {
            let mut calls = 0;
            let mut classify = |k: f64| {
                calls += 1;
                assert!(calls < 2_000, "threshold {t}: still bisecting");
                Point {
                    k,
                    stable: Some(k < t),
                    ..Point::default()
                }
            };
            let mut points = Vec::new();
            let (lo, hi) = bisect_edge(&mut classify, 1.0, 2.0, 0.0, &mut points, Point::ok);
            assert!(lo < t && hi >= t, "threshold {t}: [{lo}, {hi}]");
            assert_eq!(hi, f64::from_bits(lo.to_bits() + 1), "threshold {t}");
        }
    }

    /// Renders below `t` N/m only: a monotone verdict at one B.
    fn below(t: f64) -> impl Fn(f64) -> Point {
        move |k| Point {
            k,
            b: 0.0,
            stable: Some(k < t),
            ..Point::default()
        }
    }

    /// K-values tried, in order.
    fn ks(pts: &[Point]) -> Vec<f64> {
        pts.iter().map(|p| p.k).collect()
    }

    const TOL: Bracket = Bracket {
        k0: 10.0,
        k_cap: 1e7,
        rel_tol: 1e-2,
    };

    #[test]
    fn a_right_prediction_is_confirmed_by_its_two_verdicts() {
        // Boundary 1500; predicted [1490, 1505]: two trials, already
        // narrower than 1 %, so no bisection step.
        let start = Start::Bracket {
            lo: 1490.0,
            hi: 1505.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(start), &mut pts);
        assert_eq!((k, ks(&pts)), (Some(1490.0), vec![1490.0, 1505.0]));
        // From k0 the same bisection takes nine trials to bracket (10, 20,
        // …, 2560) and seven to bisect [1280, 2560] to 1 %.
        let mut cold = Vec::new();
        let k_cold = bisect_k(below(1500.0), TOL, false, None, &mut cold).unwrap();
        assert!((1500.0 * 0.99..1500.0).contains(&k_cold), "{k_cold}");
        assert_eq!(cold.len(), 16);
        // A predicted interval 4 % wide: the two ends, then bisection to
        // 1 % (2 steps: 4 % → 2 % → 1 %).
        let start = Start::Bracket {
            lo: 1450.0,
            hi: 1510.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(start), &mut pts).unwrap();
        assert_eq!(ks(&pts), vec![1450.0, 1510.0, 1480.0, 1495.0]);
        assert_eq!(k, 1495.0);
    }

    #[test]
    fn a_wrong_prediction_gallops_out_until_the_verdicts_bracket_the_boundary() {
        // Predicted [1000, 1010] (w = ln 1.01) for a boundary at 1500: up by
        // w, 2w, 4w, … in ln K from the last K that rendered.
        let start = Start::Bracket {
            lo: 1000.0,
            hi: 1010.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(start), &mut pts).unwrap();
        assert!((1500.0 * 0.99..1500.0).contains(&k), "{k}");
        let w = 1.01f64.ln();
        let mut expect = vec![1000.0, 1010.0];
        let (mut last, mut step) = (1010.0, w);
        while last < 1500.0 {
            step *= 2.0;
            last *= step.exp();
            expect.push(last);
        }
        assert_eq!(ks(&pts)[..expect.len()], expect[..]);
        // 1000 → 1010 → 1030.4 → 1072.4 → 1161.5 → 1362.7 → 1875.7 (fails):
        // seven trials to bracket, then bisection of [1362.7, 1875.7].
        assert_eq!(expect.len(), 7);
        // Predicted too high, [4000, 4040]: down from 4000 the same way.
        let start = Start::Bracket {
            lo: 4000.0,
            hi: 4040.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(start), &mut pts).unwrap();
        assert!((1500.0 * 0.99..1500.0).contains(&k), "{k}");
        let w = (4040.0f64 / 4000.0).ln();
        assert_eq!(pts[1].k, 4000.0 * (-w).exp());
        assert_eq!(pts[2].k, pts[1].k * (-2.0 * w).exp());
        // Off by a factor of ~2.7 either way, it costs about what a search
        // from k0 does (16 trials here), not more.
        assert!(pts.len() <= 17, "{}", pts.len());
    }

    #[test]
    fn a_column_predicted_empty_checks_k0_and_the_floor() {
        // Nothing renders: k0, then k0/1024 directly: None after two.
        let mut pts = Vec::new();
        let never = below(0.0);
        assert_eq!(
            bisect_k(never, TOL, false, Some(Start::Empty), &mut pts),
            None
        );
        assert_eq!(ks(&pts), vec![10.0, 10.0 / 1024.0]);
        // Something renders below k0 after all: bisected between the floor
        // and k0.
        let mut pts = Vec::new();
        let k = bisect_k(below(3.0), TOL, false, Some(Start::Empty), &mut pts).unwrap();
        assert!((3.0 * 0.99..3.0).contains(&k), "{k}");
        // And above k0: up from it by doubling, then faster.
        let mut pts = Vec::new();
        let k = bisect_k(below(50.0), TOL, false, Some(Start::Empty), &mut pts).unwrap();
        assert!((50.0 * 0.99..50.0).contains(&k), "{k}");
        assert_eq!(ks(&pts)[..3], [10.0, 20.0, 80.0]);
    }

    #[test]
    fn a_prediction_is_held_to_the_cap_and_the_floor() {
        // Everything renders, predicted above the cap: the cap is the result.
        let capped = Bracket {
            k_cap: 3000.0,
            ..TOL
        };
        let start = Start::Bracket {
            lo: 5000.0,
            hi: 6000.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(f64::INFINITY), capped, false, Some(start), &mut pts);
        assert_eq!((k, ks(&pts)), (Some(3000.0), vec![3000.0]));
        // Nothing renders, predicted at 100: galloping down ends at the
        // floor k0/1024 (tried once), None.
        let start = Start::Bracket {
            lo: 100.0,
            hi: 101.0,
        };
        let mut pts = Vec::new();
        assert_eq!(
            bisect_k(below(0.0), TOL, false, Some(start), &mut pts),
            None
        );
        assert_eq!(*ks(&pts).last().unwrap(), 10.0 / 1024.0);
        assert!(pts.iter().all(|p| p.k >= 10.0 / 1024.0));
    }

    #[test]
    fn a_predicted_start_finds_a_lower_end_for_the_interval() {
        // Decided verdicts from a bracket near the boundary, where nothing
        // below the first failure is decided passive: halving from the
        // lowest K tried until a K is.
        let three = |k: f64| Point {
            k,
            b: 0.0,
            stable: Some(k < 1500.0),
            decided: Some(!(1000.0..2000.0).contains(&k)),
            ..Point::default()
        };
        let mut pts: Vec<Point> = [1450.0, 1510.0].map(three).to_vec();
        anchor_below(three, TOL, &mut pts);
        // 1450 → 725 (decided passive).
        assert_eq!(ks(&pts), vec![1450.0, 1510.0, 725.0]);
        // Already one below the first failure: nothing more.
        anchor_below(three, TOL, &mut pts);
        assert_eq!(pts.len(), 3);
        // Never below the floor: a column where nothing is decided passive.
        let undecided = |k: f64| Point {
            decided: Some(false),
            ..three(k)
        };
        let mut pts = vec![undecided(40.0)];
        anchor_below(undecided, TOL, &mut pts);
        assert!(pts.iter().all(|p| p.k >= 10.0 / 1024.0));
        assert_eq!(pts.len(), 1 + 12);
    }

    #[test]
    fn a_prediction_never_tries_past_the_cap_nor_reports_past_it() {
        // Predicted empty where everything renders and the cap (15) is
        // below twice the first step (10): 10, then the cap itself.
        let capped = Bracket { k_cap: 15.0, ..TOL };
        let mut pts = Vec::new();
        let k = bisect_k(
            below(f64::INFINITY),
            capped,
            false,
            Some(Start::Empty),
            &mut pts,
        );
        assert_eq!((k, ks(&pts)), (Some(15.0), vec![10.0, 15.0]));
        // Renders below 12: bisected between 10 and the cap, never above it.
        let mut pts = Vec::new();
        let k = bisect_k(below(12.0), capped, false, Some(Start::Empty), &mut pts).unwrap();
        assert!((12.0 * 0.99..12.0).contains(&k), "{k}");
        assert!(pts.iter().all(|p| p.k <= 15.0), "{:?}", ks(&pts));
        // A predicted bracket wider than a factor of 2 is searched from its
        // lower half: [1000, 1e7] tries 1000, then 2000.
        let wide = Start::Bracket {
            lo: 1000.0,
            hi: 1e7,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(wide), &mut pts).unwrap();
        assert_eq!(ks(&pts)[..2], [1000.0, 2000.0]);
        assert!((1500.0 * 0.99..1500.0).contains(&k), "{k}");
        // Nothing tried at all: no lower end to look for, and no loop.
        let mut none = Vec::new();
        anchor_below(below(1.0), TOL, &mut none);
        assert!(none.is_empty());
    }

    #[test]
    fn robust_bisection_from_a_prediction_finds_the_first_failure_from_below() {
        // Renders below 100 N/m and again on [2000, 4000): predicted at
        // [3900, 3950], the bracket finds the upper edge (~3975); its check
        // at 0.3 of it (~1193) fails with nothing tried below, so the search
        // halves down from there for a pass (1193/16 ≈ 74.5) and bisects to
        // the first failure from below, as a robust search from k0 does.
        let two_bands = |k: f64| Point {
            k,
            b: 0.0,
            stable: Some(k < 100.0 || (2000.0..4000.0).contains(&k)),
            ..Point::default()
        };
        let start = Start::Bracket {
            lo: 3900.0,
            hi: 3950.0,
        };
        let mut pts = Vec::new();
        let seeded = bisect_k(two_bands, TOL, true, Some(start), &mut pts).unwrap();
        let mut cold = Vec::new();
        let from_k0 = bisect_k(two_bands, TOL, true, None, &mut cold).unwrap();
        assert!((99.0..100.0).contains(&seeded), "{seeded}");
        assert!((99.0..100.0).contains(&from_k0), "{from_k0}");
        let halved = pts[5].k / 16.0;
        assert!(
            pts.iter().any(|p| p.k == halved && p.ok()),
            "{:?}",
            ks(&pts)
        );
        // Nothing renders below the upper band: robust says so (None), as
        // from k0.
        let upper = |k: f64| Point {
            stable: Some((2000.0..4000.0).contains(&k)),
            ..two_bands(k)
        };
        let mut pts = Vec::new();
        assert_eq!(bisect_k(upper, TOL, true, Some(start), &mut pts), None);
        assert_eq!(bisect_k(upper, TOL, true, None, &mut Vec::new()), None);
    }

    #[test]
    fn robust_bisection_halves_down_only_when_nothing_below_was_tried() {
        // From a prediction, a check that fails above a pass already tried
        // bisects from that pass (no halving): renders below 1000 and on
        // [1300, 4000) but not on [1000, 1300); predicted at [3900, 3950]
        // the checks at 0.3 (~1193, fails) finds no pass below at first…
        let gap = |k: f64| Point {
            k,
            b: 0.0,
            stable: Some(k < 1000.0 || (1300.0..4000.0).contains(&k)),
            ..Point::default()
        };
        let start = Start::Bracket {
            lo: 3900.0,
            hi: 3950.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(gap, TOL, true, Some(start), &mut pts).unwrap();
        assert!((990.0..1000.0).contains(&k), "{k}");
        // … and halves once, to ~596 (renders), then bisects [596, 1193].
        let halved: Vec<f64> = ks(&pts).into_iter().filter(|&x| x < 990.0 * 0.3).collect();
        assert!(
            halved.is_empty(),
            "no halving below the first pass: {halved:?}"
        );
        // Where a check fails above a pass already tried (its own check at
        // 0.3), the bisection starts from that pass, without halving:
        // renders below 1000 and on [1400, 3000); predicted [1500, 1510],
        // the bracket finds 3000, the check at 0.3 (~900) renders, the one
        // at 0.45 (~1350) fails: bisected from ~900, never from its half.
        let two = |k: f64| Point {
            stable: Some(k < 1000.0 || (1400.0..3000.0).contains(&k)),
            ..gap(k)
        };
        let start_low = Start::Bracket {
            lo: 1500.0,
            hi: 1510.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(two, TOL, true, Some(start_low), &mut pts).unwrap();
        assert!((990.0..1000.0).contains(&k), "{k}");
        let failed_check = pts
            .iter()
            .find(|p| !p.ok() && p.k < 1400.0)
            .map(|p| p.k)
            .unwrap();
        assert!(
            !pts.iter().any(|p| p.k == failed_check / 2.0),
            "no halving from {failed_check}: {:?}",
            ks(&pts)
        );
        // A pass below k0 itself: renders below 5 N/m only and on [2000,
        // 4000); k0 = 10. Halving goes below k0 (to its floor k0/1024) and
        // finds the first failure from below, 5, as from k0.
        let low = |k: f64| Point {
            stable: Some(k < 5.0 || (2000.0..4000.0).contains(&k)),
            ..gap(k)
        };
        let mut pts = Vec::new();
        let seeded = bisect_k(low, TOL, true, Some(start), &mut pts).unwrap();
        let from_k0 = bisect_k(low, TOL, true, None, &mut Vec::new()).unwrap();
        assert!((4.95..5.0).contains(&seeded), "{seeded}");
        assert!((4.95..5.0).contains(&from_k0), "{from_k0}");
        // Halving never tries below the floor.
        let upper = |k: f64| Point {
            stable: Some((2000.0..4000.0).contains(&k)),
            ..gap(k)
        };
        let mut pts = Vec::new();
        assert_eq!(bisect_k(upper, TOL, true, Some(start), &mut pts), None);
        assert!(pts.iter().all(|p| p.k >= 10.0 / 1024.0), "{:?}", ks(&pts));
    }

    #[test]
    fn robust_bisection_from_k0_bisects_from_k0_itself() {
        // Renders on [0, 12) and [15, 45): from k0 = 10 the bracket finds 45;
        // its check at 0.3 (13.5) fails, and the highest pass below it is k0
        // itself, so the first failure from below is 12 (not "no boundary").
        let v = |k: f64| Point {
            k,
            b: 0.0,
            stable: Some(k < 12.0 || (15.0..45.0).contains(&k)),
            ..Point::default()
        };
        let mut pts = Vec::new();
        let k = bisect_k(v, TOL, true, None, &mut pts).unwrap();
        assert!((12.0 * 0.99..12.0).contains(&k), "{k}");
        // The same from a column predicted empty (k0 first, then up): the
        // pass at k0 is the bisection's lower end, no halving below it.
        let mut pts = Vec::new();
        let k = bisect_k(v, TOL, true, Some(Start::Empty), &mut pts).unwrap();
        assert!((12.0 * 0.99..12.0).contains(&k), "{k}");
        let failed = pts.iter().find(|p| !p.ok() && p.k < 15.0).unwrap().k;
        assert!(!pts.iter().any(|p| p.k == failed / 2.0), "{:?}", ks(&pts));
    }

    #[test]
    fn a_prediction_of_no_width_is_widened_by_the_resolution() {
        // lo = hi = 1000 for a boundary at 1500: 1000, then 1000·1.01, and
        // the gallop from there.
        let start = Start::Bracket {
            lo: 1000.0,
            hi: 1000.0,
        };
        let mut pts = Vec::new();
        let k = bisect_k(below(1500.0), TOL, false, Some(start), &mut pts).unwrap();
        assert_eq!(ks(&pts)[..2], [1000.0, 1000.0 * 1.01f64.ln().exp()]);
        assert!((1500.0 * 0.99..1500.0).contains(&k), "{k}");
    }
}
