//! Work units (issue 14; `zwidth::farm`): the columns of a bisection or
//! grid map, or a whole map, planned by an experiment's run (its driver)
//! and claimed by any worker serving the experiment's rig. Leases as for
//! experiments (`leases.rs`): a claim takes a queued unit or one whose lease
//! expired, adds one to `attempt`, and every write of the unit names that
//! attempt; after `MAX_LOST` expiries the unit fails, and with it its
//! experiment (its driver reads the reason). Only units of running
//! experiments are claimed: a cancelled or failed experiment's units wait
//! for nothing.

use super::db::{on_pool, stored_trials, Db, Store, TrialRow};
use super::lease::{lost, Held, Lease, UnitPlace, MAX_LOST};
use super::state::ExperimentState;
use super::wake::{Wakeups, ENDED, QUEUED};
use crate::clock::now_ms;
use crate::zwidth::farm::{Unit, WHOLE_MAP};
use crate::zwidth::search::StoredTrial;

/// A unit as stored.
#[derive(Debug, Clone, PartialEq, serde::Serialize, sqlx::FromRow, utoipa::ToSchema)]
pub struct UnitRow {
    pub experiment_id: String,
    /// The map within the experiment.
    pub scope: i64,
    /// The column's place in the map's B list; -1: the whole map.
    #[serde(rename = "column")]
    pub col: i64,
    /// The column's damping (N·s/m); none for a whole map.
    pub b: Option<f64>,
    #[serde(skip)]
    pub spec: String,
    pub rig: String,
    #[serde(skip)]
    pub priority: i64,
    #[serde(skip)]
    pub created_ms: i64,
    /// queued, running, done, failed or cancelled.
    pub state: String,
    /// Claims so far (2 or more: a worker's lease ran out).
    pub attempt: i64,
    /// The worker that holds (or last held) it.
    pub worker: Option<String>,
    /// The lease's end (database clock, unix ms).
    pub lease_until_ms: Option<i64>,
    #[serde(skip)]
    pub lost: i64,
    /// Trials done so far.
    pub trials: i64,
    pub error: Option<String>,
}

impl UnitRow {
    /// The unit, as `zwidth::farm` names it.
    pub fn unit(&self) -> Unit {
        match (self.col, self.b) {
            (c, Some(b)) if c >= 0 => Unit::Column {
                column: c as u32,
                b,
            },
            _ => Unit::Map,
        }
    }

    /// The lease a claim returned.
    pub fn lease(&self) -> Lease {
        Lease {
            id: self.experiment_id.clone(),
            attempt: self.attempt,
            unit: Some(UnitPlace {
                scope: self.scope,
                col: self.col,
            }),
        }
    }

    /// "map 2, column 5 (B = 40 N·s/m)" or "map 2".
    pub fn describe(&self) -> String {
        match self.unit() {
            Unit::Column { column, b } => {
                format!("map {}, column {column} (B = {b} N·s/m)", self.scope)
            }
            Unit::Map => format!("map {}", self.scope),
        }
    }
}

/// The units a claim may take, with `$now` the time: `$2` is the rig.
macro_rules! claimable_unit {
    ($now:literal) => {
        concat!(
            "rig = $2 AND state IN ('queued', 'running')
             AND ((state = 'queued' AND (lease_until_ms IS NULL OR lease_until_ms < ", $now, "))
                  OR (state = 'running' AND lease_until_ms < ", $now, "))
             AND EXISTS (SELECT 1 FROM experiments e WHERE e.id = units.experiment_id AND e.state = 'running')"
        )
    };
}

/// What a unit claim writes (as `claim_set!` for experiments).
macro_rules! claim_unit_set {
    ($now:literal) => {
        concat!(
            "state = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN 'failed' ELSE 'running' END,
             error = CASE WHEN state = 'running' AND lost + 1 >= $5
                          THEN 'its worker stopped answering ' || CAST(lost + 1 AS TEXT) || ' times (last ' || COALESCE(worker, '?') || '); not run again'
                          ELSE error END,
             attempt = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN attempt ELSE attempt + 1 END,
             worker = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN worker ELSE $3 END,
             lease_until_ms = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN NULL ELSE ", $now, " + $4 END,
             lost = lost + CASE WHEN state = 'running' THEN 1 ELSE 0 END"
        )
    };
}

