//! `zwidth bench ui`: each dashboard page's server time on a database the
//! size of a busy lab's (10 000 experiments, 1 000 000 trials by default),
//! through the real router in this process (no network: server time), with
//! the JSON list as the baseline measured in the same run. Also what seeds
//! such a database (synthetic runs shaped like real ones: a real map's
//! spec and result, a real tune's evaluations).

use std::time::Instant;

use axum::body::Body;
use axum::http::Request;
use serde::Serialize;
use tower::ServiceExt;

use crate::store::ExperimentState::{Failed, Queued, Running, Succeeded};
use crate::store::{ExperimentRow, Store};
use crate::zwidth::search::{map, Point, StoredEvaluation, StoredTrial};
use crate::zwidth::settings::MapSpec;

/// What a seeded database holds, for the pages to ask for.
#[derive(Debug, Clone, Serialize)]
pub struct Seeded {
    pub experiments: usize,
    pub trials: usize,
    /// The run with the most trials.
    pub big: String,
    /// Two succeeded map runs on one scene.
    pub pair: [String; 2],
    pub tune: String,
    pub typical: String,
}

/// A small real map (the analytic engine on the linear scene, the 2018
/// paper's impedance criterion, with fidelity): its spec, result and one
/// point to copy.
fn template() -> Result<(MapSpec, serde_json::Value, Point), String> {
    let spec: MapSpec = serde_json::from_value(serde_json::json!({
        "scene": {"device": {"coulomb": 0, "quantization": 0},
                  "loop": {"sample_hz": 1000, "render_hz": 1000},
                  "estimator": {"kind": "butterworth", "cutoff_hz": 200, "order": 2}},
        "criterion": "impedance",
        "b": [0, 2, 4, 6, 8, 10]
    }))
    .map_err(|e| e.to_string())?;
    let r = map(&spec).map_err(|e| e.to_string())?;
    let point = r
        .points
        .first()
        .cloned()
        .ok_or("the template map has no point")?;
    let result = serde_json::to_value(&r).map_err(|e| e.to_string())?;
    Ok((spec, result, point))
}

/// `n` trials spread over a K–B grid, passive below a falling boundary,
/// the fidelity error growing with K (shapes like a real map's).
fn synthetic_trials(n: usize, like: &Point) -> Vec<StoredTrial> {
    let cols = ((n as f64).sqrt() / 2.0).ceil().max(1.0) as usize;
    let rows = n.div_ceil(cols);
    (0..n)
        .map(|i| {
            let (c, r) = (i % cols, i / cols);
            let b = 1000.0 * c as f64 / cols as f64;
            let k = 5e5 * (r as f64 + 0.5) / rows as f64;
            let edge = 4e5 * (1.0 - b / 1100.0);
            let mut p = like.clone();
            (p.k, p.b) = (k, b);
            p.passive = Some(k < edge);
            p.stable = None;
            p.fidelity = (k < edge).then(|| 50.0 * k / edge + b / 100.0);
            StoredTrial {
                scope: 0,
                column: c as u32,
                index: r as u32,
                point: p,
            }
        })
        .collect()
}

