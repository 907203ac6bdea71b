//! The experiment queue: the runners — one per rig — that claim queued
//! experiments one at a time (inside the rig's window, if it has one), run
//! them off the async workers (`spawn_blocking`), write progress, and honour
//! cancellation and shutdown between trials.

use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::Duration;

pub mod bench;
pub mod farm;
mod retry;
pub mod worker;

use crate::experiment::ExperimentSpec;
use crate::rig::Rig;
use crate::store::ExperimentState::{Cancelled, Failed, Succeeded};
use crate::store::{Fault, Held, Lease, Store, UnitRow};
use crate::zwidth::cost::Cost;
use crate::zwidth::farm::Unit;
use crate::zwidth::search::run_unit;
use crate::zwidth::search::{Observer, StoredEvaluation, StoredTrial};
use crate::zwidth::settings::MapSpec;
use retry::{backoff, FIRST_RETRY};

/// The observers of running experiments by id, so a cancel request reaches
/// the simulation at once (not at the runner's next 100 ms look).
pub type Running = Arc<std::sync::Mutex<std::collections::HashMap<String, Arc<Observer>>>>;

/// Stop a running experiment's simulation now, and its units running in
/// this process (false if none of it runs here).
pub fn cancel_running(running: &Running, id: &str) -> bool {
    let map = running.lock().unwrap_or_else(|e| e.into_inner());
    let unit_of = format!("{id}/");
    let mut found = false;
    for (key, o) in map.iter() {
        if key == id || key.starts_with(&unit_of) {
            o.cancel.store(true, Ordering::Relaxed);
            found = true;
        }
    }
    found
}

/// Trials computed and stored by this process so far (its trials per
/// second, for /metrics, come from this count).
pub static TRIALS_STORED: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// Run `rig`'s work until `shutdown`: its experiments one at a time, and,
/// on a shared store (PostgreSQL) with a simulated rig, also its work
/// units, one per thread of the rig (an experiment's run then only plans
/// its units and replays them: it has its own slot, and drivers never
/// starve the units of their threads).
pub fn spawn_rig(
    store: &Store,
    rig: Arc<dyn Rig>,
    running: &Running,
    shutdown: &tokio::sync::watch::Receiver<bool>,
    me: &Arc<Worker>,
) -> Vec<tokio::task::JoinHandle<()>> {
    // Woken by other processes' submissions and units (PostgreSQL).
    store.listen();
    let threads = rig.info().parallelism.max(1);
    // Farmed, one experiment runner per rig thread: a campaign of trace
    // maps (one unit each) keeps every unit slot busy. Their runs wait on
    // threads of their own, never the rig's.
    let driver = if farmed(store, rig.as_ref()) {
        match rayon::ThreadPoolBuilder::new()
            .num_threads(DRIVER_THREADS * threads)
            .thread_name(|i| format!("zwidth-driver-{i}"))
            .build()
        {
            Ok(p) => Some(Arc::new(p)),
            Err(e) => {
                tracing::error!(error = %e, "no threads for the experiments' runs: running them on the rig's");
                None
            }
        }
    } else {
        None
    };
    let runners = if driver.is_some() { threads } else { 1 };
    let mut tasks = Vec::new();
    for _ in 0..runners {
        tasks.push(tokio::spawn(runner(
            store.clone(),
            rig.clone(),
            running.clone(),
            shutdown.clone(),
            me.clone(),
            driver.clone(),
        )));
    }
    if driver.is_some() {
        for _ in 0..threads {
            tasks.push(tokio::spawn(unit_runner(
                store.clone(),
                rig.clone(),
                running.clone(),
                shutdown.clone(),
                me.clone(),
            )));
        }
    }
    tasks
}

/// Whether `rig`'s experiments hand their units to workers: on a shared
/// store, for a simulated rig (an attached rig runs its trials itself).
fn farmed(store: &Store, rig: &dyn Rig) -> bool {
    store.shared() && rig.attached().is_none()
}

