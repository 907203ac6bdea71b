//! The SQLite store (sqlx): experiments and their results. Queries only; no
//! HTTP types. WAL and `synchronous = NORMAL`; the queue is claimed with one
//! `UPDATE … RETURNING`, so two runners never take the same experiment.

use serde::Serialize;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};
use sqlx::{FromRow, SqlitePool};
use std::path::Path;
use std::time::Duration;

use crate::zwidth::search::StoredTrial;

static MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations");

#[derive(Debug, Clone)]
pub struct Store {
    pool: SqlitePool,
}

/// One experiment row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct ExperimentRow {
    pub id: String,
    pub kind: String,
    pub spec: String,
    pub state: String,
    pub priority: i64,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub trials_done: i64,
    pub result: Option<String>,
    pub error: Option<String>,
    pub idempotency_key: Option<String>,
}

pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

impl Store {
    /// Open (creating it if needed) and migrate the database at `path`.
    pub async fn open(path: &Path) -> Result<Self, sqlx::Error> {
        let opts = SqliteConnectOptions::new()
            .filename(path)
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Normal)
            .busy_timeout(Duration::from_secs(5))
            .foreign_keys(true);
        let pool = SqlitePoolOptions::new()
            .max_connections(4)
            .connect_with(opts)
            .await?;
        MIGRATOR.run(&pool).await?;
        Ok(Self { pool })
    }

    /// Insert a queued experiment; with an idempotency key already used,
    /// return the existing row instead (`false`).
    pub async fn insert(
        &self,
        id: &str,
        kind: &str,
        spec: &str,
        priority: i64,
        key: Option<&str>,
    ) -> Result<(ExperimentRow, bool), sqlx::Error> {
        if let Some(k) = key {
            if let Some(row) = sqlx::query_as::<_, ExperimentRow>(
                "SELECT * FROM experiments WHERE idempotency_key = ?",
            )
            .bind(k)
            .fetch_optional(&self.pool)
            .await?
            {
                return Ok((row, false));
            }
        }
        let row = sqlx::query_as::<_, ExperimentRow>(
            "INSERT INTO experiments (id, kind, spec, state, priority, created_ms, idempotency_key)
             VALUES (?, ?, ?, 'queued', ?, ?, ?) RETURNING *",
        )
        .bind(id)
        .bind(kind)
        .bind(spec)
        .bind(priority)
        .bind(now_ms())
        .bind(key)
        .fetch_one(&self.pool)
        .await?;
        Ok((row, true))
    }

    pub async fn get(&self, id: &str) -> Result<Option<ExperimentRow>, sqlx::Error> {
        sqlx::query_as::<_, ExperimentRow>("SELECT * FROM experiments WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await
    }

    pub async fn list(&self, limit: i64) -> Result<Vec<ExperimentRow>, sqlx::Error> {
        sqlx::query_as::<_, ExperimentRow>(
            "SELECT * FROM experiments ORDER BY created_ms DESC, id DESC LIMIT ?",
        )
        .bind(limit)
        .fetch_all(&self.pool)
        .await
    }

    /// Claim the next queued experiment (highest priority, oldest first).
    pub async fn claim_next(&self) -> Result<Option<ExperimentRow>, sqlx::Error> {
        sqlx::query_as::<_, ExperimentRow>(
            "UPDATE experiments SET state = 'running', started_ms = ?
             WHERE id = (SELECT id FROM experiments WHERE state = 'queued' ORDER BY priority DESC, created_ms, id LIMIT 1)
             RETURNING *",
        )
        .bind(now_ms())
        .fetch_optional(&self.pool)
        .await
    }

    pub async fn set_progress(&self, id: &str, trials: i64) -> Result<(), sqlx::Error> {
        sqlx::query("UPDATE experiments SET trials_done = ? WHERE id = ? AND state = 'running'")
            .bind(trials)
            .bind(id)
            .execute(&self.pool)
            .await
            .map(|_| ())
    }

    /// Record the end of a run: `state` is succeeded, failed or cancelled.
    pub async fn finish(
        &self,
        id: &str,
        state: &str,
        trials: i64,
        result: Option<&str>,
        error: Option<&str>,
    ) -> Result<(), sqlx::Error> {
        sqlx::query("UPDATE experiments SET state = ?, trials_done = ?, result = ?, error = ?, finished_ms = ? WHERE id = ?")
            .bind(state)
            .bind(trials)
            .bind(result)
            .bind(error)
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await
            .map(|_| ())
    }

    /// Ask a queued or running experiment to stop; true if it was either.
    pub async fn cancel(&self, id: &str) -> Result<bool, sqlx::Error> {
        let r = sqlx::query("UPDATE experiments SET state = 'cancelled', finished_ms = ? WHERE id = ? AND state IN ('queued', 'scheduled', 'running')")
            .bind(now_ms())
            .bind(id)
            .execute(&self.pool)
            .await?;
        Ok(r.rows_affected() == 1)
    }

    /// After a restart: anything left running was interrupted; queue it again.
    pub async fn requeue_interrupted(&self) -> Result<u64, sqlx::Error> {
        let r = sqlx::query(
            "UPDATE experiments SET state = 'queued', started_ms = NULL WHERE state = 'running'",
        )
        .execute(&self.pool)
        .await?;
        Ok(r.rows_affected())
    }

    pub async fn state(&self, id: &str) -> Result<Option<String>, sqlx::Error> {
        sqlx::query_scalar::<_, String>("SELECT state FROM experiments WHERE id = ?")
            .bind(id)
            .fetch_optional(&self.pool)
            .await
    }

    /// Store finished trials in one transaction (already stored ones are kept).
    pub async fn add_trials(&self, id: &str, trials: &[StoredTrial]) -> Result<(), sqlx::Error> {
        if trials.is_empty() {
            return Ok(());
        }
        let mut tx = self.pool.begin().await?;
        for t in trials {
            let point = serde_json::to_string(&t.point).unwrap_or_default();
            sqlx::query("INSERT OR IGNORE INTO trials (experiment_id, scope, k, b, point) VALUES (?, ?, ?, ?, ?)")
                .bind(id)
                .bind(t.scope as i64)
                .bind(t.point.k)
                .bind(t.point.b)
                .bind(point)
                .execute(&mut *tx)
                .await?;
        }
        tx.commit().await
    }

    /// Every stored trial of an experiment.
    pub async fn trials(&self, id: &str) -> Result<Vec<StoredTrial>, sqlx::Error> {
        let rows: Vec<(i64, String)> =
            sqlx::query_as("SELECT scope, point FROM trials WHERE experiment_id = ?")
                .bind(id)
                .fetch_all(&self.pool)
                .await?;
        Ok(rows
            .into_iter()
            .filter_map(|(scope, p)| {
                serde_json::from_str(&p).ok().map(|point| StoredTrial {
                    scope: scope as u32,
                    point,
                })
            })
            .collect())
    }

    pub async fn trial_count(&self, id: &str) -> Result<i64, sqlx::Error> {
        sqlx::query_scalar("SELECT COUNT(*) FROM trials WHERE experiment_id = ?")
            .bind(id)
            .fetch_one(&self.pool)
            .await
    }
}
