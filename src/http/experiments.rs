//! `/v1/experiments`: submit (stored before it is acknowledged), list
//! (paged summaries), show, cancel, and each experiment's trials,
//! evaluations, plot and points.

use axum::body::Bytes;
use axum::extract::{Path, RawQuery, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use serde::Serialize;
use serde_json::{json, Value};

use super::guard::{authorize, require_json};
use super::problem::{from_value, json_body, Problem, ProblemBody, QueryArgs};
use super::AppState;
use crate::error::SpecError;
use crate::experiment::ExperimentSpec;
use crate::report::{self, MapSummary};
use crate::store::UnitRow;
use crate::store::{now_ms, ExperimentRow, ExperimentState, Inserted, NewExperiment};
use crate::zwidth::cost::Cost;
use crate::zwidth::search::{StoredEvaluation, StoredTrial};

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
    /// The worker process (host:pid:tag) running it, or that ran it last.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub worker: Option<String>,
    /// How many times it was claimed: 1 for a run that went through at
    /// once; more after a shutdown or a worker lost (0: never started).
    pub attempt: i64,
    /// `trials_done`, `fraction` (0 to 1), a tune's `best` so far, while
    /// running `elapsed_s`, `eta_s` and `trials_total_estimate`, and `held`
    /// with the reason while its trials cannot be stored.
    pub progress: Value,
    /// The experiment as submitted (left out of list pages unless asked for).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub spec: Option<Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub result: Option<Value>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What it was estimated to cost when it was submitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub estimate: Option<Cost>,
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
    if r.state == ExperimentState::Running {
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
            worker: r.worker.clone(),
            attempt: r.attempt,
            spec: serde_json::from_str(&r.spec).ok(),
            result: r
                .result
                .as_deref()
                .and_then(|s| serde_json::from_str(s).ok()),
            id: r.id,
            kind: r.kind,
            state: r.state.to_string(),
            priority: r.priority,
            created_ms: r.created_ms,
            started_ms: r.started_ms,
            finished_ms: r.finished_ms,
            not_before_ms: r.not_before_ms,
            error: r.error,
            estimate: None,
        }
    }
}

impl AppState {
    /// The view of a row, with `held` when its running trials cannot be stored.
    pub(crate) fn view(&self, row: ExperimentRow) -> ExperimentView {
        let (held, waiting) = self
            .running
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(&row.id)
            .map_or((None, None), |o| (o.held(), o.waiting()));
        let mut v = ExperimentView::from(row);
        if let Some(why) = held {
            v.progress["held"] = json!(why);
        }
        let waiting = waiting.or_else(|| {
            (v.state == ExperimentState::Queued.as_str())
                .then(|| self.unserved(&v.rig))
                .flatten()
        });
        if let Some(why) = waiting {
            // No ETA while the rig is away: nothing is running.
            v.progress["waiting_for_rig"] = json!(why);
            if let Some(p) = v.progress.as_object_mut() {
                p.remove("eta_s");
            }
        }
        v
    }
}

/// The experiment in a body. The kind is read first, then the body as that
/// kind, so a parse error names its field (`scene.device.mass`), which
/// serde's internally tagged enums lose.
fn experiment_body(bytes: &[u8]) -> Result<ExperimentSpec, Problem> {
    let mut v: Value = json_body(bytes, "experiment")?;
    let kinds = "must be one of map, compare, sweep, tune";
    let Some(obj) = v.as_object_mut() else {
        return Err(SpecError::new(
            "body",
            "(not an object)",
            "must be a JSON object with a kind",
        )
        .into());
    };
    let kind = match obj.remove("kind") {
        Some(Value::String(k)) => k,
        Some(other) => return Err(SpecError::new("kind", other, kinds).into()),
        None => return Err(SpecError::new("kind", "missing", kinds).into()),
    };
    let what = "experiment";
    Ok(match kind.as_str() {
        "map" => ExperimentSpec::Map(from_value(v, what, "")?),
        "compare" => ExperimentSpec::Compare(from_value(v, what, "")?),
        "sweep" => ExperimentSpec::Sweep(from_value(v, what, "")?),
        "tune" => ExperimentSpec::Tune(from_value(v, what, "")?),
        other => return Err(SpecError::new("kind", format!("{other:?}"), kinds).into()),
    })
}

/// Longest Idempotency-Key accepted (characters).
const KEY_MAX: usize = 200;

