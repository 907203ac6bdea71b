//! Tests of `compare.rs`.

use super::*;

/// An explicit list takes 1 to MAX_ESTIMATORS (20, the API's limit),
/// each valid on the scene and named by its place when not.
#[test]
fn a_list_takes_one_to_twenty_valid_estimators_named_by_place() {
    let scene = seed_2018_scene();
    let fdm = EstimatorSpec::from_json(r#"{"kind":"fdm"}"#).unwrap();
    assert_eq!(MAX_ESTIMATORS, 20);
    for n in [1, 20] {
        assert_eq!(
            check_estimators(&scene, &vec![fdm.clone(); n]),
            Ok(()),
            "{n}"
        );
    }
    for n in [0, 21] {
        let e = check_estimators(&scene, &vec![fdm.clone(); n]).unwrap_err();
        assert_eq!(
            (e.field.as_str(), e.value.clone()),
            ("estimators", n.to_string())
        );
        assert!(e.allowed.starts_with("give 1 to 20 estimators"), "{e}");
    }
    // The seed device samples at 1 kHz: a 600 Hz cutoff is past Nyquist.
    let bad = EstimatorSpec::from_json(r#"{"kind":"butterworth","cutoff_hz":600}"#).unwrap();
    let e = check_estimators(&scene, &[fdm.clone(), bad]).unwrap_err();
    assert_eq!(e.field, "estimators[1].cutoff_hz", "{e}");
}

#[test]
fn a_stability_comparison_runs_the_time_engine_on_a_nonlinear_scene() {
    // The seed device at 1 kHz with short hits: `auto` answers the
    // stability criterion with the wall hit (the impedance criterion
    // with the multisine probe), every row's map says so, and the
    // table names the criterion the maps used.
    let scene = SceneSpec::from_json(
        r#"{"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"home_distance":0.001,"settle_s":0.2,"measure_s":0.1}}"#,
    )
    .unwrap();
    let fdm: EstimatorSpec = EstimatorKind::Fdm {}.into();
    let r = compare_observed(
        &scene,
        &Accuracy::Preset(crate::zwidth::settings::Preset::Draft),
        Criterion::Stability,
        Some(&[fdm]),
        0,
        None,
    )
    .unwrap();
    let map = &r.rows[0].map;
    // No rounds allowed: no refinement reported.
    assert!(r.resolution.is_none());
    assert_eq!(map.criterion, Criterion::Stability);
    assert!(
        map.model.starts_with("time-domain wall-hit simulation"),
        "{}",
        map.model
    );
    assert!(map.k_width > 0.0);
    assert!(r
        .table()
        .contains("criterion: stability (the wall hit's RMS below its threshold"));
    let spec = map_spec(scene, &Accuracy::default(), Criterion::Impedance);
    assert_eq!(spec.criterion, Criterion::Impedance);
}

#[test]
fn pairs_are_ordered_by_estimate_and_resolved_only_by_disjoint_intervals() {
    let row = |name: &str, k: f64, interval: Option<[f64; 2]>| made_up_row(name, k, interval, None);
    let rows = [
        row("A", 100.0, Some([90.0, 110.0])),
        row("B", 120.0, Some([111.0, 130.0])),
        row("C", 105.0, Some([95.0, 125.0])),
        row("D", 50.0, None),
        row("E", 200.0, Some([110.0, 210.0])),
    ];
    let o = pair_orders(&rows, 0.95, 0.01);
    let got: Vec<(&str, &str, bool)> = o
        .iter()
        .map(|p| (p.wider.as_str(), p.narrower.as_str(), p.resolved))
        .collect();
    // D has no interval; B's [111, 130] lies above A's [90, 110]; C's
    // overlaps both; E's [110, 210] only touches A's upper end.
    assert_eq!(
        got,
        [
            ("B", "A", true),
            ("C", "A", false),
            ("E", "A", false),
            ("B", "C", false),
            ("E", "B", false),
            ("E", "C", false),
        ]
    );
    // Equal estimates: the earlier row is named first.
    let tie = pair_orders(
        &[
            row("P", 1.0, Some([0.5, 2.0])),
            row("Q", 1.0, Some([0.9, 1.1])),
        ],
        0.95,
        0.01,
    );
    assert_eq!(
        (tie[0].wider.as_str(), tie[0].narrower.as_str()),
        ("P", "Q")
    );
    // Each of the two facing bounds wrong with probability ≤ α = 5 %.
    assert!(o.iter().all(|p| (p.error_at_most - 0.10).abs() < 1e-12));
    let t = CompareResult {
        lipschitz: estimate_c(&seed_2018_scene()).unwrap(),
        rows: rows.to_vec(),
        order: o,
        tuned_for: None,
        resolution: None,
        elapsed_s: 0.0,
    }
    .table();
    assert!(t.contains("K-width order (resolved: the intervals do not overlap, wrong with probability at most 10 %)"), "{t}");
    assert!(
        t.contains("  B            > A            resolved\n"),
        "{t}"
    );
    assert!(
        t.contains("  C            > A            not resolved (the intervals overlap)\n"),
        "{t}"
    );
}

#[test]
fn the_paper_cutoff_stays_below_nyquist() {
    assert_eq!(paper_cutoff_hz(1000.0), 499.0);
    assert_eq!(paper_cutoff_hz(10_000.0), 499.0);
    assert_eq!(paper_cutoff_hz(500.0), 249.5);
}

#[test]
fn c_comes_from_the_wall_contact() {
    // docs/zwidth.md records C = 1.098 m/s² for the 2018 device at
    // 1 kHz, from the FDM + Butterworth hit at K = 7 441.2 N/m,
    // B = 29.76 N·s/m (also pinned through the CLI in tests/it/cli.rs).
    // The window starts at first contact: the free flight before it
    // accelerates at only push/m = 0.3572/0.52 = 0.69 m/s².
    let c = estimate_c(&seed_2018_scene()).unwrap();
    assert!((c.estimate.lipschitz / 1.098 - 1.0).abs() < 0.005, "{c:?}");
    assert_eq!((c.wall_k, c.wall_b), (C_WALL_K, C_WALL_B));
    // The window opens 0.1 s (a tenth of its 1 s) before the contact,
    // and the largest |ẍ| is the impact, just after it.
    assert!(
        (0.1..0.15).contains(&c.estimate.at_s),
        "{}",
        c.estimate.at_s
    );
    // The table states where C came from: 5 and 2 of the 2011 paper's
    // steps (1488.24 N/m, 14.88 N·s/m) and the fit's window.
    let t = CompareResult {
        lipschitz: c.clone(),
        rows: Vec::new(),
        order: Vec::new(),
        tuned_for: None,
        resolution: None,
        elapsed_s: 0.0,
    }
    .table();
    let window = 2 * c.estimate.half_window + 1;
    assert!(
        t.contains(&format!(
            "from a wall hit at K = 7441.2 N/m, B = 29.76 N·s/m with butterworth(499 Hz, order 2) (local quadratic fit over {window} samples)"
        )),
        "{t}"
    );
    assert!(t.contains("the 2018 paper's fixed values"), "{t}");
}

/// A row carrying made-up K-widths (on one quick linear map), refined or not.
fn made_up_row(
    name: &str,
    k: f64,
    interval: Option<[f64; 2]>,
    refined: Option<Refined>,
) -> CompareRow {
    let spec = MapSpec {
        b: Some(vec![0.0]),
        ..map_spec(
            SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0}}"#).unwrap(),
            &Accuracy::Preset(crate::zwidth::settings::Preset::Draft),
            Criterion::Impedance,
        )
    };
    CompareRow {
        name: name.into(),
        parameters: String::new(),
        estimator: EstimatorKind::Fdm {}.into(),
        map: MapResult {
            k_width: k,
            k_width_interval: interval,
            ..map_observed(&spec, None, 0).unwrap()
        },
        tuning: None,
        refined,
    }
}

