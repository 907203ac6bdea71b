//! `/v1/rigs`: what each rig can do, its window, its load.

use axum::body::Bytes;
use axum::extract::{Path, State};
use axum::http::HeaderMap;
use axum::Json;
use serde::Serialize;
use std::sync::Arc;

use super::guard::{authorize, require_json};
use super::problem::{json_body, Problem, ProblemBody};
use super::AppState;
use crate::rig::window::Window;
use crate::rig::{Rig, RigInfo};

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
    /// The experiment it is running, if any (the oldest, when several
    /// workers run it: see `runs`).
    pub running: Option<String>,
    /// Every experiment running on it, and the worker process running each
    /// (with workers: the run that plans its units and replays them).
    pub runs: Vec<RunningOn>,
    /// The work units computing now (with PostgreSQL and workers): which
    /// map and column of which experiment, on which worker.
    pub units: Vec<crate::store::UnitRow>,
    /// An attached rig: its agent's session, state and capabilities.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub attached: Option<crate::rig::attached::AttachedView>,
    /// Only in the answer to `POST /v1/rigs`: the new rig's own agent
    /// credential, shown this once (the server keeps its SHA-256). It
    /// opens this rig's agent sessions, and no other rig's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub agent_token: Option<String>,
}

/// A rig's new agent credential (`POST /v1/rigs/{id}/agent-token`).
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct AgentCredential {
    pub rig: String,
    /// Shown this once; the server keeps its SHA-256. Give it to the rig's
    /// agent (`zwidth agent --token-file`, or ZWIDTH_AGENT_TOKEN).
    pub agent_token: String,
}

/// Give attached rig `id` a new credential of its own (replacing any it
/// had): the secret, shown once.
async fn issue_credential(st: &AppState, id: &str) -> Result<String, Problem> {
    let secret = super::state::random_secret();
    st.store
        .set_rig_credential(id, &super::guard::credential_digest(&secret))
        .await
        .map_err(|e| st.fail(e))?;
    tracing::info!(rig = %id, "a new agent credential was issued: the rig's earlier one and the shared agent tokens no longer open it");
    Ok(secret)
}

#[utoipa::path(post, path = "/v1/rigs/{id}/agent-token", params(("id" = String, Path, description = "rig id")),
    description = "Issue attached rig `id` a new agent credential of its own, shown this once (`zwidth rig token ID`). From now on it alone opens the rig's agent sessions: the rig's earlier credential and the server's shared agent tokens no longer do (a session open now goes on until it ends). Other rigs' credentials are untouched.",
    responses((status = 200, body = AgentCredential),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "not an attached rig (a simulator has no agent)", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn agent_token(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<AgentCredential>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    if rig.attached().is_none() {
        return Err(Problem::new(
            axum::http::StatusCode::CONFLICT,
            "Conflict",
            format!("rig {id:?} is simulated: it has no agent, so no agent credential"),
        )
        .with_field("id"));
    }
    let agent_token = issue_credential(&st, &id).await?;
    Ok(Json(AgentCredential {
        rig: id,
        agent_token,
    }))
}

/// An experiment running, and where.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct RunningOn {
    pub id: String,
    /// The worker process (host:pid:tag) holding its lease.
    pub worker: Option<String>,
}

pub async fn rig_view(st: &AppState, rig: &Arc<dyn Rig>) -> Result<RigView, Problem> {
    let info = rig.info();
    let id = &info.id;
    let window = st.store.rig_window(id).await.map_err(|e| st.fail(e))?;
    let now = jiff::Timestamp::now();
    let next = match window.as_ref().and_then(|w| w.validate().ok()) {
        Some(h) => h.next_open(now),
        None => now,
    };
    let (waiting, running) = st.store.rig_load(id).await.map_err(|e| st.fail(e))?;
    let units = st.store.running_units(id).await.map_err(|e| st.fail(e))?;
    Ok(RigView {
        attached: rig.attached().map(|a| a.view()),
        info,
        open_now: next == now,
        next_start_ms: next.as_millisecond(),
        window,
        waiting,
        running: running.first().map(|(id, _)| id.clone()),
        runs: running
            .into_iter()
            .map(|(id, worker)| RunningOn { id, worker })
            .collect(),
        units,
        agent_token: None,
    })
}

