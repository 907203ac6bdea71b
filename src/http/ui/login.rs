//! Signing in to a server with private reads (issue 45 item 5): the
//! dashboard asks for the token once and keeps it in a cookie the page's
//! scripts cannot read (`HttpOnly`) and no other site's request carries
//! (`SameSite=Strict`; `Secure` over TLS). The cookie opens reads only:
//! writes still take `Authorization: Bearer` (the token box).

use axum::extract::{Query, State};
use axum::http::{header, HeaderValue, StatusCode};
use axum::response::{IntoResponse, Response};
use maud::html;

use super::page::{layout, Nav};
use crate::http::guard::{token_accepted, COOKIE};
use crate::http::AppState;

/// How long the sign-in lasts (s): a working week.
pub const COOKIE_MAX_AGE_S: u64 = 7 * 24 * 3600;

/// Where to go after signing in: a path of this server only (never
/// `//other.site` or a scheme).
fn local_path(next: Option<&str>) -> &str {
    match next {
        Some(p) if p.starts_with('/') && !p.starts_with("//") && !p.contains('\\') => p,
        _ => "/",
    }
}

/// The sign-in page, answered with `status`, returning to `next`.
fn page(next: &str, error: Option<&str>, status: StatusCode) -> Response {
    let next = local_path(Some(next));
    let body = html! {
        h1 { "Sign in" }
        p { "Reads on this server need its token (" code { "zwidth.db.token" } " next to its database, or the one it was given). The browser keeps it in a cookie for a week." }
        @if let Some(e) = error { p.error role="alert" { (e) } }
        form method="post" action="/login" {
            input type="hidden" name="next" value=(next);
            label { "Token " input type="password" name="token" autocomplete="current-password" required autofocus; }
            " "
            button type="submit" { "Sign in" }
        }
    };
    let mut r = layout("Sign in", Nav::None, body);
    *r.status_mut() = status;
    r
}

#[derive(serde::Deserialize)]
pub struct Next {
    next: Option<String>,
}

pub async fn show(Query(q): Query<Next>) -> Response {
    page(local_path(q.next.as_deref()), None, StatusCode::OK)
}

#[derive(serde::Deserialize)]
pub struct SignIn {
    token: String,
    next: Option<String>,
}

/// `POST /login` (a form): the token checked, then the cookie set and
/// back to `next`; a wrong token answers the page again (403).
pub async fn sign_in(State(st): State<AppState>, body: axum::body::Bytes) -> Response {
    let Ok(form) = serde_urlencoded::from_bytes::<SignIn>(&body) else {
        return page(
            "/",
            Some("send the form's token field"),
            StatusCode::BAD_REQUEST,
        );
    };
    let next = local_path(form.next.as_deref()).to_string();
    let token = form.token.trim();
    if !token_accepted(&st.tokens, token) {
        return page(
            &next,
            Some("that token is not accepted"),
            StatusCode::FORBIDDEN,
        );
    }
    let secure = if st.tls { "; Secure" } else { "" };
    let cookie = format!(
        "{COOKIE}={token}; HttpOnly; SameSite=Strict; Path=/; Max-Age={COOKIE_MAX_AGE_S}{secure}"
    );
    let mut r = (StatusCode::SEE_OTHER, [(header::LOCATION, next)]).into_response();
    match HeaderValue::from_str(&cookie) {
        Ok(v) => {
            r.headers_mut().insert(header::SET_COOKIE, v);
            r
        }
        Err(_) => page(
            "/",
            Some("that token cannot be kept in a cookie"),
            StatusCode::BAD_REQUEST,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::local_path;

    #[test]
    fn sign_in_returns_to_this_server_only() {
        assert_eq!(local_path(Some("/runs/abc?x=1")), "/runs/abc?x=1");
        for other in [
            "//evil.example/",
            "https://evil.example/",
            "evil",
            "/\\evil.example",
        ] {
            assert_eq!(local_path(Some(other)), "/", "{other}");
        }
        assert_eq!(local_path(None), "/");
    }
}