/// Threads per experiment runner of the pool the runs (drivers) wait on:
/// enough for a comparison's maps to queue their units at once.
const DRIVER_THREADS: usize = 4;

/// This process as a worker: its id in the `workers` table and on the
/// leases it holds, and how long a lease lasts without a heartbeat.
#[derive(Debug, Clone)]
pub struct Worker {
    pub id: String,
    pub lease_ms: i64,
}

impl Worker {
    /// A new worker id, `host:pid:random`, unique across restarts.
    pub fn new(lease_ms: i64) -> Self {
        use rand::Rng;
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
            .map(|h| h.trim().to_string())
            .ok()
            .filter(|h| !h.is_empty())
            .unwrap_or_else(|| "host".into());
        let tag: u32 = rand::rng().random();
        Self {
            id: format!("{host}:{}:{tag:08x}", std::process::id()),
            lease_ms,
        }
    }

    /// How often a running experiment's lease is renewed: a third of the
    /// lease (two heartbeats may be missed), at most once a second.
    pub fn heartbeat(&self) -> Duration {
        Duration::from_millis((self.lease_ms / 3).clamp(100, 1000) as u64)
    }

    /// Longest one store call of a running experiment may take (a quarter
    /// lease): a cut-off database connection (no reset, nothing answered)
    /// cannot hold the supervision loop, so its "no heartbeat for a whole
    /// lease" check still runs, within 1.5 leases of the cut (issue 45 item
    /// 8). A call that times out is dropped: what it was storing is kept
    /// for the next try.
    pub fn store_call(&self) -> Duration {
        Duration::from_millis((self.lease_ms / 4).max(100) as u64)
    }
}

/// The default lease: a worker silent this long loses its run.
pub const LEASE_MS: i64 = 15_000;

