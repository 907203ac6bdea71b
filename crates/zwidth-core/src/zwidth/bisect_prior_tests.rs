//! Tests of `bisect.rs` from a predicted start (`bisect_from`,
//! `anchor_below`, the robust checks after it; issue 46), on scripted
//! verdicts (each value worked by hand).

use super::*;

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
