//! Every estimator on one scene, as the 2018 paper's Table I: K-width,
//! B-width, tunable parameters and maximum fidelity error.
//!
//! Default scene: the paper's simulated device (§V): m = 0.52 kg,
//! b = 13.2 N·s/m, f_c = 0.19 N, 1 µm encoder, simulated at 1 kHz, with the
//! paper's tuned parameters: Butterworth ωc = 499 Hz, AKF q = 2.5e4, Levant
//! μ1 = 6.6, μ2 = 2.45. Levant's gains need C, which the papers estimated from
//! a wall hit rendered with FDM + Butterworth; we do the same (`estimate_c`).

use rayon::prelude::*;
use serde::Serialize;

use super::hit::{wall_hit, HitKnobs, TraceRow};
use super::scene::SceneSpec;
use super::search::{map_observed, MapResult, Observer};
use super::settings::{
    Accuracy, Criterion, MapSpec, Method, SearchKind, PAPER_B_STEP, PAPER_K_STEP,
};
use crate::error::SpecError;
use crate::estimators::{EstimatorKind, EstimatorSpec, FoawFit, FoawSpec, LevantSpec, QModel};
use crate::lipschitz::{self, LipschitzEstimate};

/// The 2018 paper's simulated device at 1 kHz.
pub fn seed_2018_scene() -> SceneSpec {
    SceneSpec::from_json(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#).expect("static scene")
}

/// The wall the Lipschitz constant is estimated on: 5 K steps, 2 B steps of
/// the 2011 paper's grid (a mid-range wall that renders with FDM + filter).
pub const C_WALL_K: f64 = 5.0 * PAPER_K_STEP;
pub const C_WALL_B: f64 = 2.0 * PAPER_B_STEP;

#[derive(Debug, Clone, Serialize)]
pub struct CEstimate {
    pub wall_k: f64,
    pub wall_b: f64,
    pub estimator: EstimatorSpec,
    pub estimate: LipschitzEstimate,
}

/// The 2018 paper's Butterworth cutoff, 499 Hz (its 1 kHz loop), or just
/// below Nyquist (0.499·f_s) on a slower loop.
pub fn paper_cutoff_hz(sample_hz: f64) -> f64 {
    499.0f64.min(0.499 * sample_hz)
}

/// C as the papers measured it: a wall hit with FDM + Butterworth (499 Hz, or
/// just below Nyquist), the encoder positions from first contact for 1 s, and
/// the largest |ẍ| of a smooth fit (see `lipschitz`).
pub fn estimate_c(scene: &SceneSpec) -> Result<CEstimate, SpecError> {
    let fc = paper_cutoff_hz(scene.control.sample_hz);
    let estimator: EstimatorSpec = EstimatorKind::Butterworth {
        cutoff_hz: fc,
        order: 2,
    }
    .into();
    let sc = SceneSpec {
        estimator: estimator.clone(),
        ..scene.clone()
    }
    .validate()?;
    let mut trace: Vec<TraceRow> = Vec::new();
    let knobs = HitKnobs {
        settle_s: 1.0,
        measure_s: 0.1,
    };
    wall_hit(&sc, C_WALL_K, C_WALL_B, knobs, &mut trace);
    let wall = scene.wall.position;
    let first = trace.iter().position(|r| r.y > wall).unwrap_or(0);
    let n = (1.0 / sc.dt) as usize;
    let ys: Vec<f64> = trace[first.saturating_sub(n / 10)..(first + n).min(trace.len())]
        .iter()
        .map(|r| r.y)
        .collect();
    let q = (scene.device.quantization > 0.0).then_some(scene.device.quantization);
    let estimate = lipschitz::estimate(&ys, scene.control.sample_hz, q)?;
    Ok(CEstimate {
        wall_k: C_WALL_K,
        wall_b: C_WALL_B,
        estimator,
        estimate,
    })
}

#[derive(Debug, Clone, Serialize)]
pub struct CompareRow {
    pub name: String,
    pub parameters: String,
    pub estimator: EstimatorSpec,
    pub map: MapResult,
    /// How the parameters were tuned (a tuned comparison), or absent when
    /// they are the paper's fixed values.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tuning: Option<RowTuning>,
}

/// A row's tune: what it tuned, what it found, what it cost.
#[derive(Debug, Clone, Serialize)]
pub struct RowTuning {
    /// The tuned parameters' values.
    pub params: std::collections::BTreeMap<String, f64>,
    /// Their bounds, as `name: min–max`.
    pub bounds: String,
    /// Maps the tune computed.
    pub evaluations: usize,
    pub elapsed_s: f64,
}

/// Two rows' K-widths in order, and whether the order is resolved.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PairOrder {
    /// The row with the larger K-width estimate (of equal ones, the
    /// earlier), and the other (names).
    pub wider: String,
    pub narrower: String,
    /// The wider row's K-width interval lies wholly above the other's: the
    /// order is wrong only if the wider's lower bound or the narrower's
    /// upper bound is, each with probability at most α = 1 − the scene's
    /// confidence (docs/zwidth.md, "Boundaries with intervals").
    pub resolved: bool,
    /// That probability's bound, 2α (a resolved order); the measured
    /// coverage of one standard map's interval is in docs/zwidth.md.
    pub error_at_most: f64,
}

