//! Tuning an estimator's parameters for K-width, B-width, fidelity or area.
//!
//! A tune searches at a cheap accuracy (`accuracy`, default `draft`), then
//! re-evaluates its best few (`finalists`) at `final_accuracy` (default
//! `reference`) and reports whether the ranking held and what the coarse
//! search saved. Every evaluation is one Z-width map; identical evaluations
//! (same accuracy, same parameter values to the bit) come from a cache that
//! a resumed run preloads from the store.

pub mod fair;
pub mod params;
pub mod plots;
mod run;
pub mod solvers;
pub mod study;

use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

use crate::error::SpecError;
use crate::estimators::EstimatorKind;
use crate::zwidth::cost::Cost;
use crate::zwidth::scene::SceneSpec;
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
    /// Noisy scenes (friction, quantization): each finalist is mapped this
    /// many times at `final_accuracy`, each time with other random-phase
    /// realizations (probe seeds derived from the scene's), and scored by
    /// the mean; finalists whose intervals still overlap the best's get more,
    /// up to twice this. 1: one map each, as on exact scenes (default 3).
    #[serde(default = "d_replicates")]
    pub replicates: usize,
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
fn d_replicates() -> usize {
    3
}
/// Most replicates a tune may ask for per finalist.
pub const MAX_REPLICATES: usize = 20;
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
    /// Noisy scenes: the map's confidence intervals of K-width (N/m) and
    /// B-width (N·s/m). A finalist's replicates are compared by them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub k_width_interval: Option<[f64; 2]>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub b_width_interval: Option<[f64; 2]>,
}

/// A fidelity error standing in for "no passive point" (N·s/m), so such a
/// point ranks below any real one without NaN or infinity.
pub const NO_FIDELITY: f64 = 1e12;

impl Metrics {
    /// The value to maximize for one metric: the map's point estimate.
    /// (Scoring K-width by its interval's middle was measured and dropped:
    /// the best cutoffs sit where draft intervals are widest, and the middle
    /// ranked the seed device's best cutoff, 499 Hz, out of the finalists;
    /// docs/tuning.md.)
    fn signed(&self, m: Metric) -> f64 {
        match m {
            Metric::KWidth => self.k_width,
            Metric::BWidth => self.b_width,
            Metric::Area => self.area,
            Metric::MaxFidelityError => -self.max_fidelity_error.unwrap_or(NO_FIDELITY),
        }
    }

