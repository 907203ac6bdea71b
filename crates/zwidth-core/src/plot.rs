//! SVG plots (plotters, SVG backend only: no system fonts needed).

use plotters::prelude::*;

use crate::zwidth::search::BoundaryPoint;

/// One named line, and optionally a confidence interval at some of its x
/// (drawn as vertical bars in the line's colour).
pub struct Series {
    pub name: String,
    pub points: Vec<(f64, f64)>,
    /// (x, lo, hi): the interval of the quantity at x.
    pub intervals: Vec<(f64, f64, f64)>,
}

impl Series {
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>) -> Self {
        Self {
            name: name.into(),
            points,
            intervals: Vec::new(),
        }
    }

    /// With these intervals, (x, lo, hi) each.
    pub fn with_intervals(mut self, intervals: Vec<(f64, f64, f64)>) -> Self {
        self.intervals = intervals;
        self
    }

    /// A boundary K(B), its points' intervals included.
    pub fn boundary(name: impl Into<String>, boundary: &[BoundaryPoint]) -> Self {
        Self::new(name, boundary.iter().map(|p| (p.b, p.k_max)).collect()).with_intervals(
            boundary
                .iter()
                .filter_map(|p| Some((p.b, p.k_lo?, p.k_hi?)))
                .collect(),
        )
    }
}

/// A log–log line chart, one coloured line with markers per series and a
/// legend; returns the SVG text.
pub fn loglog_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<String, String> {
    let pts = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| *x > 0.0 && *y > 0.0 && x.is_finite() && y.is_finite())
    };
    let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
    for &(x, y) in pts() {
        x0 = x0.min(x);
        x1 = x1.max(x);
        y0 = y0.min(y);
        y1 = y1.max(y);
    }
    if x0 > x1 {
        return Err("nothing to plot: no positive finite points".into());
    }
    // Pad the ranges a little (and make a single point a visible range);
    // the top gets room for the legend, one line per series.
    let top = 1.5
        * (1.0 + 0.12 * series.len() as f64)
        * (y1 / y0).max(10.0).powf(0.04 * series.len() as f64);
    let (x0, x1, y0, y1) = (x0 / 1.2, x1 * 1.2, y0 / 1.5, y1 * top);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (960, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .x_label_formatter(&|v| format!("{v:.0}"))
            .y_label_formatter(&|v| format!("{v:.1e}"))
            .draw()
            .map_err(|e| e.to_string())?;
        draw_lines(
            &mut chart,
            series,
            |x, y| x > 0.0 && y > 0.0,
            SeriesLabelPosition::UpperLeft,
        )?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// Each series as a coloured line with markers (points passing `keep`), and
/// the legend at `legend`.
fn draw_lines<
    'a,
    DB: DrawingBackend + 'a,
    X: Ranged<ValueType = f64>,
    Y: Ranged<ValueType = f64>,
>(
    chart: &mut ChartContext<'a, DB, Cartesian2d<X, Y>>,
    series: &[Series],
    keep: impl Fn(f64, f64) -> bool,
    legend: SeriesLabelPosition,
) -> Result<(), String> {
    for (i, s) in series.iter().enumerate() {
        let colour = Palette99::pick(i).to_rgba();
        let data: Vec<(f64, f64)> = s
            .points
            .iter()
            .copied()
            .filter(|&(x, y)| keep(x, y))
            .collect();
        chart
            .draw_series(LineSeries::new(data.clone(), colour.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label(s.name.clone())
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 18, y)], colour.stroke_width(2))
            });
        chart
            .draw_series(data.into_iter().map(|p| Circle::new(p, 3, colour.filled())))
            .map_err(|e| e.to_string())?;
        let bars = s
            .intervals
            .iter()
            .filter(|&&(x, lo, hi)| keep(x, lo) && keep(x, hi));
        chart
            .draw_series(bars.map(|&(x, lo, hi)| {
                PathElement::new(vec![(x, lo), (x, hi)], colour.mix(0.6).stroke_width(2))
            }))
            .map_err(|e| e.to_string())?;
    }
    chart
        .configure_series_labels()
        .position(legend)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(|e| e.to_string())
}

