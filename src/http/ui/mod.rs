//! The web dashboard (issue 15): server-rendered pages at `/` (maud; every
//! string escaped), the map plots from `zwidth::plot` inline, and one
//! vendored script (htmx 2.0.11, served from the binary) that polls a
//! page's live part every 2 s with a change token: an unchanged part
//! answers 204 after one cheap query. Reads need no token on loopback
//! (beyond it, private reads: the sign-in page, `login.rs`); the actions
//! (cancel, pause, resume, a rig's window) call the JSON API with the
//! token the user entered once (kept in the browser's local storage).
//! No CDN, no build step: it works offline.

pub mod bench;
mod compare;
mod login;
mod page;
mod queue;
mod run;
mod runs;
mod tune;

use axum::extract::Path;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use axum::Router;
use maud::html;

use super::AppState;
pub use page::{
    action, ago, chart, duration, fragment, layout, live_part, run_link, short, state_badge, svg,
    unchanged, utc, Nav, POLL_MS,
};

/// The pinned htmx, as published (BSD Zero Clause licence).
const HTMX: &str = include_str!("assets/htmx-2.0.11.min.js");
const APP_JS: &str = include_str!("assets/app.js");
const STYLE: &str = include_str!("assets/style.css");
/// A K–B boundary as the tab's icon.
const ICON: &str = r##"<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 16 16"><rect width="16" height="16" rx="3" fill="#0b5cad"/><path d="M2 3C6 4 9 8 14 14" stroke="#fff" stroke-width="2" fill="none"/></svg>"##;

/// The dashboard's routes; their errors are pages ([`error_page`]).
pub fn routes() -> Router<AppState> {
    Router::new()
        .route("/", get(queue::page))
        .route("/ui/queue/live", get(queue::live))
        .route("/runs", get(runs::page))
        .route("/runs/{id}", get(run::page))
        .route("/ui/runs/{id}/live", get(run::live))
        .route("/compare", get(compare::page))
        .route("/login", get(login::show).post(login::sign_in))
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
