//! The K–B map (the 2011 paper's Fig. 7 kind): every trial as a mark
//! coloured by its fidelity, the boundary with its intervals, a colour bar
//! and a legend.

use plotters::prelude::*;

use super::style::*;
use crate::zwidth::search::BoundaryPoint;

/// A fidelity colour scale (N·s/m): `lo` maps to the scale's first
/// colour, `hi` to its last; logarithmic when the errors span a factor of
/// [`LOG_SPAN`] or more (the seed device's estimators range from tens to
/// tens of thousands of N·s/m: on a linear scale all but one would look
/// alike). Several maps drawn with one scale can be compared by colour.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FidelityScale {
    pub lo: f64,
    pub hi: f64,
    pub log: bool,
}

/// The ratio hi/lo from which a fidelity scale is logarithmic.
pub const LOG_SPAN: f64 = 20.0;

impl FidelityScale {
    /// A scale from `lo` to `hi`, logarithmic if they span [`LOG_SPAN`].
    pub fn new(lo: f64, hi: f64) -> Self {
        Self {
            lo,
            hi,
            log: lo > 0.0 && hi / lo >= LOG_SPAN,
        }
    }

    /// The range of the finite fidelity errors of the points that render;
    /// none when no such point has one.
    pub fn of<'a>(points: impl IntoIterator<Item = &'a MapPlotPoint>) -> Option<Self> {
        points
            .into_iter()
            .filter(|p| p.ok)
            .filter_map(|p| p.fidelity)
            .filter(|f| f.is_finite())
            .fold(None, |acc: Option<Self>, f| {
                Some(match acc {
                    None => Self::new(f, f),
                    Some(s) => Self::new(s.lo.min(f), s.hi.max(f)),
                })
            })
    }

    /// The smallest scale holding both.
    pub fn union(a: Option<Self>, b: Option<Self>) -> Option<Self> {
        match (a, b) {
            (Some(a), Some(b)) => Some(Self::new(a.lo.min(b.lo), a.hi.max(b.hi))),
            (a, None) => a,
            (None, b) => b,
        }
    }

    /// Where `f` falls on the scale, 0 to 1.
    pub fn at(&self, f: f64) -> f64 {
        if self.log {
            (f.max(self.lo).ln() - self.lo.ln()) / (self.hi.ln() - self.lo.ln()).max(1e-12)
        } else {
            (f - self.lo) / (self.hi - self.lo).max(1e-12)
        }
    }

    /// The error at `t` (0 to 1) along the scale: the inverse of [`Self::at`].
    pub fn value_at(&self, t: f64) -> f64 {
        if self.log {
            self.lo * (self.hi / self.lo).powf(t)
        } else {
            self.lo + (self.hi - self.lo) * t
        }
    }
}

/// One evaluated point of a Z-width map, for plotting.
#[derive(Debug, Clone, Copy)]
pub struct MapPlotPoint {
    pub b: f64,
    pub k: f64,
    pub ok: bool,
    pub fidelity: Option<f64>,
    /// False for a noisy verdict left undecided (drawn as an open ring).
    pub decided: bool,
}