/// Every pair of rows whose maps have K-width intervals (noisy scenes), in
/// the rows' order: which is wider and whether the intervals say so.
pub fn pair_orders(rows: &[CompareRow], confidence: f64) -> Vec<PairOrder> {
    let widths: Vec<(f64, Option<[f64; 2]>)> = rows
        .iter()
        .map(|r| (r.map.k_width, r.map.k_width_interval))
        .collect();
    orders(&widths)
        .into_iter()
        .map(|o| PairOrder {
            wider: rows[o.wider].name.clone(),
            narrower: rows[o.narrower].name.clone(),
            resolved: o.resolved,
            error_at_most: 2.0 * (1.0 - confidence),
        })
        .collect()
}

/// Two widths in order, by their places in the list given to [`orders`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexOrder {
    pub wider: usize,
    pub narrower: usize,
    /// The wider one's interval lies wholly above the other's.
    pub resolved: bool,
}

/// Every pair of `widths` (estimate, interval) that both have intervals, in
/// the list's order: the one with the larger estimate first (of equal
/// ones, the earlier), resolved when its interval lies wholly above the
/// other's. A resolved order is wrong only if the wider one's lower bound
/// or the other's upper bound is: with probability at most 2α, α each
/// bound's error rate (docs/zwidth.md, "Boundaries with intervals").
pub fn orders(widths: &[(f64, Option<[f64; 2]>)]) -> Vec<IndexOrder> {
    let mut out = Vec::new();
    for (i, &(ea, ia)) in widths.iter().enumerate() {
        for (j, &(eb, ib)) in widths.iter().enumerate().skip(i + 1) {
            let (Some(ia), Some(ib)) = (ia, ib) else {
                continue;
            };
            let ((w, iw), (n, in_)) = if eb > ea {
                ((j, ib), (i, ia))
            } else {
                ((i, ia), (j, ib))
            };
            out.push(IndexOrder {
                wider: w,
                narrower: n,
                resolved: iw[0] > in_[1],
            });
        }
    }
    out
}

#[derive(Debug, Clone, Serialize)]
pub struct CompareResult {
    pub lipschitz: CEstimate,
    pub rows: Vec<CompareRow>,
    /// Noisy scenes: each pair of rows' K-widths in order, resolved or not
    /// by their intervals (`pair_orders`).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub order: Vec<PairOrder>,
    /// The objective every row was tuned for, or absent: the paper's fixed
    /// parameters.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tuned_for: Option<String>,
    pub elapsed_s: f64,
}

