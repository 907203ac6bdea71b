//! Errors as RFC 9457 `application/problem+json`, naming the field where
//! one is to blame; JSON bodies and query strings parsed so that every
//! rejection says which field, which value and what is allowed; and a
//! last layer that turns any other error response (the framework's own:
//! unknown route, wrong method, body too large, timeout) into a problem.

use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;

use crate::error::SpecError;
use crate::store::Fault;

/// The body of every error response (RFC 9457 problem details).
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ProblemBody {
    #[serde(rename = "type")]
    pub kind: String,
    pub title: String,
    pub status: u16,
    pub detail: String,
    /// The offending field, when one is to blame.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
}

pub const PROBLEM_JSON: &str = "application/problem+json";

/// An RFC 9457 problem.
#[derive(Debug)]
pub struct Problem {
    pub status: StatusCode,
    pub title: &'static str,
    pub detail: String,
    pub field: Option<String>,
    /// Seconds after which a retry may succeed (503).
    pub retry_after_s: Option<u32>,
}

impl Problem {
    pub fn new(status: StatusCode, title: &'static str, detail: impl Into<String>) -> Self {
        Self {
            status,
            title,
            detail: detail.into(),
            field: None,
            retry_after_s: None,
        }
    }

    pub fn with_field(mut self, field: impl Into<String>) -> Self {
        self.field = Some(field.into());
        self
    }

    pub fn internal(e: impl std::fmt::Display) -> Self {
        tracing::error!(error = %e, "internal error");
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "Internal error",
            "the server could not complete the request",
        )
    }

    /// A storage error, as the client can act on it: 507 when the disk is
    /// full (nothing was stored), 503 with Retry-After when the database is
    /// busy, unreachable or corrupt, else 500. `postgres`: the database is
    /// a server, so a connection that cannot be had means it is unreachable,
    /// not locked.
    pub fn store(e: sqlx::Error, postgres: bool) -> Self {
        // SQLSTATE class 08 (connection exception), 57P01 (the server shut
        // down), 57P03 (cannot connect now).
        let code = match &e {
            sqlx::Error::Database(d) => d.code().map(|c| c.into_owned()),
            _ => None,
        };
        let unreachable = postgres
            && (matches!(
                e,
                sqlx::Error::PoolTimedOut | sqlx::Error::Io(_) | sqlx::Error::Tls(_)
            ) || code.is_some_and(|c| c.starts_with("08") || c == "57P01" || c == "57P03"));
        if unreachable {
            tracing::warn!(error = %e, "database unreachable");
            let mut p = Self::new(
                StatusCode::SERVICE_UNAVAILABLE,
                "Database unreachable",
                format!("the database server cannot be reached ({e}): nothing was stored; retry"),
            );
            p.retry_after_s = Some(1);
            return p;
        }
        match Fault::of(&e) {
            Fault::Full => {
                tracing::error!(error = %e, "storage full");
                Self::new(
                    StatusCode::INSUFFICIENT_STORAGE,
                    "Insufficient storage",
                    "the database could not be written (no space left on its disk?): nothing was stored; retry once space is freed",
                )
            }
            Fault::Busy => {
                tracing::warn!(error = %e, "database busy");
                let mut p = Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "Storage busy",
                    "the database is locked by another writer: nothing was stored; retry",
                );
                p.retry_after_s = Some(1);
                p
            }
            Fault::Corrupt => {
                tracing::error!(error = %e, "database corrupt");
                Self::new(
                    StatusCode::SERVICE_UNAVAILABLE,
                    "Database corrupt",
                    format!("{e}; restore a backup (zwidth backup) and restart"),
                )
            }
            Fault::Other | Fault::Lost => Self::internal(e),
        }
    }

    pub fn not_found(what: &str, id: &str) -> Self {
        Self::new(
            StatusCode::NOT_FOUND,
            "Not found",
            format!("no {what} {id}"),
        )
    }
}

impl From<SpecError> for Problem {
    fn from(e: SpecError) -> Self {
        Self::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid request",
            e.to_string(),
        )
        .with_field(e.field)
    }
}

