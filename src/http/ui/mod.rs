//! The web dashboard (issue 15): server-rendered pages at `/` (maud; every
//! string escaped), the map plots from `zwidth::plot` inline, and one
//! vendored script (htmx 2.0.11, served from the binary) that polls a
//! page's live part every 2 s with a change token: an unchanged part
//! answers 204 after one cheap query. Reads need no token; the actions
//! (cancel, pause, resume, a rig's window) call the JSON API with the
//! token the user entered once (kept in the browser's local storage).
//! No CDN, no build step: it works offline.

pub mod bench;
mod compare;
mod queue;
mod run;
mod runs;
mod tune;

use axum::extract::Path;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use maud::{html, Markup, PreEscaped, DOCTYPE};

use super::AppState;

/// The pinned htmx, as published (BSD Zero Clause licence).
const HTMX: &str = include_str!("assets/htmx-2.0.11.min.js");
const APP_JS: &str = include_str!("assets/app.js");
const STYLE: &str = include_str!("assets/style.css");
/// A K–B boundary as the tab's icon.
const ICON: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 16 16"><rect width="16" height="16" rx="3" fill="#0b5cad"/><path d="M2 3C6 4 9 8 14 14" stroke="#fff" stroke-width="2" fill="none"/></svg>"##;

/// How often a live part asks for changes (ms).
pub const POLL_MS: u64 = 2000;

/// The dashboard's routes; their errors are pages ([`error_page`]).
pub fn routes() -> Router<AppState> {
    Router::new()
        .route("/", get(queue::page))
        .route("/ui/queue/live", get(queue::live))
        .route("/runs", get(runs::page))
        .route("/runs/{id}", get(run::page))
        .route("/ui/runs/{id}/live", get(run::live))
        .route("/compare", get(compare::page))
        .route("/assets/{name}", get(asset))
        .layer(axum::middleware::map_response(error_page))
}

/// A problem answered to a browser: the same status, as a page with the
/// problem's title, detail and field (the JSON API keeps problem+json).
async fn error_page(resp: Response) -> Response {
    let problem = resp.headers().get(header::CONTENT_TYPE).is_some_and(|v| {
        v.as_bytes()
            .starts_with(super::problem::PROBLEM_JSON.as_bytes())
    });
    if !problem {
        return resp;
    }
    let (parts, body) = resp.into_parts();
    let v: serde_json::Value = axum::body::to_bytes(body, 64 * 1024)
        .await
        .ok()
        .and_then(|b| serde_json::from_slice(&b).ok())
        .unwrap_or_default();
    let title = v["title"].as_str().unwrap_or("Error").to_string();
    let mut page = layout(
        &title,
        Nav::None,
        html! {
            h1 { (title) }
            p class="error" { (v["detail"].as_str().unwrap_or("")) }
            @if let Some(f) = v["field"].as_str() { p class="muted" { "Field: " code { (f) } } }
            p { a href="/" { "The queue" } " · " a href="/runs" { "every run" } }
        },
    );
    *page.status_mut() = parts.status;
    for (k, val) in parts.headers.iter() {
        if k != header::CONTENT_TYPE && k != header::CONTENT_LENGTH {
            page.headers_mut().entry(k).or_insert(val.clone());
        }
    }
    page
}

/// The script and style, cached by the browser for a day (their names
/// change with their version).
async fn asset(Path(name): Path<String>) -> Response {
    let (body, kind) = match name.as_str() {
        "htmx-2.0.11.min.js" => (HTMX, "text/javascript; charset=utf-8"),
        "app.js" => (APP_JS, "text/javascript; charset=utf-8"),
        "style.css" => (STYLE, "text/css; charset=utf-8"),
        "icon.svg" => (ICON, "image/svg+xml"),
        _ => {
            return super::Problem::not_found("asset", &name).into_response();
        }
    };
    (
        [
            (header::CONTENT_TYPE, kind),
            (header::CACHE_CONTROL, "public, max-age=86400"),
        ],
        body,
    )
        .into_response()
}

/// Which page the navigation marks as current.
#[derive(PartialEq, Clone, Copy)]
pub enum Nav {
    Queue,
    Runs,
    Compare,
    None,
}

/// A whole page: the navigation, the token box, the body.
pub fn layout(title: &str, nav: Nav, body: Markup) -> Response {
    let link = |href: &str, label: &str, me: Nav| {
        html! {
            @if nav == me {
                a href=(href) aria-current="page" { (label) }
            } @else {
                a href=(href) { (label) }
            }
        }
    };
    let markup = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width, initial-scale=1";
                meta name="htmx-config" content=r#"{"includeIndicatorStyles":false,"allowEval":false,"historyCacheSize":0}"#;
                title { (title) " · zwidth" }
                link rel="stylesheet" href="/assets/style.css";
                link rel="icon" href="/assets/icon.svg" type="image/svg+xml";
                script src="/assets/htmx-2.0.11.min.js" defer {}
                script src="/assets/app.js" defer {}
            }
            body {
                a class="skip" href="#main" { "Skip to content" }
                header {
                    nav aria-label="main" {
                        span class="brand" { "zwidth" }
                        (link("/", "Queue", Nav::Queue))
                        (link("/runs", "Runs", Nav::Runs))
                        (link("/compare", "Compare", Nav::Compare))
                    }
                    form id="token-form" class="token" {
                        label for="token" { "API token" }
                        input id="token" type="password" autocomplete="off" placeholder="for actions: cat <db>.token";
                        button type="submit" { "Save" }
                        button type="button" id="token-forget" { "Forget" }
                        span id="token-state" class="muted" aria-live="polite" {}
                    }
                }
                div id="flash" role="alert" aria-live="assertive" {}
                main id="main" { (body) }
            }
        }
    };
    html_response(StatusCode::OK, markup)
}

