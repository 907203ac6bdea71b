//! The verdicts a map's search asks for, inside a run: each trial is
//! counted, replayed when an earlier attempt stored it, sent to the rig's
//! backend when trials run elsewhere, recorded with its place in the map,
//! and skipped once the run is cancelled; a map's units go to the farm.
//! The engine itself is [`Evaluator`]'s.

use std::sync::Arc;

use super::bisect::{bisect_k, Bracket};
use super::evaluator::Evaluator;
use super::farm::Unit;
use super::observer::Observer;
use super::point::{BoundaryPoint, Point, StoredTrial};
use super::settings::{Accuracy, MapSpec, SearchKind};

/// An [`Evaluator`] inside map `scope` of a run reporting to `observer`.
pub struct Classifier {
    pub ev: Evaluator,
    pub(super) observer: Option<Arc<Observer>>,
    pub(super) scope: u32,
    /// The map's B list, by the bits of each B: a trial's column (B values
    /// not in it, and evaluators outside a map, count as column 0).
    pub(super) columns: std::collections::HashMap<u64, u32>,
    /// The accuracy as specified (a remote trial resolves it again, on the
    /// same scene, to the same `res`); set by the map.
    pub(super) accuracy: Option<Accuracy>,
}

impl std::ops::Deref for Classifier {
    type Target = Evaluator;
    fn deref(&self) -> &Evaluator {
        &self.ev
    }
}

impl Classifier {
    /// `ev` outside any run (no observer: every verdict computed here).
    pub fn new(ev: Evaluator) -> Self {
        Self {
            ev,
            observer: None,
            scope: 0,
            columns: std::collections::HashMap::new(),
            accuracy: None,
        }
    }

    pub fn classify(&self, k: f64, b: f64) -> Point {
        self.classify_seeded(k, b, self.scene.spec.probe.seed)
    }

    /// The verdict at (K, B) with a noisy probe's realizations drawn from
    /// `seed` (a trial of its own: `bla::trial_seed`); a trial sent to the
    /// rig's backend carries it as its scene's probe seed.
    pub fn classify_seeded(&self, k: f64, b: f64, seed: u64) -> Point {
        let mut p = Point {
            k,
            b,
            ..Point::default()
        };
        if let Some(o) = &self.observer {
            if o.cancelled() {
                // Every search ends quickly once nothing renders.
                p.passive = Some(false);
                return p;
            }
            o.wait_while_held();
            o.count_trial();
            let column = self.columns.get(&b.to_bits()).copied().unwrap_or(0);
            let index = o.next_index(self.scope, column);
            let trial = |point: Point| StoredTrial {
                scope: self.scope,
                column,
                index,
                point,
            };
            if let Some(done) = o.replay(self.scope, k, b) {
                // Stored without its place (by an older version, or by an
                // attached rig's result before the search took it): store
                // the place again.
                if (done.column, done.index) != (column, index) {
                    o.record(trial(done.point.clone()));
                }
                return done.point;
            }
            let p = match (o.backend(), &self.accuracy) {
                (Some(backend), Some(accuracy)) => {
                    let mut scene = self.scene.spec.clone();
                    scene.probe.seed = seed;
                    let request = super::trial::TrialRequest {
                        scope: self.scope,
                        k,
                        b,
                        scene,
                        method: self.method,
                        criterion: self.criterion,
                        accuracy: accuracy.clone(),
                    };
                    match backend.trial(&request, o.as_ref()) {
                        Some(p) => p,
                        // Cancelled while the trial was out: end as a cancel does.
                        None => {
                            p.passive = Some(false);
                            return p;
                        }
                    }
                }
                _ => self.evaluate_seeded(p, seed),
            };
            o.record(trial(p.clone()));
            return p;
        }
        self.evaluate_seeded(p, seed)
    }

    /// The farm this map's units go to, if any.
    pub(super) fn farm(&self) -> Option<&Arc<dyn super::farm::Farm>> {
        self.observer.as_ref().and_then(|o| o.farm())
    }

    /// With a farm: have `units` of this map computed elsewhere, their
    /// trials then replayed here. A unit that cannot be computed stops the
    /// map, failed with the reason. Without a farm: nothing (the map
    /// computes them itself).
    pub(super) fn farm_units(&self, spec: &MapSpec, units: &[Unit], done: &(dyn Fn(usize) + Sync)) {
        let (Some(o), Some(farm)) = (&self.observer, self.farm()) else {
            return;
        };
        // A whole-map unit's columns came with it.
        let columns = units.iter().any(|u| matches!(u, Unit::Column { .. }));
        if o.cancelled() || (columns && whole_map_unit(spec, self)) {
            return;
        }
        if let Err(why) = farm.run(self.scope, spec, units, o.as_ref(), done) {
            o.fail(why);
        }
    }

    /// Tell the observer (if any) this map is `fraction` done.
    pub(super) fn report(&self, fraction: f64) {
        if let Some(o) = &self.observer {
            o.report(self.scope, fraction);
        }
    }

    /// Largest K that renders at B: bracket from `k0` (or from a predicted
    /// `start`), then bisect. With
    /// `robust`, K values below the result are checked as well (see
    /// `SearchKind::RobustBisect`).
    pub(super) fn bisect_k(
        &self,
        b: f64,
        k0: f64,
        k_cap: f64,
        robust: bool,
        start: Option<super::prior::Start>,
        points: &mut Vec<Point>,
    ) -> Option<f64> {
        let bounds = Bracket {
            k0,
            k_cap,
            rel_tol: self.res.k_rel_tol,
        };
        bisect_k(|k| self.classify(k, b), bounds, robust, start, points)
    }

    /// The confidence interval of a boundary point found by `bisect_k`
    /// (`predicted`: from a predicted start, `bisect::anchor_below` first).
    pub(super) fn interval(
        &self,
        bp: &mut BoundaryPoint,
        k0: f64,
        k_cap: f64,
        predicted: bool,
        points: &mut Vec<Point>,
    ) {
        let bounds = Bracket {
            k0,
            k_cap,
            rel_tol: self.res.k_rel_tol,
        };
        if predicted {
            super::bisect::anchor_below(|k| self.classify(k, bp.b), bounds, points);
        }
        let (lo, hi) =
            super::bisect::interval(|k| self.classify(k, bp.b), bp.k_max, bounds, points);
        bp.k_lo = Some(lo.min(bp.k_max));
        bp.k_hi = Some(hi.unwrap_or(k_cap).max(bp.k_max));
    }
}

/// Whether a map is one unit of work (a trace, the analytic engine, the
/// Psi search: its second pass depends on every column's first), not one
/// per column.
pub(super) fn whole_map_unit(spec: &MapSpec, ev: &Evaluator) -> bool {
    spec.search == SearchKind::Trace || ev.runs_psi(spec.search) || ev.model.is_some()
}
