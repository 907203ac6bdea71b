//! A tune on a noisy scene (the 2018 paper's device: friction and 1 µm
//! quantization, the BLA verdict): finalists are replicated with other
//! probe seeds and scored by the mean, each replicate equal to a plain map.

use std::collections::BTreeMap;

use zwidth_core::tune::{Bounds, Metric, Objective, SolverKind, TuneResult, TuneSpec};
use zwidth_core::zwidth::bla::replicate_seed;
use zwidth_core::zwidth::scene::SceneSpec;
use zwidth_core::zwidth::search::map;
use zwidth_core::zwidth::settings::{Accuracy, Criterion, MapSpec, Method, Preset, SearchKind};
use zwidth_core::zwidth::sweep::Scale;

const SEED_2018: &str = include_str!("../../../../examples/seed_2018.json");

fn seed_scene(cutoff: f64) -> SceneSpec {
    let mut s = SceneSpec::from_json(SEED_2018).unwrap();
    s.estimator = serde_json::from_str(&format!(
        r#"{{"kind":"butterworth","cutoff_hz":{cutoff},"order":2}}"#
    ))
    .unwrap();
    s
}

/// One damping column, draft: a few seconds per map in a test build.
fn spec(replicates: usize) -> TuneSpec {
    TuneSpec {
        scene: seed_scene(499.0),
        params: BTreeMap::from([(
            "cutoff_hz".to_string(),
            Bounds {
                min: 300.0,
                max: 499.0,
                scale: Scale::Linear,
                step: Some(1.0),
            },
        )]),
        objective: Objective::Single(Metric::KWidth),
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::Bisect,
        accuracy: Accuracy::Preset(Preset::Draft),
        final_accuracy: Accuracy::Preset(Preset::Draft),
        finalists: 2,
        replicates,
        solver: SolverKind::Grid,
        seed: 0,
        max_evaluations: 3,
        constraint: None,
        b: Some(vec![20.0]),
        b_max: 1000.0,
        k_max: 1e7,
    }
}

/// K-width of a plain map of the seed device at `cutoff` with `seed`.
fn plain(cutoff: f64, seed: u64) -> zwidth_core::zwidth::search::MapResult {
    let mut scene = seed_scene(cutoff);
    scene.probe.seed = seed;
    map(&MapSpec {
        scene,
        method: Method::Auto,
        criterion: Criterion::Impedance,
        search: SearchKind::Bisect,
        accuracy: Accuracy::Preset(Preset::Draft),
        b: Some(vec![20.0]),
        b_max: 1000.0,
        k_max: 1e7,
        prior: None,
    })
    .unwrap()
}

/// Student t 97.5 % quantiles (NIST/SEMATECH e-Handbook §1.3.6.7.2).
fn t975(dof: usize) -> f64 {
    match dof {
        1 => 12.706,
        2 => 4.303,
        3 => 3.182,
        4 => 2.776,
        5 => 2.571,
        _ => panic!("no table entry for {dof} degrees of freedom"),
    }
}