fn html_response(code: StatusCode, m: Markup) -> Response {
    (
        code,
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
            (
                header::CONTENT_SECURITY_POLICY,
                "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; connect-src 'self'; frame-ancestors 'none'; base-uri 'none'; form-action 'self'",
            ),
        ],
        m.into_string(),
    )
        .into_response()
}

/// A live part: polled every [`POLL_MS`] with its change token while
/// `polling`; the answer to a poll whose token still holds is a bare 204.
pub fn live_part(id: &str, url: &str, token: &str, polling: bool, inner: Markup) -> Markup {
    let sep = if url.contains('?') { '&' } else { '?' };
    let src = format!("{url}{sep}since={}", urlencode(token));
    html! {
        @if polling {
            section id=(id) class="live" hx-get=(src) hx-trigger={"every " (POLL_MS / 1000) "s, refresh"} hx-swap="outerHTML" data-token=(token) { (inner) }
        } @else {
            section id=(id) class="live" data-token=(token) { (inner) }
        }
    }
}

/// 204 when the caller's `since` is the current token.
pub fn unchanged(query: Option<&str>, token: &str) -> Option<Response> {
    let since = query
        .and_then(|q| serde_urlencoded::from_str::<Vec<(String, String)>>(q).ok())
        .and_then(|v| v.into_iter().find(|(k, _)| k == "since").map(|(_, v)| v))?;
    (since == token).then(|| StatusCode::NO_CONTENT.into_response())
}

/// A fragment (a live part) as the response.
pub fn fragment(m: Markup) -> Response {
    html_response(StatusCode::OK, m)
}

fn urlencode(s: &str) -> String {
    serde_urlencoded::to_string([("", s)])
        .map(|e| e.trim_start_matches('=').to_string())
        .unwrap_or_default()
}

/// A duration in words: "45 s", "12 min", "3 h 20 min", "2 d 4 h".
pub fn duration(s: f64) -> String {
    if !s.is_finite() || s < 0.0 {
        return "–".into();
    }
    let s = s.round() as i64;
    match s {
        0..=89 => format!("{s} s"),
        90..=5399 => format!("{} min", (s + 30) / 60),
        5400..=172_799 => format!("{} h {} min", s / 3600, (s % 3600) / 60),
        _ => format!("{} d {} h", s / 86_400, (s % 86_400) / 3600),
    }
}

/// How long ago `ms` (unix ms) was, from `now_ms`.
pub fn ago(ms: i64, now_ms: i64) -> String {
    format!("{} ago", duration((now_ms - ms) as f64 / 1000.0))
}

/// A UTC time, "2026-12-03 09:41 UTC".
pub fn utc(ms: i64) -> String {
    jiff::Timestamp::from_millisecond(ms)
        .map(|t| t.strftime("%Y-%m-%d %H:%M UTC").to_string())
        .unwrap_or_else(|_| "–".into())
}

/// A state as a badge (colour and text: never colour alone).
pub fn state_badge(state: &str) -> Markup {
    html! { span class={"badge " (state)} { (state) } }
}

pub use crate::report::short_id as short;

/// A run's link.
pub fn run_link(id: &str) -> Markup {
    html! { a href={"/runs/" (id)} class="mono id" title=(id) { (short(id)) } }
}

/// An action button: app.js sends `method url` with the saved token and
/// refreshes the live part on success.
pub fn action(method: &str, url: &str, label: &str, what: &str) -> Markup {
    // An id, so the focus comes back to it when the live part is redrawn.
    let id: String = format!("act-{method}-{url}")
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect();
    html! {
        button type="button" id=(id) class="action" data-method=(method) data-url=(url) aria-label={(label) " " (what)} { (label) }
    }
}

/// A chart: its SVG inline, named for screen readers as one image (the
/// points' tooltips are for pointers).
pub fn chart(label: &str, s: &str) -> Markup {
    html! { div class="chart" role="img" aria-label=(label) { (svg(s)) } }
}

/// Inline SVG made by `zwidth::plot` (our own markup: every text in it
/// was escaped where it was written).
pub fn svg(s: &str) -> Markup {
    // Drop an XML declaration if any: inline SVG takes none.
    let s = s.trim_start();
    let s = if s.starts_with("<?xml") {
        s.split_once("?>").map_or(s, |(_, r)| r)
    } else {
        s
    };
    PreEscaped(s.to_string())
}