impl MapPlotPoint {
    /// From a map's point.
    pub fn of(p: &crate::zwidth::search::Point) -> Self {
        Self {
            b: p.b,
            k: p.k,
            ok: p.ok(),
            fidelity: p.fidelity,
            decided: p.decided != Some(false),
        }
    }

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

/// How a map is drawn. `Default` is one map on its own: its own axes and
/// colour scale, 900 × 640 px, a tooltip on every point.
#[derive(Debug, Clone)]
pub struct MapStyle {
    /// What a point that renders is called: "passive" or "stable".
    pub ok_label: String,
    /// A colour scale shared with other maps; none: this map's own.
    pub scale: Option<FidelityScale>,
    /// Axes shared with other maps: the largest B (N·s/m) and K (N/m)
    /// shown; none: this map's own.
    pub extent: Option<(f64, f64)>,
    /// Width and height, px.
    pub size: (u32, u32),
    /// Most points drawn one element each with a `<title>` tooltip; a map
    /// with more is drawn compactly (one path per colour, a tooltip per
    /// colour band), so a page with 20 000 trials stays small.
    pub tooltip_limit: usize,
    /// A predicted boundary (a map's `prior`) drawn over the map's own, as
    /// a blue line; empty: none.
    pub prediction: Vec<BoundaryPoint>,
}

impl Default for MapStyle {
    fn default() -> Self {
        Self {
            ok_label: "passive".into(),
            scale: None,
            extent: None,
            size: (900, 640),
            tooltip_limit: 4000,
            prediction: Vec::new(),
        }
    }
}

/// The axes a map needs: its largest B and K (boundary intervals
/// included), with a margin.
pub fn map_extent(points: &[MapPlotPoint], boundary: &[BoundaryPoint]) -> (f64, f64) {
    let bmax = points
        .iter()
        .map(|p| p.b)
        .chain(boundary.iter().map(|b| b.b))
        .filter(|v| v.is_finite())
        .fold(1.0, f64::max)
        * 1.05;
    let kmax = points
        .iter()
        .map(|p| p.k)
        .chain(boundary.iter().map(|b| b.k_hi.unwrap_or(b.k_max)))
        .filter(|v| v.is_finite())
        .fold(1.0, f64::max)
        * 1.08;
    (bmax, kmax)
}

/// The predicted boundary's colour (a map's prior).
const PREDICTION: RGBColor = RGBColor(30, 90, 200);

/// Colour bands of the compact drawing: points whose colour falls in one
/// band share one path.
pub(super) const BANDS: usize = 32;

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
    let style = MapStyle {
        ok_label: ok_label.into(),
        ..MapStyle::default()
    };
    zwidth_map_svg_styled(title, points, boundary, &style)
}

/// [`zwidth_map_svg`] with a shared scale, shared axes, another size. The
/// points are drawn after plotters' axes, each with the class `pt` (`ok`,
/// `no` or `undecided`) and a `<title>` giving B, K, the verdict and the
/// fidelity error, up to `style.tooltip_limit` points.
pub fn zwidth_map_svg_styled(
    title: &str,
    points: &[MapPlotPoint],
    boundary: &[BoundaryPoint],
    style: &MapStyle,
) -> Result<String, String> {
    let (bmax, kmax) = style.extent.unwrap_or_else(|| {
        let drawn: Vec<BoundaryPoint> = boundary.iter().chain(&style.prediction).copied().collect();
        map_extent(points, &drawn)
    });
    let scale = style.scale.or_else(|| FidelityScale::of(points));
    let ok_label = style.ok_label.as_str();
    let (w, h) = style.size;
    let bar_w = 120u32.min(w / 6);
    let mut svg = String::new();
    // Pixel positions of the points, from the chart's own mapping.
    let mut at: Vec<(i32, i32)> = Vec::with_capacity(points.len());
    // The plotting area's top-right corner (px): the legend's place.
    let area: (i32, i32);
    {
        let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        let (left, right) = root.split_horizontally(w - bar_w);
        let small = w < 600;
        let mut chart = ChartBuilder::on(&left)
            .caption(title, ("sans-serif", if small { 14 } else { 18 }))
            .margin(if small { 8 } else { 14 })
            .x_label_area_size(if small { 36 } else { 44 })
            .y_label_area_size(if small { 64 } else { 80 })
            .build_cartesian_2d(0.0..bmax, 0.0..kmax)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc("wall damping B (N·s/m)")
            .y_desc("wall stiffness K (N/m)")
            .y_label_formatter(&|v| format!("{v:.0}"))
            .draw()
            .map_err(|e| e.to_string())?;
        at.extend(points.iter().map(|p| chart.backend_coord(&(p.b, p.k))));
        let (xr, yr) = chart.plotting_area().get_pixel_range();
        area = (xr.end, yr.start);
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
                .map_err(|e| e.to_string())?;
        }
        let mut line: Vec<(f64, f64)> = boundary.iter().map(|p| (p.b, p.k_max)).collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        chart
            .draw_series(LineSeries::new(line, BLACK.stroke_width(2)))
            .map_err(|e| e.to_string())?;
        if !style.prediction.is_empty() {
            let mut predicted: Vec<(f64, f64)> =
                style.prediction.iter().map(|p| (p.b, p.k_max)).collect();
            predicted.sort_by(|a, b| a.0.total_cmp(&b.0));
            chart
                .draw_series(LineSeries::new(predicted, PREDICTION.stroke_width(2)))
                .map_err(|e| e.to_string())?;
        }
        // Colour bar: fidelity error (N·s/m).
        if let Some(sc) = scale {
            let (top, bottom) = (60i32, h as i32 - 80);
            let (x0, x1) = (16i32, 36i32);
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
                let v = sc.value_at(i as f64 / 4.0);
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
                .draw(&Text::new(
                    if sc.log { "(N·s/m, log)" } else { "(N·s/m)" },
                    (4, top - 24),
                    ("sans-serif", 13),
                ))
                .map_err(|e| e.to_string())?;
        }
        root.present().map_err(|e| e.to_string())?;
    }
    let mut marks = point_marks(points, &at, scale, ok_label, style.tooltip_limit);
    if w >= 800 {
        let intervals = boundary
            .iter()
            .any(|p| p.k_lo.is_some() && p.k_hi.is_some());
        marks.push_str(&legend(
            area,
            ok_label,
            points.iter().any(|p| !p.decided),
            intervals,
            !style.prediction.is_empty(),
        ));
    }
    match svg.rfind("</svg>") {
        Some(i) => svg.insert_str(i, &marks),
        None => return Err("plotters wrote no closing </svg>".into()),
    }
    Ok(svg)
}

