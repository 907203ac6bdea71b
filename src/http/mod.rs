//! The HTTP API (axum): routes, handlers, and errors as RFC 9457
//! `application/problem+json` naming the field. Bodies are parsed with the
//! engines' own spec types and validated with the engines' own validation.

use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use crate::error::SpecError;
use crate::jobs::ExperimentSpec;
use crate::store::{ExperimentRow, Store};

/// Largest request body accepted (bytes).
pub const BODY_LIMIT: usize = 1 << 20;

#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    /// Bearer tokens accepted on mutating endpoints; empty: none required
    /// (only allowed when bound to loopback).
    pub tokens: std::sync::Arc<Vec<String>>,
}

/// Mutating endpoints need `Authorization: Bearer <token>` when tokens are
/// configured: 401 without one, 403 with a wrong one.
fn authorize(st: &AppState, headers: &HeaderMap) -> Result<(), Problem> {
    if st.tokens.is_empty() {
        return Ok(());
    }
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    match given {
        None => Err(Problem::new(
            StatusCode::UNAUTHORIZED,
            "Unauthorized",
            "this endpoint needs Authorization: Bearer <token>",
        )),
        Some(t) if st.tokens.iter().any(|k| k == t) => Ok(()),
        Some(_) => Err(Problem::new(
            StatusCode::FORBIDDEN,
            "Forbidden",
            "the bearer token is not accepted",
        )),
    }
}

pub fn router(state: AppState) -> Router {
    Router::new()
        .route("/healthz", get(healthz))
        .route("/v1/experiments", post(submit).get(list))
        .route("/v1/experiments/{id}", get(show))
        .route("/v1/experiments/{id}/cancel", post(cancel))
        .route("/v1/queue", get(queue))
        .route("/v1/queue/pause", post(pause))
        .route("/v1/queue/resume", post(resume))
        .route("/metrics", get(metrics))
        .layer(DefaultBodyLimit::max(BODY_LIMIT))
        .with_state(state)
}

#[utoipa::path(get, path = "/healthz", responses((status = 200, description = "ok", body = String, content_type = "text/plain")))]
async fn healthz() -> &'static str {
    "ok"
}

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

/// The API description, generated from the code: `zwidth openapi` prints it;
/// `api/openapi.json` is that output, and a test fails when they differ.
#[derive(utoipa::OpenApi)]
#[openapi(
    info(title = "zwidth", description = "Z-width experiments: queue, run and store maps and estimator comparisons"),
    paths(healthz, submit, list, show, cancel, queue, pause, resume, metrics),
    components(schemas(ProblemBody, ExperimentView, ExperimentSpec)),
    modifiers(&BearerAuth)
)]
pub struct ApiDoc;

struct BearerAuth;

impl utoipa::Modify for BearerAuth {
    fn modify(&self, api: &mut utoipa::openapi::OpenApi) {
        use utoipa::openapi::security::{HttpAuthScheme, HttpBuilder, SecurityScheme};
        let components = api.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(HttpBuilder::new().scheme(HttpAuthScheme::Bearer).build()),
        );
    }
}

/// The OpenAPI document as pretty JSON.
pub fn openapi_json() -> String {
    use utoipa::OpenApi;
    let mut v = serde_json::to_value(ApiDoc::openapi()).unwrap_or_default();
    // The experiment kinds are `{"kind": …} + MapSpec/CompareSpec` (allOf).
    // Their structs reject unknown fields, which utoipa writes as
    // `additionalProperties: false`; inside allOf that forbids `kind` itself
    // and makes the union unsatisfiable. The server still rejects unknown
    // fields; the schema just leaves them open.
    for name in ["MapSpec", "CompareSpec"] {
        if let Some(o) = v["components"]["schemas"][name].as_object_mut() {
            o.remove("additionalProperties");
        }
    }
    serde_json::to_string_pretty(&v).unwrap_or_default()
}

/// An RFC 9457 problem.
#[derive(Debug)]
pub struct Problem {
    status: StatusCode,
    title: &'static str,
    detail: String,
    field: Option<String>,
}

