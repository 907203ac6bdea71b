//! Helpers the commands share: reading inputs, writing outputs, progress.

use std::io::{BufRead, Write};

use crate::plot::{zwidth_map_svg_styled, FidelityScale, MapPlotPoint, MapStyle};
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::MapResult;
use crate::zwidth::settings::Criterion;

use super::CliError;

pub(super) fn io(e: std::io::Error) -> CliError {
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

/// `--db` as a store location, its PostgreSQL password from the file
/// `ZWIDTH_DB_PASSWORD_FILE` names when set (a compose secret).
pub(super) fn db_location(db: &str) -> Result<crate::store::Location, CliError> {
    let file = std::env::var_os("ZWIDTH_DB_PASSWORD_FILE")
        .filter(|f| !f.is_empty())
        .map(std::path::PathBuf::from);
    crate::store::Location::parse_with_password(db, file.as_deref()).map_err(CliError::Input)
}

/// A client of `server` with the user token from `ZWIDTH_TOKEN`, else the
/// file `ZWIDTH_TOKEN_FILE`, else the one `serve` made next to its
/// database (`$ZWIDTH_DB.token`, default `zwidth.db.token`).
pub(super) fn client(server: String) -> Result<crate::client::Client, CliError> {
    check_server(&server)?;
    let tls =
        crate::tls::client_config(crate::tls::ca_file(None).as_deref()).map_err(CliError::Input)?;
    let env = |k: &str| std::env::var(k).ok().filter(|t| !t.is_empty());
    let file = env("ZWIDTH_TOKEN_FILE").unwrap_or_else(|| {
        format!(
            "{}.token",
            env("ZWIDTH_DB").unwrap_or_else(|| "zwidth.db".into())
        )
    });
    let token = env("ZWIDTH_TOKEN").or_else(|| {
        std::fs::read_to_string(file)
            .ok()
            .and_then(|t| t.lines().next().map(|l| l.trim().to_string()))
            .filter(|t| !t.is_empty())
    });
    Ok(crate::client::Client::new(&server, token, tls))
}

/// `--server` (or ZWIDTH_SERVER) must be an http:// or https:// URL.
pub(super) fn check_server(server: &str) -> Result<(), CliError> {
    let lower = server.to_ascii_lowercase();
    if ["http://", "https://"]
        .iter()
        .any(|s| lower.starts_with(s) && lower.len() > s.len())
    {
        Ok(())
    } else {
        Err(CliError::Input(format!(
            "--server = {server:?}: must be an http:// or https:// URL (e.g. https://zwidth.lab.example:8443)"
        )))
    }
}

/// A predicted boundary from `path`: a map's JSON (`zwidth map --json`,
/// its `boundary`) or the list of boundary points alone.
pub(super) fn read_boundary(
    path: &std::path::Path,
) -> Result<Vec<crate::zwidth::search::BoundaryPoint>, CliError> {
    let text = std::fs::read_to_string(path).map_err(|e| {
        CliError::Input(format!(
            "--prior-map {} cannot be read: {e}",
            path.display()
        ))
    })?;
    let bad = |e: String| {
        CliError::Input(format!(
            "--prior-map {}: {e}; give the JSON of `zwidth map --json` or a list of {{\"b\", \"k_max\", \"k_lo\", \"k_hi\"}}",
            path.display()
        ))
    };
    let value: serde_json::Value = serde_json::from_str(&text).map_err(|e| bad(e.to_string()))?;
    let list = match value {
        serde_json::Value::Object(mut map) => map
            .remove("boundary")
            .ok_or_else(|| bad("an object without \"boundary\"".to_string()))?,
        other => other,
    };
    serde_json::from_value(list).map_err(|e| bad(format!("boundary: {e}")))
}

pub(super) fn read_scene(path: &std::path::Path) -> Result<SceneSpec, CliError> {
    read_scene_of("--scene", path)
}

/// The scene file `path` given to `flag` (`--prior-scene`, `--sim-device`).
pub(super) fn read_scene_of(flag: &str, path: &std::path::Path) -> Result<SceneSpec, CliError> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| CliError::Input(format!("{flag} {} cannot be read: {e}", path.display())))?;
    SceneSpec::from_json(&text)
        .map_err(|e| CliError::Input(format!("{flag} {}: {e}", path.display())))
}

/// Run `work` while drawing a progress bar on stderr from `observer` (only
/// when stderr is a terminal).
pub(super) fn with_progress<T>(
    observer: &std::sync::Arc<crate::zwidth::search::Observer>,
    work: impl FnOnce() -> T,
) -> T {
    use std::io::IsTerminal;
    if !std::io::stderr().is_terminal() {
        return work();
    }
    with_bar(observer, std::time::Duration::from_millis(200), work)
}

/// `work` with the bar redrawn every `tick`. The bar's thread is woken when
/// the work ends, so the command does not wait out a tick (up to 200 ms at
/// the end of every command run in a terminal, before 2026-12-06).
fn with_bar<T>(
    observer: &crate::zwidth::search::Observer,
    tick: std::time::Duration,
    work: impl FnOnce() -> T,
) -> T {
    let done = std::sync::atomic::AtomicBool::new(false);
    std::thread::scope(|s| {
        let bar = s.spawn(|| {
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
                std::thread::park_timeout(tick);
            }
            eprintln!();
        });
        let r = work();
        done.store(true, std::sync::atomic::Ordering::Relaxed);
        bar.thread().unpark();
        r
    })
}

