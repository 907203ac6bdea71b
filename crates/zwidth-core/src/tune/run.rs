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
use crate::zwidth::bla::replicate_seed;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{map_observed, Observer};
use crate::zwidth::settings::Accuracy;
use crate::zwidth::stats::student_t_quantile;

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

/// The score of gains that violate the constraint by `violation` (> 0):
/// below every feasible score (K-widths are at most 1e12 N/m), and lower
/// the farther off they are, so the solver is led back towards feasibility.
fn infeasible_score(violation: f64) -> f64 {
    -1e15 - violation
}

impl<'a> Run<'a> {
    /// A run of `tune` with nothing evaluated yet.
    fn new(tune: &'a Tune, observer: Option<Arc<Observer>>) -> Self {
        Run {
            tune,
            observer,
            log: Mutex::new(Vec::new()),
            cache: Mutex::new(HashMap::new()),
            calls: Default::default(),
            failure: Mutex::new(None),
        }
    }

    /// The cache and store key of an evaluation (replicate 0 keeps the key
    /// tunes stored before replicates existed).
    fn key(
        &self,
        phase_acc: &Accuracy,
        params: &BTreeMap<String, f64>,
        replicate: usize,
    ) -> String {
        let p: Vec<String> = params
            .iter()
            .map(|(n, x)| format!("{n}={:016x}", x.to_bits()))
            .collect();
        let r = if replicate > 0 {
            format!("|r{replicate}")
        } else {
            String::new()
        };
        format!("{}|{}{r}", accuracy_name(phase_acc), p.join(","))
    }

    /// The score's interval when the objective is one metric with one
    /// (K-width or B-width on a noisy scene) and the interval's upper end is
    /// a verdict, not the map's range (`k_max`, `b_max`: nothing up to it
    /// was decided not passive).
    fn score_interval(&self, m: &Metrics) -> Option<[f64; 2]> {
        let (iv, cap) = match &self.tune.spec.objective {
            Objective::Single(Metric::KWidth) => (m.k_width_interval, self.tune.spec.k_max),
            Objective::Single(Metric::BWidth) => (m.b_width_interval, self.tune.spec.b_max),
            _ => return None,
        };
        iv.filter(|[_, hi]| *hi < cap)
    }

