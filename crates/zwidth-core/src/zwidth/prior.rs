//! A map's prediction of its own boundary (issue 46, "rig maps seeded by a
//! prediction"): a scene to simulate first, a finished run's map, or a
//! boundary given outright. Each column's bisection starts from the
//! predicted bracket (`bisect::bisect_k` with a start) and widens it until
//! the map's own verdicts bracket the boundary, so the result is always the
//! map's, never the prediction's; the report sets the two side by side.
//! Pure: the scene is simulated by `search.rs`.

use serde::{Deserialize, Serialize};

use super::point::BoundaryPoint;
use super::scene::SceneSpec;
use crate::error::SpecError;

/// Where a map's prediction comes from.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case", deny_unknown_fields)]
pub enum Prior {
    /// Simulate this scene first (same method, criterion, search, accuracy
    /// and B list as the map; in this process, never on a rig): e.g. the
    /// device `zwidth identify` gave for the rig.
    Scene(Box<SceneSpec>),
    /// A finished map run's id: the service reads its boundary when it
    /// accepts the spec and stores that boundary in its place.
    Run(String),
    /// A predicted boundary: per B (N·s/m), the largest K that renders
    /// (N/m) with its interval when known.
    Boundary(Vec<BoundaryPoint>),
}

impl Prior {
    /// What the prediction is, in words (the report's `source`).
    pub fn source(&self) -> &'static str {
        match self {
            Prior::Scene(_) => "a simulation of the prior's scene",
            Prior::Run(_) => "a finished run's map",
            Prior::Boundary(_) => "the boundary given",
        }
    }
}

/// Where a column's search starts: the bracket `[lo, hi]` the prediction
/// gives (the boundary expected between them), or a column predicted to
/// render nothing.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    Bracket { lo: f64, hi: f64 },
    Empty,
}

/// A checked prediction: boundary points sorted by B.
#[derive(Debug, Clone, PartialEq)]
pub struct Prediction {
    points: Vec<BoundaryPoint>,
}

impl Prediction {
    /// Check `points` (field `prior.boundary`): at least one, each B
    /// finite and given once, each K finite and ≥ 0 with
    /// k_lo ≤ k_max ≤ k_hi where given.
    pub fn new(mut points: Vec<BoundaryPoint>) -> Result<Self, SpecError> {
        let field = |i: usize, name: &str| format!("prior.boundary[{i}].{name}");
        if points.is_empty() {
            return Err(SpecError::new(
                "prior.boundary",
                "[]",
                "at least one boundary point {b, k_max}",
            ));
        }
        for (i, p) in points.iter().enumerate() {
            if !(p.b.is_finite() && p.b.abs() <= 1e7) {
                return Err(SpecError::new(
                    field(i, "b"),
                    p.b,
                    "a finite damping, |B| ≤ 1e7 N·s/m",
                ));
            }
            if points[..i].iter().any(|q| q.b == p.b) {
                return Err(SpecError::new(
                    field(i, "b"),
                    p.b,
                    "each B once in a predicted boundary",
                ));
            }
            for (name, v) in [("k_max", Some(p.k_max)), ("k_lo", p.k_lo), ("k_hi", p.k_hi)] {
                if let Some(v) = v {
                    if !(v.is_finite() && (0.0..=1e9).contains(&v)) {
                        return Err(SpecError::new(
                            field(i, name),
                            v,
                            "a stiffness 0 to 1e9 N/m",
                        ));
                    }
                }
            }
            if p.k_lo.is_some_and(|lo| lo > p.k_max) {
                return Err(SpecError::new(
                    field(i, "k_lo"),
                    p.k_lo.unwrap_or_default(),
                    format!("at most k_max ({})", p.k_max),
                ));
            }
            if p.k_hi.is_some_and(|hi| hi < p.k_max) {
                return Err(SpecError::new(
                    field(i, "k_hi"),
                    p.k_hi.unwrap_or_default(),
                    format!("at least k_max ({})", p.k_max),
                ));
            }
        }
        points.sort_by(|a, b| a.b.total_cmp(&b.b));
        Ok(Self { points })
    }

    pub fn points(&self) -> &[BoundaryPoint] {
        &self.points
    }

    /// The predicted point at `b`: the one at that B, else the nearest in B
    /// (the lower of two equally near).
    pub fn nearest(&self, b: f64) -> BoundaryPoint {
        let mut best = self.points[0];
        for p in &self.points[1..] {
            if (p.b - b).abs() < (best.b - b).abs() {
                best = *p;
            }
        }
        best
    }

