//! Pooling replicates, the Pareto front, infeasible scores, which accuracy
//! each phase maps at, and the gain-condition violations.

use super::*;

#[test]
fn the_pareto_front_keeps_ties_and_drops_the_dominated() {
    // (K-width, B-width): (100, 10) twice, (50, 20), (40, 5). The two
    // equal points do not dominate each other (domination needs one
    // strictly better metric), so (100, 10) is on the front, once;
    // (40, 5) is dominated by it.
    let e = |index: usize, k: f64, b: f64| {
        let mut p = pooled(k, [k, k], 1).eval;
        p.index = index;
        p.phase = "search".into();
        p.metrics.b_width = b;
        p
    };
    let h = [
        e(0, 100.0, 10.0),
        e(1, 100.0, 10.0),
        e(2, 50.0, 20.0),
        e(3, 40.0, 5.0),
    ];
    let mut f = pareto_front(&h, &[Metric::KWidth, Metric::BWidth]);
    f.sort();
    assert_eq!(f, [0, 2]);
}

#[test]
fn infeasible_gains_score_below_any_width_and_worse_the_farther_off() {
    let (near, far) = (infeasible_score(0.1), infeasible_score(2.0));
    assert!(near > far, "{near} {far}");
    assert!(near < -1e12, "below every K-width (≤ 1e12 N/m)");
    assert_eq!(near, -1e15 - 0.1);
}

fn pooled(score: f64, interval: [f64; 2], replicates: usize) -> Pooled {
    Pooled {
        eval: Evaluation {
            index: 0,
            phase: "final".into(),
            params: BTreeMap::new(),
            objectives: BTreeMap::new(),
            metrics: Metrics {
                k_width: score,
                b_width: 0.0,
                max_fidelity_error: None,
                area: 0.0,
                k_width_interval: Some(interval),
                b_width_interval: None,
            },
            score,
            feasible: true,
            cached: false,
            trials: 0,
            elapsed_s: 0.0,
            replicate: 0,
        },
        replicates,
        interval: Some(interval),
    }
}

#[test]
fn finals_are_mapped_at_the_final_accuracy_and_the_search_at_its_own() {
    // Linear scene, analytic engine (deterministic): each evaluation's
    // K-width must equal a map of its scene at its phase's accuracy,
    // computed here independently of the tune (draft resolves K to 5 %,
    // standard to 1 %, so the two differ).
    let spec: TuneSpec = serde_json::from_value(serde_json::json!({
        "scene": {"device": {"coulomb": 0, "quantization": 0},
                  "loop": {"sample_hz": 1000, "render_hz": 1000},
                  "estimator": {"kind": "butterworth", "cutoff_hz": 200}},
        "params": {"cutoff_hz": {"min": 50, "max": 450}},
        "objective": "k_width",
        "accuracy": "draft",
        "final_accuracy": "standard",
        "finalists": 1,
        "max_evaluations": 3,
        "b": [0, 20]
    }))
    .unwrap();
    let tune = spec.validate().unwrap();
    let r = tune.run(None).unwrap();
    let k_at = |e: &Evaluation, preset: &str| {
        let scene = tune.space.scene_at(&e.params).unwrap();
        let m: MapSpec = serde_json::from_value(serde_json::json!({
            "scene": scene, "method": "auto", "criterion": "impedance",
            "search": "robust_bisect", "accuracy": preset, "b": [0, 20]
        }))
        .unwrap();
        crate::zwidth::search::map(&m).unwrap().k_width
    };
    let fin = r
        .history
        .iter()
        .find(|e| e.phase == "final")
        .expect("a final");
    let search = r.history.iter().find(|e| e.phase == "search").unwrap();
    assert_eq!(fin.metrics.k_width, k_at(fin, "standard"));
    assert_ne!(fin.metrics.k_width, k_at(fin, "draft"));
    assert_eq!(search.metrics.k_width, k_at(search, "draft"));
    // saved_s: the computed search maps at the final accuracy's mean cost,
    // minus what the search and the finals did cost (its documented formula).
    let c = r.coarse_to_fine.as_ref().unwrap();
    let n = r
        .history
        .iter()
        .filter(|e| e.phase == "search" && !e.cached)
        .count() as f64;
    let want = n * c.mean_final_evaluation_s - (c.search_s + c.final_s);
    assert!(
        (c.saved_s.unwrap() - want).abs() < 1e-9,
        "{:?} vs {want}",
        c.saved_s
    );
    // The means are over the computed evaluations of each phase (not the
    // cache hits), recomputed here from the history.
    let mean = |phase: &str| {
        let t: Vec<f64> = r
            .history
            .iter()
            .filter(|e| e.phase == phase && !e.cached)
            .map(|e| e.elapsed_s)
            .collect();
        t.iter().sum::<f64>() / t.len() as f64
    };
    assert!((c.mean_search_evaluation_s - mean("search")).abs() < 1e-12);
    assert!((c.mean_final_evaluation_s - mean("final")).abs() < 1e-12);
    // One finalist: it is trivially still the best, and its rank held.
    assert!(c.best_held && c.ranking_held);
}

