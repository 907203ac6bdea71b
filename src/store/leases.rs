//! Claiming experiments with leases (issue 14). A worker claims a runnable
//! experiment and holds it until `lease_until_ms`, extending the lease with
//! each heartbeat; every claim adds one to `attempt`, and every write of the
//! run names the attempt it holds: a worker whose lease expired and was
//! claimed by another changes nothing (its writes answer `Fault::Lost`) and
//! abandons the run. An expired lease is claimed again by the next claim
//! itself; after `MAX_LOST` expiries the experiment fails saying why. Time
//! is the database's clock (PostgreSQL's `clock_timestamp()`; SQLite has
//! one process on one machine, whose clock it is).

use super::db::{on_pool, Db, ExperimentRow, Store};
use super::lease::{fraction_done, lost, Held, Lease, MAX_LOST};
use super::state::ExperimentState;
use crate::clock::now_ms;
use crate::zwidth::search::{StoredEvaluation, StoredTrial};

/// The rows a claim may take, with `$now` the time (unix ms): `$2` is the
/// rig. (The first line is the `experiments_claimable` index's predicate,
/// so the claim reads that index, not every finished run.) (A macro: sqlx takes only fixed SQL, so the statement is built at
/// compile time.)
macro_rules! claimable {
    ($now:literal) => {
        concat!(
            "rig = $2 AND state IN ('queued', 'scheduled', 'interrupted', 'running')
             AND (SELECT paused FROM queue_control WHERE id = 1) = 0
             AND ((state IN ('queued', 'scheduled') AND (not_before_ms IS NULL OR not_before_ms <= ", $now, "))
                  OR (state = 'interrupted' AND (lease_until_ms IS NULL OR lease_until_ms < ", $now, "))
                  OR (state = 'running' AND lease_until_ms < ", $now, "))"
        )
    };
}

/// What a claim writes: the lease to worker `$3` for `$4` ms, or, for a
/// run whose lease expired for the `$5`-th time, its failure with the
/// reason. (Every SET expression reads the row as it was.)
macro_rules! claim_set {
    ($now:literal) => {
        concat!(
            "state = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN 'failed' ELSE 'running' END,
             error = CASE WHEN state = 'running' AND lost + 1 >= $5
                          THEN 'its worker stopped answering ' || CAST(lost + 1 AS TEXT) || ' times (last ' || COALESCE(worker, '?') || '); not run again'
                          ELSE error END,
             finished_ms = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN ", $now, " ELSE finished_ms END,
             started_ms = COALESCE(started_ms, ", $now, "),
             attempt = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN attempt ELSE attempt + 1 END,
             worker = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN worker ELSE $3 END,
             lease_until_ms = CASE WHEN state = 'running' AND lost + 1 >= $5 THEN NULL ELSE ", $now, " + $4 END,
             lost = lost + CASE WHEN state = 'running' THEN 1 ELSE 0 END"
        )
    };
}

/// A worker process as it last reported itself.
#[derive(Debug, Clone, serde::Serialize, sqlx::FromRow, utoipa::ToSchema)]
pub struct WorkerRow {
    /// host:pid:random
    pub id: String,
    /// The rigs it runs, as given to `--rigs`.
    pub rigs: String,
    pub started_ms: i64,
    /// Its last heartbeat (database clock, unix ms).
    pub seen_ms: i64,
    /// The experiment it runs, if any.
    pub running: Option<String>,
    /// Trials per second of that run, over its last second.
    pub trials_per_s: f64,
}

impl Store {
    /// The database's clock, unix ms.
    pub async fn db_now_ms(&self) -> Result<i64, sqlx::Error> {
        match &self.db {
            Db::Sqlite(_) => Ok(now_ms()),
            Db::Postgres(p) => {
                sqlx::query_scalar(
                    "SELECT CAST(EXTRACT(EPOCH FROM clock_timestamp()) * 1000 AS BIGINT)",
                )
                .fetch_one(p)
                .await
            }
        }
    }

