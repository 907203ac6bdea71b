//! The HTTP API (axum): routes, handlers, and errors as RFC 9457
//! `application/problem+json` naming the field. Bodies are parsed with the
//! engines' own spec types and validated with the engines' own validation.

use axum::body::Bytes;
use axum::extract::{DefaultBodyLimit, Path, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post, put};
use axum::{Json, Router};
use serde::{Deserialize, Serialize};
use serde_json::{json, Value};

use std::sync::Arc;
use std::time::Duration;

use crate::error::SpecError;
use crate::jobs::window::Window;
use crate::jobs::ExperimentSpec;
use crate::report::{self, Comparison, MapSummary};
use crate::rig::{Rig, RigInfo};
use crate::store::{now_ms, ExperimentRow, NewExperiment, Store};
use crate::zwidth::search::{StoredEvaluation, StoredTrial};

/// Largest request body accepted (bytes).
pub const BODY_LIMIT: usize = 1 << 20;

#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    /// Bearer tokens accepted on mutating endpoints; empty: none required
    /// (only allowed when bound to loopback).
    pub tokens: Arc<Vec<String>>,
    /// The rigs experiments run on; the first is the default.
    pub rigs: Arc<Vec<Arc<dyn Rig>>>,
    /// Running experiments' observers (cancel reaches them at once).
    pub running: crate::jobs::Running,
}

impl AppState {
    fn rig(&self, id: &str) -> Option<&Arc<dyn Rig>> {
        self.rigs.iter().find(|r| r.info().id == id)
    }
}

