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
}

impl Default for MapStyle {
    fn default() -> Self {
        Self {
            ok_label: "passive".into(),
            scale: None,
            extent: None,
            size: (900, 640),
            tooltip_limit: 4000,
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

/// Text safe inside SVG/XML character data and attributes.
pub fn xml_escape(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

fn hex(c: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

/// Colour bands of the compact drawing: points whose colour falls in one
/// band share one path.
const BANDS: usize = 32;

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
    let (bmax, kmax) = style.extent.unwrap_or_else(|| map_extent(points, boundary));
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
        ));
    }
    match svg.rfind("</svg>") {
        Some(i) => svg.insert_str(i, &marks),
        None => return Err("plotters wrote no closing </svg>".into()),
    }
    Ok(svg)
}

/// The legend, drawn over the points at the plotting area's top right.
fn legend(corner: (i32, i32), ok_label: &str, undecided: bool, intervals: bool) -> String {
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
    legend_box(corner, &rows)
}

/// A legend box at the top-right `corner` (px): each row a mark (SVG drawn
/// around (0, 0) to (18, 0)) and its text (escaped by the caller).
fn legend_box(corner: (i32, i32), rows: &[(String, String)]) -> String {
    use std::fmt::Write;
    let longest = rows.iter().map(|r| r.1.chars().count()).max().unwrap_or(0) as i32;
    let (wd, ht) = (40 + 7 * longest, 10 + 20 * rows.len() as i32);
    let (x, y) = (corner.0 - wd - 8, corner.1 + 8);
    let mut s = format!(
        "<g class=\"legend\" transform=\"translate({x},{y})\"><rect width=\"{wd}\" height=\"{ht}\" fill=\"#fff\" fill-opacity=\"0.9\" stroke=\"#000\"/>"
    );
    for (i, (mark, text)) in rows.iter().enumerate() {
        let yy = 15 + 20 * i as i32;
        let _ = write!(
            s,
            "<g transform=\"translate(8,{yy})\">{mark}<text x=\"28\" y=\"4\" font-family=\"sans-serif\" font-size=\"13\">{text}</text></g>"
        );
    }
    s.push_str("</g>\n");
    s
}

/// Height of the legend row under a scatter plot (px).
const LEGEND_ROW: i32 = 30;

/// A tick label with as many decimals as the axis span needs.
fn tick(v: f64, span: f64) -> String {
    let digits = if span >= 50.0 {
        0
    } else if span >= 0.5 {
        2
    } else {
        4
    };
    if v.abs() >= 1e7 {
        format!("{v:.2e}")
    } else {
        format!("{v:.digits$}")
    }
}

/// A legend in one row from `at` (px, its top left): mark, text, mark, …
fn legend_row(at: (i32, i32), rows: &[(String, String)]) -> String {
    use std::fmt::Write;
    let mut s = format!(
        "<g class=\"legend\" transform=\"translate({},{})\">",
        at.0,
        at.1 + 12
    );
    let mut x = 0;
    for (mark, text) in rows {
        let _ = write!(
            s,
            "<g transform=\"translate({x},0)\">{mark}<text x=\"24\" y=\"4\" font-family=\"sans-serif\" font-size=\"13\">{text}</text></g>"
        );
        x += 40 + 8 * text.chars().count() as i32;
    }
    s.push_str("</g>\n");
    s
}

/// How a group of scatter points is marked.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mark {
    /// A filled dot of this colour (r, g, b).
    Dot(u8, u8, u8),
    /// An open ring of this colour, larger: drawn around other marks.
    Ring(u8, u8, u8),
    /// A filled diamond of this colour.
    Diamond(u8, u8, u8),
}

/// One group of a scatter plot: its points and a tooltip for each.
#[derive(Debug, Clone)]
pub struct Scatter {
    pub name: String,
    pub mark: Mark,
    pub points: Vec<(f64, f64)>,
    /// One per point (plain text, escaped here); missing ones are B = …
    pub tips: Vec<String>,
}