impl IntoResponse for Problem {
    fn into_response(self) -> Response {
        let mut body = json!({
            "type": "about:blank",
            "title": self.title,
            "status": self.status.as_u16(),
            "detail": self.detail,
        });
        if let Some(f) = self.field {
            body["field"] = Value::String(f);
        }
        let mut r = (
            self.status,
            [(header::CONTENT_TYPE, PROBLEM_JSON)],
            body.to_string(),
        )
            .into_response();
        if let Some(s) = self.retry_after_s {
            r.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        r
    }
}

/// Parse a JSON body into `T`, naming the field a parse error is in
/// (`scene.device.mass`), or `body` when it is the whole document.
pub fn json_body<T: serde::de::DeserializeOwned>(bytes: &[u8], what: &str) -> Result<T, Problem> {
    // A key written twice: refused (serde would keep the last silently:
    // `{"kind":"map","kind":"compare"}` ran as a compare).
    if let Some(d) = crate::error::duplicate_key(bytes) {
        return Err(d.error("").into());
    }
    let mut de = serde_json::Deserializer::from_slice(bytes);
    let v = serde_path_to_error::deserialize(&mut de).map_err(|e| parse_problem(e, what, ""))?;
    // Nothing but white space may follow the document.
    de.end().map_err(|e| {
        Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid request",
            format!("the body is not a valid {what}: {e}"),
        )
        .with_field("body")
    })?;
    // PostgreSQL's text cannot hold U+0000 (it was a 500 there): refused
    // on both databases, naming the string's field. In JSON a NUL can only
    // be written `\u0000`, so only such bodies are walked.
    if bytes.windows(6).any(|w| w == b"\\u0000") {
        if let Some(field) = serde_json::from_slice::<Value>(bytes)
            .ok()
            .and_then(|doc| nul_in(&doc, String::new()))
        {
            return Err(crate::error::SpecError::new(
                &field,
                "(a string with U+0000)",
                "text without NUL characters (U+0000)",
            )
            .into());
        }
    }
    Ok(v)
}

/// The path (`a.b[1]`, as serde_path_to_error writes it; `body` for the
/// document) of the first string or key that holds a NUL character.
fn nul_in(v: &Value, path: String) -> Option<String> {
    let here = || {
        if path.is_empty() {
            "body".to_string()
        } else {
            path.clone()
        }
    };
    match v {
        Value::String(s) if s.contains('\0') => Some(here()),
        Value::Array(items) => items
            .iter()
            .enumerate()
            .find_map(|(i, x)| nul_in(x, format!("{path}[{i}]"))),
        Value::Object(map) => map.iter().find_map(|(key, x)| {
            // A key with a NUL is named with it written `\u0000`.
            let k = key.replace('\0', "\\u0000");
            let p = if path.is_empty() {
                k
            } else {
                format!("{path}.{k}")
            };
            if key.contains('\0') {
                Some(p)
            } else {
                nul_in(x, p)
            }
        }),
        _ => None,
    }
}

/// `T` from a parsed value, naming fields below `prefix` (`""` or `a.`).
pub fn from_value<T: serde::de::DeserializeOwned>(
    v: Value,
    what: &str,
    prefix: &str,
) -> Result<T, Problem> {
    serde_path_to_error::deserialize(v).map_err(|e| parse_problem(e, what, prefix))
}

fn parse_problem<E: std::fmt::Display>(
    e: serde_path_to_error::Error<E>,
    what: &str,
    prefix: &str,
) -> Problem {
    let inner = e.inner().to_string();
    let path = e.path().to_string();
    let field = if path.is_empty() || path == "." || path == "?" {
        match named_in(&inner) {
            Some(n) => format!("{prefix}{n}"),
            None if prefix.is_empty() => "body".into(),
            None => prefix.trim_end_matches('.').to_string(),
        }
    } else {
        format!("{prefix}{path}")
    };
    Problem::new(
        StatusCode::UNPROCESSABLE_ENTITY,
        "Invalid request",
        format!("the body is not a valid {what}: {field}: {inner}"),
    )
    .with_field(field)
}

