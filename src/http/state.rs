//! What every handler shares ([`AppState`]): the store, the tokens, the
//! rigs and the running experiments, and which rigs live workers run.

use std::sync::Arc;

use super::problem::Problem;
use crate::rig::Rig;
use crate::store::Store;

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
    /// Every read needs a token too (`--reads private`, the default beyond
    /// loopback): `guard::host_and_reads`.
    pub private_reads: bool,
    /// Host names this server answers to besides loopback names and IP
    /// addresses (`--host`): `guard::host_allowed`.
    pub hosts: Arc<Vec<String>>,
    /// Served over TLS: the dashboard's cookie is `Secure`.
    pub tls: bool,
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
    pub(crate) fn rig(&self, id: &str) -> Option<Arc<dyn Rig>> {
        self.rig_list().into_iter().find(|r| r.info().id == id)
    }

    /// Every rig, the default first.
    pub fn rig_list(&self) -> Vec<Arc<dyn Rig>> {
        self.rigs.read().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// A storage error as a problem; a corrupt page met on the way is
    /// remembered, so writes are refused from then on.
    pub(crate) fn fail(&self, e: sqlx::Error) -> Problem {
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
            private_reads: false,
            hosts: Arc::new(Vec::new()),
            tls: false,
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

    pub(crate) fn rig_ids(&self) -> String {
        self.rig_list()
            .iter()
            .map(|r| r.info().id.clone())
            .collect::<Vec<_>>()
            .join(", ")
    }
}

/// 24 random bytes in hex.
pub(crate) fn random_secret() -> String {
    use rand::Rng;
    let bytes: [u8; 24] = rand::rng().random();
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
