//! `zwidth bench tradeoff`: what each accuracy preset costs and how far its
//! K-width and B-width land from `reference`, on the example scenes (the
//! files in `examples/`, compiled in so the command runs anywhere).

use serde::Serialize;
use std::time::Instant;

use super::point::Point;
use super::scene::SceneSpec;
use super::search::map;
use super::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
use crate::error::SpecError;

/// (name, scene JSON, criterion) of each example.
pub const EXAMPLES: [(&str, &str, Criterion); 5] = [
    (
        "linear_1khz (analytic)",
        include_str!("../../../../examples/linear_1khz.json"),
        Criterion::Impedance,
    ),
    (
        "seed_2018 (frequency)",
        include_str!("../../../../examples/seed_2018.json"),
        Criterion::Impedance,
    ),
    (
        "seed_2011 (time)",
        include_str!("../../../../examples/seed_2011.json"),
        Criterion::Stability,
    ),
    (
        "linear_1khz (time)",
        include_str!("../../../../examples/linear_1khz.json"),
        Criterion::Stability,
    ),
    // The realistic 10 kHz scene (two masses, amplifier, LuGre): its
    // reference map takes minutes (docs/benchmarks.md).
    (
        "mode_lag_2011 (frequency)",
        include_str!("../../../../examples/mode_lag_2011.json"),
        Criterion::Impedance,
    ),
];

#[derive(Debug, Clone, Serialize)]
pub struct TradeoffRow {
    pub scene: String,
    /// How the maps searched (each row against the same search's
    /// reference).
    pub search: SearchKind,
    pub preset: Preset,
    pub wall_s: f64,
    pub trials: usize,
    /// Simulated realizations: each trial's random-phase realizations (the
    /// frequency engine's BLA) or replicate hits (the time engine), one for
    /// a trial without (a deterministic simulation, a closed form).
    pub realizations: u64,
    /// `realizations / wall_s`: the engine's speed, whatever the search.
    pub realizations_per_s: f64,
    pub k_width: f64,
    pub b_width: f64,
    /// Relative errors against the reference preset of the same scene.
    pub k_width_error: f64,
    pub b_width_error: f64,
    /// Noisy scenes: the K-width interval, and whether it overlaps the
    /// reference preset's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_width_interval: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overlaps_reference: Option<bool>,
}

/// Every preset on every example scene whose name contains `filter`, each
/// map searched by `search` (`zwidth bench tradeoff [--scene FILTER]
/// [--search S]`); an error names the choices when none does.
pub fn run(filter: Option<&str>, search: SearchKind) -> Result<Vec<TradeoffRow>, SpecError> {
    let chosen: Vec<_> = EXAMPLES
        .iter()
        .filter(|(name, _, _)| filter.is_none_or(|f| name.contains(f)))
        .copied()
        .collect();
    if chosen.is_empty() {
        let names: Vec<&str> = EXAMPLES.iter().map(|e| e.0).collect();
        return Err(SpecError::new(
            "scene",
            filter.unwrap_or_default(),
            format!("must be part of an example's name: {}", names.join(", ")),
        ));
    }
    run_on(&chosen, search)
}

/// Realizations a map simulated (see [`TradeoffRow::realizations`]).
fn realizations(points: &[Point]) -> u64 {
    points.iter().map(|p| u64::from(p.realizations_run())).sum()
}

/// Every preset on the given scenes, each against its own reference (of
/// the same search).
fn run_on(
    examples: &[(&str, &str, Criterion)],
    search: SearchKind,
) -> Result<Vec<TradeoffRow>, SpecError> {
    let mut rows = Vec::new();
    for &(name, json, criterion) in examples {
        let scene = SceneSpec::from_json(json)?;
        let method = if name.ends_with("(time)") {
            Method::Time
        } else {
            Method::Auto
        };
        let mut results = Vec::new();
        for preset in [Preset::Reference, Preset::Standard, Preset::Draft] {
            let spec = MapSpec {
                scene: scene.clone(),
                method,
                criterion,
                search,
                accuracy: Accuracy::Preset(preset),
                b: None,
                b_max: 1000.0,
                k_max: 1e7,
                prior: None,
            };
            let t = Instant::now();
            let r = map(&spec)?;
            results.push((preset, t.elapsed().as_secs_f64(), r));
        }
        let (kr, br) = (results[0].2.k_width, results[0].2.b_width);
        let ref_interval = results[0].2.k_width_interval;
        for (preset, wall_s, r) in results {
            let realizations = realizations(&r.points);
            rows.push(TradeoffRow {
                scene: name.to_string(),
                search,
                preset,
                wall_s,
                trials: r.trials,
                realizations,
                realizations_per_s: realizations as f64 / wall_s.max(1e-9),
                k_width: r.k_width,
                b_width: r.b_width,
                k_width_error: relative_error(r.k_width, kr),
                b_width_error: relative_error(r.b_width, br),
                k_width_interval: r.k_width_interval,
                overlaps_reference: r
                    .k_width_interval
                    .zip(ref_interval)
                    .map(|(a, b)| a[0] <= b[1] && b[0] <= a[1]),
            });
        }
    }
    Ok(rows)
}

/// (x − r)/r, or 0 against a reference of 0 (a scene that renders
/// nothing at reference accuracy: no relative error, and never NaN).
fn relative_error(x: f64, r: f64) -> f64 {
    if r > 0.0 {
        (x - r) / r
    } else {
        0.0
    }
}

