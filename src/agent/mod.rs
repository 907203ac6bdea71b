//! `zwidth agent`: runs next to a rig's controller and dials out to the
//! server (`GET /v1/agent`, a WebSocket), so a rig behind a lab firewall
//! needs no inbound port. It runs one trial at a time on its [`Driver`],
//! writes each result to an on-disk outbox before sending it and drops it
//! only on the server's `ack`; on a lost link it finishes the trial,
//! starts nothing new, reconnects with back-off and lists what is
//! unacknowledged in its `hello`. Its own limits (the operator's, given on
//! its command line) are checked on every trial; nothing from the server
//! can raise them.

pub mod driver;
pub mod outbox;

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use futures_util::{SinkExt, StreamExt};
use tokio_tungstenite::tungstenite::Message;

use crate::rig::protocol::{
    self, AgentMessage, Capabilities, Measured, RefusalCode, RigState, ServerMessage, StopMode,
    TrialLimits, TrialResult,
};
use crate::zwidth::search::Point;
use crate::zwidth::trial::TrialRequest;
pub use driver::{Driver, SimDriver, StdioDriver};
use outbox::Outbox;

/// The operator's limits: trials beyond them are refused, whatever the
/// server asks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LocalLimits {
    pub max_force_n: f64,
    pub max_k: f64,
    pub max_b: f64,
    /// The controller aborts a trial past this speed (m/s) …
    pub max_speed_m_s: f64,
    /// … or this penetration (m).
    pub max_penetration_m: f64,
}

/// Faults a test injects into the simulated agent (`--faults FILE`).
#[derive(Debug, Clone, Default, PartialEq, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Faults {
    /// Report this peak force (N) instead of the measured one.
    pub report_peak_force_n: Option<f64>,
    /// Send every result twice.
    #[serde(default)]
    pub duplicate_results: bool,
    /// Wait this long (ms) before sending each result.
    #[serde(default)]
    pub delay_result_ms: u64,
    /// Exit (as if killed) halfway through the Nth trial (1-based).
    pub exit_mid_trial: Option<u32>,
    /// Stop itself (SIGSTOP, as if frozen) at the start of the Nth trial,
    /// after taking it: a test resumes it with SIGCONT (unix).
    pub stop_mid_trial: Option<u32>,
    /// Exit (as if killed) after the Nth result is in the outbox, before
    /// it is sent.
    pub exit_before_send: Option<u32>,
}

pub struct AgentConfig {
    pub server: String,
    pub rig: String,
    pub agent: String,
    pub token: String,
    /// Whom a `wss://` server may be (`tls::client_config`).
    pub tls: Arc<rustls::ClientConfig>,
    pub outbox: std::path::PathBuf,
    pub limits: LocalLimits,
    pub faults: Faults,
}

/// A finished (or aborted) trial, from the driver thread.
enum Done {
    Result(TrialResult),
    Aborted {
        epoch: u64,
        trial_id: String,
        code: RefusalCode,
        why: String,
    },
}

/// Set by the operator's local reset (SIGUSR1), taken at the next beat.
static RESET: AtomicBool = AtomicBool::new(false);

/// What survives a reconnect.
struct Agent {
    cfg: AgentConfig,
    boot: String,
    driver: Arc<Mutex<Box<dyn Driver>>>,
    capabilities: Capabilities,
    outbox: Outbox,
    state: RigState,
    last_epoch: u64,
    /// The running trial: id and its cancel flag.
    running: Option<(String, Arc<AtomicBool>)>,
    /// Stop after the running trial (a deferred stop).
    disarm_after: bool,
    trials_started: u32,
    results_kept: u32,
    done_tx: tokio::sync::mpsc::UnboundedSender<Done>,
}

