//! What finished experiments show: each map as a summary row, the points as
//! CSV, the plot as SVG, and the comparison of several runs on one scene.
//! Pure: reads stored specs and results (JSON), touches no store or HTTP.

use serde::Serialize;
use serde_json::Value;

use crate::error::SpecError;
use crate::experiment::ExperimentSpec;
use crate::plot::{lines_svg, zwidth_map_svg, MapPlotPoint, Series};
use crate::zwidth::compare::seed_2018_scene;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::{area, BoundaryPoint};

/// One map of a finished experiment.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct MapSummary {
    /// The experiment it belongs to.
    pub run: String,
    /// Its name within the experiment (estimator, compare row, sweep variant).
    pub label: String,
    /// The estimator, in words.
    pub estimator: String,
    pub method: String,
    pub criterion: String,
    /// N/m.
    pub k_width: f64,
    /// N·s/m.
    pub b_width: f64,
    /// N·s/m; null when the criterion gives no fidelity.
    pub max_fidelity_error: Option<f64>,
    /// ∫ K_max dB (N/m · N·s/m).
    pub area: f64,
    /// Noisy scenes: the K-width's confidence interval (N/m) and the
    /// B-width's (N·s/m), from the boundary's (docs/zwidth.md); absent where
    /// the verdicts are exact.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_width_interval: Option<[f64; 2]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub b_width_interval: Option<[f64; 2]>,
    #[serde(skip)]
    pub boundary: Vec<BoundaryPoint>,
    #[serde(skip)]
    pub points: Vec<Value>,
    /// The scene without its estimator: what "the same scene" means.
    #[serde(skip)]
    pub scene: SceneSpec,
}

fn summary(run: &str, label: String, scene: &SceneSpec, map: &Value) -> MapSummary {
    let boundary: Vec<BoundaryPoint> = map["boundary"]
        .as_array()
        .map(|a| {
            a.iter()
                .map(|p| BoundaryPoint {
                    b: p["b"].as_f64().unwrap_or(0.0),
                    k_max: p["k_max"].as_f64().unwrap_or(0.0),
                    k_lo: p["k_lo"].as_f64(),
                    k_hi: p["k_hi"].as_f64(),
                })
                .collect()
        })
        .unwrap_or_default();
    let mut bare = scene.clone();
    bare.estimator = SceneSpec::default().estimator;
    MapSummary {
        run: run.into(),
        label,
        estimator: scene.estimator.label(),
        method: map["method"].as_str().unwrap_or("").into(),
        criterion: map["criterion"].as_str().unwrap_or("").into(),
        k_width: map["k_width"].as_f64().unwrap_or(0.0),
        b_width: map["b_width"].as_f64().unwrap_or(0.0),
        max_fidelity_error: map["max_fidelity_error"].as_f64(),
        // Results stored before `area` existed: the same integral.
        area: map["area"].as_f64().unwrap_or_else(|| area(&boundary)),
        k_width_interval: interval(&map["k_width_interval"]),
        b_width_interval: interval(&map["b_width_interval"]),
        boundary,
        points: map["points"].as_array().cloned().unwrap_or_default(),
        scene: bare,
    }
}

/// A stored `[low, high]`, finite and in order; anything else is none.
fn interval(v: &Value) -> Option<[f64; 2]> {
    match v.as_array()?.as_slice() {
        [lo, hi] => {
            let (lo, hi) = (lo.as_f64()?, hi.as_f64()?);
            (lo.is_finite() && hi.is_finite() && lo <= hi).then_some([lo, hi])
        }
        _ => None,
    }
}

/// Every map of experiment `run` with its stored `result`.
pub fn maps(run: &str, spec: &ExperimentSpec, result: &Value) -> Vec<MapSummary> {
    match spec {
        ExperimentSpec::Map(m) => vec![summary(run, m.scene.estimator.label(), &m.scene, result)],
        ExperimentSpec::Compare(c) => {
            let base = c.scene.clone().unwrap_or_else(seed_2018_scene);
            rows(result)
                .iter()
                .map(|r| {
                    let mut scene = base.clone();
                    if let Ok(e) = serde_json::from_value(r["estimator"].clone()) {
                        scene.estimator = e;
                    }
                    let label = r["name"].as_str().unwrap_or("").to_string();
                    summary(run, label, &scene, &r["map"])
                })
                .collect()
        }
        ExperimentSpec::Sweep(s) => {
            let variants = s.variant_specs().unwrap_or_default();
            rows(result)
                .iter()
                .zip(variants)
                .map(|(r, (label, _, m))| summary(run, label, &m.scene, &r["map"]))
                .collect()
        }
        // A tune's evaluations are not maps it keeps (see `TuneResult::csv`).
        ExperimentSpec::Tune(_) => Vec::new(),
    }
}