/// The paper's four estimators with its tuned parameters.
pub fn paper_estimators(scene: &SceneSpec, c: f64) -> Vec<(String, String, EstimatorSpec)> {
    let fc = paper_cutoff_hz(scene.control.sample_hz);
    vec![
        (
            "FDM+filter".into(),
            format!("ωc = {fc} Hz"),
            EstimatorKind::Butterworth {
                cutoff_hz: fc,
                order: 2,
            }
            .into(),
        ),
        (
            "FOAW".into(),
            "none (best-fit, d = encoder step)".into(),
            EstimatorKind::Foaw(FoawSpec {
                fit: FoawFit::Best,
                d: None,
                max_window: 15,
                outlier_tolerance: false,
            })
            .into(),
        ),
        (
            "AKF".into(),
            "q = 2.5e4".into(),
            EstimatorKind::AdaptiveKalman {
                q: 2.5e4,
                q_model: QModel::WhiteJerk,
                rho: crate::estimators::kalman::DEFAULT_RHO,
            }
            .into(),
        ),
        (
            "Levant".into(),
            format!(
                "α = {:.2} m/s², λ = {:.3} m^½/s (μ1 = 6.6, μ2 = 2.45, C = {c:.3})",
                6.6 * c,
                2.45 * c.sqrt()
            ),
            EstimatorKind::Levant(LevantSpec {
                mu1: Some(6.6),
                mu2: Some(2.45),
                lipschitz: Some(c),
                ..Default::default()
            })
            .into(),
        ),
    ]
}

/// The map a comparison runs for each estimator: bisection over
/// B = 0 … 1000 N·s/m by `criterion` (the paper's impedance test, or the
/// time domain's stability), the engine `auto` picks for it.
pub fn map_spec(scene: SceneSpec, accuracy: &Accuracy, criterion: Criterion) -> MapSpec {
    MapSpec {
        scene,
        method: Method::Auto,
        criterion,
        search: SearchKind::Bisect,
        accuracy: accuracy.clone(),
        b: None,
        b_max: 1000.0,
        k_max: 1e7,
    }
}

pub fn compare(scene: &SceneSpec, accuracy: &Accuracy) -> Result<CompareResult, SpecError> {
    compare_observed(scene, accuracy, Criterion::Impedance, None, None)
}

/// The same, each estimator's map reporting to `observer` as scope 0, 1, …;
/// `estimators` replaces the paper's four (named by their labels).
pub fn compare_observed(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    estimators: Option<&[EstimatorSpec]>,
    observer: Option<std::sync::Arc<Observer>>,
) -> Result<CompareResult, SpecError> {
    if let Some(list) = estimators {
        check_estimators(scene, list)?;
    }
    let c = estimate_c(scene)?;
    let estimators = match estimators {
        Some(list) => list
            .iter()
            .map(|e| (e.label(), e.label(), e.clone()))
            .collect(),
        None => paper_estimators(scene, c.estimate.lipschitz),
    };
    if let Some(o) = &observer {
        o.set_scopes(estimators.len());
    }
    compare_rows(scene, accuracy, criterion, c, estimators, observer)
}

/// Most estimators one compare takes: the same limit in the API, the CLI
/// and Python.
pub const MAX_ESTIMATORS: usize = 20;

/// A compare's own estimator list: 1 to `MAX_ESTIMATORS`, each valid on
/// `scene` (its errors named `estimators[i].…`).
pub fn check_estimators(scene: &SceneSpec, list: &[EstimatorSpec]) -> Result<(), SpecError> {
    if list.is_empty() || list.len() > MAX_ESTIMATORS {
        return Err(SpecError::new(
            "estimators",
            list.len(),
            format!("give 1 to {MAX_ESTIMATORS} estimators, or leave it out for the paper's four"),
        ));
    }
    let sc = scene.validate().map_err(|e| e.within("scene"))?;
    for (i, e) in list.iter().enumerate() {
        sc.with_estimator(e.clone()).map_err(|err| SpecError {
            field: err
                .field
                .replacen("estimator", &format!("estimators[{i}]"), 1),
            ..err
        })?;
    }
    Ok(())
}

