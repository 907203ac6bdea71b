//! Tests of a map seeded by a prediction (`search.rs` with a `prior`,
//! issue 46): fewer trials where it is right, its own boundary and the
//! disagreement flagged where it is wrong, the refusals, the plan and the
//! cancel.

use super::*;
use crate::zwidth::scene::SceneSpec;

/// The seed device at 1 kHz, three short hits per verdict (as in
/// `replicate_hits_give_majority_verdicts_and_intervals`), over three B,
/// its handle of `mass` (kg; the seed device's is 0.52).
fn replicated_map(mass: f64) -> MapSpec {
    let mut scene = SceneSpec::from_json(
        r#"{"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"home_distance":0.001,"settle_s":0.3,"measure_s":0.2,"replicates":3}}"#,
    )
    .unwrap();
    scene.device.mass = mass;
    MapSpec {
        criterion: Criterion::Stability,
        scene,
        method: Method::Time,
        search: SearchKind::Bisect,
        accuracy: Default::default(),
        b: Some(vec![0.0, 20.0, 40.0]),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    }
}

#[test]
fn a_right_prior_brackets_each_column_in_a_few_trials() {
    // Issue 46: a map seeded by its own device's prediction lands inside
    // the unseeded map's intervals with at least 3× fewer trials.
    let spec = replicated_map(0.52);
    let cold = map(&spec).unwrap();
    let seeded = map(&MapSpec {
        prior: Some(Prior::Boundary(cold.boundary.clone())),
        ..spec.clone()
    })
    .unwrap();
    assert!(
        3 * seeded.trials <= cold.trials,
        "{} against {}",
        seeded.trials,
        cold.trials
    );
    for (c, s) in cold.boundary.iter().zip(&seeded.boundary) {
        let (lo, hi) = (c.k_lo.unwrap(), c.k_hi.unwrap());
        assert!(lo <= s.k_max && s.k_max <= hi, "{s:?} outside {c:?}");
    }
    let report = seeded.prior.as_ref().unwrap();
    assert_eq!((report.disagreements, report.trials), (0, seeded.trials));
    assert_eq!(report.source, "the boundary given");
    // A scene to simulate first gives the same prediction, so the same map
    // (the same trials, to the bit).
    let simulated = map(&MapSpec {
        prior: Some(Prior::Scene(Box::new(spec.scene.clone()))),
        ..spec.clone()
    })
    .unwrap();
    assert_eq!(simulated.points, seeded.points);
    assert_eq!(
        simulated.prior.unwrap().source,
        "a simulation of the prior's scene"
    );
    // Without a prior, no report.
    assert!(cold.prior.is_none());
}

#[test]
fn a_wrong_prior_is_flagged_and_the_map_stays_its_own() {
    // The device 30 % heavier than the prediction's: the columns'
    // boundaries move, the report says where, and each boundary point is
    // the map's own verdicts' (a K that renders, with a failure within
    // the resolution above it).
    let light = replicated_map(0.52);
    let heavy = replicated_map(0.676);
    let cold = map(&heavy).unwrap();
    let seeded = map(&MapSpec {
        prior: Some(Prior::Scene(Box::new(light.scene.clone()))),
        ..heavy.clone()
    })
    .unwrap();
    let report = seeded.prior.as_ref().unwrap();
    assert!(report.disagreements >= 1, "{report:?}");
    for (col, bp) in report.columns.iter().zip(&seeded.boundary) {
        assert_eq!(col.b, bp.b);
        let ok_at = |k: f64| {
            seeded
                .points
                .iter()
                .any(|p| p.b == bp.b && p.k == k && p.ok())
        };
        assert!(bp.k_max == 0.0 || ok_at(bp.k_max), "{bp:?}");
        let fails_above = seeded
            .points
            .iter()
            .any(|p| p.b == bp.b && !p.ok() && p.k > bp.k_max && p.k <= bp.k_max * 1.011 + 1e-9);
        assert!(bp.k_max == 0.0 || fails_above, "{bp:?}");
    }
    // Not more than 1.3× the unseeded map's trials (issue 46).
    assert!(
        10 * seeded.trials <= 13 * cold.trials,
        "{} against {}",
        seeded.trials,
        cold.trials
    );
}

