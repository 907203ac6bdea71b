//! What the dashboard reads (issue 15): the queue at a glance, a filtered
//! page of runs, and change tokens, so a page that polls and finds nothing
//! new costs one cheap query.

use super::{on_pool, Db, ExperimentRow, Store};
use crate::zwidth::search::Point;

/// The columns of a summary row (no spec, no result).
macro_rules! summary_columns {
    () => {
        "id, kind, '' AS spec, state, priority, created_ms, started_ms, finished_ms, trials_done,
         NULL AS result, error, idempotency_key, not_before_ms, rig, progress, best,
         attempt, worker, lease_until_ms"
    };
}

/// The queue now: what runs, what waits in the order it will be claimed
/// (runnable now by priority then age, then those scheduled for later by
/// their time), and what failed since `since_ms`.
#[derive(Debug, Default)]
pub struct Board {
    pub running: Vec<ExperimentRow>,
    pub waiting: Vec<ExperimentRow>,
    /// All waiting, of which `waiting` is the first page.
    pub waiting_total: i64,
    pub failed: Vec<ExperimentRow>,
    /// All failed since `since_ms`, of which `failed` is the first page.
    pub failed_total: i64,
}

/// Which runs a list shows; an empty field matches every run.
#[derive(Debug, Default, Clone)]
pub struct ListFilter {
    pub kind: String,
    pub state: String,
    pub rig: String,
    /// Text the run's spec contains (its scene: device, estimator, wall…).
    pub scene: String,
}

