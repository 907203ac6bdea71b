//! Attached rigs: the epoch counter that fences agent sessions, the audit
//! of refused agent messages, registered rigs and their quarantine.

use serde::Serialize;

use super::{now_ms, on_pool, Db, Store};

/// One refused agent message.
#[derive(Debug, Clone, Serialize, sqlx::FromRow, utoipa::ToSchema)]
pub struct AuditRow {
    pub id: i64,
    pub at_ms: i64,
    pub rig: String,
    pub epoch: Option<i64>,
    pub trial: Option<String>,
    pub reason: String,
    pub message: String,
}

/// An attached rig as registered.
#[derive(Debug, Clone, sqlx::FromRow)]
pub struct AttachedRow {
    pub id: String,
    pub description: String,
    pub created_ms: i64,
    pub quarantine: Option<String>,
}

/// Longest message text kept in the audit (bytes); the rest is cut at a
/// character boundary and the row says how long the message was.
pub const AUDIT_MESSAGE: usize = 4 * 1024;
/// Longest reason kept (bytes): an agent's refusal reason is its own text.
pub const AUDIT_REASON: usize = 1024;
/// Longest rig or trial id kept (bytes): a hello may name anything.
pub const AUDIT_ID: usize = 128;
/// The audit keeps, per rig, the newest this many rows …
pub const AUDIT_KEEP_ROWS: i64 = 1000;
/// … and none older than this (ms): 30 days.
pub const AUDIT_KEEP_MS: i64 = 30 * 24 * 3600 * 1000;
/// Most rows one page of `GET /v1/rigs/{id}/audit` returns (default 100).
pub const AUDIT_PAGE_MAX: i64 = 500;
/// The rig under which refusals of sessions that named no rig of this
/// server are kept (`GET /v1/agent/audit`, the name they gave in the
/// reason); no rig can be called so (rig ids are letters, digits, `-`
/// and `_`: `rig::check_id`).
pub const UNKNOWN_RIG: &str = "?";

pub use crate::error::clip;

impl Store {
    /// The next epoch of `rig`'s sessions: larger than every one before,
    /// also across restarts (committed before it is handed out).
    pub async fn next_epoch(&self, rig: &str) -> Result<u64, sqlx::Error> {
        self.writable()?;
        let rows: Vec<i64> = on_pool!(self, p => sqlx::query_scalar(
            "INSERT INTO rig_epochs (rig, epoch) VALUES ($1, 1) ON CONFLICT (rig) DO UPDATE SET epoch = rig_epochs.epoch + 1 RETURNING epoch",
        )
        .bind(rig)
        .fetch_all(p)
        .await)?;
        Ok(rows.first().copied().unwrap_or(1).max(1) as u64)
    }

    /// Keep a refused message for audit: every text capped ([`AUDIT_ID`],
    /// [`AUDIT_REASON`], [`AUDIT_MESSAGE`]), then the rig's audit trimmed
    /// to its retention ([`AUDIT_KEEP_ROWS`] rows, [`AUDIT_KEEP_MS`]).
    pub async fn audit(
        &self,
        rig: &str,
        epoch: Option<u64>,
        trial: Option<&str>,
        reason: &str,
        message: &str,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        let rig = clip(rig, AUDIT_ID);
        let trial = trial.map(|t| clip(t, AUDIT_ID));
        let now = now_ms();
        on_pool!(self, p => sqlx::query("INSERT INTO agent_audit (at_ms, rig, epoch, trial, reason, message) VALUES ($1, $2, $3, $4, $5, $6)")
            .bind(now)
            .bind(rig.as_ref())
            .bind(epoch.map(|e| e.min(i64::MAX as u64) as i64))
            .bind(trial.as_deref())
            .bind(clip(reason, AUDIT_REASON).as_ref())
            .bind(clip(message, AUDIT_MESSAGE).as_ref())
            .execute(p)
            .await
            .map(|_| ()))?;
        // Retention: older than the age limit, or past the newest rows.
        on_pool!(self, p => sqlx::query("DELETE FROM agent_audit WHERE rig = $1 AND (at_ms < $2 OR id <= (SELECT id FROM agent_audit WHERE rig = $1 ORDER BY id DESC LIMIT 1 OFFSET $3))")
            .bind(rig.as_ref())
            .bind(now - AUDIT_KEEP_MS)
            .bind(AUDIT_KEEP_ROWS)
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// The audit of `rig`, newest first: at most `limit` rows with ids
    /// below `before` (a page; the next page's `before` is the last id).
    pub async fn audit_log(
        &self,
        rig: &str,
        limit: i64,
        before: Option<i64>,
    ) -> Result<Vec<AuditRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as("SELECT * FROM agent_audit WHERE rig = $1 AND id < $2 ORDER BY id DESC LIMIT $3")
            .bind(rig)
            .bind(before.unwrap_or(i64::MAX))
            .bind(limit.clamp(1, AUDIT_PAGE_MAX))
            .fetch_all(p)
            .await)
    }