    /// Where the search at `b` starts, for a bisection to `rel_tol`: the
    /// predicted interval `[k_lo, k_hi]` (`k_max` where `k_lo` is unknown
    /// or 0; `k_max`·(1 + `rel_tol`) where `k_hi` is unknown or not above
    /// the lower end); `Empty` where nothing was predicted to render. A
    /// predicted interval narrower than `rel_tol` is kept: its two verdicts
    /// are the ones that bracketed the boundary before.
    pub fn start(&self, b: f64, rel_tol: f64) -> Start {
        let p = self.nearest(b);
        if p.k_max <= 0.0 {
            return Start::Empty;
        }
        let lo = p.k_lo.filter(|&lo| lo > 0.0).unwrap_or(p.k_max);
        let hi = p
            .k_hi
            .filter(|&hi| hi > lo)
            .unwrap_or(lo * (1.0 + rel_tol))
            .min(1e9);
        Start::Bracket { lo, hi }
    }
}

/// One column's prediction beside the map's own boundary.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PriorColumn {
    /// Damping (N·s/m).
    pub b: f64,
    /// The predicted largest K that renders (N/m) and its interval.
    pub predicted_k_max: f64,
    pub predicted_k_lo: f64,
    pub predicted_k_hi: f64,
    /// The map's own boundary agrees with the prediction: their intervals
    /// overlap (a point without one stands for `k_max` ± `rel_tol`).
    pub agrees: bool,
}

/// The prediction beside the map's boundary, column by column.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct PriorReport {
    /// Where the prediction came from, in words.
    pub source: String,
    pub columns: Vec<PriorColumn>,
    /// Columns whose boundary disagrees with the prediction.
    pub disagreements: usize,
    /// The search's trials, for the saving against a map without a prior.
    pub trials: usize,
}

impl PriorReport {
    /// The predicted boundary, as boundary points (for a plot).
    pub fn predicted_boundary(&self) -> Vec<BoundaryPoint> {
        self.columns
            .iter()
            .map(|c| BoundaryPoint {
                b: c.b,
                k_max: c.predicted_k_max,
                k_lo: Some(c.predicted_k_lo),
                k_hi: Some(c.predicted_k_hi),
            })
            .collect()
    }
}

/// A boundary point's interval, `k_max` ± `rel_tol` where it has none.
fn interval(p: &BoundaryPoint, rel_tol: f64) -> (f64, f64) {
    (
        p.k_lo.unwrap_or(p.k_max * (1.0 - rel_tol)),
        p.k_hi.unwrap_or(p.k_max * (1.0 + rel_tol)),
    )
}