#[test]
fn a_cancel_stops_a_scene_prior_s_simulation() {
    // The prior's map runs in this process before the map's own trials:
    // cancelling the run stops it there, and the map ends without a
    // prediction (its report absent). The example rig's standard wall hits
    // (6 s each at 10 kHz, three a trial) are seconds of a debug build.
    let spec = MapSpec {
        scene: SceneSpec::from_json(include_str!(
            "../../../../examples/rig_2011_motor_encoder.json"
        ))
        .unwrap(),
        b: Some(vec![0.0, 14.88, 29.76]),
        ..replicated_map(0.52)
    };
    let seeded = MapSpec {
        prior: Some(Prior::Scene(Box::new(spec.scene.clone()))),
        ..spec.clone()
    };
    // Cancelled before it starts: nothing simulated, nothing mapped.
    let o = std::sync::Arc::new(Observer::default());
    o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
    let r = map_observed(&seeded, Some(o), 0).unwrap();
    assert!(r.prior.is_none());
    // Cancelled a moment into the prior's simulation.
    let o = std::sync::Arc::new(Observer::default());
    let canceller = {
        let o = o.clone();
        std::thread::spawn(move || {
            std::thread::sleep(std::time::Duration::from_millis(100));
            o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        })
    };
    let r = map_observed(&seeded, Some(o.clone()), 0).unwrap();
    canceller.join().unwrap();
    assert!(r.prior.is_none(), "{:?}", r.prior);
    assert!(o.cancelled());
}

#[test]
fn a_prior_is_refused_where_it_cannot_seed_the_search() {
    let spec = replicated_map(0.52);
    let with = |prior: Prior, search: SearchKind| {
        validate(&MapSpec {
            prior: Some(prior),
            search,
            ..spec.clone()
        })
        .map(|_| ())
        .map_err(|e| e.field)
    };
    let given = || Prior::Boundary(vec![BoundaryPoint::new(0.0, 1000.0)]);
    assert_eq!(with(given(), SearchKind::Bisect), Ok(()));
    assert_eq!(with(given(), SearchKind::RobustBisect), Ok(()));
    for search in [SearchKind::Trace, SearchKind::Grid, SearchKind::Psi] {
        assert_eq!(with(given(), search), Err("prior".to_string()));
    }
    assert_eq!(
        with(Prior::Run("abc".into()), SearchKind::Bisect),
        Err("prior.run".to_string())
    );
    assert_eq!(
        with(Prior::Boundary(vec![]), SearchKind::Bisect),
        Err("prior.boundary".to_string())
    );
    // A scene prior is a second map's trials, run here and not stored.
    let alone = validate(&spec).unwrap();
    let with_scene = validate(&MapSpec {
        prior: Some(Prior::Scene(Box::new(spec.scene.clone()))),
        ..spec.clone()
    })
    .unwrap();
    assert_eq!(
        (
            with_scene.maps,
            with_scene.trials,
            with_scene.stored_rows,
            with_scene.stored_bytes
        ),
        (2, 2 * alone.trials, alone.stored_rows, alone.stored_bytes)
    );
    assert_eq!(
        validate(&MapSpec {
            prior: Some(given()),
            ..spec.clone()
        })
        .unwrap(),
        alone
    );
    // The map's own faults are named as its own, before any prior runs.
    let twice = MapSpec {
        b: Some(vec![0.0, 0.0]),
        prior: Some(Prior::Scene(Box::new(spec.scene.clone()))),
        ..spec.clone()
    };
    assert_eq!(map(&twice).unwrap_err().field, "b");
    assert_eq!(validate(&twice).unwrap_err().field, "b");
    // No search to seed: strict passivity on the analytic model.
    let exact = MapSpec {
        criterion: Criterion::StrictPassivity,
        method: Method::Analytic,
        scene: SceneSpec::from_json(
            r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap(),
        prior: Some(given()),
        ..spec.clone()
    };
    assert_eq!(validate(&exact).unwrap_err().field, "prior");
    let mut bad = spec.scene.clone();
    bad.device.mass = -1.0;
    assert_eq!(
        with(Prior::Scene(Box::new(bad)), SearchKind::Bisect),
        Err("prior.scene.device.mass".to_string())
    );
}
