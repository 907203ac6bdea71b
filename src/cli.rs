//! The `zwidth` command line: parse, call the library, print. Bad input
//! exits with code 2 and one line naming the problem; I/O failures exit 1.

use std::io::{BufRead, BufWriter, Write};
use std::path::PathBuf;

use clap::{Parser, Subcommand};

use crate::accuracy::{self, AccuracyConfig};
use crate::error::SpecError;
use crate::estimators::{EstimatorKind, EstimatorSpec, Sampling, VelocityEstimator};
use crate::lipschitz;
use crate::plot::{loglog_svg, Series};
use crate::plot::{zwidth_map_svg, MapPlotPoint};
use crate::zwidth::compare;
use crate::zwidth::hit::{wall_hit, HitKnobs, NoTrace, TraceRow};
use crate::zwidth::scene::{validate_wall, SceneSpec};
use crate::zwidth::search::{map_observed, Evaluator, MapResult, Observer};
use crate::zwidth::settings::{
    Accuracy, AccuracyKnobs, Criterion, MapSpec, Method, Preset, SearchKind,
};
use crate::zwidth::tradeoff;

/// Default encoder step (m): the 1 µm encoder of the papers' device.
pub const DEFAULT_QUANTIZATION: f64 = 1e-6;

#[derive(Parser, Debug)]
#[command(
    name = "zwidth",
    version,
    about = "Velocity estimators and Z-width of haptic devices (SI units throughout)"
)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Estimate velocity: positions (m, one per line) on stdin, velocities (m/s) on stdout.
    Estimate {
        /// Sample rate (Hz).
        #[arg(long)]
        rate: f64,
        /// Estimator spec as JSON, e.g. '{"kind":"butterworth","cutoff_hz":100}'.
        #[arg(long)]
        estimator: String,
        /// Encoder quantization step d (m); sets Kalman r = d²/3 and the FOAW band.
        #[arg(long, default_value_t = DEFAULT_QUANTIZATION)]
        quantization: f64,
    },
    /// The 2011 paper's Fig. 2 study: RMS derivative error of every estimator vs sample rate.
    Accuracy {
        /// Sample rates (Hz), comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = [1e3, 2e3, 5e3, 1e4, 2e4, 5e4, 1e5])]
        rates: Vec<f64>,
        /// Print JSON instead of the table.
        #[arg(long)]
        json: bool,
        /// Also write the error-vs-rate plot here.
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Encoder quantization step (m).
        #[arg(long, default_value_t = DEFAULT_QUANTIZATION)]
        quantization: f64,
    },
    /// Estimate the Lipschitz constant C (bound on |acceleration|, m/s²) of a position trace on stdin.
    Lipschitz {
        /// Sample rate (Hz).
        #[arg(long)]
        rate: f64,
        /// Encoder quantization step (m), if known; otherwise the noise is estimated from the data.
        #[arg(long)]
        quantization: Option<f64>,
        #[arg(long)]
        json: bool,
    },
    /// One wall hit (time domain, 2011 paper §2.4).
    Trial {
        /// Scene JSON file.
        #[arg(long)]
        scene: PathBuf,
        /// Wall stiffness K (N/m).
        #[arg(long)]
        k: f64,
        /// Wall damping B (N·s/m).
        #[arg(long, allow_negative_numbers = true)]
        b: f64,
        #[arg(long)]
        json: bool,
        /// Write the trace here: t, true and measured position, estimated and true velocity, force.
        #[arg(long)]
        trace: Option<PathBuf>,
    },
    /// Impedance of the rendered wall over the probe band (analytic when the scene is linear, else simulated).
    Impedance {
        #[arg(long)]
        scene: PathBuf,
        #[arg(long)]
        k: f64,
        #[arg(long, allow_negative_numbers = true)]
        b: f64,
        /// auto | analytic | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
    },
    /// Z-width map: the (K, B) region the scene renders.
    Map {
        #[arg(long)]
        scene: PathBuf,
        /// auto | analytic | time | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// stability | impedance | strict_passivity
        #[arg(long, default_value = "impedance")]
        criterion: String,
        /// trace | bisect | robust_bisect | grid
        #[arg(long, default_value = "bisect")]
        search: String,
        /// Only these damping values (N·s/m), comma-separated.
        #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
        b: Option<Vec<f64>>,
        /// Relative K resolution of the bisection (overrides the accuracy preset).
        #[arg(long)]
        k_rel_tol: Option<f64>,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
        /// Write the Fig. 7-style plot here.
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// Tune the scene's estimator parameters (argmin) for an objective.
    Tune {
        #[arg(long)]
        scene: PathBuf,
        /// Parameters with bounds, e.g. '{"cutoff_hz":{"min":10,"max":500}}',
        /// '{"q":{"min":1e2,"max":1e8,"scale":"log"}}'.
        #[arg(long)]
        params: String,
        /// k_width | b_width | max_fidelity_error | area, or JSON:
        /// '{"weighted":{"k_width":1e-5,"b_width":1e-2}}', '{"pareto":["k_width","max_fidelity_error"]}'.
        #[arg(long)]
        objective: String,
        /// auto | analytic | time | frequency
        #[arg(long, default_value = "auto")]
        method: String,
        /// stability | impedance | strict_passivity
        #[arg(long, default_value = "impedance")]
        criterion: String,
        /// robust_bisect | bisect | trace | grid: how each map searches.
        #[arg(long, default_value = "robust_bisect")]
        search: String,
        /// auto | brent | golden | nelder_mead | particle_swarm | grid | halton
        #[arg(long, default_value = "auto")]
        solver: String,
        #[arg(long, default_value_t = 0)]
        seed: u64,
        /// Accuracy while searching: draft | standard | reference.
        #[arg(long, default_value = "draft")]
        accuracy: String,
        /// Accuracy the finalists are re-evaluated at.
        #[arg(long, default_value = "reference")]
        final_accuracy: String,
        #[arg(long, default_value_t = 3)]
        finalists: usize,
        #[arg(long, default_value_t = 40)]
        max_evaluations: usize,
        /// levant | lyapunov (Levant gains only).
        #[arg(long)]
        constraint: Option<String>,
        /// Only these damping values (N·s/m), comma-separated.
        #[arg(long, value_delimiter = ',', allow_negative_numbers = true)]
        b: Option<Vec<f64>>,
        #[arg(long)]
        json: bool,
        /// Plot of the objective over evaluations (or the Pareto front).
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Every evaluation as CSV.
        #[arg(long)]
        csv: Option<PathBuf>,
    },
    /// Every estimator on one scene, as the 2018 paper's Table I.
    Compare {
        /// Scene JSON file (default: the 2018 paper's simulated device at 1 kHz).
        scene: Option<PathBuf>,
        /// draft | standard | reference
        #[arg(long, default_value = "standard")]
        accuracy: String,
        #[arg(long)]
        json: bool,
        /// Write one map plot per estimator into this directory.
        #[arg(long)]
        svg_dir: Option<PathBuf>,
    },
    /// Run the HTTP service: queue experiments, run them, store every run in SQLite.
    Serve {
        /// SQLite database file (created and migrated on first start).
        #[arg(long, env = "ZWIDTH_DB", default_value = "zwidth.db")]
        db: PathBuf,
        /// Address to listen on; port 0 picks a free one (printed on start).
        #[arg(long, env = "ZWIDTH_BIND", default_value = "127.0.0.1:8080")]
        bind: String,
        /// Bearer tokens that may submit and cancel (comma-separated); required beyond loopback.
        #[arg(
            long = "token",
            env = "ZWIDTH_TOKENS",
            value_delimiter = ',',
            hide_env_values = true
        )]
        tokens: Vec<String>,
        /// A file with the bearer tokens, one per line (keeps them out of `ps`
        /// and the shell history; prefer this or ZWIDTH_TOKENS to --token).
        #[arg(long, env = "ZWIDTH_TOKEN_FILE")]
        token_file: Option<PathBuf>,
        /// Another origin that may write (e.g. a dashboard behind a proxy:
        /// https://lab.example); the server's own origin always may.
        #[arg(
            long = "allow-origin",
            env = "ZWIDTH_ALLOW_ORIGINS",
            value_delimiter = ','
        )]
        allow_origins: Vec<String>,
        /// Simulated rigs, NAME[:THREADS] comma-separated (0 threads: one per core); the first is the default.
        #[arg(long, env = "ZWIDTH_RIGS", default_value = "sim:0")]
        rigs: String,
        /// Longest a request may take before a 503 (s).
        #[arg(long, env = "ZWIDTH_REQUEST_TIMEOUT_S", default_value_t = 30.0)]
        request_timeout_s: f64,
    },
    /// Submit an experiment JSON file to a running service; prints its id.
    Submit {
        file: PathBuf,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long, default_value_t = 0, allow_negative_numbers = true)]
        priority: i64,
        #[arg(long)]
        idempotency_key: Option<String>,
        /// Rig to run on (see GET /v1/rigs); default the server's first.
        #[arg(long)]
        rig: Option<String>,
        #[arg(long)]
        json: bool,
    },
    /// Show an experiment's state and progress (JSON).
    Status {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
    },
    /// Follow an experiment with a progress line until it ends (exit 1 unless it succeeded).
    Watch {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
    },
    /// Fetch a finished experiment's result: JSON on stdout, or points as CSV, or the plot.
    Results {
        id: String,
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long)]
        csv: Option<PathBuf>,
        #[arg(long)]
        svg: Option<PathBuf>,
    },
    /// Print the service's OpenAPI 3.1 description (what api/openapi.json holds).
    Openapi,
    /// A consistent copy of a service's database in one file (SQLite
    /// `VACUUM INTO`), safe while the service runs; restore by starting
    /// `zwidth serve --db` on the copy.
    Backup {
        /// The database to copy.
        #[arg(long, env = "ZWIDTH_DB", default_value = "zwidth.db")]
        db: PathBuf,
        /// The copy to write (must not exist).
        #[arg(long)]
        out: PathBuf,
    },
    /// Measurements: `zwidth bench tradeoff`.
    Bench {
        #[command(subcommand)]
        what: BenchCommand,
    },
    /// Report which convergence conditions a Levant gain pair meets.
    Gains {
        /// A levant estimator spec, e.g. '{"kind":"levant","alpha":13,"lambda":1.58,"lipschitz":12}'.
        #[arg(long)]
        estimator: String,
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand, Debug)]
pub enum BenchCommand {
    /// Against a running service: 1 000 submissions, then GET latency at 500 requests/s while a long experiment runs.
    Service {
        #[arg(long, env = "ZWIDTH_SERVER", default_value = "http://127.0.0.1:8080")]
        server: String,
        #[arg(long, default_value_t = 1000)]
        submissions: usize,
        #[arg(long, default_value_t = 500.0)]
        rate: f64,
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
    },
    /// Tuning on the seed device: Butterworth tuner vs a 1 Hz brute-force scan, Levant tuned vs rule gains.
    Tune {
        /// Accuracy of the Butterworth scan and tune.
        #[arg(long, default_value = "draft")]
        accuracy: String,
        /// Points of the brute-force scan (490: 1 Hz steps over 10–499 Hz); the tuner gets a fifth.
        #[arg(long, default_value_t = 490)]
        scan_points: usize,
        /// Accuracy of the Levant tune.
        #[arg(long, default_value = "standard")]
        levant_accuracy: String,
        /// Evaluations the Levant tune may make.
        #[arg(long, default_value_t = 16)]
        levant_evaluations: usize,
        #[arg(long)]
        json: bool,
    },
    /// Wall time and K/B-width error against `reference` for each accuracy preset, on the example scenes.
    Tradeoff {
        #[arg(long)]
        json: bool,
    },
}

