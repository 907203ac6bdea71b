//! Tests of the Psi search's driver on the seed device (friction and
//! quantization: noisy verdicts), at the draft preset on a few columns.

use std::sync::Arc;

use crate::zwidth::observer::Observer;
use crate::zwidth::point::Point;
use crate::zwidth::point::StoredTrial;
use crate::zwidth::scene::SceneSpec;
use crate::zwidth::search::map_observed;
use crate::zwidth::settings::{Criterion, MapSpec, Method, SearchKind};

fn seed_device(b: Vec<f64>) -> MapSpec {
    MapSpec {
        scene: SceneSpec::default(),
        method: Method::Frequency,
        criterion: Criterion::Impedance,
        search: SearchKind::Psi,
        accuracy: serde_json::from_str(r#""draft""#).unwrap(),
        b: Some(b),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    }
}

/// The same map by bisection.
fn bisected(spec: &MapSpec) -> crate::zwidth::search::MapResult {
    map_observed(
        &MapSpec {
            search: SearchKind::Bisect,
            ..spec.clone()
        },
        None,
        0,
    )
    .unwrap()
}

#[test]
fn a_psi_map_is_the_same_on_any_thread_count_and_replays_from_its_trials() {
    let spec = seed_device(vec![0.0, 200.0, 400.0]);
    let mut first: Option<(Vec<StoredTrial>, String)> = None;
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let o = Arc::new(Observer::default());
        let r = pool
            .install(|| map_observed(&spec, Some(o.clone()), 2))
            .unwrap();
        let mut stored = o.take_new();
        stored.sort_by_key(|t| (t.column, t.index));
        let points: Vec<_> = stored.iter().map(|t| t.point.clone()).collect();
        assert_eq!(
            r.points, points,
            "{threads} threads: the points in (column, index) order"
        );
        // Each column's trials at distinct K (a trial is stored, and
        // replayed, by its K).
        for column in 0..3 {
            let mut ks: Vec<u64> = stored
                .iter()
                .filter(|t| t.column == column)
                .map(|t| t.point.k.to_bits())
                .collect();
            let n = ks.len();
            ks.sort_unstable();
            ks.dedup();
            assert_eq!(ks.len(), n, "column {column}");
        }
        let boundary = serde_json::to_string(&r.boundary).unwrap();
        match &first {
            None => first = Some((stored, boundary)),
            Some((s0, b0)) => {
                assert_eq!(&stored, s0, "{threads} threads");
                assert_eq!(&boundary, b0, "{threads} threads");
            }
        }
    }
    // Resumed from every stored trial, nothing is computed again and the
    // map is the same.
    let (stored, boundary) = first.unwrap();
    let o = Arc::new(Observer::resuming(stored.clone()));
    let r = map_observed(&spec, Some(o.clone()), 2).unwrap();
    assert_eq!(serde_json::to_string(&r.boundary).unwrap(), boundary);
    assert!(o.take_new().is_empty(), "a replayed trial stored again");
}

#[test]
fn a_psi_map_brackets_each_boundary_and_states_its_resolution() {
    let spec = seed_device(vec![0.0, 200.0]);
    let r = map_observed(&spec, None, 0).unwrap();
    assert!(r.resolution.contains("Psi method"), "{}", r.resolution);
    for bp in &r.boundary {
        let (lo, hi) = (bp.k_lo.unwrap(), bp.k_hi.unwrap());
        assert!(lo <= bp.k_max && bp.k_max <= hi, "{bp:?}");
        // Every trial of the column below the lower end by more than the
        // bracket passed or was undecided, and the column's trials
        // straddle its boundary: one above it failed.
        let column: Vec<_> = r.points.iter().filter(|p| p.b == bp.b).collect();
        assert!(column.iter().any(|p| p.k > bp.k_max && !p.ok()), "{bp:?}");
        assert!(column.iter().any(|p| p.k < bp.k_max && p.ok()), "{bp:?}");
    }
    // The draft bisection of the same columns defines its boundary by a
    // shorter trial (10 realizations, not the standard 24) on one
    // excitation sequence per column; its interval still meets the Psi
    // interval.
    let bisect = bisected(&spec);
    for (p, q) in r.boundary.iter().zip(&bisect.boundary) {
        assert!(
            q.k_lo.unwrap() <= p.k_hi.unwrap() && p.k_lo.unwrap() <= q.k_hi.unwrap(),
            "psi {p:?}, bisection {q:?}"
        );
    }
}

