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

/// `scheme://user:secret@host…` with the secret replaced by `***`.
fn hide_password(url: &str) -> String {
    let Some((scheme, rest)) = url.split_once("://") else {
        return url.to_string();
    };
    // The user info ends at the last '@' before the path or query.
    let authority_end = rest.find(['/', '?']).unwrap_or(rest.len());
    match rest[..authority_end].rfind('@') {
        Some(at) => match rest[..at].split_once(':') {
            Some((user, _)) => format!("{scheme}://{user}:***{}", &rest[at..]),
            None => url.to_string(),
        },
        None => url.to_string(),
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
            ("postgres://u:s3cret@h/db", "postgres://u:***@h/db"),
            ("postgres://u:a@b@h/db?x=1", "postgres://u:***@h/db?x=1"),
            ("postgres://u@h/db", "postgres://u@h/db"),
            ("postgres:///db?host=/tmp/x", "postgres:///db?host=/tmp/x"),
            ("postgres://h/db?user=a@b", "postgres://h/db?user=a@b"),
        ] {
            assert_eq!(hide_password(url), shown);
            assert_eq!(Location::Postgres(url.into()).to_string(), shown);
        }
    }
}
