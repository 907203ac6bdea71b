//! The queue (paused flag, counts, pause and resume), Prometheus metrics,
//! and the health check (the database's integrity included).

use axum::extract::{RawQuery, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;
use serde_json::{json, Value};

use super::guard::authorize;
use super::problem::{Problem, ProblemBody, QueryArgs};
use super::AppState;
use crate::store::Health;

/// The service's health.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct HealthView {
    /// "ok", or "corrupt" (the database failed its integrity check: writes
    /// are refused), or "unavailable" (the database cannot be read).
    pub status: String,
    pub database: Health,
}

#[utoipa::path(get, path = "/healthz",
    params(("check" = Option<bool>, Query, description = "run the database's integrity check (PRAGMA quick_check) now, unless one ran in the last 10 s")),
    responses((status = 200, description = "serving, the database readable and not known to be corrupt", body = HealthView),
              (status = 422, description = "bad check value", body = ProblemBody, content_type = "application/problem+json"),
              (status = 503, description = "the database is corrupt or cannot be read", body = HealthView)))]
pub async fn healthz(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
) -> Result<Response, Problem> {
    let q = QueryArgs::parse(query.as_deref(), &["check"])?;
    // The full check at most every 10 s (it reads every page).
    let recent = crate::store::now_ms() - st.store.health().checked_ms < 10_000;
    let readable = if q.flag("check")?.unwrap_or(false) && !recent {
        st.store.check().await.map(|_| ())
    } else {
        st.store.paused().await.map(|_| ())
    };
    if let Err(e) = &readable {
        st.store.observe(e);
    }
    let database = st.store.health();
    let status = match (&database.corrupt, &readable) {
        (Some(_), _) => "corrupt",
        (None, Err(_)) => "unavailable",
        (None, Ok(())) => "ok",
    };
    let code = if status == "ok" {
        StatusCode::OK
    } else {
        StatusCode::SERVICE_UNAVAILABLE
    };
    Ok((
        code,
        Json(HealthView {
            status: status.into(),
            database,
        }),
    )
        .into_response())
}

#[utoipa::path(get, path = "/v1/queue", responses((status = 200, description = "paused flag and experiments per state", body = Object)))]
pub async fn queue(State(st): State<AppState>) -> Result<Json<Value>, Problem> {
    let paused = st.store.paused().await.map_err(|e| st.fail(e))?;
    let (by_state, _) = st.store.counts().await.map_err(|e| st.fail(e))?;
    let counts: serde_json::Map<String, Value> =
        by_state.into_iter().map(|(s, n)| (s, json!(n))).collect();
    Ok(Json(json!({ "paused": paused, "experiments": counts })))
}

#[utoipa::path(post, path = "/v1/queue/pause", responses((status = 200, description = "paused flag and experiments per state", body = Object), (status = 401, description = "token required", body = ProblemBody, content_type = "application/problem+json"), (status = 403, description = "token refused, or a cross-origin write", body = ProblemBody, content_type = "application/problem+json")), security((), ("bearer" = [])))]
pub async fn pause(State(st): State<AppState>, headers: HeaderMap) -> Result<Json<Value>, Problem> {
    authorize(&st, &headers)?;
    st.store.set_paused(true).await.map_err(|e| st.fail(e))?;
    queue(State(st)).await
}

#[utoipa::path(post, path = "/v1/queue/resume", responses((status = 200, description = "paused flag and experiments per state", body = Object), (status = 401, description = "token required", body = ProblemBody, content_type = "application/problem+json"), (status = 403, description = "token refused, or a cross-origin write", body = ProblemBody, content_type = "application/problem+json")), security((), ("bearer" = [])))]
pub async fn resume(
    State(st): State<AppState>,
    headers: HeaderMap,
) -> Result<Json<Value>, Problem> {
    authorize(&st, &headers)?;
    st.store.set_paused(false).await.map_err(|e| st.fail(e))?;
    queue(State(st)).await
}

/// Prometheus text: queue depth, experiments by state, trials done and the
/// runner's current trials per second.
#[utoipa::path(get, path = "/metrics", responses((status = 200, description = "Prometheus text", body = String, content_type = "text/plain")))]
pub async fn metrics(State(st): State<AppState>) -> Result<Response, Problem> {
    let (by_state, trials) = st.store.counts().await.map_err(|e| st.fail(e))?;
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
    for state in crate::store::STATES {
        let n = by_state
            .iter()
            .find(|(s, _)| s == state)
            .map(|(_, n)| *n)
            .unwrap_or(0);
        out.push_str(&format!("zwidth_experiments{{state=\"{state}\"}} {n}\n"));
    }
    out.push_str("# HELP zwidth_trials_total Trials done over all experiments.\n# TYPE zwidth_trials_total counter\n");
    out.push_str(&format!("zwidth_trials_total {trials}\n"));
    // Every process (this one too) reports itself each second: those
    // seen in the last three seconds are alive; those that run rigs are
    // workers (an API-only process runs none).
    let mut workers = st.store.workers(3_000).await.map_err(|e| st.fail(e))?;
    workers.retain(|w| !w.rigs.is_empty());
    let rate: f64 = workers.iter().map(|w| w.trials_per_s).sum();
    let busy = workers.iter().filter(|w| w.running.is_some()).count();
    out.push_str("# HELP zwidth_trials_per_second Trials per second over every worker, last second.\n# TYPE zwidth_trials_per_second gauge\n");
    out.push_str(&format!("zwidth_trials_per_second {rate}\n"));
    out.push_str("# HELP zwidth_workers Worker processes seen in the last 3 s, by whether they run an experiment.\n# TYPE zwidth_workers gauge\n");
    out.push_str(&format!(
        "zwidth_workers{{busy=\"true\"}} {busy}\nzwidth_workers{{busy=\"false\"}} {}\n",
        workers.len() - busy
    ));
    Ok(([(header::CONTENT_TYPE, "text/plain; version=0.0.4")], out).into_response())
}