    /// The trial out on `rig` (written before it is sent).
    pub async fn set_trial_out(
        &self,
        rig: &str,
        trial: &str,
        epoch: u64,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("INSERT INTO rig_trials_out (rig, trial, epoch, sent_ms) VALUES ($1, $2, $3, $4) ON CONFLICT (rig) DO UPDATE SET trial = excluded.trial, epoch = excluded.epoch, sent_ms = excluded.sent_ms")
            .bind(rig)
            .bind(trial)
            .bind(epoch.min(i64::MAX as u64) as i64)
            .bind(now_ms())
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// `trial` is no longer out on `rig` (its result is committed).
    pub async fn clear_trial_out(&self, rig: &str, trial: &str) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("DELETE FROM rig_trials_out WHERE rig = $1 AND trial = $2")
            .bind(rig)
            .bind(trial)
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// The trial out on `rig` and its epoch, if one is.
    pub async fn trial_out(&self, rig: &str) -> Result<Option<(String, u64)>, sqlx::Error> {
        let row: Option<(String, i64)> = on_pool!(self, p => sqlx::query_as("SELECT trial, epoch FROM rig_trials_out WHERE rig = $1")
                .bind(rig)
                .fetch_optional(p)
                .await)?;
        Ok(row.map(|(t, e)| (t, e.max(0) as u64)))
    }

    /// The highest epoch handed out to `rig` (0: none).
    pub async fn epoch(&self, rig: &str) -> Result<u64, sqlx::Error> {
        let e: Option<i64> = on_pool!(self, p => sqlx::query_scalar("SELECT epoch FROM rig_epochs WHERE rig = $1")
            .bind(rig)
            .fetch_optional(p)
            .await)?;
        Ok(e.unwrap_or(0).max(0) as u64)
    }

    /// Register an attached rig (false: the id exists).
    pub async fn add_attached_rig(&self, id: &str, description: &str) -> Result<bool, sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query(
            "INSERT INTO attached_rigs (id, description, created_ms) VALUES ($1, $2, $3) ON CONFLICT (id) DO NOTHING",
        )
        .bind(id)
        .bind(description)
        .bind(now_ms())
        .execute(p)
        .await
        .map(|r| r.rows_affected() == 1))
    }

    pub async fn attached_rigs(&self) -> Result<Vec<AttachedRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as("SELECT * FROM attached_rigs ORDER BY created_ms, id")
            .fetch_all(p)
            .await)
    }

    /// Give `rig` its own agent credential (its SHA-256 in hex), replacing
    /// any it had: from now on that credential alone opens its sessions.
    pub async fn set_rig_credential(&self, rig: &str, sha256: &str) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("INSERT INTO rig_credentials (rig, sha256, created_ms) VALUES ($1, $2, $3) ON CONFLICT (rig) DO UPDATE SET sha256 = excluded.sha256, created_ms = excluded.created_ms")
            .bind(rig)
            .bind(sha256)
            .bind(now_ms())
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// The SHA-256 of `rig`'s own credential, if it has one.
    pub async fn rig_credential(&self, rig: &str) -> Result<Option<String>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_scalar("SELECT sha256 FROM rig_credentials WHERE rig = $1")
            .bind(rig)
            .fetch_optional(p)
            .await)
    }

    /// The rig whose own credential has this SHA-256, if any.
    pub async fn rig_of_credential(&self, sha256: &str) -> Result<Option<String>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_scalar("SELECT rig FROM rig_credentials WHERE sha256 = $1")
            .bind(sha256)
            .fetch_optional(p)
            .await)
    }

    /// Quarantine `rig` (Some(why)) or lift it (None).
    pub async fn set_quarantine(&self, rig: &str, why: Option<&str>) -> Result<(), sqlx::Error> {
        self.writable()?;
        on_pool!(self, p => sqlx::query("INSERT INTO attached_rigs (id, description, created_ms, quarantine) VALUES ($1, '', $2, $3) ON CONFLICT (id) DO UPDATE SET quarantine = excluded.quarantine")
            .bind(rig)
            .bind(now_ms())
            .bind(why)
            .execute(p)
            .await
            .map(|_| ()))
    }
}
