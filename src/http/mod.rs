//! The HTTP API (axum), one module per resource. Errors are RFC 9457
//! `application/problem+json` naming the field (`problem`); who may write
//! and from where is `guard`. Bodies are parsed with the engines' own spec
//! types and validated with the engines' own validation.

pub mod accept;
pub mod agent;
pub mod compare;
pub mod experiments;
pub mod guard;
pub mod openapi;
pub mod problem;
pub mod queue;
pub mod rigs;
pub mod ui;

use axum::http::StatusCode;
use axum::routing::{get, post, put};
use axum::Router;
use std::sync::Arc;
use std::time::Duration;

pub use openapi::openapi_json;
pub use problem::{Problem, ProblemBody};

use crate::rig::Rig;
use crate::store::Store;
use guard::token_accepted;

/// Largest request body accepted (bytes).
pub const BODY_LIMIT: usize = 1 << 20;
/// Longest request target (path and query) accepted, bytes; longer is a 414.
/// (hyper itself answers a bare 414 beyond 64 KiB.)
pub const URI_LIMIT: usize = 16 * 1024;

#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    /// Bearer tokens accepted on mutating endpoints; empty: none required
    /// (only allowed when bound to loopback).
    pub tokens: Arc<Vec<String>>,
    /// Tokens that open agent sessions (`GET /v1/agent`), never a user's.
    pub agent_tokens: Arc<Vec<String>>,
    /// Origins besides the server's own that may write (`--allow-origin`).
    pub allow_origins: Arc<Vec<String>>,
    /// The rigs experiments run on; the first is the default. Attached
    /// rigs registered through the API join at run time.
    pub rigs: Arc<std::sync::RwLock<Vec<Arc<dyn Rig>>>>,
    /// Starts the queue runner of a rig registered at run time.
    pub start_runner: Arc<dyn Fn(Arc<dyn Rig>) + Send + Sync>,
    /// Heartbeat, TTL and grace of attached rigs' sessions.
    pub lease: crate::rig::lease::Timing,
    /// Running experiments' observers (cancel reaches them at once).
    pub running: crate::jobs::Running,
    /// This process runs only attached rigs (`--api-only`).
    pub api_only: bool,
    /// The rigs live workers run, as the `workers` table last said
    /// ([`refresh_served`]): a queued run on another rig says it waits.
    pub served: Arc<std::sync::RwLock<Option<std::collections::HashSet<String>>>>,
}

/// Within how long a worker's last report counts it as live (ms).
pub const WORKER_LIVE_MS: i64 = 5_000;

/// Every second until `stop`: the rigs that live workers run, from the
/// `workers` table (so every API process, also one restarted, knows).
pub async fn refresh_served(st: AppState, mut stop: tokio::sync::watch::Receiver<bool>) {
    while !*stop.borrow() {
        if let Ok(rows) = st.store.workers(WORKER_LIVE_MS).await {
            let rigs = rows
                .iter()
                .flat_map(|w| {
                    w.rigs
                        .split(',')
                        .map(|r| r.split(':').next().unwrap_or("").to_string())
                })
                .filter(|r| !r.is_empty())
                .collect();
            *st.served.write().unwrap_or_else(|e| e.into_inner()) = Some(rigs);
        }
        tokio::select! {
            _ = tokio::time::sleep(crate::jobs::worker::SEEN_EVERY) => {}
            _ = stop.changed() => {}
        }
    }
}

impl AppState {
    fn rig(&self, id: &str) -> Option<Arc<dyn Rig>> {
        self.rig_list().into_iter().find(|r| r.info().id == id)
    }

