//! An attached rig: hardware behind a `zwidth agent` that dialled in over
//! `GET /v1/agent`. The searches run here, on one thread (hardware runs one
//! trial at a time); each trial goes to the agent under the session's
//! epoch and its result comes back through the WebSocket handler
//! (`http::agent`), which stores it before acknowledging it. While the rig
//! cannot take a trial (no agent, lost contact, disarmed, locked, e-stop,
//! fault, quarantine) the experiment waits, saying why; nothing fails.

use serde::Serialize;
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::time::Duration;

use super::base::{check_id, rig_pool, Rig, RigInfo};
use super::lease::{Lease, Refusal, Timing};
use super::protocol::{
    parse_trial_id, trial_id, Capabilities, DspIdentity, EstimatorCheck, RigState, ServerMessage,
    TrialLimits, TrialResult,
};
use crate::clock::now_ms;
use crate::error::SpecError;
use crate::zwidth::control::RunControl;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::Point;
use crate::zwidth::settings::Method;
use crate::zwidth::trial::{TrialBackend, TrialRequest};

/// Where the live session's messages go (the WebSocket handler's queue).
pub type Outbox = tokio::sync::mpsc::UnboundedSender<ServerMessage>;

pub struct AttachedRig {
    id: String,
    description: String,
    pool: rayon::ThreadPool,
    shared: Arc<Shared>,
}

struct Shared {
    inner: Mutex<Inner>,
    changed: Condvar,
}

/// The agent as its last `hello` described it.
#[derive(Debug, Clone)]
struct Agent {
    agent: String,
    boot: String,
    capabilities: Capabilities,
}

#[derive(Default)]
struct Inner {
    lease: Lease,
    /// The live session's epoch and queue.
    outbox: Option<(u64, Outbox)>,
    agent: Option<Agent>,
    pending: Option<Pending>,
}

/// The trial the search waits for.
struct Pending {
    trial_id: String,
    experiment: String,
    scope: u32,
    request: TrialRequest,
    /// The committed result, once in.
    point: Option<Point>,
    /// Why the experiment cannot go on (the agent refused the trial as
    /// beyond its own limits).
    failed: Option<String>,
}

/// An attached rig's session, as `GET /v1/rigs` shows it.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct AttachedView {
    /// A session is open and was heard within the heartbeat TTL.
    pub connected: bool,
    /// A session is open but silent past the TTL (nothing new is sent).
    pub lost_contact: bool,
    /// When the agent was last heard (unix ms).
    pub last_heartbeat_ms: Option<i64>,
    /// The live session's epoch, else the highest handed out.
    pub epoch: u64,
    pub agent: Option<String>,
    pub boot: Option<String>,
    /// The rig's state as its agent last reported it.
    pub state: Option<RigState>,
    /// What the agent advertised in its last `hello`.
    pub capabilities: Option<Capabilities>,
    /// Whether the rig runs this build's estimators to the bit (from its
    /// capabilities' `dsp`): a mismatch names each kind with both
    /// fingerprints.
    pub estimators: Option<EstimatorCheck>,
    /// Why the rig takes no trials until released (`DELETE
    /// /v1/rigs/{id}/quarantine`).
    pub quarantine: Option<String>,
    /// The trial out on the rig, if any.
    pub trial_out: Option<String>,
    /// Why nothing can be sent now, if nothing can.
    pub waiting: Option<String>,
}

/// What the handler does with a result.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Store it for `experiment` (map `scope`), then [`AttachedRig::deliver`].
    Store { experiment: String, scope: u32 },
    /// Audit it, never store it: why.
    Refuse(String),
}

