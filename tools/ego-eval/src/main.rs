//! EGO (egobox-ego) vs zwidth's tuner on the noisy seed_2018 objective.
//!
//! Usage:
//!   ego-eval eval  <cutoff>            one draft map (smoke test)
//!   ego-eval egor  <seed> [n_doe]      plain Egor (full GP, no noise option exists), 30 calls
//!   ego-eval egorint <seed> [n_doe]   plain Egor on XType::Int(10, 499), 30 calls
//!   ego-eval sgp   <seed> [n_doe]      Egor's EgorSolver::suggest (ask-and-tell) with a custom
//!                                      SurrogateBuilder: sparse GP (FITC) whose noise variance
//!                                      is estimated, 30 calls
//!   ego-eval truth <cutoff>...         standard accuracy, probe seeds 1,2,3
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use egobox_doe::{Lhs, SamplingMethod};
use egobox_ego::{
    Cstr, CorrelationSpec, EgorBuilder, EgorConfig, EgorSolver, RegressionSpec, SurrogateBuilder,
    XType,
};
use egobox_moe::{
    Clustering, GpMixtureParams, GpType, Inducings, MixtureGpSurrogate, NbClusters,
    Recombination, SparseMethod, ThetaTuning,
};
use ndarray::{array, Array2, ArrayView1, ArrayView2};
use rand_xoshiro::rand_core::SeedableRng;
use rand_xoshiro::Xoshiro256Plus;
use serde::{Deserialize, Serialize};

use zwidth_core::zwidth::scene::SceneSpec;
use zwidth_core::zwidth::search::map;
use zwidth_core::zwidth::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};

const SEED_2018: &str = include_str!("../../../examples/seed_2018.json");
const LO: f64 = 10.0;
const HI: f64 = 499.0;
const BUDGET: usize = 30;
const K_MAX: f64 = 1e7;

/// The tuner's score (to maximize) for one map at integer `cutoff`.
fn score(cutoff: i64, probe_seed: Option<u64>, preset: Preset) -> (f64, f64) {
    let mut scene = SceneSpec::from_json(SEED_2018).unwrap();
    scene.estimator = serde_json::from_str(&format!(
        r#"{{"kind":"butterworth","cutoff_hz":{cutoff},"order":2}}"#
    ))
    .unwrap();
    if let Some(s) = probe_seed {
        scene.probe.seed = s;
    }
    let t = Instant::now();
    let m = map(&MapSpec {
        scene,
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::RobustBisect,
        accuracy: Accuracy::Preset(preset),
        b: None,
        b_max: 1000.0,
        k_max: K_MAX,
        prior: None,
    })
    .unwrap();
    let s = match m.k_width_interval {
        Some([lo, hi]) if hi < K_MAX => 0.5 * (lo + hi),
        _ => m.k_width,
    };
    (s, t.elapsed().as_secs_f64())
}

/// Budgeted, cached objective: integer cutoffs, calls counted.
#[derive(Default)]
struct Book {
    calls: usize,
    maps: usize,
    over_budget: usize,
    cache: BTreeMap<i64, f64>,
    seq: Vec<(f64, i64, f64, bool)>, // (x asked, cutoff, score, cache hit)
    map_secs: f64,
}

impl Book {
    fn eval(&mut self, x: f64) -> f64 {
        let c = x.round().clamp(LO, HI) as i64;
        if self.calls >= BUDGET {
            // Never expected (n_doe + max_iters = BUDGET): answer the worst score seen.
            self.over_budget += 1;
            eprintln!("over budget: asked {x}");
            return self.cache.values().cloned().fold(f64::INFINITY, f64::min);
        }
        self.calls += 1;
        let (s, hit) = match self.cache.get(&c) {
            Some(&s) => (s, true),
            None => {
                let (s, secs) = score(c, None, Preset::Draft);
                self.maps += 1;
                self.map_secs += secs;
                self.cache.insert(c, s);
                (s, false)
            }
        };
        eprintln!(
            "call {:2} x={x:8.3} cutoff={c:3} score={s:.6e}{}",
            self.calls,
            if hit { " (cache)" } else { "" }
        );
        self.seq.push((x, c, s, hit));
        s
    }

    fn report(&self, variant: &str, seed: u64, n_doe: usize, wall: f64, extra: serde_json::Value) {
        let (&bc, &bs) = self
            .cache
            .iter()
            .max_by(|a, b| a.1.partial_cmp(b.1).unwrap())
            .unwrap();
        let out = serde_json::json!({
            "variant": variant, "seed": seed, "n_doe": n_doe,
            "best_cutoff": bc, "best_score": bs,
            "calls": self.calls, "distinct_maps": self.maps, "over_budget_calls": self.over_budget,
            "wall_s": wall, "map_s": self.map_secs,
            "seq": self.seq.iter().map(|(x, c, s, h)| serde_json::json!([x, c, s, h])).collect::<Vec<_>>(),
            "extra": extra,
        });
        println!("{out}");
    }
}

fn gp_conf(c: EgorConfig) -> EgorConfig {
    c.configure_gp(|gp| {
        gp.regression_spec(RegressionSpec::CONSTANT)
            .correlation_spec(CorrelationSpec::MATERN52)
    })
}

