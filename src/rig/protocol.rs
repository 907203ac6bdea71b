//! The agent protocol (`GET /v1/agent`, a WebSocket the agent dials out
//! on): JSON text messages, each `{"v": 1, "seq": n, "type": …, …}`.
//! The message set is documented in `api/agent-protocol.json` (generated
//! from these types; a test keeps it from drifting) and docs/rigs.md.

use serde::{Deserialize, Serialize};

use crate::error::SpecError;
pub use crate::estimators::identity::{DspIdentity, EstimatorCheck};
use crate::zwidth::search::Point;
use crate::zwidth::trial::TrialRequest;

/// The protocol version this build speaks.
pub const VERSION: u32 = 1;
/// Largest message accepted (bytes); larger closes the session.
pub const MAX_MESSAGE: usize = 256 * 1024;

/// Every message: the version, the sender's sequence number (1, 2, …
/// within a connection) and the body.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Envelope<B> {
    pub v: u32,
    pub seq: u64,
    #[serde(flatten)]
    pub body: B,
}

/// What the agent's rig is doing, as the operator set it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "state", rename_all = "snake_case")]
pub enum RigState {
    /// Powered but not allowed to move: nothing is sent.
    Disarmed,
    /// Ready for trials.
    Armed,
    /// An operator holds the rig (maintenance, a person at the device).
    OperatorLocked {
        user: String,
        note: String,
        /// Until when (unix ms); null: until unlocked.
        until_ms: Option<i64>,
    },
    /// The emergency stop is latched: a local reset is needed.
    EStop,
    /// The controller reports a fault.
    Fault { message: String },
}

impl RigState {
    pub fn armed(&self) -> bool {
        matches!(self, RigState::Armed)
    }

    /// In words, for `GET /v1/rigs` and a waiting experiment.
    pub fn describe(&self) -> String {
        match self {
            RigState::Disarmed => "disarmed".into(),
            RigState::Armed => "armed".into(),
            RigState::OperatorLocked { user, note, .. } => {
                format!("locked by operator {user}: {note}")
            }
            RigState::EStop => "e-stop latched".into(),
            RigState::Fault { message } => format!("fault: {message}"),
        }
    }
}

/// What an attached rig can do, as its agent advertises it in `hello`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Capabilities {
    /// Peak force (N).
    pub peak_force_n: f64,
    /// Continuous force (N).
    pub continuous_force_n: f64,
    /// Largest wall stiffness (N/m) and damping (N·s/m) it renders.
    pub k_max: f64,
    pub b_max: f64,
    /// Travel (m) and top speed (m/s).
    pub travel_m: f64,
    pub speed_m_s: f64,
    /// Encoder resolution (m).
    pub encoder_m: f64,
    /// Encoder sample rates it can run (Hz).
    pub sample_hz: Vec<f64>,
    /// Estimator kinds it runs (`fdm`, `butterworth`, …).
    pub estimators: Vec<String>,
    /// Trial kinds: `wall_hit` (the time engine) and/or `multisine` (the
    /// frequency engine).
    pub probes: Vec<String>,
    /// An identified model of the device (a scene JSON), if it has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub model: Option<serde_json::Value>,
    /// The estimator library the rig's controller runs: zwidth-dsp's
    /// version and each kind's reference fingerprint (`zw_dsp_identity` in
    /// C, `zwidth.dsp_identity()` in Python). The server compares them
    /// with its own (`GET /v1/rigs`: `attached.estimators`); absent, the
    /// rig runs estimators of its own and says so nowhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dsp: Option<DspIdentity>,
}

impl Capabilities {
    /// A bench-top device's figures: 10 N peak, 1 µm encoder, the rates
    /// and every estimator and probe zwidth has (what `zwidth agent --sim`
    /// advertises unless given `--capabilities`).
    pub fn bench() -> Self {
        Self {
            peak_force_n: 10.0,
            continuous_force_n: 4.0,
            k_max: 1e6,
            b_max: 1e4,
            travel_m: 0.1,
            speed_m_s: 1.0,
            encoder_m: 1e-6,
            sample_hz: vec![1000.0, 2000.0, 5000.0, 10000.0],
            estimators: crate::estimators::identity::KINDS
                .map(String::from)
                .to_vec(),
            probes: vec!["wall_hit".into(), "multisine".into()],
            model: None,
            dsp: Some(DspIdentity::ours()),
        }
    }

