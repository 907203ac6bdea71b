//! `GET /v1/agent`: the WebSocket a rig's agent dials out on (protocol in
//! `rig::protocol`, docs/rigs.md). The session opens with `hello`, gets an
//! epoch from the database's counter, and then carries trials out and
//! results back. A result is committed before it is acknowledged; one that
//! does not belong (stale epoch, never sent, impossible) is audited and
//! acknowledged, never stored as a trial. Bad messages close the session
//! with an `error` saying why, and are audited.

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::time::Duration;

use super::guard::{credential_digest, credential_fits, token_accepted};
use super::problem::Problem;
use super::AppState;
use crate::rig::attached::{AttachedRig, Verdict};
use crate::rig::protocol::{self, AgentMessage, ServerMessage, TrialResult};
use crate::rig::Rig;
use crate::store::agents::{clip, AUDIT_ID, AUDIT_REASON, UNKNOWN_RIG};
use crate::zwidth::search::StoredTrial;

/// How long an agent has to send `hello` after connecting.
const HELLO_WITHIN: Duration = Duration::from_secs(10);
/// Longest one message to an agent may wait for the agent to read it (its
/// socket's buffers full): past it the session is closed and its epoch
/// fenced (docs/rigs.md, "Budgets").
pub const WRITE_WITHIN: Duration = Duration::from_secs(5);
/// Most bytes queued for an agent beyond the socket's own buffers: a
/// write past it fails, which closes the session.
/// (Above tungstenite's 128 KiB write buffer and a trial message.)
pub const SEND_QUEUE: usize = 512 * 1024;
/// Audit rows one session may cause within [`AUDIT_WINDOW`]: one more
/// closes it (audited once more, saying so). Generous for an agent that
/// repeats late results after a fault (each is audited); the rows kept
/// are bounded anyway by the retention (`store::agents::AUDIT_KEEP_ROWS`).
pub const AUDIT_BUDGET: u32 = 120;
pub const AUDIT_WINDOW: Duration = Duration::from_secs(60);

#[utoipa::path(get, path = "/v1/agent",
    description = "WebSocket upgrade for a rig's agent (the agent protocol: api/agent-protocol.json, docs/rigs.md). Needs an agent token (`Authorization: Bearer`), never a user's.",
    responses((status = 101, description = "switching to the agent protocol"),
              (status = 401, body = super::ProblemBody, content_type = "application/problem+json"),
              (status = 403, body = super::ProblemBody, content_type = "application/problem+json")),
    security(("agent" = [])))]
pub async fn agent(
    State(st): State<AppState>,
    headers: HeaderMap,
    ws: Result<WebSocketUpgrade, axum::extract::ws::rejection::WebSocketUpgradeRejection>,
) -> Response {
    let given = super::guard::bearer(&headers);
    match given {
        None => {
            return Problem::new(
                StatusCode::UNAUTHORIZED,
                "Unauthorized",
                "an agent session needs Authorization: Bearer <agent token>",
            )
            .with_field("Authorization")
            .into_response()
        }
        Some(t) if !token_accepted(&st.agent_tokens, t) && !own_credential(&st, t).await => {
            return Problem::new(
                StatusCode::FORBIDDEN,
                "Forbidden",
                "not an agent token (user tokens cannot open agent sessions)",
            )
            .with_field("Authorization")
            .into_response()
        }
        Some(_) => {}
    }
    // Which rig it may open is checked at hello, where the rig is named.
    let token = given.unwrap_or_default().to_string();
    let ws = match ws {
        Ok(ws) => ws,
        Err(e) => {
            return Problem::new(
                StatusCode::BAD_REQUEST,
                "Bad request",
                format!("GET /v1/agent is a WebSocket upgrade: {e}"),
            )
            .into_response()
        }
    };
    ws.max_message_size(protocol::MAX_MESSAGE)
        .max_write_buffer_size(SEND_QUEUE)
        .on_upgrade(move |socket| session(st, socket, token))
}

/// Whether `token` is some rig's own credential.
async fn own_credential(st: &AppState, token: &str) -> bool {
    match st.store.rig_of_credential(&credential_digest(token)).await {
        Ok(rig) => rig.is_some(),
        Err(e) => {
            st.store.observe(&e);
            false
        }
    }
}

/// One connection: writes go through `send` (numbered, each within
/// [`WRITE_WITHIN`]); audits through `audit` (at most [`AUDIT_BUDGET`] in
/// [`AUDIT_WINDOW`]).
struct Conn {
    socket: WebSocket,
    seq: u64,
    /// The rig the audit rows go under ([`UNKNOWN_RIG`] before hello).
    rig: String,
    audits: u32,
    window: tokio::time::Instant,
    /// A write failed or timed out: nothing more is sent.
    dead: bool,
}

