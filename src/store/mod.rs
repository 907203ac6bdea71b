//! The store (sqlx): experiments and their results, in SQLite (the embedded
//! default: WAL and `synchronous = NORMAL`) or PostgreSQL (shared by several
//! processes). Queries only; no HTTP types. One code path for both: an enum
//! over the two pools, the same SQL where the dialects agree (`$n`
//! placeholders, `ON CONFLICT`, `RETURNING`), per-backend SQL only where they
//! do not (claiming, integrity checks, backups, DDL: `migrations/sqlite/`
//! and `migrations/postgres/`). The queue is claimed with one
//! `UPDATE … RETURNING`, so two runners never take the same experiment.
//!
//! Every statement runs to completion before its answer is used: with
//! `RETURNING`, SQLite hands out the rows before the implicit commit, so a
//! query that stops after the first row never sees a commit that failed
//! (disk full) and leaves its transaction open ("database is locked" for
//! everyone after). Hence `fetch_all`, never `fetch_one`, on writes.

pub mod agents;
pub mod dashboard;
mod db;
pub mod fault;
pub mod lease;
pub mod leases;
mod state;
pub mod units;
pub mod wake;
pub(crate) use db::on_pool;
use db::{stored_trials, Db, TrialRow};
pub use db::{ExperimentRow, Store};
pub use fault::{Fault, Health};
pub use lease::{Held, Lease, UnitPlace, MAX_LOST};
pub use leases::WorkerRow;
pub use state::{ExperimentState, STATES};
pub use units::UnitRow;

pub mod location;
pub use location::Location;

use sqlx::postgres::PgPoolOptions;
use sqlx::sqlite::{SqliteConnectOptions, SqliteJournalMode, SqlitePoolOptions, SqliteSynchronous};

use std::path::Path;
use std::time::Duration;

use crate::rig::window::Window;
use crate::zwidth::search::{StoredEvaluation, StoredTrial};

static SQLITE_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/sqlite");
static POSTGRES_MIGRATOR: sqlx::migrate::Migrator = sqlx::migrate!("./migrations/postgres");

/// Why a store could not be opened: the location is wrong or unusable (a
/// bad URL, an unreachable server, a refused password, a schema newer than
/// this binary; nothing was written), or something failed on the way.
#[derive(Debug)]
pub enum OpenError {
    Refused(String),
    Failed(String),
}

impl std::fmt::Display for OpenError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            OpenError::Refused(m) | OpenError::Failed(m) => f.write_str(m),
        }
    }
}

/// How a submission went into the store.
#[derive(Debug)]
pub enum Inserted {
    /// Stored (committed) now.
    New(ExperimentRow),
    /// The idempotency key was used before with the same request.
    Earlier(ExperimentRow),
    /// The idempotency key was used before with a different request.
    KeyReused(ExperimentRow),
}

/// What a submission stores.
#[derive(Debug, Clone, Copy)]
pub struct NewExperiment<'a> {
    pub id: &'a str,
    pub kind: &'a str,
    /// The validated spec JSON.
    pub spec: &'a str,
    pub priority: i64,
    /// Idempotency key.
    pub key: Option<&'a str>,
    pub not_before_ms: Option<i64>,
    pub rig: &'a str,
}

impl<'a> NewExperiment<'a> {
    /// A queued experiment at priority 0, with no idempotency key and no
    /// earliest start.
    pub fn queued(id: &'a str, kind: &'a str, spec: &'a str, rig: &'a str) -> Self {
        Self {
            id,
            kind,
            spec,
            priority: 0,
            key: None,
            not_before_ms: None,
            rig,
        }
    }
}

pub use crate::clock::now_ms;