/// Plain `Egor`: the only GP the builder can make is the interpolating full GP.
fn run_egor(seed: u64, n_doe: usize) {
    let book = Arc::new(Mutex::new(Book::default()));
    let b = book.clone();
    // Egor minimizes: f = -score.
    let f = move |x: &ArrayView2<f64>| -> Array2<f64> {
        let mut bk = b.lock().unwrap();
        Array2::from_shape_fn((x.nrows(), 1), |(i, _)| -bk.eval(x[[i, 0]]))
    };
    let t = Instant::now();
    let res = EgorBuilder::optimize(f)
        .configure(|c| gp_conf(c.n_doe(n_doe).max_iters(BUDGET - n_doe).seed(seed)))
        .min_within(&array![[LO, HI]])
        .expect("Egor configured")
        .run();
    let wall = t.elapsed().as_secs_f64();
    let extra = match &res {
        Ok(r) => serde_json::json!({"x_opt": r.x_opt.to_vec(), "y_opt": r.y_opt.to_vec(),
                                     "n_doe_rows": r.x_doe.nrows(),
                                     "termination": format!("{:?}", r.state.get_termination_status())}),
        Err(e) => serde_json::json!({"error": e.to_string()}),
    };
    book.lock().unwrap().report("egor", seed, n_doe, wall, extra);
}

/// `Egor` on an integer variable (`XType::Int(10, 499)`, continuous relaxation
/// inside egobox); otherwise as `run_egor`.
fn run_egor_int(seed: u64, n_doe: usize) {
    let book = Arc::new(Mutex::new(Book::default()));
    let b = book.clone();
    let f = move |x: &ArrayView2<f64>| -> Array2<f64> {
        let mut bk = b.lock().unwrap();
        Array2::from_shape_fn((x.nrows(), 1), |(i, _)| -bk.eval(x[[i, 0]]))
    };
    let t = Instant::now();
    let res = EgorBuilder::optimize(f)
        .configure(|c| gp_conf(c.n_doe(n_doe).max_iters(BUDGET - n_doe).seed(seed)))
        .min_within_mixint_space(&[XType::Int(LO as i32, HI as i32)])
        .expect("Egor configured")
        .run();
    let wall = t.elapsed().as_secs_f64();
    let extra = match &res {
        Ok(r) => serde_json::json!({"x_opt": r.x_opt.to_vec(), "y_opt": r.y_opt.to_vec(),
                                     "n_doe_rows": r.x_doe.nrows(),
                                     "termination": format!("{:?}", r.state.get_termination_status())}),
        Err(e) => serde_json::json!({"error": e.to_string()}),
    };
    book.lock().unwrap().report("egor_int", seed, n_doe, wall, extra);
}

static SGP_SEED: AtomicU64 = AtomicU64::new(0);

/// egobox-moe's mixture parameters switched to a sparse GP (FITC) whose
/// homoscedastic noise variance is estimated with the hyperparameters
/// (`ParamTuning::default()`: init 1e-2, bounds [100·eps, 1e10]); inducing
/// points: a fixed grid of 12 half-integer cutoffs over the range.
#[derive(Clone, Serialize, Deserialize)]
#[serde(transparent)]
struct NoisyMoe(GpMixtureParams<f64>);

impl SurrogateBuilder for NoisyMoe {
    fn new_with_xtypes(_xtypes: &[XType]) -> Self {
        // Half-integer positions: never on a (rounded, integer) data point. With
        // inducing points on data points (first try: a grid including 10 and 499)
        // FITC's diagonal correction there is only the noise variance, whose lower
        // bound is 100·eps, and egobox-gp panicked (NotPositiveDefinite unwrap).
        let z = Array2::from_shape_fn((12, 1), |(i, _)| {
            (LO + (HI - LO) * i as f64 / 11.0).round().clamp(LO, HI - 1.0) + 0.5
        });
        NoisyMoe(GpMixtureParams::new_with_rng(
            GpType::SparseGp {
                sparse_method: SparseMethod::Fitc,
                inducings: Inducings::Located(z),
            },
            Xoshiro256Plus::seed_from_u64(SGP_SEED.load(Ordering::SeqCst)),
        ))
    }
    fn set_regression_spec(&mut self, s: RegressionSpec) {
        self.0.set_regression_spec(s)
    }
    fn set_correlation_spec(&mut self, s: CorrelationSpec) {
        self.0.set_correlation_spec(s)
    }
    fn set_kpls_dim(&mut self, d: Option<usize>) {
        self.0.set_kpls_dim(d)
    }
    fn set_n_clusters(&mut self, n: NbClusters) {
        self.0.set_n_clusters(n)
    }
    fn set_recombination(&mut self, r: Recombination<f64>) {
        self.0.set_recombination(r)
    }
    fn set_theta_tunings(&mut self, t: &[ThetaTuning<f64>]) {
        self.0.set_theta_tunings(t)
    }
    fn set_optim_params(&mut self, n_start: usize, max_eval: usize) {
        self.0.set_optim_params(n_start, max_eval)
    }
    fn train(
        &self,
        xt: ArrayView2<f64>,
        yt: ArrayView1<f64>,
    ) -> egobox_moe::Result<Box<dyn MixtureGpSurrogate>> {
        self.0.train(xt, yt)
    }
    fn train_on_clusters(
        &self,
        xt: ArrayView2<f64>,
        yt: ArrayView1<f64>,
        clustering: &Clustering,
    ) -> egobox_moe::Result<Box<dyn MixtureGpSurrogate>> {
        self.0.train_on_clusters(xt, yt, clustering)
    }
}