/// The legend, drawn over the points at the plotting area's top right.
pub(super) fn legend(
    corner: (i32, i32),
    ok_label: &str,
    undecided: bool,
    intervals: bool,
    predicted: bool,
) -> String {
    let ok = xml_escape(ok_label);
    let mut rows: Vec<(String, String)> = vec![
        (
            format!(
                "<circle cx=\"9\" cy=\"0\" r=\"4\" fill=\"{}\"/>",
                hex(colour(0.5))
            ),
            ok.clone(),
        ),
        (
            "<path d=\"M6 -3l6 6m0 -6l-6 6\" stroke=\"#969696\" fill=\"none\"/>".into(),
            format!("not {ok}"),
        ),
    ];
    if undecided {
        rows.push((
            "<circle cx=\"9\" cy=\"0\" r=\"6\" fill=\"none\" stroke=\"#e67814\"/>".into(),
            "undecided (sign of the estimate inside)".into(),
        ));
    }
    rows.push((
        "<path d=\"M0 0h18\" stroke=\"#000\" stroke-width=\"2\"/>".into(),
        "boundary (largest K)".into(),
    ));
    if intervals {
        rows.push((
            "<path d=\"M9 -6v12\" stroke=\"#c81e1e\" stroke-width=\"2\"/>".into(),
            "boundary interval (k_lo to k_hi)".into(),
        ));
    }
    if predicted {
        rows.push((
            format!(
                "<path d=\"M0 0h18\" stroke=\"{}\" stroke-width=\"2\"/>",
                hex(PREDICTION)
            ),
            "prediction (the map's prior)".into(),
        ));
    }
    legend_box(corner, &rows)
}

