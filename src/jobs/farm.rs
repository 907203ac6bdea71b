//! The database as a [`Farm`] (issue 14): an experiment's run on a shared
//! store (PostgreSQL) queues its maps' units and waits for the workers
//! that claim them (`units.rs`), then replays their stored trials. The run
//! itself stays light: it plans, polls and replays.

use std::collections::BTreeSet;
use std::time::Duration;

use super::retry::{backoff, FIRST_RETRY};
use crate::store::{Fault, Lease, Store};
use crate::zwidth::control::RunControl;
use crate::zwidth::farm::{Farm, Unit};
use crate::zwidth::settings::MapSpec;

/// How often a waiting run looks at its units when no unit's end wakes it
/// (see `Wakeups`).
const POLL: Duration = Duration::from_millis(250);

/// The units of the experiment `lease` holds, queued in `store`; waited
/// for on `handle` (the runtime the run's runner is on).
pub struct DbFarm {
    pub store: Store,
    pub lease: Lease,
    pub handle: tokio::runtime::Handle,
}

/// Whether a store fault goes away by itself (the lock, a full disk).
fn transient(e: &sqlx::Error) -> bool {
    matches!(Fault::of(e), Fault::Busy | Fault::Full)
}

impl Farm for DbFarm {
    fn run(
        &self,
        scope: u32,
        spec: &MapSpec,
        units: &[Unit],
        observer: &dyn RunControl,
        done: &(dyn Fn(usize) + Sync),
    ) -> Result<(), String> {
        let spec = serde_json::to_string(spec).map_err(|e| e.to_string())?;
        self.handle
            .block_on(self.wait(scope, &spec, units, observer, done))
    }
}

