//! Running a tune: the solvers ask for evaluations (each one Z-width map),
//! which come from the cache, from an interrupted earlier run (replayed,
//! counted toward the budget as the first time), or are computed; then the
//! finalists are re-evaluated at the final accuracy.

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use super::*;
use crate::error::SpecError;
use crate::estimators::EstimatorKind;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{map_observed, Observer};
use crate::zwidth::settings::Accuracy;

/// Why the solver was stopped (not an error of the tune).
#[derive(Debug, thiserror::Error)]
enum Stop {
    #[error("evaluation budget spent")]
    Budget,
    #[error("cancelled")]
    Cancelled,
    #[error("{0}")]
    Spec(SpecError),
}

/// The running state: log, cache, budget.
struct Run<'a> {
    tune: &'a Tune,
    observer: Option<Arc<Observer>>,
    log: Mutex<Vec<Evaluation>>,
    cache: Mutex<HashMap<String, Evaluation>>,
    /// Solver calls, cache hits included (a guard against a solver that
    /// keeps asking for cached points).
    calls: std::sync::atomic::AtomicUsize,
    failure: Mutex<Option<SpecError>>,
}

impl Run<'_> {
    fn key(&self, phase_acc: &Accuracy, params: &BTreeMap<String, f64>) -> String {
        let p: Vec<String> = params
            .iter()
            .map(|(n, x)| format!("{n}={:016x}", x.to_bits()))
            .collect();
        format!("{}|{}", accuracy_name(phase_acc), p.join(","))
    }

    fn score(&self, m: &Metrics, feasible_violation: f64) -> f64 {
        if feasible_violation > 0.0 {
            // Below every feasible score, ordered by how far off it is.
            return -1e15 - feasible_violation;
        }
        match &self.tune.spec.objective {
            Objective::Single(x) => m.signed(*x),
            Objective::Weighted(w) => w.iter().map(|(x, wt)| wt * m.signed(*x)).sum(),
            Objective::Pareto(list) => m.signed(list[0]),
        }
    }

    /// How far gains violate the constraint (0: met).
    fn violation(&self, scene: &SceneSpec) -> f64 {
        let (Some(cond), Some(c)) = (self.tune.spec.constraint, self.tune.lipschitz) else {
            return 0.0;
        };
        let EstimatorKind::Levant(l) = &scene.estimator.kind else {
            return 0.0;
        };
        let Ok(g) = l.gains() else { return 1.0 };
        let (a, lam) = (g.alpha, g.lambda);
        match cond {
            // 2018 paper eq. 10.
            GainCondition::Levant => {
                if a <= c {
                    1.0 + (c - a) / c
                } else {
                    ((4.0 * c * (a + c) / (a - c) - lam * lam) / (c * c).max(1e-300)).max(0.0)
                }
            }
            // 2018 paper eq. 14.
            GainCondition::Lyapunov => ((3.0 * c + 2.0 * c * c / (lam * lam) - a) / c).max(0.0),
        }
    }

    /// Search evaluations computed so far (not from the cache).
    fn computed(&self) -> usize {
        self.log
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .iter()
            .filter(|e| e.phase == "search" && !e.cached)
            .count()
    }

    /// Evaluate at these parameter values in `phase` ("search" / "final").
    fn evaluate(&self, params: BTreeMap<String, f64>, phase: &str) -> Result<Evaluation, Stop> {
        let spec = &self.tune.spec;
        let acc = if phase == "final" {
            &spec.final_accuracy
        } else {
            &spec.accuracy
        };
        let key = self.key(acc, &params);
        let index = self.log.lock().unwrap_or_else(|e| e.into_inner()).len();
        let calls = self
            .calls
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed)
            + 1;
        if calls > 20 * spec.max_evaluations + 100 {
            return Err(Stop::Budget);
        }
        let cached = self
            .cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&key)
            .cloned();
        // Stored by an earlier, interrupted run of this tune: the evaluation
        // as it was made then (computed, so it counts toward the budget, and
        // its trials count as done), so the resumed run takes the same path.
        let replayed = match (&cached, &self.observer) {
            (None, Some(o)) => o
                .stored_evaluation(&key)
                .and_then(|v| serde_json::from_value::<Evaluation>(v).ok())
                .filter(|e| !e.cached && e.phase == phase),
            _ => None,
        };
        let ev = if let Some(mut e) = cached {
            e.index = index;
            e.cached = true;
            e.phase = phase.into();
            e
        } else if let Some(mut e) = replayed {
            if phase == "search" && self.computed() >= spec.max_evaluations {
                return Err(Stop::Budget);
            }
            e.index = index;
            if let Some(o) = &self.observer {
                o.trials
                    .fetch_add(e.trials, std::sync::atomic::Ordering::Relaxed);
            }
            e
        } else {
            if self.observer.as_ref().is_some_and(|o| o.cancelled()) {
                return Err(Stop::Cancelled);
            }
            if phase == "search" && self.computed() >= spec.max_evaluations {
                return Err(Stop::Budget);
            }
            let start = Instant::now();
            let scene = self.tune.space.scene_at(&params).map_err(Stop::Spec)?;
            let violation = self.violation(&scene);
            let (metrics, trials) = if violation > 0.0 {
                // Infeasible gains: no map is run.
                (
                    Metrics {
                        k_width: 0.0,
                        b_width: 0.0,
                        max_fidelity_error: None,
                        area: 0.0,
                    },
                    0,
                )
            } else {
                let m = map_observed(
                    &spec.map_spec(scene, acc.clone()),
                    self.observer.clone(),
                    index as u32,
                )
                .map_err(Stop::Spec)?;
                if self.observer.as_ref().is_some_and(|o| o.cancelled()) {
                    return Err(Stop::Cancelled);
                }
                (
                    Metrics {
                        k_width: m.k_width,
                        b_width: m.b_width,
                        max_fidelity_error: m.max_fidelity_error,
                        area: m.area,
                    },
                    m.trials,
                )
            };
            let mut objectives: BTreeMap<String, Option<f64>> = BTreeMap::new();
            for m in [
                Metric::KWidth,
                Metric::BWidth,
                Metric::MaxFidelityError,
                Metric::Area,
            ] {
                objectives.insert(metric_name(m).into(), metrics.get(m));
            }
            let e = Evaluation {
                index,
                phase: phase.into(),
                params,
                objectives,
                metrics,
                score: self.score(&metrics, violation),
                feasible: violation == 0.0,
                cached: false,
                trials,
                elapsed_s: start.elapsed().as_secs_f64(),
            };
            if let Some(o) = &self.observer {
                o.record_evaluation(key.clone(), serde_json::to_value(&e).unwrap_or_default());
            }
            e
        };
        self.cache
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .insert(key, ev.clone());
        if let (Some(o), false) = (&self.observer, ev.cached) {
            // Progress counts computed evaluations (cache hits are free).
            o.report(index as u32, 1.0);
        }
        let mut log = self.log.lock().unwrap_or_else(|e| e.into_inner());
        log.push(ev.clone());
        if let Some(o) = &self.observer {
            if let Some(b) = log
                .iter()
                .filter(|e| e.phase == phase)
                .max_by(|a, b| a.score.total_cmp(&b.score))
            {
                o.set_best(serde_json::json!({"params": b.params, "score": b.score, "objectives": b.objectives, "phase": b.phase}));
            }
        }
        Ok(ev)
    }
}

