//! The hardware boundary of `zwidth agent`: a [`Driver`] runs one trial on
//! the rig and says what state the rig is in. Two come with zwidth: the
//! simulated plant ([`SimDriver`], `--sim`) and [`StdioDriver`], which
//! talks line-oriented JSON to a child process, so a controller in any
//! language can be the rig (docs/rigs.md has the protocol and a Python
//! example).

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use serde::{Deserialize, Serialize};

use crate::rig::protocol::{Capabilities, Measured, TrialLimits};
use crate::zwidth::hit::{wall_hit, Recorder, TraceRow};
use crate::zwidth::search::Point;
use crate::zwidth::settings::Method;
use crate::zwidth::trial::{self, TrialRequest};

/// A rig, as the agent drives it. Calls come from one thread at a time.
pub trait Driver: Send {
    /// What the rig can do (sent in `hello`).
    fn capabilities(&self) -> Capabilities;
    /// Run one trial within `limits` (the controller clamps force to
    /// `limits.force_limit_n` and aborts past the speed and penetration
    /// limits); stop early when `cancel` turns true (Err: aborted).
    fn run(
        &mut self,
        request: &TrialRequest,
        limits: &TrialLimits,
        cancel: &AtomicBool,
    ) -> Result<(Point, Measured), String>;
}

/// The simulated plant of the trial's own scene (what the server would
/// compute in process), paced to take at least `trial_ms`; with `device`,
/// that device in place of the scene's (hardware that differs from its
/// model, `zwidth agent --sim --sim-device FILE`).
pub struct SimDriver {
    pub capabilities: Capabilities,
    pub trial_ms: u64,
    pub device: Option<crate::zwidth::scene::DeviceSpec>,
}

/// Peak force, speed and penetration over a simulated wall hit.
#[derive(Default)]
struct Peaks(Measured);

impl Recorder for Peaks {
    fn record(&mut self, row: TraceRow) {
        let m = &mut self.0;
        m.peak_force_n = m.peak_force_n.max(row.force.abs());
        m.peak_speed_m_s = m.peak_speed_m_s.max(row.v.abs());
        if row.force != 0.0 {
            m.penetration_m = m.penetration_m.max(row.x.abs());
        }
    }
}

impl Driver for SimDriver {
    /// As configured, with this build's estimator library: the simulator
    /// runs zwidth-dsp itself, whatever `--capabilities` said.
    fn capabilities(&self) -> Capabilities {
        Capabilities {
            dsp: Some(crate::rig::protocol::DspIdentity::ours()),
            ..self.capabilities.clone()
        }
    }

    fn run(
        &mut self,
        request: &TrialRequest,
        limits: &TrialLimits,
        cancel: &AtomicBool,
    ) -> Result<(Point, Measured), String> {
        let start = Instant::now();
        let simulated;
        let request = match &self.device {
            Some(device) => {
                let mut r = request.clone();
                r.scene.device = device.clone();
                simulated = r;
                &simulated
            }
            None => request,
        };
        let point = trial::run(request).map_err(|e| e.to_string())?;
        // What the hardware would have measured: one wall hit's peaks (the
        // verdict's own hits for the time engine; the force bound for a
        // probe).
        let mut peaks = Peaks::default();
        if request.method == Method::Time {
            let scene = request.scene.validate().map_err(|e| e.to_string())?;
            let res = request
                .accuracy
                .resolve(&scene)
                .map_err(|e| e.to_string())?;
            wall_hit(&scene, request.k, request.b, res.hit, &mut peaks);
        }
        peaks.0.peak_force_n = peaks.0.peak_force_n.min(limits.force_limit_n);
        while start.elapsed() < Duration::from_millis(self.trial_ms) {
            if cancel.load(Ordering::Relaxed) {
                return Err("aborted".into());
            }
            std::thread::sleep(Duration::from_millis(5));
        }
        if cancel.load(Ordering::Relaxed) {
            return Err("aborted".into());
        }
        Ok((point, peaks.0))
    }
}