/// The field serde names in "unknown field `x`" / "missing field `x`".
fn named_in(msg: &str) -> Option<String> {
    for pre in ["unknown field `", "missing field `", "unknown variant `"] {
        if let Some(rest) = msg.split(pre).nth(1) {
            let name = rest.split('`').next()?;
            return Some(if pre == "unknown variant `" {
                "kind".into()
            } else {
                name.to_string()
            });
        }
    }
    None
}

/// A query string as named values; a name not in `allowed`, a repeated
/// one, or a string that is not `a=b&c=d` is a 422 naming it.
pub struct QueryArgs(BTreeMap<String, String>);

impl QueryArgs {
    pub fn parse(raw: Option<&str>, allowed: &[&str]) -> Result<Self, Problem> {
        let pairs: Vec<(String, String)> =
            serde_urlencoded::from_str(raw.unwrap_or("")).map_err(|e| {
                Problem::new(
                    StatusCode::UNPROCESSABLE_ENTITY,
                    "Invalid query",
                    format!("the query string cannot be read: {e}"),
                )
                .with_field("query")
            })?;
        let mut map = BTreeMap::new();
        for (k, v) in pairs {
            if !allowed.contains(&k.as_str()) {
                return Err(SpecError::new(
                    k.clone(),
                    format!("{v:?}"),
                    format!(
                        "is not a parameter here; allowed: {}",
                        if allowed.is_empty() {
                            "none".into()
                        } else {
                            allowed.join(", ")
                        }
                    ),
                )
                .into());
            }
            if map.insert(k.clone(), v).is_some() {
                return Err(SpecError::new(k, "(repeated)", "give it once").into());
            }
        }
        Ok(Self(map))
    }

    pub fn str(&self, name: &str) -> Option<&str> {
        self.0.get(name).map(String::as_str)
    }

    /// An integer in `range`, or `None` when absent.
    pub fn int(
        &self,
        name: &str,
        range: std::ops::RangeInclusive<i64>,
    ) -> Result<Option<i64>, Problem> {
        let Some(v) = self.str(name) else {
            return Ok(None);
        };
        match v.parse::<i64>() {
            Ok(n) if range.contains(&n) => Ok(Some(n)),
            _ => Err(SpecError::new(
                name,
                format!("{v:?}"),
                format!(
                    "must be a whole number {} to {}",
                    range.start(),
                    range.end()
                ),
            )
            .into()),
        }
    }

    /// `true`/`false` (also 1/0), or `None` when absent.
    pub fn flag(&self, name: &str) -> Result<Option<bool>, Problem> {
        match self.str(name) {
            None => Ok(None),
            Some("true" | "1") => Ok(Some(true)),
            Some("false" | "0") => Ok(Some(false)),
            Some(v) => Err(SpecError::new(name, format!("{v:?}"), "must be true or false").into()),
        }
    }
}

/// Most bytes of a framework error's text kept as the problem's detail.
const DETAIL_MAX: usize = 500;