impl Conn {
    async fn send(&mut self, msg: &ServerMessage) -> bool {
        self.seq += 1;
        let text = Message::Text(protocol::encode(self.seq, msg).into());
        self.write(text).await
    }

    async fn write(&mut self, m: Message) -> bool {
        if self.dead {
            return false;
        }
        let ok = matches!(
            tokio::time::timeout(WRITE_WITHIN, self.socket.send(m)).await,
            Ok(Ok(()))
        );
        self.dead = !ok;
        ok
    }

    /// Keep a refused message, within the session's budget.
    async fn audit(
        &mut self,
        st: &AppState,
        epoch: Option<u64>,
        trial: Option<&str>,
        why: &str,
        raw: &str,
    ) -> Audit {
        let now = tokio::time::Instant::now();
        if now.duration_since(self.window) > AUDIT_WINDOW {
            (self.window, self.audits) = (now, 0);
        }
        self.audits += 1;
        let over = self.audits > AUDIT_BUDGET;
        if self.audits > AUDIT_BUDGET + 1 {
            return Audit::OverBudget;
        }
        let why = if over {
            format!(
                "the session is closed: more than {AUDIT_BUDGET} refused messages in {} s; the last: {why}",
                AUDIT_WINDOW.as_secs()
            )
        } else {
            why.to_string()
        };
        match st.store.audit(&self.rig, epoch, trial, &why, raw).await {
            Err(e) => {
                st.store.observe(&e);
                tracing::error!(error = %e, "the agent audit could not be written");
                Audit::Failed
            }
            Ok(()) if over => Audit::OverBudget,
            Ok(()) => Audit::Kept,
        }
    }

    /// Audit why, say it, then close.
    async fn refuse_audited(mut self, st: &AppState, epoch: Option<u64>, why: String, raw: &str) {
        self.audit(st, epoch, None, &why, raw).await;
        self.refuse(why).await
    }

    /// Say why, then close (each within [`WRITE_WITHIN`]).
    async fn refuse(mut self, why: String) {
        tracing::warn!(rig = %self.rig, %why, "agent session refused or ended");
        let _ = self.send(&ServerMessage::Error { message: why }).await;
        let _ = self.write(Message::Close(None)).await;
    }
}

/// What became of an audit row.
#[derive(PartialEq)]
enum Audit {
    Kept,
    /// Not written (the agent keeps a result it could not have audited).
    Failed,
    /// The session's budget is spent: it closes.
    OverBudget,
}

/// The first message as audited: its text, or what it was.
fn shown(m: &Message) -> String {
    match m {
        Message::Text(t) => t.to_string(),
        Message::Binary(b) => format!("(a binary message of {} bytes)", b.len()),
        other => format!("({other:?})"),
    }
}