    /// Every figure physical: positive and finite, at least one rate,
    /// estimator and probe kind. Err names the field.
    pub fn validate(&self) -> Result<(), SpecError> {
        let positive = [
            ("peak_force_n", self.peak_force_n),
            ("continuous_force_n", self.continuous_force_n),
            ("k_max", self.k_max),
            ("b_max", self.b_max),
            ("travel_m", self.travel_m),
            ("speed_m_s", self.speed_m_s),
            ("encoder_m", self.encoder_m),
        ];
        for (field, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(SpecError::new(
                    format!("capabilities.{field}"),
                    v,
                    "must be a finite number > 0",
                ));
            }
        }
        if self.continuous_force_n > self.peak_force_n {
            return Err(SpecError::new(
                "capabilities.continuous_force_n",
                self.continuous_force_n,
                format!("must be at most peak_force_n = {}", self.peak_force_n),
            ));
        }
        if self.sample_hz.is_empty() || self.sample_hz.len() > 64 {
            return Err(SpecError::new(
                "capabilities.sample_hz",
                format!("{:?}", self.sample_hz),
                "list 1 to 64 sample rates",
            ));
        }
        for &hz in &self.sample_hz {
            if !(hz.is_finite() && (10.0..=1e7).contains(&hz)) {
                return Err(SpecError::new(
                    "capabilities.sample_hz",
                    hz,
                    "each rate must be 10 to 1e7 Hz",
                ));
            }
        }
        const PROBES: [&str; 2] = ["wall_hit", "multisine"];
        if self.probes.is_empty() || self.probes.iter().any(|p| !PROBES.contains(&p.as_str())) {
            return Err(SpecError::new(
                "capabilities.probes",
                format!("{:?}", self.probes),
                "one or both of wall_hit, multisine",
            ));
        }
        if self.estimators.is_empty() || self.estimators.len() > 32 {
            return Err(SpecError::new(
                "capabilities.estimators",
                format!("{:?}", self.estimators),
                "list 1 to 32 estimator kinds",
            ));
        }
        if let Some(dsp) = &self.dsp {
            dsp.validate()?;
        }
        Ok(())
    }
}

/// A trial result's measurements of the hardware.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
pub struct Measured {
    /// Largest force commanded during the trial (N).
    pub peak_force_n: f64,
    /// Largest handle speed (m/s).
    pub peak_speed_m_s: f64,
    /// Deepest penetration into the wall (m).
    pub penetration_m: f64,
}

/// A finished trial, as the agent reports it (and keeps in its outbox
/// until acknowledged).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TrialResult {
    /// The epoch the trial was sent with.
    pub epoch: u64,
    pub trial_id: String,
    pub point: Point,
    pub measured: Measured,
}

/// Limits the server sends with a trial; the agent's own limits (its
/// operator's config) and the controller's clamp still apply beneath them.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TrialLimits {
    /// Force the trial may command (N).
    pub force_limit_n: f64,
    /// Abort when the handle moves faster (m/s) …
    pub abort_speed_m_s: f64,
    /// … or penetrates deeper (m).
    pub abort_penetration_m: f64,
}

/// Agent → server. (Messages live for one send or receive: their size
/// does not matter.)
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum AgentMessage {
    /// The first message of every connection.
    Hello {
        rig: String,
        agent: String,
        /// New at every start of the agent process.
        boot: String,
        /// The last epoch this agent held (0: none).
        last_epoch: u64,
        /// The trial it is running now, if any.
        running: Option<String>,
        /// Results sent but not acknowledged (its outbox).
        unacked: Vec<TrialResult>,
        #[serde(flatten)]
        state: RigState,
        capabilities: Capabilities,
    },
    /// Every `heartbeat_ms`, and whenever the rig's state changes.
    Heartbeat {
        epoch: u64,
        #[serde(flatten)]
        state: RigState,
    },
    Result(TrialResult),
    /// The agent will not run this trial.
    Refused {
        epoch: u64,
        trial_id: String,
        code: RefusalCode,
        reason: String,
    },
}

/// Why an agent refuses a trial.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum RefusalCode {
    /// Sent under an epoch that is not the agent's session's.
    StaleEpoch,
    /// It arrived, or would start, after its expiry.
    Expired,
    /// The rig is not armed (disarmed, locked, e-stop, fault).
    NotArmed,
    /// Another trial is running.
    Busy,
    /// Beyond the agent's own, operator-owned limits.
    BeyondLimits,
    /// Started, then ended early: cancelled, stopped (abort, halt) or the
    /// controller's own abort (speed, travel).
    Aborted,
    /// The rig could not run it (the driver failed or is gone).
    Failed,
}

impl RefusalCode {
    /// Whether the trial may be sent again (to a session that can take
    /// it); `beyond_limits` and `failed` fail the experiment instead.
    pub fn transient(self) -> bool {
        !matches!(self, RefusalCode::BeyondLimits | RefusalCode::Failed)
    }
}

