//! `zwidth bench scale`: what more workers buy (issue 14). Two kinds of
//! work, each run by 1 and 2 workers on PostgreSQL and by one process on
//! SQLite (the embedded default), all in this process (each worker has its
//! own single-thread simulator, its own lease id and the code path of a
//! `zwidth worker` process: an experiment runner and a unit runner): a
//! column-heavy sweep (one experiment whose B columns are the work units)
//! and a campaign of trace maps (one unit each). Then the claim rate the
//! database sustains with many claimers on empty experiments, and the
//! latency of one claim. Everything it stores is under rig names of its
//! own and deleted at the end.

use std::sync::Arc;
use std::time::{Duration, Instant};

use serde::Serialize;

use super::{spawn_rig, Running, Worker};
use crate::store::{ExperimentState, Lease, Location, NewExperiment, Store};

/// The 2011 boundary trace of the seed device (time domain, 537 trials):
/// one map of real work, a few tenths of a second in a release build.
const MAP: &str = r#"{"kind":"map","scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability","search":"trace"}"#;

/// A column-heavy sweep, as a lab runs one: the 2018 paper's device
/// (`examples/seed_2018.json`: friction, 1 µm quantization; the frequency
/// engine with its BLA verdicts and intervals) at reference accuracy, over
/// 8 B values (0 to 175 N·s/m) at three Butterworth cutoffs (400, 450,
/// 499 Hz): 24 B columns of ~0.6 s, each a unit of its own.
const SWEEP: &str = r#"{"kind":"sweep","map":{"scene":{"device":{"mass":0.52,"damping":13.2,"coulomb":0.19,"quantization":1e-6},"loop":{"sample_hz":1000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":499,"order":2},"probe":{"f_min_hz":1,"f_max_hz":100,"amplitude":0.5,"periods":4}},"accuracy":"reference","b":[0,25,50,75,100,125,150,175]},"parameter":{"path":"estimator.cutoff_hz","values":[400,450,499]}}"#;

#[derive(Debug, Serialize)]
pub struct CampaignRow {
    /// "column sweep" (SWEEP) or "trace maps" (MAP).
    pub work: &'static str,
    pub store: &'static str,
    pub workers: usize,
    /// Experiments run.
    pub maps: usize,
    pub wall_s: f64,
    pub maps_per_s: f64,
    /// Against one PostgreSQL worker on the same work, in the same run.
    pub speedup: f64,
}

#[derive(Debug, Serialize)]
pub struct ClaimRow {
    pub claimers: usize,
    pub claims: usize,
    pub claims_per_s: f64,
    pub p50_ms: f64,
    pub p99_ms: f64,
}

#[derive(Debug, Serialize)]
pub struct ScaleReport {
    pub campaign: Vec<CampaignRow>,
    pub claims: Vec<ClaimRow>,
    /// Seconds of one map on one worker, and the workers one database's
    /// claim rate would keep busy (see docs/service.md, "Scaling out").
    pub map_s: f64,
    pub workers_at_claim_limit: f64,
}

fn tag() -> String {
    use rand::Rng;
    format!("{:08x}", rand::rng().random::<u32>())
}

async fn insert(store: &Store, rig: &str, n: usize, spec: &str) -> Result<Vec<String>, String> {
    let kind = if spec.starts_with(r#"{"kind":"sweep""#) {
        "sweep"
    } else {
        "map"
    };
    let mut ids = Vec::new();
    for i in 0..n {
        let id = format!("{rig}-{i:05}");
        store
            .insert(NewExperiment {
                id: &id,
                kind,
                spec,
                priority: 0,
                key: None,
                not_before_ms: None,
                rig,
            })
            .await
            .map_err(|e| e.to_string())?;
        ids.push(id);
    }
    Ok(ids)
}

/// Run `maps` copies of `spec` with `workers` workers on `store`: wall
/// seconds.
async fn campaign(store: &Store, workers: usize, maps: usize, spec: &str) -> Result<f64, String> {
    let rig = format!("bench-{}", tag());
    let ids = insert(store, &rig, maps, spec).await?;
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let start = Instant::now();
    let mut tasks = Vec::new();
    for _ in 0..workers {
        let sim = crate::rig::SimulatedRig::new(&rig, 1).map_err(|e| e.to_string())?;
        tasks.extend(spawn_rig(
            store,
            Arc::new(sim),
            &Running::default(),
            &stop_rx,
            &Arc::new(Worker::new(super::LEASE_MS)),
        ));
    }
    // Wait for the last one unfinished, one look every 20 ms (looking at
    // every run each time would load the database the workers share).
    let mut next = 0;
    while let Some(id) = ids.get(next) {
        match store.get(id).await.map_err(|e| e.to_string())? {
            Some(r) if r.state == ExperimentState::Succeeded => next += 1,
            Some(r) if r.state == ExperimentState::Failed => {
                return Err(format!("a bench run failed: {:?}", r.error))
            }
            _ => tokio::time::sleep(Duration::from_millis(20)).await,
        }
    }
    let wall = start.elapsed().as_secs_f64();
    let _ = stop_tx.send(true);
    for t in tasks {
        let _ = t.await;
    }
    store.purge_rig(&rig).await.map_err(|e| e.to_string())?;
    Ok(wall)
}