#[test]
fn violation_measures_how_far_gains_miss_eqs_10_and_14() {
    // C = 12 m/s². Eq. 10 (Levant 1998): α > C and λ² ≥ 4C(α + C)/(α − C);
    // eq. 14 (Moreno–Osorio): α > 3C + 2C²/λ². Violations by hand.
    let run_with = |cond: &str, check: &dyn Fn(&Run)| {
        let spec: TuneSpec = serde_json::from_value(serde_json::json!({
            "scene": {"device": {"coulomb": 0, "quantization": 0},
                      "estimator": {"kind": "levant", "mu1": 2, "mu2": 4, "lipschitz": 12}},
            "params": {"mu1": {"min": 1, "max": 40}, "mu2": {"min": 0.5, "max": 60}},
            "objective": "k_width",
            "constraint": cond
        }))
        .unwrap();
        let tune = spec.validate().unwrap();
        let run = Run::new(&tune, None);
        check(&run);
    };
    let gains = |a: f64, l: f64| -> SceneSpec {
        serde_json::from_value(serde_json::json!({
            "estimator": {"kind": "levant", "alpha": a, "lambda": l, "lipschitz": 12}
        }))
        .unwrap()
    };
    let close = |got: f64, want: f64| assert!((got - want).abs() < 1e-12, "{got} vs {want}");
    run_with("levant", &|r| {
        // α ≤ C: 1 + (C − α)/C = 1 + 6/12.
        close(r.violation(&gains(6.0, 100.0)), 1.5);
        // α = 24: λ² must reach 4·12·36/12 = 144; λ = 10 misses by 44/C² = 44/144.
        close(r.violation(&gains(24.0, 10.0)), 44.0 / 144.0);
        close(r.violation(&gains(24.0, 13.0)), 0.0);
    });
    run_with("lyapunov", &|r| {
        // λ = 12: bound 36 + 2·144/144 = 38; α = 30 misses by 8/C.
        close(r.violation(&gains(30.0, 12.0)), 8.0 / 12.0);
        close(r.violation(&gains(40.0, 12.0)), 0.0);
    });
}

