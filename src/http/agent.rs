//! `GET /v1/agent`: the WebSocket a rig's agent dials out on (protocol in
//! `rig::protocol`, docs/rigs.md). The session opens with `hello`, gets an
//! epoch from the database's counter, and then carries trials out and
//! results back. A result is committed before it is acknowledged; one that
//! does not belong (stale epoch, never sent, impossible) is audited and
//! acknowledged, never stored as a trial. Bad messages close the session
//! with an `error` saying why, and are audited.

use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::State;
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use std::sync::Arc;
use std::time::Duration;

use super::guard::token_accepted;
use super::problem::Problem;
use super::AppState;
use crate::rig::attached::{AttachedRig, Verdict};
use crate::rig::protocol::{self, AgentMessage, ServerMessage, TrialResult};
use crate::rig::Rig;
use crate::zwidth::search::StoredTrial;

/// How long an agent has to send `hello` after connecting.
const HELLO_WITHIN: Duration = Duration::from_secs(10);

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
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
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
        Some(t) if !token_accepted(&st.agent_tokens, t) => {
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
        .on_upgrade(move |socket| session(st, socket))
}

/// One connection: writes go through `send` (numbered).
struct Conn {
    socket: WebSocket,
    seq: u64,
}

impl Conn {
    async fn send(&mut self, msg: &ServerMessage) -> bool {
        self.seq += 1;
        self.socket
            .send(Message::Text(protocol::encode(self.seq, msg).into()))
            .await
            .is_ok()
    }

    /// Say why, then close.
    async fn refuse(mut self, why: String) {
        tracing::warn!(%why, "agent session refused or ended");
        let _ = self.send(&ServerMessage::Error { message: why }).await;
        let _ = self.socket.send(Message::Close(None)).await;
    }
}

async fn session(st: AppState, socket: WebSocket) {
    let mut conn = Conn { socket, seq: 0 };
    let first = match tokio::time::timeout(HELLO_WITHIN, conn.socket.recv()).await {
        Ok(Some(Ok(Message::Text(t)))) => t.to_string(),
        Ok(Some(Ok(_))) => {
            return conn
                .refuse("the first message must be a text hello".into())
                .await
        }
        Ok(_) => return,
        Err(_) => {
            return conn
                .refuse(format!("no hello within {} s", HELLO_WITHIN.as_secs()))
                .await
        }
    };
    let hello = match protocol::decode::<AgentMessage>(&first) {
        Ok(env) => env.body,
        Err(why) => {
            let _ = st.store.audit("?", None, None, &why, &first).await;
            return conn.refuse(why).await;
        }
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
        return conn.refuse("the first message must be hello".into()).await;
    };
    let Some(handle) = st.rig(&rig) else {
        let why = format!(
            "rig {rig:?} is not one of this server's rigs: {}",
            st.rig_ids()
        );
        let _ = st.store.audit(&rig, None, None, &why, &first).await;
        return conn.refuse(why).await;
    };
    let Some(attached) = handle.attached() else {
        let why = format!("rig {rig:?} is not an attached rig");
        let _ = st.store.audit(&rig, None, None, &why, &first).await;
        return conn.refuse(why).await;
    };
    if let Err(e) = capabilities.validate() {
        let why = format!("hello: {e}");
        let _ = st.store.audit(&rig, None, None, &why, &first).await;
        return conn.refuse(why).await;
    }
    if agent.is_empty() || agent.len() > 128 || boot.is_empty() || boot.len() > 128 {
        return conn
            .refuse("hello: agent and boot must be 1 to 128 characters".into())
            .await;
    }
    let epoch = match st.store.next_epoch(&rig).await {
        Ok(e) => e,
        Err(e) => return conn.refuse(format!("cannot open a session: {e}")).await,
    };
    if let Err(why) = attached.open(epoch, &agent, &boot, state, capabilities) {
        let _ = st.store.audit(&rig, Some(epoch), None, &why, &first).await;
        return conn.refuse(why).await;
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
        if !result(&st, attached, &mut conn, r, &raw).await {
            attached.closed(epoch);
            return conn
                .refuse("a result could not be stored: send it again".into())
                .await;
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
                    if !conn.send(&msg).await { break None }
                }
                None => break Some(format!(
                    "epoch {epoch} fenced off: the agent was silent past the heartbeat TTL and grace"
                )),
            },
            _ = beat.tick() => {
                attached.tick();
                if conn.socket.send(Message::Ping(Default::default())).await.is_err() {
                    break None;
                }
            }
            incoming = conn.socket.recv() => {
                let text = match incoming {
                    Some(Ok(Message::Text(t))) => t.to_string(),
                    Some(Ok(Message::Ping(_) | Message::Pong(_))) => continue,
                    Some(Ok(Message::Binary(_))) => break Some("binary messages are not part of the protocol".into()),
                    Some(Ok(Message::Close(_))) | None => break None,
                    Some(Err(e)) => break Some(format!("the link failed: {e}")),
                };
                match protocol::decode::<AgentMessage>(&text) {
                    Err(why) => {
                        let _ = st.store.audit(&rig, Some(epoch), None, &why, &text).await;
                        break Some(why);
                    }
                    Ok(env) => match env.body {
                        AgentMessage::Heartbeat { epoch: e, state } => {
                            if !attached.heard(e, Some(state)) {
                                let why = format!("heartbeat under epoch {e}: this session's is {epoch}");
                                let _ = st.store.audit(&rig, Some(e), None, &why, &text).await;
                                break Some(why);
                            }
                        }
                        AgentMessage::Result(r) => {
                            attached.heard(epoch, None);
                            if !result(&st, attached, &mut conn, r, &text).await {
                                break Some("a result could not be stored: send it again".into());
                            }
                        }
                        AgentMessage::Refused { epoch: e, trial_id, code, reason } => {
                            attached.heard(epoch, None);
                            let _ = st.store.audit(&rig, Some(e), Some(&trial_id), &format!("the agent refused the trial ({code:?}): {reason}"), &text).await;
                            attached.refused(e, &trial_id, code.transient(), &reason);
                        }
                        AgentMessage::Hello { .. } => break Some("hello is only the first message".into()),
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

/// Take one result: store it (then acknowledge it and hand it to the
/// search) or audit it (then acknowledge it: the agent drops it). False
/// when neither could be committed (no ack: the agent keeps it).
async fn result(
    st: &AppState,
    rig: &AttachedRig,
    conn: &mut Conn,
    r: TrialResult,
    raw: &str,
) -> bool {
    let committed = match rig.check_result(&r) {
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
                    true
                }
                Err(e) => {
                    st.store.observe(&e);
                    tracing::error!(error = %e, trial = %r.trial_id, "storing an agent's result failed");
                    false
                }
            }
        }
        Verdict::Refuse(why) => {
            if let Some(q) = why.strip_prefix("quarantined: ") {
                tracing::error!(rig = %rig.id(), reason = %q, "rig quarantined");
                let _ = st.store.set_quarantine(rig.id(), Some(q)).await;
            }
            st.store
                .audit(rig.id(), Some(r.epoch), Some(&r.trial_id), &why, raw)
                .await
                .is_ok()
        }
    };
    committed
        && conn
            .send(&ServerMessage::Ack {
                epoch: r.epoch,
                trial_id: r.trial_id,
            })
            .await
}

/// The attached rigs among `rigs`.
pub fn attached_rigs(rigs: &[Arc<dyn Rig>]) -> Vec<&AttachedRig> {
    rigs.iter().filter_map(|r| r.attached()).collect()
}