/// Turn every error response that is not already a problem (axum's and
/// tower-http's own rejections) into one, keeping status and text.
pub async fn problems_everywhere(resp: Response) -> Response {
    let status = resp.status();
    // Ours are problem+json already (or, /healthz's 503, a JSON report;
    // or a dashboard's error page: the framework's own are plain text).
    let ours = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|ct| {
            ct.starts_with(PROBLEM_JSON)
                || ct.starts_with("application/json")
                || ct.starts_with("text/html")
        });
    if !(status.is_client_error() || status.is_server_error()) || ours {
        return resp;
    }
    let (parts, body) = resp.into_parts();
    let text = axum::body::to_bytes(body, 64 * 1024)
        .await
        .map(|b| String::from_utf8_lossy(&b).into_owned())
        .unwrap_or_default();
    let mut detail: String = text.trim().chars().take(DETAIL_MAX).collect();
    let (title, field) = match status {
        StatusCode::PAYLOAD_TOO_LARGE => ("Body too large", Some("body")),
        StatusCode::NOT_FOUND => ("Not found", None),
        StatusCode::METHOD_NOT_ALLOWED => ("Method not allowed", None),
        StatusCode::SERVICE_UNAVAILABLE => ("Unavailable", None),
        // axum: "Invalid URL: Invalid UTF-8 in `id`" for a bad escape.
        StatusCode::BAD_REQUEST if detail.starts_with("Invalid URL") => {
            ("Invalid path", Some("id"))
        }
        StatusCode::URI_TOO_LONG => ("URI too long", Some("query")),
        _ => ("Request failed", None),
    };
    if detail.is_empty() {
        detail = match status {
            StatusCode::PAYLOAD_TOO_LARGE => {
                format!("the body is over {} bytes", super::BODY_LIMIT)
            }
            StatusCode::NOT_FOUND => "no such resource".into(),
            StatusCode::METHOD_NOT_ALLOWED => "this resource does not take that method".into(),
            StatusCode::SERVICE_UNAVAILABLE => "the request took too long (timeout); retry".into(),
            s => s.canonical_reason().unwrap_or("error").into(),
        };
    }
    let mut p = Problem::new(status, title, detail);
    p.field = field.map(str::to_owned);
    if status == StatusCode::SERVICE_UNAVAILABLE {
        p.retry_after_s = Some(1);
    }
    let mut r = p.into_response();
    // Keep the framework's other headers (Allow on a 405, the request id).
    for (k, v) in parts.headers.iter() {
        if k != header::CONTENT_TYPE && k != header::CONTENT_LENGTH {
            r.headers_mut().entry(k).or_insert(v.clone());
        }
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 30, defect 8: with PostgreSQL a connection that cannot be had
    /// is an unreachable server, not a lock; with SQLite it is the lock.
    #[test]
    fn an_unreachable_server_is_not_called_locked() {
        let pg = Problem::store(sqlx::Error::PoolTimedOut, true);
        assert_eq!(pg.status, StatusCode::SERVICE_UNAVAILABLE);
        assert_eq!(pg.title, "Database unreachable");
        assert!(pg.detail.contains("cannot be reached"), "{}", pg.detail);
        assert!(!pg.detail.contains("locked"), "{}", pg.detail);
        let io = std::io::Error::new(std::io::ErrorKind::ConnectionRefused, "refused");
        assert_eq!(
            Problem::store(sqlx::Error::Io(io), true).title,
            "Database unreachable"
        );
        let sqlite = Problem::store(sqlx::Error::PoolTimedOut, false);
        assert_eq!(sqlite.title, "Storage busy");
        assert!(sqlite.detail.contains("locked"), "{}", sqlite.detail);
        assert_eq!((pg.retry_after_s, sqlite.retry_after_s), (Some(1), Some(1)));
    }

    #[derive(serde::Deserialize, Debug)]
    #[allow(dead_code)]
    struct Doc {
        name: String,
        #[serde(default)]
        tags: Vec<String>,
        #[serde(default)]
        extra: BTreeMap<String, String>,
    }

    /// The field a body's NUL is in, as `serde_path_to_error` would name it.
    #[test]
    fn a_nul_character_is_refused_naming_its_field() {
        for (body, field) in [
            (r#"{"name":"a\u0000b"}"#, "name"),
            (r#"{"name":"ok","tags":["x","\u0000"]}"#, "tags[1]"),
            (r#"{"name":"ok","extra":{"k\u0000":"v"}}"#, "extra.k\\u0000"),
            (r#"{"name":"ok","extra":{"k":"\u0000"}}"#, "extra.k"),
        ] {
            let p = json_body::<Doc>(body.as_bytes(), "doc").unwrap_err();
            assert_eq!(p.status, StatusCode::UNPROCESSABLE_ENTITY, "{body}");
            assert_eq!(p.field.as_deref(), Some(field), "{body}");
            assert!(p.detail.contains("U+0000"), "{}", p.detail);
        }
        // An escaped backslash before `u0000` is the text `\u0000`, no NUL.
        let d: Doc = json_body(br#"{"name":"a\\u0000"}"#, "doc").unwrap();
        assert_eq!(d.name, "a\\u0000");
        // A string document: the field is the body.
        assert_eq!(
            nul_in(&json!("\u{0}"), String::new()).as_deref(),
            Some("body")
        );
        assert_eq!(nul_in(&json!({"a": [1, "b"]}), String::new()), None);
    }
}