#[test]
fn two_widths_are_equal_when_one_interval_of_the_resolution_holds_both() {
    // [99, 101] and [100, 101.5]: the interval holding both is [99, 101.5],
    // 2.5/101.5 = 2.463 % wide by bisection's measure (hi − lo)/hi (by hand).
    let a = (100.0, Some([99.0, 101.0]));
    let b = (100.5, Some([100.0, 101.5]));
    assert!(!equal_within(&a, &b, 0.0246));
    assert!(equal_within(&a, &b, 0.0247));
    assert!(equal_within(&b, &a, 0.0247));
    // No interval, or an empty one at zero: never equal.
    assert!(!equal_within(&a, &(100.0, None), 0.5));
    assert!(!equal_within(
        &(0.0, Some([0.0, 0.0])),
        &(0.0, Some([0.0, 0.0])),
        0.5
    ));
    assert_eq!(relative_width(&a), 2.0 / 101.0);
    assert!(relative_width(&(0.0, Some([0.0, 0.0]))).is_infinite());
    assert!(relative_width(&(1.0, None)).is_infinite());
}

#[test]
fn refined_rows_carry_their_spent_error_into_each_pair_bound() {
    // A refined once at 97.5 % (α spent 0.05 + 0.025), B never refined
    // (0.05), C refined twice (0.05 + 0.025 + 0.0125).
    let once = Refined {
        maps: 1,
        k_rel_tol: 0.005,
        confidence: 0.975,
        realizations: 48,
        alpha_spent: 0.075,
    };
    let twice = Refined {
        maps: 2,
        k_rel_tol: 0.0025,
        confidence: 0.9875,
        realizations: 96,
        alpha_spent: 0.0875,
    };
    let rows = [
        made_up_row("A", 120.0, Some([119.0, 121.0]), Some(once)),
        made_up_row("B", 100.0, Some([99.0, 101.0]), None),
        made_up_row("C", 100.5, Some([100.0, 101.5]), Some(twice)),
    ];
    let o = pair_orders(&rows, 0.95, 0.0247);
    let got: Vec<(&str, &str, bool, bool)> = o
        .iter()
        .map(|p| (p.wider.as_str(), p.narrower.as_str(), p.resolved, p.equal))
        .collect();
    assert_eq!(
        got,
        [
            ("A", "B", true, false),
            ("A", "C", true, false),
            ("C", "B", false, true),
        ]
    );
    // Resolved: one bound of each row, α spent summed; equal: both bounds.
    let bounds: Vec<f64> = o.iter().map(|p| p.error_at_most).collect();
    let want = [0.075 + 0.05, 0.075 + 0.0875, 2.0 * (0.0875 + 0.05)];
    for (g, w) in bounds.iter().zip(want) {
        assert!((g - w).abs() < 1e-12, "{bounds:?} against {want:?}");
    }
    // At a finer resolution C and B are open; a round maps again those of
    // the two wider than its own resolution (B 2/101 = 1.98 %, C 1.5/101.5
    // = 1.48 %), both when neither is; A never. B exactly at the round's
    // resolution is not wider.
    assert_eq!(open_rows(&rows, 0.0246, 0.01), [1, 2]);
    assert_eq!(open_rows(&rows, 0.0246, 0.016), [1]);
    assert_eq!(open_rows(&rows, 0.0246, 0.03), [1, 2]);
    assert_eq!(open_rows(&rows, 0.0246, 2.0 / 101.0), [1, 2]);
    assert!(open_rows(&rows, 0.0247, 0.01).is_empty());
    // The table gives each line its bound once a row is refined.
    let t = CompareResult {
        lipschitz: estimate_c(&seed_2018_scene()).unwrap(),
        rows: rows.to_vec(),
        order: o,
        tuned_for: None,
        resolution: None,
        elapsed_s: 0.0,
    }
    .table();
    assert!(
        t.contains("  C            > B            equal within the resolution (wrong with probability at most 28 %)\n"),
        "{t}"
    );
}

