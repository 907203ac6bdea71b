//! Tuning: the library against independent brute force, seeds, the cache,
//! resume, Pareto fronts, and the `zwidth tune` command's contract.

use std::process::Command;
use std::sync::Arc;

use zwidth::tune::{Bounds, Metric, Objective, SolverKind, TuneSpec};
use zwidth::zwidth::scene::SceneSpec;
use zwidth::zwidth::search::{map, Observer};
use zwidth::zwidth::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
use zwidth::zwidth::sweep::Scale;

/// The 2018 paper's device without friction and quantization at 1 kHz: the
/// analytic engine answers exactly and in milliseconds.
fn linear(estimator: &str) -> SceneSpec {
    serde_json::from_str(&format!(
        r#"{{"device":{{"coulomb":0,"quantization":0}},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{estimator}}}"#
    ))
    .unwrap()
}

fn spec(
    scene: SceneSpec,
    params: &[(&str, f64, f64)],
    objective: Objective,
    solver: SolverKind,
    evals: usize,
) -> TuneSpec {
    TuneSpec {
        scene,
        params: params
            .iter()
            .map(|&(n, min, max)| {
                (
                    n.to_string(),
                    Bounds {
                        min,
                        max,
                        scale: Scale::Linear,
                        step: None,
                    },
                )
            })
            .collect(),
        objective,
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::Bisect,
        accuracy: Accuracy::Preset(Preset::Standard),
        final_accuracy: Accuracy::Preset(Preset::Standard),
        finalists: 3,
        replicates: 3,
        solver,
        seed: 0,
        max_evaluations: evals,
        constraint: None,
        b: Some(vec![20.0]),
        b_max: 1000.0,
        k_max: 1e7,
    }
}

fn k_at(cutoff: f64) -> f64 {
    k_at_accuracy(cutoff, Preset::Standard)
}

