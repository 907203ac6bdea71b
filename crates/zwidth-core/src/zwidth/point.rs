//! The points of a map: one verdict at (K, B) ([`Point`]), one boundary
//! point at a B ([`BoundaryPoint`]), and a trial with its place in the
//! map ([`StoredTrial`]). A leaf: everything else in `zwidth` builds on it.

use serde::Serialize;

/// One evaluated (K, B).
#[derive(Debug, Clone, Default, PartialEq, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct Point {
    pub k: f64,
    pub b: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stable: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub passive: Option<bool>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fidelity: Option<f64>,
    /// Noisy scenes: whether the verdict was decided at the scene's
    /// confidence (false: undecided, `passive` is the sign of `margin`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub decided: Option<bool>,
    /// Noisy scenes: min over the lines of Re Z of the best linear
    /// approximation (N·s/m) and its standard error.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub margin_se: Option<f64>,
    /// Noisy scenes: random-phase realizations the verdict took (the
    /// frequency engine's BLA), or hits (the time engine's
    /// `hit.replicates`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub realizations: Option<u32>,
    /// Simulations: true when the device's force limit clipped the wall
    /// force during the trial (the verdict then reflects the actuator too).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub saturated: Option<bool>,
}

impl Point {
    /// The realizations (or replicate hits) the trial ran: one for a
    /// verdict without (a deterministic simulation, a closed form).
    pub fn realizations_run(&self) -> u32 {
        self.realizations.unwrap_or(1)
    }

    /// Decided passive (or stable): certain at the stated confidence.
    pub fn surely_ok(&self) -> bool {
        self.ok() && self.decided != Some(false)
    }

    /// Decided not passive (or unstable).
    pub fn surely_not_ok(&self) -> bool {
        !self.ok() && self.decided != Some(false)
    }

    /// Noisy scenes: the loop diverged (escaped) in the last of its
    /// `realizations`. The frequency engine states a divergence as a
    /// decided verdict with margin −1 and standard error 0 (`probe.rs`,
    /// `diverged`: "Re Z = −1 on every line stands for no steady state");
    /// a measured margin never has a standard error of exactly 0 over two
    /// or more realizations.
    pub fn diverged(&self) -> bool {
        self.decided == Some(true) && self.margin == Some(-1.0) && self.margin_se == Some(0.0)
    }

    pub fn ok(&self) -> bool {
        self.stable.or(self.passive).unwrap_or(false)
    }
}

#[derive(
    Debug, Clone, Copy, Default, PartialEq, Serialize, serde::Deserialize, utoipa::ToSchema,
)]
#[serde(deny_unknown_fields)]
pub struct BoundaryPoint {
    /// Wall damping B (N·s/m).
    pub b: f64,
    /// Largest stiffness that renders at this B (N/m).
    pub k_max: f64,
    /// Noisy scenes: the confidence interval of `k_max` (N/m), from the
    /// largest K decided passive to the smallest decided not passive
    /// (`bisect::interval`); `k_hi` is absent when nothing up to `k_max`
    /// of the map was decided not passive.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_lo: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub k_hi: Option<f64>,
}

impl BoundaryPoint {
    pub fn new(b: f64, k_max: f64) -> Self {
        Self {
            b,
            k_max,
            ..Self::default()
        }
    }

    /// Nothing renders at this B, surely: no K rendered and, on a noisy
    /// scene, the smallest K searched (`k_floor`) was decided not passive.
    /// An empty column whose upper bound lies above `k_floor` may still
    /// render (its verdicts there were undecided).
    pub fn surely_empty(&self, k_floor: f64) -> bool {
        self.k_max == 0.0 && self.k_hi.is_none_or(|h| h <= k_floor)
    }
}

/// A finished trial of map `scope` within one experiment, with its place
/// in the map: `column` is the position of its B in the map's B list (the
/// automatic range counts from B = 0), `index` its order among that
/// column's trials. Stored trials are listed by (scope, column, index):
/// the order the map's own search visits them, whatever the thread count,
/// the worker or the interruptions.
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct StoredTrial {
    pub scope: u32,
    #[serde(default)]
    pub column: u32,
    #[serde(default)]
    pub index: u32,
    pub point: Point,
}