/// What a stop does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum StopMode {
    /// Finish the running trial, start nothing new.
    Deferred,
    /// End the running trial now (controlled ramp-down), start nothing new.
    Abort,
    /// Abort and latch: nothing runs until the rig is reset locally.
    Halt,
}

/// Server → agent.
#[allow(clippy::large_enum_variant)]
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "type", rename_all = "snake_case")]
pub enum ServerMessage {
    /// The session is open under `epoch`; heartbeat every `heartbeat_ms`;
    /// the server calls the link lost after `ttl_ms` of silence.
    Welcome {
        epoch: u64,
        heartbeat_ms: u64,
        ttl_ms: u64,
    },
    Trial {
        epoch: u64,
        trial_id: String,
        /// Refuse it if it has not started within this long of arriving.
        expires_in_ms: u64,
        request: TrialRequest,
        limits: TrialLimits,
    },
    /// The result is committed: drop it from the outbox.
    Ack {
        epoch: u64,
        trial_id: String,
    },
    CancelTrial {
        epoch: u64,
        trial_id: String,
    },
    Stop {
        epoch: u64,
        mode: StopMode,
    },
    /// The session is refused or ends; the text says why.
    Error {
        message: String,
    },
}

/// A trial's stable id: experiment, map scope, K and B as bits.
pub fn trial_id(experiment: &str, scope: u32, k: f64, b: f64) -> String {
    format!(
        "{experiment}/{scope}/{:016x}/{:016x}",
        k.to_bits(),
        b.to_bits()
    )
}

/// The parts of a trial id: experiment, scope, K and B (None: not one).
pub fn parse_trial_id(id: &str) -> Option<(&str, u32, f64, f64)> {
    let mut parts = id.split('/');
    let (e, s, k, b) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    if parts.next().is_some() || e.is_empty() || k.len() != 16 || b.len() != 16 {
        return None;
    }
    let bits = |h: &str| u64::from_str_radix(h, 16).ok().map(f64::from_bits);
    Some((e, s.parse().ok()?, bits(k)?, bits(b)?))
}

/// Read one message: size, JSON, version. Err is the reason, in words.
pub fn decode<B: serde::de::DeserializeOwned>(text: &str) -> Result<Envelope<B>, String> {
    if text.len() > MAX_MESSAGE {
        return Err(format!(
            "message of {} bytes: at most {MAX_MESSAGE}",
            text.len()
        ));
    }
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    if let Some(d) = crate::error::duplicate_key(text.as_bytes()) {
        return Err(d.error("").to_string());
    }
    match v.get("v").and_then(|v| v.as_u64()) {
        Some(n) if n == u64::from(VERSION) => {}
        Some(n) => {
            return Err(format!(
                "protocol version v = {n}: this server speaks {VERSION}"
            ))
        }
        None => return Err("no protocol version: every message has \"v\": 1".into()),
    }
    serde_json::from_value(v).map_err(|e| format!("unreadable message: {e}"))
}

/// Write one message.
pub fn encode<B: Serialize>(seq: u64, body: &B) -> String {
    serde_json::to_string(&Envelope {
        v: VERSION,
        seq,
        body,
    })
    .unwrap_or_default()
}

#[derive(utoipa::OpenApi)]
#[openapi(components(schemas(
    AgentMessage,
    ServerMessage,
    TrialResult,
    TrialLimits,
    Measured,
    Capabilities,
    RigState,
    RefusalCode,
    StopMode,
    TrialRequest
)))]
struct ProtocolDoc;