/// What went wrong, and so the exit code.
#[derive(Debug)]
pub enum CliError {
    /// Bad input: exit 2.
    Input(String),
    /// I/O or internal failure: exit 1.
    Failure(String),
}

impl CliError {
    pub fn exit_code(&self) -> i32 {
        match self {
            CliError::Input(_) => 2,
            CliError::Failure(_) => 1,
        }
    }
}

impl std::fmt::Display for CliError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            CliError::Input(m) | CliError::Failure(m) => f.write_str(m),
        }
    }
}

impl From<SpecError> for CliError {
    fn from(e: SpecError) -> Self {
        CliError::Input(e.to_string())
    }
}

fn io(e: std::io::Error) -> CliError {
    CliError::Failure(format!("i/o error: {e}"))
}

/// Read one finite number per non-blank line; the error names the line.
pub fn read_samples(input: impl BufRead) -> Result<Vec<f64>, CliError> {
    let mut out = Vec::new();
    for (i, line) in input.lines().enumerate() {
        let line = line.map_err(io)?;
        let s = line.trim();
        if s.is_empty() {
            continue;
        }
        match s.parse::<f64>() {
            Ok(v) if v.is_finite() => out.push(v),
            _ => {
                return Err(CliError::Input(format!(
                    "stdin line {} = {s:?} is not allowed: each line must be one finite position in metres",
                    i + 1
                )))
            }
        }
    }
    Ok(out)
}

