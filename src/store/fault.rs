//! What a storage error means for the caller: the disk is full, the
//! database is busy (another writer holds the lock), the file is corrupt,
//! or something else. The HTTP layer turns these into 507, 503 and 500.

use serde::Serialize;

/// Prefix of the error a known-corrupt store answers writes with.
pub const CORRUPT_PREFIX: &str = "the database is corrupt; writes are refused";

/// Prefix of the error a write of a run answers when the run's lease was
/// taken over (or the run ended): the writer must abandon the run.
pub const LEASE_LOST_PREFIX: &str = "the lease on this run is lost";

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
    /// A write of a run whose lease another worker holds now (or whose run
    /// ended): nothing was written, and the writer abandons the run.
    Lost,
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
            sqlx::Error::Database(d)
                if d.try_downcast_ref::<sqlx::postgres::PgDatabaseError>()
                    .is_some() =>
            {
                // PostgreSQL's SQLSTATE (https://www.postgresql.org/docs/current/errcodes-appendix.html).
                match d.code().as_deref() {
                    Some("53100") => Fault::Full,
                    Some("40001" | "40P01" | "55P03" | "57P01" | "57P03" | "53300") => Fault::Busy,
                    Some("XX001" | "XX002") => Fault::Corrupt,
                    _ => Fault::Other,
                }
            }
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
            // No connection in time, or one lost (a database server
            // restarting): try again.
            sqlx::Error::PoolTimedOut | sqlx::Error::Io(_) => Fault::Busy,
            sqlx::Error::Protocol(m) if m.starts_with(CORRUPT_PREFIX) => Fault::Corrupt,
            sqlx::Error::Protocol(m) if m.starts_with(LEASE_LOST_PREFIX) => Fault::Lost,
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

#[cfg(test)]
mod tests {
    use super::*;
    use sqlx::sqlite::{SqliteConnectOptions, SqlitePoolOptions};
    use sqlx::Connection;

    /// Real SQLite errors, provoked: SQLITE_FULL from a page cap, SQLITE_BUSY
    /// from a second writer, and sqlx's own pool timeout.
    #[test]
    fn sqlite_errors_map_to_what_the_caller_can_do() {
        let rt = tokio::runtime::Runtime::new().unwrap();
        rt.block_on(async {
            let dir = std::env::temp_dir().join(format!("zwidth-fault-{}", std::process::id()));
            std::fs::create_dir_all(&dir).unwrap();
            // A database that may not grow past 8 pages: SQLITE_FULL.
            let opts = SqliteConnectOptions::new()
                .filename(dir.join("full.db"))
                .create_if_missing(true)
                .pragma("max_page_count", "8");
            let mut c = sqlx::SqliteConnection::connect_with(&opts).await.unwrap();
            sqlx::query("CREATE TABLE t (x TEXT)")
                .execute(&mut c)
                .await
                .unwrap();
            let mut full = None;
            for _ in 0..100 {
                if let Err(e) = sqlx::query("INSERT INTO t VALUES (?)")
                    .bind("x".repeat(4000))
                    .execute(&mut c)
                    .await
                {
                    full = Some(e);
                    break;
                }
            }
            assert_eq!(Fault::of(&full.expect("the cap is reached")), Fault::Full);
            // A write while another connection holds the write lock: BUSY.
            let busy = SqliteConnectOptions::new()
                .filename(dir.join("busy.db"))
                .create_if_missing(true)
                .busy_timeout(std::time::Duration::ZERO);
            let mut a = sqlx::SqliteConnection::connect_with(&busy).await.unwrap();
            let mut b = sqlx::SqliteConnection::connect_with(&busy).await.unwrap();
            sqlx::query("CREATE TABLE t (x)")
                .execute(&mut a)
                .await
                .unwrap();
            sqlx::query("BEGIN IMMEDIATE")
                .execute(&mut a)
                .await
                .unwrap();
            let e = sqlx::query("INSERT INTO t VALUES (1)")
                .execute(&mut b)
                .await
                .unwrap_err();
            assert_eq!(Fault::of(&e), Fault::Busy);
            // No pooled connection in time: busy too.
            let pool = SqlitePoolOptions::new()
                .max_connections(1)
                .acquire_timeout(std::time::Duration::from_millis(50))
                .connect_with(busy.clone())
                .await
                .unwrap();
            let held = pool.acquire().await.unwrap();
            let e = pool.acquire().await.unwrap_err();
            assert_eq!(Fault::of(&e), Fault::Busy);
            drop(held);
            // A syntax error is none of these.
            let e = sqlx::query("SELEC 1").execute(&mut b).await.unwrap_err();
            assert_eq!(Fault::of(&e), Fault::Other);
            std::fs::remove_dir_all(dir).unwrap();
        });
        // The store's own refusal of writes to a known-corrupt database.
        let own = sqlx::Error::Protocol(format!("{CORRUPT_PREFIX}: page 3"));
        assert_eq!(Fault::of(&own), Fault::Corrupt);
        assert_eq!(
            Fault::of(&sqlx::Error::Protocol("other".into())),
            Fault::Other
        );
    }
}
