//! `zwidth serve`: open the store, requeue interrupted work, bind, start
//! one runner per rig, serve until a signal, and stop cleanly; the secrets
//! beside the database and the lock that keeps a second server off it.

use std::sync::Arc;
use std::time::Duration;

use super::guard::token_accepted;
use super::routes::router;
use super::state::{random_secret, refresh_served, AppState};
use super::{accept, agent};
use crate::rig::Rig;
use crate::store::Store;

/// How `serve` runs.
pub struct ServeConfig {
    pub db: crate::store::Location,
    pub bind: String,
    pub tokens: Vec<String>,
    /// Agent tokens; empty: the one in `<db>.agent-token` (made on first
    /// start; with PostgreSQL, none: agents need `--agent-token-file` or
    /// `ZWIDTH_AGENT_TOKENS`).
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
    /// Serve HTTPS and WSS with this config (`tls::server_config`).
    pub tls: Option<Arc<rustls::ServerConfig>>,
    /// Reads need the token too: Some(true) private, Some(false) public,
    /// None: private unless every bound address is loopback.
    pub private_reads: Option<bool>,
    /// Host names the server answers to besides loopback names and IP
    /// addresses (`--host`).
    pub hosts: Vec<String>,
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
        tls,
        private_reads,
        hosts,
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
    // Beyond loopback, reads are private unless the lab says otherwise.
    let private_reads = private_reads.unwrap_or(!addrs.iter().all(|a| a.ip().is_loopback()));
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
            tracing::warn!("no --agent-token-file or ZWIDTH_AGENT_TOKENS: attached rigs' agents cannot connect");
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
    let scheme = if tls.is_some() { "https" } else { "http" };
    println!("zwidth serving on {scheme}://{addr}");
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
        private_reads,
        hosts: Arc::new(hosts),
        tls: tls.is_some(),
    };
    if private_reads {
        tracing::info!(
            "private reads: every read needs the token (the dashboard asks for it once)"
        );
    }
    let served = tokio::spawn(refresh_served(state.clone(), stop_rx.clone()));
    // On the signal the runners stop at once (the running experiment is
    // interrupted within a trial) while open requests drain.
    let stop_tx = Arc::new(stop_tx);
    let stop = stop_tx.clone();
    accept::serve(
        listener,
        router(state, Duration::from_secs_f64(request_timeout_s)),
        max_connections_per_client,
        tls.map(tokio_rustls::TlsAcceptor::from),
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
/// Its path is logged, never its content. The file is only ever a
/// regular file of its own: a symbolic link there refuses the start (a
/// link could send the new secret anywhere, or read one from anywhere),
/// and so does a file that group or others may read or write (the secret
/// is no longer one), with how to fix it. A new file is created with
/// `O_EXCL`, mode 0600, so no other file or mode is ever written through.
pub fn secret_file(db: &std::path::Path, name: &str) -> Result<String, String> {
    let mut p = db.as_os_str().to_owned();
    p.push(format!(".{name}"));
    let path = std::path::PathBuf::from(p);
    match std::fs::symlink_metadata(&path) {
        Ok(meta) => {
            check_secret_file(&path, &meta)?;
            let text = read_no_follow(&path)
                .map_err(|e| format!("cannot read {}: {e}", path.display()))?;
            let t = text.trim().to_string();
            if !t.is_empty() {
                tracing::info!(path = %path.display(), "{name} read");
                return Ok(t);
            }
            // An empty owner-only file (e.g. made by `touch` and
            // `chmod 600`): the secret goes into it.
            write_secret(&path, false, name)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => write_secret(&path, true, name),
        Err(e) => Err(format!("cannot read {}: {e}", path.display())),
    }
}

/// Refuse a secret file that is not a regular file, or that group or
/// others may read or write.
fn check_secret_file(path: &std::path::Path, meta: &std::fs::Metadata) -> Result<(), String> {
    let shown = path.display();
    if meta.file_type().is_symlink() {
        return Err(format!(
            "refusing: {shown} is a symbolic link; a secret file must be a regular file \
             (replace the link by the file it points to, with mode 0600)"
        ));
    }
    if !meta.is_file() {
        return Err(format!("refusing: {shown} is not a regular file"));
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let mode = meta.permissions().mode() & 0o777;
        if mode & 0o077 != 0 {
            return Err(format!(
                "refusing: {shown} has mode {mode:04o}: group or others may read it, so its \
                 secret is not one; run `chmod 600 {shown}` (and make a new secret if others \
                 could have read it: remove the file and start again)"
            ));
        }
    }
    Ok(())
}

/// Open flags that never follow a symbolic link at the last component.
#[cfg(unix)]
fn no_follow(opts: &mut std::fs::OpenOptions) {
    use std::os::unix::fs::OpenOptionsExt;
    opts.custom_flags(libc::O_NOFOLLOW);
}
#[cfg(not(unix))]
fn no_follow(_: &mut std::fs::OpenOptions) {}

fn read_no_follow(path: &std::path::Path) -> std::io::Result<String> {
    use std::io::Read;
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    no_follow(&mut opts);
    let mut text = String::new();
    opts.open(path)?.read_to_string(&mut text)?;
    Ok(text)
}

/// Write a new random secret to `path`: a new file (`O_EXCL`, mode 0600),
/// or the existing empty one, never through a link.
fn write_secret(path: &std::path::Path, new: bool, name: &str) -> Result<String, String> {
    let token = random_secret();
    put_secret(path, new, &token).map_err(|e| format!("cannot write {}: {e}", path.display()))?;
    tracing::info!(path = %path.display(), "{name} made (owner-only): pass it to the clients that need it");
    Ok(token)
}

/// Write `secret` and a newline to `path`, owner-only (mode 0600), never
/// through a symbolic link: a new file (`O_EXCL`: an existing one is an
/// error) when `new`, else the existing one, truncated.
pub fn put_secret(path: &std::path::Path, new: bool, secret: &str) -> std::io::Result<()> {
    let mut opts = std::fs::OpenOptions::new();
    opts.write(true);
    if new {
        opts.create_new(true);
    } else {
        opts.truncate(true);
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.mode(0o600);
    }
    no_follow(&mut opts);
    use std::io::Write;
    let mut f = opts.open(path)?;
    f.write_all(format!("{secret}\n").as_bytes())?;
    f.sync_all()
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

#[cfg(all(test, unix))]
mod tests {
    use super::secret_file;
    use std::os::unix::fs::PermissionsExt;

    fn dir(tag: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("zwidth-secret-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn mode(p: &std::path::Path) -> u32 {
        std::fs::symlink_metadata(p).unwrap().permissions().mode() & 0o777
    }

    #[test]
    fn a_new_secret_file_is_owner_only_and_read_back() {
        let d = dir("new");
        let db = d.join("z.db");
        let made = secret_file(&db, "token").unwrap();
        assert_eq!(made.len(), 48, "24 random bytes in hex");
        assert_eq!(mode(&d.join("z.db.token")), 0o600);
        assert_eq!(secret_file(&db, "token").unwrap(), made);
        // Issue 45 item 7: `touch z.db.token` (mode 0644 under the usual
        // umask) then serve wrote the token into it and said "owner-only".
        let loose = d.join("y.db.token");
        std::fs::write(&loose, "").unwrap();
        std::fs::set_permissions(&loose, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = secret_file(&d.join("y.db"), "token").unwrap_err();
        assert!(e.contains("mode 0644") && e.contains("chmod 600"), "{e}");
        assert_eq!(
            std::fs::read_to_string(&loose).unwrap(),
            "",
            "nothing written"
        );
        // Fixed as the message says: the secret goes into the empty file.
        std::fs::set_permissions(&loose, std::fs::Permissions::from_mode(0o600)).unwrap();
        let t = secret_file(&d.join("y.db"), "token").unwrap();
        assert_eq!(std::fs::read_to_string(&loose).unwrap().trim(), t);
        // A loose file with a secret in it is refused too (group-readable).
        std::fs::set_permissions(&loose, std::fs::Permissions::from_mode(0o640)).unwrap();
        assert!(secret_file(&d.join("y.db"), "token")
            .unwrap_err()
            .contains("0640"));
        let _ = std::fs::remove_dir_all(&d);
    }

    #[test]
    fn a_secret_file_is_never_a_symbolic_link() {
        let d = dir("link");
        let target = d.join("elsewhere");
        // A dangling link: following it would create `elsewhere`.
        std::os::unix::fs::symlink(&target, d.join("z.db.token")).unwrap();
        let e = secret_file(&d.join("z.db"), "token").unwrap_err();
        assert!(e.contains("symbolic link"), "{e}");
        assert!(!target.exists(), "nothing created through the link");
        // A link to an owner-only file with a secret: not read either.
        std::fs::write(&target, "s3cret-from-elsewhere\n").unwrap();
        std::fs::set_permissions(&target, std::fs::Permissions::from_mode(0o600)).unwrap();
        let e = secret_file(&d.join("z.db"), "token").unwrap_err();
        assert!(e.contains("symbolic link") && !e.contains("s3cret"), "{e}");
        // A directory in its place.
        std::fs::create_dir(d.join("w.db.token")).unwrap();
        let e = secret_file(&d.join("w.db"), "token").unwrap_err();
        assert!(e.contains("not a regular file"), "{e}");
        let _ = std::fs::remove_dir_all(&d);
    }
}