/// Run until the process is stopped. Err: the agent cannot start (exit 2).
pub async fn run(cfg: AgentConfig, driver: Box<dyn Driver>) -> Result<(), String> {
    let capabilities = driver.capabilities();
    capabilities
        .validate()
        .map_err(|e| format!("the rig's capabilities: {e}"))?;
    let outbox = Outbox::open(&cfg.outbox)?;
    let (done_tx, mut done_rx) = tokio::sync::mpsc::unbounded_channel();
    let mut agent = Agent {
        boot: uuid::Uuid::now_v7().to_string(),
        cfg,
        driver: Arc::new(Mutex::new(driver)),
        capabilities,
        outbox,
        state: RigState::Armed,
        last_epoch: 0,
        running: None,
        disarm_after: false,
        trials_started: 0,
        results_kept: 0,
        done_tx,
    };
    // The operator's local reset (SIGUSR1): re-arm after a stop or halt.
    #[cfg(unix)]
    tokio::spawn(async {
        use tokio::signal::unix::{signal, SignalKind};
        if let Ok(mut s) = signal(SignalKind::user_defined1()) {
            while s.recv().await.is_some() {
                RESET.store(true, Ordering::Relaxed);
            }
        }
    });
    let mut wait = Duration::from_millis(100);
    loop {
        let started = Instant::now();
        match agent.session(&mut done_rx).await {
            Ok(()) => {}
            Err(why) => eprintln!("zwidth agent: {why}; reconnecting in {wait:?}"),
        }
        if started.elapsed() > Duration::from_secs(10) {
            wait = Duration::from_millis(100);
        }
        // Results finished meanwhile go to the outbox (sent in `hello`).
        while let Ok(d) = done_rx.try_recv() {
            agent.finished(d);
        }
        tokio::time::sleep(wait).await;
        wait = (wait * 2).min(Duration::from_secs(5));
    }
}

impl Agent {
    fn url(&self) -> String {
        let base = self.cfg.server.trim_end_matches('/');
        let ws = if let Some(rest) = base.strip_prefix("https://") {
            format!("wss://{rest}")
        } else if let Some(rest) = base.strip_prefix("http://") {
            format!("ws://{rest}")
        } else {
            base.to_string()
        };
        format!("{ws}/v1/agent")
    }

    /// A finished trial: into the outbox (it is sent from there).
    fn finished(&mut self, d: Done) -> Done {
        if let Done::Result(r) = &d {
            if let Err(e) = self.outbox.put(r) {
                eprintln!("zwidth agent: the outbox cannot be written: {e}");
            }
            self.results_kept += 1;
            if self.cfg.faults.exit_before_send == Some(self.results_kept) {
                std::process::exit(137);
            }
        }
        self.running = None;
        if self.disarm_after {
            self.disarm_after = false;
            if self.state.armed() {
                self.state = RigState::Disarmed;
            }
        }
        d
    }

