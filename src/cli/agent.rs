//! `zwidth agent`: read the flags, start the driver, run the agent.

use std::path::Path;

use super::{CliError, Command};
use crate::agent::{self, AgentConfig, Driver, Faults, LocalLimits, SimDriver, StdioDriver};
use crate::rig::protocol::Capabilities;

fn read_json<T: serde::de::DeserializeOwned>(flag: &str, path: &Path) -> Result<T, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Input(format!("{flag} {} cannot be read: {e}", path.display())))?;
    serde_json::from_str(&text)
        .map_err(|e| CliError::Input(format!("{flag} {}: {e}", path.display())))
}

pub(super) fn run(command: Command) -> Result<(), CliError> {
    let Command::Agent {
        sim,
        driver,
        server,
        ca_file,
        rig,
        name,
        token_file,
        outbox,
        pace,
        trial_ms,
        capabilities,
        sim_device,
        faults,
        max_force_n,
        max_k,
        max_b,
        max_speed_m_s,
        max_penetration_m,
    } = command
    else {
        unreachable!("called for the agent command")
    };
    crate::rig::check_id("--rig", &rig).map_err(|e| CliError::Input(e.to_string()))?;
    super::common::check_server(&server)?;
    let tls = crate::tls::client_config(crate::tls::ca_file(ca_file).as_deref())
        .map_err(CliError::Input)?;
    for (flag, v) in [
        ("--max-force-n", max_force_n),
        ("--max-k", max_k),
        ("--max-b", max_b),
    ] {
        if v.is_nan() || v <= 0.0 {
            return Err(CliError::Input(format!("{flag} = {v}: must be > 0")));
        }
    }
    let token = match (&token_file, std::env::var("ZWIDTH_AGENT_TOKEN")) {
        (Some(f), _) => std::fs::read_to_string(f).map_err(|e| {
            CliError::Input(format!("--token-file {} cannot be read: {e}", f.display()))
        })?,
        (None, Ok(t)) => t,
        (None, Err(_)) => std::fs::read_to_string("zwidth.db.agent-token").map_err(|_| {
            CliError::Input(
                "no agent token: pass --token-file (serve writes <db>.agent-token) or set ZWIDTH_AGENT_TOKEN".into(),
            )
        })?,
    };
    let token = token.trim().to_string();
    if token.is_empty() {
        return Err(CliError::Input("the agent token is empty".into()));
    }
    let driver: Box<dyn Driver> = match (sim, driver) {
        (true, _) => {
            let capabilities: Capabilities = match &capabilities {
                Some(p) => read_json("--capabilities", p)?,
                None => Capabilities::bench(),
            };
            capabilities
                .validate()
                .map_err(|e| CliError::Input(format!("--capabilities: {e}")))?;
            let trial_ms = trial_ms.unwrap_or(if pace == "realtime" { 10_000 } else { 0 });
            let device = match &sim_device {
                Some(p) => {
                    let scene = super::common::read_scene_of("--sim-device", p)?;
                    scene.validate().map_err(|e| {
                        CliError::Input(format!("--sim-device {}: {e}", p.display()))
                    })?;
                    Some(scene.device)
                }
                None => None,
            };
            Box::new(SimDriver {
                capabilities,
                trial_ms,
                device,
            })
        }
        (false, Some(cmd)) => Box::new(StdioDriver::start(&cmd).map_err(CliError::Input)?),
        (false, None) => {
            return Err(CliError::Input(
                "say what runs the trials: --sim (the simulated plant) or --driver COMMAND".into(),
            ))
        }
    };
    let faults: Faults = match &faults {
        Some(p) => read_json("--faults", p)?,
        None => Faults::default(),
    };
    let cfg = AgentConfig {
        agent: name.unwrap_or_else(|| {
            format!(
                "{}-{}",
                std::env::var("HOSTNAME").unwrap_or_else(|_| "agent".into()),
                std::process::id()
            )
        }),
        outbox: outbox.unwrap_or_else(|| format!("{rig}.outbox").into()),
        server,
        rig,
        token,
        tls,
        limits: LocalLimits {
            max_force_n,
            max_k,
            max_b,
            max_speed_m_s,
            max_penetration_m,
        },
        faults,
    };
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
    rt.block_on(agent::run(cfg, driver))
        .map_err(CliError::Input)
}
