//! Tuning an estimator's parameters for K-width, B-width, fidelity or area.
//!
//! A tune searches at a cheap accuracy (`accuracy`, default `draft`), then
//! re-evaluates its best few (`finalists`) at `final_accuracy` (default
//! `reference`) and reports whether the ranking held and what the coarse
//! search saved. Every evaluation is one Z-width map; identical evaluations
//! (same accuracy, same parameter values to the bit) come from a cache that
//! a resumed run preloads from the store.

pub mod params;
pub mod solvers;
pub mod study;

use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use crate::error::SpecError;
use crate::estimators::EstimatorKind;
use crate::zwidth::cost::Cost;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{map_observed, Observer};
use crate::zwidth::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
pub use params::{Bounds, Space};

/// What a tune optimizes.
#[derive(
    Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize, utoipa::ToSchema,
)]
#[serde(rename_all = "snake_case")]
pub enum Metric {
    /// Maximize the largest K that renders (N/m).
    KWidth,
    /// Maximize the largest B that renders (N·s/m).
    BWidth,
    /// Minimize the largest fidelity error over the passive points (N·s/m).
    MaxFidelityError,
    /// Maximize the area that renders, ∫K_max dB.
    Area,
}

/// `"k_width"`, `{"weighted":{"k_width":1e-5,"b_width":1e-2}}` or
/// `{"pareto":["k_width","max_fidelity_error"]}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Objective {
    /// Maximize Σ wᵢ·sᵢ·mᵢ, sᵢ = +1 for widths and area, −1 for the fidelity error.
    Weighted(BTreeMap<Metric, f64>),
    /// The non-dominated set over these metrics.
    Pareto(Vec<Metric>),
    #[serde(untagged)]
    Single(Metric),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum SolverKind {
    /// One parameter: a coarse grid, then Brent in the best cell. More:
    /// Nelder–Mead from the best of a small Halton design. Pareto: Halton.
    #[default]
    Auto,
    Brent,
    Golden,
    NelderMead,
    ParticleSwarm,
    /// Brute force: `max_evaluations` evenly spaced points (one parameter).
    Grid,
    /// A seeded Halton design of `max_evaluations` points.
    Halton,
}

/// A condition Levant gains must meet (2018 paper eqs. 10 and 14).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GainCondition {
    /// Levant 1998: α > C and λ² ≥ 4C(α+C)/(α−C).
    Levant,
    /// Moreno–Osorio 2008 (Lyapunov): α > 3C + 2C²/λ².
    Lyapunov,
}

/// A tune request: the one spec the CLI, the API and the store share.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct TuneSpec {
    /// The scene; its estimator gives the kind and the parameters not tuned.
    pub scene: SceneSpec,
    /// The parameters to tune, with bounds and scale.
    pub params: BTreeMap<String, Bounds>,
    pub objective: Objective,
    #[serde(default)]
    pub method: Method,
    #[serde(default)]
    pub criterion: Criterion,
    /// How each map searches (default robust_bisect: a lucky pass high up
    /// must not count as width, or the tune chases noise).
    #[serde(default = "robust")]
    pub search: SearchKind,
    /// Accuracy while searching (default draft).
    #[serde(default = "draft")]
    pub accuracy: Accuracy,
    /// Accuracy the finalists are re-evaluated at (default reference).
    #[serde(default = "reference")]
    pub final_accuracy: Accuracy,
    /// How many of the best are re-evaluated at `final_accuracy` (0: none).
    #[serde(default = "d_finalists")]
    pub finalists: usize,
    #[serde(default)]
    pub solver: SolverKind,
    /// Seeds the particle swarm and the Halton design: same seed, same result.
    #[serde(default)]
    pub seed: u64,
    /// Evaluations the search may make (cache hits are free).
    #[serde(default = "d_max_evaluations")]
    pub max_evaluations: usize,
    /// Levant only: gains must meet this condition.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub constraint: Option<GainCondition>,
    /// Restrict each map to these damping values (N·s/m); faster.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b: Option<Vec<f64>>,
    #[serde(default = "d_b_max")]
    pub b_max: f64,
    #[serde(default = "d_k_max")]
    pub k_max: f64,
}