#[test]
fn a_psi_map_whose_trials_run_elsewhere_is_the_same_map_to_the_bit() {
    // A rig's backend (`agent --sim`) gets each trial as a request: its
    // scene carries the trial's own seed and its accuracy the standard
    // trial, after a JSON round trip; computed from the request alone
    // (`trial::run`), every verdict is the one this process computes.
    use crate::zwidth::control::RunControl;
    use crate::zwidth::trial::{run, TrialBackend, TrialRequest};
    struct OverTheWire;
    impl TrialBackend for OverTheWire {
        fn trial(&self, request: &TrialRequest, _: &dyn RunControl) -> Option<Point> {
            let wire = serde_json::to_string(request).unwrap();
            let back: TrialRequest = serde_json::from_str(&wire).unwrap();
            Some(run(&back).unwrap())
        }
    }
    // At the draft preset: the standard trial must cross the wire too.
    let spec = seed_device(vec![300.0]);
    let here = map_observed(&spec, None, 0).unwrap();
    let o = Arc::new(Observer::default().with_backend(Arc::new(OverTheWire)));
    let there = map_observed(&spec, Some(o), 0).unwrap();
    assert_eq!(here.points, there.points);
    assert_eq!(
        serde_json::to_string(&here.boundary).unwrap(),
        serde_json::to_string(&there.boundary).unwrap()
    );
    // The standard trial: 24 realizations at most (draft's cap is 10).
    assert!(here.points.iter().any(|p| p.realizations > Some(10)));
}

#[test]
fn a_psi_map_s_k_width_is_made_of_each_column_s_own_trials() {
    // Five columns: the first and the last searched knowing nothing, the
    // middle one from a prior between them, the other two from priors
    // between it and the ends (`levels`). The K-width and its interval,
    // recomputed here from the stored trials alone (each column's trials
    // told to a column that knows nothing, then `max_estimate`), are the
    // map's to the bit: the priors steer the trials, and the K-width
    // takes the columns as independent only because each is told its own.
    use crate::zwidth::psi::{max_estimate, PsiColumn, PsiModel};
    use crate::zwidth::settings::PAPER_K_STEP;
    let bs = vec![300.0, 320.0, 340.0, 360.0, 380.0];
    let spec = seed_device(bs.clone());
    let r = map_observed(&spec, None, 0).unwrap();
    // Draft's K step (PAPER_K_STEP / 0.5), the standard trial's horizon.
    let model = PsiModel::new(PAPER_K_STEP / 0.5, spec.k_max, 24);
    let marginals: Vec<_> = bs
        .iter()
        .map(|&b| {
            let history: Vec<_> = r
                .points
                .iter()
                .filter(|p| p.b == b)
                .map(|p| (model.lattice(p.k), super::outcome(p)))
                .collect();
            assert!(!history.is_empty(), "B = {b}");
            PsiColumn::from_history(&model, None, &history).marginal_of()
        })
        .collect();
    let e = max_estimate(&model, &marginals, 1.0 - spec.scene.probe.confidence);
    assert_eq!(r.k_width, e.k_mid);
    assert_eq!(r.k_width_interval, Some([e.k_lo, e.k_hi]));
    // The priors did steer: a column knowing nothing plans its first
    // trial from the log-uniform lattice alone, the same K at B = 300 and
    // 380; the three between plan theirs from their priors.
    let first_k = |b: f64| r.points.iter().find(|p| p.b == b).unwrap().k;
    assert_eq!(first_k(300.0), first_k(380.0));
    for b in [320.0, 340.0, 360.0] {
        assert_ne!(first_k(b), first_k(300.0), "B = {b}");
    }
}