fn client(server: String) -> crate::client::Client {
    crate::client::Client {
        server: server.trim_end_matches('/').to_string(),
        token: std::env::var("ZWIDTH_TOKEN").ok().filter(|t| !t.is_empty()),
    }
}

fn read_scene(path: &std::path::Path) -> Result<SceneSpec, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Input(format!("--scene {} cannot be read: {e}", path.display())))?;
    SceneSpec::from_json(&text).map_err(|e| CliError::Input(format!("{}: {e}", path.display())))
}

/// A snake_case enum value from a flag, with serde's message naming the choices.
/// Run `work` while drawing a progress bar on stderr from `observer` (only
/// when stderr is a terminal).
fn with_progress<T>(
    observer: &std::sync::Arc<crate::zwidth::search::Observer>,
    work: impl FnOnce() -> T,
) -> T {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return work();
    }
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        s.spawn(|| {
            let start = std::time::Instant::now();
            while !done.load(std::sync::atomic::Ordering::Relaxed) {
                let f = observer.fraction();
                let t = start.elapsed().as_secs_f64();
                let eta = if f > 0.01 {
                    format!("ETA {:>5.0} s", t * (1.0 - f) / f)
                } else {
                    String::new()
                };
                let filled = (f * 30.0).round() as usize;
                eprint!(
                    "\r[{}{}] {:>3.0} % {t:>6.1} s {eta}  ",
                    "#".repeat(filled),
                    ".".repeat(30 - filled.min(30)),
                    100.0 * f
                );
                std::thread::sleep(std::time::Duration::from_millis(200));
            }
            eprintln!();
        });
        let r = work();
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        r
    })
}

