//! Work units (issue 14): the parts of a map another process can compute
//! on its own — one B column of a bisection or a grid (its columns do not
//! depend on each other), or the whole map for a trace (each B starts from
//! the last) and for the analytic engine (closed forms: a column is not
//! worth a round trip). A map whose observer has a [`Farm`] hands its units
//! to it and waits; the farm has them computed (by `run_unit`, anywhere)
//! and adds their trials to the observer's replay, so the map then replays
//! every trial and its result is the one a single process computes.

use serde::{Deserialize, Serialize};

use super::control::RunControl;
use super::settings::MapSpec;

/// One unit of map `scope` of an experiment.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(tag = "unit", rename_all = "snake_case")]
pub enum Unit {
    /// The column at position `column` of the map's B list (the automatic
    /// range counts from B = 0), whose damping is `b` (N·s/m).
    Column { column: u32, b: f64 },
    /// The whole map.
    Map,
}

impl Unit {
    /// The unit's column as stored: its position, or -1 for a whole map.
    pub fn column_key(&self) -> i64 {
        match self {
            Unit::Column { column, .. } => i64::from(*column),
            Unit::Map => WHOLE_MAP,
        }
    }
}

/// The stored column of a whole-map unit.
pub const WHOLE_MAP: i64 = -1;

/// Has units computed elsewhere (the jobs layer: a database queue that
/// workers claim from).
pub trait Farm: Send + Sync {
    /// Have `units` of map `scope` (whose spec is `spec`) computed, and
    /// their trials added to `observer`'s replay ([`RunControl::add_done`]);
    /// block until every one is, calling `done(n)` as the count of finished
    /// ones grows. Return early (Ok) once `observer` is cancelled. Err: why
    /// a unit cannot be computed (the map stops, failed with it).
    fn run(
        &self,
        scope: u32,
        spec: &MapSpec,
        units: &[Unit],
        observer: &dyn RunControl,
        done: &(dyn Fn(usize) + Sync),
    ) -> Result<(), String>;