/// How `serve` runs.
pub struct ServeConfig {
    pub db: std::path::PathBuf,
    pub bind: String,
    pub tokens: Vec<String>,
    pub rigs: Vec<Arc<dyn Rig>>,
    /// Longest a request may take before a 503 (s).
    pub request_timeout_s: f64,
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

/// The routes, with a body-size limit, a per-request timeout (503), and a
/// request id (`x-request-id`, taken from the request or made) that is
/// logged with the request and returned on the response.
pub fn router(state: AppState, timeout: Duration) -> Router {
    use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
    let trace = tower_http::trace::TraceLayer::new_for_http().make_span_with(
        |req: &axum::http::Request<axum::body::Body>| {
            let id = req
                .headers()
                .get("x-request-id")
                .and_then(|v| v.to_str().ok())
                .unwrap_or("");
            tracing::info_span!("request", method = %req.method(), uri = %req.uri(), request_id = %id)
        },
    );
    Router::new()
        .route("/healthz", get(healthz))
        .route("/v1/rigs", get(rigs))
        .route("/v1/rigs/{id}/window", put(set_window).delete(clear_window))
        .route("/v1/experiments", post(submit).get(list))
        .route("/v1/experiments/{id}", get(show))
        .route("/v1/experiments/{id}/cancel", post(cancel))
        .route("/v1/experiments/{id}/trials", get(trials))
        .route("/v1/experiments/{id}/evaluations", get(evaluations))
        .route("/v1/experiments/{id}/plot.svg", get(plot))
        .route("/v1/experiments/{id}/points.csv", get(points))
        .route("/v1/compare", get(compare_runs))
        .route("/v1/queue", get(queue))
        .route("/v1/queue/pause", post(pause))
        .route("/v1/queue/resume", post(resume))
        .route("/metrics", get(metrics))
        .layer(DefaultBodyLimit::max(BODY_LIMIT))
        .layer(tower_http::timeout::TimeoutLayer::with_status_code(
            StatusCode::SERVICE_UNAVAILABLE,
            timeout,
        ))
        .layer(PropagateRequestIdLayer::x_request_id())
        .layer(trace)
        .layer(SetRequestIdLayer::x_request_id(MakeRequestUuid))
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
    paths(healthz, rigs, set_window, clear_window, submit, list, show, cancel, trials, evaluations, plot, points, compare_runs, queue, pause, resume, metrics),
    components(schemas(ProblemBody, ExperimentView, ExperimentSpec, RigView, Window, Comparison, StoredTrial, crate::tune::TuneResult)),
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
    for name in ["MapSpec", "CompareSpec", "SweepSpec", "TuneSpec"] {
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
    /// The rig it runs on.
    pub rig: String,
    /// `trials_done`, `fraction` (0 to 1), a tune's `best` so far, and while
    /// running `elapsed_s`, `eta_s` and `trials_total_estimate`.
    pub progress: Value,
    pub spec: Value,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

/// Trials done, the fraction of the work done, and while running the time
/// elapsed and the estimated time left (s), extrapolated from the fraction.
fn progress(r: &ExperimentRow) -> Value {
    let mut p = json!({ "trials_done": r.trials_done, "fraction": r.progress });
    if let Some(best) = r
        .best
        .as_deref()
        .and_then(|b| serde_json::from_str::<Value>(b).ok())
    {
        p["best"] = best;
    }
    if r.state == "running" {
        if let Some(t0) = r.started_ms {
            let elapsed = ((now_ms() - t0) as f64 / 1000.0).max(0.0);
            p["elapsed_s"] = json!(elapsed);
            if r.progress >= 0.01 && r.progress < 1.0 {
                p["eta_s"] = json!(elapsed * (1.0 - r.progress) / r.progress);
                // Trials left scale like the work left.
                p["trials_total_estimate"] =
                    json!((r.trials_done as f64 / r.progress).round() as i64);
            }
        }
    }
    p
}

impl From<ExperimentRow> for ExperimentView {
    fn from(r: ExperimentRow) -> Self {
        Self {
            progress: progress(&r),
            rig: r.rig.clone(),
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
    /// The rig to run on; default the first.
    #[serde(default)]
    rig: Option<String>,
}

#[utoipa::path(post, path = "/v1/experiments", request_body = ExperimentSpec,
    params(("priority" = Option<i64>, Query, description = "-1000 to 1000, higher first"),
           ("not_before_ms" = Option<i64>, Query, description = "do not start before (unix ms)"),
           ("rig" = Option<String>, Query, description = "rig id (GET /v1/rigs); default the first"),
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
    let rig = match &q.rig {
        None => st.rigs[0].clone(),
        Some(id) => st.rig(id).cloned().ok_or_else(|| {
            Problem::from(SpecError::new(
                "rig",
                format!("{id:?}"),
                format!("must be one of the rigs: {}", rig_ids(&st)),
            ))
        })?,
    };
    rig.check(&spec)?;
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
        .insert(NewExperiment {
            id: &id,
            kind: spec.kind(),
            spec: &text,
            priority: q.priority,
            key: key.as_deref(),
            not_before_ms: q.not_before_ms,
            rig: &rig.info().id,
        })
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
    if changed {
        crate::jobs::cancel_running(&st.running, &id);
    }
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

fn rig_ids(st: &AppState) -> String {
    st.rigs
        .iter()
        .map(|r| r.info().id.clone())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A result with nothing to draw (e.g. every boundary empty) is the
/// request's problem, not the server's.
fn no_plot(e: String) -> Problem {
    Problem::new(StatusCode::UNPROCESSABLE_ENTITY, "Nothing to plot", e)
}

fn not_found(what: &str, id: &str) -> Problem {
    Problem::new(
        StatusCode::NOT_FOUND,
        "Not found",
        format!("no {what} {id}"),
    )
}

/// A rig: what it can do, its window, and its load.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RigView {
    #[serde(flatten)]
    pub info: RigInfo,
    /// Recurring window outside which it starts nothing new; null: any time.
    pub window: Option<Window>,
    /// Whether it may start an experiment now.
    pub open_now: bool,
    /// When it may next start one (unix ms; now when open).
    pub next_start_ms: i64,
    /// Experiments waiting for it (queued or scheduled).
    pub waiting: i64,
    /// The experiment it is running, if any.
    pub running: Option<String>,
}

async fn rig_view(st: &AppState, rig: &Arc<dyn Rig>) -> Result<RigView, Problem> {
    let id = &rig.info().id;
    let window = st.store.rig_window(id).await.map_err(Problem::internal)?;
    let now = jiff::Timestamp::now();
    let next = match window.as_ref().and_then(|w| w.validate().ok()) {
        Some(h) => h.next_open(now),
        None => now,
    };
    let (waiting, running) = st.store.rig_load(id).await.map_err(Problem::internal)?;
    Ok(RigView {
        info: rig.info().clone(),
        open_now: next == now,
        next_start_ms: next.as_millisecond(),
        window,
        waiting,
        running,
    })
}

#[utoipa::path(get, path = "/v1/rigs", responses((status = 200, description = "the rigs, the first is the default", body = Vec<RigView>)))]
async fn rigs(State(st): State<AppState>) -> Result<Json<Vec<RigView>>, Problem> {
    let mut out = Vec::new();
    for r in st.rigs.iter() {
        out.push(rig_view(&st, r).await?);
    }
    Ok(Json(out))
}

#[utoipa::path(put, path = "/v1/rigs/{id}/window", request_body = Window, params(("id" = String, Path, description = "rig id")),
    responses((status = 200, body = RigView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "invalid window", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
async fn set_window(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    body: Bytes,
) -> Result<Json<RigView>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).cloned().ok_or_else(|| not_found("rig", &id))?;
    let w: Window = serde_json::from_slice(&body).map_err(|e| {
        Problem::new(
            StatusCode::UNPROCESSABLE_ENTITY,
            "Invalid window",
            format!("the body is not a window {{\"start\":\"HH:MM\",\"end\":\"HH:MM\",\"tz\":\"Europe/Berlin\"}}: {e}"),
        )
    })?;
    w.validate()?;
    st.store
        .set_rig_window(&id, Some(&w))
        .await
        .map_err(Problem::internal)?;
    Ok(Json(rig_view(&st, &rig).await?))
}

#[utoipa::path(delete, path = "/v1/rigs/{id}/window", params(("id" = String, Path, description = "rig id")),
    responses((status = 200, body = RigView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
async fn clear_window(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<RigView>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).cloned().ok_or_else(|| not_found("rig", &id))?;
    st.store
        .set_rig_window(&id, None)
        .await
        .map_err(Problem::internal)?;
    Ok(Json(rig_view(&st, &rig).await?))
}

#[derive(Debug, Deserialize)]
pub struct TrialsQuery {
    #[serde(default)]
    scope: Option<u32>,
    #[serde(default)]
    offset: Option<i64>,
    #[serde(default)]
    limit: Option<i64>,
}

/// Most trials one page returns.
pub const TRIALS_PAGE_MAX: i64 = 10_000;

#[utoipa::path(get, path = "/v1/experiments/{id}/trials",
    params(("id" = String, Path, description = "experiment id"),
           ("scope" = Option<u32>, Query, description = "only this map of the experiment (0, 1, …)"),
           ("offset" = Option<i64>, Query, description = "skip this many (default 0)"),
           ("limit" = Option<i64>, Query, description = "at most this many, 1 to 10000 (default 1000)")),
    responses((status = 200, description = "stored trials in the order they finished", body = Vec<StoredTrial>),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, body = ProblemBody, content_type = "application/problem+json")))]
async fn trials(
    State(st): State<AppState>,
    Path(id): Path<String>,
    Query(q): Query<TrialsQuery>,
) -> Result<Json<Vec<StoredTrial>>, Problem> {
    let limit = q.limit.unwrap_or(1000);
    if !(1..=TRIALS_PAGE_MAX).contains(&limit) {
        return Err(
            SpecError::new("limit", limit, format!("must be 1 to {TRIALS_PAGE_MAX}")).into(),
        );
    }
    let offset = q.offset.unwrap_or(0);
    if offset < 0 {
        return Err(SpecError::new("offset", offset, "must be >= 0").into());
    }
    if st
        .store
        .state(&id)
        .await
        .map_err(Problem::internal)?
        .is_none()
    {
        return Err(not_found("experiment", &id));
    }
    let t = st
        .store
        .trials_page(&id, q.scope, offset, limit)
        .await
        .map_err(Problem::internal)?;
    Ok(Json(t))
}

#[utoipa::path(get, path = "/v1/experiments/{id}/evaluations", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "a tune's stored evaluations (parameters, objectives, elapsed time), in the order stored, also while it runs", body = Vec<StoredEvaluation>),
              (status = 404, body = ProblemBody, content_type = "application/problem+json")))]
async fn evaluations(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<Vec<StoredEvaluation>>, Problem> {
    if st
        .store
        .state(&id)
        .await
        .map_err(Problem::internal)?
        .is_none()
    {
        return Err(not_found("experiment", &id));
    }
    Ok(Json(
        st.store.evaluations(&id).await.map_err(Problem::internal)?,
    ))
}

/// The maps of a succeeded experiment (409 while it is not).
async fn finished_maps(
    st: &AppState,
    id: &str,
) -> Result<(ExperimentSpec, Value, Vec<MapSummary>), Problem> {
    let row = st
        .store
        .get(id)
        .await
        .map_err(Problem::internal)?
        .ok_or_else(|| not_found("experiment", id))?;
    let (Some(result), "succeeded") = (row.result.as_deref(), row.state.as_str()) else {
        return Err(Problem::new(
            StatusCode::CONFLICT,
            "No result yet",
            format!(
                "experiment {id} is {}: results exist once it has succeeded",
                row.state
            ),
        ));
    };
    let spec: ExperimentSpec = serde_json::from_str(&row.spec).map_err(Problem::internal)?;
    let result: Value = serde_json::from_str(result).map_err(Problem::internal)?;
    let maps = report::maps(id, &spec, &result);
    Ok((spec, result, maps))
}

#[utoipa::path(get, path = "/v1/experiments/{id}/plot.svg", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "one map: Fig. 7 style; a parameter sweep: K-width against the parameter; else every boundary", body = String, content_type = "image/svg+xml"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "not succeeded (yet)", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "nothing to plot", body = ProblemBody, content_type = "application/problem+json")))]
async fn plot(State(st): State<AppState>, Path(id): Path<String>) -> Result<Response, Problem> {
    let (spec, result, maps) = finished_maps(&st, &id).await?;
    let svg = report::svg(&spec, &maps, &result).map_err(no_plot)?;
    Ok(([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response())
}

#[utoipa::path(get, path = "/v1/experiments/{id}/points.csv", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "maps: map,k_n_per_m,b_ns_per_m,renders,fidelity_ns_per_m; a tune: its evaluations", body = String, content_type = "text/csv"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "not succeeded (yet)", body = ProblemBody, content_type = "application/problem+json")))]
async fn points(State(st): State<AppState>, Path(id): Path<String>) -> Result<Response, Problem> {
    let (spec, result, maps) = finished_maps(&st, &id).await?;
    let csv = match spec {
        ExperimentSpec::Tune(_) => report::tune_result(&result)
            .map_err(Problem::internal)?
            .csv(),
        _ => report::points_csv(&maps),
    };
    Ok(([(header::CONTENT_TYPE, "text/csv")], csv).into_response())
}

#[derive(Debug, Deserialize)]
pub struct CompareQuery {
    #[serde(default)]
    runs: Option<String>,
    #[serde(default)]
    format: Option<String>,
}

/// Most runs one comparison takes.
pub const COMPARE_MAX_RUNS: usize = 50;

#[utoipa::path(get, path = "/v1/compare",
    params(("runs" = String, Query, description = "comma-separated ids of succeeded experiments on one scene"),
           ("format" = Option<String>, Query, description = "json (default), svg (every boundary on one chart) or text (a table)")),
    responses((status = 200, description = "K-width, B-width, max fidelity error and area per map, with differences from the first", body = Comparison),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "a run has not succeeded", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "bad runs or format, or different scenes", body = ProblemBody, content_type = "application/problem+json")))]
async fn compare_runs(
    State(st): State<AppState>,
    Query(q): Query<CompareQuery>,
) -> Result<Response, Problem> {
    let format = q.format.as_deref().unwrap_or("json");
    if !["json", "svg", "text"].contains(&format) {
        return Err(
            SpecError::new("format", format!("{format:?}"), "must be json, svg or text").into(),
        );
    }
    let ids: Vec<String> = q
        .runs
        .as_deref()
        .unwrap_or("")
        .split(',')
        .map(str::trim)
        .filter(|s| !s.is_empty())
        .map(str::to_owned)
        .collect();
    if ids.is_empty() || ids.len() > COMPARE_MAX_RUNS {
        return Err(SpecError::new(
            "runs",
            q.runs.as_deref().unwrap_or(""),
            format!("give 1 to {COMPARE_MAX_RUNS} experiment ids, comma-separated"),
        )
        .into());
    }
    let mut all = Vec::new();
    for id in &ids {
        all.extend(finished_maps(&st, id).await?.2);
    }
    let c = report::compare(ids, all)?;
    Ok(match format {
        "svg" => (
            [(header::CONTENT_TYPE, "image/svg+xml")],
            c.svg().map_err(no_plot)?,
        )
            .into_response(),
        "text" => (
            [(header::CONTENT_TYPE, "text/plain; charset=utf-8")],
            c.table(),
        )
            .into_response(),
        _ => Json(c).into_response(),
    })
}

/// Open the store, requeue interrupted work, bind, start one runner per
/// rig, and serve until Ctrl-C or SIGTERM. On shutdown the server stops
/// accepting, a running experiment stops within one trial with its trials
/// stored (state `interrupted`, resumed at the next start), then it returns.
/// Prints the bound address on stdout first.
pub async fn serve(cfg: ServeConfig) -> Result<(), String> {
    let ServeConfig {
        db,
        bind,
        tokens,
        rigs,
        request_timeout_s,
    } = cfg;
    let db = db.as_path();
    if rigs.is_empty() {
        return Err("refusing to serve without a rig".into());
    }
    if !(request_timeout_s.is_finite() && (0.1..=3600.0).contains(&request_timeout_s)) {
        return Err(format!(
            "refusing: --request-timeout-s = {request_timeout_s} must be 0.1 to 3600 s"
        ));
    }
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
    let listener = tokio::net::TcpListener::bind(&bind)
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
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let running = crate::jobs::Running::default();
    let runners: Vec<_> = rigs
        .iter()
        .map(|r| {
            tracing::info!(rig = %r.info().id, parallelism = r.info().parallelism, "rig ready");
            tokio::spawn(crate::jobs::runner(
                store.clone(),
                r.clone(),
                running.clone(),
                stop_rx.clone(),
            ))
        })
        .collect();
    let state = AppState {
        store,
        tokens: Arc::new(tokens),
        rigs: Arc::new(rigs),
        running,
    };
    let served = axum::serve(
        listener,
        router(state, Duration::from_secs_f64(request_timeout_s)),
    )
    .with_graceful_shutdown(shutdown_signal())
    .await
    .map_err(|e| e.to_string());
    tracing::info!("shutting down: letting the runners stop");
    let _ = stop_tx.send(true);
    for r in runners {
        let _ = r.await;
    }
    served
}

/// Ctrl-C or SIGTERM (what `docker stop` sends).
async fn shutdown_signal() {
    let ctrl_c = async {
        let _ = tokio::signal::ctrl_c().await;
    };
    #[cfg(unix)]
    let term = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(_) => std::future::pending::<()>().await,
        }
    };
    #[cfg(not(unix))]
    let term = std::future::pending::<()>();
    tokio::select! {
        _ = ctrl_c => {},
        _ = term => {},
    }
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
            "/v1/rigs",
            "/v1/rigs/{id}/window",
            "/v1/compare",
            "/v1/experiments/{id}/trials",
            "/v1/experiments/{id}/plot.svg",
            "/v1/experiments/{id}/points.csv",
            "/v1/experiments/{id}/evaluations",
        ] {
            assert!(v["paths"].get(path).is_some(), "{path} missing");
        }
    }
}
