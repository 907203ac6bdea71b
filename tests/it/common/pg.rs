//! PostgreSQL for tests: `ZWIDTH_TEST_PG` is an admin URL to a throwaway
//! server (`.ci/postgres start` makes one, as CI does); each caller gets a
//! database of its own. Without it the Postgres half of a test is skipped,
//! unless `ZWIDTH_REQUIRE_PG=1` (CI), where it fails.

use std::sync::atomic::{AtomicUsize, Ordering};

static NEXT: AtomicUsize = AtomicUsize::new(0);

/// The admin URL, or None (skip) when Postgres is not configured and not
/// required. Panics when required and missing.
pub fn admin_url() -> Option<String> {
    required("ZWIDTH_TEST_PG", "the PostgreSQL half of this test")
}

/// Environment variable `name` set by `.ci/postgres start`, or None (skip,
/// saying `what` is skipped) unless `ZWIDTH_REQUIRE_PG=1`, where it panics.
fn required(name: &str, what: &str) -> Option<String> {
    match std::env::var(name) {
        Ok(u) if !u.is_empty() => Some(u),
        _ => {
            assert!(
                std::env::var("ZWIDTH_REQUIRE_PG").as_deref() != Ok("1"),
                "ZWIDTH_REQUIRE_PG=1 but {name} is not set: start one with `eval \"$(.ci/postgres start)\"`"
            );
            eprintln!("{name} not set: {what} is skipped");
            None
        }
    }
}

/// `url` with its database name replaced by `db`.
pub fn with_database(url: &str, db: &str) -> String {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, format!("?{q}")),
        None => (url, String::new()),
    };
    let after_scheme = base.find("://").map_or(0, |i| i + 3);
    let path_start = base[after_scheme..]
        .find('/')
        .map_or(base.len(), |i| after_scheme + i);
    format!("{}/{db}{query}", &base[..path_start])
}

/// A fresh, empty database on the test server: its URL.
pub async fn fresh_database(name: &str) -> Option<String> {
    let admin = admin_url()?;
    use sqlx::Connection;
    let db = format!(
        "zt_{}_{}_{}",
        name.replace(|c: char| !c.is_ascii_alphanumeric(), "_"),
        std::process::id(),
        NEXT.fetch_add(1, Ordering::Relaxed)
    );
    let mut c = sqlx::PgConnection::connect(&admin)
        .await
        .expect("connect to ZWIDTH_TEST_PG");
    sqlx::query(sqlx::AssertSqlSafe(format!("DROP DATABASE IF EXISTS {db}")))
        .execute(&mut c)
        .await
        .unwrap();
    sqlx::query(sqlx::AssertSqlSafe(format!("CREATE DATABASE {db}")))
        .execute(&mut c)
        .await
        .unwrap();
    c.close().await.unwrap();
    Some(with_database(&admin, &db))
}

/// [`fresh_database`] for synchronous tests.
pub fn fresh_database_blocking(name: &str) -> Option<String> {
    tokio::runtime::Runtime::new()
        .unwrap()
        .block_on(fresh_database(name))
}

/// `ZWIDTH_TEST_PG_TLS`: the same server over TLS on loopback
/// (`sslmode=verify-full` with the throwaway CA `.ci/postgres` made), or
/// None (skip) unless required, as [`admin_url`].
pub fn tls_url() -> Option<String> {
    required("ZWIDTH_TEST_PG_TLS", "the PostgreSQL TLS test")
}