fn k_at_accuracy(cutoff: f64, preset: Preset) -> f64 {
    let m = MapSpec {
        scene: linear(&format!(r#"{{"kind":"butterworth","cutoff_hz":{cutoff}}}"#)),
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::Bisect,
        accuracy: Accuracy::Preset(preset),
        b: Some(vec![20.0]),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    };
    map(&m).unwrap().k_width
}

#[test]
fn tuned_cutoff_matches_an_independent_scan() {
    // Brute force by plain maps, 1 Hz steps over 20…200 Hz at B = 20 N·s/m
    // (the impedance test has a dip near 100 Hz: not unimodal).
    let scan_best = (20..=200).map(|f| k_at(f as f64)).fold(0.0, f64::max);
    let s = spec(
        linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
        &[("cutoff_hz", 20.0, 200.0)],
        Objective::Single(Metric::KWidth),
        SolverKind::Auto,
        36,
    );
    let r = s.validate().unwrap().run(None).unwrap();
    let k = r.best.objectives["k_width"].unwrap();
    assert!(k >= 0.98 * scan_best, "tuned {k} vs scan {scan_best}");
    assert!(r.evaluations <= 36 + 3, "{}", r.evaluations);
    // The reported K-width is what a plain map at those parameters gives.
    assert_eq!(k, k_at(r.best.params["cutoff_hz"]));
}

#[test]
fn a_seed_reproduces_a_particle_swarm_exactly() {
    let run = |seed| {
        let mut s = spec(
            linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
            &[("cutoff_hz", 20.0, 400.0), ("order", 1.0, 4.0)],
            Objective::Single(Metric::KWidth),
            SolverKind::ParticleSwarm,
            24,
        );
        s.seed = seed;
        let r = s.validate().unwrap().run(None).unwrap();
        r.history
            .iter()
            .map(|e| e.params.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(run(11), run(11));
    assert_ne!(run(11), run(12));
}

#[test]
fn identical_evaluations_come_from_the_cache_and_a_resumed_tune_redoes_none() {
    // Butterworth order 1…4 on a 10-point grid: only 4 distinct points.
    let s = spec(
        linear(r#"{"kind":"butterworth","cutoff_hz":150}"#),
        &[("order", 1.0, 4.0)],
        Objective::Single(Metric::KWidth),
        SolverKind::Grid,
        10,
    );
    let tune = s.validate().unwrap();
    let obs = Arc::new(Observer::default());
    let r = tune.run(Some(obs.clone())).unwrap();
    assert_eq!(r.evaluations, 4, "{r:#?}");
    assert!(r.cache_hits >= 6);
    // Finalists at the search's own accuracy are cache hits too.
    let finals: Vec<_> = r.history.iter().filter(|e| e.phase == "final").collect();
    assert_eq!(finals.len(), 3);
    assert!(finals.iter().all(|e| e.cached));
    // Resume: an observer holding the stored evaluations makes none anew,
    // and reports what the first run computed (they count as computed).
    let stored = obs.take_new_evaluations();
    assert_eq!(stored.len(), 4);
    let resumed = Arc::new(Observer::default().with_evaluations(stored));
    let again = tune.run(Some(resumed.clone())).unwrap();
    assert!(resumed.take_new_evaluations().is_empty());
    assert_eq!(again.evaluations, 4);
    assert_eq!(again.cache_hits, r.cache_hits);
    assert_eq!(again.best.params, r.best.params);
    assert_eq!(again.best.objectives, r.best.objectives);
}

/// What must not differ between an uninterrupted tune and a resumed one:
/// every evaluation's parameters, phase, score and origin, and the best.
/// One evaluation as (phase, parameter bits, score bits, cached).
type Step = (String, Vec<(String, u64)>, u64, bool);
/// A parameter with its bounds.
type Param<'a> = (&'a str, f64, f64);

fn path_of(r: &zwidth::tune::TuneResult) -> Vec<Step> {
    r.history
        .iter()
        .map(|e| {
            (
                e.phase.clone(),
                e.params
                    .iter()
                    .map(|(k, v)| (k.clone(), v.to_bits()))
                    .collect(),
                e.score.to_bits(),
                e.cached,
            )
        })
        .collect()
}

#[test]
fn a_tune_killed_at_any_point_resumes_to_the_uninterrupted_result_with_every_solver() {
    // A kill after n stored evaluations leaves exactly the first n of the
    // uninterrupted run's evaluations (the path is deterministic) and the
    // trials of the one under way; resuming from them must take the same
    // path: replayed evaluations count toward the budget as the first time.
    let one_d = [("cutoff_hz", 20.0, 400.0)];
    let two_d = [("cutoff_hz", 20.0, 400.0), ("order", 1.0, 4.0)];
    let cases: [(SolverKind, &[Param]); 9] = [
        (SolverKind::Auto, &one_d),
        (SolverKind::Auto, &two_d),
        (SolverKind::Brent, &one_d),
        (SolverKind::Golden, &one_d),
        (SolverKind::Grid, &one_d),
        (SolverKind::NelderMead, &two_d),
        (SolverKind::ParticleSwarm, &two_d),
        (SolverKind::Halton, &two_d),
        (SolverKind::Halton, &one_d),
    ];
    for (solver, params) in cases {
        let mut s = spec(
            linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
            params,
            Objective::Single(Metric::KWidth),
            solver,
            8,
        );
        s.finalists = 2;
        s.final_accuracy = Accuracy::Preset(Preset::Draft);
        s.seed = 3;
        let tune = s.validate().unwrap();
        let obs = Arc::new(Observer::default());
        let full = tune.run(Some(obs.clone())).unwrap();
        let evals = obs.take_new_evaluations();
        let trials = obs.take_new();
        let total_trials = obs.trials.load(std::sync::atomic::Ordering::Relaxed);
        assert!(evals.len() >= 4, "{solver:?}: {} evaluations", evals.len());
        for cut in [1, evals.len() / 2, evals.len() - 1] {
            // The evaluation under way at the kill: its scope is its index.
            let under_way = evals[cut].record["index"].as_u64().unwrap() as u32;
            let done_before: Vec<_> = evals[..cut]
                .iter()
                .map(|e| e.record["index"].as_u64().unwrap() as u32)
                .collect();
            let mut partial: Vec<_> = trials
                .iter()
                .filter(|t| done_before.contains(&t.scope))
                .cloned()
                .collect();
            let of_current: Vec<_> = trials.iter().filter(|t| t.scope == under_way).collect();
            partial.extend(
                of_current[..of_current.len() / 2]
                    .iter()
                    .map(|t| (*t).clone()),
            );
            let resumed =
                Arc::new(Observer::resuming(partial).with_evaluations(evals[..cut].to_vec()));
            let again = tune.run(Some(resumed.clone())).unwrap();
            assert_eq!(path_of(&again), path_of(&full), "{solver:?} cut at {cut}");
            assert_eq!(
                again.best.params, full.best.params,
                "{solver:?} cut at {cut}"
            );
            assert_eq!(
                again.evaluations, full.evaluations,
                "{solver:?} cut at {cut}"
            );
            // trials_done counts the replayed ones too (defect 16).
            assert_eq!(
                resumed.trials.load(std::sync::atomic::Ordering::Relaxed),
                total_trials,
                "{solver:?} cut at {cut}"
            );
            // Only the evaluations after the cut were computed anew.
            assert_eq!(resumed.take_new_evaluations().len(), evals.len() - cut);
        }
    }
}

#[test]
fn the_pareto_front_is_non_dominated() {
    let s = spec(
        linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
        &[("cutoff_hz", 20.0, 450.0)],
        Objective::Pareto(vec![Metric::KWidth, Metric::MaxFidelityError]),
        SolverKind::Auto,
        24,
    );
    let r = s.validate().unwrap().run(None).unwrap();
    let front = r.pareto_front.clone().unwrap();
    assert!(!front.is_empty());
    let search: Vec<_> = r.history.iter().filter(|e| e.phase == "search").collect();
    let val = |e: &zwidth::tune::Evaluation| {
        (
            e.metrics.k_width,
            -e.metrics.max_fidelity_error.unwrap_or(1e12),
        )
    };
    for &i in &front {
        let f = val(search.iter().find(|e| e.index == i).unwrap());
        for e in &search {
            let o = val(e);
            let dominates = o.0 >= f.0 && o.1 >= f.1 && (o.0 > f.0 || o.1 > f.1);
            assert!(
                !dominates,
                "front member {i} {f:?} dominated by {} {o:?}",
                e.index
            );
        }
    }
    // And every non-member is dominated by (or equal to) some member.
    for e in &search {
        if !front.contains(&e.index) {
            let o = val(e);
            assert!(front.iter().any(|&i| {
                let f = val(search.iter().find(|x| x.index == i).unwrap());
                f.0 >= o.0 && f.1 >= o.1
            }));
        }
    }
    assert!(r.svg().unwrap().contains("<svg"));
}

#[test]
fn levant_constraint_keeps_the_gains_inside_the_condition() {
    // Levant 1998 (2018 paper eq. 10): α > C and λ² ≥ 4C(α+C)/(α−C).
    let c = 2.0;
    let r = constrained_levant_tune(c, zwidth::tune::GainCondition::Levant);
    for e in &r.history {
        let (a, l) = (e.params["alpha"], e.params["lambda"]);
        let meets = a > c && l * l >= 4.0 * c * (a + c) / (a - c);
        assert_eq!(e.feasible, meets, "{a} {l}");
        if !meets {
            assert_eq!(e.trials, 0, "infeasible gains are not simulated");
        }
    }
    let (a, l) = (r.best.params["alpha"], r.best.params["lambda"]);
    assert!(a > c && l * l >= 4.0 * c * (a + c) / (a - c));
    assert!(r.best.gains.as_deref().unwrap().contains("Levant 1998"));
}

/// A Halton tune of Levant's α and λ (0.5…20) for B-width at draft, under
/// a gain condition with Lipschitz bound `c`.
fn constrained_levant_tune(
    c: f64,
    condition: zwidth::tune::GainCondition,
) -> zwidth::tune::TuneResult {
    let mut s = spec(
        serde_json::from_str(&format!(
            r#"{{"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{{"kind":"levant","rule":"hba_sc","lipschitz":{c}}}}}"#
        ))
        .unwrap(),
        &[("alpha", 0.5, 20.0), ("lambda", 0.5, 20.0)],
        Objective::Single(Metric::BWidth),
        SolverKind::Halton,
        12,
    );
    s.constraint = Some(condition);
    s.accuracy = Accuracy::Preset(Preset::Draft);
    s.final_accuracy = Accuracy::Preset(Preset::Draft);
    s.b = Some(vec![0.0, 10.0]);
    s.validate().unwrap().run(None).unwrap()
}

#[test]
fn draft_search_then_standard_finals_report_what_plain_maps_give() {
    // Grid over the cutoff at draft, the best three re-evaluated at
    // standard. Each score must be what a plain map at that accuracy gives,
    // and ranking_held / best_held must say what those maps say.
    let mut s = spec(
        linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
        &[("cutoff_hz", 30.0, 210.0)],
        Objective::Single(Metric::KWidth),
        SolverKind::Grid,
        7,
    );
    s.accuracy = Accuracy::Preset(Preset::Draft);
    let r = s.validate().unwrap().run(None).unwrap();
    let c = r.coarse_to_fine.as_ref().expect("draft → standard");
    assert_eq!(
        (c.search_accuracy.as_str(), c.final_accuracy.as_str()),
        ("draft", "standard")
    );
    assert_eq!(c.finalists.len(), 3);
    // The search's scores, best first, are plain draft maps; the finalists
    // are the three best of them.
    let mut search: Vec<(f64, f64)> = r
        .history
        .iter()
        .filter(|e| e.phase == "search")
        .map(|e| (e.params["cutoff_hz"], e.score))
        .collect();
    assert_eq!(search.len(), 7);
    for &(f, score) in &search {
        assert_eq!(score, k_at_accuracy(f, Preset::Draft), "draft at {f} Hz");
    }
    search.sort_by(|a, b| b.1.total_cmp(&a.1));
    let finals: Vec<f64> = c.finalists.iter().map(|f| f.params["cutoff_hz"]).collect();
    assert_eq!(finals, search[..3].iter().map(|x| x.0).collect::<Vec<_>>());
    // Final scores are plain standard maps; the ranks follow from them.
    let standard: Vec<f64> = finals
        .iter()
        .map(|&f| k_at_accuracy(f, Preset::Standard))
        .collect();
    for (f, want) in c.finalists.iter().zip(&standard) {
        assert_eq!(f.final_score, *want);
        let rank = standard.iter().filter(|&&x| x > *want).count();
        assert_eq!(f.final_rank, rank);
    }
    // Held: wherever draft ordered two finalists strictly, standard agrees.
    let draft: Vec<f64> = search[..3].iter().map(|x| x.1).collect();
    let held =
        (0..3).all(|i| (i + 1..3).all(|j| draft[i] <= draft[j] || standard[i] >= standard[j]));
    assert_eq!(c.ranking_held, held);
    let best_std = standard.iter().cloned().fold(f64::MIN, f64::max);
    assert_eq!(c.best_held, standard[0] == best_std);
    // The best is the finalist best at standard, in the "final" phase.
    assert_eq!(r.best.phase, "final");
    assert_eq!(r.best.objectives["k_width"], Some(best_std));
    // saved_s: what the search would have cost at standard minus what the
    // search and finals did cost (the struct's own documented formula).
    let want = 7.0 * c.mean_final_evaluation_s - (c.search_s + c.final_s);
    assert!(
        (c.saved_s.unwrap() - want).abs() < 1e-9,
        "{:?} vs {want}",
        c.saved_s
    );
    assert!(c.mean_search_evaluation_s > 0.0 && c.mean_final_evaluation_s > 0.0);
    // The same accuracy twice: nothing to save.
    let mut same = s.clone();
    same.accuracy = Accuracy::Preset(Preset::Standard);
    same.max_evaluations = 3;
    let r = same.validate().unwrap().run(None).unwrap();
    assert_eq!(r.coarse_to_fine.unwrap().saved_s, None);
}

#[test]
fn lyapunov_constraint_keeps_the_gains_inside_the_condition() {
    // Moreno–Osorio (2018 paper eq. 14): α > 3C + 2C²/λ².
    let c = 2.0;
    let r = constrained_levant_tune(c, zwidth::tune::GainCondition::Lyapunov);
    let (mut met, mut not) = (0, 0);
    for e in &r.history {
        let (a, l) = (e.params["alpha"], e.params["lambda"]);
        let meets = a > 3.0 * c + 2.0 * c * c / (l * l);
        assert_eq!(e.feasible, meets, "{a} {l}");
        if meets {
            met += 1;
        } else {
            not += 1;
            assert_eq!(e.trials, 0, "infeasible gains are not simulated");
            assert!(e.score < -1e15, "ranked below every feasible score");
        }
    }
    assert!(met > 0 && not > 0, "both sides exercised: {met} / {not}");
    let (a, l) = (r.best.params["alpha"], r.best.params["lambda"]);
    assert!(a > 3.0 * c + 2.0 * c * c / (l * l));
    assert!(r.best.gains.as_deref().unwrap().contains("Moreno-Osorio"));
}

#[test]
fn weighted_objective_is_the_weighted_sum_of_plain_map_metrics() {
    // score = 1e-5·K-width + 1e-2·B-width − 1e-3·fidelity error, each
    // metric what a plain map at those parameters gives.
    let weights = [
        (Metric::KWidth, 1e-5),
        (Metric::BWidth, 1e-2),
        (Metric::MaxFidelityError, 1e-3),
    ];
    let mut s = spec(
        linear(r#"{"kind":"butterworth","cutoff_hz":100}"#),
        &[("cutoff_hz", 40.0, 200.0)],
        Objective::Weighted(weights.into_iter().collect()),
        SolverKind::Grid,
        5,
    );
    s.b = Some(vec![0.0, 10.0, 20.0]);
    s.finalists = 0;
    let r = s.validate().unwrap().run(None).unwrap();
    let mut best = (f64::MIN, 0.0);
    for e in &r.history {
        let f = e.params["cutoff_hz"];
        let m = map(&MapSpec {
            scene: linear(&format!(r#"{{"kind":"butterworth","cutoff_hz":{f}}}"#)),
            method: Method::Auto,
            criterion: Criterion::Impedance,
            search: SearchKind::Bisect,
            accuracy: Accuracy::Preset(Preset::Standard),
            b: Some(vec![0.0, 10.0, 20.0]),
            b_max: 1000.0,
            k_max: 1e7,
            prior: None,
        })
        .unwrap();
        let want = 1e-5 * m.k_width + 1e-2 * m.b_width - 1e-3 * m.max_fidelity_error.unwrap();
        assert!(
            (e.score - want).abs() <= 1e-12 * want.abs(),
            "{f} Hz: {} vs {want}",
            e.score
        );
        if want > best.0 {
            best = (want, f);
        }
    }
    assert_eq!(r.best.params["cutoff_hz"], best.1);
}

fn zwidth(args: &[&str]) -> (i32, String, String) {
    let o = Command::new(env!("CARGO_BIN_EXE_zwidth"))
        .args(args)
        .output()
        .unwrap();
    (
        o.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&o.stdout).into_owned(),
        String::from_utf8_lossy(&o.stderr).into_owned(),
    )
}

#[test]
fn zwidth_tune_contract_and_bad_requests() {
    let dir = std::env::temp_dir().join(format!("zwidth-tune-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    // Removed when the test ends, passed or failed.
    struct Remove(std::path::PathBuf);
    impl Drop for Remove {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
    let _cleanup = Remove(dir.clone());
    let scene = dir.join("scene.json");
    std::fs::write(
        &scene,
        serde_json::to_string(&linear(r#"{"kind":"kalman","q":1e4}"#)).unwrap(),
    )
    .unwrap();
    let sc = scene.to_str().unwrap();
    let svg = dir.join("t.svg");
    let (code, out, err) = zwidth(&[
        "tune",
        "--scene",
        sc,
        "--params",
        r#"{"q":{"min":1e2,"max":1e8,"scale":"log"}}"#,
        "--objective",
        "b_width",
        "--seed",
        "3",
        "--max-evaluations",
        "12",
        "--json",
        "--svg",
        svg.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let q = v["best"]["params"]["q"].as_f64().unwrap();
    assert!((1e2..=1e8).contains(&q), "{q}");
    assert!(v["best"]["objectives"]["b_width"].as_f64().is_some());
    assert!(v["evaluations"].as_u64().unwrap() >= 1);
    assert!(v["elapsed_s"].as_f64().unwrap() > 0.0);
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
    // Bad requests: exit 2, one line naming the field.
    for (params, objective, needle) in [
        (r#"{"q":{"min":1e8,"max":1e2}}"#, "k_width", "params.q.max"),
        (
            r#"{"cutoff_hz":{"min":10,"max":100}}"#,
            "k_width",
            "params.cutoff_hz",
        ),
        (r#"{}"#, "k_width", "params"),
        (r#"{"q":{"min":1,"max":10}}"#, "", "--objective"),
        (
            r#"{"q":{"min":1,"max":10}}"#,
            r#"{"weighted":{}}"#,
            "objective.weighted",
        ),
        (
            r#"{"q":{"min":1,"max":10}}"#,
            r#"{"pareto":[]}"#,
            "objective.pareto",
        ),
        (r#"{"q":{"min":1,"max":10}}"#, "fastest", "--objective"),
        ("not json", "k_width", "--params"),
    ] {
        let (code, _, err) = zwidth(&[
            "tune",
            "--scene",
            sc,
            "--params",
            params,
            "--objective",
            objective,
        ]);
        assert_eq!(code, 2, "{params} {objective}: {err}");
        assert!(
            err.contains(needle),
            "{params} {objective}: {err} lacks {needle}"
        );
        assert!(!err.contains("panicked"));
    }
    // The finalists' replicate count: 1 to 20 (docs/tuning.md).
    for n in ["0", "21"] {
        let (code, _, err) = zwidth(&[
            "tune",
            "--scene",
            sc,
            "--params",
            r#"{"q":{"min":1,"max":10}}"#,
            "--objective",
            "k_width",
            "--replicates",
            n,
        ]);
        assert_eq!(code, 2, "--replicates {n}: {err}");
        assert!(
            err.contains(&format!("replicates = {n}")) && err.contains("1 to 20"),
            "{err}"
        );
    }
}
