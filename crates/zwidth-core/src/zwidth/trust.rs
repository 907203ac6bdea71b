//! `zwidth bench trust`: how far the seed device's figures can be trusted
//! (issue 11's targets, measured): the K-width and its interval for a few
//! probe seeds, against the Butterworth cutoff 480–499 Hz, and against the
//! probe amplitude. All at standard accuracy on `examples/seed_2018.json`,
//! judged by the BLA verdict; the cutoff rows again with the 2018 paper's
//! `tfestimate` verdict, the baseline the BLA is measured against.

use serde::Serialize;
use std::time::Instant;

use super::scene::{ProbeMethod, SceneSpec};
use super::search::{map, BoundaryPoint};
use super::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
use super::tradeoff::{interval_cell, EXAMPLES};
use crate::error::SpecError;

#[derive(Debug, Clone, Serialize)]
pub struct TrustRow {
    /// What varies: "seed", "cutoff_hz" or "amplitude_n".
    pub vary: &'static str,
    /// How points were judged: "bla" or "tfestimate" (`probe.method`).
    pub verdict: &'static str,
    pub value: f64,
    /// N/m, and its interval (N/m).
    pub k_width: f64,
    pub k_width_interval: Option<[f64; 2]>,
    /// Change of the K-width from the previous row of the same kind.
    pub change_from_previous: Option<f64>,
    /// Largest spike of the boundary the intervals do not allow: how far a
    /// point's interval misses the straight line between its two
    /// neighbours' intervals (B is evenly spaced), relative to the lower of
    /// the point and that line. A steep but steady slope is not a spike.
    pub spike: f64,
    pub wall_s: f64,
}

fn seed_scene() -> Result<SceneSpec, SpecError> {
    SceneSpec::from_json(EXAMPLES[1].1)
}

fn one(vary: &'static str, value: f64, scene: SceneSpec) -> Result<TrustRow, SpecError> {
    let spec = MapSpec {
        scene,
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::Bisect,
        accuracy: Accuracy::Preset(Preset::Standard),
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    };
    let t = Instant::now();
    let r = map(&spec)?;
    let spike = spike(&r.boundary);
    Ok(TrustRow {
        vary,
        verdict: match spec.scene.probe.method {
            ProbeMethod::Bla => "bla",
            ProbeMethod::Tfestimate => "tfestimate",
        },
        value,
        k_width: r.k_width,
        k_width_interval: r.k_width_interval,
        change_from_previous: None,
        spike,
        wall_s: t.elapsed().as_secs_f64(),
    })
}

/// The largest spike of a boundary its intervals do not allow (see
/// [`TrustRow::spike`]). A point without an interval (a verdict taken as
/// certain: the `tfestimate` baseline) is its own zero-width interval.
fn spike(boundary: &[BoundaryPoint]) -> f64 {
    let lo = |p: &BoundaryPoint| p.k_lo.unwrap_or(p.k_max);
    let hi = |p: &BoundaryPoint| p.k_hi.unwrap_or(p.k_max);
    boundary
        .windows(3)
        .filter_map(|w| {
            let (a, p, c) = (&w[0], &w[1], &w[2]);
            let line_lo = 0.5 * (lo(a) + lo(c));
            let line_hi = 0.5 * (hi(a) + hi(c));
            let gap = (lo(p) - line_hi).max(line_lo - hi(p)).max(0.0);
            let base = p.k_max.min(0.5 * (a.k_max + c.k_max));
            (base > 0.0).then(|| gap / base)
        })
        .fold(0.0, f64::max)
}

pub fn run() -> Result<Vec<TrustRow>, SpecError> {
    let base = seed_scene()?;
    let mut rows = Vec::new();
    for seed in [1u64, 2, 3] {
        let mut s = base.clone();
        s.probe.seed = seed;
        rows.push(one("seed", seed as f64, s)?);
    }
    for method in [ProbeMethod::Bla, ProbeMethod::Tfestimate] {
        for hz in 480..=499 {
            let mut s = base.clone();
            s.estimator = serde_json::from_value(serde_json::json!({
                "kind": "butterworth", "cutoff_hz": hz, "order": 2
            }))
            .map_err(|e| SpecError::new("estimator", hz, e.to_string()))?;
            s.probe.method = method;
            rows.push(one("cutoff_hz", f64::from(hz), s)?);
        }
    }
    for amp in [0.25, 0.5, 1.0, 2.0] {
        let mut s = base.clone();
        s.probe.amplitude = amp;
        rows.push(one("amplitude_n", amp, s)?);
    }
    mark_changes(&mut rows);
    Ok(rows)
}

/// Each row's K-width change from the row before it, where that row varies
/// the same thing and rendered something (none across kinds, none from 0).
fn mark_changes(rows: &mut [TrustRow]) {
    for i in 1..rows.len() {
        let same = rows[i].vary == rows[i - 1].vary && rows[i].verdict == rows[i - 1].verdict;
        if same && rows[i - 1].k_width > 0.0 {
            rows[i].change_from_previous = Some(rows[i].k_width / rows[i - 1].k_width - 1.0);
        }
    }
}