#[utoipa::path(post, path = "/v1/experiments", request_body = ExperimentSpec,
    params(("priority" = Option<i64>, Query, description = "-1000 to 1000, higher first"),
           ("not_before_ms" = Option<i64>, Query, description = "do not start before (unix ms)"),
           ("rig" = Option<String>, Query, description = "rig id (GET /v1/rigs); default the first"),
           ("Idempotency-Key" = Option<String>, Header, description = "repeat-safe submission: the same key with the same request returns the first experiment (200); with a different request, 422")),
    responses((status = 202, description = "stored and queued, with its estimated cost", body = ExperimentView),
              (status = 200, description = "an earlier submission with the same Idempotency-Key", body = ExperimentView),
              (status = 401, description = "token required", body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, description = "token refused, or a cross-origin write", body = ProblemBody, content_type = "application/problem+json"),
              (status = 413, description = "body over 1 MiB", body = ProblemBody, content_type = "application/problem+json"),
              (status = 415, description = "body not sent as application/json", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "invalid experiment, or over the cost limits", body = ProblemBody, content_type = "application/problem+json"),
              (status = 503, description = "database busy or corrupt: nothing stored", body = ProblemBody, content_type = "application/problem+json"),
              (status = 507, description = "disk full: nothing stored", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
#[tracing::instrument(skip(st, headers, body, query))]
pub async fn submit(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
    headers: HeaderMap,
    body: Bytes,
) -> Result<Response, Problem> {
    authorize(&st, &headers)?;
    let q = QueryArgs::parse(query.as_deref(), &["priority", "not_before_ms", "rig"])?;
    require_json(&headers)?;
    let mut spec = experiment_body(&body)?;
    super::prior::resolve_run_prior(&st, &mut spec).await?;
    let estimate = spec.validate()?;
    let rig = match q.str("rig") {
        None => st.rig_list()[0].clone(),
        Some(id) => st.rig(id).ok_or_else(|| {
            Problem::from(SpecError::new(
                "rig",
                format!("{id:?}"),
                format!("must be one of the rigs: {}", st.rig_ids()),
            ))
        })?,
    };
    rig.check(&spec.scenes())?;
    if let (Some(_), ExperimentSpec::Compare(c)) = (rig.attached(), &spec) {
        if c.tuned.is_some() {
            return Err(SpecError::new(
                "tuned",
                "(set)",
                "a tuned comparison tunes in this process, not on an attached rig: submit the tunes as tune experiments on the rig, then compare their results",
            )
            .into());
        }
    }
    let rig_id = rig.info().id;
    let priority = q.int("priority", -1000..=1000)?.unwrap_or(0);
    let not_before_ms = q.int("not_before_ms", 0..=i64::MAX / 2)?;
    let key = match headers.get("idempotency-key") {
        None => None,
        Some(v) => match v.to_str() {
            Ok(k) if !k.is_empty() && k.len() <= KEY_MAX => Some(k.to_owned()),
            _ => {
                return Err(SpecError::new(
                    "Idempotency-Key",
                    format!("{v:?}"),
                    format!("must be 1 to {KEY_MAX} visible ASCII characters"),
                )
                .into())
            }
        },
    };
    let id = uuid::Uuid::now_v7().to_string();
    let text = serde_json::to_string(&spec).map_err(Problem::internal)?;
    let inserted = st
        .store
        .insert(NewExperiment {
            id: &id,
            kind: spec.kind(),
            spec: &text,
            priority,
            key: key.as_deref(),
            not_before_ms,
            rig: &rig_id,
        })
        .await
        .map_err(|e| st.fail(e))?;
    let (status, row) = match inserted {
        Inserted::New(row) => (StatusCode::ACCEPTED, row),
        Inserted::Earlier(row) => (StatusCode::OK, row),
        Inserted::KeyReused(row) => {
            return Err(SpecError::new(
                "Idempotency-Key",
                format!("{:?}", key.unwrap_or_default()),
                format!(
                    "was used for experiment {} with a different request: use a new key for a new request",
                    row.id
                ),
            )
            .into())
        }
    };
    let location = format!("/v1/experiments/{}", row.id);
    let mut view = st.view(row);
    view.estimate = Some(estimate);
    Ok((status, [(header::LOCATION, location)], Json(view)).into_response())
}

/// Experiments on one page of the list by default, and at most.
const LIST_DEFAULT: i64 = 50;
const LIST_MAX: i64 = 200;
/// At most this many per page when results are included (each can be MBs).
const LIST_MAX_WITH_RESULTS: i64 = 20;

/// A page of experiments and the cursor of the next one.
#[derive(Debug, Serialize, utoipa::ToSchema)]
pub struct ExperimentPage {
    pub experiments: Vec<ExperimentView>,
    /// Pass as `cursor` for the next (older) page; absent on the last page.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub next_cursor: Option<String>,
}

#[utoipa::path(get, path = "/v1/experiments",
    params(("limit" = Option<i64>, Query, description = "1 to 200 per page (default 50; at most 20 with results)"),
           ("cursor" = Option<String>, Query, description = "next_cursor of the previous page"),
           ("include" = Option<String>, Query, description = "comma-separated extras: spec, result")),
    responses((status = 200, description = "newest first: summaries (state, progress, error) unless include asks for more", body = ExperimentPage),
              (status = 422, description = "bad limit, cursor or include", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn list(
    State(st): State<AppState>,
    RawQuery(query): RawQuery,
) -> Result<Json<ExperimentPage>, Problem> {
    let q = QueryArgs::parse(query.as_deref(), &["limit", "cursor", "include"])?;
    let mut with_spec = false;
    let mut with_result = false;
    for part in q
        .str("include")
        .unwrap_or("")
        .split(',')
        .filter(|s| !s.is_empty())
    {
        match part.trim() {
            "spec" => with_spec = true,
            "result" => with_result = true,
            other => {
                return Err(SpecError::new(
                    "include",
                    format!("{other:?}"),
                    "must be spec, result or both (comma-separated)",
                )
                .into())
            }
        }
    }
    let max = if with_result {
        LIST_MAX_WITH_RESULTS
    } else {
        LIST_MAX
    };
    let limit = q.int("limit", 1..=max)?.unwrap_or(LIST_DEFAULT.min(max));
    let cursor = match q.str("cursor") {
        None => None,
        Some(c) => Some(parse_cursor(c).ok_or_else(|| {
            Problem::from(SpecError::new(
                "cursor",
                format!("{c:?}"),
                "must be a next_cursor this server returned",
            ))
        })?),
    };
    let rows = st
        .store
        .list(
            limit,
            cursor.as_ref().map(|(t, id)| (*t, id.as_str())),
            with_spec || with_result,
        )
        .await
        .map_err(|e| st.fail(e))?;
    let next_cursor = (rows.len() as i64 == limit)
        .then(|| rows.last().map(|r| format!("{}_{}", r.created_ms, r.id)))
        .flatten();
    let experiments = rows
        .into_iter()
        .map(|r| {
            let mut v = st.view(r);
            if !with_spec {
                v.spec = None;
            }
            if !with_result {
                v.result = None;
            }
            v
        })
        .collect();
    Ok(Json(ExperimentPage {
        experiments,
        next_cursor,
    }))
}

/// `"<created_ms>_<id>"`.
fn parse_cursor(c: &str) -> Option<(i64, String)> {
    let (t, id) = c.split_once('_')?;
    let t = t.parse::<i64>().ok()?;
    (!id.is_empty() && id.len() <= 64).then(|| (t, id.to_owned()))
}

#[utoipa::path(get, path = "/v1/experiments/{id}", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "the experiment: state, progress, spec, result", body = ExperimentView),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn show(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<ExperimentView>, Problem> {
    match st.store.get(&id).await.map_err(|e| st.fail(e))? {
        Some(row) => Ok(Json(st.view(row))),
        None => Err(Problem::not_found("experiment", &id)),
    }
}

#[utoipa::path(post, path = "/v1/experiments/{id}/cancel", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "cancelled: it stays cancelled", body = ExperimentView),
              (status = 401, description = "token required", body = ProblemBody, content_type = "application/problem+json"),
              (status = 403, description = "token refused, or a cross-origin write", body = ProblemBody, content_type = "application/problem+json"),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "already ended", body = ProblemBody, content_type = "application/problem+json")),
    security((), ("bearer" = [])))]