/// A stored tune result, read back.
pub fn tune_result(result: &Value) -> Result<crate::tune::TuneResult, String> {
    serde_json::from_value(result.clone()).map_err(|e| format!("not a tune result: {e}"))
}

fn rows(result: &Value) -> &[Value] {
    result["rows"].as_array().map(Vec::as_slice).unwrap_or(&[])
}

/// One row of a comparison: a map and how it differs from the first row.
#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct ComparisonRow {
    #[serde(flatten)]
    pub map: MapSummary,
    /// Differences from the first row (this − first), absolute and in %.
    pub k_width_diff: f64,
    pub k_width_diff_pct: Option<f64>,
    pub b_width_diff: f64,
    pub b_width_diff_pct: Option<f64>,
    pub max_fidelity_error_diff: Option<f64>,
    pub area_diff: f64,
    pub area_diff_pct: Option<f64>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct Comparison {
    pub runs: Vec<String>,
    pub rows: Vec<ComparisonRow>,
    /// Index of the row with the largest K-width, B-width, area, and the
    /// smallest max fidelity error.
    pub best: Best,
    /// Noisy scenes: each pair of rows' K-widths and B-widths in order,
    /// resolved or not by their intervals.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub order: Vec<RowOrder>,
    /// Things to know before reading the table (e.g. different criteria).
    pub notes: Vec<String>,
}

#[derive(Debug, Clone, Serialize, utoipa::ToSchema)]
pub struct Best {
    pub k_width: usize,
    /// Whether the K-width's best is ranked above every other row by the
    /// intervals (always, on exact verdicts without intervals); a page
    /// marks it best only then.
    pub k_width_resolved: bool,
    pub b_width: usize,
    /// The same for the B-width.
    pub b_width_resolved: bool,
    pub area: usize,
    pub max_fidelity_error: Option<usize>,
}

/// A run's id in 8 characters: its last ones (a uuid v7 starts with its
/// time, the same for runs submitted within a minute).
pub fn short_id(id: &str) -> &str {
    let n = id.chars().count();
    let skip = n.saturating_sub(8);
    &id[id.char_indices().nth(skip).map_or(0, |(i, _)| i)..]
}

/// Two rows' widths in order (`wider` and `narrower` index `rows`).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct RowOrder {
    /// `k_width` or `b_width`.
    pub width: &'static str,
    pub wider: usize,
    pub narrower: usize,
    /// The wider row's interval lies wholly above the other's.
    pub resolved: bool,
    /// A resolved order's error bound, 2α (α = 1 − the scene's confidence).
    pub error_at_most: f64,
}

/// The orders of one width over `maps`, and whether `best` is ranked above
/// every other row: every order with it resolved in its favour, and every
/// row has an interval if any has (rows without intervals are exact; one
/// beside rows with intervals cannot be ranked against them).
fn width_orders(
    maps: &[MapSummary],
    width: &'static str,
    of: impl Fn(&MapSummary) -> (f64, Option<[f64; 2]>),
    best: usize,
    confidence: f64,
) -> (Vec<RowOrder>, bool) {
    let widths: Vec<(f64, Option<[f64; 2]>)> = maps.iter().map(&of).collect();
    let orders: Vec<RowOrder> = crate::zwidth::compare::orders(&widths)
        .into_iter()
        .map(|o| RowOrder {
            width,
            wider: o.wider,
            narrower: o.narrower,
            resolved: o.resolved,
            error_at_most: 2.0 * (1.0 - confidence),
        })
        .collect();
    let any = widths.iter().any(|w| w.1.is_some());
    let all = widths.iter().all(|w| w.1.is_some());
    let resolved = (!any || all)
        && orders
            .iter()
            .filter(|o| o.wider == best || o.narrower == best)
            .all(|o| o.wider == best && o.resolved);
    (orders, resolved)
}

fn pct(d: f64, base: f64) -> Option<f64> {
    (base != 0.0).then(|| 100.0 * d / base)
}

fn argmax(v: impl Iterator<Item = f64>) -> usize {
    v.enumerate()
        .fold(
            (0, f64::MIN),
            |(bi, bv), (i, x)| if x > bv { (i, x) } else { (bi, bv) },
        )
        .0
}

