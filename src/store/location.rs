//! Where a store lives, as `--db` and `ZWIDTH_DB` give it: a SQLite file
//! (a path, or `sqlite://PATH`) or a PostgreSQL database
//! (`postgres://` or `postgresql://`, libpq's URL form).

use std::path::PathBuf;

#[derive(Debug, Clone, PartialEq)]
pub enum Location {
    Sqlite(PathBuf),
    /// The URL as given (shown only with its password hidden).
    Postgres(String),
}

impl Location {
    /// Parse `--db`: a PostgreSQL URL, `sqlite://PATH`, or a plain path
    /// (SQLite). Any other `scheme://` is refused, naming what is allowed.
    pub fn parse(s: &str) -> Result<Self, String> {
        let s = s.trim();
        if s.is_empty() {
            return Err("--db is empty: give a SQLite file path or a postgres:// URL".into());
        }
        let lower = s.to_ascii_lowercase();
        if lower.starts_with("postgres://") || lower.starts_with("postgresql://") {
            let loc = Location::Postgres(s.to_string());
            s.parse::<sqlx::postgres::PgConnectOptions>()
                .map_err(|e| format!("--db {loc}: not a valid PostgreSQL URL: {e}"))?;
            return Ok(loc);
        }
        if let Some(path) = s.strip_prefix("sqlite://") {
            if path.is_empty() {
                return Err("--db sqlite:// names no file: give sqlite://PATH".into());
            }
            return Ok(Location::Sqlite(PathBuf::from(path)));
        }
        if let Some((scheme, _)) = s.split_once("://") {
            return Err(format!(
                "--db {}: unknown scheme `{scheme}://`; give a SQLite file path (or sqlite://PATH) or a postgres:// URL",
                hide_password(s)
            ));
        }
        Ok(Location::Sqlite(PathBuf::from(s)))
    }

    /// The SQLite file, if this is one.
    pub fn sqlite_path(&self) -> Option<&std::path::Path> {
        match self {
            Location::Sqlite(p) => Some(p),
            Location::Postgres(_) => None,
        }
    }
}

/// A URL as shown in logs and errors: never its password. A PostgreSQL URL
/// is rebuilt from what libpq's syntax parses out of it (user, host or
/// socket directory, port, database), so a password given any way (in the
/// user part, as `?password=`, with characters that confuse a reader) is
/// left out; one that does not parse shows only its scheme.
fn hide_password(url: &str) -> String {
    let scheme = url.split_once("://").map_or("postgres", |(s, _)| s);
    match url.parse::<sqlx::postgres::PgConnectOptions>() {
        Ok(o) => {
            let db = o.get_database().unwrap_or("");
            let place = match o.get_socket() {
                Some(dir) => format!("/{db}?host={}", dir.display()),
                None => format!("{}:{}/{db}", o.get_host(), o.get_port()),
            };
            format!("{scheme}://{}@{place}", o.get_username())
        }
        Err(_) => format!("{scheme}://… (not shown: it may hold a password)"),
    }
}

impl std::fmt::Display for Location {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Location::Sqlite(p) => write!(f, "{}", p.display()),
            Location::Postgres(url) => f.write_str(&hide_password(url)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn db_locations_parse_by_scheme() {
        assert_eq!(
            Location::parse("zwidth.db").unwrap(),
            Location::Sqlite("zwidth.db".into())
        );
        assert_eq!(
            Location::parse("sqlite:///tmp/a.db").unwrap(),
            Location::Sqlite("/tmp/a.db".into())
        );
        let pg = "postgres://u:pw@localhost/z?host=/tmp/s";
        assert_eq!(Location::parse(pg).unwrap(), Location::Postgres(pg.into()));
        assert!(matches!(
            Location::parse("postgresql:///z").unwrap(),
            Location::Postgres(_)
        ));
        let e = Location::parse("mysql://root:hunter2@db/z").unwrap_err();
        assert!(!e.contains("hunter2"), "{e}");
        assert!(e.contains("unknown scheme `mysql://`"), "{e}");
        assert!(e.contains("postgres://"), "names what is allowed: {e}");
        assert!(!e.contains("hunter2"), "no password in errors: {e}");
        assert!(Location::parse("").is_err());
        assert!(Location::parse("sqlite://").is_err());
        let e = Location::parse("postgres://u:pw@host:notaport/z").unwrap_err();
        assert!(e.contains("not a valid PostgreSQL URL"), "{e}");
        assert!(!e.contains(":pw@"), "{e}");
    }

    #[test]
    fn passwords_are_hidden_when_shown() {
        for (url, shown) in [
            ("postgres://u:s3cret@h/db", "postgres://u@h:5432/db"),
            (
                "postgres://u:s3cret@h:6543/db?sslmode=disable",
                "postgres://u@h:6543/db",
            ),
            (
                "postgres://u@h/db?password=s3cret",
                "postgres://u@h:5432/db",
            ),
            (
                "postgresql://u:s3cret@localhost/db?host=/tmp/pg",
                "postgresql://u@/db?host=/tmp/pg",
            ),
        ] {
            assert_eq!(hide_password(url), shown, "{url}");
            assert_eq!(Location::Postgres(url.into()).to_string(), shown);
        }
        // Unparseable: nothing of it is shown.
        let shown = hide_password("postgres://u:p?w@h:x/db");
        assert!(!shown.contains("p?w") && !shown.contains("u:"), "{shown}");
    }
}