fn robust() -> SearchKind {
    SearchKind::RobustBisect
}
fn draft() -> Accuracy {
    Accuracy::Preset(Preset::Draft)
}
fn reference() -> Accuracy {
    Accuracy::Preset(Preset::Reference)
}
fn d_finalists() -> usize {
    3
}
fn d_max_evaluations() -> usize {
    40
}
fn d_b_max() -> f64 {
    1000.0
}
fn d_k_max() -> f64 {
    1e7
}

/// Largest |weight| of a weighted objective.
pub const WEIGHT_MAX: f64 = 1e6;

/// Most evaluations one tune may make.
pub const MAX_EVALUATIONS: usize = 5000;

/// The four measures of one map.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Metrics {
    pub k_width: f64,
    pub b_width: f64,
    pub max_fidelity_error: Option<f64>,
    pub area: f64,
}

/// A fidelity error standing in for "no passive point" (N·s/m), so such a
/// point ranks below any real one without NaN or infinity.
pub const NO_FIDELITY: f64 = 1e12;

impl Metrics {
    /// The value to maximize for one metric.
    fn signed(&self, m: Metric) -> f64 {
        match m {
            Metric::KWidth => self.k_width,
            Metric::BWidth => self.b_width,
            Metric::Area => self.area,
            Metric::MaxFidelityError => -self.max_fidelity_error.unwrap_or(NO_FIDELITY),
        }
    }

    fn get(&self, m: Metric) -> Option<f64> {
        match m {
            Metric::KWidth => Some(self.k_width),
            Metric::BWidth => Some(self.b_width),
            Metric::Area => Some(self.area),
            Metric::MaxFidelityError => self.max_fidelity_error,
        }
    }
}

/// One evaluation: parameters, the map's measures, the scalar score
/// (higher is better), and what it cost.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Evaluation {
    /// Order made in this run (cache hits included).
    pub index: usize,
    /// "search" or "final".
    pub phase: String,
    pub params: BTreeMap<String, f64>,
    /// The requested objective(s) by name, then every measure.
    pub objectives: BTreeMap<String, Option<f64>>,
    pub metrics: Metrics,
    /// The objective as one number to maximize (weighted sum; the first
    /// metric for Pareto); infeasible gains score below everything.
    pub score: f64,
    /// Whether the gains meet `constraint` (true without one).
    pub feasible: bool,
    /// Served from the cache (this run or a stored earlier one).
    pub cached: bool,
    pub trials: usize,
    pub elapsed_s: f64,
}

#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Finalist {
    pub params: BTreeMap<String, f64>,
    pub search_score: f64,
    pub final_score: f64,
    pub search_rank: usize,
    pub final_rank: usize,
}

/// What the coarse-to-fine split cost and saved.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CoarseToFine {
    pub search_accuracy: String,
    pub final_accuracy: String,
    pub finalists: Vec<Finalist>,
    /// The finalists keep their order at the final accuracy.
    pub ranking_held: bool,
    /// The search's best is still the best.
    pub best_held: bool,
    pub search_s: f64,
    pub final_s: f64,
    pub mean_search_evaluation_s: f64,
    pub mean_final_evaluation_s: f64,
    /// Time all search evaluations would have taken at the final accuracy,
    /// minus what the search and the finals took (s); null when both
    /// accuracies are the same (nothing to save).
    pub saved_s: Option<f64>,
}

#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Best {
    pub params: BTreeMap<String, f64>,
    pub objectives: BTreeMap<String, Option<f64>>,
    pub score: f64,
    /// "final" when it was re-evaluated at the final accuracy.
    pub phase: String,
    /// The scene with the best parameters, ready to map.
    pub scene: SceneSpec,
    /// Levant only: which gain conditions it meets, in words.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gains: Option<String>,
}

#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TuneResult {
    pub best: Best,
    /// Evaluations made (computed, not cached).
    pub evaluations: usize,
    pub cache_hits: usize,
    pub solver: SolverKind,
    pub objective: Objective,
    pub history: Vec<Evaluation>,
    /// Pareto: the non-dominated search evaluations (indices into history).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub pareto_front: Option<Vec<usize>>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub coarse_to_fine: Option<CoarseToFine>,
    pub elapsed_s: f64,
}

/// A validated tune.
pub struct Tune {
    spec: TuneSpec,
    space: Space,
    metrics: Vec<Metric>,
    lipschitz: Option<f64>,
    /// What every evaluation and finalist together may cost.
    pub cost: Cost,
}