/// A linear-axes line chart (from 0 on both axes), one coloured line with
/// markers per series and a legend: boundaries K(B) of several maps, or a
/// quantity against a swept parameter. Returns the SVG text.
pub fn lines_svg(
    title: &str,
    x_label: &str,
    y_label: &str,
    series: &[Series],
) -> Result<String, String> {
    let finite = || {
        series
            .iter()
            .flat_map(|s| s.points.iter())
            .filter(|(x, y)| x.is_finite() && y.is_finite())
    };
    if finite().next().is_none() {
        return Err("nothing to plot: no finite points".into());
    }
    let x1 = finite().map(|p| p.0).fold(f64::MIN, f64::max).max(1e-12) * 1.05;
    let x0 = finite().map(|p| p.0).fold(0.0, f64::min);
    let highs = series
        .iter()
        .flat_map(|s| s.intervals.iter().map(|i| i.2))
        .filter(|h| h.is_finite());
    let y1 = finite()
        .map(|p| p.1)
        .chain(highs)
        .fold(f64::MIN, f64::max)
        .max(1e-12)
        * (1.1 + 0.08 * series.len() as f64);
    let y0 = finite().map(|p| p.1).fold(0.0, f64::min);
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (960, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let mut chart = ChartBuilder::on(&root)
            .caption(title, ("sans-serif", 20))
            .margin(16)
            .x_label_area_size(48)
            .y_label_area_size(80)
            .build_cartesian_2d(x0..x1, y0..y1)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(x_label)
            .y_desc(y_label)
            .y_label_formatter(&|v| format!("{v:.2e}"))
            .draw()
            .map_err(|e| e.to_string())?;
        draw_lines(
            &mut chart,
            series,
            |x, y| x.is_finite() && y.is_finite(),
            SeriesLabelPosition::UpperRight,
        )?;
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

/// One evaluated point of a Z-width map, for plotting.
pub struct MapPlotPoint {
    pub b: f64,
    pub k: f64,
    pub ok: bool,
    pub fidelity: Option<f64>,
    /// False for a noisy verdict left undecided (drawn as an open ring).
    pub decided: bool,
}

impl MapPlotPoint {
    /// From a stored or computed point's JSON (`search::Point`).
    pub fn from_json(p: &serde_json::Value) -> Self {
        Self {
            k: p["k"].as_f64().unwrap_or(0.0),
            b: p["b"].as_f64().unwrap_or(0.0),
            ok: p["stable"]
                .as_bool()
                .or(p["passive"].as_bool())
                .unwrap_or(false),
            fidelity: p["fidelity"].as_f64(),
            decided: p["decided"].as_bool().unwrap_or(true),
        }
    }
}

/// Viridis-like colour for t in [0, 1] (piecewise-linear through five stops).
fn colour(t: f64) -> RGBColor {
    const STOPS: [(f64, f64, f64); 5] = [
        (68.0, 1.0, 84.0),
        (59.0, 82.0, 139.0),
        (33.0, 145.0, 140.0),
        (94.0, 201.0, 98.0),
        (253.0, 231.0, 37.0),
    ];
    let t = if t.is_finite() {
        t.clamp(0.0, 1.0)
    } else {
        0.0
    } * 4.0;
    let i = (t.floor() as usize).min(3);
    let f = t - i as f64;
    let (a, b) = (STOPS[i], STOPS[i + 1]);
    let mix = |x: f64, y: f64| (x + (y - x) * f).round() as u8;
    RGBColor(mix(a.0, b.0), mix(a.1, b.1), mix(a.2, b.2))
}

/// The 2018 paper's Fig. 7 style: K against B, the points that render
/// coloured by fidelity error (with a colour bar), the others as grey
/// crosses, undecided noisy verdicts as open orange rings, the boundary as
/// a line and, where the map has them, its confidence intervals as
/// vertical bars. Returns the SVG text.
pub fn zwidth_map_svg(
    title: &str,
    points: &[MapPlotPoint],
    boundary: &[BoundaryPoint],
    ok_label: &str,
) -> Result<String, String> {
    let bmax = points
        .iter()
        .map(|p| p.b)
        .chain(boundary.iter().map(|b| b.b))
        .fold(1.0, f64::max)
        * 1.05;
    let kmax = points
        .iter()
        .map(|p| p.k)
        .chain(boundary.iter().map(|b| b.k_hi.unwrap_or(b.k_max)))
        .fold(1.0, f64::max)
        * 1.08;
    let fids: Vec<f64> = points
        .iter()
        .filter(|p| p.ok)
        .filter_map(|p| p.fidelity)
        .filter(|f| f.is_finite())
        .collect();
    let (fmin, fmax) = fids
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), &f| (a.min(f), b.max(f)));
    let has_fid = !fids.is_empty();
    let span = if has_fid {
        (fmax - fmin).max(1e-12)
    } else {
        1.0
    };
    let mut svg = String::new();
    {
        let root = SVGBackend::with_string(&mut svg, (900, 640)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (left, right) = root.split_horizontally(780);
        let mut chart = ChartBuilder::on(&left)
            .caption(title, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(80)
            .build_cartesian_2d(0.0..bmax, 0.0..kmax)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("wall damping B (N·s/m)")
            .y_desc("wall stiffness K (N/m)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(|e| e.to_string())?;
        chart
            .draw_series(
                points
                    .iter()
                    .filter(|p| !p.ok)
                    .map(|p| Cross::new((p.b, p.k), 3, RGBColor(170, 170, 170).stroke_width(1))),
            )
            .map_err(|e| e.to_string())?
            .label(format!("not {ok_label}"))
            .legend(|(x, y)| Cross::new((x + 8, y), 3, RGBColor(170, 170, 170)));
        if points.iter().any(|p| !p.decided) {
            chart
                .draw_series(
                    points.iter().filter(|p| !p.decided).map(|p| {
                        Circle::new((p.b, p.k), 6, RGBColor(230, 120, 20).stroke_width(1))
                    }),
                )
                .map_err(|e| e.to_string())?
                .label("undecided (sign of the estimate inside)")
                .legend(|(x, y)| {
                    Circle::new((x + 8, y), 6, RGBColor(230, 120, 20).stroke_width(1))
                });
        }
        chart
            .draw_series(points.iter().filter(|p| p.ok).map(|p| {
                let c = match p.fidelity {
                    Some(f) if has_fid => colour((f - fmin) / span),
                    _ => RGBColor(40, 120, 200),
                };
                Circle::new((p.b, p.k), 4, c.filled())
            }))
            .map_err(|e| e.to_string())?
            .label(ok_label.to_string())
            .legend(|(x, y)| Circle::new((x + 8, y), 4, colour(0.5).filled()));
        let bars: Vec<(f64, f64, f64)> = boundary
            .iter()
            .filter_map(|p| Some((p.b, p.k_lo?, p.k_hi?)))
            .collect();
        if !bars.is_empty() {
            chart
                .draw_series(bars.iter().map(|&(b, lo, hi)| {
                    PathElement::new(
                        vec![(b, lo), (b, hi)],
                        RGBColor(200, 30, 30).stroke_width(2),
                    )
                }))
                .map_err(|e| e.to_string())?
                .label("boundary interval (k_lo to k_hi)")
                .legend(|(x, y)| {
                    PathElement::new(
                        vec![(x + 8, y - 6), (x + 8, y + 6)],
                        RGBColor(200, 30, 30).stroke_width(2),
                    )
                });
        }
        let mut line: Vec<(f64, f64)> = boundary.iter().map(|p| (p.b, p.k_max)).collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))
            .map_err(|e| e.to_string())?
            .label("boundary (largest K)")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 18, y)], BLACK.stroke_width(2)));
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(|e| e.to_string())?;
        // Colour bar: fidelity error (N·s/m).
        if has_fid {
            let (top, bottom, x0, x1) = (60i32, 560i32, 20i32, 44i32);
            let n = 100;
            for i in 0..n {
                let y0 = bottom - (bottom - top) * i / n;
                let y1 = bottom - (bottom - top) * (i + 1) / n;
                right
                    .draw(&Rectangle::new(
                        [(x0, y1), (x1, y0)],
                        colour(i as f64 / (n - 1) as f64).filled(),
                    ))
                    .map_err(|e| e.to_string())?;
            }
            right
                .draw(&Rectangle::new(
                    [(x0, top), (x1, bottom)],
                    BLACK.stroke_width(1),
                ))
                .map_err(|e| e.to_string())?;
            for i in 0..=4 {
                let y = bottom - (bottom - top) * i / 4;
                let v = fmin + span * i as f64 / 4.0;
                right
                    .draw(&Text::new(
                        format!("{v:.1}"),
                        (x1 + 6, y - 6),
                        ("sans-serif", 13),
                    ))
                    .map_err(|e| e.to_string())?;
            }
            right
                .draw(&Text::new(
                    "fidelity error",
                    (4, top - 40),
                    ("sans-serif", 13),
                ))
                .map_err(|e| e.to_string())?;
            right
                .draw(&Text::new("(N·s/m)", (4, top - 24), ("sans-serif", 13)))
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    Ok(svg)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_an_svg_with_legend_and_labels() {
        let s = vec![
            Series::new("fdm", vec![(1e3, 1e-3), (1e4, 1e-2)]),
            Series::new("levant", vec![(1e3, 2e-3), (1e4, 5e-4)]),
        ];
        let svg = loglog_svg("t", "sample rate (Hz)", "RMS error (m/s)", &s).unwrap();
        assert!(svg.starts_with("<svg"));
        for text in ["fdm", "levant", "sample rate (Hz)", "RMS error (m/s)"] {
            assert!(svg.contains(text), "missing {text}");
        }
        assert!(loglog_svg("t", "x", "y", &[]).is_err());
    }

    #[test]
    fn a_boundary_draws_one_bar_per_interval_and_the_axis_reaches_its_top() {
        // Three boundary points, two with an interval: two bars (the
        // series' colour at 0.6 opacity; the boundary without intervals has
        // none), and the y axis (ticks labelled `{:.2e}`) reaches the 9e4
        // top of the highest interval.
        let mut b: Vec<BoundaryPoint> = [(0.0, 3e4), (10.0, 5e4), (20.0, 4e4)]
            .iter()
            .map(|&(b, k)| BoundaryPoint::new(b, k))
            .collect();
        let bare = lines_svg("t", "B", "K", &[Series::boundary("m", &b)]).unwrap();
        (b[1].k_lo, b[1].k_hi) = (Some(4e4), Some(9e4));
        (b[2].k_lo, b[2].k_hi) = (Some(3.5e4), Some(4.5e4));
        b[0].k_lo = Some(2e4); // no k_hi: no bar
        let with = lines_svg("t", "B", "K", &[Series::boundary("m", &b)]).unwrap();
        let bars = |s: &str| s.matches("<polyline fill=\"none\" opacity=\"0.6\"").count();
        assert_eq!((bars(&bare), bars(&with)), (0, 2));
        assert!(
            with.contains("9.00e4"),
            "the axis reaches the interval's top"
        );
        assert!(!bare.contains("9.00e4"));
    }
}