    /// Every rig, the default first.
    pub fn rig_list(&self) -> Vec<Arc<dyn Rig>> {
        self.rigs.read().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// A storage error as a problem; a corrupt page met on the way is
    /// remembered, so writes are refused from then on.
    fn fail(&self, e: sqlx::Error) -> Problem {
        self.store.observe(&e);
        Problem::store(e, self.store.is_postgres())
    }

    /// A state that serves reads of `store` with the default simulated rig
    /// and runs nothing (benchmarks and tests of the pages).
    pub fn reader(store: Store) -> Result<Self, String> {
        let sim: Arc<dyn Rig> =
            Arc::new(crate::rig::SimulatedRig::new("sim", 1).map_err(|e| e.to_string())?);
        Ok(Self {
            store,
            tokens: Arc::new(vec![random_secret()]),
            agent_tokens: Arc::new(vec![random_secret()]),
            allow_origins: Arc::new(Vec::new()),
            rigs: Arc::new(std::sync::RwLock::new(vec![sim])),
            start_runner: Arc::new(|_| {}),
            lease: crate::rig::lease::Timing::default(),
            running: Default::default(),
            api_only: false,
            served: Default::default(),
        })
    }

    /// Why a queued run on `rig` cannot start: no process runs that rig
    /// (None while it is run here, by a live worker, or not yet known).
    pub fn unserved(&self, rig: &str) -> Option<String> {
        let here = self
            .rig(rig)
            .is_some_and(|r| !self.api_only || r.attached().is_some());
        if here {
            return None;
        }
        let served = self.served.read().unwrap_or_else(|e| e.into_inner());
        let rigs = served.as_ref()?;
        if rigs.contains(rig) {
            return None;
        }
        let mut others: Vec<&str> = rigs.iter().map(String::as_str).collect();
        others.sort_unstable();
        Some(format!(
            "no live worker runs rig {rig} (start one with `zwidth worker --rigs {rig}`); the live workers run: {}",
            if others.is_empty() {
                "none".to_string()
            } else {
                others.join(", ")
            }
        ))
    }

    fn rig_ids(&self) -> String {
        self.rig_list()
            .iter()
            .map(|r| r.info().id.clone())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// How `serve` runs.
pub struct ServeConfig {
    pub db: crate::store::Location,
    pub bind: String,
    pub tokens: Vec<String>,
    /// Agent tokens; empty: the one in `<db>.agent-token` (made on first
    /// start; with PostgreSQL, none: agents need `--agent-token-file`).
    pub agent_tokens: Vec<String>,
    pub allow_origins: Vec<String>,
    pub rigs: Vec<Arc<dyn Rig>>,
    /// Heartbeat, TTL and grace of attached rigs' sessions.
    pub lease: crate::rig::lease::Timing,
    /// Longest a request may take before a 503 (s).
    pub request_timeout_s: f64,
    /// Most connections one client address may hold at once.
    pub max_connections_per_client: usize,
    /// Run only attached rigs here (workers run the simulated ones).
    pub api_only: bool,
    /// This process as a worker (its id on the leases it holds).
    pub worker: crate::jobs::Worker,
}

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
        agent_tokens,
        allow_origins,
        rigs,
        lease,
        request_timeout_s,
        max_connections_per_client,
        api_only,
        worker,
    } = cfg;
    let me = Arc::new(worker);
    if rigs.is_empty() {
        return Err("refusing to serve without a rig".into());
    }
    if !(request_timeout_s.is_finite() && (0.1..=3600.0).contains(&request_timeout_s)) {
        return Err(format!(
            "refusing: --request-timeout-s = {request_timeout_s} must be 0.1 to 3600 s"
        ));
    }
    // With PostgreSQL, several API processes serve one database: they and
    // the clients share the user token, so it is given, never made here.
    if db.sqlite_path().is_none() && tokens.is_empty() {
        return Err("refusing: with a PostgreSQL database give the user token (--token-file, ZWIDTH_TOKENS or --token): the API processes and their clients must share it".into());
    }
    // Every check that can refuse comes before any side effect (no
    // socket, no database file).
    let addrs: Vec<std::net::SocketAddr> = tokio::net::lookup_host(&bind)
        .await
        .map_err(|e| format!("cannot resolve --bind {bind}: {e}"))?
        .collect();
    if addrs.is_empty() {
        return Err(format!("--bind {bind} names no address"));
    }
    // Then the socket (a second server on the same port stops here, before
    // touching the database), then the database, which one server at a time
    // may serve (an exclusive lock on `<db>.lock`).
    let listener = tokio::net::TcpListener::bind(addrs.as_slice())
        .await
        .map_err(|e| format!("cannot bind {bind}: {e}"))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    // One server per SQLite file; PostgreSQL takes many.
    let _serving = db.sqlite_path().map(lock_database).transpose()?;
    let store = Store::connect(&db).await.map_err(|e| match e {
        crate::store::OpenError::Refused(m) => format!("refusing: {m}"),
        crate::store::OpenError::Failed(m) => m,
    })?;
    // A corrupt database is served read-only: /healthz says so, writes are
    // refused with the reason, nothing is requeued or run.
    if let Some(why) = store.health().corrupt {
        tracing::error!(%why, "the database failed its integrity check: serving it read-only; restore a backup");
    } else if db.sqlite_path().is_some() {
        // The only server on this file: whatever it ran before is its own.
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
    }
    let agent_tokens = match (agent_tokens.is_empty(), db.sqlite_path()) {
        (false, _) => agent_tokens,
        (true, Some(path)) => vec![secret_file(path, "agent-token")?],
        (true, None) => {
            tracing::warn!("no --agent-token-file: attached rigs' agents cannot connect");
            vec![random_secret()]
        }
    };
    // Attached rigs registered through the API (`POST /v1/rigs`) are data:
    // they come back with the database.
    let mut rigs = rigs;
    for row in store.attached_rigs().await.map_err(|e| e.to_string())? {
        if !rigs.iter().any(|r| r.info().id == row.id) {
            let rig = crate::rig::AttachedRig::new(&row.id, &row.description)
                .map_err(|e| format!("stored rig {}: {e}", row.id))?;
            rigs.push(Arc::new(rig));
        }
    }
    for r in agent::attached_rigs(&rigs) {
        r.set_timing(lease);
        // Reconcile: the epochs handed out and the trial that was out.
        let epoch = store.epoch(r.id()).await.map_err(|e| e.to_string())?;
        let out = store.trial_out(r.id()).await.map_err(|e| e.to_string())?;
        if let Some((trial, e)) = &out {
            tracing::info!(rig = %r.id(), %trial, epoch = e, "a trial was out at the last stop: its result is awaited from the agent");
        }
        r.restore(epoch, out);
        if let Ok(rows) = store.attached_rigs().await {
            if let Some(q) = rows
                .iter()
                .find(|a| a.id == r.id())
                .and_then(|a| a.quarantine.clone())
            {
                tracing::warn!(rig = %r.id(), reason = %q, "rig quarantined (DELETE /v1/rigs/{{id}}/quarantine releases it)");
                r.set_quarantine(Some(q));
            }
        }
    }
    // No write is ever unauthenticated (the service can move hardware):
    // without a configured token the server makes one, owner-only, next to
    // the database, where the client commands find it (`<db>.token`).
    let tokens = match db.sqlite_path() {
        Some(path) if tokens.is_empty() => vec![secret_file(path, "token")?],
        _ => tokens,
    };
    if agent_tokens.iter().any(|a| token_accepted(&tokens, a)) {
        return Err("refusing: an agent token is also a user token; they must differ".into());
    }
    println!("zwidth serving on http://{addr}");
    use std::io::Write;
    let _ = std::io::stdout().flush();
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let running = crate::jobs::Running::default();
    let runners = Arc::new(std::sync::Mutex::new(Vec::new()));
    let start_runner: Arc<dyn Fn(Arc<dyn Rig>) + Send + Sync> = {
        let (store, running, stop_rx, runners) = (
            store.clone(),
            running.clone(),
            stop_rx.clone(),
            runners.clone(),
        );
        let me = me.clone();
        Arc::new(move |r: Arc<dyn Rig>| {
            if api_only && r.attached().is_none() {
                tracing::info!(rig = %r.info().id, "rig accepted; its experiments run on workers (--api-only)");
                return;
            }
            tracing::info!(rig = %r.info().id, parallelism = r.info().parallelism, "rig ready");
            let tasks = crate::jobs::spawn_rig(&store, r, &running, &stop_rx, &me);
            runners
                .lock()
                .unwrap_or_else(|e| e.into_inner())
                .extend(tasks);
        })
    };
    for r in &rigs {
        start_runner(r.clone());
    }
    // This process in the `workers` table, with the rigs it runs.
    let ran: Vec<Arc<dyn Rig>> = rigs
        .iter()
        .filter(|r| !api_only || r.attached().is_some())
        .cloned()
        .collect();
    let announce = tokio::spawn(crate::jobs::worker::announce(
        store.clone(),
        me.clone(),
        crate::jobs::worker::rig_names(&ran),
        running.clone(),
        stop_rx.clone(),
    ));
    let state = AppState {
        store: store.clone(),
        tokens: Arc::new(tokens),
        agent_tokens: Arc::new(agent_tokens),
        allow_origins: Arc::new(allow_origins),
        rigs: Arc::new(std::sync::RwLock::new(rigs)),
        start_runner,
        lease,
        running,
        api_only,
        served: Default::default(),
    };
    let served = tokio::spawn(refresh_served(state.clone(), stop_rx.clone()));
    // On the signal the runners stop at once (the running experiment is
    // interrupted within a trial) while open requests drain.
    let stop_tx = Arc::new(stop_tx);
    let stop = stop_tx.clone();
    accept::serve(
        listener,
        router(state, Duration::from_secs_f64(request_timeout_s)),
        max_connections_per_client,
        async move {
            crate::jobs::worker::shutdown_signal().await;
            tracing::info!("shutting down: stopping the runners, draining requests");
            let _ = stop.send(true);
        },
    )
    .await;
    let _ = stop_tx.send(true);
    let tasks = std::mem::take(&mut *runners.lock().unwrap_or_else(|e| e.into_inner()));
    for r in tasks {
        let _ = r.await;
    }
    let _ = announce.await;
    let _ = served.await;
    let _ = store.worker_gone(&me.id).await;
    // Everything in the WAL goes into the database file: the `.db` alone
    // is then a complete copy.
    match store.close().await {
        Ok(()) => tracing::info!("database checkpointed and closed"),
        Err(e) => tracing::error!(error = %e, "checkpoint at shutdown failed"),
    }
    Ok(())
}

/// The secret in `<db>.<name>`, made (random, owner-only) if missing.
/// Its path is logged, never its content.
pub fn secret_file(db: &std::path::Path, name: &str) -> Result<String, String> {
    let mut p = db.as_os_str().to_owned();
    p.push(format!(".{name}"));
    let path = std::path::PathBuf::from(p);
    if let Ok(text) = std::fs::read_to_string(&path) {
        let t = text.trim().to_string();
        if !t.is_empty() {
            tracing::info!(path = %path.display(), "{name} read");
            return Ok(t);
        }
    }
    let token = random_secret();
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true).create(true).truncate(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    use std::io::Write;
    opts.open(&path)
        .and_then(|mut f| {
            f.write_all(format!("{token}\n").as_bytes())
                .and_then(|_| f.sync_all())
        })
        .map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    tracing::info!(path = %path.display(), "{name} made (owner-only): pass it to the clients that need it");
    Ok(token)
}

/// 24 random bytes in hex.
fn random_secret() -> String {
    use rand::Rng;
    let bytes: [u8; 24] = rand::rng().random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Hold an exclusive lock on `<db>.lock` while serving: a second server
/// on the same database is refused (two would run the same experiments).
fn lock_database(db: &std::path::Path) -> Result<std::fs::File, String> {
    let mut name = db.as_os_str().to_owned();
    name.push(".lock");
    let path = std::path::PathBuf::from(name);
    let f = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(&path)
        .map_err(|e| format!("cannot open {}: {e}", path.display()))?;
    match f.try_lock() {
        Ok(()) => Ok(f),
        Err(std::fs::TryLockError::WouldBlock) => Err(format!(
            "refusing: another zwidth serve is using {} (lock {})",
            db.display(),
            path.display()
        )),
        Err(std::fs::TryLockError::Error(e)) => Err(format!("cannot lock {}: {e}", path.display())),
    }
}
