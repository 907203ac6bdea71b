//! The CLI client of a running service: submit, status, watch (a progress
//! bar), results (JSON, CSV of the points, the map plot). Blocking HTTP
//! (ureq); `--server` or `ZWIDTH_SERVER`, token from `ZWIDTH_TOKEN`.

use serde_json::Value;
use std::io::Write;
use std::time::{Duration, Instant};

use crate::error::CliError;

pub struct Client {
    pub server: String,
    pub token: Option<String>,
    /// Whom an https:// server may be (`tls::client_config`).
    tls: std::sync::Arc<rustls::ClientConfig>,
    http: ureq::Agent,
}

fn failure(e: impl std::fmt::Display) -> CliError {
    CliError::Failure(e.to_string())
}

impl Client {
    /// A client of `server` (http:// or https://) trusting `tls`'s roots.
    pub fn new(
        server: &str,
        token: Option<String>,
        tls: std::sync::Arc<rustls::ClientConfig>,
    ) -> Self {
        Self {
            server: server.trim_end_matches('/').to_string(),
            token,
            http: Self::agent(&tls),
            tls,
        }
    }

    /// A new connection pool of its own.
    fn agent(tls: &std::sync::Arc<rustls::ClientConfig>) -> ureq::Agent {
        ureq::AgentBuilder::new().tls_config(tls.clone()).build()
    }

    fn call(&self, req: ureq::Request, body: Option<&str>) -> Result<Value, CliError> {
        let text = self.call_text(req, body)?;
        serde_json::from_str(&text).map_err(failure)
    }

    /// The response body as text; a 4xx is bad input (exit 2), anything
    /// else that fails is a failure.
    fn call_text(&self, req: ureq::Request, body: Option<&str>) -> Result<String, CliError> {
        let req = match &self.token {
            Some(t) => req.set("authorization", &format!("Bearer {t}")),
            None => req,
        };
        let resp = match body {
            Some(b) => req.set("content-type", "application/json").send_string(b),
            None => req.call(),
        };
        match resp {
            Ok(r) => r.into_string().map_err(failure),
            Err(ureq::Error::Status(code, r)) => {
                let v: Value = r.into_json().unwrap_or_default();
                let detail = v["detail"].as_str().unwrap_or("no detail").to_string();
                // The server refused the input: exit 2, as for local bad input.
                if (400..500).contains(&code) {
                    Err(CliError::Input(format!("server said {code}: {detail}")))
                } else {
                    Err(CliError::Failure(format!("server said {code}: {detail}")))
                }
            }
            Err(e) => Err(CliError::Failure(format!(
                "cannot reach {}: {e}",
                self.server
            ))),
        }
    }

    pub fn submit(
        &self,
        body: &str,
        priority: i64,
        key: Option<&str>,
        rig: Option<&str>,
    ) -> Result<Value, CliError> {
        let mut req = self
            .http
            .post(&format!("{}/v1/experiments", self.server))
            .query("priority", &priority.to_string());
        if let Some(r) = rig {
            req = req.query("rig", r);
        }
        if let Some(k) = key {
            req = req.set("idempotency-key", k);
        }
        self.call(req, Some(body))
    }

    /// Issue attached rig `rig` a new agent credential of its own.
    pub fn agent_token(&self, rig: &str) -> Result<Value, CliError> {
        self.call(
            self.http
                .post(&format!("{}/v1/rigs/{rig}/agent-token", self.server)),
            None,
        )
    }

    pub fn status(&self, id: &str) -> Result<Value, CliError> {
        self.call(
            self.http
                .get(&format!("{}/v1/experiments/{id}", self.server)),
            None,
        )
    }

    /// A succeeded experiment's `plot.svg` or `points.csv`, made by the server.
    pub fn export(&self, id: &str, file: &str) -> Result<String, CliError> {
        self.call_text(
            self.http
                .get(&format!("{}/v1/experiments/{id}/{file}", self.server)),
            None,
        )
    }

    /// Poll until the experiment ends, drawing a progress bar on stderr.
    pub fn watch(&self, id: &str) -> Result<Value, CliError> {
        let start = Instant::now();
        let mut err = std::io::stderr();
        let spin = ['|', '/', '-', '\\'];
        let mut i = 0usize;
        loop {
            let v = self.status(id)?;
            let state = v["state"].as_str().unwrap_or("?").to_string();
            let trials = v["progress"]["trials_done"].as_i64().unwrap_or(0);
            let fraction = v["progress"]["fraction"]
                .as_f64()
                .unwrap_or(0.0)
                .clamp(0.0, 1.0);
            let eta = v["progress"]["eta_s"]
                .as_f64()
                .map_or("     ".to_string(), |e| format!("ETA {e:>5.0} s"));
            let t = start.elapsed().as_secs_f64();
            let filled = (fraction * 30.0).round() as usize;
            let _ = write!(
                err,
                "\r{} {state:<10} [{}{}] {:>3.0} % {trials:>7} trials {t:>7.1} s {eta} ",
                spin[i % 4],
                "#".repeat(filled),
                ".".repeat(30 - filled),
                100.0 * fraction
            );
            let _ = err.flush();
            i += 1;
            if matches!(
                state.as_str(),
                "succeeded" | "failed" | "cancelled" | "interrupted"
            ) {
                let _ = writeln!(err);
                return Ok(v);
            }
            std::thread::sleep(Duration::from_millis(250));
        }
    }
}

