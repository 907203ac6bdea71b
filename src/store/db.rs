//! The store itself: its pool on either database ([`Db`], and
//! [`on_pool!`] to run one body on whichever it is), and the rows every part
//! of the store reads.

use serde::Serialize;
use sqlx::{FromRow, PgPool, SqlitePool};

use super::fault::Health;
use super::state::ExperimentState;
use super::wake::Wakeups;
use crate::zwidth::search::StoredTrial;

/// The database behind a store.
#[derive(Debug, Clone)]
pub(super) enum Db {
    Sqlite(SqlitePool),
    Postgres(PgPool),
}

/// Run `$body` with `$p` bound to this store's pool, whichever database it
/// is: the body is compiled once per backend (shared SQL, typed twice).
macro_rules! on_pool {
    ($store:expr, $p:ident => $body:expr) => {
        match &$store.db {
            Db::Sqlite($p) => $body,
            Db::Postgres($p) => $body,
        }
    };
}
pub(crate) use on_pool;

#[derive(Debug, Clone)]
pub struct Store {
    pub(super) db: Db,
    /// What the last integrity check found; a corrupt database refuses writes.
    pub(super) health: std::sync::Arc<std::sync::Mutex<Health>>,
    /// Wake-ups when units are queued or end (`wake.rs`).
    pub(super) wake: std::sync::Arc<Wakeups>,
}

/// One experiment row.
#[derive(Debug, Clone, Serialize, FromRow)]
pub struct ExperimentRow {
    pub id: String,
    pub kind: String,
    pub spec: String,
    #[sqlx(try_from = "String")]
    pub state: ExperimentState,
    pub priority: i64,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    pub trials_done: i64,
    pub result: Option<String>,
    pub error: Option<String>,
    pub idempotency_key: Option<String>,
    pub not_before_ms: Option<i64>,
    pub rig: String,
    /// Fraction of the work done, 0 to 1.
    pub progress: f64,
    /// A tune's best so far (JSON).
    pub best: Option<String>,
    /// Claims so far; the one holding the run now (see `lease.rs`).
    pub attempt: i64,
    /// The worker holding the run, if running.
    pub worker: Option<String>,
    /// When its lease ends (database clock, unix ms).
    pub lease_until_ms: Option<i64>,
}

/// A stored trial as read: scope, column, index, the point (JSON).
pub(super) type TrialRow = (i64, i64, i64, String);

/// The trials of `rows` (a point that does not parse is left out).
pub(super) fn stored_trials(rows: Vec<TrialRow>) -> Vec<StoredTrial> {
    rows.into_iter()
        .filter_map(|(scope, column, index, p)| {
            serde_json::from_str(&p).ok().map(|point| StoredTrial {
                scope: scope as u32,
                column: column as u32,
                index: index as u32,
                point,
            })
        })
        .collect()
}