impl Problem {
    fn new(status: StatusCode, title: &'static str, detail: impl Into<String>) -> Self {
        Self {
            status,
            title,
            detail: detail.into(),
            field: None,
        }
    }

    fn internal(e: impl std::fmt::Display) -> Self {
        tracing::error!(error = %e, "internal error");
        Self::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "Internal error",
            "the server could not complete the request",
        )
    }
}

impl From<SpecError> for Problem {
    fn from(e: SpecError) -> Self {
        Self {
            status: StatusCode::UNPROCESSABLE_ENTITY,
            title: "Invalid experiment",
            detail: e.to_string(),
            field: Some(e.field),
        }
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
        (
            self.status,
            [(header::CONTENT_TYPE, "application/problem+json")],
            body.to_string(),
        )
            .into_response()
    }
}

/// What the API shows of an experiment.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ExperimentView {
    pub id: String,
    pub kind: String,
    pub state: String,
    pub priority: i64,
    pub created_ms: i64,
    pub started_ms: Option<i64>,
    pub finished_ms: Option<i64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_before_ms: Option<i64>,
    pub progress: Value,
    pub spec: Value,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl From<ExperimentRow> for ExperimentView {
    fn from(r: ExperimentRow) -> Self {
        Self {
            progress: json!({ "trials_done": r.trials_done }),
            spec: serde_json::from_str(&r.spec).unwrap_or(Value::Null),
            result: r
                .result
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
            id: r.id,
            kind: r.kind,
            state: r.state,
            priority: r.priority,
            created_ms: r.created_ms,
            started_ms: r.started_ms,
            finished_ms: r.finished_ms,
            not_before_ms: r.not_before_ms,
            error: r.error,
        }
    }
}

#[derive(Debug, Deserialize)]
pub struct SubmitQuery {
    #[serde(default)]
    priority: i64,
    /// Do not start before this time (unix ms).
    #[serde(default)]
    not_before_ms: Option<i64>,
}