/// Compare the maps of several runs; they must share one scene (the
/// estimator aside). `runs` are the ids in the order asked.
pub fn compare(runs: Vec<String>, maps: Vec<MapSummary>) -> Result<Comparison, SpecError> {
    let first = maps
        .first()
        .ok_or_else(|| SpecError::new("runs", runs.join(","), "the runs hold no maps to compare"))?
        .clone();
    if let Some(other) = maps.iter().find(|m| m.scene != first.scene) {
        return Err(SpecError::new(
            "runs",
            &other.run,
            format!(
                "ran on a different scene from run {} ({}): compare runs on the same device, loop, wall and protocol",
                first.run,
                scene_difference(&first.scene, &other.scene)
            ),
        ));
    }
    let mut notes = Vec::new();
    let criteria: std::collections::BTreeSet<_> = maps
        .iter()
        .map(|m| (m.method.as_str(), m.criterion.as_str()))
        .collect();
    if criteria.len() > 1 {
        notes.push(format!(
            "the maps used different engines or criteria ({}): widths are not directly comparable",
            criteria
                .iter()
                .map(|(m, c)| format!("{m}/{c}"))
                .collect::<Vec<_>>()
                .join(", ")
        ));
    }
    let (k_best, b_best) = (
        argmax(maps.iter().map(|m| m.k_width)),
        argmax(maps.iter().map(|m| m.b_width)),
    );
    let confidence = first.scene.probe.confidence;
    let (mut order, k_width_resolved) = width_orders(
        &maps,
        "k_width",
        |m| (m.k_width, m.k_width_interval),
        k_best,
        confidence,
    );
    let (b_order, b_width_resolved) = width_orders(
        &maps,
        "b_width",
        |m| (m.b_width, m.b_width_interval),
        b_best,
        confidence,
    );
    order.extend(b_order);
    let best = Best {
        k_width: k_best,
        k_width_resolved,
        b_width: b_best,
        b_width_resolved,
        area: argmax(maps.iter().map(|m| m.area)),
        max_fidelity_error: maps
            .iter()
            .enumerate()
            .filter_map(|(i, m)| m.max_fidelity_error.map(|f| (i, f)))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .map(|(i, _)| i),
    };
    let rows = maps
        .into_iter()
        .map(|m| ComparisonRow {
            k_width_diff: m.k_width - first.k_width,
            k_width_diff_pct: pct(m.k_width - first.k_width, first.k_width),
            b_width_diff: m.b_width - first.b_width,
            b_width_diff_pct: pct(m.b_width - first.b_width, first.b_width),
            max_fidelity_error_diff: m
                .max_fidelity_error
                .zip(first.max_fidelity_error)
                .map(|(a, b)| a - b),
            area_diff: m.area - first.area,
            area_diff_pct: pct(m.area - first.area, first.area),
            map: m,
        })
        .collect();
    Ok(Comparison {
        runs,
        rows,
        best,
        order,
        notes,
    })
}

/// The first top-level part of the scene that differs, in words.
fn scene_difference(a: &SceneSpec, b: &SceneSpec) -> String {
    let (va, vb) = (
        serde_json::to_value(a).unwrap_or_default(),
        serde_json::to_value(b).unwrap_or_default(),
    );
    for part in ["device", "loop", "wall", "hit", "probe"] {
        if va[part] != vb[part] {
            return format!("{part} {} vs {}", va[part], vb[part]);
        }
    }
    "the scenes differ".into()
}

