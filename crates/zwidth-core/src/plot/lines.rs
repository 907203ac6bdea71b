//! Line plots (plotters): named series on linear or log-log axes, with
//! optional confidence bars.

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
pub(super) fn draw_lines<
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
