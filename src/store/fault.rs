//! What a storage error means for the caller: the disk is full, the
//! database is busy (another writer holds the lock), the file is corrupt,
//! or something else. The HTTP layer turns these into 507, 503 and 500.

use serde::Serialize;

/// Prefix of the error a known-corrupt store answers writes with.
pub const CORRUPT_PREFIX: &str = "the database is corrupt; writes are refused";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// SQLITE_FULL, or an I/O error while writing (ENOSPC reaches SQLite as
    /// SQLITE_IOERR_WRITE / _FSYNC on some file systems).
    Full,
    /// SQLITE_BUSY / SQLITE_LOCKED after the busy timeout, or no pooled
    /// connection in time: try again later.
    Busy,
    /// SQLITE_CORRUPT or SQLITE_NOTADB, or a store that knows it is corrupt.
    Corrupt,
    Other,
}

// SQLite primary result codes (https://sqlite.org/rescode.html).
const SQLITE_BUSY: i64 = 5;
const SQLITE_LOCKED: i64 = 6;
const SQLITE_IOERR: i64 = 10;
const SQLITE_CORRUPT: i64 = 11;
const SQLITE_FULL: i64 = 13;
const SQLITE_NOTADB: i64 = 26;

impl Fault {
    pub fn of(e: &sqlx::Error) -> Fault {
        match e {
            sqlx::Error::Database(d) => {
                // Extended codes carry the primary code in the low byte.
                let code = d
                    .code()
                    .and_then(|c| c.parse::<i64>().ok())
                    .map(|c| c & 0xff);
                match code {
                    Some(SQLITE_FULL) | Some(SQLITE_IOERR) => Fault::Full,
                    Some(SQLITE_BUSY) | Some(SQLITE_LOCKED) => Fault::Busy,
                    Some(SQLITE_CORRUPT) | Some(SQLITE_NOTADB) => Fault::Corrupt,
                    _ => Fault::Other,
                }
            }
            sqlx::Error::PoolTimedOut => Fault::Busy,
            sqlx::Error::Protocol(m) if m.starts_with(CORRUPT_PREFIX) => Fault::Corrupt,
            _ => Fault::Other,
        }
    }
}

/// The database's health as `/healthz` shows it.
#[derive(Debug, Clone, Default, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Health {
    /// When it was last checked (unix ms); 0: not yet.
    pub checked_ms: i64,
    /// What the integrity check reported, when it was not "ok".
    #[serde(skip_serializing_if = "Option::is_none")]
    pub corrupt: Option<String>,
}

impl Health {
    pub fn ok() -> Self {
        Self {
            checked_ms: super::now_ms(),
            corrupt: None,
        }
    }

    pub fn corrupt(why: String) -> Self {
        Self {
            checked_ms: super::now_ms(),
            corrupt: Some(why),
        }
    }
}