#[test]
fn the_second_pass_reports_its_progress_by_the_interval_s_narrowing_on_a_log_scale() {
    use super::{narrowed, relative_width};
    // [90, 110]: half-width 10 around 100.
    assert_eq!(relative_width(90.0, 110.0), 0.1);
    assert_eq!(relative_width(0.0, 0.0), 0.0);
    // From ±8 % to ±1 %: ±4 % is one halving of three, ±2 % two.
    assert!((narrowed(0.08, 0.04, 0.01) - 1.0 / 3.0).abs() < 1e-12);
    assert!((narrowed(0.08, 0.02, 0.01) - 2.0 / 3.0).abs() < 1e-12);
    assert_eq!(narrowed(0.08, 0.08, 0.01), 0.0);
    assert_eq!(narrowed(0.08, 0.01, 0.01), 1.0);
    assert_eq!(narrowed(0.08, 0.005, 0.01), 1.0);
    // Already resolved when the pass starts, or wider than it started.
    assert_eq!(narrowed(0.01, 0.01, 0.01), 1.0);
    assert_eq!(narrowed(0.04, 0.05, 0.01), 0.0);
}

#[test]
fn psi_on_replicated_wall_hits_is_bisection() {
    // Three replicate hits a verdict: noisy (the replicates may disagree)
    // but not random (the same K gives the same verdict), so the Psi
    // search has nothing to average and the map is the bisection's, bit
    // for bit, and says so (docs/zwidth.md, "Not for the rig's wall hits
    // yet": Psi took 3x the hits there).
    let mut spec = seed_device(vec![200.0]);
    spec.scene.hit.replicates = 3;
    spec.method = Method::Time;
    spec.criterion = Criterion::Stability;
    let psi = map_observed(&spec, None, 0).unwrap();
    let bisect = bisected(&spec);
    assert!(psi.resolution.contains("bisection"), "{}", psi.resolution);
    // And it is planned as one: the bisection's cost, not Psi's budget.
    use crate::zwidth::search::validate;
    let planned = |search| {
        validate(&MapSpec {
            search,
            ..spec.clone()
        })
        .unwrap()
        .trials
    };
    assert_eq!(planned(SearchKind::Psi), planned(SearchKind::Bisect));
    // On the BLA probe it is Psi's: its budget a column.
    let probe = seed_device(vec![200.0]);
    assert_eq!(validate(&probe).unwrap().trials, super::BUDGET as u64);
    assert_eq!(psi.points, bisect.points);
    assert_eq!(
        serde_json::to_string(&psi.boundary).unwrap(),
        serde_json::to_string(&bisect.boundary).unwrap()
    );
}

#[test]
fn every_fourth_column_and_the_last_are_searched_first() {
    use super::seed_positions;
    assert_eq!(seed_positions(0), Vec::<usize>::new());
    assert_eq!(seed_positions(1), [0]);
    assert_eq!(seed_positions(3), [0, 2]);
    assert_eq!(seed_positions(5), [0, 4]);
    assert_eq!(seed_positions(6), [0, 4, 5]);
    assert_eq!(seed_positions(9), [0, 4, 8]);
}