#[test]
fn a_refinement_says_whether_its_rounds_were_spent_and_counts_its_scopes() {
    // Scopes: n first maps, then n a round (r·n + i).
    assert_eq!((scopes(4, 0), scopes(3, 2), scopes(2, 3)), (4, 9, 8));
    assert_eq!(
        (scope_of(3, 0, 2), scope_of(3, 1, 0), scope_of(3, 2, 1)),
        (2, 3, 7)
    );
    let r = |run, open, cancelled| Resolution::new(2, run, open, cancelled);
    assert!(!r(2, 0, false).budget_ended);
    assert!(r(2, 1, false).budget_ended);
    assert!(r(1, 1, false).budget_ended);
    assert!(!r(1, 1, true).budget_ended);
    assert_eq!(
        (r(1, 3, false).rounds_run, r(1, 3, false).open_pairs),
        (1, 3)
    );
    // Each round plans every row once more, finer: the seed device at
    // draft, 4 rows, 2 rounds: 8 maps, each with more trials than a first
    // map (a finer bisection halves more often).
    let scene = seed_2018_scene();
    let draft = Accuracy::Preset(crate::zwidth::settings::Preset::Draft);
    let one =
        super::super::search::validate(&map_spec(scene.clone(), &draft, Criterion::Impedance))
            .unwrap();
    let c = refinement_cost(&scene, &draft, Criterion::Impedance, 2, 4).unwrap();
    assert_eq!(c.maps, 8);
    assert!(c.trials > 8 * one.trials, "{c:?} vs {one:?}");
    assert_eq!(
        refinement_cost(&scene, &draft, Criterion::Impedance, 0, 4).unwrap(),
        super::super::cost::Cost::default()
    );
}