#[utoipa::path(get, path = "/v1/rigs", responses((status = 200, description = "the rigs, the first is the default", body = Vec<RigView>)))]
pub async fn rigs(State(st): State<AppState>) -> Result<Json<Vec<RigView>>, Problem> {
    let mut out = Vec::new();
    for r in st.rig_list().iter() {
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
pub async fn set_window(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    body: Bytes,
) -> Result<Json<RigView>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    require_json(&headers)?;
    let w: Window = json_body(
        &body,
        r#"window {"start":"HH:MM","end":"HH:MM","tz":"Europe/Berlin"}"#,
    )?;
    w.validate()?;
    st.store
        .set_rig_window(&id, Some(&w))
        .await
        .map_err(|e| st.fail(e))?;
    Ok(Json(rig_view(&st, &rig).await?))
}

#[utoipa::path(delete, path = "/v1/rigs/{id}/window", params(("id" = String, Path, description = "rig id")),
    responses((status = 200, body = RigView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn clear_window(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<RigView>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    st.store
        .set_rig_window(&id, None)
        .await
        .map_err(|e| st.fail(e))?;
    Ok(Json(rig_view(&st, &rig).await?))
}

#[utoipa::path(delete, path = "/v1/rigs/{id}/quarantine", params(("id" = String, Path, description = "rig id")),
    description = "Release a quarantined attached rig (after an operator has checked it): its queue goes on.",
    responses((status = 200, body = RigView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn release(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<RigView>, Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    if let Some(a) = rig.attached() {
        st.store
            .set_quarantine(&id, None)
            .await
            .map_err(|e| st.fail(e))?;
        a.set_quarantine(None);
    }
    Ok(Json(rig_view(&st, &rig).await?))
}

#[utoipa::path(get, path = "/v1/rigs/{id}/audit",
    params(("id" = String, Path, description = "rig id"),
           ("limit" = Option<i64>, Query, description = "rows per page, 1 to 500 (default 100)"),
           ("before" = Option<i64>, Query, description = "only rows with an id below this (the next page: the last row's id)")),
    description = "Agent messages refused for this rig (stale epochs, results for trials never sent or not a verdict of their trial, malformed messages), newest first, a page at a time. Each text is capped (reason 1 KiB, message 4 KiB, ids 128 bytes) and the audit keeps each rig's newest 1000 rows of at most 30 days (docs/rigs.md, \"The audit\").",
    responses((status = 200, body = Vec<crate::store::agents::AuditRow>),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "bad limit or before", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn audit(
    State(st): State<AppState>,
    Path(id): Path<String>,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
) -> Result<Json<Vec<crate::store::agents::AuditRow>>, Problem> {
    st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    audit_page(&st, &id, query.as_deref()).await
}

#[utoipa::path(get, path = "/v1/agent/audit",
    params(("limit" = Option<i64>, Query, description = "rows per page, 1 to 500 (default 100)"),
           ("before" = Option<i64>, Query, description = "only rows with an id below this (the next page: the last row's id)")),
    description = "Refused agent sessions that named no rig of this server (not JSON, not a hello, an unknown rig: its name, cut to 128 bytes, in the reason), newest first, a page at a time; kept like a rig's audit.",
    responses((status = 200, body = Vec<crate::store::agents::AuditRow>),
              (status = 422, description = "bad limit or before", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn agent_audit(
    State(st): State<AppState>,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
) -> Result<Json<Vec<crate::store::agents::AuditRow>>, Problem> {
    audit_page(&st, crate::store::agents::UNKNOWN_RIG, query.as_deref()).await
}

async fn audit_page(
    st: &AppState,
    rig: &str,
    query: Option<&str>,
) -> Result<Json<Vec<crate::store::agents::AuditRow>>, Problem> {
    use crate::store::agents::AUDIT_PAGE_MAX;
    let q = super::problem::QueryArgs::parse(query, &["limit", "before"])?;
    let limit = q.int("limit", 1..=AUDIT_PAGE_MAX)?.unwrap_or(100);
    let before = q.int("before", 1..=i64::MAX)?;
    Ok(Json(
        st.store
            .audit_log(rig, limit, before)
            .await
            .map_err(|e| st.fail(e))?,
    ))
}

/// `?mode=` of a stop.
#[derive(Debug, serde::Deserialize, utoipa::IntoParams)]
#[into_params(parameter_in = Query)]
pub struct StopQuery {
    /// deferred (finish the trial), abort (end it now) or halt (abort and
    /// latch: the rig needs a local reset).
    pub mode: crate::rig::protocol::StopMode,
}

#[utoipa::path(post, path = "/v1/rigs/{id}/stop", params(("id" = String, Path, description = "rig id"), StopQuery),
    description = "Stop an attached rig: the agent ends or finishes its trial and takes no more until re-armed on the rig (halt: until reset locally). The experiment waits; it does not fail.",
    responses((status = 202, body = RigView),
              (status = 422, description = "bad mode, or not an attached rig", body = ProblemBody, content_type = "application/problem+json"),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "no agent connected", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn stop(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
) -> Result<(axum::http::StatusCode, Json<RigView>), Problem> {
    authorize(&st, &headers)?;
    let rig = st.rig(&id).ok_or_else(|| Problem::not_found("rig", &id))?;
    let q = super::problem::QueryArgs::parse(query.as_deref(), &["mode"])?;
    let mode = match q.str("mode") {
        Some("deferred") => crate::rig::protocol::StopMode::Deferred,
        Some("abort") => crate::rig::protocol::StopMode::Abort,
        Some("halt") => crate::rig::protocol::StopMode::Halt,
        other => {
            return Err(crate::error::SpecError::new(
                "mode",
                format!("{other:?}"),
                "must be one of deferred, abort, halt",
            )
            .into())
        }
    };
    let Some(a) = rig.attached() else {
        return Err(crate::error::SpecError::new(
            "id",
            &id,
            "only an attached rig can be stopped (a simulator's experiments are cancelled instead)",
        )
        .into());
    };
    if !a.stop(mode) {
        return Err(Problem::new(
            axum::http::StatusCode::CONFLICT,
            "Conflict",
            format!("rig {id} has no agent connected: nothing is moving"),
        )
        .with_field("id"));
    }
    Ok((
        axum::http::StatusCode::ACCEPTED,
        Json(rig_view(&st, &rig).await?),
    ))
}

/// Most rigs one server runs (each has a queue runner).
pub const MAX_RIGS: usize = 64;

/// A rig to register: hardware behind a `zwidth agent`.
#[derive(Debug, serde::Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewRig {
    /// 1 to 64 letters, digits, '-' or '_'.
    pub id: String,
    /// What it is, for people (at most 500 characters).
    #[serde(default)]
    pub description: String,
}

#[utoipa::path(post, path = "/v1/rigs", request_body = NewRig,
    description = "Register an attached rig (hardware behind a `zwidth agent`, docs/rigs.md). It is stored, and experiments may be submitted for it at once: they wait until its agent connects. The answer carries the rig's own agent credential (`agent_token`), shown this once: it alone opens this rig's agent sessions.",
    responses((status = 201, body = RigView),
              (status = 401, body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "a rig with this id exists", body = ProblemBody, content_type = "application/problem+json"),
              (status = 415, body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "bad id or description", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn register(
    State(st): State<AppState>,
    headers: HeaderMap,
    body: Bytes,
) -> Result<(axum::http::StatusCode, Json<RigView>), Problem> {
    authorize(&st, &headers)?;
    require_json(&headers)?;
    let new: NewRig = json_body(&body, r#"rig {"id":"bench","description":"…"}"#)?;
    crate::rig::check_id("id", &new.id)?;
    if new.description.chars().count() > 500 {
        return Err(crate::error::SpecError::new(
            "description",
            format!("({} characters)", new.description.chars().count()),
            "at most 500 characters",
        )
        .into());
    }
    let conflict = || {
        Problem::new(
            axum::http::StatusCode::CONFLICT,
            "Conflict",
            format!("a rig {:?} exists (GET /v1/rigs)", new.id),
        )
        .with_field("id")
    };
    if st.rig(&new.id).is_some() {
        return Err(conflict());
    }
    if st.rig_list().len() >= MAX_RIGS {
        return Err(crate::error::SpecError::new(
            "id",
            &new.id,
            format!("a server has at most {MAX_RIGS} rigs"),
        )
        .into());
    }
    let rig = crate::rig::AttachedRig::new(&new.id, &new.description)?;
    rig.set_timing(st.lease);
    if !st
        .store
        .add_attached_rig(&new.id, &new.description)
        .await
        .map_err(|e| st.fail(e))?
    {
        return Err(conflict());
    }
    let rig: Arc<dyn Rig> = Arc::new(rig);
    {
        let mut list = st.rigs.write().unwrap_or_else(|e| e.into_inner());
        if list.iter().any(|r| r.info().id == new.id) {
            return Err(conflict());
        }
        list.push(rig.clone());
    }
    let agent_token = issue_credential(&st, &new.id).await?;
    (st.start_runner)(rig.clone());
    let mut view = rig_view(&st, &rig).await?;
    view.agent_token = Some(agent_token);
    Ok((axum::http::StatusCode::CREATED, Json(view)))
}
