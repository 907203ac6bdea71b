//! What the plots share: the colour ramp, colours as SVG
//! strings, tick labels, legend boxes and rows, and escaping text for SVG.

use plotters::prelude::*;

/// Viridis-like colour for t in [0, 1] (piecewise-linear through five stops).
pub(super) fn colour(t: f64) -> RGBColor {
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

pub(super) fn hex(c: RGBColor) -> String {
    format!("#{:02x}{:02x}{:02x}", c.0, c.1, c.2)
}

/// A legend box at the top-right `corner` (px): each row a mark (SVG drawn
/// around (0, 0) to (18, 0)) and its text (escaped by the caller).
pub(super) fn legend_box(corner: (i32, i32), rows: &[(String, String)]) -> String {
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
pub(super) const LEGEND_ROW: i32 = 30;

/// A tick label with as many decimals as the axis span needs.
pub(super) fn tick(v: f64, span: f64) -> String {
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
pub(super) fn legend_row(at: (i32, i32), rows: &[(String, String)]) -> String {
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