/// Claim and run `rig`'s experiments until `shutdown` turns true. Outside
/// the rig's window (if it has one) nothing new starts. On shutdown a
/// running experiment stops within one trial, its finished trials stored,
/// and is marked `interrupted` (it resumes at the next start). With
/// `driver`, experiments run on its threads and hand their units to the
/// workers (`farm.rs`).
pub async fn runner(
    store: Store,
    rig: Arc<dyn Rig>,
    running: Running,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
    me: Arc<Worker>,
    driver: Option<Arc<rayon::ThreadPool>>,
) {
    let id = rig.info().id.clone();
    while !*shutdown.borrow() {
        if !may_start(&store, &id).await {
            continue;
        }
        // With several API processes (PostgreSQL), an attached rig's
        // experiments are claimed by the process its agent is connected
        // to, never by one that could only wait for it.
        if let Some(a) = rig.attached() {
            if store.shared() && !a.connected() {
                tokio::time::sleep(Duration::from_millis(200)).await;
                continue;
            }
        }
        // Woken when work is queued; a run coming due, a lease expiring or
        // a window opening wakes nobody: looked for every 500 ms.
        let queued = store.wakeups().queued.notified();
        tokio::pin!(queued);
        queued.as_mut().enable();
        match store.claim(&id, &me.id, me.lease_ms).await {
            Ok(Some(row)) => {
                let run = Run {
                    store: &store,
                    lease: Lease::of(row.id, row.attempt),
                    shutdown: shutdown.clone(),
                    me: &me,
                };
                let work = Work::Experiment(row.spec);
                run_one(run, rig.clone(), &running, work, driver.clone()).await
            }
            Ok(None) => {
                tokio::select! {
                    _ = &mut queued => {}
                    // (No sender left: nobody can stop this runner but by
                    // dropping it; it stops.)
                    r = shutdown.changed() => if r.is_err() { return; },
                    _ = tokio::time::sleep(Duration::from_millis(500)) => {}
                }
            }
            Err(e) => {
                tracing::error!(error = %e, "claiming the next experiment failed");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// Whether `rig` may start something now: the store is sound and the
/// rig's window (if any) is open. When not, this waits a little first.
async fn may_start(store: &Store, rig: &str) -> bool {
    if store.health().corrupt.is_some() {
        tokio::time::sleep(Duration::from_secs(1)).await;
        return false;
    }
    match store.rig_window(rig).await {
        Ok(Some(w)) => {
            if let Ok(hours) = w.validate() {
                if !hours.is_open(jiff::Timestamp::now()) {
                    tokio::time::sleep(Duration::from_millis(500)).await;
                    return false;
                }
            }
        }
        Ok(None) => {}
        Err(e) => tracing::warn!(error = %e, rig, "reading the rig window failed"),
    }
    true
}

/// Claim and compute `rig`'s work units (`zwidth::farm`) until `shutdown`:
/// one at a time, on the rig's threads, inside its window.
pub async fn unit_runner(
    store: Store,
    rig: Arc<dyn Rig>,
    running: Running,
    mut shutdown: tokio::sync::watch::Receiver<bool>,
    me: Arc<Worker>,
) {
    let id = rig.info().id.clone();
    while !*shutdown.borrow() {
        if !may_start(&store, &id).await {
            continue;
        }
        // Woken when a unit is queued (here or, on PostgreSQL, anywhere);
        // a lease that expires wakes nobody: looked for every 250 ms.
        let queued = store.wakeups().queued.notified();
        tokio::pin!(queued);
        queued.as_mut().enable();
        match store.claim_unit(&id, &me.id, me.lease_ms).await {
            Ok(Some(row)) => {
                let run = Run {
                    store: &store,
                    lease: row.lease(),
                    shutdown: shutdown.clone(),
                    me: &me,
                };
                run_one(run, rig.clone(), &running, Work::Unit(Box::new(row)), None).await
            }
            Ok(None) => {
                tokio::select! {
                    _ = &mut queued => {}
                    // (No sender left: nobody can stop this runner but by
                    // dropping it; it stops.)
                    r = shutdown.changed() => if r.is_err() { return; },
                    _ = tokio::time::sleep(Duration::from_millis(250)) => {}
                }
            }
            Err(e) => {
                tracing::error!(error = %e, "claiming the next unit failed");
                tokio::time::sleep(Duration::from_secs(1)).await;
            }
        }
    }
}

/// Why a rig's `window` keeps it from starting anything at `now` (None:
/// open, or no window).
fn window_closed(
    window: Option<&crate::rig::window::Window>,
    now: jiff::Timestamp,
) -> Option<String> {
    let hours = window?.validate().ok()?;
    if hours.is_open(now) {
        return None;
    }
    let next = hours.next_open(now);
    Some(format!(
        "outside the rig's window (opens again in {} min)",
        (next.as_millisecond() - now.as_millisecond() + 59_999) / 60_000
    ))
}

/// Trials and evaluations finished but not yet stored. A write that fails
/// (disk full, a writer holding the lock) keeps them for the next try; while
/// they cannot be written the simulation is held (it waits between trials),
/// and the experiment shows why in its progress.
#[derive(Default)]
struct Unstored {
    /// The run's lease was taken over: nothing more is written.
    lost: bool,
    trials: Vec<StoredTrial>,
    /// Columns dropped from a map: (scope, B of the first dropped column).
    dropped: Vec<(u32, f64)>,
    evals: Vec<StoredEvaluation>,
    failing_since: Option<std::time::Instant>,
}

impl Unstored {
    /// Store what finished since the last call (and a tune's best so far).
    /// Err: what could not be stored is kept for the next call.
    async fn flush(
        &mut self,
        store: &Store,
        lease: &Lease,
        observer: &Observer,
    ) -> Result<(), Fault> {
        if self.lost {
            return Err(Fault::Lost);
        }
        let new = observer.take_new();
        TRIALS_STORED.fetch_add(new.len() as u64, Ordering::Relaxed);
        self.trials.extend(new);
        self.evals.extend(observer.take_new_evaluations());
        self.dropped.extend(observer.take_dropped());
        let r = async {
            // Dropped columns after the trials, in the same transaction: a
            // dropped column may have had some in this batch.
            let progress = (observer.trials_done() as i64, observer.fraction());
            store
                .add_trials(lease, &self.trials, &self.dropped, progress)
                .await?;
            self.trials.clear();
            self.dropped.clear();
            store
                .add_evaluations(lease, &self.evals, observer.best())
                .await?;
            self.evals.clear();
            Ok::<(), sqlx::Error>(())
        }
        .await;
        match r {
            Ok(()) => {
                if self.failing_since.take().is_some() {
                    tracing::info!("storing works again: the run goes on");
                    observer.hold(None);
                }
                Ok(())
            }
            Err(e) if Fault::of(&e) == Fault::Lost => {
                tracing::warn!(error = %e, "the run's lease was taken over: abandoning it");
                self.lost = true;
                observer.cancel.store(true, Ordering::Relaxed);
                Err(Fault::Lost)
            }
            Err(e) => {
                store.observe(&e);
                if self.failing_since.is_none() {
                    tracing::error!(error = %e, unstored = self.trials.len(), "storing trials failed; retrying");
                    self.failing_since = Some(std::time::Instant::now());
                }
                // Nothing more is computed until what is done is stored.
                observer.hold(Some(format!(
                    "held: {} finished trials cannot be stored ({e}); retrying",
                    self.trials.len()
                )));
                Err(Fault::of(&e))
            }
        }
    }
}

/// Run a store operation, retrying while its fault is transient (another
/// writer holds the lock, the disk is full) with back-off (0.1 s to 5 s);
/// meanwhile `held` (if any) shows why. A permanent fault, or shutdown,
/// ends the retries with the error.
async fn retrying<T, F, Fut>(
    what: &str,
    shutdown: &tokio::sync::watch::Receiver<bool>,
    store: &Store,
    held: Option<&Observer>,
    mut f: F,
) -> Result<T, sqlx::Error>
where
    F: FnMut() -> Fut,
    Fut: std::future::Future<Output = Result<T, sqlx::Error>>,
{
    let mut wait = FIRST_RETRY;
    loop {
        match f().await {
            Ok(v) => {
                if let Some(o) = held {
                    o.hold(None);
                }
                return Ok(v);
            }
            Err(e) => {
                store.observe(&e);
                let transient = matches!(Fault::of(&e), Fault::Busy | Fault::Full);
                if !transient || *shutdown.borrow() {
                    tracing::error!(error = %e, "{what} failed; not retrying");
                    return Err(e);
                }
                if let Some(o) = held {
                    o.hold(Some(format!(
                        "held: {what} cannot be written ({e}); retrying"
                    )));
                }
                tracing::warn!(error = %e, "{what} failed; retrying in {wait:?}");
                tokio::time::sleep(wait).await;
                wait = backoff(wait);
            }
        }
    }
}

/// What a runner claimed: an experiment (its stored spec) or a unit.
enum Work {
    Experiment(String),
    Unit(Box<UnitRow>),
}

/// What runs: an experiment, or one unit of one of its maps.
enum Job {
    Experiment(ExperimentSpec),
    Unit(MapSpec, u32, Unit),
}

impl Job {
    fn run(&self, observer: Arc<Observer>) -> Result<serde_json::Value, crate::error::SpecError> {
        match self {
            Job::Experiment(spec) => spec.run(observer),
            Job::Unit(spec, scope, unit) => {
                run_unit(spec, *scope, *unit, observer).map(|()| serde_json::Value::Null)
            }
        }
    }
}

/// One claimed run, as its steps see it: the store it is written to, the
/// lease every write is fenced by, shutdown, and the worker's lease timing.
struct Run<'a> {
    store: &'a Store,
    lease: Lease,
    shutdown: tokio::sync::watch::Receiver<bool>,
    me: &'a Worker,
}

/// How a run's computation ended, as [`Run::supervise`] saw it.
struct Supervised {
    /// What the computation returned (Err: it panicked).
    outcome: Result<Result<serde_json::Value, crate::error::SpecError>, tokio::task::JoinError>,
    /// Stopped by shutdown: it resumes at the next start.
    interrupted: bool,
    /// What is not stored yet, and whether the lease was lost.
    unstored: Unstored,
}

/// Run an experiment (with `driver`, its units go to the workers and it
/// waits on the driver's threads) or a unit, under `lease`: store its
/// trials as they finish, renew the lease, honour cancel and shutdown, and
/// record its end. Four steps: [`Run::prepare`] (the stored spec checked
/// again), [`Run::resume`] (the stored work read back), [`Run::supervise`]
/// (the computation watched), [`Run::finish`] (its end recorded).
#[tracing::instrument(skip_all, fields(rig = %rig.info().id, id = %run.lease.id, unit = ?run.lease.unit, attempt = run.lease.attempt))]
async fn run_one(
    run: Run<'_>,
    rig: Arc<dyn Rig>,
    running: &Running,
    work: Work,
    driver: Option<Arc<rayon::ThreadPool>>,
) {
    let Some((job, cost, unit)) = run.prepare(work).await else {
        return;
    };
    let Some((done, evals)) = run.resume(unit.as_deref()).await else {
        return;
    };
    let mut observer = Observer::resuming(done).with_evaluations(evals);
    if let Some(backend) = rig.backend(&run.lease.id) {
        observer = observer.with_backend(backend);
    }
    if driver.is_some() {
        observer = observer.with_farm(Arc::new(farm::DbFarm {
            store: run.store.clone(),
            lease: run.lease.clone(),
            handle: tokio::runtime::Handle::current(),
        }));
    }
    let observer = Arc::new(observer);
    observer.limit_trials(usize::try_from(cost.trial_limit()).unwrap_or(usize::MAX));
    let key = match run.lease.unit {
        None => run.lease.id.clone(),
        Some(u) => format!("{}/{}/{}", run.lease.id, u.scope, u.col),
    };
    running
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .insert(key.clone(), observer.clone());
    let obs = observer.clone();
    let on_rig = rig.clone();
    let task = tokio::task::spawn_blocking(move || match driver {
        Some(pool) => pool.install(|| job.run(obs)),
        None => on_rig.pool().install(|| job.run(obs)),
    });
    let ran = run.supervise(task, &observer, rig.as_ref()).await;
    run.finish(ran, &observer).await;
    running
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .remove(&key);
}

impl Run<'_> {
    /// The claimed work as a job and its cost. A stored spec is checked
    /// again: one stored by an older version may not pass today's limits,
    /// and must fail here (recorded so), not take the server down.
    #[tracing::instrument(skip_all)]
    async fn prepare(&self, work: Work) -> Option<(Job, Cost, Option<Box<UnitRow>>)> {
        let (checked, unit) = match work {
            Work::Experiment(spec) => (
                serde_json::from_str::<ExperimentSpec>(&spec)
                    .map_err(|e| format!("stored spec unreadable: {e}"))
                    .and_then(|s| match s.validate() {
                        Ok(cost) => Ok((Job::Experiment(s), cost)),
                        Err(e) => Err(e.to_string()),
                    }),
                None,
            ),
            Work::Unit(row) => (
                serde_json::from_str::<MapSpec>(&row.spec)
                    .map_err(|e| format!("stored unit spec unreadable: {e}"))
                    .and_then(|m| match crate::zwidth::search::validate(&m) {
                        Ok(cost) => Ok((Job::Unit(m, row.scope as u32, row.unit()), cost)),
                        Err(e) => Err(e.to_string()),
                    }),
                Some(row),
            ),
        };
        match checked {
            Ok((job, cost)) => Some((job, cost, unit)),
            Err(e) => {
                let _ = retrying(
                    "recording a failed spec",
                    &self.shutdown,
                    self.store,
                    None,
                    || self.store.finish(&self.lease, Failed, 0, None, Some(&e)),
                )
                .await;
                None
            }
        }
    }

    /// The trials (and a tune's evaluations) an interrupted run stored, to
    /// be replayed, not redone. They are read (retrying while the database
    /// is busy) before anything runs; a run whose stored work cannot be
    /// read fails saying so.
    #[tracing::instrument(skip_all)]
    async fn resume(
        &self,
        unit: Option<&UnitRow>,
    ) -> Option<(Vec<StoredTrial>, Vec<StoredEvaluation>)> {
        let (store, id, shutdown) = (self.store, &self.lease.id, &self.shutdown);
        let stored = async {
            let t = retrying("reading stored trials", shutdown, store, None, || async {
                match unit {
                    Some(row) => store.unit_trials(row).await,
                    None => store.trials(id).await,
                }
            })
            .await?;
            let e = match unit {
                Some(_) => Vec::new(),
                None => {
                    retrying("reading stored evaluations", shutdown, store, None, || {
                        store.evaluations(id)
                    })
                    .await?
                }
            };
            Ok::<_, sqlx::Error>((t, e))
        };
        match stored.await {
            Ok((done, evals)) => {
                tracing::info!(
                    stored_trials = done.len(),
                    stored_evaluations = evals.len(),
                    "starting (stored work is replayed, not redone)"
                );
                Some((done, evals))
            }
            Err(e) => {
                if !*shutdown.borrow() {
                    let why = format!("its stored trials could not be read: {e}");
                    let _ = store.finish(&self.lease, Failed, 0, None, Some(&why)).await;
                }
                None
            }
        }
    }

    /// Watch the computation until it ends. Every 100 ms: store the trials
    /// finished since (one transaction) and look for shutdown; every
    /// heartbeat: renew the lease, write progress, and look for a cancel
    /// request (made by any API process).
    #[tracing::instrument(skip_all)]
    async fn supervise(
        &self,
        mut task: tokio::task::JoinHandle<Result<serde_json::Value, crate::error::SpecError>>,
        observer: &Observer,
        rig: &dyn Rig,
    ) -> Supervised {
        let (store, lease, me) = (self.store, &self.lease, self.me);
        let rig_id = rig.info().id;
        let mut interrupted = false;
        let mut unstored = Unstored::default();
        let mut beat = std::time::Instant::now();
        let mut held_at = std::time::Instant::now();
        let outcome = loop {
            tokio::select! {
                r = &mut task => break r,
                _ = tokio::time::sleep(Duration::from_millis(100)) => {
                    let bound = me.store_call();
                    if tokio::time::timeout(bound, unstored.flush(store, lease, observer)).await.is_err() {
                        tracing::warn!(timeout_ms = bound.as_millis() as u64, "storing the finished trials took too long: kept for the next try");
                    }
                    let trials = observer.trials_done() as i64;
                    if beat.elapsed() >= me.heartbeat() && !unstored.lost {
                        beat = std::time::Instant::now();
                        let beat_call = store.heartbeat(lease, trials, observer.fraction(), me.lease_ms);
                        let answer = match tokio::time::timeout(bound, beat_call).await {
                            Ok(r) => r,
                            Err(_) => Err(sqlx::Error::PoolTimedOut),
                        };
                        match answer {
                            Ok(Held::Held) => held_at = std::time::Instant::now(),
                            Ok(Held::Cancelled) => {
                                held_at = std::time::Instant::now();
                                observer.cancel.store(true, Ordering::Relaxed);
                            }
                            Ok(Held::Lost) => {
                                tracing::warn!("the run's lease was taken over: abandoning it (or, for a unit, its experiment ended)");
                                unstored.lost = true;
                                observer.cancel.store(true, Ordering::Relaxed);
                            }
                            Err(e) => tracing::warn!(error = %e, "heartbeat failed"),
                        }
                        // Unheard for a whole lease, the run may be another
                        // worker's by now: stop computing (and moving a rig).
                        // (SQLite has one process: nobody else can take it.)
                        if !unstored.lost
                            && store.shared()
                            && held_at.elapsed().as_millis() as i64 > me.lease_ms
                        {
                            tracing::warn!(lease_ms = me.lease_ms, "no heartbeat went through for a whole lease: abandoning the run");
                            unstored.lost = true;
                            observer.cancel.store(true, Ordering::Relaxed);
                        }
                    }
                    // Hardware moves only inside its window: an attached rig
                    // takes no new trial once it closes (the experiment waits).
                    if let Some(a) = rig.attached() {
                        if let Ok(Ok(w)) = tokio::time::timeout(bound, store.rig_window(&rig_id)).await {
                            a.set_window_closed(window_closed(w.as_ref(), jiff::Timestamp::now()));
                        }
                    }
                    if *self.shutdown.borrow() && !interrupted {
                        tracing::info!("shutting down: stopping the running experiment");
                        interrupted = true;
                        observer.cancel.store(true, Ordering::Relaxed);
                    }
                }
            }
        };
        Supervised {
            outcome,
            interrupted,
            unstored,
        }
    }

    /// Record the end: every finished trial is stored first (the experiment
    /// stays `running` meanwhile, so its `held` reason shows); then its end
    /// state, or, shut down or unable to store, `interrupted` to resume
    /// from what is stored (never ended with trials lost). A lost lease
    /// writes nothing: another worker holds the run.
    #[tracing::instrument(skip_all)]
    async fn finish(&self, ran: Supervised, observer: &Observer) {
        let (store, lease, shutdown) = (self.store, &self.lease, &self.shutdown);
        let Supervised {
            outcome,
            interrupted,
            mut unstored,
        } = ran;
        let mut wait = FIRST_RETRY;
        let stored_all = loop {
            match unstored.flush(store, lease, observer).await {
                Ok(()) => break true,
                Err(Fault::Busy | Fault::Full) if !*shutdown.borrow() => {
                    tokio::time::sleep(wait).await;
                    wait = backoff(wait);
                }
                Err(_) => break false,
            }
        };
        let trials = observer.trials.load(Ordering::Relaxed) as i64;
        if unstored.lost {
            return;
        }
        if interrupted || !stored_all {
            let _ = retrying(
                "recording an interrupted run",
                shutdown,
                store,
                None,
                // Its trials could not be stored: another try in a minute,
                // not at once in a loop.
                || store.interrupt(lease, trials, if interrupted { 0 } else { 60_000 }),
            )
            .await;
            return;
        }
        let (state, result, error) = match (observer.runaway(), observer.cancelled(), outcome) {
            (Some(why), _, _) => (Failed, None, Some(why)),
            (None, true, _) => (Cancelled, None, None),
            (None, false, Ok(Ok(v))) => (Succeeded, Some(v.to_string()), None),
            (None, false, Ok(Err(e))) => (Failed, None, Some(e.to_string())),
            (None, false, Err(e)) => (Failed, None, Some(format!("the run panicked: {e}"))),
        };
        let what = "recording the end of a run";
        let r = retrying(what, shutdown, store, Some(observer), || {
            store.finish(lease, state, trials, result.as_deref(), error.as_deref())
        })
        .await;
        if let (Err(e), Succeeded) = (&r, state) {
            // A result the database refuses (e.g. too big): say so.
            let why = format!("the result could not be stored: {e}");
            let _ = retrying(what, shutdown, store, Some(observer), || {
                store.finish(lease, Failed, trials, None, Some(&why))
            })
            .await;
        }
    }
}

#[cfg(test)]
mod tests;