    /// Claim `rig`'s next runnable experiment for `worker`, holding it for
    /// `lease_ms`: the highest priority, oldest first, of those queued,
    /// scheduled and due, interrupted (and due), or running under an
    /// expired lease; none while the queue is paused. A run whose lease
    /// expires for the `MAX_LOST`-th time is failed with the reason instead
    /// (and the next one claimed). One statement: on PostgreSQL the row is
    /// locked by the claim that found it first (`FOR UPDATE SKIP LOCKED` in
    /// a materialized CTE: the others skip it) and the time is the
    /// server's `clock_timestamp()`.
    pub async fn claim(
        &self,
        rig: &str,
        worker: &str,
        lease_ms: i64,
    ) -> Result<Option<ExperimentRow>, sqlx::Error> {
        self.writable()?;
        // Each pass claims one row or fails one run at its last life.
        loop {
            let row = match &self.db {
                Db::Sqlite(p) => sqlx::query_as::<_, ExperimentRow>(concat!(
                    "UPDATE experiments SET ",
                    claim_set!("$1"),
                    " WHERE id = (SELECT id FROM experiments WHERE ",
                    claimable!("$1"),
                    " ORDER BY priority DESC, created_ms, id LIMIT 1) RETURNING *"
                ))
                .bind(now_ms())
                .bind(rig)
                .bind(worker)
                .bind(lease_ms)
                .bind(MAX_LOST)
                .fetch_all(p)
                .await?
                .pop(),
                Db::Postgres(p) => sqlx::query_as::<_, ExperimentRow>(concat!(
                    "WITH clock AS (SELECT CAST(EXTRACT(EPOCH FROM clock_timestamp()) * 1000 AS BIGINT) AS now),
                     next AS MATERIALIZED (
                         SELECT id FROM experiments, clock WHERE ",
                    claimable!("clock.now"),
                    " ORDER BY priority DESC, created_ms, id LIMIT 1 FOR UPDATE OF experiments SKIP LOCKED)
                     UPDATE experiments SET ",
                    claim_set!("clock.now"),
                    " FROM next, clock WHERE experiments.id = next.id RETURNING experiments.*"
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
                Some(r) if r.state == ExperimentState::Failed => {
                    self.end_units(&r.id).await?;
                    continue;
                }
                other => return Ok(other),
            }
        }
    }

    /// Extend the lease by `lease_ms` and record progress, if the run is
    /// still ours; say whether it is (and whether it was cancelled).
    pub async fn heartbeat(
        &self,
        lease: &Lease,
        trials: i64,
        fraction: f64,
        lease_ms: i64,
    ) -> Result<Held, sqlx::Error> {
        self.writable()?;
        if let Some(at) = lease.unit {
            return self.unit_heartbeat(lease, at, trials, lease_ms).await;
        }
        let now = self.db_now_ms().await?;
        let fraction = fraction_done(fraction);
        let state: Vec<String> = on_pool!(self, p => sqlx::query_scalar(
            "UPDATE experiments SET lease_until_ms = $1 + $2,
                    trials_done = CASE WHEN state = 'running' THEN $3 ELSE trials_done END,
                    progress = CASE WHEN state = 'running' THEN $4 ELSE progress END
             WHERE id = $5 AND attempt = $6 AND state IN ('running', 'cancelled')
             RETURNING state",
        )
        .bind(now)
        .bind(lease_ms)
        .bind(trials)
        .bind(fraction)
        .bind(&lease.id)
        .bind(lease.attempt)
        .fetch_all(p)
        .await)?;
        Ok(match state.first().map(|w| w.parse::<ExperimentState>()) {
            Some(Ok(ExperimentState::Running)) => Held::Held,
            Some(_) => Held::Cancelled,
            None => Held::Lost,
        })
    }

    /// Store a run's finished trials and its progress (trials done, the
    /// fraction done) in one transaction, and then drop the columns its
    /// searches ran past (scope, and the B from which an automatic range's
    /// columns are dropped); nothing when the lease is lost. A trial already stored keeps its point and takes the
    /// place given here.
    pub async fn add_trials(
        &self,
        lease: &Lease,
        trials: &[StoredTrial],
        dropped: &[(u32, f64)],
        progress: (i64, f64),
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        if trials.is_empty() && dropped.is_empty() {
            return Ok(());
        }
        let (done, fraction) = progress;
        if let Some(at) = lease.unit {
            return self.add_unit_trials(lease, at, trials, dropped, done).await;
        }
        let fraction = fraction_done(fraction);
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            // The fence: this row stays locked until the commit, so no
            // claim can take the run over in between.
            let held = sqlx::query(
                "UPDATE experiments SET trials_done = CASE WHEN state = 'running' THEN $3 ELSE trials_done END,
                        progress = CASE WHEN state = 'running' THEN $4 ELSE progress END
                 WHERE id = $1 AND attempt = $2 AND state IN ('running', 'cancelled')",
            )
            .bind(&lease.id)
            .bind(lease.attempt)
            .bind(done)
            .bind(fraction)
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if held != 1 {
                tx.rollback().await?;
                return Err(lost(lease));
            }
            super::lease::insert_trials!(tx, &lease.id, trials);
            for &(scope, b) in dropped {
                sqlx::query("DELETE FROM trials WHERE experiment_id = $1 AND scope = $2 AND b >= $3")
                    .bind(&lease.id)
                    .bind(scope as i64)
                    .bind(b)
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await
        })
    }

    /// Store a run's finished evaluations (already stored ones are kept)
    /// and the best so far; nothing when the lease is lost.
    pub async fn add_evaluations(
        &self,
        lease: &Lease,
        evals: &[StoredEvaluation],
        best: Option<serde_json::Value>,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        if evals.is_empty() {
            return Ok(());
        }
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            let held = sqlx::query(
                "UPDATE experiments SET best = COALESCE($3, best) WHERE id = $1 AND attempt = $2 AND state IN ('running', 'cancelled')",
            )
            .bind(&lease.id)
            .bind(lease.attempt)
            .bind(best.as_ref().map(|b| b.to_string()))
            .execute(&mut *tx)
            .await?
            .rows_affected();
            if held != 1 {
                tx.rollback().await?;
                return Err(lost(lease));
            }
            for e in evals {
                sqlx::query(
                    "INSERT INTO evaluations (experiment_id, key, seq, record)
                     VALUES ($1, $2, (SELECT COUNT(*) FROM evaluations WHERE experiment_id = $1), $3)
                     ON CONFLICT (experiment_id, key) DO NOTHING",
                )
                .bind(&lease.id)
                .bind(&e.key)
                .bind(e.record.to_string())
                .execute(&mut *tx)
                .await?;
            }
            tx.commit().await
        })
    }