#[test]
fn each_round_halves_the_resolution_and_the_error_rate_and_doubles_the_realizations() {
    // Round r: k_rel_tol/2^r, 2^r × the realizations and confidence
    // 1 − α/2^r, so α + α/2 + α/4 + α/8 < 2α over the rounds (the union
    // bound over a row's maps). Standard: 1 %, 24 realizations
    // (settings.rs's presets).
    let sc = seed_2018_scene().validate().unwrap();
    let acc = Accuracy::Preset(crate::zwidth::settings::Preset::Standard);
    let res = acc.resolve(&sc).unwrap();
    let mut spent = 0.05;
    for (r, tol, reals, conf) in [
        (1, 0.005, 48, 0.975),
        (2, 0.0025, 96, 0.9875),
        (3, 0.00125, 192, 0.99375),
    ] {
        let round = Round::new(&acc, &res, 0.95, r);
        assert_eq!((round.k_rel_tol, round.confidence), (tol, conf));
        let Accuracy::Knobs(k) = &round.accuracy else {
            panic!("knobs expected")
        };
        assert_eq!((k.k_rel_tol, k.realizations), (Some(tol), Some(reals)));
        assert_eq!(round.realizations, reals);
        assert_eq!(k.preset, crate::zwidth::settings::Preset::Standard);
        spent += 1.0 - round.confidence;
    }
    assert!(spent < 0.1);
    // The spec's own knobs are kept, its resolution and realizations
    // replaced; the realizations stop at the accuracy's limit, 1000.
    let knobs: Accuracy = serde_json::from_str(
        r#"{"preset":"draft","k_rel_tol":0.04,"realizations":300,"periods":3}"#,
    )
    .unwrap();
    let round = Round::new(&knobs, &knobs.resolve(&sc).unwrap(), 0.9, 2);
    assert_eq!(round.k_rel_tol, 0.01);
    assert!((round.confidence - 0.975).abs() < 1e-15);
    let Accuracy::Knobs(k) = &round.accuracy else {
        panic!("knobs expected")
    };
    assert_eq!(
        (k.k_rel_tol, k.realizations, k.periods),
        (Some(0.01), Some(1000), Some(3))
    );
    let spec = round.map_spec(&seed_2018_scene(), Criterion::Impedance);
    assert!((spec.scene.probe.confidence - 0.975).abs() < 1e-15);
    assert_eq!(
        check_rounds(4).unwrap_err().to_string(),
        "resolve_rounds = 4 is not allowed: must be 0 to 3 (each round halves the K resolution of the rows whose orders are open)"
    );
    assert!(check_rounds(3).is_ok());
}