#[test]
fn pooled_replicates_are_the_mean_with_a_student_t_interval() {
    let spec: TuneSpec = serde_json::from_value(serde_json::json!({
        "scene": {"device": {"coulomb": 0, "quantization": 0},
                  "estimator": {"kind": "butterworth", "cutoff_hz": 200}},
        "params": {"cutoff_hz": {"min": 100, "max": 400}},
        "objective": "k_width"
    }))
    .unwrap();
    let tune = spec.validate().unwrap();
    let run = Run::new(&tune, None);
    let rep = |k: f64, lo: f64, hi: f64, fid: f64| {
        let mut e = pooled(k, [lo, hi], 1).eval;
        e.metrics.max_fidelity_error = Some(fid);
        e.metrics.area = 2.0 * k;
        e
    };
    // Two maps: 100 [99, 101] and 104 [103, 105]. Mean 102, s = 2√2,
    // t(0.975, 1) = 12.706 (NIST table): half-width 12.706·2√2/√2 =
    // 25.41, wider than the mean map interval [101, 103].
    let p = run.pool(&[rep(100.0, 99.0, 101.0, 3.0), rep(104.0, 103.0, 105.0, 5.0)]);
    assert_eq!(p.replicates, 2);
    assert_eq!(p.eval.score, 102.0);
    assert_eq!(p.eval.metrics.k_width, 102.0);
    assert_eq!(p.eval.metrics.area, 204.0);
    assert_eq!(p.eval.metrics.max_fidelity_error, Some(4.0));
    let [lo, hi] = p.interval.unwrap();
    assert!(
        (lo - (102.0 - 25.412)).abs() < 2e-3 && (hi - (102.0 + 25.412)).abs() < 2e-3,
        "{lo} {hi}"
    );
    // Three identical maps: s = 0, the mean map interval stands.
    let p = run.pool(&vec![rep(100.0, 98.0, 101.0, 1.0); 3]);
    assert_eq!(p.interval, Some([98.0, 101.0]));
    // One map: its own interval.
    let p = run.pool(&[rep(100.0, 97.0, 100.5, 1.0)]);
    assert_eq!(p.interval, Some([97.0, 100.5]));
}

#[test]
fn replicates_go_to_the_finalists_whose_interval_overlaps_the_best() {
    // Below the minimum: every finalist below it, whatever the intervals.
    let p = [pooled(10.0, [9.0, 11.0], 3), pooled(5.0, [4.0, 6.0], 2)];
    assert_eq!(more_replicates(&p, 3), vec![1]);
    // The best (index 1) overlaps index 2, not index 0: both of the
    // overlapping pair get one more, the separated one none.
    let p = [
        pooled(5.0, [4.0, 6.0], 3),
        pooled(10.0, [9.0, 11.0], 3),
        pooled(8.5, [7.0, 9.0], 3),
    ];
    assert_eq!(more_replicates(&p, 3), vec![1, 2]);
    // Touching intervals overlap (closed); disjoint ones decide.
    let p = [pooled(10.0, [9.0, 11.0], 3), pooled(8.0, [7.0, 8.999], 3)];
    assert!(more_replicates(&p, 3).is_empty());
    // Up to twice the minimum, then the ranking stands as it is.
    let p = [pooled(10.0, [9.0, 11.0], 6), pooled(9.5, [9.0, 10.0], 5)];
    assert_eq!(more_replicates(&p, 3), vec![1]);
    let p = [pooled(10.0, [9.0, 11.0], 6), pooled(9.5, [9.0, 10.0], 6)];
    assert!(more_replicates(&p, 3).is_empty());
    // Equal scores: the first is the best (as the final ranking orders).
    let p = [pooled(10.0, [9.0, 11.0], 3), pooled(10.0, [9.0, 11.0], 3)];
    assert_eq!(more_replicates(&p, 3), vec![0, 1]);
    assert!(more_replicates(&[], 3).is_empty());
}

#[test]
fn a_weighted_score_is_the_signed_weighted_sum() {
    // Σ wᵢ·sᵢ·mᵢ (the objective's docs): 1e-5·4e5 + 1e-2·300 − 0.5·12
    // (the fidelity error counts against) = 4 + 3 − 6 = 1.
    let spec: TuneSpec = serde_json::from_value(serde_json::json!({
        "scene": {"device": {"coulomb": 0, "quantization": 0},
                  "estimator": {"kind": "butterworth", "cutoff_hz": 100}},
        "params": {"cutoff_hz": {"min": 50, "max": 400}},
        "objective": {"weighted": {"k_width": 1e-5, "b_width": 1e-2, "max_fidelity_error": 0.5}}
    }))
    .unwrap();
    let tune = spec.validate().unwrap();
    let run = Run::new(&tune, None);
    let mut m = pooled(4e5, [4e5, 4e5], 1).eval.metrics;
    m.b_width = 300.0;
    m.max_fidelity_error = Some(12.0);
    assert!(
        (run.score(&m, 0.0) - 1.0).abs() < 1e-12,
        "{}",
        run.score(&m, 0.0)
    );
}
