//! Tests of `bisect.rs`: bracketing, bisection, the robust checks and
//! the interval, on scripted verdicts (each value worked by hand).

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