    pub fn get(&self, m: Metric) -> Option<f64> {
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
    /// Final phase on a noisy scene: which replicate (0: the scene's own
    /// probe seed; n: the n-th derived seed).
    #[serde(default, skip_serializing_if = "is_zero")]
    pub replicate: usize,
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Finalist {
    pub params: BTreeMap<String, f64>,
    pub search_score: f64,
    /// The mean score over its replicates at the final accuracy.
    pub final_score: f64,
    pub search_rank: usize,
    pub final_rank: usize,
    /// Maps made at the final accuracy (1 on exact scenes).
    pub replicates: usize,
    /// Noisy scenes, a K-width or B-width objective: the final score's
    /// 95 % interval (one map: the map's interval; more: the replicates'
    /// mean ± t·s/√n, at least as wide as their mean interval).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub final_interval: Option<[f64; 2]>,
}

/// What the coarse-to-fine split cost and saved.
#[derive(Debug, Clone, Serialize, Deserialize, utoipa::ToSchema)]
pub struct CoarseToFine {
    pub search_accuracy: String,
    pub final_accuracy: String,
    pub finalists: Vec<Finalist>,
    /// The finalists keep their order at the final accuracy, wherever the
    /// search ordered them (finalists tied at the search's resolution may
    /// come out in either order).
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
    /// Maps its objectives are the mean of (replicates at the final
    /// accuracy on a noisy scene; 1 otherwise).
    pub replicates: usize,
    /// The score's interval, as for a finalist.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interval: Option<[f64; 2]>,
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
    /// Most maps per finalist at the final accuracy: twice `replicates` on
    /// a noisy scene, else 1.
    per_finalist: usize,
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
        if !(1..=MAX_REPLICATES).contains(&self.replicates) {
            return Err(SpecError::new(
                "replicates",
                self.replicates,
                format!("must be 1 to {MAX_REPLICATES} (1: one map per finalist)"),
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
        // Replicates (up to twice `replicates` each) only on noisy scenes.
        let noisy = crate::zwidth::search::noisy(&self.map_spec(self.scene.clone(), reference()))?;
        let per_finalist = if noisy { 2 * self.replicates } else { 1 };
        let cost = costs[0]
            .times(self.max_evaluations as u64)
            .plus(costs[1].times((self.finalists * per_finalist) as u64))
            .check("max_evaluations")?;
        Ok(Tune {
            spec: self.clone(),
            space,
            metrics,
            lipschitz,
            per_finalist,
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
            prior: None,
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

impl TuneResult {
    /// Every evaluation as CSV: index, phase, each parameter, the four
    /// measures, score, feasible, cached, elapsed, replicate (final maps on
    /// a noisy scene: which probe seed), the K-width interval.
    pub fn csv(&self) -> String {
        let names: Vec<&String> = self.best.params.keys().collect();
        let mut s = format!(
            "index,phase,{},k_width,b_width,max_fidelity_error,area,score,feasible,cached,elapsed_s,replicate,k_width_lo,k_width_hi\n",
            names.iter().map(|n| n.as_str()).collect::<Vec<_>>().join(",")
        );
        for e in &self.history {
            let p: Vec<String> = names
                .iter()
                .map(|n| e.params.get(*n).map(|x| x.to_string()).unwrap_or_default())
                .collect();
            let m = &e.metrics;
            s.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
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
                e.elapsed_s,
                e.replicate,
                m.k_width_interval
                    .map_or(String::new(), |i| i[0].to_string()),
                m.k_width_interval
                    .map_or(String::new(), |i| i[1].to_string()),
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
        if let Some([lo, hi]) = self.best.interval {
            s.push_str(&format!(
                "  score {:.6e}, 95 % interval [{lo:.6e}, {hi:.6e}], mean of {} map(s)\n",
                self.best.score, self.best.replicates
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
            for f in &c.finalists {
                s.push_str(&format!(
                    "  finalist {}: search {:.6e} (#{}), final {:.6e} (#{}){}, {} map(s)\n",
                    f.params
                        .iter()
                        .map(|(n, x)| format!("{n} = {x:.6}"))
                        .collect::<Vec<_>>()
                        .join(", "),
                    f.search_score,
                    f.search_rank + 1,
                    f.final_score,
                    f.final_rank + 1,
                    f.final_interval
                        .map_or(String::new(), |[lo, hi]| format!(" [{lo:.6e}, {hi:.6e}]")),
                    f.replicates
                ));
            }
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

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(extra: serde_json::Value) -> TuneSpec {
        let mut v = serde_json::json!({
            "scene": {"estimator": {"kind": "butterworth", "cutoff_hz": 200}},
            "params": {"cutoff_hz": {"min": 100, "max": 400}},
            "objective": "k_width"
        });
        for (k, x) in extra.as_object().unwrap() {
            v[k] = x.clone();
        }
        serde_json::from_value(v).unwrap()
    }

    #[test]
    fn defaults_are_the_documented_ones() {
        // docs/tuning.md and the field docs: robust bisection, draft search,
        // reference finals, 3 finalists, 3 replicates, 40 evaluations, the
        // compare's B up to 1000 N·s/m and K up to 1e7 N/m.
        let s = spec(serde_json::json!({}));
        assert_eq!(s.search, SearchKind::RobustBisect);
        assert_eq!(s.accuracy, Accuracy::Preset(Preset::Draft));
        assert_eq!(s.final_accuracy, Accuracy::Preset(Preset::Reference));
        assert_eq!((s.finalists, s.replicates, s.max_evaluations), (3, 3, 40));
        assert_eq!((s.b_max, s.k_max), (1000.0, 1e7));
        assert_eq!(
            (s.solver, s.seed, s.constraint),
            (SolverKind::Auto, 0, None)
        );
    }

    #[test]
    fn a_pareto_objective_needs_two_distinct_metrics() {
        let field =
            |o: serde_json::Value| match spec(serde_json::json!({ "objective": o })).validate() {
                Ok(_) => panic!("accepted"),
                Err(e) => e.field,
            };
        assert_eq!(
            field(serde_json::json!({"pareto": ["k_width"]})),
            "objective.pareto"
        );
        assert_eq!(
            field(serde_json::json!({"pareto": ["k_width", "k_width"]})),
            "objective.pareto"
        );
        spec(serde_json::json!({"objective": {"pareto": ["k_width", "b_width"]}}))
            .validate()
            .unwrap();
    }

    #[test]
    fn finalists_and_weights_are_checked_at_their_limits() {
        // "finalists must be 0 to 20"; weights within ±WEIGHT_MAX = 1e6.
        let ok = |extra| match spec(extra).validate() {
            Ok(_) => true,
            Err(e) => panic!("{e}"),
        };
        let field = |extra| spec(extra).validate().err().unwrap().field;
        // (At draft finals, so the cost stays inside the trial limit.)
        let finals = |n: usize| serde_json::json!({"finalists": n, "final_accuracy": "draft"});
        assert!(ok(finals(20)));
        assert_eq!(field(finals(21)), "finalists");
        assert!(ok(
            serde_json::json!({"objective": {"weighted": {"k_width": 1e6}}})
        ));
        assert_eq!(
            field(serde_json::json!({"objective": {"weighted": {"k_width": 1e7}}})),
            "objective.weighted.k_width"
        );
    }
}