/// What `zwidth bench service` measured.
#[derive(Debug, serde::Serialize)]
pub struct ServiceBench {
    pub submissions: usize,
    pub submit_s: f64,
    pub gets: usize,
    pub get_rate_target: f64,
    pub get_rate_achieved: f64,
    pub get_p50_ms: f64,
    pub get_p99_ms: f64,
    pub get_max_ms: f64,
    pub busy_experiment: String,
    /// From the cancel request to the running simulation having stopped
    /// (the experiment's `finished_ms` as the runner records it); null if
    /// it was no longer running when cancelled.
    pub cancel_to_stop_ms: Option<f64>,
    /// The long experiment was still running when the GETs ended.
    pub busy_throughout: bool,
}

impl Client {
    /// Against a running service: submit `n` small experiments as fast as
    /// possible; then, while a long experiment runs on the server, GET an
    /// experiment at `rate` requests/s for `seconds` from two threads and
    /// record the latencies.
    pub fn bench(&self, n: usize, rate: f64, seconds: f64) -> Result<ServiceBench, CliError> {
        let small = r#"{"kind":"map","scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"criterion":"strict_passivity","b":[0]}"#;
        let t = Instant::now();
        let mut last = String::new();
        for _ in 0..n {
            last = self.submit(small, -1, None, None)?["id"]
                .as_str()
                .unwrap_or_default()
                .to_string();
        }
        let submit_s = t.elapsed().as_secs_f64();
        // A long experiment keeps the other core busy during the GETs.
        // A sweep of reference-accuracy time-domain traces: it outlasts the
        // GETs, so they are all measured while the other core simulates.
        let long = r#"{"kind":"sweep","map":{"scene":{"loop":{"sample_hz":10000,"render_hz":1000},"estimator":{"kind":"butterworth","cutoff_hz":100}},"method":"time","criterion":"stability","search":"trace","accuracy":"reference"},
                       "parameter":{"path":"estimator.cutoff_hz","min":100,"max":1000,"count":20}}"#;
        let busy = self.submit(long, 10, None, None)?["id"]
            .as_str()
            .unwrap_or_default()
            .to_string();
        let deadline = Instant::now() + Duration::from_secs(30);
        while self.status(&busy)?["state"] != "running" && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let url = format!("{}/v1/experiments/{last}", self.server);
        let per_thread = rate / 2.0;
        let total = (seconds * per_thread) as usize;
        let lat: Vec<f64> = std::thread::scope(|s| {
            let hs: Vec<_> = (0..2)
                .map(|_| {
                    let url = url.clone();
                    let agent = Self::agent(&self.tls);
                    s.spawn(move || {
                        let start = Instant::now();
                        let mut v = Vec::with_capacity(total);
                        for i in 0..total {
                            let due = start + Duration::from_secs_f64(i as f64 / per_thread);
                            if let Some(w) = due.checked_duration_since(Instant::now()) {
                                std::thread::sleep(w);
                            }
                            let t = Instant::now();
                            if agent.get(&url).call().is_ok() {
                                v.push(t.elapsed().as_secs_f64() * 1e3);
                            }
                        }
                        (v, start.elapsed().as_secs_f64())
                    })
                })
                .collect();
            let mut all = Vec::new();
            for h in hs {
                if let Ok((v, _)) = h.join() {
                    all.extend(v);
                }
            }
            all
        });
        let busy_throughout = self.status(&busy)?["state"] == "running";
        let cancel_ms = crate::store::now_ms();
        let _ = self.call(
            self.http
                .post(&format!("{}/v1/experiments/{busy}/cancel", self.server)),
            None,
        );
        // The runner rewrites finished_ms when the simulation has stopped.
        std::thread::sleep(Duration::from_millis(1000));
        let stopped = self.status(&busy)?["finished_ms"].as_i64();
        let mut sorted = lat.clone();
        sorted.sort_by(f64::total_cmp);
        let pct = |p: f64| {
            sorted
                .get(((sorted.len() as f64 - 1.0) * p).round() as usize)
                .copied()
                .unwrap_or(f64::NAN)
        };
        Ok(ServiceBench {
            submissions: n,
            submit_s,
            gets: sorted.len(),
            get_rate_target: rate,
            get_rate_achieved: sorted.len() as f64 / seconds,
            get_p50_ms: pct(0.5),
            get_p99_ms: pct(0.99),
            get_max_ms: sorted.last().copied().unwrap_or(f64::NAN),
            busy_experiment: busy,
            cancel_to_stop_ms: stopped
                .filter(|_| busy_throughout)
                .map(|t| (t - cancel_ms) as f64),
            busy_throughout,
        })
    }
}