pub fn table(rows: &[TrustRow]) -> String {
    let mut s = format!(
        "{:<12} {:<10} {:>8} {:>12} {:>28} {:>9} {:>10} {:>8}\n",
        "vary", "verdict", "value", "K-width", "interval (±%)", "change", "spike", "wall (s)"
    );
    for r in rows {
        let interval = interval_cell(r.k_width, r.k_width_interval);
        let change = r
            .change_from_previous
            .map_or("-".to_string(), |c| format!("{:+.1}%", 100.0 * c));
        s.push_str(&format!(
            "{:<12} {:<10} {:>8} {:>12.0} {:>28} {:>9} {:>9.1}% {:>8.2}\n",
            r.vary,
            r.verdict,
            r.value,
            r.k_width,
            interval,
            change,
            100.0 * r.spike,
            r.wall_s
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(vary: &'static str, k_width: f64) -> TrustRow {
        TrustRow {
            vary,
            verdict: "bla",
            value: 0.0,
            k_width,
            k_width_interval: None,
            change_from_previous: None,
            spike: 0.0,
            wall_s: 0.0,
        }
    }

    fn iv(k: f64, lo: f64, hi: f64) -> BoundaryPoint {
        BoundaryPoint {
            k_lo: Some(lo),
            k_hi: Some(hi),
            ..BoundaryPoint::new(0.0, k)
        }
    }

    #[test]
    fn spikes_are_gaps_the_intervals_do_not_allow() {
        // A peak: 2000 [1900, 2100] between two 1000 [900, 1100]: the
        // neighbours' line is [900, 1100], the gap 1900 − 1100 = 800 over
        // the lower of 2000 and 1000: 0.8.
        let (lo, hi) = (iv(1000.0, 900.0, 1100.0), iv(2000.0, 1900.0, 2100.0));
        assert!((spike(&[lo, hi, lo]) - 0.8).abs() < 1e-12);
        // A dip: 500 [450, 550] between them: gap 900 − 550 = 350 over 500.
        assert!((spike(&[lo, iv(500.0, 450.0, 550.0), lo]) - 0.7).abs() < 1e-12);
        // A steady slope is no spike: 1000, 2000, 3000 (±100).
        assert_eq!(spike(&[lo, hi, iv(3000.0, 2900.0, 3100.0)]), 0.0);
        // A point without an interval is its own: 5000 between two
        // [900, 1100] misses their line by 3900, over the lower 1000: 3.9.
        let bare = BoundaryPoint::new(0.0, 5000.0);
        assert!((spike(&[lo, bare, lo]) - 3.9).abs() < 1e-12);
        // Three bare points on a line: none; fewer than three: nothing to judge.
        let flat = BoundaryPoint::new(0.0, 1000.0);
        assert_eq!(spike(&[flat, flat, flat]), 0.0);
        assert_eq!(spike(&[lo, hi]), 0.0);
    }

    #[test]
    fn changes_are_from_the_previous_row_of_the_same_kind() {
        // 100 → 150 is +50 %, 150 → 120 is −20 %; a new kind starts
        // without a change, and nothing is relative to a K-width of 0.
        let mut rows = vec![
            row("seed", 100.0),
            row("seed", 150.0),
            row("seed", 120.0),
            row("cutoff_hz", 0.0),
            row("cutoff_hz", 50.0),
            row("cutoff_hz", 75.0),
        ];
        mark_changes(&mut rows);
        let got: Vec<Option<f64>> = rows.iter().map(|r| r.change_from_previous).collect();
        let want = [None, Some(0.5), Some(-0.2), None, None, Some(0.5)];
        for (g, w) in got.iter().zip(want) {
            match (g, w) {
                (Some(g), Some(w)) => assert!((g - w).abs() < 1e-12, "{got:?}"),
                (g, w) => assert_eq!(*g, w, "{got:?}"),
            }
        }
    }

    #[test]
    fn a_change_is_never_across_verdicts() {
        let mut rows = vec![row("cutoff_hz", 100.0), row("cutoff_hz", 200.0)];
        rows[1].verdict = "tfestimate";
        mark_changes(&mut rows);
        assert_eq!(rows[1].change_from_previous, None);
    }

    #[test]
    fn the_table_shows_changes_spikes_and_intervals_in_percent() {
        let r = TrustRow {
            change_from_previous: Some(0.25),
            spike: 0.123,
            k_width_interval: Some([25_080.0, 27_720.0]),
            ..row("seed", 26_400.0)
        };
        let t = table(&[r]);
        assert_eq!(t.lines().count(), 2, "{t}");
        let last = t.lines().nth(1).unwrap();
        // 50·(27 720 − 25 080)/26 400 = 5 %.
        for want in [
            "seed",
            "bla",
            "+25.0%",
            "12.3%",
            "[25080, 27720] ±5.0%",
            "26400",
        ] {
            assert!(last.contains(want), "{want:?} in {last:?}");
        }
    }

    #[test]
    fn a_spike_is_relative_only_to_a_boundary_that_renders_something() {
        // Neighbours at 0: the base is 0 and the point is not judged (the
        // ratio would be infinite).
        let zero = BoundaryPoint::new(0.0, 0.0);
        assert_eq!(spike(&[iv(1000.0, 900.0, 1100.0), zero, zero]), 0.0);
    }

    #[test]
    fn the_seed_scene_is_the_2018_paper_s_device() {
        // Chawda et al. 2018 (../shared/seeds), the simulated device: 1 kHz,
        // Butterworth at 499 Hz, m = 0.52 kg, b = 13.2 N·s/m, f_c = 0.19 N,
        // 1 µm encoder.
        let s = seed_scene().unwrap();
        assert_eq!((s.control.sample_hz, s.control.render_hz), (1000.0, 1000.0));
        let d = &s.device;
        assert_eq!(
            (d.mass, d.damping, d.coulomb, d.quantization),
            (0.52, 13.2, 0.19, 1e-6)
        );
        assert_eq!(s.estimator.label(), "butterworth(499 Hz, order 2)");
    }
}