#[test]
fn the_columns_between_come_in_two_levels_each_from_its_neighbours() {
    // Nine columns, seeds 0, 4 and 8 done: first 2 and 6 (halfway), then
    // 1, 3, 5 and 7, every one of them from a prior; the progress after
    // each level is the share of columns done.
    use super::{levels, seed_positions, Column};
    use crate::zwidth::psi::{PsiColumn, PsiModel};
    use std::collections::HashMap;
    use std::sync::Mutex;
    let model = PsiModel::new(1488.24, 1e7, 24);
    let bs: Vec<f64> = (0..9).map(|i| 10.0 * i as f64).collect();
    let seeds = seed_positions(bs.len());
    let columns: Mutex<HashMap<u64, Column>> = Mutex::default();
    // Column i's posterior: centred on lattice point 1000 + 40·i² (so
    // that the halfway point between two neighbours names them; the
    // lattice has ~5 100 points).
    let centre = |b: f64| 1000.0 + 40.0 * (b / 10.0).powi(2);
    let located = |b: f64, with_prior: bool| {
        let told = crate::zwidth::psi::Prior {
            centre: centre(b),
            sigma: 3.0,
            beta: [1.0 / 9.0; 9],
        };
        let c = Column {
            marginal: Some(PsiColumn::with_prior(&model, Some(told)).marginal_of()),
            point: Some(crate::zwidth::point::BoundaryPoint {
                b,
                k_max: b,
                k_lo: None,
                k_hi: None,
            }),
            own: None,
            prior: with_prior.then_some(crate::zwidth::psi::Prior {
                centre: 0.0,
                sigma: 1.0,
                beta: [0.0; 9],
            }),
            ..Column::default()
        };
        columns.lock().unwrap().insert(b.to_bits(), c);
    };
    for &i in &seeds {
        located(bs[i], false);
    }
    let calls: Mutex<Vec<(f64, bool)>> = Mutex::default();
    // The neighbours each column's prior lies between (index steps).
    let between = |b: f64, prior: &crate::zwidth::psi::Prior, d: f64| {
        let want = (centre(b - 10.0 * d) + centre(b + 10.0 * d)) / 2.0;
        assert!(
            (prior.centre - want).abs() <= 1.0,
            "B = {b}: {prior:?}, want {want}"
        );
    };
    let first = |b: f64, prior: Option<crate::zwidth::psi::Prior>| {
        if let Some(p) = &prior {
            // Halfway columns (2, 6) between seeds two away; the rest
            // between their next neighbours.
            between(
                b,
                p,
                if ((b / 10.0) as usize).is_multiple_of(2) {
                    2.0
                } else {
                    1.0
                },
            );
        }
        calls.lock().unwrap().push((b, prior.is_some()));
        located(b, prior.is_some());
        crate::zwidth::point::BoundaryPoint {
            b,
            k_max: b,
            k_lo: None,
            k_hi: None,
        }
    };
    let reports: Mutex<Vec<f64>> = Mutex::default();
    let boundary = levels(&model, &bs, &seeds, &columns, &first, &|f| {
        reports.lock().unwrap().push(f)
    });
    let calls = calls.into_inner().unwrap();
    let mut level1: Vec<f64> = calls[..2].iter().map(|c| c.0).collect();
    level1.sort_by(f64::total_cmp);
    assert_eq!(level1, [20.0, 60.0]);
    let mut level2: Vec<f64> = calls[2..].iter().map(|c| c.0).collect();
    level2.sort_by(f64::total_cmp);
    assert_eq!(level2, [10.0, 30.0, 50.0, 70.0]);
    assert!(calls.iter().all(|c| c.1), "{calls:?}");
    assert_eq!(reports.into_inner().unwrap(), [5.0 / 9.0, 1.0]);
    // Every column's point, in the order of bs.
    let ks: Vec<f64> = boundary.iter().map(|p| p.k_max).collect();
    assert_eq!(ks, bs);
}

