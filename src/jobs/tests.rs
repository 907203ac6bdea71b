//! The runner's own tests: cancels, store retries, ends behind a lock.
use super::*;
use crate::store::ExperimentState;
use std::sync::atomic::AtomicUsize;

#[test]
fn a_cancel_reaches_the_running_simulation_at_once() {
    let running: Running = Arc::default();
    let o = Arc::new(Observer::default());
    running.lock().unwrap().insert("a".into(), o.clone());
    assert!(!cancel_running(&running, "b"), "not running here");
    assert!(!o.cancelled());
    assert!(cancel_running(&running, "a"));
    assert!(
        o.cancelled(),
        "the simulation sees it without the runner's look"
    );
}

/// A fresh store in a temporary directory, removed with the guard.
struct TempStore(std::path::PathBuf);
impl Drop for TempStore {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}
async fn temp_store(name: &str) -> (Store, TempStore) {
    let dir = std::env::temp_dir().join(format!("zwidth-jobs-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let store = Store::open(&dir.join("z.db")).await.unwrap();
    (store, TempStore(dir))
}

#[tokio::test]
async fn retrying_waits_out_transient_faults_only() {
    let (store, _guard) = temp_store("retry").await;
    let (_tx, running) = tokio::sync::watch::channel(false);
    // Busy twice (a pool timeout is `Busy`), then it works: retried
    // after 0.1 and 0.2 s, with the reason shown meanwhile.
    let calls = AtomicUsize::new(0);
    let held = Observer::default();
    let r = tokio::time::timeout(
        Duration::from_secs(10),
        retrying("x", &running, &store, Some(&held), || async {
            match calls.fetch_add(1, Ordering::Relaxed) {
                0 | 1 => Err(sqlx::Error::PoolTimedOut),
                _ => Ok(5),
            }
        }),
    )
    .await
    .expect("retries end");
    assert_eq!(r.unwrap(), 5);
    assert_eq!(calls.load(Ordering::Relaxed), 3);
    assert_eq!(held.held(), None, "released once it worked");
    // A fault that always comes back: the calls `retrying` makes.
    let calls_with = |shutdown: bool, fault: fn() -> sqlx::Error| {
        let store = store.clone();
        async move {
            let (_tx, rx) = tokio::sync::watch::channel(shutdown);
            let calls = AtomicUsize::new(0);
            let r: Result<(), _> = tokio::time::timeout(
                Duration::from_secs(10),
                retrying("x", &rx, &store, None, || async {
                    calls.fetch_add(1, Ordering::Relaxed);
                    Err(fault())
                }),
            )
            .await
            .expect("no retry");
            (r, calls.load(Ordering::Relaxed))
        }
    };
    // A permanent fault: one call, the error back.
    let (r, n) = calls_with(false, || sqlx::Error::RowNotFound).await;
    assert!(matches!(r, Err(sqlx::Error::RowNotFound)));
    assert_eq!(n, 1);
    // Transient, but shutting down: no retry either.
    let (r, n) = calls_with(true, || sqlx::Error::PoolTimedOut).await;
    assert!(r.is_err());
    assert_eq!(n, 1);
}

#[test]
fn store_retries_back_off_from_a_tenth_of_a_second_to_five() {
    // The schedule `retrying` documents: 0.1 s, doubling, capped at 5 s.
    let mut w = FIRST_RETRY;
    let mut seen = vec![w.as_millis()];
    for _ in 0..8 {
        w = backoff(w);
        seen.push(w.as_millis());
    }
    assert_eq!(seen, [100, 200, 400, 800, 1600, 3200, 5000, 5000, 5000]);
}

/// The quick spec of tests/it/reliability.rs: one exact strict-passivity
/// point (microseconds of work).
const SMALL: &str = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]}"#;

/// A store with experiment `id` (SMALL) claimed on rig "sim", and a
/// second connection holding SQLite's write lock (`BEGIN IMMEDIATE`).
async fn claimed_behind_a_lock(
    tag: &str,
    id: &str,
) -> (Store, TempStore, sqlx::SqliteConnection, Lease) {
    use sqlx::Connection;
    let (store, guard) = temp_store(tag).await;
    store
        .insert(crate::store::NewExperiment {
            id,
            kind: "map",
            spec: SMALL,
            priority: 0,
            key: None,
            not_before_ms: None,
            rig: "sim",
        })
        .await
        .unwrap();
    let row = store.claim("sim", "w", LEASE_MS).await.unwrap().unwrap();
    assert_eq!((row.id.as_str(), row.attempt), (id, 1));
    let lease = Lease::of(row.id, row.attempt);
    let url = format!("sqlite://{}", guard.0.join("z.db").display());
    let mut lock = sqlx::SqliteConnection::connect(&url).await.unwrap();
    sqlx::query("BEGIN IMMEDIATE")
        .execute(&mut lock)
        .await
        .unwrap();
    (store, guard, lock, lease)
}

#[tokio::test(flavor = "multi_thread")]
async fn a_final_store_blocked_by_another_writer_is_retried_until_it_works() {
    // Another connection holds the write lock for 6 s while the run
    // ends: its final store is busy (the store's busy timeout), retried
    // with back-off, and the run ends `succeeded` with its trial
    // stored, not `interrupted` (that is for shutdown only).
    let (store, _guard, mut lock, lease) = claimed_behind_a_lock("busy-end", "e1").await;
    let release = tokio::spawn(async move {
        tokio::time::sleep(Duration::from_secs(6)).await;
        sqlx::query("ROLLBACK").execute(&mut lock).await.unwrap();
    });
    let rig = Arc::new(crate::rig::SimulatedRig::new("sim", 1).unwrap());
    let (_tx, shutdown) = tokio::sync::watch::channel(false);
    let me = Worker::new(LEASE_MS);
    let run = Run {
        store: &store,
        lease,
        shutdown,
        me: &me,
    };
    let work = Work::Experiment(SMALL.into());
    run_one(run, rig, &Running::default(), work, None).await;
    release.await.unwrap();
    let row = store.get("e1").await.unwrap().unwrap();
    assert_eq!(row.state, ExperimentState::Succeeded, "{:?}", row.error);
    assert_eq!(store.trials("e1").await.unwrap().len(), 1);
}

#[tokio::test(flavor = "multi_thread")]
async fn at_shutdown_a_final_store_blocked_by_another_writer_is_left_to_resume() {
    // Shutting down while another connection holds the write lock: the
    // final store is busy and not retried (the run is left to resume
    // from what is stored at the next start), so the runner returns
    // within a few busy timeouts instead of waiting for the lock.
    let (store, _guard, mut lock, lease) = claimed_behind_a_lock("busy-shutdown", "e2").await;
    let rig = Arc::new(crate::rig::SimulatedRig::new("sim", 1).unwrap());
    let (_tx, shutdown) = tokio::sync::watch::channel(true);
    let me = Worker::new(LEASE_MS);
    let run = Run {
        store: &store,
        lease,
        shutdown,
        me: &me,
    };
    let work = Work::Experiment(SMALL.into());
    let ended = tokio::time::timeout(
        Duration::from_secs(40),
        run_one(run, rig, &Running::default(), work, None),
    )
    .await;
    sqlx::query("ROLLBACK").execute(&mut lock).await.unwrap();
    assert!(ended.is_ok(), "the runner waited for the lock at shutdown");
    assert_ne!(
        store.get("e2").await.unwrap().unwrap().state,
        ExperimentState::Succeeded
    );
}
