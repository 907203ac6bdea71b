//! The lease model (issue 14), shared by experiments and their work units:
//! a claim holds a run (or a unit) at an attempt; every write names that
//! attempt, and one of a stale attempt changes nothing ([`lost`]). What a
//! heartbeat finds ([`Held`]), how many expiries a run survives
//! ([`MAX_LOST`]), and how a batch of trials is written under a lease.

use crate::zwidth::search::StoredTrial;

/// Which unit of its experiment a lease holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnitPlace {
    pub scope: i64,
    pub col: i64,
}

/// A claimed run: the experiment and the attempt that holds it; or, with
/// `unit`, one of its work units (`units.rs`) and the unit's attempt.
#[derive(Debug, Clone, PartialEq)]
pub struct Lease {
    pub id: String,
    pub attempt: i64,
    pub unit: Option<UnitPlace>,
}

impl Lease {
    /// The lease of experiment `id` at `attempt`.
    pub fn of(id: impl Into<String>, attempt: i64) -> Self {
        Self {
            id: id.into(),
            attempt,
            unit: None,
        }
    }
}

/// Insert `trials` of experiment `id` in transaction `tx`, many rows per
/// statement: a trial already stored keeps its point and takes the place
/// given here. (A macro: the transaction's type is each backend's.)
macro_rules! insert_trials {
    ($tx:ident, $id:expr, $trials:expr) => {
        // 7 parameters a row: well under either database's limit.
        for chunk in super::lease::merge_repeats($trials).chunks(500) {
            let mut q = sqlx::QueryBuilder::new(
                "INSERT INTO trials (experiment_id, scope, k, b, point, col, idx) ",
            );
            q.push_values(chunk, |mut row, t| {
                row.push_bind($id)
                    .push_bind(t.scope as i64)
                    .push_bind(t.point.k)
                    .push_bind(t.point.b)
                    .push_bind(serde_json::to_string(&t.point).unwrap_or_default())
                    .push_bind(t.column as i64)
                    .push_bind(t.index as i64);
            });
            q.push(
                " ON CONFLICT (experiment_id, scope, k, b) DO UPDATE SET col = excluded.col, idx = excluded.idx",
            );
            q.build().execute(&mut *$tx).await?;
        }
    };
}
pub(super) use insert_trials;

/// `trials` with each (scope, K, B) once, as inserting them one at a time
/// would store them: the first one's point, the last one's place (one
/// statement may not touch a row twice).
pub(super) fn merge_repeats(trials: &[StoredTrial]) -> Vec<StoredTrial> {
    let mut at = std::collections::HashMap::new();
    let mut out: Vec<StoredTrial> = Vec::with_capacity(trials.len());
    for t in trials {
        let key = (t.scope, t.point.k.to_bits(), t.point.b.to_bits());
        match at.get(&key) {
            Some(&i) => {
                let first: &mut StoredTrial = &mut out[i];
                first.column = t.column;
                first.index = t.index;
            }
            None => {
                at.insert(key, out.len());
                out.push(t.clone());
            }
        }
    }
    out
}

/// What a heartbeat found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Held {
    /// Still ours; the lease is extended.
    Held,
    /// Ours, but cancelled: stop between trials.
    Cancelled,
    /// Not ours any more (expired and claimed again, or ended): abandon it.
    Lost,
}

/// Expired leases after which an experiment fails instead of being
/// claimed again (its worker died or stalled this many times).
pub const MAX_LOST: i64 = 3;

/// A fraction done as stored: 0 to 1, 0 when not finite.
pub(super) fn fraction_done(f: f64) -> f64 {
    if f.is_finite() {
        f.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

pub(super) fn lost(lease: &Lease) -> sqlx::Error {
    let unit = lease
        .unit
        .map(|u| format!(" unit {}/{}", u.scope, u.col))
        .unwrap_or_default();
    sqlx::Error::Protocol(format!(
        "{}: experiment {}{unit} attempt {} (another worker holds it now, or it ended)",
        super::fault::LEASE_LOST_PREFIX,
        lease.id,
        lease.attempt
    ))
}

#[cfg(test)]
mod fraction_tests {
    /// A fraction done is stored as given within [0, 1], clamped beyond,
    /// 0 when not finite (a mutant returning 0 passed the store's tests).
    #[test]
    fn a_fraction_done_is_stored_within_0_and_1() {
        use super::fraction_done;
        assert_eq!(fraction_done(0.25), 0.25);
        assert_eq!(fraction_done(1.5), 1.0);
        assert_eq!(fraction_done(-0.5), 0.0);
        assert_eq!(fraction_done(f64::NAN), 0.0);
        assert_eq!(fraction_done(f64::INFINITY), 0.0);
    }
}
