//! The path the `auto` solvers take through the parameter space, the budget
//! they spend, and a resumed tune replaying its stored evaluations: pinned
//! evaluation by evaluation on a linear scene (analytic engine, so every
//! map is deterministic and cheap).

use super::*;
use crate::zwidth::observer::StoredEvaluation;

/// A K-width tune of the linear 1 kHz scene's Butterworth filter over
/// `params`, `budget` search evaluations, `solver`.
fn linear_tune(params: serde_json::Value, budget: usize, solver: &str) -> Tune {
    let spec: TuneSpec = serde_json::from_value(serde_json::json!({
        "scene": {"device": {"coulomb": 0, "quantization": 0},
                  "loop": {"sample_hz": 1000, "render_hz": 1000},
                  "estimator": {"kind": "butterworth", "cutoff_hz": 200, "order": 2}},
        "params": params,
        "objective": "k_width",
        "accuracy": "draft",
        "final_accuracy": "draft",
        "finalists": 1,
        "solver": solver,
        "max_evaluations": budget,
        "b": [0, 20]
    }))
    .unwrap();
    spec.validate().unwrap()
}

fn search(r: &TuneResult) -> Vec<&Evaluation> {
    r.history.iter().filter(|e| e.phase == "search").collect()
}

/// The first evaluation with the highest score (the solvers keep the first
/// of equals: `c < best.0` on the cost −score).
fn first_best<'a>(evals: &[&'a Evaluation]) -> &'a Evaluation {
    evals
        .iter()
        .fold(None::<&Evaluation>, |b, e| match b {
            Some(b) if b.score >= e.score => Some(b),
            _ => Some(e),
        })
        .unwrap()
}

#[test]
fn one_parameter_auto_grids_a_quarter_of_the_budget_then_runs_brent_in_the_best_cell() {
    // Budget 12: a grid of 12/4 = 3 points (u = 0, ½, 1: 50, 250, 450 Hz);
    // then Brent (1973, ch. 5) on the best point's cell [u* − ½, u* + ½] ∩
    // [0, 1], whose first point is the golden-section point
    // a + (3 − √5)/2 · (b − a); every later point lies in the cell. Points
    // round to the 10 Hz lattice (min + round((v − min)/step)·step), so
    // some repeat: those are free cache hits, and the computed ones are
    // exactly the budget.
    let tune = linear_tune(
        serde_json::json!({"cutoff_hz": {"min": 50, "max": 450, "step": 10}}),
        12,
        "auto",
    );
    let r = tune.run(None).unwrap();
    let s = search(&r);
    let hz = |e: &&Evaluation| e.params["cutoff_hz"];
    assert_eq!(
        s[..3].iter().map(hz).collect::<Vec<_>>(),
        [50.0, 250.0, 450.0]
    );
    assert!(s[..3].iter().all(|e| !e.cached));
    let best = (hz(&first_best(&s[..3])) - 50.0) / 400.0;
    let (lo, hi) = ((best - 0.5).max(0.0), (best + 0.5).min(1.0));
    let golden = lo + (3.0 - 5f64.sqrt()) / 2.0 * (hi - lo);
    let on_lattice = |u: f64| 50.0 + ((u * 400.0) / 10.0).round() * 10.0;
    assert_eq!(hz(&s[3]), on_lattice(golden), "Brent's first point");
    assert!(!s[3].cached);
    for e in &s[3..] {
        let u = (hz(e) - 50.0) / 400.0;
        assert!(
            (lo - 1e-12..=hi + 1e-12).contains(&u),
            "{} Hz outside the cell [{lo}, {hi}]",
            hz(e)
        );
    }
    let computed = s.iter().filter(|e| !e.cached).count();
    let hits = s.len() - computed;
    assert_eq!(computed, 12, "the budget counts computed evaluations only");
    assert!(hits > 0, "the lattice makes some points repeat");
    // The finalist is mapped at the search's accuracy: a cache hit too.
    assert_eq!(r.evaluations, 12);
    // Its plot: the objective against the cutoff, one point (with a
    // tooltip) per evaluation in the history, the best ringed.
    let svg = r.svg().unwrap();
    assert!(svg.starts_with("<svg") && svg.contains("against cutoff_hz"));
    let marks = svg.matches("class=\"pt\"").count();
    assert_eq!(
        marks,
        r.history.len() + 1,
        "every evaluation and the best ring"
    );
    assert!(svg.contains("best: #"));
}