async fn session(st: AppState, socket: WebSocket, token: String) {
    let mut conn = Conn {
        socket,
        seq: 0,
        rig: UNKNOWN_RIG.to_string(),
        audits: 0,
        window: tokio::time::Instant::now(),
        dead: false,
    };
    let first = match tokio::time::timeout(HELLO_WITHIN, conn.socket.recv()).await {
        Ok(Some(Ok(Message::Text(t)))) => t.to_string(),
        Ok(Some(Ok(m))) => {
            let raw = shown(&m);
            return conn
                .refuse_audited(
                    &st,
                    None,
                    "the first message must be a text hello".into(),
                    &raw,
                )
                .await;
        }
        Ok(Some(Err(e))) => {
            return conn
                .refuse_audited(
                    &st,
                    None,
                    format!("the first message could not be read: {e}"),
                    "",
                )
                .await
        }
        Ok(None) => return,
        Err(_) => {
            let why = format!("no hello within {} s", HELLO_WITHIN.as_secs());
            return conn.refuse_audited(&st, None, why, "").await;
        }
    };
    let hello = match protocol::decode::<AgentMessage>(&first) {
        Ok(env) => env.body,
        Err(why) => return conn.refuse_audited(&st, None, why, &first).await,
    };
    let AgentMessage::Hello {
        rig,
        agent,
        boot,
        last_epoch: _,
        running,
        unacked,
        state,
        capabilities,
    } = hello
    else {
        return conn
            .refuse_audited(&st, None, "the first message must be hello".into(), &first)
            .await;
    };
    let Some(handle) = st.rig(&rig) else {
        // Kept under the unknown rig, the name it gave (cut) in the reason.
        let why = format!(
            "rig {:?} is not one of this server's rigs: {}",
            clip(&rig, AUDIT_ID),
            st.rig_ids()
        );
        return conn.refuse_audited(&st, None, why, &first).await;
    };
    conn.rig = rig.clone();
    let Some(attached) = handle.attached() else {
        let why = format!("rig {rig:?} is not an attached rig");
        return conn.refuse_audited(&st, None, why, &first).await;
    };
    // Its own credential, or (without one) the shared agent tokens.
    let own = match st.store.rig_credential(&rig).await {
        Ok(own) => own,
        Err(e) => {
            return conn
                .refuse(format!("cannot check the credential: {e}"))
                .await
        }
    };
    if let Err(why) = credential_fits(&rig, own.as_deref(), &st.agent_tokens, &token) {
        return conn.refuse_audited(&st, None, why, &first).await;
    }
    if let Err(e) = capabilities.validate() {
        return conn
            .refuse_audited(&st, None, format!("hello: {e}"), &first)
            .await;
    }
    if agent.is_empty() || agent.len() > 128 || boot.is_empty() || boot.len() > 128 {
        let why = format!(
            "hello: agent ({} bytes) and boot ({} bytes) must be 1 to 128 bytes",
            agent.len(),
            boot.len()
        );
        return conn.refuse_audited(&st, None, why, &first).await;
    }
    let epoch = match st.store.next_epoch(&rig).await {
        Ok(e) => e,
        Err(e) => return conn.refuse(format!("cannot open a session: {e}")).await,
    };
    if let Err(why) = attached.open(epoch, &agent, &boot, state, capabilities) {
        return conn.refuse_audited(&st, Some(epoch), why, &first).await;
    }
    tracing::info!(%rig, %agent, %boot, epoch, unacked = unacked.len(), "agent session open");
    let timing = attached.timing();
    if !conn
        .send(&ServerMessage::Welcome {
            epoch,
            heartbeat_ms: timing.heartbeat_ms,
            ttl_ms: timing.ttl_ms,
        })
        .await
    {
        attached.closed(epoch);
        return;
    }
    // Its outbox: each result stored (or audited) before the next.
    for r in unacked {
        let raw = serde_json::to_string(&r).unwrap_or_default();
        match result(&st, attached, &mut conn, r, &raw).await {
            Taken::Yes => {}
            Taken::NotStored => {
                attached.closed(epoch);
                return conn
                    .refuse("a result could not be stored: send it again".into())
                    .await;
            }
            Taken::OverBudget | Taken::Unsent => {
                attached.closed(epoch);
                return conn.refuse("the session is closed".into()).await;
            }
        }
    }
    let (tx, mut rx) = tokio::sync::mpsc::unbounded_channel();
    attached.resume(epoch, running.as_deref(), tx);
    let mut beat = tokio::time::interval(Duration::from_millis(timing.heartbeat_ms.max(10)));
    let end = loop {
        tokio::select! {
            out = rx.recv() => match out {
                Some(msg) => {
                    // The trial out is recorded before it goes (a restarted
                    // server takes its result instead of running it again).
                    if let ServerMessage::Trial { epoch: e, trial_id, .. } = &msg {
                        if let Err(err) = st.store.set_trial_out(&rig, trial_id, *e).await {
                            st.store.observe(&err);
                            attached.refused(*e, trial_id, true, "the server could not record it");
                            continue;
                        }
                    }
                    if !conn.send(&msg).await {
                        break Some(format!("a message waited more than {} s for the agent to read it", WRITE_WITHIN.as_secs()));
                    }
                }
                None => break Some(format!(
                    "epoch {epoch} fenced off: the agent was silent past the heartbeat TTL and grace, or another session took the rig"
                )),
            },
            _ = beat.tick() => {
                attached.tick();
                if !conn.write(Message::Ping(Default::default())).await {
                    break Some(format!("a ping waited more than {} s for the agent to read it", WRITE_WITHIN.as_secs()));
                }
            }
            incoming = conn.socket.recv() => {
                let text = match incoming {
                    Some(Ok(Message::Text(t))) => t.to_string(),
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                    Some(Ok(m @ Message::Binary(_))) => {
                        let why = "binary messages are not part of the protocol".to_string();
                        conn.audit(&st, Some(epoch), None, &why, &shown(&m)).await;
                        break Some(why);
                    }
                    Some(Ok(Message::Close(_))) | None => break None,
                    Some(Err(e)) => {
                        let why = format!("the link failed: {e}");
                        conn.audit(&st, Some(epoch), None, &why, "").await;
                        break Some(why);
                    }
                };
                match protocol::decode::<AgentMessage>(&text) {
                    Err(why) => {
                        conn.audit(&st, Some(epoch), None, &why, &text).await;
                        break Some(why);
                    }
                    Ok(env) => match env.body {
                        AgentMessage::Heartbeat { epoch: e, state } => {
                            if !attached.heard(e, Some(state)) {
                                let why = format!("heartbeat under epoch {e}: this session's is {epoch}");
                                conn.audit(&st, Some(e), None, &why, &text).await;
                                break Some(why);
                            }
                        }
                        AgentMessage::Result(r) => {
                            attached.heard(epoch, None);
                            match result(&st, attached, &mut conn, r, &text).await {
                                Taken::Yes => {}
                                Taken::NotStored => break Some("a result could not be stored: send it again".into()),
                                Taken::OverBudget => break Some(format!("more than {AUDIT_BUDGET} refused messages in {} s", AUDIT_WINDOW.as_secs())),
                                Taken::Unsent => break Some(format!("an ack waited more than {} s for the agent to read it", WRITE_WITHIN.as_secs())),
                            }
                        }
                        AgentMessage::Refused { epoch: e, trial_id, code, reason } => {
                            attached.heard(epoch, None);
                            let why = format!("the agent refused the trial ({code:?}): {}", clip(&reason, AUDIT_REASON));
                            let audit = conn.audit(&st, Some(e), Some(&trial_id), &why, &text).await;
                            attached.refused(e, &trial_id, code.transient(), &clip(&reason, AUDIT_REASON));
                            if audit == Audit::OverBudget {
                                break Some(format!("more than {AUDIT_BUDGET} refused messages in {} s", AUDIT_WINDOW.as_secs()));
                            }
                        }
                        AgentMessage::Hello { .. } => {
                            let why = "hello is only the first message".to_string();
                            conn.audit(&st, Some(epoch), None, &why, &text).await;
                            break Some(why);
                        }
                    },
                }
            }
        }
    };
    attached.closed(epoch);
    tracing::info!(%rig, epoch, "agent session closed");
    if let Some(why) = end {
        conn.refuse(why).await;
    }
}