    fn score(&self, m: &Metrics, feasible_violation: f64) -> f64 {
        if feasible_violation > 0.0 {
            return infeasible_score(feasible_violation);
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

    /// Evaluate at these parameter values in `phase` ("search" / "final"),
    /// `replicate` naming the probe seed (0: the scene's; `bla::replicate_seed`).
    fn evaluate(
        &self,
        params: BTreeMap<String, f64>,
        phase: &str,
        replicate: usize,
    ) -> Result<Evaluation, Stop> {
        let spec = &self.tune.spec;
        let acc = if phase == "final" {
            &spec.final_accuracy
        } else {
            &spec.accuracy
        };
        let key = self.key(acc, &params, replicate);
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
            let mut scene = self.tune.space.scene_at(&params).map_err(Stop::Spec)?;
            scene.probe.seed = replicate_seed(scene.probe.seed, replicate);
            let violation = self.violation(&scene);
            let (metrics, trials) = if violation > 0.0 {
                // Infeasible gains: no map is run.
                (
                    Metrics {
                        k_width: 0.0,
                        b_width: 0.0,
                        max_fidelity_error: None,
                        area: 0.0,
                        k_width_interval: None,
                        b_width_interval: None,
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
                        k_width_interval: m.k_width_interval,
                        b_width_interval: m.b_width_interval,
                    },
                    m.trials,
                )
            };
            let objectives = objectives_of(&metrics);
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
                replicate,
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
        match self.evaluate(self.tune.space.values(u), "search", 0) {
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
            o.set_scopes(spec.max_evaluations + spec.finalists * self.per_finalist);
        }
        let run = Run::new(self, observer);
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
        let t_final = Instant::now();
        let replicates = run.finals(&picked)?;
        let finals: Vec<Pooled> = replicates.iter().map(|r| run.pool(r)).collect();
        let final_s = t_final.elapsed().as_secs_f64();
        let all_finals: Vec<&Evaluation> = replicates.iter().flatten().collect();
        let computed = history.iter().filter(|e| !e.cached).count()
            + all_finals.iter().filter(|e| !e.cached).count();
        let cache_hits = history.iter().filter(|e| e.cached).count()
            + all_finals.iter().filter(|e| e.cached).count();
        let coarse_to_fine = (!finals.is_empty()).then(|| {
            let mut order: Vec<usize> = (0..finals.len()).collect();
            order.sort_by(|&a, &b| {
                finals[b]
                    .eval
                    .score
                    .total_cmp(&finals[a].eval.score)
                    .then(a.cmp(&b))
            });
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
            let mean_final = mean(&all_finals);
            let n_search = history.iter().filter(|e| !e.cached).count() as f64;
            CoarseToFine {
                search_accuracy: accuracy_name(&spec.accuracy),
                final_accuracy: accuracy_name(&spec.final_accuracy),
                finalists: finals
                    .iter()
                    .zip(&picked)
                    .enumerate()
                    .map(|(i, (f, s))| Finalist {
                        params: f.eval.params.clone(),
                        search_score: s.score,
                        final_score: f.eval.score,
                        search_rank: i,
                        final_rank: final_rank[i],
                        replicates: f.replicates,
                        final_interval: f.interval,
                    })
                    .collect(),
                ranking_held: ranking_held(
                    &picked.iter().map(|e| e.score).collect::<Vec<_>>(),
                    &finals.iter().map(|f| f.eval.score).collect::<Vec<_>>(),
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
        let best_final = finals.iter().max_by(|a, b| {
            a.eval
                .score
                .total_cmp(&b.eval.score)
                .then(b.eval.index.cmp(&a.eval.index))
        });
        let (best_eval, best_replicates, best_interval) = match best_final {
            Some(f) => (f.eval.clone(), f.replicates, f.interval),
            None => {
                let e = ranked
                    .first()
                    .copied()
                    .cloned()
                    .ok_or_else(|| SpecError::new("tune", "(empty)", "no evaluation"))?;
                let iv = run.score_interval(&e.metrics);
                (e, 1, iv)
            }
        };
        let scene = self.space.scene_at(&best_eval.params)?;
        let gains = match &scene.estimator.kind {
            EstimatorKind::Levant(l) => l.gains().ok().map(|g| g.report().to_string()),
            _ => None,
        };
        let mut history = history;
        history.extend(all_finals.into_iter().cloned());
        Ok(TuneResult {
            best: Best {
                objectives: best_eval.objectives.clone(),
                params: best_eval.params.clone(),
                score: best_eval.score,
                phase: best_eval.phase.clone(),
                replicates: best_replicates,
                interval: best_interval,
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

/// A finalist's maps at the final accuracy, pooled: the mean of each
/// measure and of the score, with the score's interval.
struct Pooled {
    eval: Evaluation,
    replicates: usize,
    interval: Option<[f64; 2]>,
}

impl Run<'_> {
    /// Evaluate each finalist at the final accuracy. On a noisy scene with
    /// an objective that has an interval, map each `replicates` times (the
    /// scene's probe seed, then derived ones), then add replicates — up to
    /// twice that — to the finalists whose interval still overlaps the
    /// best's, until the ranking is decided. Stops early (with what it has)
    /// on cancellation; a spec error is returned.
    fn finals(&self, picked: &[&Evaluation]) -> Result<Vec<Vec<Evaluation>>, SpecError> {
        let spec = &self.tune.spec;
        let mut out: Vec<Vec<Evaluation>> = Vec::new();
        for e in picked {
            match self.evaluate(e.params.clone(), "final", 0) {
                Ok(f) => out.push(vec![f]),
                Err(Stop::Spec(err)) => return Err(err),
                Err(_) => return Ok(out),
            }
        }
        let replicable = !out.is_empty()
            && spec.replicates > 1
            && out
                .iter()
                .all(|r| self.score_interval(&r[0].metrics).is_some());
        if !replicable {
            return Ok(out);
        }
        loop {
            let pooled: Vec<Pooled> = out.iter().map(|r| self.pool(r)).collect();
            let want = more_replicates(&pooled, spec.replicates);
            if want.is_empty() {
                return Ok(out);
            }
            for i in want {
                let params = out[i][0].params.clone();
                match self.evaluate(params, "final", out[i].len()) {
                    Ok(f) => out[i].push(f),
                    Err(Stop::Spec(err)) => return Err(err),
                    Err(_) => return Ok(out),
                }
            }
        }
    }

    /// One finalist's replicates as one evaluation (see [`Pooled`]).
    fn pool(&self, reps: &[Evaluation]) -> Pooled {
        let n = reps.len();
        let mean = |f: &dyn Fn(&Evaluation) -> f64| reps.iter().map(f).sum::<f64>() / n as f64;
        let fidelity: Option<Vec<f64>> =
            reps.iter().map(|e| e.metrics.max_fidelity_error).collect();
        let metrics = Metrics {
            k_width: mean(&|e| e.metrics.k_width),
            b_width: mean(&|e| e.metrics.b_width),
            max_fidelity_error: fidelity.map(|v| v.iter().sum::<f64>() / n as f64),
            area: mean(&|e| e.metrics.area),
            // The pooled score's interval is `Pooled::interval`; the maps'
            // own stay with each replicate in the history.
            k_width_interval: None,
            b_width_interval: None,
        };
        let scores: Vec<f64> = reps.iter().map(|e| e.score).collect();
        let score = scores.iter().sum::<f64>() / n as f64;
        // One map: its own interval. More: the replicates' t interval of
        // the mean, never narrower than their mean interval (replicates on
        // one K lattice can agree exactly).
        let own: Option<Vec<[f64; 2]>> = reps
            .iter()
            .map(|e| self.score_interval(&e.metrics))
            .collect();
        let interval = own.map(|v| pooled_interval(&scores, &v));
        let objectives = objectives_of(&metrics);
        Pooled {
            eval: Evaluation {
                index: reps[0].index,
                phase: "final".into(),
                params: reps[0].params.clone(),
                objectives,
                metrics,
                score,
                feasible: reps.iter().all(|e| e.feasible),
                cached: reps.iter().all(|e| e.cached),
                trials: reps.iter().map(|e| e.trials).sum(),
                elapsed_s: reps.iter().map(|e| e.elapsed_s).sum(),
                replicate: 0,
            },
            replicates: n,
            interval,
        }
    }
}

/// Which finalists need another replicate: every one below `replicates`;
/// then, up to twice that, each whose interval overlaps the best's (the
/// best too, while any does). Empty: the ranking is decided.
/// The interval of the mean of replicate scores: the replicates' Student
/// t interval of the mean (95 % two-sided, n − 1 degrees of freedom:
/// mean ± t(0.975, n − 1)·s/√n), never narrower than the mean of their
/// own intervals `own` (replicates on one K lattice can agree exactly);
/// one replicate: its own interval.
fn pooled_interval(scores: &[f64], own: &[[f64; 2]]) -> [f64; 2] {
    let n = scores.len();
    let lo = own.iter().map(|x| x[0]).sum::<f64>() / n as f64;
    let hi = own.iter().map(|x| x[1]).sum::<f64>() / n as f64;
    if n < 2 {
        return [lo, hi];
    }
    let score = scores.iter().sum::<f64>() / n as f64;
    let var = scores.iter().map(|s| (s - score).powi(2)).sum::<f64>() / (n - 1) as f64;
    let half = student_t_quantile(0.975, (n - 1) as f64) * (var / n as f64).sqrt();
    [lo.min(score - half), hi.max(score + half)]
}

fn more_replicates(pooled: &[Pooled], replicates: usize) -> Vec<usize> {
    let below: Vec<usize> = (0..pooled.len())
        .filter(|&i| pooled[i].replicates < replicates)
        .collect();
    if !below.is_empty() {
        return below;
    }
    let Some(best) = (0..pooled.len()).max_by(|&a, &b| {
        pooled[a]
            .eval
            .score
            .total_cmp(&pooled[b].eval.score)
            .then(b.cmp(&a))
    }) else {
        return Vec::new();
    };
    let overlaps = |i: usize| match (pooled[i].interval, pooled[best].interval) {
        (Some([lo, hi]), Some([blo, bhi])) => i != best && lo <= bhi && blo <= hi,
        _ => false,
    };
    let rivals: Vec<usize> = (0..pooled.len()).filter(|&i| overlaps(i)).collect();
    if rivals.is_empty() {
        return Vec::new();
    }
    std::iter::once(best)
        .chain(rivals)
        .filter(|&i| pooled[i].replicates < 2 * replicates)
        .collect()
}

/// Every measure of a map by its name (an evaluation's `objectives`).
fn objectives_of(metrics: &Metrics) -> BTreeMap<String, Option<f64>> {
    [
        Metric::KWidth,
        Metric::BWidth,
        Metric::MaxFidelityError,
        Metric::Area,
    ]
    .into_iter()
    .map(|m| (metric_name(m).into(), metrics.get(m)))
    .collect()
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
pub(crate) fn pareto_front(history: &[Evaluation], metrics: &[Metric]) -> Vec<usize> {
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
mod replicate_tests;

#[cfg(test)]
mod ranking_tests;

#[cfg(test)]
mod search_path_tests;

#[cfg(test)]
mod interval_tests;
