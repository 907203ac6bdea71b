//! Scatter plots: marks of a few kinds (a tune's evaluations, the Pareto
//! front), each with its tooltip.

use plotters::prelude::*;

use super::style::*;

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