/// The points as SVG: one element with a tooltip each (up to `limit`
/// points), else one path per kind and colour band.
pub(super) fn point_marks(
    points: &[MapPlotPoint],
    at: &[(i32, i32)],
    scale: Option<FidelityScale>,
    ok_label: &str,
    limit: usize,
) -> String {
    use std::fmt::Write;
    let grey = "#969696";
    let orange = "#e67814";
    let fill = |p: &MapPlotPoint| match (p.fidelity, scale) {
        (Some(f), Some(sc)) if f.is_finite() => colour(sc.at(f)),
        _ => RGBColor(40, 120, 200),
    };
    let mut s = String::from("<g class=\"points\">");
    if points.len() <= limit {
        for (p, &(x, y)) in points.iter().zip(at) {
            let verdict = if !p.decided {
                "undecided".to_string()
            } else if p.ok {
                ok_label.to_string()
            } else {
                format!("not {ok_label}")
            };
            let fid = p
                .fidelity
                .filter(|f| f.is_finite())
                .map_or(String::new(), |f| format!(", fidelity error {f:.3} N·s/m"));
            let tip = format!(
                "<title>B = {:.3} N·s/m, K = {:.1} N/m: {}{}</title>",
                p.b,
                p.k,
                xml_escape(&verdict),
                fid
            );
            let _ = if !p.decided {
                write!(
                    s,
                    "<circle class=\"pt undecided\" cx=\"{x}\" cy=\"{y}\" r=\"6\" fill=\"none\" stroke=\"{orange}\">{tip}</circle>"
                )
            } else if p.ok {
                write!(
                    s,
                    "<circle class=\"pt ok\" cx=\"{x}\" cy=\"{y}\" r=\"4\" fill=\"{}\">{tip}</circle>",
                    hex(fill(p))
                )
            } else {
                write!(
                    s,
                    "<path class=\"pt no\" d=\"M{} {}l6 6m0 -6l-6 6\" stroke=\"{grey}\" fill=\"none\">{tip}</path>",
                    x - 3,
                    y - 3
                )
            };
        }
    } else {
        // Compact: crosses in one path, rings in one, dots in one path per
        // colour band (a round cap on a zero-length segment is a dot).
        let mut crosses = String::new();
        let mut rings = String::new();
        let mut bands: Vec<String> = vec![String::new(); BANDS + 1];
        let mut counts = [0usize; 3];
        for (p, &(x, y)) in points.iter().zip(at) {
            if !p.decided {
                counts[2] += 1;
                let _ = write!(rings, "M{} {}a6 6 0 1 0 12 0a6 6 0 1 0 -12 0", x - 6, y);
            } else if p.ok {
                counts[0] += 1;
                let band = match (p.fidelity, scale) {
                    (Some(f), Some(sc)) if f.is_finite() => {
                        (sc.at(f).clamp(0.0, 1.0) * (BANDS - 1) as f64).round() as usize
                    }
                    _ => BANDS,
                };
                let _ = write!(bands[band], "M{x} {y}h0");
            } else {
                counts[1] += 1;
                let _ = write!(crosses, "M{} {}l6 6m0 -6l-6 6", x - 3, y - 3);
            }
        }
        if !crosses.is_empty() {
            let _ = write!(
                s,
                "<path class=\"pts no\" data-n=\"{}\" d=\"{crosses}\" stroke=\"{grey}\" fill=\"none\"><title>{} points not {}</title></path>",
                counts[1],
                counts[1],
                xml_escape(ok_label)
            );
        }
        for (i, d) in bands.iter().enumerate().filter(|(_, d)| !d.is_empty()) {
            let n = d.matches('M').count();
            let (c, tip) = match scale {
                Some(sc) if i < BANDS => {
                    let t = i as f64 / (BANDS - 1) as f64;
                    let half = 0.5 / (BANDS - 1) as f64;
                    (
                        colour(t),
                        format!(
                            "{n} points {}, fidelity error {:.3} to {:.3} N·s/m",
                            xml_escape(ok_label),
                            sc.value_at((t - half).max(0.0)),
                            sc.value_at((t + half).min(1.0))
                        ),
                    )
                }
                _ => (
                    RGBColor(40, 120, 200),
                    format!("{n} points {}", xml_escape(ok_label)),
                ),
            };
            let _ = write!(
                s,
                "<path class=\"pts ok\" data-n=\"{n}\" d=\"{d}\" stroke=\"{}\" stroke-width=\"8\" stroke-linecap=\"round\" fill=\"none\"><title>{tip}</title></path>",
                hex(c)
            );
        }
        if !rings.is_empty() {
            let _ = write!(
                s,
                "<path class=\"pts undecided\" data-n=\"{}\" d=\"{rings}\" stroke=\"{orange}\" fill=\"none\"><title>{} points undecided</title></path>",
                counts[2], counts[2]
            );
        }
    }
    s.push_str("</g>\n");
    s
}