impl solvers::Cost for Run<'_> {
    fn cost(&self, u: &[f64]) -> Result<f64, argmin::core::Error> {
        match self.evaluate(self.tune.space.values(u), "search") {
            Ok(e) => Ok(-e.score),
            Err(Stop::Spec(e)) => {
                *self.failure.lock().unwrap_or_else(|x| x.into_inner()) = Some(e.clone());
                Err(argmin::core::Error::msg(e.to_string()))
            }
            Err(s) => Err(argmin::core::Error::msg(s.to_string())),
        }
    }

    fn observer(&self) -> Option<Arc<Observer>> {
        self.observer.clone()
    }
}

impl Tune {
    pub fn spec(&self) -> &TuneSpec {
        &self.spec
    }

    /// Run the tune (blocking), reporting to and honouring cancellation from `observer`.
    pub fn run(&self, observer: Option<Arc<Observer>>) -> Result<TuneResult, SpecError> {
        let start = Instant::now();
        let spec = &self.spec;
        if let Some(o) = &observer {
            o.set_scopes(spec.max_evaluations + spec.finalists);
        }
        let run = Run {
            tune: self,
            observer,
            log: Mutex::new(Vec::new()),
            cache: Mutex::new(HashMap::new()),
            calls: Default::default(),
            failure: Mutex::new(None),
        };
        let n = self.space.dim();
        let budget = spec.max_evaluations;
        let pareto = matches!(spec.objective, Objective::Pareto(_));
        let solver = match (spec.solver, pareto) {
            (SolverKind::Auto, true) => SolverKind::Halton,
            (s, _) => s,
        };
        let iters = budget as u64 * 4 + 10;
        let cost = |u: &[f64]| solvers::Cost::cost(&run, u);
        match solver {
            SolverKind::Grid => {
                for u in solvers::grid(budget) {
                    if cost(&[u]).is_err() {
                        break;
                    }
                }
            }
            SolverKind::Halton => {
                for u in solvers::halton(budget, n, spec.seed) {
                    if cost(&u).is_err() {
                        break;
                    }
                }
            }
            SolverKind::Brent => solvers::brent(&run, 0.0, 1.0, tolerance(budget), iters),
            SolverKind::Golden => {
                solvers::golden(&run, tolerance(budget), iters).map_err(internal)?
            }
            SolverKind::NelderMead => {
                solvers::nelder_mead(&run, &vec![0.5; n], 0.25, iters).map_err(internal)?
            }
            SolverKind::ParticleSwarm => {
                let particles = (4 * n).clamp(6, 20).min(budget.max(1));
                solvers::particle_swarm(
                    &run,
                    n,
                    particles,
                    (budget / particles).max(1) as u64,
                    spec.seed,
                )
            }
            SolverKind::Auto if n == 1 => {
                // A coarse grid over a quarter of the budget; Brent inside
                // the best grid cell; then the rest of the budget on an even
                // grid over that cell (the objective need not be smooth or
                // unimodal: a Z-width measured with friction and
                // quantization is not).
                let g = (budget / 4).clamp(3, 25);
                let mut best = (f64::MAX, 0.5);
                let mut stopped = false;
                for u in solvers::grid(g) {
                    match cost(&[u]) {
                        Ok(c) if c < best.0 => best = (c, u),
                        Ok(_) => {}
                        Err(_) => {
                            stopped = true;
                            break;
                        }
                    }
                }
                let cell = 1.0 / (g - 1) as f64;
                let (lo, hi) = ((best.1 - cell).max(0.0), (best.1 + cell).min(1.0));
                if !stopped {
                    solvers::brent(&run, lo, hi, tolerance(budget), iters);
                }
                let left = budget.saturating_sub(run.computed());
                if !stopped && left > 0 && !run.observer.as_ref().is_some_and(|o| o.cancelled()) {
                    // Points on a lattice (`step`) repeat: those are cache hits.
                    for u in solvers::grid(4 * left + 1) {
                        if cost(&[lo + u * (hi - lo)]).is_err() {
                            break;
                        }
                    }
                }
            }
            SolverKind::Auto => {
                // The best of a small Halton design starts Nelder–Mead.
                let mut best = (f64::MAX, vec![0.5; n]);
                for u in solvers::halton((2 * n + 1).min(budget), n, spec.seed) {
                    match cost(&u) {
                        Ok(c) if c < best.0 => best = (c, u),
                        Ok(_) => {}
                        Err(_) => break,
                    }
                }
                solvers::nelder_mead(&run, &best.1, 0.15, iters).map_err(internal)?;
            }
        }
        if let Some(e) = run.failure.lock().unwrap_or_else(|x| x.into_inner()).take() {
            return Err(e);
        }
        let search_s = start.elapsed().as_secs_f64();
        let history = run.log.lock().unwrap_or_else(|e| e.into_inner()).clone();
        if history.is_empty() {
            return Err(SpecError::new(
                "tune",
                "(cancelled)",
                "stopped before any evaluation",
            ));
        }
        // Distinct parameter sets, best first.
        let mut ranked: Vec<&Evaluation> = Vec::new();
        let mut by_score: Vec<&Evaluation> = history.iter().collect();
        by_score.sort_by(|a, b| b.score.total_cmp(&a.score).then(a.index.cmp(&b.index)));
        for e in by_score {
            if !ranked.iter().any(|r| r.params == e.params) {
                ranked.push(e);
            }
        }
        let front = pareto.then(|| pareto_front(&history, &self.metrics));
        // Finalists: the best few (Pareto: front members by the first metric).
        let candidates: Vec<&Evaluation> = match &front {
            Some(f) => ranked
                .iter()
                .copied()
                .filter(|e| f.contains(&e.index))
                .collect(),
            None => ranked.clone(),
        };
        let picked: Vec<&Evaluation> = candidates
            .into_iter()
            .filter(|e| e.feasible)
            .take(spec.finalists)
            .collect();
        let mut finals = Vec::new();
        let t_final = Instant::now();
        for e in &picked {
            match run.evaluate(e.params.clone(), "final") {
                Ok(f) => finals.push(f),
                Err(Stop::Spec(err)) => return Err(err),
                Err(_) => break,
            }
        }
        let final_s = t_final.elapsed().as_secs_f64();
        let computed = history.iter().filter(|e| !e.cached).count()
            + finals.iter().filter(|e| !e.cached).count();
        let cache_hits = history.iter().filter(|e| e.cached).count()
            + finals.iter().filter(|e| e.cached).count();
        let coarse_to_fine = (!finals.is_empty()).then(|| {
            let mut order: Vec<usize> = (0..finals.len()).collect();
            order.sort_by(|&a, &b| finals[b].score.total_cmp(&finals[a].score).then(a.cmp(&b)));
            let mut final_rank = vec![0; finals.len()];
            for (r, &i) in order.iter().enumerate() {
                final_rank[i] = r;
            }
            let mean = |v: &[&Evaluation]| {
                let c: Vec<f64> = v
                    .iter()
                    .filter(|e| !e.cached)
                    .map(|e| e.elapsed_s)
                    .collect();
                if c.is_empty() {
                    0.0
                } else {
                    c.iter().sum::<f64>() / c.len() as f64
                }
            };
            let mean_search = mean(&history.iter().collect::<Vec<_>>());
            let mean_final = mean(&finals.iter().collect::<Vec<_>>());
            let n_search = history.iter().filter(|e| !e.cached).count() as f64;
            CoarseToFine {
                search_accuracy: accuracy_name(&spec.accuracy),
                final_accuracy: accuracy_name(&spec.final_accuracy),
                finalists: finals
                    .iter()
                    .zip(&picked)
                    .enumerate()
                    .map(|(i, (f, s))| Finalist {
                        params: f.params.clone(),
                        search_score: s.score,
                        final_score: f.score,
                        search_rank: i,
                        final_rank: final_rank[i],
                    })
                    .collect(),
                ranking_held: ranking_held(
                    &picked.iter().map(|e| e.score).collect::<Vec<_>>(),
                    &finals.iter().map(|e| e.score).collect::<Vec<_>>(),
                ),
                best_held: final_rank[0] == 0,
                search_s,
                final_s,
                mean_search_evaluation_s: mean_search,
                mean_final_evaluation_s: mean_final,
                saved_s: (spec.accuracy != spec.final_accuracy)
                    .then_some(n_search * mean_final - (search_s + final_s)),
            }
        });
        let best_eval = finals
            .iter()
            .max_by(|a, b| a.score.total_cmp(&b.score).then(b.index.cmp(&a.index)))
            .or_else(|| ranked.first().copied())
            .cloned()
            .ok_or_else(|| SpecError::new("tune", "(empty)", "no evaluation"))?;
        let scene = self.space.scene_at(&best_eval.params)?;
        let gains = match &scene.estimator.kind {
            EstimatorKind::Levant(l) => l.gains().ok().map(|g| g.report().to_string()),
            _ => None,
        };
        let mut history = history;
        history.extend(finals);
        Ok(TuneResult {
            best: Best {
                objectives: best_eval.objectives.clone(),
                params: best_eval.params.clone(),
                score: best_eval.score,
                phase: best_eval.phase.clone(),
                scene,
                gains,
            },
            evaluations: computed,
            cache_hits,
            solver,
            objective: spec.objective.clone(),
            history,
            pareto_front: front,
            coarse_to_fine,
            elapsed_s: start.elapsed().as_secs_f64(),
        })
    }
}