/// Fill `store` with `experiments` runs holding `trials` trials in all,
/// `big` of them in one run; most succeeded, some running, waiting and
/// failed (in the last day), one tune with real evaluations.
pub async fn seed(
    store: &Store,
    experiments: usize,
    trials: usize,
    big: usize,
) -> Result<Seeded, String> {
    let (spec, result, like) = template()?;
    let spec_json = serde_json::to_string(&crate::experiment::ExperimentSpec::Map(spec.clone()))
        .map_err(|e| e.to_string())?;
    let result_json = result.to_string();
    // A real tune: Butterworth cutoff for K-width on the linear scene.
    let tune_spec: crate::tune::TuneSpec = serde_json::from_value(serde_json::json!({
        "scene": spec.scene,
        "params": {"cutoff_hz": [50, 450]},
        "objective": "k_width", "accuracy": "draft", "final_accuracy": "draft",
        "finalists": 2, "max_evaluations": 12, "b": [0, 20]
    }))
    .map_err(|e| e.to_string())?;
    let tuned = tune_spec
        .validate()
        .map_err(|e| e.to_string())?
        .run(None)
        .map_err(|e| e.to_string())?;
    let evals: Vec<StoredEvaluation> = tuned
        .history
        .iter()
        .enumerate()
        .map(|(i, e)| StoredEvaluation {
            key: format!("draft:{i}"),
            record: serde_json::to_value(e).unwrap_or_default(),
        })
        .collect();
    let now = crate::clock::now_ms();
    // Every 50th waiting, every 200th running, every 97th failed; the
    // first the biggest, the third the tune.
    let state_of = |i: usize| match i {
        1 => Succeeded,
        _ if i % 200 == 7 => Running,
        _ if i % 50 == 3 => Queued,
        _ if i % 97 == 5 => Failed,
        _ => Succeeded,
    };
    // The other trials over the runs that hold trials (not the biggest,
    // the tune or the waiting), so the database holds `trials` in all.
    let holders = (3..experiments).filter(|&i| state_of(i) != Queued).count() + 1;
    let per = trials.saturating_sub(big).div_ceil(holders.max(1));
    let mut left = trials.saturating_sub(big);
    let mut out = Seeded {
        experiments,
        trials: 0,
        big: String::new(),
        pair: [String::new(), String::new()],
        tune: String::new(),
        typical: String::new(),
    };
    for i in 0..experiments {
        let id = uuid::Uuid::now_v7().to_string();
        let n = if i == 0 {
            big
        } else if i == 2 || state_of(i) == Queued {
            0
        } else {
            let n = per.min(left);
            left -= n;
            n
        };
        let t0 = now - (experiments - i) as i64 * 60_000;
        let state = state_of(i);
        let is_tune = i == 2;
        let row = ExperimentRow {
            id: id.clone(),
            kind: if is_tune { "tune" } else { "map" }.into(),
            spec: if is_tune {
                serde_json::to_string(&crate::experiment::ExperimentSpec::Tune(tune_spec.clone()))
                    .map_err(|e| e.to_string())?
            } else {
                spec_json.clone()
            },
            state: if is_tune { Succeeded } else { state },
            priority: (i % 3) as i64,
            created_ms: t0,
            started_ms: (state != Queued).then_some(t0 + 1000),
            finished_ms: (state == Succeeded || state == Failed || is_tune).then_some(t0 + 30_000),
            trials_done: if is_tune { 0 } else { n as i64 },
            result: if is_tune {
                Some(serde_json::to_string(&tuned).map_err(|e| e.to_string())?)
            } else {
                (state == Succeeded).then(|| result_json.clone())
            },
            error: (state == Failed)
                .then(|| format!("seeded failure {i}: the rig stopped answering")),
            idempotency_key: None,
            not_before_ms: None,
            rig: "sim".into(),
            progress: if state == Succeeded { 1.0 } else { 0.4 },
            best: None,
            attempt: (state != Queued) as i64,
            worker: (state == Running).then(|| "bench:1:ui".to_string()),
            lease_until_ms: None,
        };
        let ts = if is_tune || state == Queued {
            Vec::new()
        } else {
            synthetic_trials(n, &like)
        };
        let ev: &[StoredEvaluation] = if is_tune { &evals } else { &[] };
        store
            .import_run(&row, &ts, ev)
            .await
            .map_err(|e| e.to_string())?;
        out.trials += ts.len();
        match i {
            0 => out.big = id,
            1 => {
                out.pair[0] = id.clone();
                out.typical = id;
            }
            2 => out.tune = id,
            _ if state == Succeeded && out.pair[1].is_empty() => out.pair[1] = id,
            _ => {}
        }
    }
    Ok(out)
}

/// One page's figures.
#[derive(Debug, Clone, Serialize)]
pub struct PageTime {
    pub page: String,
    pub path: String,
    pub median_ms: f64,
    pub max_ms: f64,
    pub bytes: usize,
    pub status: u16,
}

/// The report: the database, each page, the JSON baseline.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    pub seeded: Seeded,
    pub seed_s: f64,
    pub pages: Vec<PageTime>,
}

impl Report {
    pub fn table(&self) -> String {
        let mut s = format!(
            "{} experiments, {} trials, seeded in {:.1} s\n{:<34} {:>10} {:>10} {:>10} {:>6}\n",
            self.seeded.experiments,
            self.seeded.trials,
            self.seed_s,
            "page",
            "median ms",
            "max ms",
            "bytes",
            "status"
        );
        for p in &self.pages {
            s.push_str(&format!(
                "{:<34} {:>10.1} {:>10.1} {:>10} {:>6}\n",
                p.page, p.median_ms, p.max_ms, p.bytes, p.status
            ));
        }
        s
    }
}

/// Why a bench could not run: the database given (exit 2), or a failure.
#[derive(Debug)]
pub enum BenchError {
    Input(String),
    Failure(String),
}