impl Comparison {
    /// A plain-text table: each width with its interval (noisy scenes),
    /// then every pair's order, resolved or not.
    pub fn table(&self) -> String {
        let intervals = self
            .rows
            .iter()
            .any(|r| r.map.k_width_interval.is_some() || r.map.b_width_interval.is_some());
        let k_iv =
            |i: Option<[f64; 2]>| i.map_or("-".into(), |[lo, hi]| format!("[{lo:.3e}, {hi:.3e}]"));
        let b_iv =
            |i: Option<[f64; 2]>| i.map_or("-".into(), |[lo, hi]| format!("[{lo:.1}, {hi:.1}]"));
        let mut s = format!(
            "{:<38} {:>11} {:>9} {:>9} {:>11} {:>10} {:>9}",
            "run / map", "K-width", "ΔK %", "B-width", "max fid.", "area", "Δarea %"
        );
        if intervals {
            s.push_str(&format!(
                " {:>22} {:>22}",
                "K-width interval", "B-width interval"
            ));
        }
        s.push('\n');
        let name = |m: &MapSummary| format!("{} {}", short_id(&m.run), m.label);
        for r in &self.rows {
            let m = &r.map;
            s.push_str(&format!(
                "{:<38} {:>11.4e} {:>9} {:>9.1} {:>11} {:>10.3e} {:>9}",
                name(m).chars().take(38).collect::<String>(),
                m.k_width,
                r.k_width_diff_pct
                    .map_or("-".into(), |p| format!("{p:+.1}")),
                m.b_width,
                m.max_fidelity_error
                    .map_or("-".into(), |f| format!("{f:.2}")),
                m.area,
                r.area_diff_pct.map_or("-".into(), |p| format!("{p:+.1}")),
            ));
            if intervals {
                s.push_str(&format!(
                    " {:>22} {:>22}",
                    k_iv(m.k_width_interval),
                    b_iv(m.b_width_interval)
                ));
            }
            s.push('\n');
        }
        for width in ["k_width", "b_width"] {
            let orders: Vec<&RowOrder> = self.order.iter().filter(|o| o.width == width).collect();
            let Some(first) = orders.first() else {
                continue;
            };
            s.push_str(&format!(
                "{} order (resolved: the intervals do not overlap, wrong with probability at most {:.0} %):\n",
                if width == "k_width" { "K-width" } else { "B-width" },
                100.0 * first.error_at_most
            ));
            for o in orders {
                s.push_str(&format!(
                    "  {} > {}: {}\n",
                    name(&self.rows[o.wider].map),
                    name(&self.rows[o.narrower].map),
                    if o.resolved {
                        "resolved"
                    } else {
                        "not resolved (the intervals overlap)"
                    }
                ));
            }
        }
        s
    }

    /// Every boundary K(B) on one chart.
    pub fn svg(&self) -> Result<String, String> {
        boundaries_svg("Z-width boundaries", self.rows.iter().map(|r| &r.map))
    }

    /// The same, each map named by `name` (the dashboard names runs A, B, …).
    pub fn svg_named(&self, name: impl Fn(&MapSummary) -> String) -> Result<String, String> {
        let series: Vec<Series> = self
            .rows
            .iter()
            .map(|r| Series::boundary(name(&r.map), &r.map.boundary))
            .collect();
        lines_svg("Z-width boundaries", "B (N·s/m)", "K (N/m)", &series)
    }
}

fn boundaries_svg<'a>(
    title: &str,
    maps: impl Iterator<Item = &'a MapSummary>,
) -> Result<String, String> {
    let series: Vec<Series> = maps
        .map(|m| {
            let name = format!("{} {}", short_id(&m.run), m.label);
            Series::boundary(name, &m.boundary)
        })
        .collect();
    lines_svg(title, "B (N·s/m)", "K (N/m)", &series)
}

/// CSV of every evaluated point of every map: map, k, b, renders,
/// fidelity, and on noisy scenes whether the verdict was decided, its
/// margin (N·s/m) with standard error, and the realizations it took
/// (empty where a map has none).
pub fn points_csv(maps: &[MapSummary]) -> String {
    let mut s = String::from(
        "map,k_n_per_m,b_ns_per_m,renders,fidelity_ns_per_m,decided,margin_ns_per_m,margin_se_ns_per_m,realizations\n",
    );
    let cell = |v: &Value| match v {
        Value::Null => String::new(),
        v => v.to_string(),
    };
    for m in maps {
        let label = m.label.replace([',', '"', '\n'], " ");
        for p in &m.points {
            let ok = p["stable"]
                .as_bool()
                .or(p["passive"].as_bool())
                .unwrap_or(false);
            s.push_str(&format!(
                "{label},{},{},{ok},{},{},{},{},{}\n",
                p["k"],
                p["b"],
                cell(&p["fidelity"]),
                cell(&p["decided"]),
                cell(&p["margin"]),
                cell(&p["margin_se"]),
                cell(&p["realizations"])
            ));
        }
    }
    s
}