/// Tolerance in u for the 1-D solvers: finer with a bigger budget.
fn tolerance(budget: usize) -> f64 {
    (1.0 / (budget as f64 * 8.0)).clamp(1e-5, 1e-2)
}

fn internal(e: argmin::core::Error) -> SpecError {
    SpecError::new("solver", "(setup)", e.to_string())
}

/// Indices of the feasible search evaluations no other one dominates
/// (at least as good in every metric, better in one).
fn pareto_front(history: &[Evaluation], metrics: &[Metric]) -> Vec<usize> {
    let pts: Vec<(usize, Vec<f64>)> = history
        .iter()
        .filter(|e| e.phase == "search" && e.feasible)
        .map(|e| {
            (
                e.index,
                metrics.iter().map(|&m| e.metrics.signed(m)).collect(),
            )
        })
        .collect();
    let dominates = |a: &[f64], b: &[f64]| {
        a.iter().zip(b).all(|(x, y)| x >= y) && a.iter().zip(b).any(|(x, y)| x > y)
    };
    let mut front: Vec<usize> = Vec::new();
    for (i, p) in &pts {
        let dominated = pts.iter().any(|(_, q)| dominates(q, p));
        let duplicate = front
            .iter()
            .any(|f| pts.iter().any(|(j, q)| j == f && q == p));
        if !dominated && !duplicate {
            front.push(*i);
        }
    }
    front
}