/// The report of `prediction` against the map's `boundary` (found to
/// `rel_tol` in `trials` trials).
pub fn report(
    source: &str,
    prediction: &Prediction,
    boundary: &[BoundaryPoint],
    rel_tol: f64,
    trials: usize,
) -> PriorReport {
    let columns: Vec<PriorColumn> = boundary
        .iter()
        .map(|m| {
            let p = prediction.nearest(m.b);
            let (p_lo, p_hi) = interval(&p, rel_tol);
            let (m_lo, m_hi) = interval(m, rel_tol);
            PriorColumn {
                b: m.b,
                predicted_k_max: p.k_max,
                predicted_k_lo: p_lo,
                predicted_k_hi: p_hi,
                agrees: p_lo <= m_hi && m_lo <= p_hi,
            }
        })
        .collect();
    PriorReport {
        source: source.to_string(),
        disagreements: columns.iter().filter(|c| !c.agrees).count(),
        columns,
        trials,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bp(b: f64, k_max: f64, k_lo: Option<f64>, k_hi: Option<f64>) -> BoundaryPoint {
        BoundaryPoint {
            b,
            k_max,
            k_lo,
            k_hi,
        }
    }

    #[test]
    fn the_start_is_the_predicted_interval_at_least_one_resolution_wide() {
        let p = Prediction::new(vec![
            bp(10.0, 2000.0, Some(1900.0), Some(2100.0)),
            bp(0.0, 1000.0, None, None),
            bp(20.0, 0.0, None, Some(5.0)),
            bp(30.0, 3000.0, Some(2999.0), Some(3000.5)),
            bp(40.0, 4000.0, Some(4000.0), Some(4000.0)),
            bp(50.0, 500.0, Some(0.0), Some(600.0)),
        ])
        .unwrap();
        // Sorted by B; the interval where given.
        let bs: Vec<f64> = p.points().iter().map(|q| q.b).collect();
        assert_eq!(bs, [0.0, 10.0, 20.0, 30.0, 40.0, 50.0]);
        // No lower end decided (k_lo 0): from k_max, not from 0.
        assert_eq!(
            p.start(50.0, 0.01),
            Start::Bracket {
                lo: 500.0,
                hi: 600.0
            }
        );
        assert_eq!(
            p.start(10.0, 0.01),
            Start::Bracket {
                lo: 1900.0,
                hi: 2100.0
            }
        );
        // No interval: k_max to k_max·(1 + rel_tol).
        assert_eq!(
            p.start(0.0, 0.01),
            Start::Bracket {
                lo: 1000.0,
                hi: 1010.0
            }
        );
        // An interval narrower than the resolution is kept (its verdicts
        // bracketed the boundary); one of no width is widened above.
        assert_eq!(
            p.start(30.0, 0.01),
            Start::Bracket {
                lo: 2999.0,
                hi: 3000.5
            }
        );
        assert_eq!(p.start(20.0, 0.01), Start::Empty);
        assert_eq!(
            p.start(40.0, 0.01),
            Start::Bracket {
                lo: 4000.0,
                hi: 4040.0
            }
        );
        // Between columns: the nearest (the lower of two equally near).
        assert_eq!(
            p.start(4.0, 0.01),
            Start::Bracket {
                lo: 1000.0,
                hi: 1010.0
            }
        );
        assert_eq!(
            p.start(5.0, 0.01),
            Start::Bracket {
                lo: 1000.0,
                hi: 1010.0
            }
        );
        assert_eq!(
            p.start(6.0, 0.01),
            Start::Bracket {
                lo: 1900.0,
                hi: 2100.0
            }
        );
        assert_eq!(
            p.start(44.0, 0.01),
            Start::Bracket {
                lo: 4000.0,
                hi: 4040.0
            }
        );
    }

    #[test]
    fn a_bad_prediction_names_its_field() {
        let err = |pts: Vec<BoundaryPoint>| Prediction::new(pts).unwrap_err().field;
        assert_eq!(err(vec![]), "prior.boundary");
        assert_eq!(
            err(vec![bp(f64::NAN, 1.0, None, None)]),
            "prior.boundary[0].b"
        );
        assert_eq!(
            err(vec![bp(0.0, 1.0, None, None), bp(0.0, 2.0, None, None)]),
            "prior.boundary[1].b"
        );
        assert_eq!(
            err(vec![bp(0.0, 1.0, None, None), bp(-0.0, 2.0, None, None)]),
            "prior.boundary[1].b"
        );
        assert_eq!(
            err(vec![bp(0.0, -1.0, None, None)]),
            "prior.boundary[0].k_max"
        );
        assert_eq!(
            err(vec![bp(0.0, 1.0, Some(f64::INFINITY), None)]),
            "prior.boundary[0].k_lo"
        );
        assert_eq!(
            err(vec![bp(0.0, 1.0, Some(2.0), None)]),
            "prior.boundary[0].k_lo"
        );
        assert_eq!(
            err(vec![bp(0.0, 1.0, None, Some(0.5))]),
            "prior.boundary[0].k_hi"
        );
        assert_eq!(
            err(vec![bp(0.0, 2e9, None, None)]),
            "prior.boundary[0].k_max"
        );
    }

    #[test]
    fn a_column_agrees_where_the_intervals_overlap() {
        let p = Prediction::new(vec![
            bp(0.0, 1000.0, Some(990.0), Some(1010.0)),
            bp(1.0, 1000.0, None, None),
            bp(2.0, 0.0, None, None),
        ])
        .unwrap();
        let r = report(
            "given",
            &p,
            &[
                // Overlaps [990, 1010] at its end.
                bp(0.0, 1020.0, Some(1010.0), Some(1030.0)),
                // 1000 ± 1 % against 1030 ± 1 %: [990, 1010] and [1019.7, 1040.3].
                bp(1.0, 1030.0, None, None),
                // Both empty.
                bp(2.0, 0.0, None, None),
            ],
            0.01,
            7,
        );
        assert_eq!(
            r.columns.iter().map(|c| c.agrees).collect::<Vec<_>>(),
            [true, false, true]
        );
        assert_eq!((r.disagreements, r.trials), (1, 7));
        assert_eq!(r.columns[1].predicted_k_lo, 990.0);
        assert_eq!(r.columns[1].predicted_k_hi, 1010.0);
    }
}