fn parse_choice<T: serde::de::DeserializeOwned>(flag: &str, value: &str) -> Result<T, CliError> {
    serde_json::from_value(serde_json::Value::String(value.to_string()))
        .map_err(|e| CliError::Input(format!("--{flag} = {value:?} is not allowed: {e}")))
}

fn write_json(out: &mut impl Write, v: &impl serde::Serialize) -> Result<(), CliError> {
    serde_json::to_writer_pretty(&mut *out, v).map_err(|e| CliError::Failure(e.to_string()))?;
    writeln!(out).map_err(io)
}

/// The JSON with `--json`, else the text table.
fn write_either(
    out: &mut impl Write,
    json: bool,
    v: &impl serde::Serialize,
    text: impl FnOnce() -> String,
) -> Result<(), CliError> {
    if json {
        write_json(out, v)
    } else {
        write!(out, "{}", text()).map_err(io)
    }
}

fn write_file(path: &std::path::Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::Failure(format!("cannot write {}: {e}", path.display())))
}

/// The Fig. 7-style plot of a map.
pub fn map_svg(title: &str, r: &MapResult) -> Result<String, CliError> {
    let points: Vec<MapPlotPoint> = r
        .points
        .iter()
        .map(|p| MapPlotPoint {
            b: p.b,
            k: p.k,
            ok: p.ok(),
            fidelity: p.fidelity,
        })
        .collect();
    let boundary: Vec<(f64, f64)> = r.boundary.iter().map(|p| (p.b, p.k_max)).collect();
    let label = if r.criterion == Criterion::Stability {
        "stable"
    } else {
        "passive"
    };
    zwidth_map_svg(title, &points, &boundary, label).map_err(CliError::Failure)
}

/// A text summary of a map.
pub fn map_table(r: &MapResult) -> String {
    let mut s = format!(
        "model: {}
criterion: {:?}, search: {:?}, resolution: {}
{:>14} {:>14}
",
        r.model, r.criterion, r.search, r.resolution, "B (N·s/m)", "K_max (N/m)"
    );
    for p in &r.boundary {
        s.push_str(&format!(
            "{:>14.2} {:>14.1}
",
            p.b, p.k_max
        ));
    }
    s.push_str(&format!(
        "K-width {:.1} N/m, B-width {:.2} N·s/m",
        r.k_width, r.b_width
    ));
    if let Some(f) = r.max_fidelity_error {
        s.push_str(&format!(", max fidelity error {f:.2} N·s/m"));
    }
    s.push_str(&format!(
        "
{} trials in {:.3} s
",
        r.trials, r.elapsed_s
    ));
    s
}