/// Ask-and-tell with `EgorSolver::<NoisyMoe>::suggest`: same LHS initial DOE
/// as Egor (egobox-doe `Lhs` seeded the same way), then one suggestion per call.
/// The data handed to `suggest` holds each integer cutoff once (x = the
/// integer): duplicate rows make egobox-gp's sparse GP panic
/// (`NotPositiveDefinite` unwrap). A suggestion that rounds to a cutoff
/// already mapped is a cached call (counted); as in `Egor` (3 retries, then
/// "converged"), 3 such calls in a row stop the run. The suggest seed moves
/// on with each call so that a retry is not the same computation.
fn run_sgp(seed: u64, n_doe: usize) {
    SGP_SEED.store(seed, Ordering::SeqCst);
    let mut book = Book::default();
    let t = Instant::now();
    let xlimits = array![[LO, HI]];
    let doe = Lhs::new(&xlimits)
        .with_rng(Xoshiro256Plus::seed_from_u64(seed))
        .sample(n_doe);
    let mut xs: Vec<f64> = vec![];
    let mut ys: Vec<f64> = vec![];
    let add = |book: &mut Book, xs: &mut Vec<f64>, ys: &mut Vec<f64>, x: f64| -> bool {
        let c = x.round().clamp(LO, HI);
        let new = !book.cache.contains_key(&(c as i64));
        let y = -book.eval(x);
        if new {
            xs.push(c);
            ys.push(y);
        }
        new
    };
    for i in 0..n_doe {
        add(&mut book, &mut xs, &mut ys, doe[[i, 0]]);
    }
    let mut suggest_s = 0.0;
    let mut panics = 0;
    let mut repeats_in_row = 0;
    let mut stop = "budget";
    let mut it = 0u64;
    while book.calls < BUDGET {
        let config = gp_conf(
            EgorConfig::default()
                .n_doe(n_doe)
                .max_iters(BUDGET - n_doe)
                .seed(seed.wrapping_mul(1000).wrapping_add(it)),
        )
        .xtypes(&[XType::Float(LO, HI)])
        .check()
        .expect("config");
        it += 1;
        let solver: EgorSolver<NoisyMoe, Cstr> = EgorSolver::new(config);
        let xd = Array2::from_shape_vec((xs.len(), 1), xs.clone()).unwrap();
        let yd = Array2::from_shape_vec((ys.len(), 1), ys.clone()).unwrap();
        let ts = Instant::now();
        let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| solver.suggest(&xd, &yd)));
        suggest_s += ts.elapsed().as_secs_f64();
        let x = match r {
            Ok(x) => x[[0, 0]],
            Err(_) => {
                panics += 1;
                eprintln!("suggest panicked");
                if panics >= 3 {
                    stop = "panics";
                    break;
                }
                continue;
            }
        };
        if add(&mut book, &mut xs, &mut ys, x) {
            repeats_in_row = 0;
        } else {
            repeats_in_row += 1;
            if repeats_in_row >= 3 {
                stop = "3 repeats in a row";
                break;
            }
        }
    }
    let wall = t.elapsed().as_secs_f64();
    book.report(
        "sgp",
        seed,
        n_doe,
        wall,
        serde_json::json!({"suggest_s": suggest_s, "panics": panics, "stop": stop}),
    );
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let arg = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_string());
    match args.get(1).map(|s| s.as_str()) {
        Some("eval") => {
            let c: i64 = arg(2, "250").parse().unwrap();
            let (s, secs) = score(c, None, Preset::Draft);
            println!("{}", serde_json::json!({"cutoff": c, "score": s, "secs": secs}));
        }
        Some("egor") => run_egor(arg(2, "0").parse().unwrap(), arg(3, "8").parse().unwrap()),
        Some("egorint") => run_egor_int(arg(2, "0").parse().unwrap(), arg(3, "8").parse().unwrap()),
        Some("sgp") => run_sgp(arg(2, "0").parse().unwrap(), arg(3, "8").parse().unwrap()),
        Some("truth") => {
            for c in &args[2..] {
                let c: i64 = c.parse().unwrap();
                let mut v = vec![];
                let mut secs = 0.0;
                for s in 1..=3u64 {
                    let (x, t) = score(c, Some(s), Preset::Standard);
                    v.push(x);
                    secs += t;
                }
                let mean = v.iter().sum::<f64>() / 3.0;
                println!(
                    "{}",
                    serde_json::json!({"cutoff": c, "scores": v, "mean": mean, "secs": secs})
                );
            }
        }
        _ => eprintln!("usage: ego-eval eval|egor|sgp|truth ..."),
    }
}