pub async fn cancel(
    State(st): State<AppState>,
    headers: HeaderMap,
    Path(id): Path<String>,
) -> Result<Json<ExperimentView>, Problem> {
    authorize(&st, &headers)?;
    let changed = st.store.cancel(&id).await.map_err(|e| st.fail(e))?;
    if changed {
        crate::jobs::cancel_running(&st.running, &id);
    }
    match st.store.get(&id).await.map_err(|e| st.fail(e))? {
        None => Err(Problem::not_found("experiment", &id)),
        Some(row) if !changed => Err(Problem::new(
            StatusCode::CONFLICT,
            "Not cancellable",
            format!("experiment {id} is already {}", row.state),
        )),
        Some(row) => Ok(Json(st.view(row))),
    }
}

/// Most trials one page returns.
pub const TRIALS_PAGE_MAX: i64 = 10_000;

#[utoipa::path(get, path = "/v1/experiments/{id}/trials",
    params(("id" = String, Path, description = "experiment id"),
           ("scope" = Option<u32>, Query, description = "only this map of the experiment (0, 1, …)"),
           ("offset" = Option<i64>, Query, description = "skip this many (default 0)"),
           ("limit" = Option<i64>, Query, description = "at most this many, 1 to 10000 (default 1000)")),
    responses((status = 200, description = "stored trials in their maps' order: by scope, then column (the position of B in the map's B list), then the order the search asked them in", body = Vec<StoredTrial>),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "bad scope, offset or limit", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn trials(
    State(st): State<AppState>,
    Path(id): Path<String>,
    RawQuery(query): RawQuery,
) -> Result<Json<Vec<StoredTrial>>, Problem> {
    let q = QueryArgs::parse(query.as_deref(), &["scope", "offset", "limit"])?;
    let limit = q.int("limit", 1..=TRIALS_PAGE_MAX)?.unwrap_or(1000);
    let offset = q.int("offset", 0..=i64::MAX)?.unwrap_or(0);
    let scope = q.int("scope", 0..=u32::MAX as i64)?.map(|s| s as u32);
    st.exists(&id).await?;
    let t = st
        .store
        .trials_page(&id, scope, offset, limit)
        .await
        .map_err(|e| st.fail(e))?;
    Ok(Json(t))
}

#[utoipa::path(get, path = "/v1/experiments/{id}/evaluations", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "a tune's stored evaluations (parameters, objectives, elapsed time), in the order stored, also while it runs", body = Vec<StoredEvaluation>),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn evaluations(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<Vec<StoredEvaluation>>, Problem> {
    st.exists(&id).await?;
    Ok(Json(
        st.store.evaluations(&id).await.map_err(|e| st.fail(e))?,
    ))
}