pub fn table(rows: &[TradeoffRow]) -> String {
    let mut s = format!(
        "{:<26} {:<13} {:<10} {:>9} {:>7} {:>8} {:>10} {:>12} {:>10} {:>9} {:>9} {:>27} {:>8}\n",
        "scene",
        "search",
        "preset",
        "wall (s)",
        "trials",
        "realiz.",
        "realiz./s",
        "K-width",
        "B-width",
        "K err",
        "B err",
        "K-width interval (±%)",
        "overlap"
    );
    for r in rows {
        let interval = interval_cell(r.k_width, r.k_width_interval);
        let overlap = r
            .overlaps_reference
            .map_or("-", |o| if o { "yes" } else { "no" });
        s.push_str(&format!(
            "{:<26} {:<13} {:<10} {:>9.3} {:>7} {:>8} {:>10.0} {:>12.1} {:>10.2} {:>8.2}% {:>8.2}% {:>27} {:>8}\n",
            r.scene,
            r.search.name(),
            format!("{:?}", r.preset).to_lowercase(),
            r.wall_s,
            r.trials,
            r.realizations,
            r.realizations_per_s,
            r.k_width,
            r.b_width,
            100.0 * r.k_width_error,
            100.0 * r.b_width_error,
            interval,
            overlap
        ));
    }
    s
}

/// `[lo, hi] ±h%` for a K-width interval (h: half its width relative to
/// the K-width), or `-` where the map has none.
pub fn interval_cell(k_width: f64, interval: Option<[f64; 2]>) -> String {
    interval.map_or("-".to_string(), |[lo, hi]| {
        format!(
            "[{lo:.0}, {hi:.0}] ±{:.1}%",
            50.0 * (hi - lo) / k_width.max(f64::MIN_POSITIVE)
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn realizations_count_each_trial_s_or_one() {
        let p = |r: Option<u32>| Point {
            realizations: r,
            ..Point::default()
        };
        // 24 + 3 BLA realizations, and one deterministic trial.
        assert_eq!(realizations(&[p(Some(24)), p(None), p(Some(3))]), 28);
        assert_eq!(realizations(&[]), 0);
    }

    #[test]
    fn an_unknown_scene_filter_names_the_examples() {
        let e = run(Some("no such scene"), SearchKind::Bisect)
            .unwrap_err()
            .to_string();
        assert!(e.contains("scene") && e.contains("no such scene"), "{e}");
        assert!(e.contains("mode_lag_2011 (frequency)"), "{e}");
    }

    #[test]
    fn relative_errors_against_the_reference() {
        assert_eq!(relative_error(150.0, 100.0), 0.5);
        assert_eq!(relative_error(80.0, 100.0), -0.2);
        // A reference of 0: 0, not ±inf or NaN.
        assert_eq!(relative_error(5.0, 0.0), 0.0);
        assert_eq!(relative_error(0.0, 0.0), 0.0);
    }

    #[test]
    fn each_preset_is_measured_against_its_scene_s_reference() {
        // The linear example on the analytic engine: exact at every preset
        // (Colgate & Schenkel's bound does not depend on the search's
        // steps beyond its bisection tolerance), so every error is within
        // the presets' k_rel_tol and B-width is the same column count.
        let rows = run_on(&EXAMPLES[..1], SearchKind::Bisect).unwrap();
        let presets: Vec<_> = rows.iter().map(|r| r.preset).collect();
        assert_eq!(
            presets,
            [Preset::Reference, Preset::Standard, Preset::Draft]
        );
        assert_eq!((rows[0].k_width_error, rows[0].b_width_error), (0.0, 0.0));
        for r in &rows {
            assert_eq!(r.scene, "linear_1khz (analytic)");
            assert_eq!(r.search, SearchKind::Bisect);
            assert!(r.k_width > 0.0 && r.trials > 0, "{r:?}");
            // A closed form has no realizations: one per trial, and the
            // speed is their count over the wall time.
            assert_eq!(r.realizations, r.trials as u64);
            assert_eq!(r.realizations_per_s, r.trials as f64 / r.wall_s.max(1e-9));
            assert_eq!(r.k_width_error, relative_error(r.k_width, rows[0].k_width));
            assert_eq!(r.b_width_error, relative_error(r.b_width, rows[0].b_width));
            assert!(r.k_width_error.abs() <= 0.05, "{r:?}");
            // A deterministic scene has no interval to overlap.
            assert_eq!((r.k_width_interval, r.overlaps_reference), (None, None));
        }
        let t = table(&rows);
        assert_eq!(t.lines().count(), 4, "{t}");
        let last: Vec<&str> = t.lines().nth(3).unwrap().split_whitespace().collect();
        assert_eq!(
            last[..4],
            ["linear_1khz", "(analytic)", "bisect", "draft"],
            "{t}"
        );
    }

    #[test]
    fn the_table_shows_errors_in_percent_and_the_interval_s_half_width() {
        let row = TradeoffRow {
            scene: "s".into(),
            search: SearchKind::Psi,
            preset: Preset::Draft,
            wall_s: 1.5,
            trials: 7,
            realizations: 84,
            realizations_per_s: 56.0,
            k_width: 1000.0,
            b_width: 10.0,
            k_width_error: 0.034,
            b_width_error: -0.125,
            k_width_interval: Some([900.0, 1100.0]),
            overlaps_reference: Some(false),
        };
        let t = table(&[row]);
        let last = t.lines().nth(1).unwrap();
        // 84 realizations in 1.5 s: 56 a second.
        for want in [
            " psi ",
            "draft",
            " 84 ",
            " 56 ",
            "3.40%",
            "-12.50%",
            "[900, 1100] ±10.0%",
            " no",
        ] {
            assert!(last.contains(want), "{want:?} in {last:?}");
        }
        // Half the width over the K-width: 50·(1100 − 900)/1000 = 10 %.
        assert_eq!(
            interval_cell(1000.0, Some([900.0, 1100.0])),
            "[900, 1100] ±10.0%"
        );
        assert_eq!(interval_cell(1000.0, None), "-");
    }
}