#[utoipa::path(post, path = "/v1/experiments", request_body = ExperimentSpec,
    params(("priority" = Option<i64>, Query, description = "-1000 to 1000, higher first"),
           ("not_before_ms" = Option<i64>, Query, description = "do not start before (unix ms)"),
           ("Idempotency-Key" = Option<String>, Header, description = "repeat-safe submission")),
    responses((status = 202, description = "queued", body = ExperimentView),
              (status = 200, description = "an earlier submission with the same Idempotency-Key", body = ExperimentView),
              (status = 401, description = "token required", body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, description = "token refused", body = ProblemBody, content_type = "application/problem+json"),
              (status = 413, description = "body over 1 MiB"),
              (status = 422, description = "invalid experiment", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
#[tracing::instrument(skip(st, headers, body))]
async fn submit(
    State(st): State<AppState>,
    Query(q): Query<SubmitQuery>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, Problem> {
    authorize(&st, &headers)?;
    let spec: ExperimentSpec = serde_json::from_slice(&body).map_err(|e| {
        Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid experiment",
            format!("the body is not a valid experiment: {e}"),
        )
    })?;
    spec.validate()?;
    if !(-1000..=1000).contains(&q.priority) {
        let mut p = Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid experiment",
            format!(
                "priority = {} is not allowed: must be -1000 to 1000",
                q.priority
            ),
        );
        p.field = Some("priority".into());
        return Err(p);
    }
    if let Some(t) = q.not_before_ms {
        if !(0..=i64::MAX / 2).contains(&t) {
            let mut p = Problem::new(
                StatusCode::UNPROCESSABLE_ENTITY,
                "Invalid experiment",
                format!("not_before_ms = {t} is not allowed: must be a unix time in ms >= 0"),
            );
            p.field = Some("not_before_ms".into());
            return Err(p);
        }
    }
    let key = headers
        .get("idempotency-key")
        .and_then(|v| v.to_str().ok())
        .map(str::to_owned);
    let id = uuid::Uuid::now_v7().to_string();
    let text = serde_json::to_string(&spec).map_err(Problem::internal)?;
    let (row, created) = st
        .store
        .insert(
            &id,
            spec.kind(),
            &text,
            q.priority,
            key.as_deref(),
            q.not_before_ms,
        )
        .await
        .map_err(Problem::internal)?;
    let status = if created {
        StatusCode::ACCEPTED
    } else {
        StatusCode::OK
    };
    Ok((
        status,
        [(header::LOCATION, format!("/v1/experiments/{}", row.id))],
        Json(ExperimentView::from(row)),
    )
        .into_response())
}

#[utoipa::path(get, path = "/v1/experiments", responses((status = 200, description = "the latest 200", body = Vec<ExperimentView>)))]
async fn list(State(st): State<AppState>) -> Result<Json<Vec<ExperimentView>>, Problem> {
    let rows = st.store.list(200).await.map_err(Problem::internal)?;
    Ok(Json(rows.into_iter().map(ExperimentView::from).collect()))
}

#[utoipa::path(get, path = "/v1/experiments/{id}", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, body = ExperimentView), (status = 404, body = ProblemBody, content_type = "application/problem+json")))]
async fn show(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ExperimentView>, Problem> {
    match st.store.get(&id).await.map_err(Problem::internal)? {
        Some(row) => Ok(Json(row.into())),
        None => Err(Problem::new(
            StatusCode::NOT_FOUND,
            "Not found",
            format!("no experiment {id}"),
        )),
    }
}

#[utoipa::path(post, path = "/v1/experiments/{id}/cancel", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, body = ExperimentView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "already ended", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
async fn cancel(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<ExperimentView>, Problem> {
    authorize(&st, &headers)?;
    let changed = st.store.cancel(&id).await.map_err(Problem::internal)?;
    match st.store.get(&id).await.map_err(Problem::internal)? {
        None => Err(Problem::new(
            StatusCode::NOT_FOUND,
            "Not found",
            format!("no experiment {id}"),
        )),
        Some(row) if !changed => Err(Problem::new(
            StatusCode::CONFLICT,
            "Not cancellable",
            format!("experiment {id} is already {}", row.state),
        )),
        Some(row) => Ok(Json(row.into())),
    }
}

#[utoipa::path(get, path = "/v1/queue", responses((status = 200, description = "paused flag and experiments per state", body = Object)))]
async fn queue(State(st): State<AppState>) -> Result<Json<Value>, Problem> {
    let paused = st.store.paused().await.map_err(Problem::internal)?;
    let (by_state, _) = st.store.counts().await.map_err(Problem::internal)?;
    let counts: serde_json::Map<String, Value> =
        by_state.into_iter().map(|(s, n)| (s, json!(n))).collect();
    Ok(Json(json!({ "paused": paused, "experiments": counts })))
}

#[utoipa::path(post, path = "/v1/queue/pause", responses((status = 200, body = Object), (status = 401, body = ProblemBody, content_type = "application/problem+json"), (status = 403, body = ProblemBody, content_type = "application/problem+json")), security((), ("bearer" = [])))]
async fn pause(State(st): State<AppState>, headers: HeaderMap) -> Result<Json<Value>, Problem> {
    authorize(&st, &headers)?;
    st.store.set_paused(true).await.map_err(Problem::internal)?;
    queue(State(st)).await
}

#[utoipa::path(post, path = "/v1/queue/resume", responses((status = 200, body = Object), (status = 401, body = ProblemBody, content_type = "application/problem+json"), (status = 403, body = ProblemBody, content_type = "application/problem+json")), security((), ("bearer" = [])))]
async fn resume(State(st): State<AppState>, headers: HeaderMap) -> Result<Json<Value>, Problem> {
    authorize(&st, &headers)?;
    st.store
        .set_paused(false)
        .await
        .map_err(Problem::internal)?;
    queue(State(st)).await
}

/// Prometheus text: queue depth, experiments by state, trials done and the
/// runner's current trials per second.
#[utoipa::path(get, path = "/metrics", responses((status = 200, description = "Prometheus text", body = String, content_type = "text/plain")))]
async fn metrics(State(st): State<AppState>) -> Result<Response, Problem> {
    let (by_state, trials) = st.store.counts().await.map_err(Problem::internal)?;
    let depth: i64 = by_state
        .iter()
        .filter(|(s, _)| s == "queued" || s == "scheduled")
        .map(|(_, n)| n)
        .sum();
    let mut out = String::new();
    out.push_str("# HELP zwidth_queue_depth Experiments waiting to run (queued or scheduled).\n# TYPE zwidth_queue_depth gauge\n");
    out.push_str(&format!("zwidth_queue_depth {depth}\n"));
    out.push_str(
        "# HELP zwidth_experiments Experiments by state.\n# TYPE zwidth_experiments gauge\n",
    );
    for state in [
        "queued",
        "scheduled",
        "running",
        "succeeded",
        "failed",
        "cancelled",
        "interrupted",
    ] {
        let n = by_state
            .iter()
            .find(|(s, _)| s == state)
            .map(|(_, n)| *n)
            .unwrap_or(0);
        out.push_str(&format!("zwidth_experiments{{state=\"{state}\"}} {n}\n"));
    }
    out.push_str("# HELP zwidth_trials_total Trials done over all experiments.\n# TYPE zwidth_trials_total counter\n");
    out.push_str(&format!("zwidth_trials_total {trials}\n"));
    out.push_str("# HELP zwidth_trials_per_second Trials per second of the running experiment, last second.\n# TYPE zwidth_trials_per_second gauge\n");
    out.push_str(&format!(
        "zwidth_trials_per_second {}\n",
        crate::jobs::TRIALS_PER_SECOND.load(std::sync::atomic::Ordering::Relaxed)
    ));
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response())
}

/// Open the store, requeue interrupted work, bind, and serve until Ctrl-C.
/// Returns after shutdown. Prints the bound address on stdout first.
pub async fn serve(db: &std::path::Path, bind: &str, tokens: Vec<String>) -> Result<(), String> {
    let store = Store::open(db)
        .await
        .map_err(|e| format!("cannot open database {}: {e}", db.display()))?;
    let requeued = store
        .requeue_interrupted()
        .await
        .map_err(|e| e.to_string())?;
    if requeued > 0 {
        tracing::info!(
            requeued,
            "requeued experiments interrupted by the last shutdown"
        );
    }
    let listener = tokio::net::TcpListener::bind(bind)
        .await
        .map_err(|e| format!("cannot bind {bind}: {e}"))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    if tokens.is_empty() && !addr.ip().is_loopback() {
        return Err(format!(
            "refusing to serve on {addr} without a token: set ZWIDTH_TOKENS=<secret>[,<secret>…] (or --token), or bind to 127.0.0.1"
        ));
    }
    if tokens.is_empty() {
        tracing::warn!("no token set: anyone on this machine may submit; set ZWIDTH_TOKENS=<secret> to require Authorization: Bearer <secret>");
    }
    println!("zwidth serving on http://{addr}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
    tokio::spawn(crate::jobs::runner(store.clone()));
    let tokens = std::sync::Arc::new(tokens);
    axum::serve(listener, router(AppState { store, tokens }))
        .with_graceful_shutdown(async {
            let _ = tokio::signal::ctrl_c().await;
        })
        .await
        .map_err(|e| e.to_string())
}

#[cfg(test)]
mod tests {
    #[test]
    fn committed_openapi_matches_the_code() {
        // Regenerate with: cargo run -- openapi > api/openapi.json
        let committed = include_str!("../../api/openapi.json");
        assert_eq!(
            committed.trim_end(),
            super::openapi_json().trim_end(),
            "api/openapi.json drifted from the code"
        );
        let v: serde_json::Value = serde_json::from_str(committed).unwrap();
        assert!(v["openapi"].as_str().unwrap().starts_with("3.1"));
        for path in [
            "/v1/experiments",
            "/v1/experiments/{id}",
            "/v1/experiments/{id}/cancel",
            "/healthz",
            "/metrics",
        ] {
            assert!(v["paths"].get(path).is_some(), "{path} missing");
        }
    }
}
