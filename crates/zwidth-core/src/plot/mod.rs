//! SVG plots (plotters, SVG backend only: no system fonts needed), one
//! file per kind: line plots (`lines`), the K–B map (`map`), scatter plots
//! (`scatter`), and what they share (`style`).

mod lines;
mod map;
mod scatter;
mod style;

pub use lines::{lines_svg, loglog_svg, Series};
pub use map::{
    map_extent, zwidth_map_svg, zwidth_map_svg_styled, FidelityScale, MapPlotPoint, MapStyle,
    LOG_SPAN,
};
pub use scatter::{scatter_svg, Mark, Scatter};
pub use style::xml_escape;

#[cfg(test)]
mod tests {
    use super::lines::*;
    use super::map::*;
    use super::scatter::*;
    use super::style::*;
    use crate::zwidth::search::BoundaryPoint;

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
        // A prediction (a map's prior): a blue line in the legend and on
        // the chart.
        assert!(!c.contains("prediction"));
        let high = vec![
            BoundaryPoint::new(0.0, 4000.0),
            BoundaryPoint::new(20.0, 5000.0),
        ];
        let style = MapStyle {
            prediction: high,
            ..MapStyle::default()
        };
        let p = zwidth_map_svg_styled("t", &pts, &b, &style).unwrap();
        assert!(p.contains("prediction (the map's prior)"));
        // RGB (30, 90, 200): the line and its key.
        assert!(p.to_lowercase().matches("#1e5ac8").count() >= 2);
        assert!(!c.to_lowercase().contains("#1e5ac8"));
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