impl Store {
    /// Open (creating it if needed) and migrate the SQLite database at `path`.
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
        SQLITE_MIGRATOR.run(&pool).await?;
        Self::ready(Db::Sqlite(pool)).await
    }

    /// Open the store at `at`: a SQLite file (created if missing) or a
    /// PostgreSQL database (which must exist). Migrations are applied; a
    /// schema newer than this binary's is refused before anything is
    /// written.
    pub async fn connect(at: &Location) -> Result<Self, OpenError> {
        let shown = at.to_string();
        let failed =
            |e: sqlx::Error| OpenError::Failed(format!("cannot open database {shown}: {e}"));
        let newer = |e: &sqlx::migrate::MigrateError| {
            match e {
            sqlx::migrate::MigrateError::VersionMissing(v) => Some(OpenError::Refused(format!(
                "the database {shown} has schema version {v}, newer than this zwidth knows: upgrade zwidth (nothing was written)"
            ))),
            _ => None,
        }
        };
        match at {
            // The migrator checks the versions applied against its own
            // before it applies anything.
            Location::Sqlite(path) => Self::open(path).await.map_err(|e| match &e {
                sqlx::Error::Migrate(m) => newer(m).unwrap_or_else(|| failed(e)),
                _ => failed(e),
            }),
            Location::Postgres(url) => {
                let opts: sqlx::postgres::PgConnectOptions = url
                    .parse()
                    .map_err(|e| OpenError::Refused(format!("--db {shown}: {e}")))?;
                // Our transactions are short: one left open by a stopped
                // or cut-off worker is ended by the server, not held (with
                // its row locks) until TCP notices; a statement waits at
                // most 5 s for a lock.
                // No statement runs for more than 30 s, and the server
                // probes an idle connection after 30 s (issue 45 item 8);
                // the client side is bounded by the timeouts around each
                // store call of a running experiment (`jobs::Worker::store_call`).
                let opts = opts.options([
                    ("idle_in_transaction_session_timeout", "10s"),
                    ("lock_timeout", "5s"),
                    ("statement_timeout", "30s"),
                    ("tcp_keepalives_idle", "30"),
                    ("tcp_keepalives_interval", "10"),
                    ("tcp_keepalives_count", "3"),
                ]);
                // One connection first: its error says why (refused,
                // password, no such database), where a pool only times out.
                {
                    use sqlx::{ConnectOptions, Connection};
                    let c = opts.connect().await.map_err(|e| {
                        OpenError::Refused(format!("cannot connect to the database {shown}: {e}"))
                    })?;
                    let _ = c.close().await;
                }
                let pool = PgPoolOptions::new()
                    .max_connections(8)
                    .acquire_timeout(Duration::from_secs(10))
                    .connect_with(opts)
                    .await
                    .map_err(|e| {
                        OpenError::Refused(format!("cannot connect to the database {shown}: {e}"))
                    })?;
                if let Err(e) = POSTGRES_MIGRATOR.run(&pool).await {
                    return Err(
                        newer(&e).unwrap_or_else(|| failed(sqlx::Error::Migrate(Box::new(e))))
                    );
                }
                Self::ready(Db::Postgres(pool)).await.map_err(failed)
            }
        }
    }

    async fn ready(db: Db) -> Result<Self, sqlx::Error> {
        let store = Self {
            db,
            health: Default::default(),
            wake: Default::default(),
        };
        store.check().await?;
        Ok(store)
    }

    /// Whether several processes may share this database (PostgreSQL):
    /// then a run may be taken over by another worker, and an attached
    /// rig's agent may be connected to another API process.
    pub fn shared(&self) -> bool {
        matches!(self.db, Db::Postgres(_))
    }

    /// Which database this is: "sqlite" or "postgres".
    pub fn backend(&self) -> &'static str {
        match self.db {
            Db::Sqlite(_) => "sqlite",
            Db::Postgres(_) => "postgres",
        }
    }

    /// SQLite: `PRAGMA quick_check` (O(pages), no index cross-check);
    /// PostgreSQL: a round trip (the server checks its own pages). Remember
    /// and return what it found. Run at start and on `GET /healthz?check=true`.
    pub async fn check(&self) -> Result<Health, sqlx::Error> {
        let rows: Result<Vec<String>, sqlx::Error> = match &self.db {
            Db::Sqlite(p) => sqlx::query_scalar("PRAGMA quick_check").fetch_all(p).await,
            Db::Postgres(p) => sqlx::query_scalar("SELECT 'ok'::text").fetch_all(p).await,
        };
        let h = match rows {
            Ok(r) if r.len() == 1 && r[0] == "ok" => Health::ok(),
            Ok(r) => Health::corrupt(r.join("; ")),
            Err(e) if Fault::of(&e) == Fault::Corrupt => Health::corrupt(e.to_string()),
            Err(e) => return Err(e),
        };
        *self.health.lock().unwrap_or_else(|e| e.into_inner()) = h.clone();
        Ok(h)
    }

    /// What the last integrity check (or a corrupt read since) found.
    /// Whether the database is a PostgreSQL server (reached over a
    /// connection that can fail) rather than a SQLite file.
    pub fn is_postgres(&self) -> bool {
        matches!(self.db, Db::Postgres(_))
    }

    pub fn health(&self) -> Health {
        self.health
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Note an error: a corrupt database is remembered (writes refused).
    pub fn observe(&self, e: &sqlx::Error) {
        if Fault::of(e) == Fault::Corrupt {
            *self.health.lock().unwrap_or_else(|x| x.into_inner()) = Health::corrupt(e.to_string());
        }
    }

    /// Refuse writes to a database known to be corrupt.
    fn writable(&self) -> Result<(), sqlx::Error> {
        match self.health().corrupt {
            None => Ok(()),
            Some(why) => Err(sqlx::Error::Protocol(format!(
                "{}: {why}",
                fault::CORRUPT_PREFIX
            ))),
        }
    }

    /// Write everything in the WAL into the database file and close every
    /// connection, so the `.db` file alone is a complete copy (clean shutdown).
    pub async fn close(&self) -> Result<(), sqlx::Error> {
        match &self.db {
            Db::Sqlite(p) => {
                let r = sqlx::query("PRAGMA wal_checkpoint(TRUNCATE)")
                    .execute(p)
                    .await
                    .map(|_| ());
                p.close().await;
                r
            }
            Db::Postgres(p) => {
                p.close().await;
                Ok(())
            }
        }
    }

    /// A consistent copy of the whole SQLite database in one file (`VACUUM
    /// INTO`), safe while the service runs. `to` must not exist. (A
    /// PostgreSQL database is copied with its own tools: pg_dump.)
    pub async fn backup(&self, to: &Path) -> Result<(), sqlx::Error> {
        match &self.db {
            Db::Sqlite(p) => sqlx::query("VACUUM INTO $1")
                .bind(to.to_string_lossy().into_owned())
                .execute(p)
                .await
                .map(|_| ()),
            Db::Postgres(_) => Err(sqlx::Error::Protocol(
                "a PostgreSQL database is backed up with pg_dump, not zwidth backup".into(),
            )),
        }
    }

    /// Insert a queued experiment and commit it. With an idempotency key
    /// used before, nothing is inserted and the earlier row is returned
    /// (one `INSERT … ON CONFLICT DO NOTHING`: concurrent submissions with
    /// one key store one experiment, also from several API processes).
    pub async fn insert(&self, e: NewExperiment<'_>) -> Result<Inserted, sqlx::Error> {
        self.writable()?;
        let NewExperiment {
            id,
            kind,
            spec,
            priority,
            key,
            not_before_ms,
            rig,
        } = e;
        let state = if not_before_ms.is_some_and(|t| t > now_ms()) {
            ExperimentState::Scheduled
        } else {
            ExperimentState::Queued
        };
        let created_ms = now_ms();
        let r = on_pool!(self, p => sqlx::query(
            "INSERT INTO experiments (id, kind, spec, state, priority, created_ms, idempotency_key, not_before_ms, rig)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9) ON CONFLICT (idempotency_key) DO NOTHING",
        )
        .bind(id)
        .bind(kind)
        .bind(spec)
        .bind(state.as_str())
        .bind(priority)
        .bind(created_ms)
        .bind(key)
        .bind(not_before_ms)
        .bind(rig)
        .execute(p)
        .await
        .map(|r| r.rows_affected()))?;
        if r == 1 {
            if state == ExperimentState::Queued {
                self.notify_units(wake::QUEUED, id).await;
            }
            // Committed: the row is what was written (no read that could
            // fail after the commit and turn a stored submission into an error).
            return Ok(Inserted::New(ExperimentRow {
                id: id.into(),
                kind: kind.into(),
                spec: spec.into(),
                state,
                priority,
                created_ms,
                started_ms: None,
                finished_ms: None,
                trials_done: 0,
                result: None,
                error: None,
                idempotency_key: key.map(str::to_owned),
                not_before_ms,
                rig: rig.into(),
                progress: 0.0,
                best: None,
                attempt: 0,
                worker: None,
                lease_until_ms: None,
            }));
        }
        let row = on_pool!(self, p => sqlx::query_as::<_, ExperimentRow>(
            "SELECT * FROM experiments WHERE idempotency_key = $1",
        )
        .bind(key)
        .fetch_one(p)
        .await)?;
        let same = row.spec == spec
            && row.priority == priority
            && row.rig == rig
            && row.not_before_ms == not_before_ms;
        Ok(if same {
            Inserted::Earlier(row)
        } else {
            Inserted::KeyReused(row)
        })
    }

    pub async fn get(&self, id: &str) -> Result<Option<ExperimentRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as::<_, ExperimentRow>("SELECT * FROM experiments WHERE id = $1")
            .bind(id)
            .fetch_optional(p)
            .await)
    }

    /// A page of experiments, newest first, after `cursor` (the last page's
    /// last `(created_ms, id)`); with `full`, their specs and results too
    /// (else `spec` is empty and `result` none).
    pub async fn list(
        &self,
        limit: i64,
        cursor: Option<(i64, &str)>,
        full: bool,
    ) -> Result<Vec<ExperimentRow>, sqlx::Error> {
        // Two fixed statements (sqlx takes no SQL built at run time).
        let sql = if full {
            "SELECT * FROM experiments
             WHERE $1 = '' OR created_ms < $2 OR (created_ms = $2 AND id < $1)
             ORDER BY created_ms DESC, id DESC LIMIT $3"
        } else {
            "SELECT id, kind, '' AS spec, state, priority, created_ms, started_ms, finished_ms, trials_done,
                    NULL AS result, error, idempotency_key, not_before_ms, rig, progress, best,
                    attempt, worker, lease_until_ms
             FROM experiments
             WHERE $1 = '' OR created_ms < $2 OR (created_ms = $2 AND id < $1)
             ORDER BY created_ms DESC, id DESC LIMIT $3"
        };
        let (t, id) = cursor.unwrap_or((i64::MAX, ""));
        on_pool!(self, p => sqlx::query_as::<_, ExperimentRow>(sql)
            .bind(id)
            .bind(t)
            .bind(limit)
            .fetch_all(p)
            .await)
    }

    /// The rig's window, if it has one.
    pub async fn rig_window(&self, rig: &str) -> Result<Option<Window>, sqlx::Error> {
        let w: Option<String> = on_pool!(self, p => sqlx::query_scalar(r#"SELECT "window" FROM rig_windows WHERE rig = $1"#)
            .bind(rig)
            .fetch_optional(p)
            .await)?;
        Ok(w.and_then(|w| serde_json::from_str(&w).ok()))
    }

    /// Set (Some) or clear (None) the rig's window.
    pub async fn set_rig_window(&self, rig: &str, w: Option<&Window>) -> Result<(), sqlx::Error> {
        self.writable()?;
        match w {
            Some(w) => {
                on_pool!(self, p => sqlx::query(r#"INSERT INTO rig_windows (rig, "window") VALUES ($1, $2) ON CONFLICT (rig) DO UPDATE SET "window" = excluded."window""#)
                .bind(rig)
                .bind(serde_json::to_string(w).unwrap_or_default())
                .execute(p)
                .await
                .map(|_| ()))
            }
            None => on_pool!(self, p => sqlx::query("DELETE FROM rig_windows WHERE rig = $1")
                .bind(rig)
                .execute(p)
                .await
                .map(|_| ())),
        }
    }

    /// Per rig: experiments waiting, and those running with the worker
    /// running each (oldest first).
    pub async fn rig_load(
        &self,
        rig: &str,
    ) -> Result<(i64, Vec<(String, Option<String>)>), sqlx::Error> {
        let waiting: i64 = on_pool!(self, p => sqlx::query_scalar(
            "SELECT COUNT(*) FROM experiments WHERE rig = $1 AND state IN ('queued', 'scheduled')",
        )
        .bind(rig)
        .fetch_one(p)
        .await)?;
        let running: Vec<(String, Option<String>)> = on_pool!(self, p => sqlx::query_as(
            "SELECT id, worker FROM experiments WHERE rig = $1 AND state = 'running' ORDER BY started_ms, id",
        )
        .bind(rig)
        .fetch_all(p)
        .await)?;
        Ok((waiting, running))
    }

    pub async fn set_paused(&self, paused: bool) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("UPDATE queue_control SET paused = $1 WHERE id = 1")
            .bind(paused as i64)
            .execute(p)
            .await
            .map(|_| ()))?;
        if !paused {
            self.notify_units(wake::QUEUED, "resumed").await;
        }
        Ok(())
    }

    pub async fn paused(&self) -> Result<bool, sqlx::Error> {
        on_pool!(self, p => sqlx::query_scalar::<_, i64>("SELECT paused FROM queue_control WHERE id = 1")
            .fetch_one(p)
            .await
            .map(|p| p != 0))
    }

    /// Experiments per state, and the trials done over all of them.
    pub async fn counts(&self) -> Result<(Vec<(String, i64)>, i64), sqlx::Error> {
        let by_state: Vec<(String, i64)> = on_pool!(self, p =>
            sqlx::query_as("SELECT state, COUNT(*) FROM experiments GROUP BY state ORDER BY state")
                .fetch_all(p)
                .await)?;
        // SUM of BIGINT is NUMERIC in PostgreSQL: cast back.
        let trials: i64 = on_pool!(self, p =>
            sqlx::query_scalar("SELECT CAST(COALESCE(SUM(trials_done), 0) AS BIGINT) FROM experiments")
                .fetch_one(p)
                .await)?;
        Ok((by_state, trials))
    }

    /// Ask a queued, scheduled, running or interrupted experiment to stop;
    /// true if it was one of those.
    pub async fn cancel(&self, id: &str) -> Result<bool, sqlx::Error> {
        self.writable()?;
        let r = on_pool!(self, p => sqlx::query("UPDATE experiments SET state = 'cancelled', finished_ms = $1 WHERE id = $2 AND state IN ('queued', 'scheduled', 'running', 'interrupted')")
            .bind(now_ms())
            .bind(id)
            .execute(p)
            .await
            .map(|r| r.rows_affected()))?;
        if r == 1 {
            self.end_units(id).await?;
        }
        Ok(r == 1)
    }

    /// After a restart: anything left running (killed) or interrupted
    /// (shut down) is queued again; it resumes from its stored trials.
    pub async fn requeue_interrupted(&self) -> Result<u64, sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query(
            "UPDATE experiments SET state = 'queued', started_ms = NULL, lease_until_ms = NULL WHERE state IN ('running', 'interrupted')",
        )
        .execute(p)
        .await
        .map(|r| r.rows_affected()))
    }

    pub async fn state(&self, id: &str) -> Result<Option<ExperimentState>, sqlx::Error> {
        let word = on_pool!(self, p => sqlx::query_scalar::<_, String>("SELECT state FROM experiments WHERE id = $1")
            .bind(id)
            .fetch_optional(p)
            .await)?;
        word.map(|w| w.parse().map_err(|e: String| sqlx::Error::Decode(e.into())))
            .transpose()
    }

    /// Store a trial whose place in its map is not known here (an attached
    /// rig's result, stored before the search takes it; the search's
    /// [`Store::add_trials`] places it); a trial already stored is kept.
    /// Fenced by the experiment's state: an ended experiment takes no
    /// trial (the rig's epoch has fenced the session before this: a stale
    /// session's result never gets here).
    pub async fn add_trial_unplaced(&self, id: &str, t: &StoredTrial) -> Result<(), sqlx::Error> {
        self.writable()?;
        let point = serde_json::to_string(&t.point).unwrap_or_default();
        on_pool!(self, p => sqlx::query(
            "INSERT INTO trials (experiment_id, scope, k, b, point, col, idx)
             SELECT $1, $2, $3, $4, $5, $6, $7
             WHERE EXISTS (SELECT 1 FROM experiments WHERE id = $1 AND state NOT IN ('succeeded', 'failed', 'cancelled'))
             ON CONFLICT (experiment_id, scope, k, b) DO NOTHING",
        )
        .bind(id)
        .bind(t.scope as i64)
        .bind(t.point.k)
        .bind(t.point.b)
        .bind(point)
        .bind(t.column as i64)
        .bind(t.index as i64)
        .execute(p)
        .await
        .map(|_| ()))
    }

    /// Every stored trial of an experiment.
    pub async fn trials(&self, id: &str) -> Result<Vec<StoredTrial>, sqlx::Error> {
        self.trials_page(id, None, 0, i64::MAX).await
    }

    /// Stored trials in their maps' order (scope, column, then the order
    /// within a column), a page at a time.
    pub async fn trials_page(
        &self,
        id: &str,
        scope: Option<u32>,
        offset: i64,
        limit: i64,
    ) -> Result<Vec<StoredTrial>, sqlx::Error> {
        // Trials that share a place (those stored before places existed,
        // all at (0, 0); a place given twice) are ordered by K, then B: the
        // same order on both databases (docs/service.md), never the
        // insertion order, which differs between them.
        let sql = match self.db {
            Db::Sqlite(_) => {
                "SELECT scope, col, idx, point FROM trials WHERE experiment_id = $1 AND ($2 IS NULL OR scope = $2)
                 ORDER BY scope, col, idx, k, b LIMIT $3 OFFSET $4"
            }
            Db::Postgres(_) => {
                "SELECT scope, col, idx, point FROM trials WHERE experiment_id = $1 AND ($2::BIGINT IS NULL OR scope = $2)
                 ORDER BY scope, col, idx, k, b LIMIT $3 OFFSET $4"
            }
        };
        let rows: Vec<TrialRow> = on_pool!(self, p => sqlx::query_as(sql)
            .bind(id)
            .bind(scope.map(|s| s as i64))
            .bind(limit)
            .bind(offset)
            .fetch_all(p)
            .await)?;
        Ok(stored_trials(rows))
    }

    /// Every stored evaluation of a tune, in the order stored.
    pub async fn evaluations(&self, id: &str) -> Result<Vec<StoredEvaluation>, sqlx::Error> {
        let rows: Vec<(String, String)> = on_pool!(self, p => sqlx::query_as(
            "SELECT key, record FROM evaluations WHERE experiment_id = $1 ORDER BY seq",
        )
        .bind(id)
        .fetch_all(p)
        .await)?;
        Ok(rows
            .into_iter()
            .filter_map(|(key, r)| {
                serde_json::from_str(&r)
                    .ok()
                    .map(|record| StoredEvaluation { key, record })
            })
            .collect())
    }

    pub async fn trial_count(&self, id: &str) -> Result<i64, sqlx::Error> {
        on_pool!(self, p => sqlx::query_scalar("SELECT COUNT(*) FROM trials WHERE experiment_id = $1")
            .bind(id)
            .fetch_one(p)
            .await)
    }
}
