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

/// Longest message text kept in the audit (bytes).
const AUDIT_TEXT: usize = 64 * 1024;

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

    /// Keep a refused message for audit.
    pub async fn audit(
        &self,
        rig: &str,
        epoch: Option<u64>,
        trial: Option<&str>,
        reason: &str,
        message: &str,
    ) -> Result<(), sqlx::Error> {
        self.writable()?;
        let mut end = message.len().min(AUDIT_TEXT);
        while !message.is_char_boundary(end) {
            end -= 1;
        }
        on_pool!(self, p => sqlx::query("INSERT INTO agent_audit (at_ms, rig, epoch, trial, reason, message) VALUES ($1, $2, $3, $4, $5, $6)")
            .bind(now_ms())
            .bind(rig)
            .bind(epoch.map(|e| e.min(i64::MAX as u64) as i64))
            .bind(trial)
            .bind(reason)
            .bind(&message[..end])
            .execute(p)
            .await
            .map(|_| ()))
    }

    /// The audit of `rig`, newest first.
    pub async fn audit_log(&self, rig: &str, limit: i64) -> Result<Vec<AuditRow>, sqlx::Error> {
        on_pool!(self, p => sqlx::query_as("SELECT * FROM agent_audit WHERE rig = $1 ORDER BY id DESC LIMIT $2")
            .bind(rig)
            .bind(limit)
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