/// One line to the driver process.
#[derive(Serialize)]
#[serde(tag = "type", rename_all = "snake_case")]
enum ToDriver<'a> {
    Capabilities,
    Trial {
        request: &'a TrialRequest,
        limits: &'a TrialLimits,
    },
    Abort,
}

/// One line from the driver process.
#[derive(Deserialize)]
#[serde(tag = "type", rename_all = "snake_case")]
enum FromDriver {
    Capabilities(Capabilities),
    Result { point: Point, measured: Measured },
    Error { message: String },
}

/// A rig behind a child process speaking one JSON object per line on its
/// stdin and stdout (docs/rigs.md, "the driver protocol"). Its answers
/// are read on a thread of their own, so a trial can be aborted while the
/// driver runs it.
pub struct StdioDriver {
    child: Child,
    to: ChildStdin,
    lines: std::sync::mpsc::Receiver<String>,
    capabilities: Capabilities,
}

impl StdioDriver {
    /// Start `command` (run by `sh -c`) and ask for its capabilities.
    pub fn start(command: &str) -> Result<Self, String> {
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(command)
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .spawn()
            .map_err(|e| format!("--driver {command:?} cannot start: {e}"))?;
        let to = child.stdin.take().ok_or("no stdin")?;
        let from: ChildStdout = child.stdout.take().ok_or("no stdout")?;
        let (tx, lines) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for line in BufReader::new(from).lines() {
                let Ok(line) = line else { break };
                if tx.send(line).is_err() {
                    break;
                }
            }
        });
        let mut d = Self {
            child,
            to,
            lines,
            capabilities: Capabilities::bench(),
        };
        d.say(&ToDriver::Capabilities)?;
        match d.answer(None)? {
            FromDriver::Capabilities(c) => {
                c.validate()
                    .map_err(|e| format!("the driver's capabilities: {e}"))?;
                d.capabilities = c;
                Ok(d)
            }
            _ => Err("the driver must answer capabilities first".into()),
        }
    }

    fn say(&mut self, msg: &ToDriver) -> Result<(), String> {
        let line = serde_json::to_string(msg).map_err(|e| e.to_string())?;
        writeln!(self.to, "{line}")
            .and_then(|_| self.to.flush())
            .map_err(|e| format!("the driver is gone: {e}"))
    }

    /// The next answer; with `cancel`, an abort is sent (once) when it
    /// turns true, and the answer to the trial is still awaited.
    fn answer(&mut self, cancel: Option<&AtomicBool>) -> Result<FromDriver, String> {
        use std::sync::mpsc::RecvTimeoutError;
        let mut aborted = false;
        loop {
            match self.lines.recv_timeout(Duration::from_millis(10)) {
                Ok(line) => {
                    return serde_json::from_str(&line).map_err(|e| {
                        format!("the driver's answer is not a message: {e}: {line:?}")
                    })
                }
                Err(RecvTimeoutError::Timeout) => {
                    if !aborted && cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
                        self.say(&ToDriver::Abort)?;
                        aborted = true;
                    }
                }
                Err(RecvTimeoutError::Disconnected) => {
                    return Err("the driver closed its output".into())
                }
            }
        }
    }
}

impl Drop for StdioDriver {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

impl Driver for StdioDriver {
    fn capabilities(&self) -> Capabilities {
        self.capabilities.clone()
    }

    fn run(
        &mut self,
        request: &TrialRequest,
        limits: &TrialLimits,
        cancel: &AtomicBool,
    ) -> Result<(Point, Measured), String> {
        if cancel.load(Ordering::Relaxed) {
            return Err("aborted before it started".into());
        }
        self.say(&ToDriver::Trial { request, limits })?;
        match self.answer(Some(cancel))? {
            FromDriver::Result { point, measured } if !cancel.load(Ordering::Relaxed) => {
                Ok((point, measured))
            }
            FromDriver::Result { .. } => Err("aborted".into()),
            FromDriver::Error { message } => Err(message),
            FromDriver::Capabilities(_) => {
                Err("the driver answered a trial with capabilities".into())
            }
        }
    }
}
