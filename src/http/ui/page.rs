//! What every dashboard page is made of: the layout with its navigation,
//! the live parts that poll for changes, and the small pieces (badges,
//! links, times, inline charts) the pages share.

use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use maud::{html, Markup, PreEscaped, DOCTYPE};

/// How often a live part asks for changes (ms).
pub const POLL_MS: u64 = 2000;

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
pub fn state_badge(state: crate::store::ExperimentState) -> Markup {
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