#[test]
fn a_comparison_refines_the_rows_of_an_open_order_and_reports_every_scope() {
    // The same estimator twice on the seed device at draft (not the
    // scene's own: the refined maps must use the row's): equal maps, so the
    // pair is never resolved. A third row far from them (FDM without a
    // filter) is resolved from the first maps and not mapped again.
    let scene = seed_2018_scene();
    let bw: EstimatorSpec =
        serde_json::from_value(serde_json::json!({"kind":"butterworth","cutoff_hz":300,"order":2}))
            .unwrap();
    let o = std::sync::Arc::new(Observer::default());
    let r = compare_observed(
        &scene,
        &Accuracy::Preset(crate::zwidth::settings::Preset::Draft),
        Criterion::Impedance,
        Some(&[bw.clone(), bw, EstimatorKind::Fdm {}.into()]),
        2,
        Some(o.clone()),
    )
    .unwrap();
    assert_eq!(r.rows[0].map.k_width, r.rows[1].map.k_width);
    assert!(r.rows[2].refined.is_none(), "{:?}", r.order);
    let p = &r.order[0];
    assert!(!p.resolved);
    let res = r.resolution.expect("a resolution with rounds allowed");
    // Refined once: half the draft's 5 %, twice its 10 realizations, α/2 of
    // the default 95 %, with the row's estimator. Its interval then fits
    // within the draft's resolution ([244 071, 255 977], 4.65 % wide when
    // recorded): the pair is equal, with both bounds of both rows as its
    // error, 2·(0.075 + 0.075), and nothing is left open.
    let f = r.rows[0].refined.expect("refined");
    assert_eq!(
        (f.maps, f.k_rel_tol, f.confidence, f.realizations),
        (1, 0.025, 0.975, 20)
    );
    assert!((f.alpha_spent - 0.075).abs() < 1e-12);
    let m = &r.rows[0].map;
    assert!(m.resolution.contains("2.50 %"), "{}", m.resolution);
    assert!(
        m.model.contains("estimator butterworth(300 Hz"),
        "{}",
        m.model
    );
    assert!(p.equal);
    assert!((p.error_at_most - 0.3).abs() < 1e-12, "{p:?}");
    // Round 2 has nothing left to map: its scopes are reported done.
    assert_eq!((res.rounds, res.rounds_run, res.open_pairs), (2, 1, 0));
    assert!(!res.budget_ended);
    // Both bounds of every row, α spent each: 2·(0.075 + 0.075 + 0.05).
    assert!((res.joint_error_at_most - 0.4).abs() < 1e-12, "{res:?}");
    // Trials stored under the first maps' scopes 0–2 and round 1's of rows
    // 0 and 1 (3·1 + 0, 3·1 + 1); row 2's scope 5 and round 2's 6–8
    // reported done unmapped.
    let stored: std::collections::BTreeSet<u32> = o.take_new().iter().map(|t| t.scope).collect();
    assert_eq!(stored.into_iter().collect::<Vec<_>>(), [0, 1, 2, 3, 4]);
    assert!((o.fraction() - 1.0).abs() < 1e-12, "{}", o.fraction());
    assert!(
        r.table().contains("Refinement: 1 of 2 rounds run, every pair order decided; every decided order at once wrong with probability at most 40 %"),
        "{}",
        r.table()
    );
}