impl DbFarm {
    async fn wait(
        &self,
        scope: u32,
        spec: &str,
        units: &[Unit],
        observer: &dyn RunControl,
        done: &(dyn Fn(usize) + Sync),
    ) -> Result<(), String> {
        let mut pause = FIRST_RETRY;
        // Plan (again, after a takeover: planned units stay as they are).
        loop {
            if observer.cancelled() {
                return Ok(());
            }
            match self.store.plan_units(&self.lease, scope, spec, units).await {
                Ok(()) => break,
                // Another worker runs the experiment now: stop; its runner
                // learns it at the next heartbeat and writes nothing.
                Err(e) if Fault::of(&e) == Fault::Lost => {
                    observer.cancel();
                    return Ok(());
                }
                Err(e) if transient(&e) => {
                    tracing::warn!(error = %e, scope, "queueing units failed; retrying in {pause:?}");
                    tokio::time::sleep(pause).await;
                    pause = backoff(pause);
                }
                Err(e) => return Err(format!("the units of map {scope} could not be queued: {e}")),
            }
        }
        let want: BTreeSet<i64> = units.iter().map(Unit::column_key).collect();
        // Woken when a unit of this experiment ends (here or, on
        // PostgreSQL, anywhere); other experiments' units wake nobody here.
        let mut ended = self.store.wakeups().ended.subscribe();
        loop {
            if observer.cancelled() {
                observer.set_elsewhere(scope, 0);
                return Ok(());
            }
            match self.store.units_of(&self.lease.id, scope).await {
                Ok(rows) => {
                    let mine: Vec<_> = rows.iter().filter(|r| want.contains(&r.col)).collect();
                    if let Some(f) = mine.iter().find(|r| r.state == "failed") {
                        return Err(format!(
                            "{} failed: {}",
                            f.describe(),
                            f.error.as_deref().unwrap_or("no reason given")
                        ));
                    }
                    let finished = mine.iter().filter(|r| r.state == "done").count();
                    observer
                        .set_elsewhere(scope, mine.iter().map(|r| r.trials.max(0) as usize).sum());
                    done(finished);
                    if finished == want.len() {
                        match self
                            .store
                            .trials_page(&self.lease.id, Some(scope), 0, i64::MAX)
                            .await
                        {
                            Ok(trials) => {
                                observer.add_done(trials);
                                observer.set_elsewhere(scope, 0);
                                return Ok(());
                            }
                            Err(e) if transient(&e) => {}
                            Err(e) => {
                                return Err(format!(
                                    "the trials of map {scope} could not be read: {e}"
                                ))
                            }
                        }
                    }
                }
                Err(e) if transient(&e) => {}
                Err(e) => return Err(format!("the units of map {scope} could not be read: {e}")),
            }
            let look = tokio::time::sleep(POLL);
            tokio::pin!(look);
            loop {
                tokio::select! {
                    r = ended.recv() => match r {
                        Ok(id) if id != self.lease.id => continue,
                        // Ours, or some missed (lagged): look.
                        Ok(_) | Err(tokio::sync::broadcast::error::RecvError::Lagged(_)) => break,
                        Err(tokio::sync::broadcast::error::RecvError::Closed) => {
                            (&mut look).await;
                            break;
                        }
                    },
                    _ = &mut look => break,
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::store::{ExperimentState, NewExperiment};
    use crate::zwidth::search::run_unit;
    use crate::zwidth::search::Observer;
    use crate::zwidth::search::{map, map_observed};
    use std::sync::Arc;

    /// The 2011 device in the time domain, two B columns (draft accuracy):
    /// a few dozen trials.
    fn two_columns() -> MapSpec {
        serde_json::from_str(
            r#"{"scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
                "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability",
                "accuracy":"draft","b":[0,10]}"#,
        )
        .unwrap()
    }

    /// A SQLite store in a fresh directory (removed by the guard) with
    /// experiment "e" claimed: the store and the driver's lease.
    async fn claimed(tag: &str) -> (Store, Lease, TempDir) {
        let dir = std::env::temp_dir().join(format!("zwidth-farm-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let store = Store::open(&dir.join("z.db")).await.unwrap();
        store
            .insert(NewExperiment::queued("e", "map", "{}", "sim"))
            .await
            .unwrap();
        let row = store.claim("sim", "driver", 60_000).await.unwrap().unwrap();
        (store, Lease::of(row.id, row.attempt), TempDir(dir))
    }

    struct TempDir(std::path::PathBuf);
    impl Drop for TempDir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }

    /// A worker on `store`: claim `n` units and compute them with
    /// `run_unit` (or fail them with `fail`), storing their trials.
    async fn work(store: &Store, n: usize, fail: Option<&str>) {
        let mut left = n;
        while left > 0 {
            let Some(u) = store.claim_unit("sim", "worker", 60_000).await.unwrap() else {
                tokio::time::sleep(Duration::from_millis(20)).await;
                continue;
            };
            let lease = u.lease();
            if let Some(why) = fail {
                assert!(store
                    .finish(&lease, ExperimentState::Failed, 0, None, Some(why))
                    .await
                    .unwrap());
            } else {
                let spec: MapSpec = serde_json::from_str(&u.spec).unwrap();
                let own = Arc::new(Observer::default());
                let (o, unit, scope) = (own.clone(), u.unit(), u.scope as u32);
                tokio::task::spawn_blocking(move || run_unit(&spec, scope, unit, o))
                    .await
                    .unwrap()
                    .unwrap();
                let trials = own.take_new();
                let n = trials.len() as i64;
                store
                    .add_trials(&lease, &trials, &[], (n, 1.0))
                    .await
                    .unwrap();
                assert!(store
                    .finish(&lease, ExperimentState::Succeeded, n, None, None)
                    .await
                    .unwrap());
            }
            left -= 1;
        }
    }

    /// The driver's side: `spec` as map `scope` through a `DbFarm`, off the
    /// runtime's workers (as the runner runs it).
    fn drive(
        store: &Store,
        lease: &Lease,
        spec: &MapSpec,
        scope: u32,
    ) -> (
        Arc<Observer>,
        tokio::task::JoinHandle<crate::zwidth::search::MapResult>,
    ) {
        let farm = Arc::new(DbFarm {
            store: store.clone(),
            lease: lease.clone(),
            handle: tokio::runtime::Handle::current(),
        });
        let o = Arc::new(Observer::default().with_farm(farm));
        let (obs, spec) = (o.clone(), spec.clone());
        let task =
            tokio::task::spawn_blocking(move || map_observed(&spec, Some(obs), scope).unwrap());
        (o, task)
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_map_farmed_through_the_database_equals_one_process() {
        let (store, lease, _dir) = claimed("equal").await;
        let spec = two_columns();
        let (o, driver) = drive(&store, &lease, &spec, 3);
        work(&store, 2, None).await;
        let r = tokio::time::timeout(Duration::from_secs(30), driver)
            .await
            .expect("the driver saw its units end")
            .unwrap();
        let one = map(&spec).unwrap();
        assert_eq!(r.points, one.points);
        assert_eq!(r.boundary, one.boundary);
        assert_eq!(o.runaway(), None);
        // Every trial came from the units: the driver computed none.
        assert!(o.take_new().is_empty());
        assert_eq!(o.trials_done(), one.trials);
        // Two column units, done, with the map's trials between them.
        let units = store.units("e").await.unwrap();
        let shape: Vec<_> = units
            .iter()
            .map(|u| (u.scope, u.col, u.b, u.state.as_str()))
            .collect();
        assert_eq!(
            shape,
            [(3, 0, Some(0.0), "done"), (3, 1, Some(10.0), "done")]
        );
        assert_eq!(
            units.iter().map(|u| u.trials).sum::<i64>(),
            one.trials as i64
        );
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_failed_unit_fails_its_map_with_the_reason() {
        let (store, lease, _dir) = claimed("fail").await;
        let spec = two_columns();
        let (o, driver) = drive(&store, &lease, &spec, 0);
        work(
            &store,
            1,
            Some("its worker stopped answering 3 times (last w9)"),
        )
        .await;
        tokio::time::timeout(Duration::from_secs(30), driver)
            .await
            .expect("the driver saw the failure")
            .unwrap();
        assert_eq!(
            o.runaway().as_deref(),
            Some("map 0, column 0 (B = 0 N·s/m) failed: its worker stopped answering 3 times (last w9)")
        );
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_driver_whose_lease_is_lost_stops_without_planning() {
        let (store, _lease, _dir) = claimed("lost").await;
        let spec = two_columns();
        let (o, driver) = drive(&store, &Lease::of("e", 9), &spec, 0);
        tokio::time::timeout(Duration::from_secs(30), driver)
            .await
            .expect("the driver stopped")
            .unwrap();
        assert!(o.cancelled());
        assert_eq!(o.runaway(), None);
        assert!(store.units("e").await.unwrap().is_empty());
    }
}