/// `claims` empty experiments claimed and ended by `claimers` concurrent
/// claimers, as fast as they go. Each claimer has a connection pool of its
/// own, as a worker process has.
async fn claim_rate(
    at: &Location,
    store: &Store,
    claimers: usize,
    claims: usize,
) -> Result<ClaimRow, String> {
    let rig = format!("claims-{}", tag());
    insert(store, &rig, claims, "{}").await?;
    let mut own = Vec::new();
    for _ in 0..claimers {
        own.push(Store::connect(at).await.map_err(|e| e.to_string())?);
    }
    let start = Instant::now();
    let mut tasks = Vec::new();
    for (c, store) in own.iter().enumerate() {
        let (store, rig) = (store.clone(), rig.clone());
        tasks.push(tokio::spawn(async move {
            let me = format!("claimer-{c}");
            let mut lat = Vec::new();
            loop {
                let t0 = Instant::now();
                let row = store
                    .claim(&rig, &me, 60_000)
                    .await
                    .map_err(|e| e.to_string())?;
                lat.push(t0.elapsed().as_secs_f64() * 1e3);
                let Some(r) = row else { break };
                let lease = Lease::of(r.id, r.attempt);
                store
                    .finish(&lease, ExperimentState::Succeeded, 0, None, None)
                    .await
                    .map_err(|e| e.to_string())?;
            }
            Ok::<_, String>(lat)
        }));
    }
    let mut lat = Vec::new();
    for t in tasks {
        lat.extend(t.await.map_err(|e| e.to_string())??);
    }
    let wall = start.elapsed().as_secs_f64();
    for s in own {
        let _ = s.close().await;
    }
    store.purge_rig(&rig).await.map_err(|e| e.to_string())?;
    lat.sort_by(f64::total_cmp);
    let q = |p: f64| lat[((lat.len() - 1) as f64 * p).round() as usize];
    Ok(ClaimRow {
        claimers,
        claims,
        claims_per_s: claims as f64 / wall,
        p50_ms: q(0.5),
        p99_ms: q(0.99),
    })
}

pub async fn run(
    pg: &Location,
    maps: usize,
    sweeps: usize,
    claims: usize,
    repeat: usize,
) -> Result<ScaleReport, String> {
    let pg_store = Store::connect(pg).await.map_err(|e| e.to_string())?;
    if !pg_store.shared() {
        return Err(format!(
            "--db {pg}: bench scale measures a PostgreSQL database (postgres://…)"
        ));
    }
    let dir = std::env::temp_dir().join(format!("zwidth-bench-scale-{}", tag()));
    std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
    let sqlite = Store::open(&dir.join("bench.db"))
        .await
        .map_err(|e| e.to_string())?;
    // Warm up (page cache, prepared statements), then measure; one
    // PostgreSQL worker is the baseline of each kind of work, measured in
    // the same run.
    campaign(&pg_store, 1, 2, MAP).await?;
    let mut rows = Vec::new();
    for (work, spec, n) in [("column sweep", SWEEP, sweeps), ("trace maps", MAP, maps)] {
        // Each configuration `repeat` times, interleaved (a slow spell of
        // the machine hits all three alike); the fastest run of each counts.
        let (mut pg1, mut lite1, mut pg2) = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
        for _ in 0..repeat {
            pg1 = pg1.min(campaign(&pg_store, 1, n, spec).await?);
            lite1 = lite1.min(campaign(&sqlite, 1, n, spec).await?);
            pg2 = pg2.min(campaign(&pg_store, 2, n, spec).await?);
        }
        let row = |store, workers, wall: f64| CampaignRow {
            work,
            store,
            workers,
            maps: n,
            wall_s: wall,
            maps_per_s: n as f64 / wall,
            speedup: pg1 / wall,
        };
        rows.extend([
            row("sqlite", 1, lite1),
            row("postgres", 1, pg1),
            row("postgres", 2, pg2),
        ]);
    }
    let _ = sqlite.close().await;
    let _ = std::fs::remove_dir_all(&dir);
    let mut claim_rows = Vec::new();
    for c in [1, 8, 32] {
        claim_rows.push(claim_rate(pg, &pg_store, c, claims).await?);
    }
    let best = claim_rows
        .iter()
        .map(|r| r.claims_per_s)
        .fold(0.0, f64::max);
    let map_s = rows
        .iter()
        .find(|r| r.work == "trace maps" && r.store == "postgres" && r.workers == 1)
        .map_or(0.0, |r| r.wall_s / maps as f64);
    Ok(ScaleReport {
        campaign: rows,
        claims: claim_rows,
        map_s,
        // Each worker claims one map every `map_s` seconds.
        workers_at_claim_limit: best * map_s,
    })
}

impl ScaleReport {
    pub fn table(&self) -> String {
        let mut s =
            String::from("work          store     workers  runs  wall (s)  runs/s  speedup\n");
        for r in &self.campaign {
            s.push_str(&format!(
                "{:<13} {:<9} {:>7}  {:>4}  {:>8.2}  {:>6.2}  {:>6.2}×\n",
                r.work, r.store, r.workers, r.maps, r.wall_s, r.maps_per_s, r.speedup
            ));
        }
        s.push_str("\nclaimers  claims  claims/s  p50 (ms)  p99 (ms)\n");
        for r in &self.claims {
            s.push_str(&format!(
                "{:>8}  {:>6}  {:>8.0}  {:>8.2}  {:>8.2}\n",
                r.claimers, r.claims, r.claims_per_s, r.p50_ms, r.p99_ms
            ));
        }
        s.push_str(&format!(
            "\none map: {:.3} s on one worker; the best claim rate keeps {:.0} such workers busy\n",
            self.map_s, self.workers_at_claim_limit
        ));
        s
    }
}
