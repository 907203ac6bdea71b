//! The router: every endpoint's path and method, and the layers every
//! request passes (limits, timeouts, security headers, logging).

use axum::http::StatusCode;
use axum::routing::{get, post, put};
use axum::Router;
use std::time::Duration;

use super::limits::{BODY_LIMIT, URI_LIMIT};
use super::problem::Problem;
use super::state::AppState;
use super::{agent, compare, experiments, guard, problem, queue, rigs, ui};

/// The URI as logged: query values of anything that looks like a secret
/// are replaced, so a token put in a query string never reaches the logs.
fn logged_uri(uri: &axum::http::Uri) -> String {
    let Some(q) = uri.query() else {
        return uri.path().to_string();
    };
    let redacted: Vec<String> = q
        .split('&')
        .map(|pair| {
            let name = pair.split('=').next().unwrap_or("");
            let lower = name.to_ascii_lowercase();
            if ["token", "key", "secret", "password", "auth"]
                .iter()
                .any(|s| lower.contains(s))
            {
                format!("{name}=REDACTED")
            } else {
                pair.to_string()
            }
        })
        .collect();
    format!("{}?{}", uri.path(), redacted.join("&"))
}

/// A request target longer than [`URI_LIMIT`] is a 414 problem; one with
/// a NUL byte a 404 (path) or 422 (query).
async fn uri_limit(
    req: axum::extract::Request,
    next: axum::middleware::Next,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    let len = req.uri().path_and_query().map_or(0, |p| p.as_str().len());
    if len > URI_LIMIT {
        return Problem::new(
            StatusCode::URI_TOO_LONG,
            "URI too long",
            format!("the request target is {len} bytes; at most {URI_LIMIT}"),
        )
        .with_field("query")
        .into_response();
    }
    // A NUL byte names nothing that can be stored (PostgreSQL's text
    // refuses it): an id with one does not exist, a query value with one
    // is invalid.
    if req.uri().path().contains("%00") {
        return Problem::new(
            StatusCode::NOT_FOUND,
            "Not found",
            "the path holds a NUL byte (%00): no resource is named so",
        )
        .with_field("path")
        .into_response();
    }
    if req.uri().query().is_some_and(|q| q.contains("%00")) {
        return Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid request",
            "the query holds a NUL byte (%00): no parameter takes one",
        )
        .with_field("query")
        .into_response();
    }
    next.run(req).await
}

/// On every response: no content sniffing; an SVG (a document that could
/// hold script) gets a policy that runs none.
async fn safe_headers(mut resp: axum::response::Response) -> axum::response::Response {
    use axum::http::{header, HeaderValue};
    let h = resp.headers_mut();
    h.insert(
        header::X_CONTENT_TYPE_OPTIONS,
        HeaderValue::from_static("nosniff"),
    );
    let svg = h
        .get(header::CONTENT_TYPE)
        .is_some_and(|v| v.as_bytes().starts_with(b"image/svg+xml"));
    if svg {
        h.insert(
            header::CONTENT_SECURITY_POLICY,
            HeaderValue::from_static("default-src 'none'; style-src 'unsafe-inline'; sandbox"),
        );
    }
    resp
}

/// The routes, with a body-size limit, a per-request timeout (503), a
/// request id (`x-request-id`, taken from the request or made) logged with
/// the request and returned on the response, the write guards, and every
/// error as problem+json.
pub fn router(state: AppState, timeout: Duration) -> Router {
    use axum::extract::DefaultBodyLimit;
    use axum::middleware::{from_fn, from_fn_with_state, map_response};
    use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
    let trace = tower_http::trace::TraceLayer::new_for_http().make_span_with(
        |req: &axum::http::Request<axum::body::Body>| {
            let id = req
                .headers()
                .get("x-request-id")
                .and_then(|v| v.to_str().ok())
                .unwrap_or("");
            tracing::info_span!("request", method = %req.method(), uri = %logged_uri(req.uri()), request_id = %id)
        },
    );
    Router::new()
        .route("/healthz", get(queue::healthz))
        .route("/v1/rigs", get(rigs::rigs).post(rigs::register))
        .route("/v1/agent", get(agent::agent))
        .route("/v1/agent/audit", get(rigs::agent_audit))
        .route(
            "/v1/rigs/{id}/quarantine",
            axum::routing::delete(rigs::release),
        )
        .route("/v1/rigs/{id}/audit", get(rigs::audit))
        .route("/v1/rigs/{id}/stop", post(rigs::stop))
        .route("/v1/rigs/{id}/agent-token", post(rigs::agent_token))
        .route(
            "/v1/rigs/{id}/window",
            put(rigs::set_window).delete(rigs::clear_window),
        )
        .route(
            "/v1/experiments",
            post(experiments::submit).get(experiments::list),
        )
        .route("/v1/experiments/{id}", get(experiments::show))
        .route("/v1/experiments/{id}/cancel", post(experiments::cancel))
        .route("/v1/experiments/{id}/trials", get(experiments::trials))
        .route("/v1/experiments/{id}/units", get(experiments::units))
        .route(
            "/v1/experiments/{id}/evaluations",
            get(experiments::evaluations),
        )
        .route("/v1/experiments/{id}/plot.svg", get(experiments::plot))
        .route("/v1/experiments/{id}/points.csv", get(experiments::points))
        .route("/v1/compare", get(compare::compare_runs))
        .route("/v1/queue", get(queue::queue))
        .route("/v1/queue/pause", post(queue::pause))
        .route("/v1/queue/resume", post(queue::resume))
        .route("/metrics", get(queue::metrics))
        .merge(ui::routes())
        .layer(from_fn_with_state(state.clone(), guard::same_origin_writes))
        .layer(from_fn_with_state(state.clone(), guard::host_and_reads))
        .layer(DefaultBodyLimit::max(BODY_LIMIT))
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::SERVICE_UNAVAILABLE,
            timeout,
        ))
        .layer(from_fn(uri_limit))
        // A panic in a handler is a 500 problem, not a dropped connection.
        .layer(tower_http::catch_panic::CatchPanicLayer::new())
        .layer(map_response(problem::problems_everywhere))
        .layer(map_response(safe_headers))
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(trace)
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
        .with_state(state)
}