    /// One connection, until it ends (Err: why).
    async fn session(
        &mut self,
        done_rx: &mut tokio::sync::mpsc::UnboundedReceiver<Done>,
    ) -> Result<(), String> {
        use tokio_tungstenite::tungstenite::client::IntoClientRequest;
        let mut req = self
            .url()
            .into_client_request()
            .map_err(|e| format!("--server {}: {e}", self.cfg.server))?;
        req.headers_mut().insert(
            "authorization",
            format!("Bearer {}", self.cfg.token)
                .parse()
                .map_err(|_| "the token is not a valid header value".to_string())?,
        );
        // A link that swallows the handshake (a black hole) is given up.
        let (mut ws, _) = tokio::time::timeout(
            Duration::from_secs(10),
            // No Nagle delay on small messages (docs/rigs.md, figures).
            tokio_tungstenite::connect_async_tls_with_config(
                req,
                None,
                true,
                Some(tokio_tungstenite::Connector::Rustls(self.cfg.tls.clone())),
            ),
        )
        .await
        .map_err(|_| format!("no answer from {} within 10 s", self.url()))?
        .map_err(|e| format!("cannot connect to {}: {e}", self.url()))?;
        let mut seq = 0u64;
        let mut send = |msg: &AgentMessage| {
            seq += 1;
            Message::Text(protocol::encode(seq, msg).into())
        };
        let hello = AgentMessage::Hello {
            rig: self.cfg.rig.clone(),
            agent: self.cfg.agent.clone(),
            boot: self.boot.clone(),
            last_epoch: self.last_epoch,
            running: self.running.as_ref().map(|(id, _)| id.clone()),
            unacked: self.outbox.all(),
            state: self.state.clone(),
            capabilities: self.capabilities.clone(),
        };
        ws.send(send(&hello)).await.map_err(|e| e.to_string())?;
        let (epoch, heartbeat_ms, ttl_ms) = match ws.next().await {
            Some(Ok(Message::Text(t))) => match protocol::decode::<ServerMessage>(&t) {
                Ok(env) => match env.body {
                    ServerMessage::Welcome {
                        epoch,
                        heartbeat_ms,
                        ttl_ms,
                    } => (epoch, heartbeat_ms, ttl_ms),
                    ServerMessage::Error { message } => {
                        return Err(format!("the server refused the session: {message}"))
                    }
                    other => return Err(format!("expected welcome, got {other:?}")),
                },
                Err(e) => return Err(e),
            },
            other => return Err(format!("expected welcome, got {other:?}")),
        };
        self.last_epoch = epoch;
        eprintln!(
            "zwidth agent: rig {} connected to {}, epoch {epoch}",
            self.cfg.rig,
            self.url()
        );
        let mut beat = tokio::time::interval(Duration::from_millis(heartbeat_ms.max(10)));
        let mut last_heard = Instant::now();
        loop {
            tokio::select! {
                _ = beat.tick() => {
                    if last_heard.elapsed() > Duration::from_millis(ttl_ms) {
                        return Err(format!("nothing heard from the server for {ttl_ms} ms"));
                    }
                    if self.running.is_none() && RESET.swap(false, Ordering::Relaxed) {
                        eprintln!("zwidth agent: reset by the operator: armed");
                        self.state = RigState::Armed;
                    }
                    let hb = AgentMessage::Heartbeat { epoch, state: self.state.clone() };
                    ws.send(send(&hb)).await.map_err(|e| e.to_string())?;
                }
                d = done_rx.recv() => {
                    let Some(d) = d else { return Err("the driver thread ended".into()) };
                    let state_before = self.state.clone();
                    let msg = match self.finished(d) {
                        Done::Result(r) => {
                            if self.cfg.faults.delay_result_ms > 0 {
                                tokio::time::sleep(Duration::from_millis(self.cfg.faults.delay_result_ms)).await;
                            }
                            let m = AgentMessage::Result(r);
                            if self.cfg.faults.duplicate_results {
                                ws.send(send(&m)).await.map_err(|e| e.to_string())?;
                            }
                            m
                        }
                        Done::Aborted { epoch: e, trial_id, code, why } => AgentMessage::Refused {
                            epoch: e,
                            trial_id,
                            code,
                            reason: why,
                        },
                    };
                    ws.send(send(&msg)).await.map_err(|e| e.to_string())?;
                    if self.state != state_before {
                        let hb = AgentMessage::Heartbeat { epoch, state: self.state.clone() };
                        ws.send(send(&hb)).await.map_err(|e| e.to_string())?;
                    }
                }
                incoming = ws.next() => {
                    let text = match incoming {
                        Some(Ok(Message::Text(t))) => t.to_string(),
                        Some(Ok(Message::Close(_))) | None => return Err("the server closed the link".into()),
                        Some(Ok(_)) => { last_heard = Instant::now(); continue }
                        Some(Err(e)) => return Err(format!("the link failed: {e}")),
                    };
                    last_heard = Instant::now();
                    let env = protocol::decode::<ServerMessage>(&text)?;
                    let reply = self.handle(epoch, env.body)?;
                    for m in reply {
                        ws.send(send(&m)).await.map_err(|e| e.to_string())?;
                    }
                }
            }
        }
    }

