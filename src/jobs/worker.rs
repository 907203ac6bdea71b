//! A worker process (`zwidth worker`): one runner per rig, claiming from
//! the shared database, and its row in the `workers` table, renewed every
//! second (what it runs, trials per second) for `/v1/rigs` and `/metrics`.

use std::sync::Arc;
use std::time::Duration;

use super::{spawn_rig, Running, Worker, TRIALS_STORED};
use crate::rig::Rig;
use crate::store::{Location, OpenError, Store};

/// How often a worker process reports itself.
pub const SEEN_EVERY: Duration = Duration::from_secs(1);

/// Run `rigs` from the database at `db` until Ctrl-C or SIGTERM; then the
/// running experiments stop within a trial, their trials stored, and are
/// left `interrupted` for the next claim. Prints one line on stdout when
/// it is ready.
pub async fn run(db: Location, rigs: Vec<Arc<dyn Rig>>, me: Worker) -> Result<(), OpenError> {
    let store = Store::connect(&db).await?;
    let me = Arc::new(me);
    let running = Running::default();
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let names = rig_names(&rigs);
    let mut tasks = Vec::new();
    for r in &rigs {
        tracing::info!(rig = %r.info().id, parallelism = r.info().parallelism, "rig ready");
        tasks.extend(spawn_rig(&store, r.clone(), &running, &stop_rx, &me));
    }
    let seen = tokio::spawn(announce(
        store.clone(),
        me.clone(),
        names.clone(),
        running.clone(),
        stop_rx,
    ));
    println!("zwidth worker {} running rigs {names} from {db}", me.id);
    use std::io::Write;
    let _ = std::io::stdout().flush();
    shutdown_signal().await;
    tracing::info!("shutting down: stopping the running experiments");
    let _ = stop_tx.send(true);
    for t in tasks {
        let _ = t.await;
    }
    let _ = seen.await;
    let _ = store.worker_gone(&me.id).await;
    let _ = store.close().await;
    Ok(())
}

/// The rigs as `--rigs` lists them: `sim:2,bench:1`.
pub fn rig_names(rigs: &[Arc<dyn Rig>]) -> String {
    rigs.iter()
        .map(|r| {
            let i = r.info();
            format!("{}:{}", i.id, i.parallelism)
        })
        .collect::<Vec<_>>()
        .join(",")
}

/// Report this process in the `workers` table every second until `stop`.
pub async fn announce(
    store: Store,
    me: Arc<Worker>,
    rigs: String,
    running: Running,
    mut stop: tokio::sync::watch::Receiver<bool>,
) {
    // Killed workers never leave the table: forget those unseen for a day.
    let _ = store.prune_workers(86_400_000).await;
    let load = || TRIALS_STORED.load(std::sync::atomic::Ordering::Relaxed);
    let mut mark = (std::time::Instant::now(), load());
    while !*stop.borrow() {
        let ids: Vec<String> = {
            let r = running.lock().unwrap_or_else(|e| e.into_inner());
            let mut ids: Vec<String> = r.keys().cloned().collect();
            ids.sort();
            ids
        };
        let runs = (!ids.is_empty()).then(|| ids.join(","));
        // Trials stored per second since the last report (every thread's).
        let now = (std::time::Instant::now(), load());
        let dt = now.0.duration_since(mark.0).as_secs_f64();
        let rate = if dt > 0.0 {
            now.1.saturating_sub(mark.1) as f64 / dt
        } else {
            0.0
        };
        mark = now;
        if let Err(e) = store
            .worker_seen(&me.id, &rigs, runs.as_deref(), rate)
            .await
        {
            tracing::debug!(error = %e, "reporting this worker failed");
        }
        tokio::select! {
            _ = tokio::time::sleep(SEEN_EVERY) => {}
            _ = stop.changed() => {}
        }
    }
}

/// Ctrl-C or SIGTERM (what `docker stop` sends).
pub async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
}