/// A unit's state as its heartbeat and writes name it.
fn unit_state(state: ExperimentState) -> &'static str {
    match state {
        ExperimentState::Succeeded => "done",
        ExperimentState::Cancelled => "cancelled",
        _ => "failed",
    }
}

/// The longest the listener's connect or LISTEN may take.
const LISTEN_CALL: std::time::Duration = std::time::Duration::from_secs(10);
/// Without a notification this long, the listener reconnects (a connection
/// silently cut off shows no error: this bounds how long it goes unheard).
const LISTEN_QUIET: std::time::Duration = std::time::Duration::from_secs(60);

impl Store {
    /// The wake-ups of this store's units.
    pub fn wakeups(&self) -> &Wakeups {
        &self.wake
    }

    /// On PostgreSQL, relay other processes' unit notifications to
    /// [`Store::wakeups`] (once per store; the listener reconnects after a
    /// lost connection). Nothing on SQLite (one process).
    pub fn listen(&self) {
        let Db::Postgres(pool) = &self.db else {
            return;
        };
        if self
            .wake
            .listening
            .swap(true, std::sync::atomic::Ordering::Relaxed)
        {
            return;
        }
        // The listener holds its connection for good: one of its own, not
        // one of the store's pool.
        let own = sqlx::postgres::PgPoolOptions::new()
            .max_connections(1)
            .connect_lazy_with((*pool.connect_options()).clone());
        let (pool, wake) = (pool.clone(), self.wake.clone());
        tokio::spawn(async move {
            loop {
                // Every call bounded (issue 45 item 8): a connection cut off
                // mid-statement would otherwise hold the listener for good.
                // Quiet for LISTEN_QUIET, the listener starts again on a new
                // connection (notifications are best effort: waiters poll).
                let relay = async {
                    let bounded = |what: &'static str| {
                        move |_| sqlx::Error::Protocol(format!("{what} took over {LISTEN_CALL:?}"))
                    };
                    let mut l = tokio::time::timeout(
                        LISTEN_CALL,
                        sqlx::postgres::PgListener::connect_with(&own),
                    )
                    .await
                    .map_err(bounded("connecting the listener"))??;
                    tokio::time::timeout(LISTEN_CALL, l.listen_all([QUEUED, ENDED]))
                        .await
                        .map_err(bounded("LISTEN"))??;
                    loop {
                        let Ok(n) = tokio::time::timeout(LISTEN_QUIET, l.recv()).await else {
                            return Ok(());
                        };
                        let n = n?;
                        match n.channel() {
                            QUEUED => wake.queued.notify_waiters(),
                            _ => {
                                let _ = wake.ended.send(n.payload().to_string());
                            }
                        }
                    }
                };
                let r: Result<(), sqlx::Error> = relay.await;
                if let Err(e) = r {
                    tracing::debug!(error = %e, "unit notifications lost; listening again in 1 s");
                }
                if pool.is_closed() {
                    return;
                }
                tokio::time::sleep(std::time::Duration::from_secs(1)).await;
            }
        });
    }

    /// Tell other processes (PostgreSQL) and this one that units were
    /// queued or one ended, after the write. Best effort: the write stands
    /// whatever happens here (waiters poll too).
    pub(super) async fn notify_units(&self, channel: &str, payload: &str) {
        if let Db::Postgres(p) = &self.db {
            if let Err(e) = sqlx::query("SELECT pg_notify($1, $2)")
                .bind(channel)
                .bind(payload)
                .execute(p)
                .await
            {
                tracing::debug!(error = %e, channel, "notifying other workers failed");
            }
        }
        match channel {
            QUEUED => self.wake.queued.notify_waiters(),
            _ => {
                let _ = self.wake.ended.send(payload.to_string());
            }
        }
    }

    /// Queue `units` of map `scope` of the experiment `lease` holds, whose
    /// spec is `spec` (JSON); units planned before are left as they are,
    /// but for cancelled ones, which are queued again.
    /// Nothing when the lease is lost.
    pub async fn plan_units(
        &self,
        lease: &Lease,
        scope: u32,
        spec: &str,
        units: &[Unit],
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            // The fence, as for trials: the experiment row stays locked
            // until the commit.
            let held = sqlx::query(
                "UPDATE experiments SET lease_until_ms = lease_until_ms WHERE id = $1 AND attempt = $2 AND state = 'running'",
            )
            .bind(&lease.id)
            .bind(lease.attempt)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if held != 1 {
                tx.rollback().await?;
                return Err(lost(lease));
            }
            for u in units {
                let b = match u {
                    Unit::Column { b, .. } => Some(*b),
                    Unit::Map => None,
                };
                sqlx::query(
                    "INSERT INTO units (experiment_id, scope, col, b, spec, rig, priority, created_ms, state)
                     SELECT id, $2, $3, $4, $5, rig, priority, created_ms, 'queued' FROM experiments WHERE id = $1
                     ON CONFLICT (experiment_id, scope, col) DO UPDATE SET state = 'queued', lease_until_ms = NULL
                     WHERE units.state = 'cancelled'",
                )
                .bind(&lease.id)
                .bind(i64::from(scope))
                .bind(u.column_key())
                .bind(b)
                .bind(spec)
                .execute(&mut *tx)
                .await?;
            }
            tx.commit().await
        })?;
        self.notify_units(QUEUED, &lease.id).await;
        Ok(())
    }

    /// The units of map `scope` of experiment `id`, by column (a whole
    /// map's first).
    pub async fn units_of(&self, id: &str, scope: u32) -> Result<Vec<UnitRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as::<_, UnitRow>(
            "SELECT * FROM units WHERE experiment_id = $1 AND scope = $2 ORDER BY col",
        )
        .bind(id)
        .bind(i64::from(scope))
        .fetch_all(p)
        .await)
    }

    /// Every unit of experiment `id`, by map and column.
    pub async fn units(&self, id: &str) -> Result<Vec<UnitRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as::<_, UnitRow>(
            "SELECT * FROM units WHERE experiment_id = $1 ORDER BY scope, col",
        )
        .bind(id)
        .fetch_all(p)
        .await)
    }

    /// The units running on `rig`, oldest experiment first.
    /// (Under a live lease: a unit whose worker died is not computing.)
    pub async fn running_units(&self, rig: &str) -> Result<Vec<UnitRow>, sqlx::Error> {
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query_as::<_, UnitRow>(
            "SELECT * FROM units WHERE rig = $1 AND state = 'running' AND lease_until_ms >= $2
             ORDER BY created_ms, experiment_id, scope, col",
        )
        .bind(rig)
        .bind(now)
        .fetch_all(p)
        .await)
    }

    /// The units of experiment `id` not done yet are cancelled: it ended
    /// (their holders' next heartbeat or write finds them gone, and no
    /// claim looks at them again).
    pub(super) async fn end_units(&self, id: &str) -> Result<(), sqlx::Error> {
        on_pool!(self, p => sqlx::query(
            "UPDATE units SET state = 'cancelled', lease_until_ms = NULL
             WHERE experiment_id = $1 AND state IN ('queued', 'running')",
        )
        .bind(id)
        .execute(p)
        .await
        .map(|_| ()))
    }

    /// The stored trials of a unit: its column's, or its whole map's.
    pub async fn unit_trials(&self, unit: &UnitRow) -> Result<Vec<StoredTrial>, sqlx::Error> {
        if unit.col == WHOLE_MAP {
            return self
                .trials_page(&unit.experiment_id, Some(unit.scope as u32), 0, i64::MAX)
                .await;
        }
        let rows: Vec<TrialRow> = on_pool!(self, p => sqlx::query_as(
            "SELECT scope, col, idx, point FROM trials WHERE experiment_id = $1 AND scope = $2 AND col = $3 ORDER BY idx",
        )
        .bind(&unit.experiment_id)
        .bind(unit.scope)
        .bind(unit.col)
        .fetch_all(p)
        .await)?;
        Ok(stored_trials(rows))
    }

    /// Claim `rig`'s next unit for `worker`, holding it for `lease_ms`:
    /// of running experiments, the highest priority, the oldest experiment,
    /// then by map and column; a unit queued, or running under an expired
    /// lease (failed instead at its `MAX_LOST`-th expiry). One statement,
    /// as [`Store::claim`].
    pub async fn claim_unit(
        &self,
        rig: &str,
        worker: &str,
        lease_ms: i64,
    ) -> Result<Option<UnitRow>, sqlx::Error> {
        self.writable()?;
        loop {
            let row = match &self.db {
                Db::Sqlite(p) => sqlx::query_as::<_, UnitRow>(concat!(
                    "UPDATE units SET ",
                    claim_unit_set!("$1"),
                    " WHERE (experiment_id, scope, col) = (SELECT experiment_id, scope, col FROM units WHERE ",
                    claimable_unit!("$1"),
                    " ORDER BY priority DESC, created_ms, experiment_id, scope, col LIMIT 1) RETURNING *"
                ))
                .bind(now_ms())
                .bind(rig)
                .bind(worker)
                .bind(lease_ms)
                .bind(MAX_LOST)
                .fetch_all(p)
                .await?
                .pop(),
                Db::Postgres(p) => sqlx::query_as::<_, UnitRow>(concat!(
                    "WITH clock AS (SELECT CAST(EXTRACT(EPOCH FROM clock_timestamp()) * 1000 AS BIGINT) AS now),
                     next AS MATERIALIZED (
                         SELECT experiment_id, scope, col FROM units, clock WHERE ",
                    claimable_unit!("clock.now"),
                    " ORDER BY priority DESC, created_ms, experiment_id, scope, col LIMIT 1 FOR UPDATE OF units SKIP LOCKED)
                     UPDATE units SET ",
                    claim_unit_set!("clock.now"),
                    " FROM next, clock WHERE units.experiment_id = next.experiment_id AND units.scope = next.scope AND units.col = next.col
                     RETURNING units.*"
                ))
                .bind(0_i64)
                .bind(rig)
                .bind(worker)
                .bind(lease_ms)
                .bind(MAX_LOST)
                .fetch_all(p)
                .await?
                .pop(),
            };
            match row {
                Some(r) if r.state == "failed" => continue,
                other => return Ok(other),
            }
        }
    }

    /// [`Store::heartbeat`] of a unit: extend its lease and record its
    /// trials; `Cancelled` once its experiment is not running any more.
    pub(super) async fn unit_heartbeat(
        &self,
        lease: &Lease,
        at: UnitPlace,
        trials: i64,
        lease_ms: i64,
    ) -> Result<Held, sqlx::Error> {
        let now = self.db_now_ms().await?;
        let held: Vec<String> = on_pool!(self, p => sqlx::query_scalar(
            "UPDATE units SET lease_until_ms = $1 + $2, trials = $3
             WHERE experiment_id = $4 AND scope = $5 AND col = $6 AND attempt = $7 AND state = 'running'
             RETURNING experiment_id",
        )
        .bind(now)
        .bind(lease_ms)
        .bind(trials)
        .bind(&lease.id)
        .bind(at.scope)
        .bind(at.col)
        .bind(lease.attempt)
        .fetch_all(p)
        .await)?;
        if held.is_empty() {
            return Ok(Held::Lost);
        }
        // Its experiment ended: stop. Running, or waiting for a driver (a
        // driver shut down leaves it interrupted): the unit goes on, its
        // result is what the next driver replays.
        Ok(match self.state(&lease.id).await? {
            Some(s) if !s.ended() => Held::Held,
            _ => Held::Cancelled,
        })
    }

    /// [`Store::add_trials`] of a unit: its trials, fenced by its lease, and
    /// the columns a whole-map unit's automatic B range ran past (`dropped`;
    /// the unit owns its map). On PostgreSQL a unit's trial writes do not
    /// wait for the disk (`synchronous_commit` off for their transactions):
    /// a server crash may lose the last few of them (never part of one;
    /// the unit, still `running`, is claimed again when its lease runs out
    /// and computes them again). Its end waits for the disk, which makes
    /// every earlier write of it durable (WAL order) before its driver can
    /// read `done`.
    pub(super) async fn add_unit_trials(
        &self,
        lease: &Lease,
        at: UnitPlace,
        trials: &[StoredTrial],
        dropped: &[(u32, f64)],
        done: i64,
    ) -> Result<(), sqlx::Error> {
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            if self.shared() {
                sqlx::query("SET LOCAL synchronous_commit TO OFF").execute(&mut *tx).await?;
            }
            let held = sqlx::query(
                "UPDATE units SET trials = $1
                 WHERE experiment_id = $2 AND scope = $3 AND col = $4 AND attempt = $5 AND state = 'running'",
            )
            .bind(done)
            .bind(&lease.id)
            .bind(at.scope)
            .bind(at.col)
            .bind(lease.attempt)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if held != 1 {
                tx.rollback().await?;
                return Err(lost(lease));
            }
            super::lease::insert_trials!(tx, &lease.id, trials);
            for &(scope, b) in dropped.iter().filter(|(s, _)| i64::from(*s) == at.scope) {
                sqlx::query("DELETE FROM trials WHERE experiment_id = $1 AND scope = $2 AND b >= $3")
                    .bind(&lease.id)
                    .bind(i64::from(scope))
                    .bind(b)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await
        })
    }

    /// [`Store::finish`] of a unit: `succeeded` is stored as `done`.
    pub(super) async fn finish_unit(
        &self,
        lease: &Lease,
        at: UnitPlace,
        state: ExperimentState,
        trials: i64,
        error: Option<&str>,
    ) -> Result<bool, sqlx::Error> {
        // Waiting for the disk (unlike its trial writes): its driver reads
        // `done` only once this and every earlier write of the unit are
        // durable.
        let r = on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let r = sqlx::query(
                "UPDATE units SET state = $1, trials = $2, error = $3, lease_until_ms = NULL
                 WHERE experiment_id = $4 AND scope = $5 AND col = $6 AND attempt = $7 AND state = 'running'",
            )
            .bind(unit_state(state))
            .bind(trials)
            .bind(error)
            .bind(&lease.id)
            .bind(at.scope)
            .bind(at.col)
            .bind(lease.attempt)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            tx.commit().await?;
            Ok::<u64, sqlx::Error>(r)
        })?;
        if r == 1 {
            self.notify_units(ENDED, &lease.id).await;
        }
        Ok(r == 1)
    }

    /// [`Store::interrupt`] of a unit: queued again, at once or after
    /// `retry_in_ms`.
    pub(super) async fn interrupt_unit(
        &self,
        lease: &Lease,
        at: UnitPlace,
        trials: i64,
        retry_in_ms: i64,
    ) -> Result<(), sqlx::Error> {
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query(
            "UPDATE units SET state = 'queued', trials = $1, lease_until_ms = CASE WHEN $2 > 0 THEN $3 + $2 END
             WHERE experiment_id = $4 AND scope = $5 AND col = $6 AND attempt = $7 AND state = 'running'",
        )
        .bind(trials)
        .bind(retry_in_ms)
        .bind(now)
        .bind(&lease.id)
        .bind(at.scope)
        .bind(at.col)
        .bind(lease.attempt)
        .execute(p)
        .await
        .map(|_| ()))?;
        self.notify_units(QUEUED, &lease.id).await;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(col: i64, b: Option<f64>) -> UnitRow {
        UnitRow {
            experiment_id: "e1".into(),
            scope: 2,
            col,
            b,
            spec: "{}".into(),
            rig: "sim".into(),
            priority: 0,
            created_ms: 0,
            state: "queued".into(),
            attempt: 0,
            worker: None,
            lease_until_ms: None,
            lost: 0,
            trials: 0,
            error: None,
        }
    }

    /// The stored column key decides what a unit is: a column at its
    /// place with its B, and the whole map at `WHOLE_MAP` whatever B a
    /// row carries (`plan_units` writes none there; a mutant that let any
    /// row with a B be a column passed the store's tests).
    #[test]
    fn the_column_key_decides_a_unit_s_kind() {
        assert_eq!(
            row(3, Some(40.0)).unit(),
            Unit::Column { column: 3, b: 40.0 }
        );
        assert_eq!(row(WHOLE_MAP, None).unit(), Unit::Map);
        assert_eq!(row(WHOLE_MAP, Some(40.0)).unit(), Unit::Map);
        assert_eq!(row(3, None).unit(), Unit::Map);
        assert_eq!(
            row(3, Some(40.0)).describe(),
            "map 2, column 3 (B = 40 N·s/m)"
        );
        assert_eq!(row(WHOLE_MAP, None).describe(), "map 2");
    }
}