    /// A server message; what to answer (Err: the session ends).
    fn handle(&mut self, epoch: u64, msg: ServerMessage) -> Result<Vec<AgentMessage>, String> {
        match msg {
            ServerMessage::Trial {
                epoch: e,
                trial_id,
                expires_in_ms,
                request,
                limits,
            } => {
                let refuse = |code, reason: String| {
                    Ok(vec![AgentMessage::Refused {
                        epoch: e,
                        trial_id: trial_id.clone(),
                        code,
                        reason,
                    }])
                };
                let received = Instant::now();
                if e != epoch {
                    return refuse(
                        RefusalCode::StaleEpoch,
                        format!("sent under epoch {e}; this session's is {epoch}"),
                    );
                }
                if expires_in_ms == 0 {
                    return refuse(RefusalCode::Expired, "expired on arrival".into());
                }
                if !self.state.armed() {
                    return refuse(RefusalCode::NotArmed, self.state.describe());
                }
                if self.running.is_some() {
                    return refuse(RefusalCode::Busy, "another trial is running".into());
                }
                if let Err(why) = self.within_limits(&request, &limits) {
                    return refuse(RefusalCode::BeyondLimits, why);
                }
                let cancel = Arc::new(AtomicBool::new(false));
                self.running = Some((trial_id.clone(), cancel.clone()));
                self.trials_started += 1;
                let exit_now = self.cfg.faults.exit_mid_trial == Some(self.trials_started);
                let stop_now = self.cfg.faults.stop_mid_trial == Some(self.trials_started);
                let driver = self.driver.clone();
                let done = self.done_tx.clone();
                let report_force = self.cfg.faults.report_peak_force_n;
                let own = self.cfg.limits;
                let deadline = received
                    .checked_add(Duration::from_millis(expires_in_ms.min(86_400_000)))
                    .unwrap_or(received);
                std::thread::spawn(move || {
                    if Instant::now() > deadline {
                        let _ = done.send(Done::Aborted {
                            epoch: e,
                            trial_id,
                            code: RefusalCode::Expired,
                            why: "expired before it started".into(),
                        });
                        return;
                    }
                    // The operator's limits bound the server's: never raised.
                    let limits = TrialLimits {
                        force_limit_n: limits.force_limit_n.min(own.max_force_n),
                        abort_speed_m_s: limits.abort_speed_m_s.min(own.max_speed_m_s),
                        abort_penetration_m: limits.abort_penetration_m.min(own.max_penetration_m),
                    };
                    let mut d = driver.lock().unwrap_or_else(|e| e.into_inner());
                    if exit_now {
                        // The fault: killed halfway through the trial.
                        std::thread::sleep(Duration::from_millis(50));
                        std::process::exit(137);
                    }
                    if stop_now {
                        // The fault: frozen with the trial taken (the
                        // whole process, until a SIGCONT).
                        let _ = std::process::Command::new("kill")
                            .args(["-STOP", &std::process::id().to_string()])
                            .status();
                    }
                    let out = d.run(&request, &limits, &cancel);
                    let msg = match out {
                        Ok((point, mut measured)) => {
                            if let Some(f) = report_force {
                                measured.peak_force_n = f;
                            }
                            Done::Result(result(e, trial_id, point, measured))
                        }
                        Err(why) => Done::Aborted {
                            epoch: e,
                            trial_id,
                            code: if cancel.load(Ordering::Relaxed) {
                                RefusalCode::Aborted
                            } else {
                                RefusalCode::Failed
                            },
                            why,
                        },
                    };
                    let _ = done.send(msg);
                });
                Ok(vec![])
            }
            ServerMessage::Ack { epoch: e, trial_id } => {
                self.outbox.remove(&trial_id, e);
                Ok(vec![])
            }
            ServerMessage::CancelTrial { trial_id, .. } => {
                if let Some((id, cancel)) = &self.running {
                    if *id == trial_id {
                        cancel.store(true, Ordering::Relaxed);
                    }
                }
                Ok(vec![])
            }
            ServerMessage::Stop { mode, .. } => {
                match mode {
                    StopMode::Deferred => {
                        if self.running.is_some() {
                            self.disarm_after = true;
                        } else if self.state.armed() {
                            self.state = RigState::Disarmed;
                        }
                    }
                    StopMode::Abort | StopMode::Halt => {
                        if let Some((_, cancel)) = &self.running {
                            cancel.store(true, Ordering::Relaxed);
                        }
                        self.state = if mode == StopMode::Halt {
                            RigState::EStop
                        } else {
                            RigState::Disarmed
                        };
                    }
                }
                Ok(vec![AgentMessage::Heartbeat {
                    epoch,
                    state: self.state.clone(),
                }])
            }
            ServerMessage::Error { message } => Err(format!("the server: {message}")),
            ServerMessage::Welcome { .. } => Err("a second welcome".into()),
        }
    }

    /// The operator's limits against a trial.
    fn within_limits(&self, r: &TrialRequest, limits: &TrialLimits) -> Result<(), String> {
        let own = self.cfg.limits;
        if r.k > own.max_k {
            return Err(format!(
                "K = {} N/m is above this rig's limit {} N/m",
                r.k, own.max_k
            ));
        }
        if r.b.abs() > own.max_b {
            return Err(format!(
                "|B| = {} N·s/m is above this rig's limit {} N·s/m",
                r.b.abs(),
                own.max_b
            ));
        }
        if let Some(f) = r.scene.device.force_limit {
            if f > own.max_force_n {
                return Err(format!(
                    "the scene's force limit {f} N is above this rig's limit {} N",
                    own.max_force_n
                ));
            }
        }
        if !(limits.force_limit_n.is_finite() && limits.force_limit_n > 0.0) {
            return Err(format!(
                "force limit {} N: must be > 0",
                limits.force_limit_n
            ));
        }
        Ok(())
    }
}

fn result(epoch: u64, trial_id: String, point: Point, measured: Measured) -> TrialResult {
    TrialResult {
        epoch,
        trial_id,
        point,
        measured,
    }
}