fn mark_svg(m: Mark, x: i32, y: i32, class: &str, tip: &str) -> String {
    match m {
        Mark::Dot(r, g, b) => format!(
            "<circle class=\"{class}\" cx=\"{x}\" cy=\"{y}\" r=\"4\" fill=\"{}\">{tip}</circle>",
            hex(RGBColor(r, g, b))
        ),
        Mark::Ring(r, g, b) => format!(
            "<circle class=\"{class}\" cx=\"{x}\" cy=\"{y}\" r=\"8\" fill=\"none\" stroke-width=\"2\" stroke=\"{}\">{tip}</circle>",
            hex(RGBColor(r, g, b))
        ),
        Mark::Diamond(r, g, b) => format!(
            "<path class=\"{class}\" d=\"M{x} {}l6 6l-6 6l-6 -6z\" fill=\"{}\">{tip}</path>",
            y - 6,
            hex(RGBColor(r, g, b))
        ),
    }
}

/// A scatter plot on linear axes (from the data's range, with a margin),
/// every point with a `<title>` tooltip and the class `pt`; groups drawn
/// in order (later on top), a legend at the top right.
pub fn scatter_svg(
    title: &str,
    x_desc: &str,
    y_desc: &str,
    groups: &[Scatter],
    size: (u32, u32),
) -> Result<String, String> {
    let all = || {
        groups
            .iter()
            .flat_map(|g| g.points.iter())
            .filter(|p| p.0.is_finite() && p.1.is_finite())
    };
    if all().next().is_none() {
        return Err("no points to plot".into());
    }
    let range = |f: &dyn Fn(&(f64, f64)) -> f64| {
        let (lo, hi) = all().fold((f64::MAX, f64::MIN), |(a, b), p| (a.min(f(p)), b.max(f(p))));
        let pad = ((hi - lo) * 0.08).max(hi.abs().max(1e-9) * 0.02);
        (lo - pad)..(hi + pad)
    };
    let (xr, yr) = (range(&|p| p.0), range(&|p| p.1));
    let mut svg = String::new();
    let mut at: Vec<Vec<(i32, i32)>> = Vec::new();
    let corner: (i32, i32);
    {
        let root = SVGBackend::with_string(&mut svg, size).into_drawing_area();
        root.fill(&WHITE).map_err(|e| e.to_string())?;
        // The legend goes in a row below the chart, never over the data.
        let (top, _) = root.split_vertically(size.1 as i32 - LEGEND_ROW);
        let (yspan, xspan) = (yr.end - yr.start, xr.end - xr.start);
        let mut chart = ChartBuilder::on(&top)
            .caption(title, ("sans-serif", 18))
            .margin(14)
            .x_label_area_size(44)
            .y_label_area_size(84)
            .build_cartesian_2d(xr, yr)
            .map_err(|e| e.to_string())?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .x_label_formatter(&|v| tick(*v, xspan))
            .y_label_formatter(&|v| tick(*v, yspan))
            .draw()
            .map_err(|e| e.to_string())?;
        for g in groups {
            at.push(g.points.iter().map(|p| chart.backend_coord(p)).collect());
        }
        let (x, _) = chart.plotting_area().get_pixel_range();
        corner = (x.start, size.1 as i32 - LEGEND_ROW);
        root.present().map_err(|e| e.to_string())?;
    }
    let mut marks = String::from("<g class=\"points\">");
    let mut rows = Vec::new();
    for (g, px) in groups.iter().zip(&at) {
        for (i, &(x, y)) in px.iter().enumerate() {
            let (vx, vy) = g.points[i];
            if !(vx.is_finite() && vy.is_finite()) {
                continue;
            }
            let tip = g
                .tips
                .get(i)
                .cloned()
                .unwrap_or_else(|| format!("{x_desc} = {vx:.4}, {y_desc} = {vy:.4}"));
            marks.push_str(&mark_svg(
                g.mark,
                x,
                y,
                "pt",
                &format!("<title>{}</title>", xml_escape(&tip)),
            ));
        }
        if !g.points.is_empty() {
            rows.push((mark_svg(g.mark, 9, 0, "key", ""), xml_escape(&g.name)));
        }
    }
    marks.push_str("</g>\n");
    marks.push_str(&legend_row(corner, &rows));
    match svg.rfind("</svg>") {
        Some(i) => svg.insert_str(i, &marks),
        None => return Err("plotters wrote no closing </svg>".into()),
    }
    Ok(svg)
}