/// The plot of a finished experiment: one map in the 2018 paper's Fig. 7
/// style; a parameter sweep as K-width against the parameter; several maps
/// as their boundaries on one chart.
pub fn svg(spec: &ExperimentSpec, maps: &[MapSummary], result: &Value) -> Result<String, String> {
    match (spec, maps) {
        (ExperimentSpec::Tune(_), _) => tune_result(result)?.svg(),
        (ExperimentSpec::Map(_), [m]) => {
            let points: Vec<MapPlotPoint> = m.points.iter().map(MapPlotPoint::from_json).collect();
            let label = if m.criterion == "stability" {
                "stable"
            } else {
                "passive"
            };
            zwidth_map_svg(
                &format!("Z-width: {}", m.label),
                &points,
                &m.boundary,
                label,
            )
        }
        (ExperimentSpec::Sweep(s), _) if s.parameter.is_some() => {
            let path = s.parameter.as_ref().map(|p| p.path.as_str()).unwrap_or("");
            let pts: Vec<(f64, f64)> = rows(result)
                .iter()
                .filter_map(|r| Some((r["value"].as_f64()?, r["k_width"].as_f64()?)))
                .collect();
            // Noisy scenes: each row's map carries the K-width's interval.
            let bars = rows(result)
                .iter()
                .filter_map(|r| {
                    let i = r["map"]["k_width_interval"].as_array()?;
                    Some((
                        r["value"].as_f64()?,
                        i.first()?.as_f64()?,
                        i.get(1)?.as_f64()?,
                    ))
                })
                .collect();
            lines_svg(
                &format!("K-width against {path}"),
                path,
                "K-width (N/m)",
                &[Series::new("K-width", pts).with_intervals(bars)],
            )
        }
        _ => boundaries_svg("Z-width boundaries", maps.iter()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::search::map;
    use crate::zwidth::settings::MapSpec;

    fn run(id: &str, scene: &str) -> (ExperimentSpec, Value) {
        let spec: MapSpec = serde_json::from_str(&format!(
            r#"{{"scene":{scene},"criterion":"strict_passivity","b":[0,5,10]}}"#
        ))
        .unwrap();
        let result = serde_json::to_value(map(&spec).unwrap()).unwrap();
        let _ = id;
        (ExperimentSpec::Map(spec), result)
    }

    #[test]
    fn comparison_of_fdm_and_butterworth_runs() {
        let lin =
            r#""device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}"#;
        let (s1, r1) = run("a", &format!(r#"{{{lin},"estimator":{{"kind":"fdm"}}}}"#));
        let (s2, r2) = run(
            "b",
            &format!(r#"{{{lin},"estimator":{{"kind":"butterworth","cutoff_hz":100}}}}"#),
        );
        let mut all = maps("run-a", &s1, &r1);
        all.extend(maps("run-b", &s2, &r2));
        let c = compare(vec!["run-a".into(), "run-b".into()], all).unwrap();
        // FDM, strict passivity (Colgate & Schenkel): K = 2(b − |B|)/T with
        // b = 13.2 N·s/m, T = 1 ms: 26 400, 16 400, 6 400 N/m at B = 0, 5, 10.
        let fdm = &c.rows[0].map;
        assert!((fdm.k_width - 26_400.0).abs() < 1.0, "{}", fdm.k_width);
        // Trapezoids over those three points: 5·(26 400 + 16 400)/2 + 5·(16 400 + 6 400)/2.
        assert!((fdm.area - 164_000.0).abs() < 20.0, "{}", fdm.area);
        let d = &c.rows[1];
        assert_eq!(d.k_width_diff, d.map.k_width - fdm.k_width);
        assert_eq!(c.rows[0].k_width_diff, 0.0);
        assert!(c.svg().unwrap().contains("<svg"));
        assert!(c.table().contains("run-a"));
        // Exact verdicts (no intervals): the best is ranked, no order listed.
        assert!(c.best.k_width_resolved && c.order.is_empty());
        let csv = points_csv(&c.rows.iter().map(|r| r.map.clone()).collect::<Vec<_>>());
        assert_eq!(csv.lines().count(), 1 + 6);

        // A different device is refused, naming the run.
        let (s3, r3) = run(
            "c",
            r#"{"device":{"mass":1,"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        );
        let mut all = maps("run-a", &s1, &r1);
        all.extend(maps("run-c", &s3, &r3));
        let e = compare(vec!["run-a".into(), "run-c".into()], all).unwrap_err();
        assert_eq!((e.field.as_str(), e.value.as_str()), ("runs", "run-c"));
        assert!(e.allowed.contains("device"), "{}", e.allowed);
    }

    /// A map summary with a K-width and B-width and their intervals (as a
    /// noisy scene's stored result has them) on the default scene.
    fn noisy(run: &str, k: f64, ki: Option<[f64; 2]>, b: f64, bi: Option<[f64; 2]>) -> MapSummary {
        let result = serde_json::json!({
            "method": "frequency", "criterion": "impedance",
            "k_width": k, "b_width": b, "area": 1.0,
            "k_width_interval": ki, "b_width_interval": bi,
            "boundary": [], "points": []
        });
        summary(run, run.to_uppercase(), &SceneSpec::default(), &result)
    }

    #[test]
    fn the_best_width_is_marked_only_where_its_intervals_rank_it_first() {
        // The README compare's K-widths (docs/zwidth.md, output of
        // 2026-12-06): AKF's 6.012e5 in [4.286e5, 6.132e5] overlaps
        // FDM+filter's [4.316e5, 4.435e5]; FOAW's [3.572e5, 4.048e5] lies
        // below both. B-widths: FDM+filter's [990, 997] above AKF's [800, 830].
        let rows = vec![
            noisy(
                "fdm",
                4.405e5,
                Some([4.316e5, 4.435e5]),
                997.0,
                Some([990.0, 997.0]),
            ),
            noisy(
                "foaw",
                3.988e5,
                Some([3.572e5, 4.048e5]),
                997.0,
                Some([990.0, 997.0]),
            ),
            noisy(
                "akf",
                6.012e5,
                Some([4.286e5, 6.132e5]),
                818.4,
                Some([800.0, 830.0]),
            ),
        ];
        let c = compare(vec!["r".into()], rows.clone()).unwrap();
        assert_eq!(c.best.k_width, 2);
        assert!(
            !c.best.k_width_resolved,
            "AKF's interval overlaps FDM+filter's"
        );
        // B: FDM+filter and FOAW tie (the earlier is best) and overlap.
        assert_eq!((c.best.b_width, c.best.b_width_resolved), (0, false));
        let k: Vec<(usize, usize, bool)> = c
            .order
            .iter()
            .filter(|o| o.width == "k_width")
            .map(|o| (o.wider, o.narrower, o.resolved))
            .collect();
        assert_eq!(k, [(0, 1, true), (2, 0, false), (2, 1, true)]);
        // 2α at the scene's confidence, 0.95.
        assert!(c
            .order
            .iter()
            .all(|o| (o.error_at_most - 0.1).abs() < 1e-12));
        let t = c.table();
        assert!(t.contains("[4.286e5, 6.132e5]"), "{t}");
        assert!(
            t.contains("akf AKF > fdm FDM: not resolved (the intervals overlap)"),
            "{t}"
        );
        assert!(t.contains("fdm FDM > foaw FOAW: resolved"), "{t}");
        assert!(t.contains("[800.0, 830.0]"), "{t}");
        // Without AKF, FDM+filter's K-width is resolved best over FOAW.
        let c = compare(vec!["r".into()], rows[..2].to_vec()).unwrap();
        assert_eq!((c.best.k_width, c.best.k_width_resolved), (0, true));
        // A row without an interval beside rows with one is not ranked:
        // its best is not resolved.
        let mut bare = rows[2].clone();
        bare.k_width_interval = None;
        let c = compare(vec!["r".into()], vec![rows[0].clone(), bare]).unwrap();
        assert_eq!((c.best.k_width, c.best.k_width_resolved), (1, false));
        // The K-widths' orders under their name, then the B-widths'.
        let (k_at, b_at) = (
            t.find("K-width order (resolved").unwrap(),
            t.find("B-width order (resolved").unwrap(),
        );
        assert!(
            k_at < b_at && t[k_at..b_at].contains("akf AKF > fdm FDM"),
            "{t}"
        );
        // Best ranked above every other row though another pair overlaps:
        // A [10, 12] above B [5, 8] and C [6, 9], which overlap each other.
        let three = vec![
            noisy("a", 11.0, Some([10.0, 12.0]), 1.0, None),
            noisy("b", 7.0, Some([5.0, 8.0]), 1.0, None),
            noisy("c", 8.0, Some([6.0, 9.0]), 1.0, None),
        ];
        let c = compare(vec!["r".into()], three).unwrap();
        assert_eq!((c.best.k_width, c.best.k_width_resolved), (0, true));
        // K-width intervals alone (no B-width's) still get their column.
        assert!(c.table().contains("[1.000e1, 1.200e1]"), "{}", c.table());
        // A stored interval that is not two finite numbers in order is none.
        for bad in [
            serde_json::json!([2.0, 1.0]),
            serde_json::json!([1.0]),
            serde_json::json!("x"),
        ] {
            assert_eq!(interval(&bad), None, "{bad}");
        }
    }
}
