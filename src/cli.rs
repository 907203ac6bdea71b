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
    /// Report which convergence conditions a Levant gain pair meets.
    Gains {
        /// A levant estimator spec, e.g. '{"kind":"levant","alpha":13,"lambda":1.58,"lipschitz":12}'.
        #[arg(long)]
        estimator: String,
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

pub fn run(cli: Cli, stdin: impl BufRead, stdout: &mut impl Write) -> Result<(), CliError> {
    match cli.command {
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
                serde_json::to_writer_pretty(&mut *stdout, &report)
                    .map_err(|e| CliError::Failure(e.to_string()))?;
                writeln!(stdout).map_err(io)
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
                serde_json::to_writer_pretty(&mut *stdout, &est)
                    .map_err(|e| CliError::Failure(e.to_string()))?;
                writeln!(stdout).map_err(io)
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
                serde_json::to_writer_pretty(&mut *stdout, &report)
                    .map_err(|e| CliError::Failure(e.to_string()))?;
                writeln!(stdout).map_err(io)
            } else {
                writeln!(stdout, "{report}").map_err(io)
            }
        }
    }
}
