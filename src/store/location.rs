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

    /// `parse`, with the PostgreSQL password read from `password_file`
    /// when one is given (`ZWIDTH_DB_PASSWORD_FILE`: a compose secret, so
    /// the password is in no environment variable): its first line, put
    /// into a URL that has none. A URL with a password of its own, or a
    /// SQLite location, is refused with a file given (one source each).
    pub fn parse_with_password(
        s: &str,
        password_file: Option<&std::path::Path>,
    ) -> Result<Self, String> {
        let loc = Self::parse(s)?;
        let Some(file) = password_file else {
            return Ok(loc);
        };
        let Location::Postgres(url) = &loc else {
            return Err(format!(
                "ZWIDTH_DB_PASSWORD_FILE {} is given, but --db {loc} is a SQLite file: the password file is for a postgres:// URL",
                file.display()
            ));
        };
        if has_password(url) {
            return Err(format!(
                "--db {loc} has a password of its own and ZWIDTH_DB_PASSWORD_FILE {} gives one too: give one of them",
                file.display()
            ));
        }
        let text = std::fs::read_to_string(file).map_err(|e| {
            format!(
                "ZWIDTH_DB_PASSWORD_FILE {} cannot be read: {e}",
                file.display()
            )
        })?;
        let password = text.lines().next().unwrap_or("").trim_end_matches('\r');
        if password.is_empty() {
            return Err(format!(
                "ZWIDTH_DB_PASSWORD_FILE {} is empty: its first line is the password",
                file.display()
            ));
        }
        // The password as a query parameter (libpq's form), percent-encoded;
        // checked as the URL it becomes.
        let sep = if url.contains('?') { '&' } else { '?' };
        let with = format!("{url}{sep}password={}", percent_encode(password));
        Self::parse(&with)
    }

    /// The SQLite file, if this is one.
    pub fn sqlite_path(&self) -> Option<&std::path::Path> {
        match self {
            Location::Sqlite(p) => Some(p),
            Location::Postgres(_) => None,
        }
    }
}

/// Whether a PostgreSQL URL carries a password (in its user part or as
/// `password=`).
fn has_password(url: &str) -> bool {
    let rest = url.split_once("://").map_or(url, |(_, r)| r);
    let authority = rest.split(['/', '?']).next().unwrap_or("");
    let in_user = authority
        .rsplit_once('@')
        .is_some_and(|(user, _)| user.contains(':'));
    let in_query = url
        .split_once('?')
        .is_some_and(|(_, q)| q.split('&').any(|kv| kv.starts_with("password=")));
    in_user || in_query
}

/// `s` with every byte but RFC 3986's unreserved characters as `%XX`.
fn percent_encode(s: &str) -> String {
    s.bytes()
        .map(|b| match b {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'-' | b'.' | b'_' | b'~' => {
                (b as char).to_string()
            }
            _ => format!("%{b:02X}"),
        })
        .collect()
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

    /// A compose secret's password file (issue 45 item 6): its first line
    /// becomes the URL's password (percent-encoded, so any character
    /// works), never shown; a URL with a password, a SQLite file, an
    /// empty or missing file are refused naming the variable.
    #[test]
    fn a_password_file_gives_the_postgres_password() {
        let dir = std::env::temp_dir().join(format!("zwidth-pwfile-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("pw");
        std::fs::write(&f, "s3 cr@t/&?x\nsecond line\n").unwrap();
        let loc = Location::parse_with_password("postgres://u@h/db", Some(&f)).unwrap();
        let Location::Postgres(url) = &loc else {
            panic!("{loc:?}")
        };
        let o: sqlx::postgres::PgConnectOptions = url.parse().unwrap();
        assert_eq!(o.get_username(), "u");
        assert_eq!(o.get_database(), Some("db"));
        assert!(url.ends_with("?password=s3%20cr%40t%2F%26%3Fx"), "{url}");
        assert!(!loc.to_string().contains("s3"), "{loc}");
        // An existing query keeps its parameters.
        let Location::Postgres(q) =
            Location::parse_with_password("postgres://u@h/db?sslmode=disable", Some(&f)).unwrap()
        else {
            panic!()
        };
        assert!(
            q.starts_with("postgres://u@h/db?sslmode=disable&password="),
            "{q}"
        );
        // No file: the URL as it is.
        assert_eq!(
            Location::parse_with_password("postgres://u:p@h/db", None).unwrap(),
            Location::Postgres("postgres://u:p@h/db".into())
        );
        for (url, words) in [
            ("postgres://u:p@h/db", "has a password of its own"),
            ("postgres://u@h/db?password=p", "has a password of its own"),
            ("zwidth.db", "is a SQLite file"),
        ] {
            let e = Location::parse_with_password(url, Some(&f)).unwrap_err();
            assert!(e.contains(words), "{url}: {e}");
            assert!(!e.contains("cr@t"), "{e}");
        }
        std::fs::write(&f, "\n").unwrap();
        let e = Location::parse_with_password("postgres://u@h/db", Some(&f)).unwrap_err();
        assert!(e.contains("is empty"), "{e}");
        let e =
            Location::parse_with_password("postgres://u@h/db", Some(&dir.join("no"))).unwrap_err();
        assert!(
            e.starts_with("ZWIDTH_DB_PASSWORD_FILE ") && e.contains("cannot be read"),
            "{e}"
        );
        std::fs::remove_dir_all(&dir).unwrap();
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