#[test]
fn auto_on_two_parameters_starts_nelder_mead_at_the_best_of_its_halton_design() {
    // n = 2: a Halton design of 2n + 1 = 5 points, then Nelder–Mead (1965)
    // from the best of them, whose first vertex is that point itself (a
    // cache hit, same parameters).
    let tune = linear_tune(
        serde_json::json!({"cutoff_hz": {"min": 50, "max": 450},
                           "order": {"min": 1, "max": 4}}),
        9,
        "auto",
    );
    let r = tune.run(None).unwrap();
    let s = search(&r);
    assert!(s.len() > 5, "{} search evaluations", s.len());
    let best = first_best(&s[..5]);
    assert!(
        s[..5].iter().any(|e| e.score < best.score),
        "the design's points differ in score, so the start matters"
    );
    assert_eq!(s[5].params, best.params, "Nelder–Mead's first vertex");
    assert!(s[5].cached);
}

#[test]
fn a_resumed_tune_replays_its_stored_evaluations_and_takes_the_same_path() {
    // An interrupted run stored its first 7 evaluations; the resumed run
    // must replay them (not recompute: only the rest is stored anew),
    // count them toward the budget, count their trials, and end where the
    // uninterrupted run ended.
    let tune = linear_tune(
        serde_json::json!({"cutoff_hz": {"min": 50, "max": 450, "step": 10}}),
        12,
        "auto",
    );
    let whole = Arc::new(Observer::default());
    let full = tune.run(Some(whole.clone())).unwrap();
    let stored = whole.take_new_evaluations();
    assert_eq!(stored.len(), full.evaluations, "every computed map stored");
    let again = Arc::new(Observer::default().with_evaluations(stored[..7].to_vec()));
    let resumed = tune.run(Some(again.clone())).unwrap();
    let path = |r: &TuneResult| {
        r.history
            .iter()
            .map(|e| (e.phase.clone(), e.params.clone(), e.score, e.cached))
            .collect::<Vec<_>>()
    };
    assert_eq!(path(&resumed), path(&full));
    // What a running tune shows as its best: at the end, the finalist.
    let shown = whole.best().expect("a best is shown");
    assert_eq!(
        shown["params"],
        serde_json::to_value(&full.best.params).unwrap()
    );
    assert_eq!(shown["phase"], "final");
    assert_eq!(resumed.best.params, full.best.params);
    let keys = |v: &[StoredEvaluation]| v.iter().map(|e| e.key.clone()).collect::<Vec<_>>();
    assert_eq!(keys(&again.take_new_evaluations()), keys(&stored[7..]));
    let trials = |o: &Observer| o.trials.load(std::sync::atomic::Ordering::Relaxed);
    assert_eq!(trials(&again), trials(&whole));
}

#[test]
fn cache_hits_do_not_end_a_search_before_its_grid_is_walked() {
    // Budget 60 over a 20 Hz lattice (21 values): the coarse grid takes 15
    // (60/4), Brent a few in the best cell (±1/14: 3 lattice values), and
    // the rest of the budget is an even grid of 4·left + 1 points over the
    // cell, all of them cache hits by then. The runaway guard counts calls
    // (20 per evaluation of budget, + 100): it must let that grid finish,
    // ending on the cell's top.
    let tune = linear_tune(
        serde_json::json!({"cutoff_hz": {"min": 50, "max": 450, "step": 20}}),
        60,
        "auto",
    );
    let r = tune.run(None).unwrap();
    let s = search(&r);
    let hz = |e: &Evaluation| e.params["cutoff_hz"];
    let on_lattice = |u: f64| 50.0 + ((u * 400.0) / 20.0).round() * 20.0;
    let grid: Vec<f64> = s[..15].iter().map(|e| hz(e)).collect();
    let want: Vec<f64> = (0..15).map(|i| on_lattice(i as f64 / 14.0)).collect();
    assert_eq!(grid, want, "a grid of 60/4 = 15 points");
    let best = (hz(first_best(&s[..15])) - 50.0) / 400.0;
    let hi = (best + 1.0 / 14.0).min(1.0);
    assert_eq!(hz(s.last().unwrap()), on_lattice(hi), "grid {grid:?}");
    assert!(
        s.len() > 60 + 120,
        "{} calls: more than 20 + 60 + 100",
        s.len()
    );
}

#[test]
fn the_one_dimensional_tolerance_is_an_eighth_of_a_step_per_map() {
    // 1/(8·budget) in u, within [1e-5, 1e-2] (run.rs).
    assert_eq!(tolerance(60), 1.0 / 480.0);
    assert_eq!(tolerance(200), 6.25e-4);
    assert_eq!(tolerance(12), 1e-2);
    assert_eq!(tolerance(20_000), 1e-5);
}