/// A snake_case enum value from a flag, with serde's message naming the choices.
pub(super) fn parse_choice<T: serde::de::DeserializeOwned>(
    flag: &str,
    value: &str,
) -> Result<T, CliError> {
    serde_json::from_value(serde_json::Value::String(value.to_string()))
        .map_err(|e| CliError::Input(format!("--{flag} = {value:?} is not allowed: {e}")))
}

/// A tune objective from a flag: a metric name or its JSON form.
pub(super) fn parse_objective(flag: &str, value: &str) -> Result<crate::tune::Objective, CliError> {
    if value.trim_start().starts_with('{') {
        serde_json::from_str(value)
    } else {
        serde_json::from_value(serde_json::Value::String(value.to_string()))
    }
    .map_err(|e| {
        CliError::Input(format!(
            "--{flag} = {value:?} is not allowed: {e}; k_width, b_width, max_fidelity_error, area, {{\"weighted\":{{…}}}} or {{\"pareto\":[…]}}"
        ))
    })
}

pub(super) fn write_json(out: &mut impl Write, v: &impl serde::Serialize) -> Result<(), CliError> {
    serde_json::to_writer_pretty(&mut *out, v).map_err(|e| CliError::Failure(e.to_string()))?;
    writeln!(out).map_err(io)
}

/// The JSON with `--json`, else the text table.
pub(super) fn write_either(
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

pub(super) fn write_file(path: &std::path::Path, text: &str) -> Result<(), CliError> {
    std::fs::write(path, text)
        .map_err(|e| CliError::Failure(format!("cannot write {}: {e}", path.display())))
}

/// A map's points, for plotting.
pub fn plot_points(r: &MapResult) -> Vec<MapPlotPoint> {
    r.points.iter().map(MapPlotPoint::of).collect()
}

/// The Fig. 7-style plot of a map; `scale` is a fidelity colour scale
/// shared with the other maps written with it (none: the map's own).
pub fn map_svg(
    title: &str,
    r: &MapResult,
    scale: Option<FidelityScale>,
) -> Result<String, CliError> {
    let label = if r.criterion == Criterion::Stability {
        "stable"
    } else {
        "passive"
    };
    let style = MapStyle {
        ok_label: label.into(),
        scale,
        prediction: r
            .prior
            .as_ref()
            .map(|p| p.predicted_boundary())
            .unwrap_or_default(),
        ..MapStyle::default()
    };
    zwidth_map_svg_styled(title, &plot_points(r), &r.boundary, &style).map_err(CliError::Failure)
}

/// A text summary of a map.
pub fn map_table(r: &MapResult) -> String {
    let intervals = r.k_width_interval.is_some();
    let mut s = format!(
        "model: {}
criterion: {:?}, search: {:?}, resolution: {}
{:>14} {:>14}{}
",
        r.model,
        r.criterion,
        r.search,
        r.resolution,
        "B (N·s/m)",
        "K_max (N/m)",
        if intervals {
            format!(" {:>29}", "interval (N/m)")
        } else {
            String::new()
        }
    );
    for p in &r.boundary {
        s.push_str(&format!("{:>14.2} {:>14.1}", p.b, p.k_max));
        if let (Some(lo), Some(hi)) = (p.k_lo, p.k_hi) {
            s.push_str(&format!("   [{lo:>12.1}, {hi:>12.1}]"));
        }
        s.push('\n');
    }
    s.push_str(&format!(
        "K-width {:.1} N/m, B-width {:.2} N·s/m",
        r.k_width, r.b_width
    ));
    if let (Some(k), Some(b)) = (r.k_width_interval, r.b_width_interval) {
        s.push_str(&format!(
            " (intervals: K-width [{:.1}, {:.1}], B-width [{:.2}, {:.2}])",
            k[0], k[1], b[0], b[1]
        ));
    }
    if let Some(f) = r.max_fidelity_error {
        s.push_str(&format!(", max fidelity error {f:.2} N·s/m"));
    }
    s.push_str(&format!(
        "
{} trials in {:.3} s
",
        r.trials, r.elapsed_s
    ));
    if let Some(why) = &r.saturation {
        s.push_str(&format!("saturation: {why}\n"));
    }
    if let Some(p) = &r.prior {
        s.push_str(&format!(
            "prior ({}): {} of {} columns agree with the prediction",
            p.source,
            p.columns.len() - p.disagreements,
            p.columns.len()
        ));
        let off: Vec<String> = p
            .columns
            .iter()
            .filter(|c| !c.agrees)
            .map(|c| format!("B = {:.2}: predicted {:.1} N/m", c.b, c.predicted_k_max))
            .collect();
        if !off.is_empty() {
            s.push_str(&format!("; they disagree at {}", off.join(", ")));
        }
        s.push('\n');
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_bar_does_not_hold_the_command_past_its_work() {
        // A tick of a minute: a bar that waited out its tick would hold
        // this job of 0.3 s (by then the bar has drawn and is waiting)
        // for 60 s.
        let o = crate::zwidth::search::Observer::default();
        let start = std::time::Instant::now();
        let job = || {
            std::thread::sleep(std::time::Duration::from_millis(300));
            7
        };
        assert_eq!(with_bar(&o, std::time::Duration::from_secs(60), job), 7);
        assert!(
            start.elapsed() < std::time::Duration::from_secs(30),
            "{:?}",
            start.elapsed()
        );
    }
}