/// One map per (name, parameters, estimator), in parallel, as scopes 0, 1, …
/// of `observer` (whose scope count the caller sets).
pub fn compare_rows(
    scene: &SceneSpec,
    accuracy: &Accuracy,
    criterion: Criterion,
    c: CEstimate,
    estimators: Vec<(String, String, EstimatorSpec)>,
    observer: Option<std::sync::Arc<Observer>>,
) -> Result<CompareResult, SpecError> {
    let start = std::time::Instant::now();
    let rows = estimators
        .into_par_iter()
        .enumerate()
        .map(|(scope, (name, parameters, estimator))| {
            let spec = map_spec(
                SceneSpec {
                    estimator: estimator.clone(),
                    ..scene.clone()
                },
                accuracy,
                criterion,
            );
            Ok(CompareRow {
                name,
                parameters,
                estimator,
                map: map_observed(&spec, observer.clone(), scope as u32)?,
                tuning: None,
            })
        })
        .collect::<Result<Vec<_>, SpecError>>()?;
    Ok(CompareResult {
        lipschitz: c,
        order: pair_orders(&rows, scene.probe.confidence),
        rows,
        tuned_for: None,
        elapsed_s: start.elapsed().as_secs_f64(),
    })
}

impl CompareResult {
    /// Shaped like the 2018 paper's Table I.
    pub fn table(&self) -> String {
        let w = 14;
        let mut s = format!("{:<28}", "");
        for r in &self.rows {
            s.push_str(&format!("{:>w$}", r.name));
        }
        s.push('\n');
        let mut row = |label: &str, f: &dyn Fn(&CompareRow) -> String| {
            s.push_str(&format!("{label:<28}"));
            for r in &self.rows {
                s.push_str(&format!("{:>w$}", f(r)));
            }
            s.push('\n');
        };
        row("K-width (N/m)", &|r| format!("{:.3e}", r.map.k_width));
        if self.rows.iter().any(|r| r.map.k_width_interval.is_some()) {
            row("  interval low", &|r| {
                r.map
                    .k_width_interval
                    .map_or("-".into(), |i| format!("{:.3e}", i[0]))
            });
            row("  interval high", &|r| {
                r.map
                    .k_width_interval
                    .map_or("-".into(), |i| format!("{:.3e}", i[1]))
            });
        }
        row("B-width (N·s/m)", &|r| format!("{:.1}", r.map.b_width));
        row("Max. fidelity error (N·s/m)", &|r| {
            r.map
                .max_fidelity_error
                .map(|f| format!("{f:.2}"))
                .unwrap_or("-".into())
        });
        row("Trials", &|r| r.map.trials.to_string());
        if let Some(p) = self.order.first() {
            s.push_str(&format!(
                "K-width order (resolved: the intervals do not overlap, wrong with probability at most {:.0} %):\n",
                100.0 * p.error_at_most
            ));
            for p in &self.order {
                let verdict = if p.resolved {
                    "resolved"
                } else {
                    "not resolved (the intervals overlap)"
                };
                s.push_str(&format!(
                    "  {:<12} > {:<12} {verdict}\n",
                    p.wider, p.narrower
                ));
            }
        }
        match &self.tuned_for {
            Some(objective) => s.push_str(&format!(
                "Tunable parameters, each tuned for {objective} (argmin, draft search, finalists re-mapped):\n"
            )),
            None => s.push_str(
                "Tunable parameters (the 2018 paper's fixed values; `compare --tuned OBJECTIVE` tunes each first):\n",
            ),
        }
        for r in &self.rows {
            s.push_str(&format!("  {:<12} {}\n", r.name, r.parameters));
            if let Some(t) = &r.tuning {
                s.push_str(&format!(
                    "  {:<12} tuned over {} in {} maps, {:.1} s\n",
                    "", t.bounds, t.evaluations, t.elapsed_s
                ));
            }
            if let EstimatorKind::Levant(l) = &r.estimator.kind {
                if let Ok(g) = l.gains() {
                    s.push_str(&format!("  {:<12} {}\n", "", g.report()));
                }
            }
        }
        let e = &self.lipschitz;
        s.push_str(&format!(
            "C = {:.3} m/s² from a wall hit at K = {:.1} N/m, B = {:.2} N·s/m with {} (local quadratic fit over {} samples)\n",
            e.estimate.lipschitz,
            e.wall_k,
            e.wall_b,
            e.estimator.label(),
            2 * e.estimate.half_window + 1
        ));
        if let Some(r) = self.rows.first() {
            let criterion = match r.map.criterion {
                Criterion::Impedance => "impedance (Re Z ≥ 0 over the probe band)",
                Criterion::Stability => {
                    "stability (the wall hit's RMS below its threshold; eigenvalues on a linear scene)"
                }
                Criterion::StrictPassivity => "strict passivity (Colgate & Schenkel)",
            };
            s.push_str(&format!(
                "model: {}\ncriterion: {criterion}, {}\n",
                r.map.model, r.map.resolution
            ));
        }
        s.push_str(&format!("elapsed: {:.2} s\n", self.elapsed_s));
        s
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An explicit list takes 1 to MAX_ESTIMATORS (20, the API's limit),
    /// each valid on the scene and named by its place when not.
    #[test]
    fn a_list_takes_one_to_twenty_valid_estimators_named_by_place() {
        let scene = seed_2018_scene();
        let fdm = EstimatorSpec::from_json(r#"{"kind":"fdm"}"#).unwrap();
        assert_eq!(MAX_ESTIMATORS, 20);
        for n in [1, 20] {
            assert_eq!(
                check_estimators(&scene, &vec![fdm.clone(); n]),
                Ok(()),
                "{n}"
            );
        }
        for n in [0, 21] {
            let e = check_estimators(&scene, &vec![fdm.clone(); n]).unwrap_err();
            assert_eq!(
                (e.field.as_str(), e.value.clone()),
                ("estimators", n.to_string())
            );
            assert!(e.allowed.starts_with("give 1 to 20 estimators"), "{e}");
        }
        // The seed device samples at 1 kHz: a 600 Hz cutoff is past Nyquist.
        let bad = EstimatorSpec::from_json(r#"{"kind":"butterworth","cutoff_hz":600}"#).unwrap();
        let e = check_estimators(&scene, &[fdm.clone(), bad]).unwrap_err();
        assert_eq!(e.field, "estimators[1].cutoff_hz", "{e}");
    }

    #[test]
    fn a_stability_comparison_runs_the_time_engine_on_a_nonlinear_scene() {
        // The seed device at 1 kHz with short hits: `auto` answers the
        // stability criterion with the wall hit (the impedance criterion
        // with the multisine probe), every row's map says so, and the
        // table names the criterion the maps used.
        let scene = SceneSpec::from_json(
            r#"{"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"home_distance":0.001,"settle_s":0.2,"measure_s":0.1}}"#,
        )
        .unwrap();
        let fdm: EstimatorSpec = EstimatorKind::Fdm {}.into();
        let r = compare_observed(
            &scene,
            &Accuracy::Preset(crate::zwidth::settings::Preset::Draft),
            Criterion::Stability,
            Some(&[fdm]),
            None,
        )
        .unwrap();
        let map = &r.rows[0].map;
        assert_eq!(map.criterion, Criterion::Stability);
        assert!(
            map.model.starts_with("time-domain wall-hit simulation"),
            "{}",
            map.model
        );
        assert!(map.k_width > 0.0);
        assert!(r
            .table()
            .contains("criterion: stability (the wall hit's RMS below its threshold"));
        let spec = map_spec(scene, &Accuracy::default(), Criterion::Impedance);
        assert_eq!(spec.criterion, Criterion::Impedance);
    }

    #[test]
    fn pairs_are_ordered_by_estimate_and_resolved_only_by_disjoint_intervals() {
        // One quick map (a linear scene, B = 0) to carry made-up widths.
        let spec = MapSpec {
            b: Some(vec![0.0]),
            ..map_spec(
                SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0}}"#).unwrap(),
                &Accuracy::Preset(crate::zwidth::settings::Preset::Draft),
                Criterion::Impedance,
            )
        };
        let base = map_observed(&spec, None, 0).unwrap();
        let row = |name: &str, k: f64, interval: Option<[f64; 2]>| CompareRow {
            name: name.into(),
            parameters: String::new(),
            estimator: EstimatorKind::Fdm {}.into(),
            map: MapResult {
                k_width: k,
                k_width_interval: interval,
                ..base.clone()
            },
            tuning: None,
        };
        let rows = [
            row("A", 100.0, Some([90.0, 110.0])),
            row("B", 120.0, Some([111.0, 130.0])),
            row("C", 105.0, Some([95.0, 125.0])),
            row("D", 50.0, None),
            row("E", 200.0, Some([110.0, 210.0])),
        ];
        let o = pair_orders(&rows, 0.95);
        let got: Vec<(&str, &str, bool)> = o
            .iter()
            .map(|p| (p.wider.as_str(), p.narrower.as_str(), p.resolved))
            .collect();
        // D has no interval; B's [111, 130] lies above A's [90, 110]; C's
        // overlaps both; E's [110, 210] only touches A's upper end.
        assert_eq!(
            got,
            [
                ("B", "A", true),
                ("C", "A", false),
                ("E", "A", false),
                ("B", "C", false),
                ("E", "B", false),
                ("E", "C", false),
            ]
        );
        // Equal estimates: the earlier row is named first.
        let tie = pair_orders(
            &[
                row("P", 1.0, Some([0.5, 2.0])),
                row("Q", 1.0, Some([0.9, 1.1])),
            ],
            0.95,
        );
        assert_eq!(
            (tie[0].wider.as_str(), tie[0].narrower.as_str()),
            ("P", "Q")
        );
        // Each of the two facing bounds wrong with probability ≤ α = 5 %.
        assert!(o.iter().all(|p| (p.error_at_most - 0.10).abs() < 1e-12));
        let t = CompareResult {
            lipschitz: estimate_c(&seed_2018_scene()).unwrap(),
            rows: rows.to_vec(),
            order: o,
            tuned_for: None,
            elapsed_s: 0.0,
        }
        .table();
        assert!(t.contains("K-width order (resolved: the intervals do not overlap, wrong with probability at most 10 %)"), "{t}");
        assert!(
            t.contains("  B            > A            resolved\n"),
            "{t}"
        );
        assert!(
            t.contains("  C            > A            not resolved (the intervals overlap)\n"),
            "{t}"
        );
    }

    #[test]
    fn the_paper_cutoff_stays_below_nyquist() {
        assert_eq!(paper_cutoff_hz(1000.0), 499.0);
        assert_eq!(paper_cutoff_hz(10_000.0), 499.0);
        assert_eq!(paper_cutoff_hz(500.0), 249.5);
    }

    #[test]
    fn c_comes_from_the_wall_contact() {
        // docs/zwidth.md records C = 1.098 m/s² for the 2018 device at
        // 1 kHz, from the FDM + Butterworth hit at K = 7 441.2 N/m,
        // B = 29.76 N·s/m (also pinned through the CLI in tests/it/cli.rs).
        // The window starts at first contact: the free flight before it
        // accelerates at only push/m = 0.3572/0.52 = 0.69 m/s².
        let c = estimate_c(&seed_2018_scene()).unwrap();
        assert!((c.estimate.lipschitz / 1.098 - 1.0).abs() < 0.005, "{c:?}");
        assert_eq!((c.wall_k, c.wall_b), (C_WALL_K, C_WALL_B));
        // The window opens 0.1 s (a tenth of its 1 s) before the contact,
        // and the largest |ẍ| is the impact, just after it.
        assert!(
            (0.1..0.15).contains(&c.estimate.at_s),
            "{}",
            c.estimate.at_s
        );
        // The table states where C came from: 5 and 2 of the 2011 paper's
        // steps (1488.24 N/m, 14.88 N·s/m) and the fit's window.
        let t = CompareResult {
            lipschitz: c.clone(),
            rows: Vec::new(),
            order: Vec::new(),
            tuned_for: None,
            elapsed_s: 0.0,
        }
        .table();
        let window = 2 * c.estimate.half_window + 1;
        assert!(
            t.contains(&format!(
                "from a wall hit at K = 7441.2 N/m, B = 29.76 N·s/m with butterworth(499 Hz, order 2) (local quadratic fit over {window} samples)"
            )),
            "{t}"
        );
        assert!(t.contains("the 2018 paper's fixed values"), "{t}");
    }
}
