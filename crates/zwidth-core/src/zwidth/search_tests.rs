//! Tests of `search.rs` (the searches, the automatic B range, the map result).

use super::*;
use crate::zwidth::hit::NoTrace;
use crate::zwidth::scene::SceneSpec;

fn bp(b: f64, k_max: f64) -> BoundaryPoint {
    BoundaryPoint::new(b, k_max)
}

fn iv(b: f64, k_max: f64, lo: f64, hi: f64) -> BoundaryPoint {
    BoundaryPoint {
        k_lo: Some(lo),
        k_hi: Some(hi),
        ..BoundaryPoint::new(b, k_max)
    }
}

/// Which verdict a frequency-domain model says it gives: the BLA's
/// with a confidence on a scene with friction or quantization, the
/// 2018 paper's tfestimate when asked for, neither on a linear scene
/// (whatever the probe method), and replicated hits in the time domain.
#[test]
fn the_model_description_names_its_verdict() {
    let describe = |json: &str, method: Method, criterion: Criterion| {
        let scene = SceneSpec::from_json(json).unwrap().validate().unwrap();
        let res = crate::zwidth::settings::Accuracy::default()
            .resolve(&scene)
            .unwrap();
        let ev = Evaluator::new(scene, method, criterion, res).unwrap();
        (ev.model_description(), ev.noisy())
    };
    let imp = |json: &str| describe(json, Method::Frequency, Criterion::Impedance);
    let friction = r#"{"device":{"coulomb":0.1,"quantization":0}}"#;
    let quantized = r#"{"device":{"coulomb":0,"quantization":1e-6}}"#;
    let linear = r#"{"device":{"coulomb":0,"quantization":0}}"#;
    for nonlinear in [friction, quantized] {
        let (d, noisy) = imp(nonlinear);
        assert!(noisy && d.contains("best linear approximation"), "{d}");
        let tf = nonlinear.replace("}}", r#"},"probe":{"method":"tfestimate"}}"#);
        let (d, noisy) = imp(&tf);
        assert!(!noisy && d.contains("tfestimate verdict"), "{d}");
    }
    for probe in ["bla", "tfestimate"] {
        let lin = linear.replace("}}", &format!(r#"}},"probe":{{"method":"{probe}"}}}}"#));
        let (d, noisy) = imp(&lin);
        assert!(!noisy, "{d}");
        assert!(
            d.contains("frequency-domain multisine simulation (bilateral wall)"),
            "{d}"
        );
        assert!(
            !d.contains("tfestimate") && !d.contains("best linear"),
            "{d}"
        );
    }
    let (d, noisy) = describe(
        r#"{"hit":{"replicates":3}}"#,
        Method::Time,
        Criterion::Stability,
    );
    assert!(noisy && d.contains("3 replicate hits"), "{d}");
    let (d, noisy) = describe(friction, Method::Time, Criterion::Stability);
    assert!(!noisy && !d.contains("replicate"), "{d}");
}

#[test]
fn b_width_upper_end_counts_columns_not_surely_empty() {
    // k_floor = 100 N/m (the smallest K searched). B = 20: nothing
    // rendered, but the verdicts up to 400 N/m were undecided, so the
    // column may render: B-width is at most 20, at least 10 (its
    // largest column with a K decided passive). B = 30 is surely empty
    // (decided not passive at the floor), so it bounds nothing.
    let boundary = [
        iv(0.0, 900.0, 850.0, 950.0),
        iv(10.0, 500.0, 450.0, 520.0),
        iv(20.0, 0.0, 0.0, 400.0),
        iv(30.0, 0.0, 0.0, 100.0),
    ];
    let (k, b) = widths_interval(&boundary, 100.0);
    assert_eq!(k, Some([850.0, 950.0]));
    assert_eq!(b, Some([10.0, 20.0]));
    assert!(!boundary[2].surely_empty(100.0));
    assert!(boundary[3].surely_empty(100.0));
    // A column without intervals (a deterministic verdict) is empty
    // exactly when nothing rendered.
    assert!(bp(40.0, 0.0).surely_empty(100.0));
    assert!(!bp(40.0, 1.0).surely_empty(100.0));
    // Any column without an interval: no intervals at all.
    assert_eq!(
        widths_interval(&[boundary[0], bp(10.0, 5.0)], 100.0),
        (None, None)
    );
    assert_eq!(widths_interval(&[], 100.0), (None, None));
}

#[test]
fn planned_b_extrapolates_the_boundary_to_zero() {
    // K falls 100 N/m per 10 N·s/m from 900 at B = 10: K = 0 at
    // B = 10 + 900·10/100 = 100, i.e. 10 steps of 10, plus the three
    // B values that end an automatic search.
    let b = [bp(0.0, 1000.0), bp(10.0, 900.0)];
    assert_eq!(planned_b(&b, 68, 10.0), 13);
    // Rising or flat boundaries give no estimate: the whole range.
    assert_eq!(planned_b(&[bp(0.0, 900.0), bp(10.0, 1000.0)], 68, 10.0), 68);
    // A steep fall: K = 0 at B = 10 + 10·10/990 = 10.1, ceil(1.01) = 2
    // steps, plus three; never more than the range.
    assert_eq!(planned_b(&[bp(0.0, 1000.0), bp(10.0, 10.0)], 68, 10.0), 5);
    assert_eq!(planned_b(&[bp(0.0, 1000.0), bp(10.0, 999.0)], 68, 10.0), 68);
    // From the last two points, not from B = 0: 1000 at B = 10, 900 at
    // 20 reach 0 at B = 20 + 900·10/100 = 110: 11 steps, plus three.
    assert_eq!(
        planned_b(&[bp(10.0, 1000.0), bp(20.0, 900.0)], 68, 10.0),
        14
    );
}

/// The 2018 device without friction and quantization (analytic: each
/// trial well under a millisecond), with a B step that makes the
/// automatic range end after a handful of columns.
pub(super) fn auto_b_map(search: SearchKind) -> MapSpec {
    MapSpec {
        scene: SceneSpec::from_json(
            r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap(),
        method: Method::Analytic,
        criterion: Criterion::Impedance,
        search,
        accuracy: serde_json::from_str(r#"{"preset":"draft","b_step":100}"#).unwrap(),
        b: None,
        b_max: 5000.0,
        k_max: 1e6,
        prior: None,
    }
}

#[test]
fn an_automatic_b_range_ends_at_its_first_empty_pair_on_any_thread_count() {
    let spec = auto_b_map(SearchKind::Bisect);
    // Independently, column by column (one B per map): the first two
    // B values in a row where nothing renders end the range.
    let empty = |b: f64| {
        let one = MapSpec {
            b: Some(vec![b]),
            ..spec.clone()
        };
        map_observed(&one, None, 0).unwrap().k_width == 0.0
    };
    let step = 100.0;
    let mut end = 1;
    while !(empty(step * (end - 1) as f64) && empty(step * end as f64)) {
        end += 1;
        assert!(
            step * end as f64 <= spec.b_max,
            "the range ends before b_max"
        );
    }
    let n_columns = end + 1;
    // Not a multiple of any batch size tried below but 1 (13 here):
    // batches of 2, 3 and 5 all run past the end.
    assert!(
        [2, 3, 5].iter().all(|n| n_columns % n != 0),
        "{n_columns} columns"
    );
    let mut first: Option<(MapResult, Vec<StoredTrial>)> = None;
    for threads in [1, 2, 3, 5] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let o = std::sync::Arc::new(Observer::default());
        let r = pool
            .install(|| map_observed(&spec, Some(o.clone()), 4))
            .unwrap();
        // What a store would hold: every trial recorded, less the
        // dropped columns, in (column, index) order.
        // Always from the column after the end (B = 100 · n_columns),
        // whether or not this run's batches reached it: an earlier
        // attempt may have.
        let dropped = o.take_dropped();
        assert_eq!(dropped, [(4, step * n_columns as f64)], "{threads} threads");
        let mut stored: Vec<StoredTrial> = o
            .take_new()
            .into_iter()
            .filter(|t| dropped.iter().all(|&(s, b)| t.scope != s || t.point.b < b))
            .collect();
        stored.sort_by_key(|t| (t.column, t.index));
        assert!(stored.iter().all(|t| t.scope == 4));
        assert_eq!(
            stored.last().unwrap().column as usize,
            n_columns - 1,
            "{threads} threads"
        );
        // The points are the stored trials, in the same order; the
        // boundary keeps one empty column at the end.
        let points: Vec<Point> = stored.iter().map(|t| t.point.clone()).collect();
        assert_eq!(r.points, points, "{threads} threads");
        assert_eq!(r.boundary.len(), n_columns - 1);
        match &first {
            None => first = Some((r, stored)),
            Some((r0, s0)) => {
                assert_eq!(&stored, s0, "{threads} threads");
                assert_eq!(r.boundary, r0.boundary);
                assert_eq!(r.k_width.to_bits(), r0.k_width.to_bits());
            }
        }
    }
}

#[test]
fn a_cancelled_automatic_map_drops_no_column() {
    // Cancelled, every trial answers "not passive": the first two
    // columns look empty, but they say nothing about the map's end, so
    // no stored trial may be dropped for them.
    let o = std::sync::Arc::new(Observer::default());
    o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    map_observed(&auto_b_map(SearchKind::Bisect), Some(o.clone()), 0).unwrap();
    assert!(o.take_dropped().is_empty());
}

#[test]
fn a_b_list_with_a_value_twice_is_refused() {
    let spec = MapSpec {
        b: Some(vec![0.0, 10.0, 0.0]),
        ..auto_b_map(SearchKind::Bisect)
    };
    let e = map_observed(&spec, None, 0).unwrap_err();
    assert_eq!(e.field, "b");
    assert!(e.to_string().contains("twice"), "{e}");
}

#[test]
fn area_is_the_trapezoid_sum_over_sorted_b() {
    // (0, 1000), (10, 600), (20, 0) in any order: ½·10·(1000 + 600)
    // + ½·10·(600 + 0) = 8 000 + 3 000 N/m·N·s/m.
    let b = [bp(10.0, 600.0), bp(0.0, 1000.0), bp(20.0, 0.0)];
    assert_eq!(area(&b), 11_000.0);
    assert_eq!(area(&b[..1]), 0.0);
    assert_eq!(area(&[]), 0.0);
}

#[test]
fn grid_progress_is_the_share_of_points_done() {
    // A grid of 3 B × 10 K = 30 points reports every 16th point: once,
    // at 16/30. Cancelled before it starts, every point ends at once
    // (not rendered) and the map does not claim to be done.
    let scene: SceneSpec = SceneSpec::from_json(
        r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
    )
    .unwrap();
    let spec = MapSpec {
        scene,
        method: Method::Analytic,
        criterion: Criterion::Impedance,
        search: SearchKind::Grid,
        accuracy: serde_json::from_str(r#"{"k_step":1000}"#).unwrap(),
        b: Some(vec![0.0, 10.0, 20.0]),
        b_max: 1000.0,
        k_max: 10_000.0,
        prior: None,
    };
    let o = std::sync::Arc::new(Observer::default());
    o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    let r = map_observed(&spec, Some(o.clone()), 0).unwrap();
    assert_eq!(r.points.len(), 30);
    assert!(
        (o.fraction() - 16.0 / 30.0).abs() < 1e-12,
        "{}",
        o.fraction()
    );
    // Not cancelled: done is done.
    let o = std::sync::Arc::new(Observer::default());
    map_observed(&spec, Some(o.clone()), 0).unwrap();
    assert_eq!(o.fraction(), 1.0);
    // A bisection over a list reports each finished column: one column,
    // finished at once when cancelled, is 1 of 1.
    let one = MapSpec {
        search: SearchKind::Bisect,
        b: Some(vec![0.0]),
        ..spec
    };
    let o = std::sync::Arc::new(Observer::default());
    o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    map_observed(&one, Some(o.clone()), 0).unwrap();
    assert_eq!(o.fraction(), 1.0);
}

#[test]
fn saturation_counts_boundary_points_decided_by_a_clipped_trial() {
    // B = 0: K_max = 100, its first failure above is K = 200, clipped.
    // B = 10: K_max = 100, its first failure above is K = 150, not
    // clipped (a clipped one at 300 comes later). So 1 of 2 boundary
    // points, 2 of 6 trials clipped, the first at K = 200.
    let pt = |b: f64, k: f64, ok: bool, sat: bool| Point {
        k,
        b,
        passive: Some(ok),
        saturated: sat.then_some(true),
        ..Point::default()
    };
    let points = [
        pt(0.0, 50.0, true, false),
        pt(0.0, 200.0, false, true),
        pt(0.0, 400.0, false, false),
        pt(10.0, 300.0, false, true),
        pt(10.0, 150.0, false, false),
        pt(10.0, 60.0, true, false),
    ];
    let boundary = [bp(0.0, 100.0), bp(10.0, 100.0)];
    let note = saturation_note(&points, &boundary, 0.5).unwrap();
    assert!(
        note.starts_with("the force limit ±0.5 N clipped the wall force in 2 of 6 trials (from K = 2.0000e2 N/m); 1 of 2 boundary points"),
        "{note}"
    );
    // Nothing clipped: no note.
    assert_eq!(saturation_note(&points[4..], &boundary, 0.5), None);
}

#[test]
fn verdicts_are_noisy_with_friction_or_quantization_in_the_frequency_engine() {
    let spec = |device: &str, method: Method| MapSpec {
        criterion: if method == Method::Time {
            Criterion::Stability
        } else {
            Criterion::Impedance
        },
        scene: SceneSpec::from_json(&format!(
            r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}}}}"#
        ))
        .unwrap(),
        method,
        search: SearchKind::Bisect,
        accuracy: Default::default(),
        b: Some(vec![0.0]),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    };
    let f = Method::Frequency;
    assert!(noisy(&spec(r#"{"coulomb":0,"quantization":1e-6}"#, f)).unwrap());
    assert!(noisy(&spec(r#"{"coulomb":0.19,"quantization":0}"#, f)).unwrap());
    assert!(!noisy(&spec(r#"{"coulomb":0,"quantization":0}"#, f)).unwrap());
    // The time engine's verdict is a threshold on one run: no intervals,
    // unless the scene asks for replicate hits.
    let t = Method::Time;
    assert!(!noisy(&spec(r#"{"coulomb":0.19,"quantization":1e-6}"#, t)).unwrap());
    let mut replicated = spec(r#"{"coulomb":0.19,"quantization":1e-6}"#, t);
    replicated.scene.hit.replicates = 2;
    assert!(noisy(&replicated).unwrap());
}

#[test]
fn replicate_hits_give_majority_verdicts_and_intervals() {
    // The seed device at 1 kHz with three hits per verdict, short hits:
    // every point took three hits, is decided exactly when the three
    // hits' verdicts (`replicate_hit`, run here again) agree, stable by
    // majority, and the boundary carries an interval around K_max.
    let mut scene = SceneSpec::from_json(
        r#"{"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"home_distance":0.001,"settle_s":0.3,"measure_s":0.2,"replicates":3}}"#,
    )
    .unwrap();
    let spec = MapSpec {
        criterion: Criterion::Stability,
        scene: scene.clone(),
        method: Method::Time,
        search: SearchKind::Bisect,
        accuracy: Default::default(),
        b: Some(vec![20.0]),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    };
    let r = map(&spec).unwrap();
    assert!(
        r.model.contains("3 replicate hits per verdict"),
        "{}",
        r.model
    );
    let sc = scene.validate().unwrap();
    let knobs = spec.accuracy.resolve(&sc).unwrap().hit;
    for p in r.points.iter().take(6) {
        let stable: Vec<bool> = (0..3)
            .map(|i| super::super::hit::replicate_hit(&sc, p.k, p.b, knobs, i, &mut NoTrace).stable)
            .collect();
        let n = stable.iter().filter(|s| **s).count();
        assert_eq!(p.realizations, Some(3), "{p:?}");
        assert_eq!(p.stable, Some(n >= 2), "{p:?} {stable:?}");
        assert_eq!(p.decided, Some(n == 0 || n == 3), "{p:?} {stable:?}");
    }
    let bp = r.boundary[0];
    let (lo, hi) = (bp.k_lo.unwrap(), bp.k_hi.unwrap());
    assert!(lo <= bp.k_max && bp.k_max <= hi && bp.k_max > 0.0, "{bp:?}");
    // One hit per verdict: the same map has no intervals and none of
    // the replicate fields.
    scene.hit.replicates = 1;
    let one = map(&MapSpec { scene, ..spec }).unwrap();
    assert!(
        one.boundary[0].k_lo.is_none()
            && one
                .points
                .iter()
                .all(|p| p.decided.is_none() && p.realizations.is_none())
    );
}

#[test]
fn observer_fraction_averages_the_maps() {
    let o = Observer::default();
    o.set_scopes(4);
    o.report(0, 1.0);
    o.report(1, 0.5);
    assert!((o.fraction() - 0.375).abs() < 1e-12);
    o.report(2, f64::NAN); // ignored, never NaN out
    assert!((o.fraction() - 0.375).abs() < 1e-12);
    // Out of order (parallel columns), or a plan that grew: no rewind.
    o.report(1, 0.25);
    assert!((o.fraction() - 0.375).abs() < 1e-12);
    o.report(1, 0.75);
    assert!((o.fraction() - 0.4375).abs() < 1e-12);
}

/// A single-rate 1 kHz scene with the given device, FDM, on the
/// analytic engine.
fn analytic(device: &str, criterion: Criterion, search: SearchKind, accuracy: &str) -> MapSpec {
    MapSpec {
        scene: SceneSpec::from_json(&format!(
            r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}}}}"#
        ))
        .unwrap(),
        method: Method::Analytic,
        criterion,
        search,
        accuracy: serde_json::from_str(accuracy).unwrap(),
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    }
}

const UNDAMPED: &str = r#"{"damping":0,"coulomb":0,"quantization":0}"#;

/// Jury's criterion for an undamped mass under FDM at T = 1 ms (no
/// delay): z³ + (x + y − 2)z² + (1 + x)z − y with x = KT²/2m, y = BT/2m
/// is stable iff 0 < K < (4m/T²)·y(1 − y)/(1 + y), 0 < B < 2m/T.
fn jury_undamped(b: f64) -> f64 {
    let (m, t) = (0.52, 1e-3);
    let y = b * t / (2.0 * m);
    (4.0 * m / (t * t) * y * (1.0 - y) / (1.0 + y)).max(0.0)
}

#[test]
fn an_automatic_b_range_starts_empty_and_ends_at_two_empty_columns() {
    // Undamped: B = 0 renders nothing, 100 … 1000 do (up to 2m/T =
    // 1040), 1100 and beyond nothing. The search ends at the first
    // two empty columns (1100, 1200), whatever ran past it on the other
    // thread (dropped), and keeps one empty column past the last that
    // renders.
    let mut spec = analytic(
        UNDAMPED,
        Criterion::Stability,
        SearchKind::Bisect,
        r#"{"preset":"draft","b_step":100}"#,
    );
    spec.b_max = 2000.0;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let r = pool.install(|| map(&spec)).unwrap();
    let bs: Vec<f64> = r.boundary.iter().map(|p| p.b).collect();
    assert_eq!(
        bs,
        (0..=11).map(|i| f64::from(i) * 100.0).collect::<Vec<_>>()
    );
    for p in &r.boundary {
        let want = jury_undamped(p.b);
        assert!(
            p.k_max <= want && p.k_max >= 0.95 * want,
            "B = {}: {} vs Jury {want}",
            p.b,
            p.k_max
        );
    }
    assert_eq!((r.boundary[0].k_max, r.boundary[11].k_max), (0.0, 0.0));
    assert_eq!(r.b_width, 1000.0);
    assert_eq!(r.points.iter().map(|p| p.b).fold(0.0, f64::max), 1200.0);
    // Two columns, the first empty: both kept.
    spec.b_max = 100.0;
    let r = map(&spec).unwrap();
    let got: Vec<(f64, bool)> = r.boundary.iter().map(|p| (p.b, p.k_max > 0.0)).collect();
    assert_eq!(got, [(0.0, false), (100.0, true)]);
}

#[test]
fn a_trace_climbs_then_falls_one_k_step_at_a_time() {
    // 2011 paper §2.4 on the undamped device, steps of 20 000 N/m:
    // B = 100 climbs 20k … 160k (Jury: 164 912) and fails at 180k (9
    // trials); B = 0 renders nothing: 180k, then 160k … 20k, all fail
    // (9 more), and the boundary there is 0.
    let mut spec = analytic(
        UNDAMPED,
        Criterion::Stability,
        SearchKind::Trace,
        r#"{"preset":"draft","k_step":20000}"#,
    );
    spec.b = Some(vec![100.0, 0.0]);
    let r = map(&spec).unwrap();
    let bd: Vec<(f64, f64)> = r.boundary.iter().map(|p| (p.b, p.k_max)).collect();
    assert_eq!(bd, [(100.0, 160_000.0), (0.0, 0.0)]);
    assert_eq!(r.trials, 18);
    assert!(r.points.iter().all(|p| p.k >= 20_000.0));
}

#[test]
fn strict_passivity_is_exact_per_b_and_stops_where_nothing_is_passive() {
    // Colgate & Schenkel for FDM: K < 2(b − |B|)/T with b = 13.2 N·s/m,
    // T = 1 ms: 26 400, 16 400, 6 400 at B = 0, 5, 10; none from 13.2.
    let lin = r#"{"coulomb":0,"quantization":0}"#;
    let mut spec = analytic(
        lin,
        Criterion::StrictPassivity,
        SearchKind::Bisect,
        r#""draft""#,
    );
    spec.b = Some(vec![0.0, 5.0, 10.0, 15.0, 20.0]);
    let r = map(&spec).unwrap();
    let want = [26_400.0, 16_400.0, 6_400.0, 0.0, 0.0];
    assert_eq!(r.boundary.len(), 5);
    for (p, w) in r.boundary.iter().zip(want) {
        assert!(
            (p.k_max - w).abs() <= 1e-3 * w,
            "B = {}: {} vs {w}",
            p.b,
            p.k_max
        );
    }
    assert_eq!((r.b_width, r.trials), (10.0, 3));
    assert!(r.resolution.starts_with("exact per B"), "{}", r.resolution);
    // Trapezoids: ½·5·(26 400 + 16 400) + ½·5·(16 400 + 6 400) + ½·5·6 400.
    assert!((r.area - 180_000.0).abs() < 1e-3 * 180_000.0, "{}", r.area);
    // The automatic range: B = 0, 5, 10 to b_max = 10 inclusive …
    spec.b = None;
    spec.accuracy = serde_json::from_str(r#"{"b_step":5}"#).unwrap();
    spec.b_max = 10.0;
    let bs: Vec<f64> = map(&spec).unwrap().boundary.iter().map(|p| p.b).collect();
    assert_eq!(bs, [0.0, 5.0, 10.0]);
    // … and to b_max = 100 it ends at the first B with nothing passive.
    spec.b_max = 100.0;
    let bs: Vec<f64> = map(&spec).unwrap().boundary.iter().map(|p| p.b).collect();
    assert_eq!(bs, [0.0, 5.0, 10.0]);
    // The evaluator's verdict on either side of 26 400 at B = 0.
    let sc = spec.scene.validate().unwrap();
    let res = spec.accuracy.resolve(&sc).unwrap();
    let ev = Evaluator::new(
        sc.clone(),
        Method::Analytic,
        Criterion::StrictPassivity,
        res,
    )
    .unwrap();
    assert_eq!(ev.evaluate_point(30_000.0, 0.0).passive, Some(false));
    assert_eq!(ev.evaluate_point(20_000.0, 0.0).passive, Some(true));
    // A linear scene on `auto` is answered by the analytic engine.
    let ev = Evaluator::new(sc.clone(), Method::Auto, Criterion::Stability, res).unwrap();
    assert_eq!(ev.method, Method::Analytic);
    // Colgate & Schenkel's condition assumes the force is applied as
    // commanded: with an amplifier lag it is refused, naming why.
    let mut lag = sc.spec.clone();
    lag.device.amplifier_hz = Some(100.0);
    let e = Evaluator::new(
        lag.validate().unwrap(),
        Method::Auto,
        Criterion::StrictPassivity,
        res,
    )
    .err()
    .unwrap();
    assert_eq!(e.field, "criterion");
    assert!(e.to_string().contains("device.amplifier_hz"), "{e}");
}

#[test]
fn a_bisection_states_its_tolerance_and_robust_checks_below_the_result() {
    // FDM, B = 0, k_max 20 000 (below Jury's 26 512 for b = 13.2): a
    // bisection doubles 2976.48, 5952.96, 11 905.92 and then tries the
    // cap, 20 000 (4 trials); the robust one then checks 0.3 … 0.9 of
    // 20 000 (5 more), all stable.
    let lin = r#"{"coulomb":0,"quantization":0}"#;
    let mut spec = analytic(lin, Criterion::Stability, SearchKind::Bisect, r#""draft""#);
    spec.b = Some(vec![0.0]);
    spec.k_max = 20_000.0;
    let r = map(&spec).unwrap();
    assert_eq!((r.trials, r.k_width), (4, 20_000.0));
    assert_eq!(r.resolution, "K to 5.00 % (bisection)");
    spec.search = SearchKind::RobustBisect;
    let r = map(&spec).unwrap();
    assert_eq!((r.trials, r.k_width), (9, 20_000.0));
    assert!(
        r.resolution.starts_with("K to 5.00 % (bisection, checked"),
        "{}",
        r.resolution
    );
}

#[test]
fn maps_refuse_ranges_outside_the_documented_limits() {
    let lin = r#"{"coulomb":0,"quantization":0}"#;
    let field = |spec: &MapSpec| validate(spec).unwrap_err().field;
    let mut spec = analytic(
        lin,
        Criterion::Stability,
        SearchKind::Bisect,
        r#"{"k_step":1000}"#,
    );
    spec.b = Some(vec![0.0]);
    spec.b_max = 0.0;
    assert_eq!(field(&spec), "b_max");
    spec.b_max = 1e6;
    assert!(validate(&spec).is_ok());
    spec.b_max = f64::INFINITY;
    assert_eq!(field(&spec), "b_max");
    spec.b_max = 1000.0;
    spec.k_max = 0.0;
    assert_eq!(field(&spec), "k_max");
    spec.k_max = 1e9;
    assert!(validate(&spec).is_ok());
    spec.k_max = f64::INFINITY;
    assert_eq!(field(&spec), "k_max");
    // A trace needs k_max of at least one K step (here 1000 N/m).
    spec.search = SearchKind::Trace;
    spec.k_max = 1000.0;
    assert!(validate(&spec).is_ok());
    spec.k_max = 999.0;
    assert_eq!(field(&spec), "k_max");
    spec.k_max = 1e4;
    spec.b = Some(vec![]);
    assert_eq!(field(&spec), "b");
}

#[test]
fn planned_b_ignores_empty_columns_and_never_plans_fewer_than_done() {
    // The extrapolation (B where the last two rendering columns' line
    // reaches K = 0, in steps, plus three) kept within [done + 1,
    // max(n_auto, done + 1)].
    let b = [bp(0.0, 1000.0), bp(10.0, 900.0), bp(20.0, 0.0)];
    assert_eq!(planned_b(&b, 68, 10.0), 13);
    // Flat, or two points at one B: no slope, the whole range.
    assert_eq!(planned_b(&[bp(0.0, 900.0), bp(10.0, 900.0)], 68, 10.0), 68);
    assert_eq!(
        planned_b(&[bp(10.0, 1000.0), bp(10.0, 900.0)], 68, 10.0),
        68
    );
    // 1000 → 10 from B = 0 to 10 ends at B = 10.1: 2 steps + 3 = 5, but
    // six columns are done already: 7.
    let done = [
        bp(0.0, 1000.0),
        bp(10.0, 10.0),
        bp(20.0, 0.0),
        bp(30.0, 0.0),
        bp(40.0, 0.0),
        bp(50.0, 0.0),
    ];
    assert_eq!(planned_b(&done, 68, 10.0), 7);
    assert_eq!(planned_b(&done, 3, 10.0), 7);
    assert_eq!(planned_b(&[bp(0.0, 900.0), bp(10.0, 1000.0)], 1, 10.0), 3);
}

#[test]
fn widths_have_intervals_only_when_every_point_has_both_ends() {
    let half = BoundaryPoint {
        k_lo: Some(50.0),
        ..bp(0.0, 100.0)
    };
    assert_eq!(widths_interval(&[half], 10.0), (None, None));
    let other = BoundaryPoint {
        k_hi: Some(150.0),
        ..bp(0.0, 100.0)
    };
    assert_eq!(widths_interval(&[other], 10.0), (None, None));
    assert_eq!(widths_interval(&[], 10.0), (None, None));
}

#[test]
fn saturation_is_judged_at_the_boundary_point_s_own_b_above_its_k() {
    // B = 0, K_max = 100: the first failure above 100 at B = 0 is the
    // clipped 200 (not the unclipped 100 itself, nor 150 at B = 10).
    let pt = |b: f64, k: f64, sat: bool| Point {
        k,
        b,
        passive: Some(false),
        saturated: sat.then_some(true),
        ..Point::default()
    };
    let points = [
        pt(0.0, 200.0, true),
        pt(0.0, 100.0, false),
        pt(10.0, 150.0, false),
    ];
    let note = saturation_note(&points, &[bp(0.0, 100.0)], 0.5).unwrap();
    assert!(
        note.contains("in 1 of 3 trials (from K = 2.0000e2 N/m); 1 of 1 boundary points"),
        "{note}"
    );
}