impl TuneSpec {
    pub fn validate(&self) -> Result<Tune, SpecError> {
        self.scene.validate().map_err(|e| e.within("scene"))?;
        let space = Space::new(&self.scene, &self.params)?;
        let metrics: Vec<Metric> = match &self.objective {
            Objective::Single(m) => vec![*m],
            Objective::Weighted(w) => {
                if w.is_empty() {
                    return Err(SpecError::new(
                        "objective.weighted",
                        "{}",
                        "give at least one metric with its weight",
                    ));
                }
                // |w| ≤ 1e6 with every metric bounded (K ≤ 1e9 N/m, area ≤
                // 1e15, fidelity stand-in 1e12) keeps the weighted sum finite.
                for (m, x) in w {
                    if !(x.is_finite() && x.abs() <= WEIGHT_MAX) {
                        return Err(SpecError::new(
                            format!("objective.weighted.{}", metric_name(*m)),
                            x,
                            format!("weights must be finite, within ±{WEIGHT_MAX:e}"),
                        ));
                    }
                }
                w.keys().copied().collect()
            }
            Objective::Pareto(list) => {
                let mut l = list.clone();
                l.sort();
                l.dedup();
                if l.len() < 2 || l.len() != list.len() {
                    return Err(SpecError::new(
                        "objective.pareto",
                        format!("{list:?}"),
                        "give two or more different metrics (k_width, b_width, max_fidelity_error, area)",
                    ));
                }
                list.clone()
            }
        };
        if !(1..=MAX_EVALUATIONS).contains(&self.max_evaluations) {
            return Err(SpecError::new(
                "max_evaluations",
                self.max_evaluations,
                format!("must be 1 to {MAX_EVALUATIONS}"),
            ));
        }
        if self.finalists > 20 {
            return Err(SpecError::new(
                "finalists",
                self.finalists,
                "must be 0 to 20",
            ));
        }
        let one_d = matches!(
            self.solver,
            SolverKind::Brent | SolverKind::Golden | SolverKind::Grid
        );
        if one_d && space.dim() != 1 {
            return Err(SpecError::new(
                "solver",
                format!("{:?}", self.solver).to_lowercase(),
                format!(
                    "tunes one parameter; {} given: use nelder_mead, particle_swarm or halton",
                    space.dim()
                ),
            ));
        }
        if matches!(self.objective, Objective::Pareto(_))
            && !matches!(
                self.solver,
                SolverKind::Auto | SolverKind::Halton | SolverKind::Grid
            )
        {
            return Err(SpecError::new(
                "solver",
                format!("{:?}", self.solver).to_lowercase(),
                "a Pareto front needs a design: auto, halton or grid",
            ));
        }
        let lipschitz = match (&self.scene.estimator.kind, self.constraint) {
            (_, None) => None,
            (EstimatorKind::Levant(l), Some(_)) => Some(l.lipschitz.ok_or_else(|| {
                SpecError::new(
                    "constraint",
                    "(set)",
                    "needs the scene's estimator.lipschitz (C) to check the gains against",
                )
            })?),
            (_, Some(_)) => {
                return Err(SpecError::new(
                    "constraint",
                    "(set)",
                    "applies to Levant gains only",
                ));
            }
        };
        // The engines' own checks, on the base scene at both accuracies;
        // every evaluation costs what one map does.
        let mut costs = [Cost::default(); 2];
        for (c, acc) in costs.iter_mut().zip([&self.accuracy, &self.final_accuracy]) {
            *c = crate::zwidth::search::validate(&self.map_spec(self.scene.clone(), acc.clone()))?;
        }
        let cost = costs[0]
            .times(self.max_evaluations as u64)
            .plus(costs[1].times(self.finalists as u64))
            .check("max_evaluations")?;
        Ok(Tune {
            spec: self.clone(),
            space,
            metrics,
            lipschitz,
            cost,
        })
    }

    fn map_spec(&self, scene: SceneSpec, accuracy: Accuracy) -> MapSpec {
        MapSpec {
            scene,
            method: self.method,
            criterion: self.criterion,
            search: self.search,
            accuracy,
            b: self.b.clone(),
            b_max: self.b_max,
            k_max: self.k_max,
        }
    }
}

fn metric_name(m: Metric) -> &'static str {
    match m {
        Metric::KWidth => "k_width",
        Metric::BWidth => "b_width",
        Metric::MaxFidelityError => "max_fidelity_error",
        Metric::Area => "area",
    }
}