/// The points as SVG: one element with a tooltip each (up to `limit`
/// points), else one path per kind and colour band.
fn point_marks(
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

    /// The colour bar takes a sixth of a narrow map's width (at most
    /// 120 px): its frame starts 16 px into that strip.
    #[test]
    fn the_colour_bar_takes_a_sixth_of_a_narrow_map() {
        let pts = [
            pt(10.0, 100.0, true, Some(1.0), true),
            pt(20.0, 200.0, true, Some(3.0), true),
        ];
        for (w, bar) in [(620u32, 103i32), (900, 120)] {
            let style = MapStyle {
                size: (w, 440),
                ..MapStyle::default()
            };
            let svg = zwidth_map_svg_styled("m", &pts, &[], &style).unwrap();
            let x = w as i32 - bar + 16;
            // From 60 px below the top to 80 px above the bottom.
            let frame = format!(
                "<rect x=\"{x}\" y=\"60\" width=\"20\" height=\"{}\"",
                440 - 80 - 60
            );
            assert!(svg.contains(&frame), "w = {w}: {frame}");
            // Five labels up the bar, a quarter of its height apart, from
            // the scale's lowest (1.0) to its highest (3.0) error.
            for (i, v) in ["1.0", "1.5", "2.0", "2.5", "3.0"].iter().enumerate() {
                let y = 360 - 300 * i as i32 / 4 - 6;
                let at = format!("<text x=\"{}\" y=\"{y}\"", x + 26);
                let start = svg.find(&at).unwrap_or_else(|| panic!("w = {w}: {at}"));
                let text = &svg[start..start + svg[start..].find("</text>").unwrap()];
                assert!(text.contains(v), "w = {w}: {text}");
            }
        }
        // Below 600 px the caption is set smaller: 14 px against 18 px
        // (plotters writes both scaled by one factor, so their ratio holds).
        let caption = |w: u32| {
            let style = MapStyle {
                size: (w, 440),
                ..MapStyle::default()
            };
            let svg = zwidth_map_svg_styled("Caption-T", &pts, &[], &style).unwrap();
            let at = svg.find("Caption-T").unwrap();
            let tag = &svg[svg[..at].rfind("<text").unwrap()..at];
            let v = tag.split("font-size=\"").nth(1).unwrap();
            v[..v.find('"').unwrap()].parse::<f64>().unwrap()
        };
        let (small, edge, big) = (caption(580), caption(600), caption(900));
        assert!((small / edge - 14.0 / 18.0).abs() < 1e-9, "{small} {edge}");
        assert_eq!(edge, big);
    }

    /// The criterion's word (the 2011 paper's maps are "stable", the 2018
    /// paper's "passive") names the legend's rows and the tooltips.
    #[test]
    fn a_map_names_its_criterion_in_the_legend_and_tooltips() {
        let pts = [
            pt(10.0, 100.0, true, Some(1.0), true),
            pt(20.0, 900.0, false, None, true),
        ];
        let svg = zwidth_map_svg("m", &pts, &[], "stable").unwrap();
        assert!(svg.contains(">not stable<"), "legend row");
        assert!(svg.contains("stable"));
        assert!(!svg.contains("passive"), "the default word leaked");
        let svg = zwidth_map_svg("m", &pts, &[], "passive").unwrap();
        assert!(svg.contains(">not passive<") && !svg.contains("stable"));
    }

    fn pt(b: f64, k: f64, ok: bool, fidelity: Option<f64>, decided: bool) -> MapPlotPoint {
        MapPlotPoint {
            b,
            k,
            ok,
            fidelity,
            decided,
        }
    }

    #[test]
    fn a_fidelity_scale_spans_the_rendering_points_and_goes_log_past_twenty() {
        // Only points that render count; NaN and non-rendering ones do not.
        let pts = [
            pt(0.0, 1.0, true, Some(2.0), true),
            pt(0.0, 2.0, true, Some(30.0), true),
            pt(0.0, 3.0, false, Some(1e6), true),
            pt(0.0, 4.0, true, Some(f64::NAN), true),
            pt(0.0, 5.0, true, None, true),
        ];
        let s = FidelityScale::of(&pts).unwrap();
        assert_eq!((s.lo, s.hi), (2.0, 30.0));
        // 30/2 = 15 < 20: linear; at(16) = (16 − 2)/(30 − 2) = 0.5.
        assert!(!s.log);
        assert_eq!(s.at(16.0), 0.5);
        assert_eq!(s.value_at(0.5), 16.0);
        assert!(FidelityScale::of(&pts[2..3]).is_none());
        // Exactly 20×: logarithmic; the middle is the geometric mean.
        let l = FidelityScale::new(10.0, 200.0);
        assert!(l.log);
        assert!(!FidelityScale::new(10.0, 199.0).log);
        assert!(!FidelityScale::new(0.0, 1e9).log, "no log scale from 0");
        let mid = (10.0f64 * 200.0).sqrt();
        assert!((l.at(mid) - 0.5).abs() < 1e-12);
        assert!((l.value_at(0.5) - mid).abs() < 1e-9);
        assert_eq!(l.at(10.0), 0.0);
        assert!((l.at(200.0) - 1.0).abs() < 1e-12);
        assert!((l.value_at(1.0) - 200.0).abs() < 1e-9);
        // The union holds both, and is log when together they span 20×.
        let u = FidelityScale::union(Some(FidelityScale::new(5.0, 50.0)), Some(s)).unwrap();
        assert_eq!((u.lo, u.hi, u.log), (2.0, 50.0, true));
        assert_eq!(FidelityScale::union(None, Some(s)), Some(s));
        assert_eq!(FidelityScale::union(Some(s), None), Some(s));
        assert_eq!(FidelityScale::union(None, None), None);
    }

    #[test]
    fn every_point_is_one_mark_with_its_tooltip_or_counted_in_a_compact_path() {
        let pts = vec![
            pt(1.0, 100.0, true, Some(1.0), true),
            pt(2.0, 200.0, true, Some(3.0), true),
            pt(3.0, 300.0, false, None, true),
            pt(4.0, 400.0, false, None, false),
        ];
        let b = [
            BoundaryPoint::new(1.0, 150.0),
            BoundaryPoint::new(2.0, 250.0),
        ];
        let svg = zwidth_map_svg("t <&>", &pts, &b, "passive").unwrap();
        assert!(svg.trim_end().ends_with("</svg>"));
        assert_eq!(svg.matches("class=\"pt ok\"").count(), 2);
        assert_eq!(svg.matches("class=\"pt no\"").count(), 1);
        assert_eq!(svg.matches("class=\"pt undecided\"").count(), 1);
        assert!(svg.contains(
            "<title>B = 2.000 N·s/m, K = 200.0 N/m: passive, fidelity error 3.000 N·s/m</title>"
        ));
        assert!(svg.contains("K = 300.0 N/m: not passive</title>"));
        assert!(svg.contains("K = 400.0 N/m: undecided</title>"));
        // Colours: the scale's ends (viridis' first and last stops).
        assert!(svg.contains("fill=\"#440154\""), "the smallest error");
        assert!(svg.contains("fill=\"#fde725\""), "the largest error");
        // The title is escaped by plotters.
        assert!(!svg.contains("t <&>"));
        // Past the limit: one path per kind and band, counting its points.
        let style = MapStyle {
            tooltip_limit: 3,
            ..MapStyle::default()
        };
        let c = zwidth_map_svg_styled("t", &pts, &b, &style).unwrap();
        assert_eq!(c.matches("class=\"pt ").count(), 0);
        let n: Vec<usize> = c
            .match_indices("data-n=\"")
            .map(|(i, m)| {
                let r = &c[i + m.len()..];
                r[..r.find('"').unwrap()].parse().unwrap()
            })
            .collect();
        assert_eq!(n.iter().sum::<usize>(), pts.len());
        // Two rendering points at the two ends of the scale: two bands.
        assert_eq!(c.matches("class=\"pts ok\"").count(), 2);
        assert!(c.contains("1 points passive, fidelity error 1.000 to"));
        assert_eq!(c.matches("class=\"pts no\"").count(), 1);
        assert_eq!(c.matches("class=\"pts undecided\"").count(), 1);
    }

    #[test]
    fn a_shared_scale_and_extent_override_the_maps_own() {
        let pts = vec![pt(1.0, 100.0, true, Some(2.0), true)];
        let style = MapStyle {
            scale: Some(FidelityScale::new(0.0, 4.0)),
            extent: Some((50.0, 1000.0)),
            ..MapStyle::default()
        };
        let svg = zwidth_map_svg_styled("t", &pts, &[], &style).unwrap();
        // 2 on a 0–4 scale is the middle stop of the five: #21918c.
        assert!(
            svg.contains("fill=\"#21918c\""),
            "the shared scale's middle"
        );
        let flat = svg.replace('\n', "");
        assert!(
            flat.contains(">4.0</text>") && flat.contains(">0.0</text>"),
            "its colour bar"
        );
        // The axis reaches the shared extent, not the point's own 105.
        assert!(
            flat.contains(">1000</text>") || flat.contains(">900</text>"),
            "K axis to 1000"
        );
        assert_eq!(map_extent(&pts, &[]), (1.05, 108.0));
    }

    #[test]
    fn a_scatter_marks_every_point_with_an_escaped_tooltip_and_a_legend_row() {
        let g = vec![
            Scatter {
                name: "search <draft>".into(),
                mark: Mark::Dot(1, 2, 3),
                points: vec![(1.0, 2.0), (2.0, 3.0), (f64::NAN, 1.0)],
                tips: vec!["a & b".into()],
            },
            Scatter {
                name: "best".into(),
                mark: Mark::Ring(0, 0, 0),
                points: vec![(2.0, 3.0)],
                tips: vec![],
            },
        ];
        let svg = scatter_svg("t", "x", "y", &g, (600, 400)).unwrap();
        // NaN points are left out: 2 + 1 marks.
        assert_eq!(svg.matches("class=\"pt\"").count(), 3);
        assert!(svg.contains("<title>a &amp; b</title>"));
        assert!(
            svg.contains("<title>x = 2.0000, y = 3.0000</title>"),
            "a default tooltip"
        );
        assert!(svg.contains("search &lt;draft&gt;</text>"));
        assert!(svg.contains("fill=\"#010203\""));
        assert_eq!(svg.matches("class=\"key\"").count(), 2);
        assert!(scatter_svg("t", "x", "y", &[], (600, 400)).is_err());
    }

    #[test]
    fn ticks_carry_the_decimals_their_span_needs() {
        assert_eq!(tick(123456.0, 400000.0), "123456");
        assert_eq!(tick(1.25, 3.0), "1.25");
        assert_eq!(tick(0.12345, 0.2), "0.1235");
        assert_eq!(tick(3.4e7, 1e8), "3.40e7");
        assert_eq!(
            xml_escape("<a href='x'>&\"</a>"),
            "&lt;a href=&#39;x&#39;&gt;&amp;&quot;&lt;/a&gt;"
        );
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