#[test]
fn noisy_finalists_are_the_mean_of_replicate_maps_with_a_t_interval() {
    let r: TuneResult = spec(2).validate().unwrap().run(None).unwrap();
    let c = r.coarse_to_fine.as_ref().expect("finalists");
    assert_eq!(c.finalists.len(), 2);
    for f in &c.finalists {
        let cutoff = f.params["cutoff_hz"];
        let reps: Vec<_> = r
            .history
            .iter()
            .filter(|e| e.phase == "final" && e.params == f.params)
            .collect();
        let n = reps.len();
        assert_eq!(n, f.replicates);
        assert!(
            (2..=4).contains(&n),
            "{n} replicates, between replicates and twice that"
        );
        let mut scores = Vec::new();
        for (i, e) in reps.iter().enumerate() {
            assert_eq!(e.replicate, i, "replicates in order");
            // Each replicate is the plain map with the derived probe seed.
            let m = plain(cutoff, replicate_seed(1, i));
            assert_eq!(e.metrics.k_width, m.k_width, "{cutoff} Hz replicate {i}");
            let [lo, hi] = m.k_width_interval.expect("a noisy map has intervals");
            assert_eq!(e.metrics.k_width_interval, Some([lo, hi]));
            // Scored by the map's K-width; the interval's upper end is a
            // verdict well below the 1e7 N/m range here.
            assert!(lo <= m.k_width && m.k_width <= hi && hi < 1e6, "{lo} {hi}");
            assert_eq!(e.score, m.k_width);
            scores.push(e.score);
        }
        // The final score: the mean; its interval: mean ± t·s/√n, widened
        // to the replicates' mean interval.
        let mean = scores.iter().sum::<f64>() / n as f64;
        assert!((f.final_score - mean).abs() <= 1e-9 * mean);
        let s = (scores.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1) as f64).sqrt();
        let half = t975(n - 1) * s / (n as f64).sqrt();
        let lo = reps
            .iter()
            .map(|e| e.metrics.k_width_interval.unwrap()[0])
            .sum::<f64>()
            / n as f64;
        let hi = reps
            .iter()
            .map(|e| e.metrics.k_width_interval.unwrap()[1])
            .sum::<f64>()
            / n as f64;
        let [flo, fhi] = f.final_interval.expect("an interval");
        // The t table has 4 digits: 1e-3 relative on the half-width.
        assert!(
            (flo - lo.min(mean - half)).abs() <= 1e-3 * half.max(1.0),
            "{flo}"
        );
        assert!(
            (fhi - hi.max(mean + half)).abs() <= 1e-3 * half.max(1.0),
            "{fhi}"
        );
    }
    // The ranking is decided, or every overlapping finalist has twice the
    // minimum of replicates.
    let best = c.finalists.iter().find(|f| f.final_rank == 0).unwrap();
    let [blo, bhi] = best.final_interval.unwrap();
    for f in &c.finalists {
        let [lo, hi] = f.final_interval.unwrap();
        if f.final_rank != 0 && lo <= bhi && blo <= hi {
            assert_eq!(f.replicates, 4);
        }
    }
    // The best's measures are its replicates' means.
    let best_reps: Vec<_> = r
        .history
        .iter()
        .filter(|e| e.phase == "final" && e.params == best.params)
        .collect();
    let mean_of = |f: &dyn Fn(&zwidth_core::tune::Evaluation) -> f64| {
        best_reps.iter().map(|e| f(e)).sum::<f64>() / best_reps.len() as f64
    };
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-9 * b.abs().max(1.0);
    let k = mean_of(&|e| e.metrics.k_width);
    let fid = mean_of(&|e| e.metrics.max_fidelity_error.unwrap());
    assert!(close(r.best.objectives["k_width"].unwrap(), k));
    assert!(close(r.best.objectives["max_fidelity_error"].unwrap(), fid));
    // Counts: maps computed and cache hits, over the search and every replicate.
    assert_eq!(
        r.evaluations,
        r.history.iter().filter(|e| !e.cached).count()
    );
    assert_eq!(r.cache_hits, r.history.iter().filter(|e| e.cached).count());
    assert_eq!(r.best.replicates, best.replicates);
    assert_eq!(r.best.score, best.final_score);
    assert_eq!(r.best.interval, best.final_interval);

    // What a user reads: the history's JSON names the replicate of final
    // maps only (0 is left out); the CSV has one row per evaluation with
    // the replicate and the K-width interval; the table a line per
    // finalist with its map count.
    let finals: Vec<_> = r.history.iter().filter(|e| e.phase == "final").collect();
    for e in &r.history {
        let v = serde_json::to_value(e).unwrap();
        assert_eq!(v.get("replicate").is_some(), e.replicate > 0, "{v}");
    }
    assert!(finals.iter().any(|e| e.replicate > 0));
    let csv = r.csv();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    assert_eq!(
        &header[header.len() - 3..],
        ["replicate", "k_width_lo", "k_width_hi"]
    );
    let rows: Vec<Vec<&str>> = lines.map(|l| l.split(',').collect()).collect();
    assert_eq!(rows.len(), r.history.len());
    for (row, e) in rows.iter().zip(&r.history) {
        assert_eq!(row.len(), header.len());
        assert_eq!(row[header.len() - 3], e.replicate.to_string());
        let [lo, hi] = e.metrics.k_width_interval.unwrap();
        assert_eq!(row[header.len() - 2], lo.to_string());
        assert_eq!(row[header.len() - 1], hi.to_string());
    }
    let table = r.table();
    for f in &c.finalists {
        let line = format!("cutoff_hz = {:.6}", f.params["cutoff_hz"]);
        let l = table
            .lines()
            .find(|l| l.contains("finalist") && l.contains(&line))
            .unwrap_or_else(|| panic!("{line} in {table}"));
        assert!(l.ends_with(&format!("{} map(s)", f.replicates)), "{l}");
    }
    assert!(
        table.contains(&format!("mean of {} map(s)", r.best.replicates)),
        "{table}"
    );
}