fn accuracy_name(a: &Accuracy) -> String {
    match a {
        Accuracy::Preset(p) => format!("{p:?}").to_lowercase(),
        Accuracy::Knobs(k) => serde_json::to_string(k).unwrap_or_default(),
    }
}

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
                ranking_held: final_rank.iter().enumerate().all(|(i, &r)| i == r),
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

impl TuneResult {
    /// The score of each search evaluation and the best so far, against
    /// the evaluation number; with a Pareto front, the front over the first
    /// two metrics instead.
    pub fn svg(&self) -> Result<String, String> {
        use crate::plot::{lines_svg, Series};
        if let (Some(front), Objective::Pareto(ms)) = (&self.pareto_front, &self.objective) {
            let (mx, my) = (ms[0], ms[1]);
            let mut pts: Vec<(f64, f64)> = front
                .iter()
                .filter_map(|&i| self.history.iter().find(|e| e.index == i))
                .filter_map(|e| Some((e.metrics.get(mx)?, e.metrics.get(my)?)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            return lines_svg(
                "Pareto front (search evaluations)",
                metric_name(mx),
                metric_name(my),
                &[Series {
                    name: "non-dominated".into(),
                    points: pts,
                }],
            );
        }
        let search: Vec<&Evaluation> = self
            .history
            .iter()
            .filter(|e| e.phase == "search" && e.feasible)
            .collect();
        let mut best = f64::MIN;
        let running: Vec<(f64, f64)> = search
            .iter()
            .map(|e| {
                best = best.max(e.score);
                (e.index as f64, best)
            })
            .collect();
        lines_svg(
            "Objective over evaluations",
            "evaluation",
            "score (higher is better)",
            &[
                Series {
                    name: "each evaluation".into(),
                    points: search.iter().map(|e| (e.index as f64, e.score)).collect(),
                },
                Series {
                    name: "best so far".into(),
                    points: running,
                },
            ],
        )
    }

    /// Every evaluation as CSV: index, phase, each parameter, the four
    /// measures, score, feasible, cached, elapsed.
    pub fn csv(&self) -> String {
        let names: Vec<&String> = self.best.params.keys().collect();
        let mut s = format!(
            "index,phase,{},k_width,b_width,max_fidelity_error,area,score,feasible,cached,elapsed_s\n",
            names.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(",")
        );
        for e in &self.history {
            let p: Vec<String> = names
                .iter()
                .map(|n| e.params.get(*n).map(|x| x.to_string()).unwrap_or_default())
                .collect();
            let m = &e.metrics;
            s.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{}\n",
                e.index,
                e.phase,
                p.join(","),
                m.k_width,
                m.b_width,
                m.max_fidelity_error
                    .map(|f| f.to_string())
                    .unwrap_or_default(),
                m.area,
                e.score,
                e.feasible,
                e.cached,
                e.elapsed_s
            ));
        }
        s
    }

    /// A short text report.
    pub fn table(&self) -> String {
        let mut s = format!(
            "best {}: {}\n",
            self.best.phase,
            self.best
                .params
                .iter()
                .map(|(n, x)| format!("{n} = {x:.6}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
        for (n, v) in &self.best.objectives {
            s.push_str(&format!(
                "  {n:<20} {}\n",
                v.map_or("-".into(), |v| format!("{v:.6e}"))
            ));
        }
        if let Some(g) = &self.best.gains {
            s.push_str(&format!("  gains: {g}\n"));
        }
        s.push_str(&format!(
            "solver {:?}: {} evaluations, {} from the cache, {:.2} s\n",
            self.solver, self.evaluations, self.cache_hits, self.elapsed_s
        ));
        if let Some(c) = &self.coarse_to_fine {
            s.push_str(&format!(
                "coarse to fine: search at {} ({:.2} s/evaluation), {} finalists at {} ({:.2} s/evaluation); ranking held: {}, best held: {}{}\n",
                c.search_accuracy, c.mean_search_evaluation_s, c.finalists.len(), c.final_accuracy, c.mean_final_evaluation_s, c.ranking_held, c.best_held,
                c.saved_s.map_or(String::new(), |s| format!("; saved {s:.1} s"))
            ));
        }
        if let Some(f) = &self.pareto_front {
            s.push_str(&format!(
                "Pareto front: {} non-dominated evaluations\n",
                f.len()
            ));
        }
        s
    }
}