pub fn run(cli: Cli, stdin: impl BufRead, stdout: &mut impl Write) -> Result<(), CliError> {
    match cli.command {
        Command::Trial {
            scene,
            k,
            b,
            json,
            trace,
        } => {
            let sc = read_scene(&scene)?.validate()?;
            validate_wall(k, b)?;
            let knobs = HitKnobs {
                settle_s: sc.spec.hit.settle_s,
                measure_s: sc.spec.hit.measure_s,
            };
            let outcome = if let Some(path) = &trace {
                let worst = (sc.spec.hit.settle_s * 11.0 + sc.spec.hit.measure_s + 60.0)
                    * sc.spec.control.sample_hz;
                if worst > 1e7 {
                    return Err(CliError::Input(format!(
                        "--trace: this trial may run to {worst:.0} samples; traces are limited to 10 000 000 rows (shorten hit.settle_s/measure_s or lower loop.sample_hz)"
                    )));
                }
                let mut rows: Vec<TraceRow> = Vec::new();
                let o = wall_hit(&sc, k, b, knobs, &mut rows);
                let mut csv = String::from(
                    "t_s,x_true_m,y_measured_m,v_est_m_per_s,v_true_m_per_s,force_n\n",
                );
                for r in rows {
                    csv.push_str(&format!(
                        "{},{},{},{},{},{}\n",
                        r.t, r.x, r.y, r.v_est, r.v, r.force
                    ));
                }
                write_file(path, &csv)?;
                o
            } else {
                wall_hit(&sc, k, b, knobs, &mut NoTrace)
            };
            if json {
                write_json(stdout, &outcome)
            } else {
                let rms = outcome
                    .rms
                    .map(|r| format!("{r:.3e} m"))
                    .unwrap_or("- (diverged)".into());
                writeln!(
                    stdout,
                    "{} (RMS {rms} about {:.6e} m, threshold {:.3e} m; {} samples)",
                    if outcome.stable { "stable" } else { "unstable" },
                    outcome.mean_position,
                    sc.spec.hit.threshold,
                    outcome.samples
                )
                .map_err(io)
            }
        }
        Command::Impedance {
            scene,
            k,
            b,
            method,
            accuracy,
            json,
        } => {
            let sc = read_scene(&scene)?.validate()?;
            validate_wall(k, b)?;
            let method: Method = parse_choice("method", &method)?;
            let acc = Accuracy::Preset(parse_choice("accuracy", &accuracy)?);
            let res = acc.resolve(&sc)?;
            let ev = Evaluator::new(sc, method, Criterion::Impedance, res)?;
            let curve = ev.impedance(k, b).ok_or_else(|| {
                CliError::Input("--method must be auto, analytic or frequency".into())
            })?;
            if json {
                #[derive(serde::Serialize)]
                struct Out<'a> {
                    model: String,
                    #[serde(flatten)]
                    curve: &'a crate::zwidth::analytic::ImpedanceCurve,
                }
                write_json(
                    stdout,
                    &Out {
                        model: ev.model_description(),
                        curve: &curve,
                    },
                )
            } else {
                let mut s = format!(
                    "model: {}
{:>10} {:>14} {:>10}
",
                    ev.model_description(),
                    "f (Hz)",
                    "|Z| (N·s/m)",
                    "phase (°)"
                );
                for i in 0..curve.freq_hz.len() {
                    s.push_str(&format!(
                        "{:>10.2} {:>14.4} {:>10.3}
",
                        curve.freq_hz[i], curve.magnitude[i], curve.phase_deg[i]
                    ));
                }
                s.push_str(&format!(
                    "{}; fidelity error {:.3} N·s/m
",
                    if curve.passive {
                        "passive (phase within ±90° over the band)"
                    } else {
                        "NOT passive"
                    },
                    curve.fidelity
                ));
                write!(stdout, "{s}").map_err(io)
            }
        }
        Command::Map {
            scene,
            method,
            criterion,
            search,
            b,
            k_rel_tol,
            accuracy,
            json,
            svg,
        } => {
            let spec = MapSpec {
                scene: read_scene(&scene)?,
                method: parse_choice("method", &method)?,
                criterion: parse_choice("criterion", &criterion)?,
                search: parse_choice::<SearchKind>("search", &search)?,
                accuracy: Accuracy::Knobs(AccuracyKnobs {
                    preset: parse_choice::<Preset>("accuracy", &accuracy)?,
                    k_rel_tol,
                    ..Default::default()
                }),
                b,
                b_max: 1000.0,
                k_max: 1e7,
            };
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || map_observed(&spec, Some(observer.clone()), 0))?;
            if let Some(path) = svg {
                write_file(
                    &path,
                    &map_svg(&format!("Z-width: {}", spec.scene.estimator.label()), &r)?,
                )?;
            }
            write_either(stdout, json, &r, || map_table(&r))
        }
        Command::Tune {
            scene,
            params,
            objective,
            method,
            criterion,
            search,
            solver,
            seed,
            accuracy,
            final_accuracy,
            finalists,
            max_evaluations,
            constraint,
            b,
            json,
            svg,
            csv,
        } => {
            let params = serde_json::from_str(&params).map_err(|e| {
                CliError::Input(format!(
                    "--params = {params:?} is not allowed: {e}; e.g. '{{\"cutoff_hz\":{{\"min\":10,\"max\":500}}}}'"
                ))
            })?;
            let objective: crate::tune::Objective = if objective.trim_start().starts_with('{') {
                serde_json::from_str(&objective)
            } else {
                serde_json::from_value(serde_json::Value::String(objective.clone()))
            }
            .map_err(|e| {
                CliError::Input(format!(
                    "--objective = {objective:?} is not allowed: {e}; k_width, b_width, max_fidelity_error, area, {{\"weighted\":{{…}}}} or {{\"pareto\":[…]}}"
                ))
            })?;
            let spec = crate::tune::TuneSpec {
                scene: read_scene(&scene)?,
                params,
                objective,
                method: parse_choice("method", &method)?,
                criterion: parse_choice("criterion", &criterion)?,
                search: parse_choice("search", &search)?,
                accuracy: Accuracy::Preset(parse_choice("accuracy", &accuracy)?),
                final_accuracy: Accuracy::Preset(parse_choice("final-accuracy", &final_accuracy)?),
                finalists,
                solver: parse_choice("solver", &solver)?,
                seed,
                max_evaluations,
                constraint: constraint
                    .map(|c| parse_choice("constraint", &c))
                    .transpose()?,
                b,
                b_max: 1000.0,
                k_max: 1e7,
            };
            let tune = spec.validate()?;
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || tune.run(Some(observer.clone())))?;
            if let Some(p) = svg {
                write_file(&p, &r.svg().map_err(CliError::Failure)?)?;
            }
            if let Some(p) = csv {
                write_file(&p, &r.csv())?;
            }
            write_either(stdout, json, &r, || r.table())
        }
        Command::Compare {
            scene,
            accuracy,
            json,
            svg_dir,
        } => {
            let spec = match &scene {
                Some(p) => read_scene(p)?,
                None => compare::seed_2018_scene(),
            };
            let acc = Accuracy::Preset(parse_choice("accuracy", &accuracy)?);
            let observer = std::sync::Arc::new(Observer::default());
            let r = with_progress(&observer, || {
                compare::compare_observed(&spec, &acc, None, Some(observer.clone()))
            })?;
            if let Some(dir) = svg_dir {
                std::fs::create_dir_all(&dir).map_err(|e| {
                    CliError::Failure(format!("cannot create {}: {e}", dir.display()))
                })?;
                for row in &r.rows {
                    let name: String = row
                        .name
                        .chars()
                        .map(|c| {
                            if c.is_ascii_alphanumeric() {
                                c.to_ascii_lowercase()
                            } else {
                                '_'
                            }
                        })
                        .collect();
                    write_file(
                        &dir.join(format!("{name}.svg")),
                        &map_svg(
                            &format!("Z-width: {} ({})", row.name, row.parameters),
                            &row.map,
                        )?,
                    )?;
                }
            }
            write_either(stdout, json, &r, || r.table())
        }
        Command::Serve {
            db,
            bind,
            tokens,
            token_file,
            allow_origins,
            rigs,
            request_timeout_s,
        } => {
            let mut tokens = tokens;
            if let Some(f) = &token_file {
                let text = std::fs::read_to_string(f).map_err(|e| {
                    CliError::Input(format!("--token-file {} cannot be read: {e}", f.display()))
                })?;
                tokens.extend(text.lines().map(str::to_owned));
            }
            let rigs: Vec<std::sync::Arc<dyn crate::rig::Rig>> =
                crate::rig::SimulatedRig::parse_list(&rigs)
                    .map_err(|e| CliError::Input(format!("--rigs: {e}")))?
                    .into_iter()
                    .map(|r| std::sync::Arc::new(r) as std::sync::Arc<dyn crate::rig::Rig>)
                    .collect();
            use std::io::IsTerminal;
            let _ = tracing_subscriber::fmt()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::stderr().is_terminal())
                .with_env_filter(
                    tracing_subscriber::EnvFilter::try_from_default_env()
                        .unwrap_or_else(|_| "info".into()),
                )
                .try_init();
            let rt = tokio::runtime::Builder::new_multi_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            let tokens: Vec<String> = tokens
                .into_iter()
                .map(|t| t.trim().to_string())
                .filter(|t| !t.is_empty())
                .collect();
            rt.block_on(crate::http::serve(crate::http::ServeConfig {
                db,
                bind,
                tokens,
                allow_origins,
                rigs,
                request_timeout_s,
            }))
            .map_err(|e| {
                if e.starts_with("refusing") {
                    CliError::Input(e)
                } else {
                    CliError::Failure(e)
                }
            })
        }
        Command::Submit {
            file,
            server,
            priority,
            idempotency_key,
            rig,
            json,
        } => {
            let body = std::fs::read_to_string(&file)
                .map_err(|e| CliError::Input(format!("{} cannot be read: {e}", file.display())))?;
            let v = client(server).submit(
                &body,
                priority,
                idempotency_key.as_deref(),
                rig.as_deref(),
            )?;
            if json {
                write_json(stdout, &v)
            } else {
                writeln!(
                    stdout,
                    "{} {}",
                    v["id"].as_str().unwrap_or("?"),
                    v["state"].as_str().unwrap_or("?")
                )
                .map_err(io)
            }
        }
        Command::Openapi => writeln!(stdout, "{}", crate::http::openapi_json()).map_err(io),
        Command::Backup { db, out } => {
            if !db.is_file() {
                return Err(CliError::Input(format!(
                    "--db {} is not a database file",
                    db.display()
                )));
            }
            if out.exists() {
                return Err(CliError::Input(format!(
                    "--out {} exists: give a new file",
                    out.display()
                )));
            }
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .map_err(|e| CliError::Failure(format!("cannot start the runtime: {e}")))?;
            rt.block_on(async {
                let store = crate::store::Store::open(&db)
                    .await
                    .map_err(|e| CliError::Failure(format!("cannot open {}: {e}", db.display())))?;
                let r = store.backup(&out).await;
                let _ = store.close().await;
                r.map_err(|e| CliError::Failure(format!("backup to {} failed: {e}", out.display())))
            })?;
            writeln!(stdout, "{} -> {}", db.display(), out.display()).map_err(io)
        }
        Command::Status { id, server } => write_json(stdout, &client(server).status(&id)?),
        Command::Watch { id, server } => {
            let v = client(server).watch(&id)?;
            let state = v["state"].as_str().unwrap_or("?").to_string();
            writeln!(stdout, "{id} {state}").map_err(io)?;
            if state == "succeeded" {
                Ok(())
            } else {
                Err(CliError::Failure(format!(
                    "experiment {id} ended {state}: {}",
                    v["error"].as_str().unwrap_or("")
                )))
            }
        }
        Command::Results {
            id,
            server,
            csv,
            svg,
        } => {
            let c = client(server);
            let v = c.status(&id)?;
            if v["state"] != "succeeded" {
                return Err(CliError::Input(format!(
                    "experiment {id} is {}, not succeeded: no result yet",
                    v["state"]
                )));
            }
            let result = &v["result"];
            if let Some(p) = &csv {
                write_file(p, &c.export(&id, "points.csv")?)?;
            }
            if let Some(p) = &svg {
                write_file(p, &c.export(&id, "plot.svg")?)?;
            }
            if csv.is_none() && svg.is_none() {
                write_json(stdout, result)?;
            }
            Ok(())
        }
        Command::Bench {
            what:
                BenchCommand::Service {
                    server,
                    submissions,
                    rate,
                    seconds,
                },
        } => {
            if !(rate > 0.0
                && rate <= 10_000.0
                && seconds > 0.0
                && seconds <= 600.0
                && (1..=100_000).contains(&submissions))
            {
                return Err(CliError::Input(
                    "bench service: rate must be 0–10000 /s, seconds 0–600, submissions 1–100000"
                        .into(),
                ));
            }
            let r = client(server).bench(submissions, rate, seconds)?;
            write_json(stdout, &r)
        }
        Command::Bench {
            what:
                BenchCommand::Tune {
                    accuracy,
                    scan_points,
                    levant_accuracy,
                    levant_evaluations,
                    json,
                },
        } => {
            if !(5..=5000).contains(&scan_points) || !(1..=1000).contains(&levant_evaluations) {
                return Err(CliError::Input(
                    "bench tune: --scan-points must be 5 to 5000, --levant-evaluations 1 to 1000"
                        .into(),
                ));
            }
            let study = crate::tune::study::Study {
                cutoff: crate::tune::study::cutoff(
                    parse_choice("accuracy", &accuracy)?,
                    scan_points,
                )?,
                levant: crate::tune::study::levant(
                    parse_choice("levant-accuracy", &levant_accuracy)?,
                    levant_evaluations,
                )?,
            };
            write_either(stdout, json, &study, || study.table())
        }
        Command::Bench {
            what: BenchCommand::Tradeoff { json },
        } => {
            let rows = tradeoff::run()?;
            write_either(stdout, json, &rows, || tradeoff::table(&rows))
        }
        Command::Estimate {
            rate,
            estimator,
            quantization,
        } => {
            let sampling = Sampling::new(rate, quantization)?;
            let spec = EstimatorSpec::from_json(&estimator)?;
            let mut est = spec.build(sampling)?;
            let ys = read_samples(stdin)?;
            let mut out = BufWriter::new(stdout);
            for y in ys {
                let v = est.update(y);
                if !v.is_finite() {
                    return Err(CliError::Failure(format!(
                        "internal error: non-finite estimate for input {y}"
                    )));
                }
                writeln!(out, "{v}").map_err(io)?;
            }
            out.flush().map_err(io)
        }
        Command::Accuracy {
            rates,
            json,
            svg,
            quantization,
        } => {
            let cfg = AccuracyConfig {
                rates,
                quantization,
                ..AccuracyConfig::default()
            };
            let report = accuracy::run(&cfg)?;
            if let Some(path) = svg {
                let series: Vec<Series> = report
                    .rows
                    .iter()
                    .map(|r| Series {
                        name: r.name.clone(),
                        points: report
                            .rates
                            .iter()
                            .copied()
                            .zip(r.rms_error.iter().copied())
                            .collect(),
                    })
                    .collect();
                let text = loglog_svg(
                    "RMS velocity error vs sample rate (2011 paper Fig. 2 study)",
                    "sample rate (Hz)",
                    "RMS error (m/s)",
                    &series,
                )
                .map_err(CliError::Failure)?;
                std::fs::write(&path, text).map_err(|e| {
                    CliError::Failure(format!("cannot write {}: {e}", path.display()))
                })?;
            }
            if json {
                write_json(stdout, &report)
            } else {
                write!(stdout, "{}", report.table()).map_err(io)
            }
        }
        Command::Lipschitz {
            rate,
            quantization,
            json,
        } => {
            let ys = read_samples(stdin)?;
            let est = lipschitz::estimate(&ys, rate, quantization)?;
            if json {
                write_json(stdout, &est)
            } else {
                writeln!(
                    stdout,
                    "C = {:.6} m/s² (max |x''| at t = {:.6} s; window {} samples = {:.6} s; noise floor {:.3e} m/s²)\nmethod: {}",
                    est.lipschitz,
                    est.at_s,
                    2 * est.half_window + 1,
                    est.window_s,
                    est.noise_floor,
                    est.method
                )
                .map_err(io)
            }
        }
        Command::Gains { estimator, json } => {
            let spec = EstimatorSpec::from_json(&estimator)?;
            let EstimatorKind::Levant(l) = &spec.kind else {
                return Err(CliError::Input(format!(
                    "estimator.kind = {:?} is not allowed: gains are reported for kind \"levant\" only",
                    serde_json::to_value(&spec).ok().and_then(|v| v.get("kind").cloned()).unwrap_or_default()
                )));
            };
            let report = l.gains()?.report();
            if json {
                write_json(stdout, &report)
            } else {
                writeln!(stdout, "{report}").map_err(io)
            }
        }
    }
}