    /// How many columns of an automatic B range to hand out at once (the
    /// range ends at the first two empty columns: a larger batch is more
    /// parallel, and computes more columns past the end, which are dropped).
    fn batch(&self) -> usize {
        8
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::observer::Observer;
    use crate::zwidth::point::StoredTrial;
    use crate::zwidth::search::{map, map_observed, run_unit, MapResult};
    use std::sync::{Arc, Mutex};

    /// A farm in this process: each unit computed by `run_unit` on an
    /// observer of its own (as a worker claiming it would), its trials
    /// handed back; every call recorded.
    #[derive(Default)]
    struct LocalFarm {
        calls: Mutex<Vec<(u32, Vec<Unit>)>>,
        fail: Option<String>,
    }

    impl Farm for LocalFarm {
        fn run(
            &self,
            scope: u32,
            spec: &MapSpec,
            units: &[Unit],
            observer: &dyn RunControl,
            done: &(dyn Fn(usize) + Sync),
        ) -> Result<(), String> {
            self.calls.lock().unwrap().push((scope, units.to_vec()));
            if let Some(why) = &self.fail {
                return Err(why.clone());
            }
            for (i, &u) in units.iter().enumerate() {
                let own = Arc::new(Observer::default());
                run_unit(spec, scope, u, own.clone()).map_err(|e| e.to_string())?;
                observer.add_done(own.take_new());
                done(i + 1);
            }
            Ok(())
        }

        fn batch(&self) -> usize {
            3
        }
    }

    /// The 2011 paper's device in the time domain (force limit 4 N, 10 kHz
    /// sampling), draft accuracy: a few hundred trials.
    fn time_map(extra: &str) -> MapSpec {
        serde_json::from_str(&format!(
            r#"{{"scene":{{"device":{{"force_limit":4}},"loop":{{"sample_hz":10000,"render_hz":1000}},
                "estimator":{{"kind":"butterworth","cutoff_hz":500}}}},
                "method":"time","criterion":"stability"{extra}{draft}}}"#,
            draft = if extra.contains("accuracy") { "" } else { r#","accuracy":"draft""# }
        ))
        .unwrap()
    }

    /// A farmed map's result, the trials it computed itself, the columns it
    /// dropped, and its observer.
    type Farmed = (MapResult, Vec<StoredTrial>, Vec<(u32, f64)>, Arc<Observer>);

    /// The map through `farm` as map 2 of an experiment: its result, what
    /// the map itself computed (it should be nothing: every trial
    /// replayed), the columns it dropped, and its observer.
    fn farmed(spec: &MapSpec, farm: Arc<LocalFarm>) -> Farmed {
        let o = Arc::new(Observer::default().with_farm(farm));
        let r = map_observed(spec, Some(o.clone()), 2).unwrap();
        (r, o.take_new(), o.take_dropped(), o)
    }

    fn same(a: &MapResult, b: &MapResult) {
        assert!(a
            .points
            .iter()
            .all(|p| p.passive.is_some() || p.stable.is_some()));
        assert_eq!(a.points, b.points);
        assert_eq!(a.boundary, b.boundary);
        assert_eq!(a.k_width.to_bits(), b.k_width.to_bits());
        assert_eq!(a.b_width.to_bits(), b.b_width.to_bits());
        assert_eq!(a.area.to_bits(), b.area.to_bits());
        assert_eq!(a.trials, b.trials);
    }

    #[test]
    fn a_listed_bisection_is_farmed_column_by_column_and_equals_one_process() {
        let spec = time_map(r#","b":[0,10,20,30]"#);
        let farm = Arc::new(LocalFarm::default());
        let (r, new, dropped, o) = farmed(&spec, farm.clone());
        same(&r, &map(&spec).unwrap());
        assert!(
            new.is_empty(),
            "the map computed {} trials itself",
            new.len()
        );
        assert!(dropped.is_empty());
        // One call with the four columns, in list order, each with its B.
        let calls = farm.calls.lock().unwrap().clone();
        let want: Vec<Unit> = [0.0, 10.0, 20.0, 30.0]
            .iter()
            .enumerate()
            .map(|(i, &b)| Unit::Column {
                column: i as u32,
                b,
            })
            .collect();
        assert_eq!(calls, [(2, want)]);
        assert_eq!(o.fraction(), 1.0);
        // Replayed trials count as the map's trials.
        assert_eq!(o.trials_done(), r.trials);
    }

    #[test]
    fn an_automatic_range_is_farmed_in_batches_and_ends_where_one_process_ends() {
        let spec = time_map(r#","b_max":400,"accuracy":{"preset":"draft","b_step":40}"#);
        let one = {
            let o = Arc::new(Observer::default());
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(1)
                .build()
                .unwrap();
            let r = pool
                .install(|| map_observed(&spec, Some(o.clone()), 2))
                .unwrap();
            (r, o.take_dropped())
        };
        let farm = Arc::new(LocalFarm::default());
        let (r, new, dropped, o) = farmed(&spec, farm.clone());
        assert_eq!(o.runaway(), None);
        same(&r, &one.0);
        assert_eq!(dropped, one.1, "the same columns dropped");
        assert!(new.is_empty());
        // Batches of the farm's 3 columns, from B = 0 by 40, until the end.
        let calls = farm.calls.lock().unwrap().clone();
        let mut next = 0u32;
        for (scope, units) in &calls {
            assert_eq!(*scope, 2);
            assert!(units.len() <= 3);
            for u in units {
                assert_eq!(
                    *u,
                    Unit::Column {
                        column: next,
                        b: 40.0 * f64::from(next)
                    }
                );
                next += 1;
            }
        }
        assert!(next as usize >= r.boundary.len(), "{next} columns farmed");
        assert!(calls.len() >= 2, "more than one batch: {calls:?}");
    }

    #[test]
    fn a_grid_is_farmed_by_column_and_a_trace_or_an_analytic_map_whole() {
        let grid = time_map(
            r#","search":"grid","b":[0,25],"k_max":4000,"accuracy":{"preset":"draft","k_step":500}"#,
        );
        let farm = Arc::new(LocalFarm::default());
        let (r, new, _, o) = farmed(&grid, farm.clone());
        assert_eq!(o.runaway(), None);
        same(&r, &map(&grid).unwrap());
        assert!(new.is_empty());
        assert_eq!(
            farm.calls.lock().unwrap().clone(),
            [(
                2,
                vec![
                    Unit::Column { column: 0, b: 0.0 },
                    Unit::Column { column: 1, b: 25.0 }
                ]
            )]
        );
        let analytic: MapSpec = serde_json::from_str(
            r#"{"scene":{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}},"method":"analytic","b_max":2000,"accuracy":{"preset":"draft","b_step":100}}"#,
        )
        .unwrap();
        let trace = time_map(r#","search":"trace","b_max":60"#);
        for spec in [analytic, trace] {
            let farm = Arc::new(LocalFarm::default());
            let (r, new, _, o) = farmed(&spec, farm.clone());
            assert_eq!(o.runaway(), None);
            same(&r, &map(&spec).unwrap());
            assert!(new.is_empty());
            assert_eq!(farm.calls.lock().unwrap().clone(), [(2, vec![Unit::Map])]);
        }
    }

    /// A farm that keeps the default batch (as the database's does).
    struct DefaultBatch(LocalFarm);
    impl Farm for DefaultBatch {
        fn run(
            &self,
            scope: u32,
            spec: &MapSpec,
            units: &[Unit],
            observer: &dyn RunControl,
            done: &(dyn Fn(usize) + Sync),
        ) -> Result<(), String> {
            self.0.run(scope, spec, units, observer, done)
        }
    }

    #[test]
    fn an_automatic_range_goes_out_eight_columns_at_a_time_by_default() {
        // docs/service.md: "queues its columns 8 at a time". The analytic
        // engine would be one unit: the time engine, 10 columns or more.
        let spec = time_map(r#","b_max":400,"accuracy":{"preset":"draft","b_step":40}"#);
        let inner = DefaultBatch(LocalFarm::default());
        let farm = Arc::new(inner);
        let o = Arc::new(Observer::default().with_farm(farm.clone()));
        map_observed(&spec, Some(o.clone()), 0).unwrap();
        let sizes: Vec<usize> = farm
            .0
            .calls
            .lock()
            .unwrap()
            .iter()
            .map(|(_, u)| u.len())
            .collect();
        assert_eq!(sizes.first(), Some(&8), "{sizes:?}");
        // And the observer says it hands its maps to a farm.
        assert!(format!("{o:?}").contains("farm: Some(Farm)"), "{o:?}");
    }

    #[test]
    fn a_unit_that_cannot_be_computed_fails_the_map_with_its_reason() {
        let spec = time_map(r#","b":[0,10]"#);
        let farm = Arc::new(LocalFarm {
            fail: Some("unit 2/1 failed: its worker stopped answering 3 times".into()),
            ..LocalFarm::default()
        });
        let (_, _, _, o) = farmed(&spec, farm);
        assert!(o.cancelled());
        assert_eq!(
            o.runaway().as_deref(),
            Some("unit 2/1 failed: its worker stopped answering 3 times")
        );
    }

    #[test]
    fn a_farmed_sweep_equals_one_process_map_by_map() {
        use crate::zwidth::sweep::{sweep_observed, SweepSpec};
        let spec: SweepSpec = serde_json::from_str(
            r#"{"map":{"scene":{"device":{"force_limit":4},"loop":{"sample_hz":10000,"render_hz":1000},
                "estimator":{"kind":"butterworth","cutoff_hz":500}},"method":"time","criterion":"stability",
                "accuracy":"draft","b":[0,10]},"parameter":{"path":"estimator.cutoff_hz","values":[300,400,500]}}"#,
        )
        .unwrap();
        let one = sweep_observed(&spec, None).unwrap();
        let farm = Arc::new(LocalFarm::default());
        let o = Arc::new(Observer::default().with_farm(farm.clone()));
        let got = sweep_observed(&spec, Some(o.clone())).unwrap();
        assert_eq!(o.runaway(), None);
        assert_eq!(got.rows.len(), 3);
        for (a, b) in got.rows.iter().zip(&one.rows) {
            assert_eq!((&a.label, a.value), (&b.label, b.value));
            same(&a.map, &b.map);
        }
        assert_eq!(got.best_k_width, one.best_k_width);
        assert!(o.take_new().is_empty());
        // Each map (scope 0, 1, 2) farmed its two columns.
        let mut scopes: Vec<u32> = farm.calls.lock().unwrap().iter().map(|(s, _)| *s).collect();
        scopes.sort();
        assert_eq!(scopes, [0, 1, 2]);
    }

    #[test]
    fn a_unit_is_stored_by_its_column_or_minus_one_for_a_whole_map() {
        // migrations/sqlite/0012_units.sql: `col`, -1 for a whole map.
        assert_eq!(Unit::Map.column_key(), -1);
        assert_eq!(WHOLE_MAP, -1);
        assert_eq!(Unit::Column { column: 7, b: 35.0 }.column_key(), 7);
        assert_eq!(Unit::Column { column: 0, b: 0.0 }.column_key(), 0);
    }

    #[test]
    fn a_column_unit_must_be_a_column_of_its_map() {
        let listed = time_map(r#","b":[0,10]"#);
        let o = || Arc::new(Observer::default());
        let e = run_unit(&listed, 0, Unit::Column { column: 1, b: 15.0 }, o()).unwrap_err();
        assert_eq!((e.field.as_str(), e.value.as_str()), ("b", "15"));
        let trace = time_map(r#","search":"trace","b":[0,10]"#);
        let e = run_unit(&trace, 0, Unit::Column { column: 1, b: 10.0 }, o()).unwrap_err();
        assert_eq!(e.field, "b");
        // A listed column computes exactly that column's trials, numbered
        // from 0 in its place.
        let own = o();
        run_unit(&listed, 5, Unit::Column { column: 1, b: 10.0 }, own.clone()).unwrap();
        let t = own.take_new();
        assert!(!t.is_empty());
        assert!(t
            .iter()
            .all(|t| t.scope == 5 && t.column == 1 && t.point.b == 10.0));
        assert_eq!(
            t.iter().map(|t| t.index).collect::<Vec<_>>(),
            (0..t.len() as u32).collect::<Vec<_>>()
        );
    }
}