impl Store {
    /// The queue board at `now_ms`: at most `limit` waiting and failed rows.
    pub async fn board(
        &self,
        now_ms: i64,
        since_ms: i64,
        limit: i64,
    ) -> Result<Board, sqlx::Error> {
        let running: Vec<ExperimentRow> = on_pool!(self, p => sqlx::query_as(concat!(
            "SELECT ", summary_columns!(), " FROM experiments WHERE state = 'running' ORDER BY started_ms, id"))
            .fetch_all(p)
            .await)?;
        // Runnable now first (by priority, then age: the claim's order),
        // then those that become runnable later (scheduled, or interrupted
        // until their lease ends) by that time.
        let waiting: Vec<ExperimentRow> = on_pool!(self, p => sqlx::query_as(concat!(
            "SELECT ", summary_columns!(), " FROM experiments
             WHERE state IN ('queued', 'scheduled', 'interrupted')
             ORDER BY CASE WHEN not_before_ms > $1 OR (state = 'interrupted' AND lease_until_ms > $1) THEN 1 ELSE 0 END,
                      CASE WHEN not_before_ms > $1 THEN not_before_ms
                           WHEN state = 'interrupted' AND lease_until_ms > $1 THEN lease_until_ms ELSE 0 END,
                      priority DESC, created_ms, id
             LIMIT $2"))
            .bind(now_ms)
            .bind(limit)
            .fetch_all(p)
            .await)?;
        let waiting_total: i64 = on_pool!(self, p => sqlx::query_scalar(
            "SELECT COUNT(*) FROM experiments WHERE state IN ('queued', 'scheduled', 'interrupted')")
            .fetch_one(p)
            .await)?;
        let failed_total: i64 = on_pool!(self, p => sqlx::query_scalar(
            "SELECT COUNT(*) FROM experiments WHERE state = 'failed' AND finished_ms >= $1")
            .bind(since_ms)
            .fetch_one(p)
            .await)?;
        let failed: Vec<ExperimentRow> = on_pool!(self, p => sqlx::query_as(concat!(
            "SELECT ", summary_columns!(), " FROM experiments
             WHERE state = 'failed' AND finished_ms >= $1
             ORDER BY finished_ms DESC, id LIMIT $2"))
            .bind(since_ms)
            .bind(limit)
            .fetch_all(p)
            .await)?;
        Ok(Board {
            running,
            waiting,
            waiting_total,
            failed,
            failed_total,
        })
    }

    /// What changes the queue board at `now_ms`: the runs waiting and
    /// running by state, their trials, progress, attempts and priorities,
    /// the next time a waiting one becomes runnable, the failures since
    /// `since_ms`, the paused flag, and the minute (the "ago" and "opens
    /// in" texts). Two indexed aggregates.
    pub async fn board_token(&self, now_ms: i64, since_ms: i64) -> Result<String, sqlx::Error> {
        let row: (i64, i64, i64, i64, f64, i64, i64, i64, i64) = on_pool!(self, p => sqlx::query_as(
            "SELECT CAST(COALESCE(SUM(CASE WHEN state = 'queued' THEN 1 ELSE 0 END), 0) AS BIGINT),
                    CAST(COALESCE(SUM(CASE WHEN state = 'scheduled' THEN 1 ELSE 0 END), 0) AS BIGINT),
                    CAST(COALESCE(SUM(CASE WHEN state = 'interrupted' THEN 1 ELSE 0 END), 0) AS BIGINT),
                    CAST(COALESCE(SUM(trials_done), 0) AS BIGINT),
                    CAST(COALESCE(SUM(progress), 0) AS DOUBLE PRECISION),
                    CAST(COALESCE(SUM(attempt), 0) AS BIGINT),
                    CAST(COALESCE(SUM(priority), 0) AS BIGINT),
                    CAST(COALESCE(MAX(started_ms), 0) AS BIGINT),
                    CAST(COALESCE(MIN(CASE WHEN not_before_ms > $1 THEN not_before_ms
                                           WHEN state = 'interrupted' AND lease_until_ms > $1 THEN lease_until_ms END), 0) AS BIGINT)
             FROM experiments WHERE state IN ('queued', 'scheduled', 'interrupted', 'running')")
            .bind(now_ms)
            .fetch_one(p)
            .await)?;
        let running: (i64, i64) = on_pool!(self, p => sqlx::query_as(
            "SELECT CAST(COUNT(*) AS BIGINT), CAST(COALESCE(SUM(attempt), 0) AS BIGINT) FROM experiments WHERE state = 'running'")
            .fetch_one(p)
            .await)?;
        let failed: (i64, i64) = on_pool!(self, p => sqlx::query_as(
            "SELECT CAST(COUNT(*) AS BIGINT), CAST(COALESCE(MAX(finished_ms), 0) AS BIGINT)
             FROM experiments WHERE state = 'failed' AND finished_ms >= $1")
            .bind(since_ms)
            .fetch_one(p)
            .await)?;
        let paused = self.paused().await?;
        Ok(format!(
            "{}.{}.{}.{}.{:.4}.{}.{}.{}.{}.{}.{}.{}.{}.{}.{}",
            row.0,
            row.1,
            row.2,
            row.3,
            row.4,
            row.5,
            row.6,
            row.7,
            row.8,
            running.0,
            running.1,
            failed.0,
            failed.1,
            paused as u8,
            now_ms / 60_000
        ))
    }

    /// A page of runs matching `f`, newest first, and how many match.
    pub async fn list_filtered(
        &self,
        f: &ListFilter,
        limit: i64,
        offset: i64,
    ) -> Result<(Vec<ExperimentRow>, i64), sqlx::Error> {
        // Substring tests without LIKE's wildcards.
        let (rows_sql, count_sql) = match self.db {
            Db::Sqlite(_) => (
                concat!(
                    "SELECT ",
                    summary_columns!(),
                    " FROM experiments
                 WHERE ($1 = '' OR kind = $1) AND ($2 = '' OR state = $2) AND ($3 = '' OR rig = $3)
                   AND ($4 = '' OR instr(spec, $4) > 0)
                 ORDER BY created_ms DESC, id DESC LIMIT $5 OFFSET $6"
                ),
                "SELECT COUNT(*) FROM experiments
                 WHERE ($1 = '' OR kind = $1) AND ($2 = '' OR state = $2) AND ($3 = '' OR rig = $3)
                   AND ($4 = '' OR instr(spec, $4) > 0)",
            ),
            Db::Postgres(_) => (
                concat!(
                    "SELECT ",
                    summary_columns!(),
                    " FROM experiments
                 WHERE ($1 = '' OR kind = $1) AND ($2 = '' OR state = $2) AND ($3 = '' OR rig = $3)
                   AND ($4 = '' OR strpos(spec, $4) > 0)
                 ORDER BY created_ms DESC, id DESC LIMIT $5 OFFSET $6"
                ),
                "SELECT COUNT(*) FROM experiments
                 WHERE ($1 = '' OR kind = $1) AND ($2 = '' OR state = $2) AND ($3 = '' OR rig = $3)
                   AND ($4 = '' OR strpos(spec, $4) > 0)",
            ),
        };
        let rows: Vec<ExperimentRow> = on_pool!(self, p => sqlx::query_as(rows_sql)
            .bind(&f.kind)
            .bind(&f.state)
            .bind(&f.rig)
            .bind(&f.scene)
            .bind(limit)
            .bind(offset)
            .fetch_all(p)
            .await)?;
        let total: i64 = on_pool!(self, p => sqlx::query_scalar(count_sql)
            .bind(&f.kind)
            .bind(&f.state)
            .bind(&f.rig)
            .bind(&f.scene)
            .fetch_one(p)
            .await)?;
        Ok((rows, total))
    }

    /// A run's stored points per scope, in the maps' order, for drawing:
    /// one row per scope (the points joined in the database), not one per
    /// trial, because handing 20 000 rows one by one from SQLite's thread
    /// cost ~100 ms of a 20 000-trial run page (docs/benchmarks.md). A
    /// scope whose joined text does not parse (a damaged point) is read
    /// trial by trial, leaving that point out as `trials` does.
    pub async fn map_points(&self, id: &str) -> Result<Vec<(u32, Vec<Point>)>, sqlx::Error> {
        let sql = match self.db {
            Db::Sqlite(_) => {
                "SELECT scope, '[' || group_concat(point, ',' ORDER BY col, idx, k, b) || ']'
                 FROM trials WHERE experiment_id = $1 GROUP BY scope ORDER BY scope"
            }
            Db::Postgres(_) => {
                "SELECT scope, '[' || string_agg(point, ',' ORDER BY col, idx, k, b) || ']'
                 FROM trials WHERE experiment_id = $1 GROUP BY scope ORDER BY scope"
            }
        };
        let rows: Vec<(i64, String)> =
            on_pool!(self, p => sqlx::query_as(sql).bind(id).fetch_all(p).await)?;
        let mut out = Vec::with_capacity(rows.len());
        for (scope, joined) in rows {
            let points = match serde_json::from_str::<Vec<Point>>(&joined) {
                Ok(points) => points,
                Err(_) => self
                    .trials_page(id, Some(scope as u32), 0, i64::MAX)
                    .await?
                    .into_iter()
                    .map(|t| t.point)
                    .collect(),
            };
            out.push((scope as u32, points));
        }
        Ok(out)
    }

    /// Refresh the planner's statistics (PostgreSQL's `ANALYZE`; nothing
    /// on SQLite, whose planner keeps none unless asked). Autovacuum does
    /// this on its own within a minute of a big change; `bench ui` calls it
    /// after seeding a million trials in seconds, or it would time the
    /// planner's sequential scans over a table it still thinks is small.
    pub async fn analyze(&self) -> Result<(), sqlx::Error> {
        if let Db::Postgres(p) = &self.db {
            sqlx::query("ANALYZE").execute(p).await?;
        }
        Ok(())
    }

    /// Every rig's window as stored (JSON), by rig: one query.
    pub async fn rig_windows(&self) -> Result<Vec<(String, String)>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as(r#"SELECT rig, "window" FROM rig_windows ORDER BY rig"#)
            .fetch_all(p)
            .await)
    }

    /// The rigs named by any stored run (for the list's filter).
    pub async fn run_rigs(&self) -> Result<Vec<String>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_scalar("SELECT DISTINCT rig FROM experiments ORDER BY rig")
            .fetch_all(p)
            .await)
    }
}

impl Store {
    /// A run written as given, with its trials, in one transaction: for
    /// benchmarks and demos of the dashboard (`zwidth bench ui`), never for
    /// work (it bypasses the queue's rules).
    pub async fn import_run(
        &self,
        r: &ExperimentRow,
        trials: &[crate::zwidth::search::StoredTrial],
        evaluations: &[crate::zwidth::search::StoredEvaluation],
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => {
            let mut tx = p.begin().await?;
            sqlx::query(
                "INSERT INTO experiments (id, kind, spec, state, priority, created_ms, started_ms, finished_ms,
                     trials_done, result, error, not_before_ms, rig, progress, best, attempt, worker)
                 VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14, $15, $16, $17)",
            )
            .bind(&r.id)
            .bind(&r.kind)
            .bind(&r.spec)
            .bind(r.state.as_str())
            .bind(r.priority)
            .bind(r.created_ms)
            .bind(r.started_ms)
            .bind(r.finished_ms)
            .bind(r.trials_done)
            .bind(&r.result)
            .bind(&r.error)
            .bind(r.not_before_ms)
            .bind(&r.rig)
            .bind(r.progress)
            .bind(&r.best)
            .bind(r.attempt)
            .bind(&r.worker)
            .execute(&mut *tx)
            .await?;
            super::lease::insert_trials!(tx, &r.id, trials);
            for (seq, e) in evaluations.iter().enumerate() {
                sqlx::query("INSERT INTO evaluations (experiment_id, key, seq, record) VALUES ($1, $2, $3, $4)")
                    .bind(&r.id)
                    .bind(&e.key)
                    .bind(seq as i64)
                    .bind(e.record.to_string())
                    .execute(&mut *tx)
                    .await?;
            }
            tx.commit().await
        })
    }
}