impl From<String> for BenchError {
    fn from(s: String) -> Self {
        Self::Failure(s)
    }
}

impl From<&str> for BenchError {
    fn from(s: &str) -> Self {
        Self::Failure(s.into())
    }
}

/// Seed `db` (it must be new or empty) and time every page `repeat` times.
pub async fn run(
    db: &crate::store::Location,
    experiments: usize,
    trials: usize,
    big: usize,
    repeat: usize,
) -> Result<Report, BenchError> {
    let store = Store::connect(db).await.map_err(|e| match e {
        crate::store::OpenError::Refused(m) => BenchError::Input(format!("--db {db}: {m}")),
        crate::store::OpenError::Failed(m) => BenchError::Failure(m),
    })?;
    let (counts, _) = store.counts().await.map_err(|e| e.to_string())?;
    if counts.iter().any(|(_, n)| *n > 0) {
        return Err(BenchError::Input(format!(
            "--db {db} holds experiments: bench ui seeds a new, empty database"
        )));
    }
    let t = Instant::now();
    let seeded = seed(&store, experiments, trials, big).await?;
    let seed_s = t.elapsed().as_secs_f64();
    store.analyze().await.map_err(|e| e.to_string())?;
    let app = super::super::router(
        super::super::AppState::reader(store.clone())?,
        std::time::Duration::from_secs(60),
    );
    let pages: Vec<(&str, String)> = vec![
        (
            "baseline: GET /v1/experiments",
            "/v1/experiments?limit=50".into(),
        ),
        ("queue", "/".into()),
        ("queue, live part", "/ui/queue/live".into()),
        ("runs, page 1", "/runs".into()),
        // The last page: the deepest OFFSET.
        (
            "runs, last page",
            format!("/runs?page={}", experiments.div_ceil(50)),
        ),
        (
            "runs, kind+state filter",
            "/runs?kind=map&state=failed".into(),
        ),
        ("runs, scene text filter", "/runs?scene=butterworth".into()),
        ("run (biggest)", format!("/runs/{}", seeded.big)),
        ("run (typical)", format!("/runs/{}", seeded.typical)),
        (
            "run, live part unchanged (204)",
            format!("/ui/runs/{}/live?since=x", seeded.big),
        ),
        (
            "queue, live part unchanged (204)",
            "/ui/queue/live?since=q".into(),
        ),
        (
            "compare two runs",
            format!("/compare?runs={},{}", seeded.pair[0], seeded.pair[1]),
        ),
        ("tune", format!("/runs/{}", seeded.tune)),
    ];
    let mut out = Vec::new();
    for (name, path) in pages {
        // The 204 path needs the run's current token.
        let path = if path.contains("since=x") {
            let r = store
                .get(&seeded.big)
                .await
                .map_err(|e| e.to_string())?
                .ok_or("big run gone")?;
            let st = super::super::AppState::reader(store.clone())?;
            let n = store.trial_count(&r.id).await.map_err(|e| e.to_string())?;
            let q = serde_urlencoded::to_string([("since", super::run::token(&r, n, &st))])
                .map_err(|e| e.to_string())?;
            path.replace("since=x", &q)
        } else if path.contains("since=q") {
            let st = super::super::AppState::reader(store.clone())?;
            let t = super::queue::token(&st)
                .await
                .map_err(|p| format!("{p:?}"))?;
            let q = serde_urlencoded::to_string([("since", t)]).map_err(|e| e.to_string())?;
            path.replace("since=q", &q)
        } else {
            path
        };
        let mut times = Vec::new();
        let (mut bytes, mut status) = (0, 0);
        for _ in 0..repeat.max(1) {
            let t = Instant::now();
            let resp = app
                .clone()
                .oneshot(
                    Request::get(&path)
                        .body(Body::empty())
                        .map_err(|e| e.to_string())?,
                )
                .await
                .map_err(|e| e.to_string())?;
            status = resp.status().as_u16();
            let body = axum::body::to_bytes(resp.into_body(), usize::MAX)
                .await
                .map_err(|e| e.to_string())?;
            times.push(t.elapsed().as_secs_f64() * 1000.0);
            bytes = body.len();
        }
        times.sort_by(f64::total_cmp);
        out.push(PageTime {
            page: name.into(),
            path,
            median_ms: times[times.len() / 2],
            max_ms: *times.last().unwrap_or(&0.0),
            bytes,
            status,
        });
    }
    Ok(Report {
        seeded,
        seed_s,
        pages: out,
    })
}