/// Whether the final accuracy keeps the order the search gave its
/// finalists (`search` best first): wherever the search ordered two of them
/// strictly, the final scores agree; finalists tied at the search's
/// resolution (common: a bisection's K values fall on a lattice) order
/// nothing.
fn ranking_held(search: &[f64], finals: &[f64]) -> bool {
    let n = search.len().min(finals.len());
    (0..n).all(|i| (i + 1..n).all(|j| search[i] <= search[j] || finals[i] >= finals[j]))
}

#[cfg(test)]
mod ranking_tests {
    use super::ranking_held;

    #[test]
    fn ties_at_the_search_order_nothing() {
        // docs/tuning.md's seed tune: 499 Hz first; 480 and 487 Hz tied at
        // draft (428 613.12) and swapped at reference: the ranking held.
        assert!(ranking_held(
            &[440_519.04, 428_613.12, 428_613.12],
            &[442_751.4, 418_195.44, 428_613.12]
        ));
        // A strict order reversed does not hold, wherever it is.
        assert!(!ranking_held(&[3.0, 2.0, 1.0], &[3.0, 1.0, 2.0]));
        assert!(!ranking_held(&[3.0, 2.0, 2.0], &[1.0, 2.0, 2.0]));
        assert!(ranking_held(&[3.0, 2.0, 1.0], &[3.0, 2.0, 2.0]));
        assert!(ranking_held(&[1.0], &[5.0]));
    }
}