#[test]
fn a_psi_map_over_the_automatic_range_takes_every_column() {
    // The automatic B range (draft: B step 29.76 N·s/m from 0 to b_max =
    // 1000, 34 columns; the seed device renders at every one, so the range
    // does not end early): every column without a gap, each with trials of
    // its own, the seeds' and the levels' alike.
    let spec = MapSpec {
        b: None,
        ..seed_device(vec![])
    };
    let r = map_observed(&spec, None, 0).unwrap();
    let step = crate::zwidth::settings::PAPER_B_STEP / 0.5;
    for (i, bp) in r.boundary.iter().enumerate() {
        assert_eq!(bp.b, step * i as f64, "column {i}");
        assert!(r.points.iter().any(|p| p.b == bp.b), "column {i}");
    }
    assert_eq!(r.boundary.len(), 34);
    // Pinned (recorded 2026-12-07; re-recorded 2026-12-07 for the first
    // pass's budget of FIRST_BUDGET trials a column and the second pass's
    // water level, the same K-width to the bit, 566 trials before; again
    // for its FIRST_REALIZATIONS, 590 before: the first pass's columns end
    // wider and the second refines more of them): the
    // map's trials and its K-width to the bit, so a change of the search's
    // rules (which columns compete for the K-width, its rounds) shows here.
    // Re-record only with a change that says why (docs/zwidth.md's figures
    // re-measured).
    assert_eq!(
        (r.points.len(), r.k_width.to_bits()),
        (681, 4690075366122498127),
        "{} trials, K-width {}",
        r.points.len(),
        r.k_width
    );
}

#[test]
fn the_water_level_shares_alpha_among_the_tails_above_it() {
    // Its definition: Σ_c min(t_c, τ) = α, the tails of columns that
    // cannot take trials (false) counted whole, and never below α/N (the
    // equal share). Each case is worked by hand in the comment beside it;
    // the first two are checked against the definition's sum too.
    let sum = |t: &[(f64, bool)], level: f64| -> f64 {
        t.iter()
            .map(|&(x, open)| if open { x.min(level) } else { x })
            .sum()
    };
    let close = |a: f64, b: f64| (a - b).abs() < 1e-12;
    use super::water_level;
    // Two large tails share what the two small ones leave: (0.05 − 0.0015)/2.
    let t = [(0.04, true), (0.001, true), (0.03, true), (0.0005, true)];
    let level = water_level(&t, 0.05);
    assert!(close(level, 0.02425), "{level}");
    assert!(close(sum(&t, level), 0.05));
    // A spent column's 0.02 is taken off first: 0.03 left, the 0.01 tail
    // stays as it is, the 0.04 one is brought to 0.02.
    let t = [(0.02, false), (0.04, true), (0.01, true)];
    assert!(close(water_level(&t, 0.05), 0.02));
    assert!(close(sum(&t, 0.02), 0.05));
    // Spent columns holding most of α: the sum would need τ = 0.001; the
    // equal share α/2 = 0.025 instead (no jump as the spent tails near α).
    let t = [(0.049, false), (0.1, true)];
    assert!(close(water_level(&t, 0.05), 0.025));
    // Equal tails above the equal share: the equal share α/N.
    let t = [(0.1, true); 4];
    assert!(close(water_level(&t, 0.05), 0.0125));
    // Tails already small: the level lies above every one (no trial); the
    // water-filling's 0.049 is above the equal share 0.025.
    let t = [(0.001, true), (0.002, true)];
    let level = water_level(&t, 0.05);
    assert!(close(level, 0.049), "{level}");
    // Spent columns over α already: the equal share over all.
    let t = [(0.06, false), (0.01, true)];
    assert!(close(water_level(&t, 0.05), 0.025));
    assert!(close(water_level(&[], 0.05), 0.05));
}

#[test]
fn a_column_takes_trials_until_its_budget_of_100() {
    // BUDGET (the resolution's "at most 100 trials a column"): a column
    // with 99 trials may take one more, with 100 none; the water level
    // counts the latter's tail as it is.
    let with = |n: usize| super::Column {
        history: vec![(0, crate::zwidth::psi::Outcome::Failed); n],
        ..super::Column::default()
    };
    assert!(with(0).may_take_trials());
    assert!(with(99).may_take_trials());
    assert!(!with(100).may_take_trials());
}