/// What became of a result.
enum Taken {
    /// Stored or audited, and acknowledged.
    Yes,
    /// Neither could be committed (no ack: the agent keeps it).
    NotStored,
    /// Audited, and the session's audit budget is spent.
    OverBudget,
    /// Committed, but the ack could not be written in time.
    Unsent,
}

/// Take one result: store it (then acknowledge it and hand it to the
/// search) or audit it (then acknowledge it: the agent drops it).
async fn result(
    st: &AppState,
    rig: &AttachedRig,
    conn: &mut Conn,
    r: TrialResult,
    raw: &str,
) -> Taken {
    match rig.check_result(&r) {
        Verdict::Store { experiment, scope } => {
            // Its place in the map is stored when the search takes it.
            let t = StoredTrial {
                scope,
                column: 0,
                index: 0,
                point: r.point.clone(),
            };
            match st.store.add_trial_unplaced(&experiment, &t).await {
                Ok(()) => {
                    rig.deliver(&r.trial_id, r.point.clone());
                    let _ = st.store.clear_trial_out(rig.id(), &r.trial_id).await;
                }
                Err(e) => {
                    st.store.observe(&e);
                    tracing::error!(error = %e, trial = %r.trial_id, "storing an agent's result failed");
                    return Taken::NotStored;
                }
            }
        }
        Verdict::Refuse(why) => {
            if let Some(q) = why.strip_prefix("quarantined: ") {
                tracing::error!(rig = %rig.id(), reason = %q, "rig quarantined");
                let _ = st.store.set_quarantine(rig.id(), Some(q)).await;
            }
            match conn
                .audit(st, Some(r.epoch), Some(&r.trial_id), &why, raw)
                .await
            {
                Audit::Kept => {}
                Audit::Failed => return Taken::NotStored,
                Audit::OverBudget => return Taken::OverBudget,
            }
        }
    }
    if conn
        .send(&ServerMessage::Ack {
            epoch: r.epoch,
            trial_id: r.trial_id,
        })
        .await
    {
        Taken::Yes
    } else {
        Taken::Unsent
    }
}

/// The attached rigs among `rigs`.
pub fn attached_rigs(rigs: &[Arc<dyn Rig>]) -> Vec<&AttachedRig> {
    rigs.iter().filter_map(|r| r.attached()).collect()
}