#[utoipa::path(get, path = "/v1/experiments/{id}/units", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "the experiment's work units, by map and column: with PostgreSQL and workers, each B column of a bisection or grid map, or a whole map (a trace, the analytic engine; column -1), is computed by whichever worker claims it; shows where each ran, its attempts and trials. Empty for an experiment run in one process (SQLite)", body = Vec<UnitRow>),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn units(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Json<Vec<UnitRow>>, Problem> {
    st.exists(&id).await?;
    Ok(Json(st.store.units(&id).await.map_err(|e| st.fail(e))?))
}

impl AppState {
    async fn exists(&self, id: &str) -> Result<(), Problem> {
        match self.store.state(id).await.map_err(|e| self.fail(e))? {
            Some(_) => Ok(()),
            None => Err(Problem::not_found("experiment", id)),
        }
    }
}

/// The maps of a succeeded experiment (409 while it is not).
pub async fn finished_maps(
    st: &AppState,
    id: &str,
) -> Result<(ExperimentSpec, Value, Vec<MapSummary>), Problem> {
    let row = st
        .store
        .get(id)
        .await
        .map_err(|e| st.fail(e))?
        .ok_or_else(|| Problem::not_found("experiment", id))?;
    let (Some(result), ExperimentState::Succeeded) = (row.result.as_deref(), row.state) else {
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

/// A result with nothing to draw (e.g. every boundary empty) is the
/// request's problem, not the server's.
pub fn no_plot(e: String) -> Problem {
    Problem::new(StatusCode::UNPROCESSABLE_ENTITY, "Nothing to plot", e)
}

#[utoipa::path(get, path = "/v1/experiments/{id}/plot.svg", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "one map: Fig. 7 style; a parameter sweep: K-width against the parameter; else every boundary", body = String, content_type = "image/svg+xml"),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "not succeeded (yet)", body = ProblemBody, content_type = "application/problem+json"),
              (status = 422, description = "nothing to plot", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn plot(State(st): State<AppState>, Path(id): Path<String>) -> Result<Response, Problem> {
    let (spec, result, maps) = finished_maps(&st, &id).await?;
    let svg = report::svg(&spec, &maps, &result).map_err(no_plot)?;
    Ok(([(header::CONTENT_TYPE, "image/svg+xml")], svg).into_response())
}

#[utoipa::path(get, path = "/v1/experiments/{id}/points.csv", params(("id" = String, Path, description = "experiment id")),
    responses((status = 200, description = "maps: map,k_n_per_m,b_ns_per_m,renders,fidelity_ns_per_m; a tune: its evaluations", body = String, content_type = "text/csv"),
              (status = 404, description = "no such experiment", body = ProblemBody, content_type = "application/problem+json"),
              (status = 409, description = "not succeeded (yet)", body = ProblemBody, content_type = "application/problem+json")))]
pub async fn points(
    State(st): State<AppState>,
    Path(id): Path<String>,
) -> Result<Response, Problem> {
    let (spec, result, maps) = finished_maps(&st, &id).await?;
    let csv = match spec {
        ExperimentSpec::Tune(_) => report::tune_result(&result)
            .map_err(Problem::internal)?
            .csv(),
        _ => report::points_csv(&maps),
    };
    Ok(([(header::CONTENT_TYPE, "text/csv")], csv).into_response())
}