    /// Record the end of a run: `state` is succeeded, failed or cancelled.
    /// Only a running experiment ends succeeded or failed; a cancelled one
    /// stays cancelled (its trial count is still recorded). False when
    /// nothing changed (it was cancelled, or the lease is not ours).
    pub async fn finish(
        &self,
        lease: &Lease,
        state: ExperimentState,
        trials: i64,
        result: Option<&str>,
        error: Option<&str>,
    ) -> Result<bool, sqlx::Error> {
        self.writable()?;
        if let Some(at) = lease.unit {
            return self.finish_unit(lease, at, state, trials, error).await;
        }
        let r = on_pool!(self, p => sqlx::query("UPDATE experiments SET state = $1, trials_done = $2, result = $3, error = $4,
                     finished_ms = COALESCE(CASE WHEN state = 'cancelled' THEN finished_ms END, $5),
                     progress = CASE WHEN $1 = 'succeeded' THEN 1 ELSE progress END,
                     lease_until_ms = NULL
                     WHERE id = $6 AND attempt = $7 AND (state = 'running' OR (state = 'cancelled' AND $1 = 'cancelled'))")
            .bind(state.as_str())
            .bind(trials)
            .bind(result)
            .bind(error)
            .bind(now_ms())
            .bind(&lease.id)
            .bind(lease.attempt)
            .execute(p)
            .await
            .map(|r| r.rows_affected()))?;
        if r == 1 && state != ExperimentState::Succeeded {
            // The experiment ended early: units it did not wait for are not
            // claimed again. (One that succeeded waited for all of its own.)
            self.end_units(&lease.id).await?;
        }
        Ok(r == 1)
    }

    /// A running experiment stopped with its stored trials: by shutdown
    /// (`retry_in_ms` 0: the next claim takes it at once), or because its
    /// trials could not be stored (claimed again only after `retry_in_ms`,
    /// not in a loop).
    pub async fn interrupt(
        &self,
        lease: &Lease,
        trials: i64,
        retry_in_ms: i64,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        if let Some(at) = lease.unit {
            return self.interrupt_unit(lease, at, trials, retry_in_ms).await;
        }
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query("UPDATE experiments SET state = 'interrupted', trials_done = $1,
                        lease_until_ms = CASE WHEN $4 > 0 THEN $5 + $4 END
                     WHERE id = $2 AND attempt = $3 AND state = 'running'")
            .bind(trials)
            .bind(&lease.id)
            .bind(lease.attempt)
            .bind(retry_in_ms)
            .bind(now)
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// Record this worker process and what it runs (at start and with
    /// every heartbeat).
    pub async fn worker_seen(
        &self,
        worker: &str,
        rigs: &str,
        running: Option<&str>,
        trials_per_s: f64,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query(
            "INSERT INTO workers (id, rigs, started_ms, seen_ms, running, trials_per_s) VALUES ($1, $2, $3, $3, $4, $5)
             ON CONFLICT (id) DO UPDATE SET seen_ms = excluded.seen_ms, running = excluded.running, trials_per_s = excluded.trials_per_s",
        )
        .bind(worker)
        .bind(rigs)
        .bind(now)
        .bind(running)
        .bind(if trials_per_s.is_finite() { trials_per_s.max(0.0) } else { 0.0 })
        .execute(p)
        .await
        .map(|_| ()))
    }

    /// Forget workers not seen for `older_than_ms` (killed ones never say
    /// goodbye).
    pub async fn prune_workers(&self, older_than_ms: i64) -> Result<(), sqlx::Error> {
        self.writable()?;
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query("DELETE FROM workers WHERE seen_ms < $1")
            .bind(now - older_than_ms)
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// A worker that stops cleanly leaves the list.
    pub async fn worker_gone(&self, worker: &str) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("DELETE FROM workers WHERE id = $1")
            .bind(worker)
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// Workers seen within the last `within_ms` (database clock), oldest first.
    pub async fn workers(&self, within_ms: i64) -> Result<Vec<WorkerRow>, sqlx::Error> {
        let now = self.db_now_ms().await?;
        on_pool!(self, p => sqlx::query_as::<_, WorkerRow>(
            "SELECT * FROM workers WHERE seen_ms >= $1 ORDER BY started_ms, id",
        )
        .bind(now - within_ms)
        .fetch_all(p)
        .await)
    }

    /// Delete every experiment of `rig` (with their trials): for the
    /// benchmarks' own rigs.
    pub async fn purge_rig(&self, rig: &str) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("DELETE FROM experiments WHERE rig = $1")
            .bind(rig)
            .execute(p)
            .await
            .map(|_| ()))
    }
}