impl AttachedRig {
    pub fn new(id: &str, description: &str) -> Result<Self, SpecError> {
        check_id("rigs", id)?;
        Ok(Self {
            id: id.into(),
            description: description.into(),
            pool: rig_pool(id, 1)?,
            shared: Arc::new(Shared {
                inner: Mutex::new(Inner::default()),
                changed: Condvar::new(),
            }),
        })
    }

    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.shared.lock()
    }

    pub fn id(&self) -> &str {
        &self.id
    }

    pub fn timing(&self) -> Timing {
        self.lock().lease.timing
    }

    pub fn set_timing(&self, timing: Timing) {
        self.lock().lease.timing = timing;
    }

    /// After a restart: the highest epoch handed out, and the trial that
    /// was out and its epoch (from the database).
    pub fn restore(&self, highest_epoch: u64, out: Option<(String, u64)>) {
        let mut g = self.lock();
        g.lease.highest_epoch = highest_epoch;
        g.lease.outstanding = out.map(|(trial_id, epoch)| super::lease::Outstanding {
            trial_id,
            sent_epoch: Some(epoch),
            sent_ms: now_ms(),
            retry_at_ms: 0,
        });
    }

    /// The rig's window closed (Some(why)) or open (None): nothing new is
    /// sent while it is closed.
    pub fn set_window_closed(&self, why: Option<String>) {
        let mut g = self.lock();
        if g.lease.window_closed != why {
            g.lease.window_closed = why;
            drop(g);
            self.shared.changed.notify_all();
        }
    }

    /// Quarantine (Some(why)) or release (None); the caller stores it.
    pub fn set_quarantine(&self, why: Option<String>) {
        self.lock().lease.quarantine = why;
        self.shared.changed.notify_all();
    }

    /// Open a session under `epoch` for the agent of a valid `hello`
    /// (Err: why it is refused: another live session). Its results listed
    /// as unacknowledged are then checked, then [`AttachedRig::resume`].
    pub fn open(
        &self,
        epoch: u64,
        agent: &str,
        boot: &str,
        state: RigState,
        capabilities: Capabilities,
    ) -> Result<(), String> {
        let mut g = self.lock();
        g.lease.open(epoch, agent, boot, state, now_ms())?;
        g.agent = Some(Agent {
            agent: agent.into(),
            boot: boot.into(),
            capabilities,
        });
        Ok(())
    }

    /// After `hello`: the session takes trials from `outbox`; a trial out
    /// that the agent is not `running` is sent again.
    pub fn resume(&self, epoch: u64, running: Option<&str>, outbox: Outbox) {
        let mut g = self.lock();
        if g.lease.session.as_ref().is_some_and(|s| s.epoch == epoch) {
            g.lease.resume(running);
            g.outbox = Some((epoch, outbox));
        }
        drop(g);
        self.shared.changed.notify_all();
    }

    /// A message of the session under `epoch` arrived (with the rig's state
    /// when it says). False: not the live session's epoch.
    pub fn heard(&self, epoch: u64, state: Option<RigState>) -> bool {
        let ok = self.lock().lease.heard(epoch, state, now_ms());
        self.shared.changed.notify_all();
        ok
    }

    /// Time passes (called by the session's timer and the waiting search):
    /// past TTL + grace the live session is fenced off and its queue
    /// dropped, which closes its WebSocket.
    pub fn tick(&self) {
        let mut g = self.lock();
        tick(&mut g);
    }

    /// The session's link closed.
    pub fn closed(&self, epoch: u64) {
        let mut g = self.lock();
        g.lease.closed(epoch, now_ms());
        if g.outbox.as_ref().is_some_and(|(e, _)| *e == epoch) {
            g.outbox = None;
        }
        drop(g);
        self.shared.changed.notify_all();
    }

    /// Whether a result may be stored, and for which experiment. A
    /// measured peak force above what the rig advertised quarantines it
    /// (the trial waits to be sent again once released).
    pub fn check_result(&self, r: &TrialResult) -> Verdict {
        let mut g = self.lock();
        if let Err(refusal) = g.lease.check_result(r.epoch, &r.trial_id) {
            return Verdict::Refuse(refusal.describe(r.epoch));
        }
        // The search waiting for it, or (after a server restart, before the
        // search has asked again) the trial out as the database recorded it.
        let pending = g.pending.as_ref().filter(|p| p.trial_id == r.trial_id);
        let (experiment, scope, k, b) = match pending {
            Some(p) => (p.experiment.clone(), p.scope, p.request.k, p.request.b),
            None => match parse_trial_id(&r.trial_id) {
                Some((e, s, k, b)) => (e.to_string(), s, k, b),
                None => return Verdict::Refuse(Refusal::NotSent.describe(r.epoch)),
            },
        };
        // Exactly a verdict of the trial asked (its criterion and engine);
        // after a restart, before the search asks again, of some trial.
        let shape = match pending {
            Some(p) => p.request.check_verdict(&r.point),
            None => any_verdict_shape(&r.point),
        };
        let advertised = g
            .agent
            .as_ref()
            .map_or(f64::INFINITY, |a| a.capabilities.peak_force_n);
        let measured = r.measured.peak_force_n;
        if !measured.is_finite() || measured > advertised {
            let why = format!(
                "trial {} measured a peak force of {measured} N; the rig advertises at most {advertised} N",
                r.trial_id
            );
            g.lease.quarantine = Some(why.clone());
            g.lease.refused(r.epoch, &r.trial_id, now_ms());
            return Verdict::Refuse(format!("quarantined: {why}"));
        }
        let wrong = if r.point.k.to_bits() != k.to_bits() || r.point.b.to_bits() != b.to_bits() {
            Some(format!(
                "the result's (K, B) = ({}, {}) is not its trial's ({k}, {b})",
                r.point.k, r.point.b
            ))
        } else if let Err(e) = shape {
            Some(format!(
                "the result is not a verdict of its trial: point.{e}"
            ))
        } else {
            [
                ("peak_speed_m_s", r.measured.peak_speed_m_s),
                ("penetration_m", r.measured.penetration_m),
                ("peak_force_n", measured),
            ]
            .into_iter()
            .find(|(_, v)| !(v.is_finite() && *v >= 0.0))
            .map(|(name, v)| format!("measured.{name} = {v} is not allowed: a finite number ≥ 0"))
        };
        if let Some(why) = wrong {
            // A rig that answers another wall than it was asked, or with
            // another kind of verdict, cannot be trusted with this one
            // either: the experiment fails saying so.
            g.lease.done(&r.trial_id);
            if let Some(p) = g.pending.as_mut().filter(|p| p.trial_id == r.trial_id) {
                p.failed = Some(format!("rig {}: {why}", self.id));
            }
            self.shared.changed.notify_all();
            return Verdict::Refuse(why);
        }
        Verdict::Store { experiment, scope }
    }

    /// The quarantine reason, if the rig is quarantined.
    pub fn quarantine(&self) -> Option<String> {
        self.lock().lease.quarantine.clone()
    }

    /// The result of `trial_id` is committed: hand it to the waiting search.
    pub fn deliver(&self, trial_id: &str, point: Point) {
        let mut g = self.lock();
        g.lease.done(trial_id);
        if let Some(p) = g.pending.as_mut().filter(|p| p.trial_id == trial_id) {
            p.point = Some(point);
        }
        drop(g);
        self.shared.changed.notify_all();
    }

    /// The agent refused `trial_id` sent under `epoch`. `transient`: it
    /// could not take it now (stale epoch, expired, not armed, busy), so it
    /// is sent again; otherwise (beyond the agent's own limits) the
    /// experiment fails with the agent's reason.
    pub fn refused(&self, epoch: u64, trial_id: &str, transient: bool, reason: &str) {
        let mut g = self.lock();
        if g.lease.check_result(epoch, trial_id).is_err() {
            return;
        }
        g.lease.refused(epoch, trial_id, now_ms());
        if !transient {
            if let Some(p) = g.pending.as_mut().filter(|p| p.trial_id == trial_id) {
                p.failed = Some(format!("rig {} refused the trial: {reason}", self.id));
            }
        }
        drop(g);
        self.shared.changed.notify_all();
    }

    /// Send a stop to the live session (false: none is open).
    pub fn stop(&self, mode: super::protocol::StopMode) -> bool {
        let g = self.lock();
        match &g.outbox {
            Some((epoch, tx)) => tx
                .send(ServerMessage::Stop {
                    epoch: *epoch,
                    mode,
                })
                .is_ok(),
            None => false,
        }
    }

    /// Whether its agent's session is live (what `view().connected` says,
    /// without building the view).
    pub fn connected(&self) -> bool {
        self.lock().lease.connected(now_ms())
    }

    pub fn view(&self) -> AttachedView {
        let g = self.lock();
        let now = now_ms();
        let s = g.lease.session.as_ref();
        let connected = g.lease.connected(now);
        AttachedView {
            connected,
            lost_contact: s.is_some() && !connected,
            last_heartbeat_ms: s.map(|s| s.last_heard_ms),
            epoch: s.map_or(g.lease.highest_epoch, |s| s.epoch),
            agent: g.agent.as_ref().map(|a| a.agent.clone()),
            boot: g.agent.as_ref().map(|a| a.boot.clone()),
            state: s.map(|s| s.state.clone()),
            capabilities: g.agent.as_ref().map(|a| a.capabilities.clone()),
            estimators: g.agent.as_ref().map(|a| {
                DspIdentity::check(a.capabilities.dsp.as_ref(), &a.capabilities.estimators)
            }),
            quarantine: g.lease.quarantine.clone(),
            trial_out: g
                .lease
                .outstanding
                .as_ref()
                .filter(|o| o.sent_epoch.is_some())
                .map(|o| o.trial_id.clone()),
            waiting: g.lease.blocked(now),
        }
    }
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Inner> {
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

/// Fence the session if it has been silent past TTL + grace.
fn tick(g: &mut Inner) {
    if let Some(epoch) = g.lease.tick(now_ms()) {
        if g.outbox.as_ref().is_some_and(|(e, _)| *e == epoch) {
            g.outbox = None;
        }
    }
}

/// Whether `p` is a verdict some trial could have: of either criterion,
/// with or without a confidence (the accuracy's largest realizations).
fn any_verdict_shape(p: &Point) -> Result<(), SpecError> {
    use crate::zwidth::settings::Criterion;
    use crate::zwidth::trial::check_verdict_shape;
    // The shape its verdict field names, else that of a stability verdict.
    let c = if p.passive.is_some() {
        Criterion::Impedance
    } else {
        Criterion::Stability
    };
    check_verdict_shape(p, c, false, 1000).or_else(|_| check_verdict_shape(p, c, true, 1000))
}

/// Whether the rig, as advertised, can run the trial (the dispatch check:
/// the agent may have reconnected with other capabilities since submit).
pub fn dispatch_check(caps: &Capabilities, r: &TrialRequest) -> Result<(), SpecError> {
    let probe = match r.method {
        Method::Time => "wall_hit",
        Method::Frequency => "multisine",
        _ => return Err(SpecError::new(
            "method",
            format!("{:?}", r.method).to_lowercase(),
            "an attached rig runs wall hits (method time) or multisine probes (method frequency)",
        )),
    };
    if !caps.probes.iter().any(|p| p == probe) {
        return Err(SpecError::new(
            "method",
            format!("{:?}", r.method).to_lowercase(),
            format!("the rig runs {:?} only", caps.probes),
        ));
    }
    check_caps(caps, &r.scene)?;
    if r.k > caps.k_max {
        return Err(SpecError::new(
            "k",
            r.k,
            format!("the rig renders K up to {} N/m", caps.k_max),
        ));
    }
    if r.b.abs() > caps.b_max {
        return Err(SpecError::new(
            "b",
            r.b,
            format!("the rig renders |B| up to {} N·s/m", caps.b_max),
        ));
    }
    Ok(())
}

/// A scene against what the rig advertises: a rate it runs, an estimator
/// it has, a force limit within its peak force.
pub fn check_caps(caps: &Capabilities, scene: &SceneSpec) -> Result<(), SpecError> {
    let hz = scene.control.sample_hz;
    if !caps.sample_hz.contains(&hz) {
        return Err(SpecError::new(
            "loop.sample_hz",
            hz,
            format!("the rig runs {:?} Hz", caps.sample_hz),
        ));
    }
    let kind = serde_json::to_value(&scene.estimator)
        .ok()
        .and_then(|v| v.get("kind").and_then(|k| k.as_str()).map(str::to_owned))
        .unwrap_or_default();
    if !caps.estimators.contains(&kind) {
        return Err(SpecError::new(
            "estimator.kind",
            kind,
            format!("the rig runs {:?}", caps.estimators),
        ));
    }
    match scene.device.force_limit {
        Some(f) if f <= caps.peak_force_n => Ok(()),
        f => Err(SpecError::new(
            "device.force_limit",
            f.map(|f| f.to_string()).unwrap_or("null".into()),
            format!(
                "the rig exerts at most {} N: set a force_limit <= {}",
                caps.peak_force_n, caps.peak_force_n
            ),
        )),
    }
}

impl Rig for AttachedRig {
    fn info(&self) -> RigInfo {
        let caps = self.lock().agent.as_ref().map(|a| a.capabilities.clone());
        let (lo, hi) = caps.as_ref().map_or((10.0, 1e7), |c| {
            (
                c.sample_hz.iter().copied().fold(f64::INFINITY, f64::min),
                c.sample_hz.iter().copied().fold(0.0, f64::max),
            )
        });
        RigInfo {
            id: self.id.clone(),
            kind: "attached".into(),
            description: self.description.clone(),
            sample_hz: [lo, hi],
            force_limit_n: caps.map(|c| c.peak_force_n),
            parallelism: 1,
        }
    }

    /// Against what its agent advertised last (nothing to check before an
    /// agent has connected: the dispatch check still applies).
    fn check(&self, scenes: &[(String, SceneSpec)]) -> Result<(), SpecError> {
        let caps = self.lock().agent.as_ref().map(|a| a.capabilities.clone());
        if let Some(caps) = caps {
            for (field, scene) in scenes {
                check_caps(&caps, scene).map_err(|e| e.within(field))?;
            }
        }
        Ok(())
    }

    fn pool(&self) -> &rayon::ThreadPool {
        &self.pool
    }

    fn backend(&self, experiment: &str) -> Option<Arc<dyn TrialBackend>> {
        Some(Arc::new(AttachedRun {
            rig: self.id.clone(),
            shared: self.shared.clone(),
            experiment: experiment.to_string(),
        }))
    }

    fn as_any(&self) -> &dyn std::any::Any {
        self
    }
}

/// One experiment's trials on an attached rig.
struct AttachedRun {
    rig: String,
    shared: Arc<Shared>,
    experiment: String,
}

impl TrialBackend for AttachedRun {
    fn trial(&self, request: &TrialRequest, observer: &dyn RunControl) -> Option<Point> {
        let id = trial_id(&self.experiment, request.scope, request.k, request.b);
        let mut g = self.shared.lock();
        g.pending = Some(Pending {
            trial_id: id.clone(),
            experiment: self.experiment.clone(),
            scope: request.scope,
            request: request.clone(),
            point: None,
            failed: None,
        });
        let outcome = loop {
            if observer.cancelled() {
                // Out on the rig (under this session's epoch or, after a
                // reconnect, an earlier one): tell the agent to end it.
                if let (Some(o), Some((epoch, tx))) = (&g.lease.outstanding, &g.outbox) {
                    if o.trial_id == id && o.sent_epoch.is_some() {
                        let _ = tx.send(ServerMessage::CancelTrial {
                            epoch: *epoch,
                            trial_id: id.clone(),
                        });
                    }
                }
                break None;
            }
            let p = g.pending.as_mut().expect("pending while waiting");
            if let Some(point) = p.point.take() {
                break Some(point);
            }
            if let Some(why) = p.failed.take() {
                observer.fail(why);
                break None;
            }
            tick(&mut g);
            let now = now_ms();
            // The dispatch check, against what the agent advertises now.
            if let Some(a) = &g.agent {
                if let Err(e) = dispatch_check(&a.capabilities, request) {
                    observer.fail(format!("rig {} cannot run this trial: {e}", self.rig));
                    break None;
                }
            }
            let live = g.outbox.clone();
            if let Some(epoch) = g.lease.send(&id, now) {
                let limits = limits(g.agent.as_ref(), request);
                let sent = live.as_ref().is_some_and(|(e, tx)| {
                    *e == epoch
                        && tx
                            .send(ServerMessage::Trial {
                                epoch,
                                trial_id: id.clone(),
                                expires_in_ms: g.lease.timing.ttl_ms,
                                request: request.clone(),
                                limits,
                            })
                            .is_ok()
                });
                if !sent {
                    // The session's queue is gone: send again to the next.
                    g.lease.refused(epoch, &id, now);
                }
            }
            observer.set_waiting(g.lease.blocked(now));
            g = self
                .shared
                .changed
                .wait_timeout(g, Duration::from_millis(50))
                .map(|(g, _)| g)
                .unwrap_or_else(|e| e.into_inner().0);
        };
        g.lease.done(&id);
        g.pending = None;
        drop(g);
        observer.set_waiting(None);
        outcome
    }
}

/// The limits sent with a trial: the scene's force limit within the
/// rig's peak force; abort beyond its top speed or half its travel.
fn limits(agent: Option<&Agent>, r: &TrialRequest) -> TrialLimits {
    let caps = agent.map(|a| &a.capabilities);
    let peak = caps.map_or(f64::MAX, |c| c.peak_force_n);
    TrialLimits {
        force_limit_n: r.scene.device.force_limit.unwrap_or(peak).min(peak),
        abort_speed_m_s: caps.map_or(f64::MAX, |c| c.speed_m_s),
        abort_penetration_m: caps.map_or(f64::MAX, |c| 0.5 * c.travel_m),
    }
}
