//! The database as a [`Farm`] (issue 14): an experiment's run on a shared
//! store (PostgreSQL) queues its maps' units and waits for the workers
//! that claim them (`units.rs`), then replays their stored trials. The run
//! itself stays light: it plans, polls and replays.

use std::collections::BTreeSet;
use std::sync::atomic::Ordering;
use std::time::Duration;

use super::{backoff, FIRST_RETRY};
use crate::store::{Fault, Lease, Store};
use crate::zwidth::farm::{Farm, Unit};
use crate::zwidth::search::Observer;
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
        observer: &Observer,
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
        observer: &Observer,
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
                    observer.cancel.store(true, Ordering::Relaxed);
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
        loop {
            let ended = self.store.wakeups().ended.notified();
            tokio::pin!(ended);
            ended.as_mut().enable();
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
            tokio::select! {
                _ = &mut ended => {}
                _ = tokio::time::sleep(POLL) => {}
            }
        }
    }
}