#[test]
fn the_cost_counts_twice_the_replicates_per_finalist_on_noisy_scenes_only() {
    // 3 search maps at draft + 2 finalists × up to 2 × 3 replicates.
    let noisy = spec(3).validate().unwrap();
    assert_eq!(noisy.cost.maps, 3 + 2 * 2 * 3);
    // The same tune on the device without friction and quantization: one
    // map per finalist (exact verdicts, nothing to replicate).
    let mut exact = spec(3);
    exact.scene.device.coulomb = 0.0;
    exact.scene.device.quantization = 0.0;
    assert_eq!(exact.validate().unwrap().cost.maps, 3 + 2);
}

#[test]
fn one_replicate_is_one_map_and_the_count_is_checked() {
    let r = spec(1).validate().unwrap().run(None).unwrap();
    let finals: Vec<_> = r.history.iter().filter(|e| e.phase == "final").collect();
    assert_eq!(finals.len(), 2);
    assert!(finals.iter().all(|e| e.replicate == 0));
    // Left out, a request gets the documented default (docs/tuning.md: 3).
    let json = serde_json::json!({
        "scene": serde_json::from_str::<serde_json::Value>(SEED_2018).unwrap(),
        "params": {"cutoff_hz": {"min": 300, "max": 499}},
        "objective": "k_width"
    });
    let parsed: TuneSpec = serde_json::from_value(json).unwrap();
    assert_eq!(parsed.replicates, 3);
    for n in [0, 21] {
        let e = spec(n).validate().err().expect("refused");
        assert_eq!(e.field, "replicates");
        assert_eq!(e.value, n.to_string());
        assert!(e.allowed.contains("1 to 20"), "{}", e.allowed);
    }
}

#[test]
fn stored_keys_name_replicates_after_the_first_and_keep_the_old_form() {
    // A tune stored before replicates existed keyed its evaluations
    // "<accuracy>|<name>=<f64 bits>"; replicate 0 keeps that key (so those
    // tunes resume from their stored maps), later ones add "|r<n>".
    let o = std::sync::Arc::new(zwidth_core::zwidth::search::Observer::default());
    let r = spec(2).validate().unwrap().run(Some(o.clone())).unwrap();
    let keys: Vec<String> = o
        .take_new_evaluations()
        .into_iter()
        .map(|e| e.key)
        .collect();
    // Progress: each computed map reports its scope done, out of the
    // search budget plus twice the replicates per finalist (3 + 2·2·2).
    let computed = r.history.iter().filter(|e| !e.cached).count();
    assert!(
        (o.fraction() - computed as f64 / 11.0).abs() < 1e-12,
        "{}",
        o.fraction()
    );
    for e in r.history.iter().filter(|e| !e.cached) {
        let bits = format!("cutoff_hz={:016x}", e.params["cutoff_hz"].to_bits());
        let want = match e.replicate {
            0 => format!("draft|{bits}"),
            n => format!("draft|{bits}|r{n}"),
        };
        assert!(keys.contains(&want), "{want} in {keys:?}");
    }
}

#[test]
fn b_width_objectives_replicate_and_unbounded_intervals_do_not() {
    // B-width has an interval on a noisy scene: replicated like K-width.
    let mut b = spec(2);
    b.objective = Objective::Single(Metric::BWidth);
    let r = b.validate().unwrap().run(None).unwrap();
    let c = r.coarse_to_fine.unwrap();
    assert!(c
        .finalists
        .iter()
        .all(|f| f.replicates >= 2 && f.final_interval.is_some()));
    // K up to 30 000 N/m only (the boundary at B = 20 lies far above):
    // nothing is decided not passive, so every
    // K-width interval reaches k_max — the search's range, not a verdict:
    // no interval to rank by, one map per finalist.
    let mut k = spec(3);
    k.k_max = 30_000.0;
    let r = k.validate().unwrap().run(None).unwrap();
    let finals: Vec<_> = r.history.iter().filter(|e| e.phase == "final").collect();
    let ivs: Vec<_> = finals
        .iter()
        .map(|e| (e.metrics.k_width, e.metrics.k_width_interval))
        .collect();
    assert!(
        finals.iter().all(|e| e
            .metrics
            .k_width_interval
            .is_some_and(|[_, hi]| hi == 30_000.0)),
        "{ivs:?}"
    );
    let c = r.coarse_to_fine.unwrap();
    assert!(c
        .finalists
        .iter()
        .all(|f| f.replicates == 1 && f.final_interval.is_none()));
}