/// The message set as JSON Schemas (`zwidth openapi --agent-protocol`;
/// committed as `api/agent-protocol.json`, kept from drifting by a test).
pub fn schema_json() -> String {
    use utoipa::OpenApi;
    let doc = ProtocolDoc::openapi();
    let v = serde_json::json!({
        "title": "zwidth agent protocol",
        "version": VERSION,
        "transport": "WebSocket text messages on GET /v1/agent; the agent dials out with Authorization: Bearer <agent token>",
        "envelope": {
            "description": "every message is one JSON object: {\"v\": 1, \"seq\": n, \"type\": ..., ...}; seq counts the sender's messages on the connection from 1; at most 262144 bytes",
            "required": ["v", "seq", "type"],
        },
        "agent_to_server": {"$ref": "#/components/schemas/AgentMessage"},
        "server_to_agent": {"$ref": "#/components/schemas/ServerMessage"},
        "sequence": [
            "agent: hello (its state, capabilities, the trial it runs, its unacknowledged results)",
            "server: welcome (epoch, heartbeat_ms, ttl_ms) or error, then close",
            "server: ack for each unacknowledged result, once committed (stored, or audited when stale)",
            "server: trial (under the epoch; expires_in_ms) -> agent: result (the trial's epoch) or refused (code) -> server: ack after commit",
            "agent: heartbeat every heartbeat_ms (and on a state change); server: WebSocket pings",
            "server: cancel_trial, stop (deferred | abort | halt); nothing the server sends can raise the agent's own limits",
        ],
        "components": doc.components,
    });
    serde_json::to_string_pretty(&v).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_committed_protocol_document_is_the_generated_one() {
        // Regenerate with: cargo run -- openapi --agent-protocol > api/agent-protocol.json
        let committed = include_str!("../../api/agent-protocol.json");
        assert_eq!(committed.trim_end(), schema_json().trim_end());
    }

    #[test]
    fn messages_are_read_with_their_version_and_size_checked() {
        let hb = encode(
            7,
            &AgentMessage::Heartbeat {
                epoch: 3,
                state: RigState::Armed,
            },
        );
        assert_eq!(
            hb,
            r#"{"v":1,"seq":7,"type":"heartbeat","epoch":3,"state":"armed"}"#
        );
        let back: Envelope<AgentMessage> = decode(&hb).unwrap();
        assert_eq!(back.seq, 7);
        let wrong = hb.replace(r#""v":1"#, r#""v":2"#);
        assert!(decode::<AgentMessage>(&wrong)
            .unwrap_err()
            .contains("v = 2"));
        let none = hb.replace(r#""v":1,"#, "");
        assert!(decode::<AgentMessage>(&none)
            .unwrap_err()
            .contains("no protocol version"));
        let big = format!(
            r#"{{"v":1,"seq":1,"type":"heartbeat","epoch":1,"state":"armed","x":"{}"}}"#,
            "a".repeat(MAX_MESSAGE)
        );
        assert!(decode::<AgentMessage>(&big)
            .unwrap_err()
            .contains("at most"));
        assert!(decode::<AgentMessage>("{")
            .unwrap_err()
            .contains("not JSON"));
        assert!(decode::<AgentMessage>(r#"{"v":1,"seq":1,"type":"launch"}"#)
            .unwrap_err()
            .contains("unreadable"));
    }

    #[test]
    fn a_trial_id_names_its_experiment_scope_and_wall_exactly() {
        // The IEEE-754 bits as Python writes them: struct.pack(">d", 1488.24).hex().
        let id = trial_id("0193-ab", 2, 1488.24, -0.1);
        assert_eq!(id, "0193-ab/2/409740f5c28f5c29/bfb999999999999a");
        assert_eq!(parse_trial_id(&id), Some(("0193-ab", 2, 1488.24, -0.1)));
        for bad in [
            "",
            "a/b",
            "e/x/409740f5c28f5c29/bfb999999999999a",
            "e/1/4097/bfb999999999999a",
            "e/1/409740f5c28f5c29/bfb999999999999a/x",
            "/1/409740f5c28f5c29/bfb999999999999a",
        ] {
            assert_eq!(parse_trial_id(bad), None, "{bad}");
        }
    }

    #[test]
    fn impossible_capabilities_are_refused_naming_the_field() {
        let ok = Capabilities::bench();
        assert!(ok.validate().is_ok());
        let field = |c: Capabilities| c.validate().unwrap_err().field;
        assert_eq!(
            field(Capabilities {
                peak_force_n: -1.0,
                ..ok.clone()
            }),
            "capabilities.peak_force_n"
        );
        assert_eq!(
            field(Capabilities {
                speed_m_s: f64::NAN,
                ..ok.clone()
            }),
            "capabilities.speed_m_s"
        );
        assert_eq!(
            field(Capabilities {
                sample_hz: vec![0.0],
                ..ok.clone()
            }),
            "capabilities.sample_hz"
        );
        assert_eq!(
            field(Capabilities {
                sample_hz: vec![],
                ..ok.clone()
            }),
            "capabilities.sample_hz"
        );
        assert_eq!(
            field(Capabilities {
                continuous_force_n: 20.0,
                ..ok.clone()
            }),
            "capabilities.continuous_force_n"
        );
        assert_eq!(
            field(Capabilities {
                probes: vec!["laser".into()],
                ..ok.clone()
            }),
            "capabilities.probes"
        );
        assert_eq!(
            field(Capabilities {
                estimators: vec![],
                ..ok
            }),
            "capabilities.estimators"
        );
    }
}
