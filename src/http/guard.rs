//! Who may write, and from where. Mutating requests need the bearer token
//! when tokens are configured (compared in constant time), must come from
//! this server's own origin (a page elsewhere cannot make the operator's
//! browser write: `Origin`, `Sec-Fetch-Site` and, without a token, `Host`
//! are checked), and send JSON bodies as `application/json`.

use axum::extract::{Request, State};
use axum::http::{header, HeaderMap, Method, StatusCode};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};

use super::problem::Problem;
use super::AppState;

/// Equal without revealing where two secrets differ (time independent of
/// the content; the length of the configured token is not secret).
pub fn same_secret(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Whether `given` is one of `tokens`; every one is compared, no early exit.
pub fn token_accepted(tokens: &[String], given: &str) -> bool {
    tokens.iter().fold(false, |acc, k| {
        acc | same_secret(k.as_bytes(), given.as_bytes())
    })
}

/// The SHA-256 of an agent credential, in hex: what the store keeps of
/// it (`rig_credentials`), never the credential itself.
pub fn credential_digest(secret: &str) -> String {
    let d = ring::digest::digest(&ring::digest::SHA256, secret.as_bytes());
    d.as_ref().iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether agent token `given` may open a session of `rig` (issue 45 item
/// 4): a rig with its own credential (`own`, its digest) takes that alone;
/// a rig without one takes the server's shared agent tokens (`shared`), as
/// before credentials per rig (the migration, docs/rigs.md "Tokens").
/// Err: why not, naming the rig.
pub fn credential_fits(
    rig: &str,
    own: Option<&str>,
    shared: &[String],
    given: &str,
) -> Result<(), String> {
    match own {
        Some(h) if same_secret(h.as_bytes(), credential_digest(given).as_bytes()) => Ok(()),
        Some(_) => Err(format!(
            "rig {rig:?} has an agent credential of its own and this token is not it (a new one: `zwidth rig token {rig}`)"
        )),
        None if token_accepted(shared, given) => Ok(()),
        None => Err(format!(
            "this token is another rig's own credential: rig {rig:?} takes the server's agent tokens (or one of its own: `zwidth rig token {rig}`)"
        )),
    }
}

/// The token of `Authorization: Bearer <token>`, if the request has one.
pub fn bearer(headers: &HeaderMap) -> Option<&str> {
    headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "))
}

/// Mutating endpoints need `Authorization: Bearer <token>` when tokens are
/// configured: 401 without one, 403 with a wrong one.
pub fn authorize(st: &AppState, headers: &HeaderMap) -> Result<(), Problem> {
    if st.tokens.is_empty() {
        return Ok(());
    }
    match bearer(headers) {
        None => Err(Problem::new(
            StatusCode::UNAUTHORIZED,
            "Unauthorized",
            "this endpoint needs Authorization: Bearer <token>",
        )
        .with_field("Authorization")),
        Some(t) => {
            if token_accepted(&st.tokens, t) {
                Ok(())
            } else {
                Err(Problem::new(
                    StatusCode::FORBIDDEN,
                    "Forbidden",
                    "the bearer token is not accepted",
                )
                .with_field("Authorization"))
            }
        }
    }
}

/// A JSON body must say so (a form post from another site cannot).
pub fn require_json(headers: &HeaderMap) -> Result<(), Problem> {
    let ct = headers
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    let mime = ct
        .split(';')
        .next()
        .unwrap_or("")
        .trim()
        .to_ascii_lowercase();
    if mime == "application/json" {
        Ok(())
    } else {
        Err(Problem::new(
            StatusCode::UNSUPPORTED_MEDIA_TYPE,
            "Unsupported media type",
            format!(
                "Content-Type = {:?} is not allowed: send the body as application/json",
                ct
            ),
        )
        .with_field("Content-Type"))
    }
}

/// Host names that are this machine.
fn loopback_host(host: &str) -> bool {
    let name = host_name(host);
    name.eq_ignore_ascii_case("localhost")
        || name
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// The host name of a `Host` header (no port, no brackets).
fn host_name(host: &str) -> &str {
    match host.strip_prefix('[') {
        Some(v6) => v6.split(']').next().unwrap_or(""),
        None => host.rsplit_once(':').map_or(host, |(h, _)| h),
    }
}

/// Whether a request's `Host` names this server: a loopback name, an IP
/// address (a DNS-rebinding page can only name its own host, never an
/// address), or one of `hosts` (`--host`), case-insensitively.
pub fn host_allowed(hosts: &[String], host: &str) -> bool {
    let name = host_name(host);
    loopback_host(host)
        || name.parse::<std::net::IpAddr>().is_ok()
        || hosts.iter().any(|h| h.eq_ignore_ascii_case(name))
}

/// The dashboard's cookie holding the token (`POST /login`).
pub const COOKIE: &str = "zwidth_token";

/// Whether the request carries an accepted user token: `Authorization:
/// Bearer` or the dashboard's cookie.
pub fn read_authorized(st: &AppState, h: &HeaderMap) -> bool {
    let cookie = h
        .get_all(header::COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|c| c.trim().strip_prefix(COOKIE)?.strip_prefix('='))
        .next();
    [bearer(h), cookie]
        .into_iter()
        .flatten()
        .any(|t| token_accepted(&st.tokens, t))
}

/// Reads that stay open with `--reads private`: the health check, the
/// agents' upgrade (it takes an agent token), the sign-in page and the
/// dashboard's static files.
fn open_read(path: &str) -> bool {
    matches!(path, "/healthz" | "/v1/agent" | "/login") || path.starts_with("/assets/")
}

/// Every request: its `Host` must name this server (421 otherwise: a
/// DNS-rebinding page in a lab member's browser reads nothing); with
/// private reads, a read needs the token (401; a dashboard page answers
/// with the sign-in page instead).
pub async fn host_and_reads(State(st): State<AppState>, req: Request, next: Next) -> Response {
    if let Some(host) = req.headers().get(header::HOST) {
        let host = String::from_utf8_lossy(host.as_bytes());
        if !host_allowed(&st.hosts, &host) {
            return Problem::new(
                StatusCode::MISDIRECTED_REQUEST,
                "Misdirected request",
                format!(
                    "Host = {host:?} is not allowed: this server answers to localhost, IP addresses and the names given with --host (ZWIDTH_HOSTS)"
                ),
            )
            .with_field("Host")
            .into_response();
        }
    }
    let read = matches!(*req.method(), Method::GET | Method::HEAD);
    let path = req.uri().path();
    if st.private_reads && read && !open_read(path) && !read_authorized(&st, req.headers()) {
        let api = path.starts_with("/v1/") || path == "/metrics";
        if !api {
            // A dashboard page: sign in first, then back here.
            let back = req
                .uri()
                .path_and_query()
                .map_or(path, |p| p.as_str())
                .to_string();
            let to = format!(
                "/login?{}",
                serde_urlencoded::to_string([("next", back)]).unwrap_or_default()
            );
            return (StatusCode::SEE_OTHER, [(header::LOCATION, to)]).into_response();
        }
        return Problem::new(
            StatusCode::UNAUTHORIZED,
            "Unauthorized",
            "reads need the token on this server (private reads: --reads private, the default beyond loopback): Authorization: Bearer <token>",
        )
        .with_field("Authorization")
        .into_response();
    }
    next.run(req).await
}

/// Where writes may come from: no cross-site browser request, an `Origin`
/// that is this server's (or one of `--allow-origin`), and without tokens
/// a loopback `Host` (a DNS-rebinding page names its own host).
pub async fn same_origin_writes(State(st): State<AppState>, req: Request, next: Next) -> Response {
    if matches!(*req.method(), Method::GET | Method::HEAD | Method::OPTIONS) {
        return next.run(req).await;
    }
    match check_origin(&st, req.headers()) {
        Ok(()) => next.run(req).await,
        Err(p) => p.into_response(),
    }
}

fn check_origin(st: &AppState, h: &HeaderMap) -> Result<(), Problem> {
    let text = |name: header::HeaderName| h.get(name).and_then(|v| v.to_str().ok());
    let refuse = |field: &str, why: String| {
        Err(
            Problem::new(StatusCode::FORBIDDEN, "Cross-origin write refused", why)
                .with_field(field),
        )
    };
    let host = text(header::HOST).unwrap_or("");
    if st.tokens.is_empty() && !loopback_host(host) {
        return refuse(
            "Host",
            format!("Host = {host:?} is not allowed: without a token this server takes writes addressed to localhost only"),
        );
    }
    let origin = text(header::ORIGIN);
    // An origin the operator allowed (a reverse proxy's public address).
    if origin.is_some_and(|o| st.allow_origins.iter().any(|a| a == o)) {
        return Ok(());
    }
    if let Some(site) = h.get("sec-fetch-site").and_then(|v| v.to_str().ok()) {
        if site == "cross-site" || site == "same-site" {
            return refuse(
                "Sec-Fetch-Site",
                format!("Sec-Fetch-Site = {site:?}: a page of another site may not write here"),
            );
        }
    }
    if let Some(origin) = origin {
        let own = format!("http://{host}");
        // Served over TLS (`serve --tls-cert`), the page's origin is https.
        if origin != own && origin != format!("https://{host}") {
            return refuse(
                "Origin",
                format!(
                    "Origin = {origin:?} is not allowed: writes come from {own} or an origin given with --allow-origin"
                ),
            );
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn secrets_compare_by_content_and_length() {
        assert!(same_secret(b"s3cret", b"s3cret"));
        assert!(!same_secret(b"s3cret", b"s3creT"));
        assert!(!same_secret(b"s3cret", b"s3cre"));
        assert!(!same_secret(b"", b"x"));
        assert!(same_secret(b"", b""));
        // Differences that cancel under xor still differ.
        assert!(!same_secret(b"ab", b"ba"));
        assert!(!same_secret(b"aabb", b"bbaa"));
    }

    #[test]
    fn a_rig_with_a_credential_of_its_own_takes_that_alone() {
        // SHA-256("abc"), FIPS 180-2 appendix B.1.
        assert_eq!(
            credential_digest("abc"),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        let shared = vec!["shared-agent-token".to_string()];
        let own = credential_digest("bench-own");
        // Its own credential, and nothing else: not the shared token, not
        // another rig's credential.
        assert!(credential_fits("bench", Some(&own), &shared, "bench-own").is_ok());
        let e = credential_fits("bench", Some(&own), &shared, "shared-agent-token").unwrap_err();
        assert!(
            e.contains("\"bench\"") && e.contains("zwidth rig token bench"),
            "{e}"
        );
        assert!(credential_fits("bench", Some(&own), &shared, "other-own").is_err());
        // Without one: the shared tokens (the migration), not a credential
        // of another rig.
        assert!(credential_fits("old", None, &shared, "shared-agent-token").is_ok());
        let e = credential_fits("old", None, &shared, "bench-own").unwrap_err();
        assert!(e.contains("another rig"), "{e}");
    }

    #[test]
    fn the_host_must_name_this_server() {
        let names = vec!["zwidth.lab.example".to_string()];
        for ok in [
            "localhost:8080",
            "127.0.0.1",
            "10.1.2.3:8443",
            "[::1]:80",
            "[2001:db8::7]:8080",
            "zwidth.lab.example",
            "ZWIDTH.Lab.Example:8443",
        ] {
            assert!(host_allowed(&names, ok), "{ok}");
        }
        // A DNS-rebinding page names its own host; a name not given; a
        // name that only ends like one given.
        for bad in [
            "rebind.evil.example:8080",
            "lab.example",
            "evil-zwidth.lab.example",
            "zwidth.lab.example.evil",
            "",
        ] {
            assert!(!host_allowed(&names, bad), "{bad}");
        }
        assert!(!host_allowed(&[], "zwidth.lab.example"));
    }

    #[test]
    fn any_configured_token_is_accepted() {
        let t = |v: &[&str]| v.iter().map(|s| s.to_string()).collect::<Vec<_>>();
        assert!(token_accepted(&t(&["x", "y"]), "y"));
        assert!(token_accepted(&t(&["x", "y"]), "x"));
        assert!(!token_accepted(&t(&["x", "y"]), "z"));
        // A token listed twice (a token file with a repeated line) still works.
        assert!(token_accepted(&t(&["x", "x"]), "x"));
        assert!(!token_accepted(&[], "x"));
    }

    #[test]
    fn loopback_hosts() {
        for h in [
            "127.0.0.1:8080",
            "localhost:1",
            "LOCALHOST",
            "[::1]:80",
            "127.9.9.9",
        ] {
            assert!(loopback_host(h), "{h}");
        }
        for h in [
            "evil.example:8080",
            "10.0.0.1:80",
            "[2001:db8::1]:80",
            "",
            "localhost.evil:80",
        ] {
            assert!(!loopback_host(h), "{h}");
        }
    }
}
