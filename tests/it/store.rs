//! The store's own rules, checked through its public methods.

use zwidth::store::{ExperimentState, Held, Lease, Location, NewExperiment, Store};
use zwidth::zwidth::search::{Point, StoredTrial};

/// The stores every test body runs on: a fresh SQLite file, and a fresh
/// PostgreSQL database when one is configured (`crate::common::pg`).
async fn stores(name: &str) -> Vec<(Store, Option<tempdir::Dir>)> {
    let dir = tempdir::Dir::new(name);
    let mut v = vec![(
        Store::connect(&Location::Sqlite(dir.0.join("z.db")))
            .await
            .unwrap(),
        Some(dir),
    )];
    if let Some(url) = crate::common::pg::fresh_database(name).await {
        v.push((
            Store::connect(&Location::Postgres(url)).await.unwrap(),
            None,
        ));
    }
    for (st, _) in &v {
        queue(st, "e1").await;
    }
    v
}

/// Queue an (empty) map `id` on rig "sim".
async fn queue(st: &Store, id: &str) {
    st.insert(NewExperiment {
        id,
        kind: "map",
        spec: "{}",
        priority: 0,
        key: None,
        not_before_ms: None,
        rig: "sim",
    })
    .await
    .unwrap();
}

mod tempdir {
    /// A temporary directory, removed on drop.
    pub struct Dir(pub std::path::PathBuf);
    impl Dir {
        pub fn new(name: &str) -> Self {
            let d =
                std::env::temp_dir().join(format!("zwidth-store-{name}-{}", std::process::id()));
            let _ = std::fs::remove_dir_all(&d);
            std::fs::create_dir_all(&d).unwrap();
            Dir(d)
        }
    }
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Claim e1 (the only experiment) for worker "w1".
async fn claim(st: &Store) -> Lease {
    let row = st.claim("sim", "w1", 60_000).await.unwrap().unwrap();
    assert_eq!(row.id, "e1");
    Lease::of(row.id, row.attempt)
}

fn trial(scope: u32, column: u32, index: u32, k: f64, passive: bool) -> StoredTrial {
    StoredTrial {
        scope,
        column,
        index,
        point: Point {
            k,
            b: 10.0 * column as f64,
            passive: Some(passive),
            ..Point::default()
        },
    }
}

/// Trials come back in their maps' order (scope, column, index) however
/// they were stored: parallel columns finish interleaved (issue 14).
#[tokio::test]
async fn trials_are_listed_in_map_order_not_insertion_order() {
    for (store, _dir) in stores("order").await {
        let st = &store;
        eprintln!("{}", st.backend());
        // Column 1 finished before column 0, interleaved; scope 1 first.
        let stored = [
            trial(1, 0, 0, 500.0, true),
            trial(0, 1, 0, 800.0, true),
            trial(0, 0, 0, 800.0, false),
            trial(0, 1, 1, 1600.0, false),
            trial(0, 0, 1, 400.0, true),
        ];
        let run = claim(st).await;
        st.add_trials(&run, &stored[..3], &[], (0, 0.0))
            .await
            .unwrap();
        st.add_trials(&run, &stored[3..], &[], (0, 0.0))
            .await
            .unwrap();
        let got = st.trials("e1").await.unwrap();
        let order: Vec<(u32, u32, u32)> =
            got.iter().map(|t| (t.scope, t.column, t.index)).collect();
        assert_eq!(
            order,
            [(0, 0, 0), (0, 0, 1), (0, 1, 0), (0, 1, 1), (1, 0, 0)]
        );
        // A page is a slice of that order; a scope only its own trials.
        let page = st.trials_page("e1", None, 1, 2).await.unwrap();
        assert_eq!(page, got[1..3]);
        let one = st.trials_page("e1", Some(1), 0, 10).await.unwrap();
        assert_eq!(one, [stored[0].clone()]);
    }
}

/// Issue 30, defect 9: trials that share a place come back in one order on
/// both databases (K, then B), whatever order they were stored in (SQLite
/// gave its insertion order, PostgreSQL K order).
#[tokio::test]
async fn trials_sharing_a_place_are_listed_alike_on_both_databases() {
    let mut orders = Vec::new();
    for (store, _dir) in stores("ties").await {
        let st = &store;
        // Stored in falling K: insertion order is the reverse of K order.
        let stored = [
            trial(0, 7, 3, 380_989.44, false),
            trial(0, 7, 3, 200_000.0, true),
            trial(0, 7, 3, 1_000.0, true),
        ];
        let run = claim(st).await;
        st.add_trials(&run, &stored, &[], (0, 0.0)).await.unwrap();
        let ks: Vec<f64> = st
            .trials("e1")
            .await
            .unwrap()
            .iter()
            .map(|t| t.point.k)
            .collect();
        assert_eq!(ks, [1_000.0, 200_000.0, 380_989.44], "{}", st.backend());
        let drawn: Vec<f64> = st.map_points("e1").await.unwrap()[0]
            .1
            .iter()
            .map(|p| p.k)
            .collect();
        assert_eq!(drawn, ks, "{}", st.backend());
        orders.push(ks);
    }
    orders.dedup();
    assert_eq!(orders.len(), 1);
}

/// An attached rig's result is stored before the search knows its place;
/// the search's record then places it, and a late duplicate without a
/// place changes nothing.
#[tokio::test]
async fn a_trial_stored_without_its_place_takes_it_from_the_search() {
    for (store, _dir) in stores("place").await {
        let st = &store;
        eprintln!("{}", st.backend());
        let t = trial(0, 3, 2, 900.0, true);
        let unplaced = StoredTrial {
            column: 0,
            index: 0,
            ..t.clone()
        };
        st.add_trial_unplaced("e1", &unplaced).await.unwrap();
        assert_eq!(
            st.trials("e1").await.unwrap(),
            std::slice::from_ref(&unplaced)
        );
        let run = claim(st).await;
        st.add_trials(&run, std::slice::from_ref(&t), &[], (0, 0.0))
            .await
            .unwrap();
        assert_eq!(st.trials("e1").await.unwrap(), std::slice::from_ref(&t));
        st.add_trial_unplaced("e1", &unplaced).await.unwrap();
        assert_eq!(st.trials("e1").await.unwrap(), std::slice::from_ref(&t));
        // The point itself is never replaced: the first stored verdict holds.
        let other = StoredTrial {
            point: Point {
                passive: Some(false),
                ..t.point.clone()
            },
            ..t.clone()
        };
        st.add_trials(&run, &[other], &[], (0, 0.0)).await.unwrap();
        assert_eq!(st.trials("e1").await.unwrap(), std::slice::from_ref(&t));
        // An ended experiment takes no late result (issue 30, item 12).
        assert!(st.cancel("e1").await.unwrap());
        let late = trial(0, 0, 0, 1234.0, true);
        st.add_trial_unplaced("e1", &late).await.unwrap();
        assert_eq!(st.trials("e1").await.unwrap(), [t]);
    }
}

/// Dropping a map's columns from one on deletes exactly those trials.
#[tokio::test]
async fn dropped_columns_lose_their_trials_and_nothing_else() {
    for (store, _dir) in stores("drop").await {
        let st = &store;
        eprintln!("{}", st.backend());
        let all = [
            trial(0, 0, 0, 100.0, true),
            trial(0, 1, 0, 100.0, true),
            trial(0, 2, 0, 100.0, false),
            trial(0, 3, 0, 100.0, false),
            trial(1, 2, 0, 100.0, true),
        ];
        let run = claim(st).await;
        st.add_trials(&run, &all, &[], (0, 0.0)).await.unwrap();
        // Column c is at B = 10 c: dropping from B = 20 drops columns 2, 3.
        st.add_trials(&run, &[], &[(0, 20.0)], (0, 0.0))
            .await
            .unwrap();
        assert_eq!(
            st.trials("e1").await.unwrap(),
            [all[0].clone(), all[1].clone(), all[4].clone()]
        );
        assert_eq!(st.trial_count("e1").await.unwrap(), 3);
    }
}

/// Defect 8 (issue 9): a cancel answered `cancelled` stays cancelled, even
/// when the run was finishing at that moment (the end-of-run write is
/// guarded by the state).
#[tokio::test]
async fn a_cancelled_experiment_never_ends_succeeded() {
    for (store, _dir) in stores("cancel").await {
        let st = &store;
        let run = claim(st).await;
        assert!(st.cancel("e1").await.unwrap());
        // The run ends a moment later with a result: it must not overwrite.
        let changed = st
            .finish(&run, ExperimentState::Succeeded, 10, Some("{}"), None)
            .await
            .unwrap();
        assert!(!changed, "{}", st.backend());
        let row = st.get("e1").await.unwrap().unwrap();
        assert_eq!(row.state, ExperimentState::Cancelled);
        assert!(row.result.is_none());
        // Its heartbeat says so; its own cancelled record still lands.
        assert_eq!(
            st.heartbeat(&run, 7, 0.5, 60_000).await.unwrap(),
            Held::Cancelled
        );
        assert!(st
            .finish(&run, ExperimentState::Cancelled, 7, None, None)
            .await
            .unwrap());
        assert_eq!(st.get("e1").await.unwrap().unwrap().trials_done, 7);
    }
}

/// Issue 14: a lease that expires is claimed again by the next claim
/// (attempt 2); from then on every write of attempt 1 changes nothing and
/// says the lease is lost, while attempt 2 writes as usual.
#[tokio::test]
async fn an_expired_lease_is_taken_over_and_the_old_holder_is_fenced() {
    for (store, _dir) in stores("fence").await {
        let st = &store;
        let first = st.claim("sim", "w1", 300).await.unwrap().unwrap();
        assert_eq!((first.attempt, first.worker.as_deref()), (1, Some("w1")));
        let old = Lease::of("e1", 1);
        // Held: nobody else can claim it, and its heartbeat holds it.
        assert!(st.claim("sim", "w2", 300).await.unwrap().is_none());
        assert_eq!(st.heartbeat(&old, 3, 0.1, 300).await.unwrap(), Held::Held);
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        let second = st.claim("sim", "w2", 60_000).await.unwrap().unwrap();
        assert_eq!(
            (second.id.as_str(), second.attempt, second.worker.as_deref()),
            ("e1", 2, Some("w2")),
            "{}",
            st.backend()
        );
        let new = Lease::of("e1", 2);
        // The old holder: heartbeat lost, trials refused, end refused.
        assert_eq!(st.heartbeat(&old, 99, 0.9, 300).await.unwrap(), Held::Lost);
        let e = st
            .add_trials(&old, &[trial(0, 0, 0, 1.0, true)], &[], (0, 0.0))
            .await
            .unwrap_err();
        assert_eq!(
            zwidth::store::Fault::of(&e),
            zwidth::store::Fault::Lost,
            "{e}"
        );
        assert!(!st
            .finish(&old, ExperimentState::Succeeded, 99, Some("{}"), None)
            .await
            .unwrap());
        st.interrupt(&old, 99, 0).await.unwrap();
        let row = st.get("e1").await.unwrap().unwrap();
        // (3: its last heartbeat while it held the lease; nothing since.)
        assert_eq!((row.state.as_str(), row.trials_done), ("running", 3));
        assert!(st.trials("e1").await.unwrap().is_empty());
        // The new holder writes.
        st.add_trials(&new, &[trial(0, 0, 0, 1.0, true)], &[], (0, 0.0))
            .await
            .unwrap();
        assert_eq!(
            st.heartbeat(&new, 1, 1.0, 60_000).await.unwrap(),
            Held::Held
        );
        assert!(st
            .finish(&new, ExperimentState::Succeeded, 1, Some("{}"), None)
            .await
            .unwrap());
        assert_eq!(
            st.get("e1").await.unwrap().unwrap().state,
            ExperimentState::Succeeded
        );
    }
}

/// Issue 14: a run whose worker keeps dying is not claimed forever: at its
/// `MAX_LOST`-th expired lease it fails, naming the last worker.
#[tokio::test]
async fn a_run_whose_lease_expires_max_lost_times_fails_with_the_reason() {
    for (store, _dir) in stores("lost").await {
        let st = &store;
        for n in 1..zwidth::store::MAX_LOST {
            let row = st
                .claim("sim", &format!("w{n}"), 300)
                .await
                .unwrap()
                .unwrap();
            assert_eq!(row.attempt, n);
            tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        }
        // Expired MAX_LOST - 1 times and claimed again each time; the last
        // claim (attempt MAX_LOST) expires too: failed, not claimed.
        let last = st.claim("sim", "w-last", 300).await.unwrap().unwrap();
        assert_eq!(last.attempt, zwidth::store::MAX_LOST);
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        assert!(st.claim("sim", "w-next", 300).await.unwrap().is_none());
        let row = st.get("e1").await.unwrap().unwrap();
        assert_eq!(row.state, ExperimentState::Failed, "{}", st.backend());
        let why = row.error.unwrap();
        assert!(
            why.contains("stopped answering 3 times") && why.contains("w-last"),
            "{why}"
        );
    }
}

/// Issue 14: a shut-down run (interrupted) is claimed again at once, and
/// a paused queue or a future start time keeps it waiting.
#[tokio::test]
async fn interrupted_runs_are_claimed_again_and_pause_holds_everything() {
    for (store, _dir) in stores("resume").await {
        let st = &store;
        let run = claim(st).await;
        st.interrupt(&run, 5, 0).await.unwrap();
        st.set_paused(true).await.unwrap();
        assert!(st.claim("sim", "w2", 60_000).await.unwrap().is_none());
        st.set_paused(false).await.unwrap();
        let again = st.claim("sim", "w2", 60_000).await.unwrap().unwrap();
        assert_eq!((again.attempt, again.trials_done), (2, 5));
        // Interrupted because its trials could not be stored: claimed
        // again only after the wait asked for, not at once in a loop.
        let again = Lease::of(again.id, again.attempt);
        st.interrupt(&again, 6, 60_000).await.unwrap();
        assert!(st.claim("sim", "w2", 60_000).await.unwrap().is_none());
        st.interrupt(&again, 6, 0).await.unwrap(); // not running: no change
        assert!(st.claim("sim", "w2", 60_000).await.unwrap().is_none());
        // Another rig's queue is its own.
        assert!(st.claim("bench", "w3", 60_000).await.unwrap().is_none());
    }
}

/// One step of a worker in the claim model.
#[derive(Debug, Clone)]
enum Step {
    /// Worker `w` claims the next runnable experiment (if it holds none).
    Claim(usize),
    /// `w` renews its lease.
    Beat(usize),
    /// `w` stalls past its lease (its lease ends now).
    Stall(usize),
    /// `w` stores a trial and ends its run succeeded.
    Complete(usize),
    /// `w` dies: it forgets its run without a word (and its lease runs out).
    Crash(usize),
}

fn step() -> impl proptest::strategy::Strategy<Value = Step> {
    use proptest::prelude::*;
    (0usize..3, 0u8..5).prop_map(|(w, k)| match k {
        0 => Step::Claim(w),
        1 => Step::Beat(w),
        2 => Step::Stall(w),
        3 => Step::Complete(w),
        _ => Step::Crash(w),
    })
}

/// Issue 14, the claim rules as a property: for any interleaving of
/// claims, heartbeats, stalls past the lease, completions and crashes of
/// three workers over four experiments, no experiment is completed twice
/// and none is lost: once the survivors drain the queue, each one ended
/// exactly once, succeeded, or failed after `MAX_LOST` lost leases.
#[test]
fn no_experiment_is_done_twice_or_lost_whatever_the_interleaving() {
    use proptest::prelude::*;
    let rt = tokio::runtime::Runtime::new().unwrap();
    let mut runner = proptest::test_runner::TestRunner::new(ProptestConfig {
        cases: 48,
        ..ProptestConfig::default()
    });
    let ids = ["e1", "e2", "e3", "e4"];
    runner
        .run(&proptest::collection::vec(step(), 1..40), |steps| {
            rt.block_on(async {
                let dir = tempdir::Dir::new("claims");
                let st = Store::connect(&Location::Sqlite(dir.0.join("z.db")))
                    .await
                    .unwrap();
                for id in ids {
                    queue(&st, id).await;
                }
                let mut held: [Option<Lease>; 4] = Default::default();
                let mut completed: std::collections::BTreeMap<String, u32> = Default::default();
                let complete = |st: &Store, l: Lease| {
                    let st = st.clone();
                    async move {
                        let t = trial(0, 0, 0, 1.0, true);
                        let stored = st.add_trials(&l, &[t], &[], (1, 1.0)).await;
                        let ended = st
                            .finish(&l, ExperimentState::Succeeded, 1, Some("{}"), None)
                            .await
                            .unwrap();
                        // A write is refused exactly when the end is.
                        assert_eq!(stored.is_ok(), ended, "{l:?}: {stored:?}");
                        (l.id, ended)
                    }
                };
                for s in steps {
                    match s {
                        Step::Claim(w) if held[w].is_none() => {
                            if let Some(r) =
                                st.claim("sim", &format!("w{w}"), 60_000).await.unwrap()
                            {
                                held[w] = Some(Lease::of(r.id, r.attempt));
                            }
                        }
                        Step::Beat(w) => {
                            if let Some(l) = &held[w] {
                                st.heartbeat(l, 0, 0.5, 60_000).await.unwrap();
                            }
                        }
                        Step::Stall(w) => {
                            // Its lease runs out while it is stalled; it
                            // wakes up later still believing it holds it.
                            if let Some(l) = &held[w] {
                                st.heartbeat(l, 0, 0.5, -1).await.unwrap();
                            }
                        }
                        Step::Complete(w) => {
                            if let Some(l) = held[w].take() {
                                let (id, ended) = complete(&st, l).await;
                                if ended {
                                    *completed.entry(id).or_default() += 1;
                                }
                            }
                        }
                        Step::Crash(w) => {
                            // Time passes: a dead worker's lease runs out.
                            if let Some(l) = held[w].take() {
                                st.heartbeat(&l, 0, 0.5, -1).await.unwrap();
                            }
                        }
                        Step::Claim(_) => {}
                    }
                }
                // The survivors (workers that held nothing, and a fresh
                // one) drain the queue; a held lease left over is a worker
                // that never comes back: it expires.
                for l in held.iter().flatten() {
                    st.heartbeat(l, 0, 0.5, -1).await.unwrap();
                }
                let mut rounds = 0;
                while let Some(r) = st.claim("sim", "drain", 60_000).await.unwrap() {
                    let (id, ended) = complete(&st, Lease::of(r.id, r.attempt)).await;
                    prop_assert!(ended);
                    *completed.entry(id).or_default() += 1;
                    rounds += 1;
                    prop_assert!(rounds <= ids.len());
                }
                for id in ids {
                    let row = st.get(id).await.unwrap().unwrap();
                    let n = completed.get(id).copied().unwrap_or(0);
                    match row.state.as_str() {
                        "succeeded" => prop_assert_eq!(n, 1, "{} completed {} times", id, n),
                        "failed" => {
                            prop_assert_eq!(n, 0);
                            prop_assert!(row.error.unwrap().contains("stopped answering"));
                        }
                        s => prop_assert!(false, "{} left {}", id, s),
                    }
                    // Exactly the one trial of its one completion.
                    let stored = st.trial_count(id).await.unwrap();
                    prop_assert_eq!(stored, i64::from(n));
                }
                st.close().await.unwrap();
                Ok(())
            })
        })
        .unwrap();
}

/// Issue 14, work units: planned by the experiment's holder (again:
/// nothing changes), claimed in map and column order, fenced by their own
/// attempt, failed at their `MAX_LOST`-th expiry, and never claimed once
/// their experiment stops running.
#[tokio::test]
async fn work_units_are_planned_once_claimed_in_order_and_fenced() {
    use zwidth::store::Fault;
    use zwidth::zwidth::farm::Unit;
    for (store, _dir) in stores("units").await {
        let st = &store;
        let driver = claim(st).await;
        let cols = [
            Unit::Column { column: 0, b: 0.0 },
            Unit::Column { column: 1, b: 10.0 },
        ];
        st.plan_units(&driver, 0, "{\"m\":0}", &cols).await.unwrap();
        // Planned again (a driver taken over), with one more: the first
        // two stay as they were.
        st.plan_units(&driver, 0, "{\"m\":\"other\"}", &cols[..1])
            .await
            .unwrap();
        st.plan_units(&driver, 3, "{\"m\":3}", &[Unit::Map])
            .await
            .unwrap();
        // A driver whose lease is not the experiment's plans nothing.
        let e = st
            .plan_units(&Lease::of("e1", 7), 5, "{}", &[Unit::Map])
            .await
            .unwrap_err();
        assert_eq!(Fault::of(&e), Fault::Lost, "{e}");
        let all = st.units("e1").await.unwrap();
        let shape: Vec<_> = all
            .iter()
            .map(|u| {
                (
                    u.scope,
                    u.col,
                    u.b,
                    u.spec.as_str(),
                    u.state.as_str(),
                    u.attempt,
                )
            })
            .collect();
        assert_eq!(
            shape,
            [
                (0, 0, Some(0.0), "{\"m\":0}", "queued", 0),
                (0, 1, Some(10.0), "{\"m\":0}", "queued", 0),
                (3, -1, None, "{\"m\":3}", "queued", 0),
            ],
            "{}",
            st.backend()
        );
        assert_eq!(all[1].unit(), cols[1]);
        assert_eq!(all[2].unit(), Unit::Map);
        // Claimed by map and column: column 0 (expiring at once), then 1,
        // then the whole map 3; then nothing but expired leases.
        let a = st.claim_unit("sim", "w2", 300).await.unwrap().unwrap();
        assert_eq!(
            (a.scope, a.col, a.attempt, a.worker.as_deref()),
            (0, 0, 1, Some("w2"))
        );
        let b = st.claim_unit("sim", "w3", 60_000).await.unwrap().unwrap();
        assert_eq!((b.scope, b.col), (0, 1));
        let m = st.claim_unit("sim", "w3", 60_000).await.unwrap().unwrap();
        assert_eq!((m.scope, m.col, m.state.as_str()), (3, -1, "running"));
        assert!(st.claim_unit("sim", "w4", 300).await.unwrap().is_none());
        // Other rigs' workers never see them.
        assert!(st.claim_unit("other", "w4", 300).await.unwrap().is_none());
        // The holder stores its column's trials; the heartbeat holds.
        let old = a.lease();
        st.add_trials(&old, &[trial(0, 0, 0, 100.0, true)], &[], (1, 0.0))
            .await
            .unwrap();
        assert_eq!(st.heartbeat(&old, 1, 0.0, 300).await.unwrap(), Held::Held);
        // Expired: taken over (attempt 2), the old holder fenced off.
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        let a2 = st.claim_unit("sim", "w4", 60_000).await.unwrap().unwrap();
        assert_eq!((a2.scope, a2.col, a2.attempt, a2.lost), (0, 0, 2, 1));
        assert_eq!(st.heartbeat(&old, 5, 0.0, 300).await.unwrap(), Held::Lost);
        let e = st
            .add_trials(&old, &[trial(0, 0, 1, 200.0, false)], &[], (2, 0.0))
            .await
            .unwrap_err();
        assert_eq!(Fault::of(&e), Fault::Lost, "{e}");
        assert!(!st
            .finish(&old, ExperimentState::Succeeded, 2, None, None)
            .await
            .unwrap());
        // The new holder resumes from the stored trial of its column only.
        st.add_trials(&b.lease(), &[trial(0, 1, 0, 300.0, true)], &[], (1, 0.0))
            .await
            .unwrap();
        let resumed = st.unit_trials(&a2).await.unwrap();
        assert_eq!(resumed, [trial(0, 0, 0, 100.0, true)]);
        assert_eq!(st.unit_trials(&m).await.unwrap(), []);
        // Ends: done (as `succeeded` says it), and interrupted: queued again.
        assert!(st
            .finish(
                &a2.lease(),
                ExperimentState::Succeeded,
                1,
                Some("null"),
                None
            )
            .await
            .unwrap());
        st.interrupt(&b.lease(), 1, 0).await.unwrap();
        let states: Vec<(i64, String, i64)> = st
            .units_of("e1", 0)
            .await
            .unwrap()
            .into_iter()
            .map(|u| (u.col, u.state, u.trials))
            .collect();
        assert_eq!(states, [(0, "done".into(), 1), (1, "queued".into(), 1)]);
        let b2 = st.claim_unit("sim", "w5", 60_000).await.unwrap().unwrap();
        assert_eq!((b2.col, b2.attempt), (1, 2));
        // Its driver shut down (the experiment interrupted): the unit goes
        // on, its result is what the next driver replays.
        st.interrupt(&driver, 0, 0).await.unwrap();
        assert_eq!(
            st.heartbeat(&b2.lease(), 1, 0.0, 60_000).await.unwrap(),
            Held::Held
        );
        assert_eq!(st.running_units("sim").await.unwrap().len(), 2, "b2 and m");
        // The experiment cancelled: its units are cancelled with it (their
        // holders find them gone), none is claimed again, and none shows
        // as computing.
        assert!(st.cancel("e1").await.unwrap());
        assert_eq!(
            st.heartbeat(&b2.lease(), 1, 0.0, -1).await.unwrap(),
            Held::Lost
        );
        assert!(!st
            .finish(&b2.lease(), ExperimentState::Cancelled, 1, None, None)
            .await
            .unwrap());
        assert!(st.claim_unit("sim", "w6", 300).await.unwrap().is_none());
        let states: Vec<String> = st
            .units("e1")
            .await
            .unwrap()
            .into_iter()
            .map(|u| u.state)
            .collect();
        assert_eq!(states, ["done", "cancelled", "cancelled"]);
        assert!(st.running_units("sim").await.unwrap().is_empty());
    }
}

/// Issue 14: a unit whose lease ran out is not shown as computing; a
/// cancelled unit is queued again when its running experiment plans it
/// again; when the experiment ends, its leftover units are cancelled.
#[tokio::test]
async fn units_of_an_ended_experiment_are_cancelled_and_replanning_revives_cancelled_ones() {
    use zwidth::zwidth::farm::Unit;
    for (store, _dir) in stores("unit-end").await {
        let st = &store;
        let driver = claim(st).await;
        let col = |c: u32| Unit::Column {
            column: c,
            b: 10.0 * f64::from(c),
        };
        st.plan_units(&driver, 0, "{}", &[col(0), col(1)])
            .await
            .unwrap();
        st.claim_unit("sim", "w1", 300).await.unwrap().unwrap();
        assert_eq!(st.running_units("sim").await.unwrap().len(), 1);
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        assert!(
            st.running_units("sim").await.unwrap().is_empty(),
            "its lease ran out"
        );
        // Taken over, then cancelled by its holder (what an interrupted
        // experiment's units did before), then planned again: queued.
        let u0 = st.claim_unit("sim", "w2", 60_000).await.unwrap().unwrap();
        assert_eq!((u0.col, u0.attempt), (0, 2));
        assert!(st
            .finish(&u0.lease(), ExperimentState::Cancelled, 0, None, None)
            .await
            .unwrap());
        st.plan_units(&driver, 0, "{}", &[col(0)]).await.unwrap();
        let states: Vec<(i64, String)> = st
            .units("e1")
            .await
            .unwrap()
            .into_iter()
            .map(|u| (u.col, u.state))
            .collect();
        assert_eq!(
            states,
            [(0, "queued".into()), (1, "queued".into())],
            "{}",
            st.backend()
        );
        // The experiment ends (failed by its driver): both cancelled.
        assert!(st
            .finish(
                &driver,
                ExperimentState::Failed,
                0,
                None,
                Some("map 0, column 1 failed")
            )
            .await
            .unwrap());
        let states: Vec<String> = st
            .units("e1")
            .await
            .unwrap()
            .into_iter()
            .map(|u| u.state)
            .collect();
        assert_eq!(states, ["cancelled", "cancelled"]);
    }
}

/// Issue 14: a unit whose workers keep dying fails at its `MAX_LOST`-th
/// expired lease, saying why; its driver fails the experiment with that.
#[tokio::test]
async fn a_unit_whose_lease_expires_max_lost_times_fails_with_the_reason() {
    use zwidth::zwidth::farm::Unit;
    for (store, _dir) in stores("unit-lost").await {
        let st = &store;
        let driver = claim(st).await;
        st.plan_units(&driver, 2, "{}", &[Unit::Column { column: 4, b: 40.0 }])
            .await
            .unwrap();
        for n in 1..=zwidth::store::MAX_LOST {
            let u = st
                .claim_unit("sim", &format!("w{n}"), 300)
                .await
                .unwrap()
                .unwrap();
            assert_eq!(u.attempt, n);
            tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        }
        assert!(st.claim_unit("sim", "w-next", 300).await.unwrap().is_none());
        let u = &st.units("e1").await.unwrap()[0];
        assert_eq!(u.state, "failed", "{}", st.backend());
        let why = u.error.clone().unwrap();
        assert!(
            why.contains("stopped answering 3 times") && why.contains("w3"),
            "{why}"
        );
        assert_eq!(u.describe(), "map 2, column 4 (B = 40 N·s/m)");
    }
}

/// Trials are inserted many to a statement: a trial asked twice in one
/// batch is stored once, as one-at-a-time inserts would store it (the
/// first answer, the last place), and so is one asked again in a later
/// batch.
#[tokio::test]
async fn a_trial_repeated_in_one_batch_is_stored_once_with_its_last_place() {
    for (store, _dir) in stores("repeats").await {
        let st = &store;
        let run = claim(st).await;
        let first = trial(0, 1, 0, 700.0, true);
        let again = StoredTrial {
            index: 4,
            point: Point {
                passive: Some(false),
                ..first.point.clone()
            },
            ..first.clone()
        };
        let other = trial(0, 1, 1, 900.0, false);
        st.add_trials(
            &run,
            &[first.clone(), other.clone(), again.clone()],
            &[],
            (3, 0.0),
        )
        .await
        .unwrap();
        let got = st.trials("e1").await.unwrap();
        let want_first = StoredTrial {
            index: 4,
            ..first.clone()
        };
        assert_eq!(got, [other.clone(), want_first.clone()], "{}", st.backend());
        // The same in a later batch: its place again, its point kept.
        let later = StoredTrial {
            index: 9,
            ..again.clone()
        };
        st.add_trials(&run, &[later], &[], (4, 0.0)).await.unwrap();
        let got = st.trials("e1").await.unwrap();
        assert_eq!(got, [other, StoredTrial { index: 9, ..first }]);
    }
}

/// Issue 14: an idempotency key is one `INSERT … ON CONFLICT`: eight
/// submissions with one key at once (as from several API processes, each
/// with its own connection pool) store one experiment; the others get it
/// back as an earlier submission, or as a reused key when their request
/// differs.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn concurrent_submissions_with_one_key_store_one_experiment() {
    use zwidth::store::Inserted;
    let dir = tempdir::Dir::new("idem");
    let mut places = vec![Location::Sqlite(dir.0.join("z.db"))];
    if let Some(url) = crate::common::pg::fresh_database("idem").await {
        places.push(Location::Postgres(url));
    }
    for at in places {
        let mut tasks = Vec::new();
        for i in 0..8 {
            // Each its own store (pool), as separate processes have.
            let st = Store::connect(&at).await.unwrap();
            tasks.push(tokio::spawn(async move {
                let spec = if i == 7 { "{\"other\":1}" } else { "{}" };
                let r = st
                    .insert(NewExperiment {
                        id: &format!("e-{i}"),
                        kind: "map",
                        spec,
                        priority: 0,
                        key: Some("the-key"),
                        not_before_ms: None,
                        rig: "sim",
                    })
                    .await
                    .unwrap();
                (i, r)
            }));
        }
        let mut new = Vec::new();
        let (mut earlier, mut reused) = (0, 0);
        for t in tasks {
            match t.await.unwrap() {
                (i, Inserted::New(row)) => new.push((i, row.id)),
                (_, Inserted::Earlier(_)) => earlier += 1,
                (_, Inserted::KeyReused(_)) => reused += 1,
            }
        }
        assert_eq!(new.len(), 1, "{at}: {new:?}");
        let (winner, id) = &new[0];
        assert_eq!(id, &format!("e-{winner}"));
        // The one that differs is told its key was reused, unless it won.
        assert_eq!(reused, usize::from(*winner != 7), "{at}");
        assert_eq!(earlier + reused, 7);
        let st = Store::connect(&at).await.unwrap();
        let mut stored = Vec::new();
        for i in 0..8 {
            if st.get(&format!("e-{i}")).await.unwrap().is_some() {
                stored.push(i);
            }
        }
        assert_eq!(stored, [*winner], "{at}");
    }
}

/// Everything stored about experiment `e1`: its row, trials, evaluations
/// and units, as text (a fenced write that changed any of it shows).
async fn snapshot(st: &Store) -> String {
    format!(
        "{:?}\n{:?}\n{:?}\n{:?}",
        st.get("e1").await.unwrap(),
        st.trials("e1").await.unwrap(),
        st.evaluations("e1").await.unwrap(),
        st.units("e1").await.unwrap()
    )
}

/// Issue 31: every fenced statement of an experiment's lease, performed
/// with the attempt a takeover made stale, changes nothing stored
/// (heartbeat, trials, evaluations, finish in each end state, interrupt,
/// planning units); each says the lease is lost where it can.
#[tokio::test]
async fn every_fenced_experiment_write_of_a_stale_attempt_changes_nothing() {
    use zwidth::store::Fault;
    use zwidth::zwidth::farm::Unit;
    use zwidth::zwidth::search::StoredEvaluation;
    for (store, _dir) in stores("fence-all").await {
        let st = &store;
        st.claim("sim", "w1", 300).await.unwrap().unwrap();
        let old = Lease::of("e1", 1);
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        let new = st.claim("sim", "w2", 60_000).await.unwrap().unwrap();
        assert_eq!(new.attempt, 2, "{}", st.backend());
        let new = Lease::of("e1", 2);
        // The new holder's own writes, so there is something to change.
        let eval = |key: &str| StoredEvaluation {
            key: key.into(),
            record: serde_json::json!({"k_width": 1.0}),
        };
        st.add_trials(&new, &[trial(0, 0, 0, 1.0, true)], &[], (1, 0.25))
            .await
            .unwrap();
        st.add_evaluations(&new, &[eval("a")], Some(serde_json::json!({"best": 1})))
            .await
            .unwrap();
        st.plan_units(&new, 0, "{}", &[Unit::Column { column: 0, b: 0.0 }])
            .await
            .unwrap();
        assert_eq!(
            st.heartbeat(&new, 1, 0.25, 60_000).await.unwrap(),
            Held::Held
        );
        let before = snapshot(st).await;
        let lost = |e: sqlx::Error| assert_eq!(Fault::of(&e), Fault::Lost, "{e}");
        assert_eq!(
            st.heartbeat(&old, 9, 0.9, 60_000).await.unwrap(),
            Held::Lost
        );
        lost(
            st.add_trials(&old, &[trial(0, 1, 0, 2.0, false)], &[], (9, 0.9))
                .await
                .unwrap_err(),
        );
        lost(
            st.add_evaluations(&old, &[eval("b")], Some(serde_json::json!({"best": 2})))
                .await
                .unwrap_err(),
        );
        lost(
            st.plan_units(&old, 1, "{}", &[Unit::Map])
                .await
                .unwrap_err(),
        );
        for end in [
            ExperimentState::Succeeded,
            ExperimentState::Failed,
            ExperimentState::Cancelled,
        ] {
            assert!(
                !st.finish(&old, end, 9, Some("{}"), Some("stale"))
                    .await
                    .unwrap(),
                "{end}"
            );
        }
        st.interrupt(&old, 9, 0).await.unwrap();
        st.interrupt(&old, 9, 5_000).await.unwrap();
        assert_eq!(snapshot(st).await, before, "{}", st.backend());
        // The holder's end is taken; the stale one's after it changes nothing.
        assert!(st
            .finish(&new, ExperimentState::Succeeded, 1, Some("{}"), None)
            .await
            .unwrap());
        let ended = snapshot(st).await;
        for end in [
            ExperimentState::Succeeded,
            ExperimentState::Failed,
            ExperimentState::Cancelled,
        ] {
            assert!(!st.finish(&old, end, 9, None, Some("stale")).await.unwrap());
        }
        st.interrupt(&old, 9, 0).await.unwrap();
        assert_eq!(
            st.heartbeat(&old, 9, 0.9, 60_000).await.unwrap(),
            Held::Lost
        );
        assert_eq!(snapshot(st).await, ended, "{}", st.backend());
    }
}

/// Issue 31: the same for every fenced statement of a work unit's lease
/// (heartbeat, trials, finish in each end state, interrupt), after the
/// unit was taken over by a second claim.
#[tokio::test]
async fn every_fenced_unit_write_of_a_stale_attempt_changes_nothing() {
    use zwidth::store::Fault;
    use zwidth::zwidth::farm::Unit;
    for (store, _dir) in stores("fence-unit").await {
        let st = &store;
        let driver = claim(st).await;
        st.plan_units(
            &driver,
            0,
            "{}",
            &[
                Unit::Column { column: 0, b: 0.0 },
                Unit::Column { column: 1, b: 10.0 },
            ],
        )
        .await
        .unwrap();
        let a = st.claim_unit("sim", "w2", 300).await.unwrap().unwrap();
        tokio::time::sleep(std::time::Duration::from_millis(400)).await;
        let a2 = st.claim_unit("sim", "w3", 60_000).await.unwrap().unwrap();
        assert_eq!((a2.col, a2.attempt), (a.col, 2), "{}", st.backend());
        let (old, new) = (a.lease(), a2.lease());
        st.add_trials(&new, &[trial(0, 0, 0, 100.0, true)], &[], (1, 0.0))
            .await
            .unwrap();
        assert_eq!(
            st.heartbeat(&new, 1, 0.0, 60_000).await.unwrap(),
            Held::Held
        );
        let before = snapshot(st).await;
        assert_eq!(
            st.heartbeat(&old, 9, 0.0, 60_000).await.unwrap(),
            Held::Lost
        );
        let e = st
            .add_trials(&old, &[trial(0, 0, 1, 200.0, false)], &[], (9, 0.0))
            .await
            .unwrap_err();
        assert_eq!(Fault::of(&e), Fault::Lost, "{e}");
        for end in [
            ExperimentState::Succeeded,
            ExperimentState::Failed,
            ExperimentState::Cancelled,
        ] {
            assert!(
                !st.finish(&old, end, 9, Some("null"), Some("stale"))
                    .await
                    .unwrap(),
                "{end}"
            );
        }
        st.interrupt(&old, 9, 0).await.unwrap();
        st.interrupt(&old, 9, 5_000).await.unwrap();
        assert_eq!(snapshot(st).await, before, "{}", st.backend());
        // The holder ends it; the stale writes after that change nothing.
        assert!(st
            .finish(&new, ExperimentState::Succeeded, 1, Some("null"), None)
            .await
            .unwrap());
        let ended = snapshot(st).await;
        assert_eq!(
            st.heartbeat(&old, 9, 0.0, 60_000).await.unwrap(),
            Held::Lost
        );
        assert!(!st
            .finish(&old, ExperimentState::Failed, 9, None, Some("stale"))
            .await
            .unwrap());
        st.interrupt(&old, 9, 0).await.unwrap();
        assert_eq!(snapshot(st).await, ended, "{}", st.backend());
    }
}

/// The workers' registry behind `/metrics` and the queue page: a worker is
/// listed with what it said last (rigs, run, rate; a rate that is not a
/// finite non-negative number is stored as 0), updated in place, and gone
/// when it says goodbye or is not seen for longer than asked. (A mutant
/// that made `worker_seen` write nothing passed the store's tests.)
#[tokio::test]
async fn the_workers_registry_keeps_what_each_worker_says() {
    for (store, _dir) in stores("workers").await {
        let st = &store;
        let row = |id: &str| {
            let id = id.to_string();
            async move {
                st.workers(60_000)
                    .await
                    .unwrap()
                    .into_iter()
                    .find(|w| w.id == id)
                    .map(|w| (w.rigs, w.running, w.trials_per_s))
            }
        };
        assert!(st.workers(60_000).await.unwrap().is_empty());
        st.worker_seen("w1", "sim:2", Some("e1"), 12.5)
            .await
            .unwrap();
        st.worker_seen("w2", "lab", None, f64::NAN).await.unwrap();
        assert_eq!(
            row("w1").await,
            Some(("sim:2".into(), Some("e1".into()), 12.5))
        );
        assert_eq!(row("w2").await, Some(("lab".into(), None, 0.0)));
        let started = st.workers(60_000).await.unwrap()[0].started_ms;
        // Seen again: the run and the rate change, the start does not.
        tokio::time::sleep(std::time::Duration::from_millis(20)).await;
        st.worker_seen("w1", "sim:2", None, -3.0).await.unwrap();
        let all = st.workers(60_000).await.unwrap();
        assert_eq!(all.len(), 2, "{}", st.backend());
        let w1 = all.iter().find(|w| w.id == "w1").unwrap();
        assert_eq!((w1.running.as_deref(), w1.trials_per_s), (None, 0.0));
        assert_eq!(w1.started_ms, started);
        assert!(
            w1.seen_ms > w1.started_ms,
            "{} {}",
            w1.seen_ms,
            w1.started_ms
        );
        // Goodbye, and pruning those unseen for longer than 10 ms.
        st.worker_gone("w2").await.unwrap();
        assert_eq!(row("w2").await, None);
        tokio::time::sleep(std::time::Duration::from_millis(50)).await;
        assert!(st.workers(10).await.unwrap().is_empty());
        st.prune_workers(10).await.unwrap();
        assert!(st.workers(60_000).await.unwrap().is_empty());
    }
}

/// `zwidth bench` purges its own rig: every experiment of that rig and
/// its trials go, nothing of another rig's. (A mutant that purged nothing
/// passed the store's tests.)
#[tokio::test]
async fn purging_a_rig_removes_its_experiments_and_trials_only() {
    for (store, _dir) in stores("purge").await {
        let st = &store;
        st.insert(NewExperiment::queued("b1", "map", "{}", "bench-1"))
            .await
            .unwrap();
        let run = claim(st).await;
        st.add_trials(&run, &[trial(0, 0, 0, 100.0, true)], &[], (1, 0.0))
            .await
            .unwrap();
        let bench = st.claim("bench-1", "w1", 60_000).await.unwrap().unwrap();
        st.add_trials(
            &Lease::of(bench.id, bench.attempt),
            &[trial(0, 0, 0, 5.0, false)],
            &[],
            (1, 0.0),
        )
        .await
        .unwrap();
        st.purge_rig("bench-1").await.unwrap();
        assert!(st.get("b1").await.unwrap().is_none(), "{}", st.backend());
        assert!(st.trials("b1").await.unwrap().is_empty());
        assert!(st.get("e1").await.unwrap().is_some());
        assert_eq!(
            st.trials("e1").await.unwrap(),
            [trial(0, 0, 0, 100.0, true)]
        );
    }
}

/// Planning units and ending one wake this process's waiters at once (and
/// on PostgreSQL another process's, through NOTIFY): idle workers do not
/// wait for their next poll. Bound: 5 s (a poll is 1 s+; the wake-up is
/// milliseconds); the waiters are registered before the write.
#[tokio::test]
async fn planned_and_ended_units_wake_the_waiting_workers() {
    use zwidth::zwidth::farm::Unit;
    let bound = std::time::Duration::from_secs(5);
    for (store, _dir) in stores("wake").await {
        let st = &store;
        let driver = claim(st).await;
        let queued = st.wakeups().queued.notified();
        tokio::pin!(queued);
        queued.as_mut().enable();
        let mut ended = st.wakeups().ended.subscribe();
        st.plan_units(&driver, 0, "{}", &[Unit::Map]).await.unwrap();
        tokio::time::timeout(bound, queued)
            .await
            .unwrap_or_else(|_| panic!("no wake-up for planned units ({})", st.backend()));
        let u = st.claim_unit("sim", "w2", 60_000).await.unwrap().unwrap();
        assert!(st
            .finish(&u.lease(), ExperimentState::Succeeded, 0, None, None)
            .await
            .unwrap());
        let who = tokio::time::timeout(bound, ended.recv())
            .await
            .expect("no wake-up for an ended unit")
            .unwrap();
        assert_eq!(who, "e1");
    }
    // Across processes: another store on the same PostgreSQL database,
    // listening, is woken by this one's writes.
    let Some(url) = crate::common::pg::fresh_database("wake_other").await else {
        return;
    };
    let (a, b) = (
        Store::connect(&Location::Postgres(url.clone()))
            .await
            .unwrap(),
        Store::connect(&Location::Postgres(url)).await.unwrap(),
    );
    b.listen();
    queue(&a, "e1").await;
    let driver = claim(&a).await;
    // The listener connects in the background: plan until it hears one.
    let mut ended = b.wakeups().ended.subscribe();
    let deadline = std::time::Instant::now() + bound;
    let mut scope = 0;
    loop {
        let queued = b.wakeups().queued.notified();
        tokio::pin!(queued);
        queued.as_mut().enable();
        a.plan_units(&driver, scope, "{}", &[Unit::Map])
            .await
            .unwrap();
        if tokio::time::timeout(std::time::Duration::from_millis(200), queued)
            .await
            .is_ok()
        {
            break;
        }
        assert!(
            std::time::Instant::now() < deadline,
            "the other process never heard units planned"
        );
        scope += 1;
    }
    let u = a.claim_unit("sim", "w2", 60_000).await.unwrap().unwrap();
    assert!(a
        .finish(&u.lease(), ExperimentState::Succeeded, 0, None, None)
        .await
        .unwrap());
    let who = tokio::time::timeout(bound, ended.recv())
        .await
        .expect("the other process never heard a unit end")
        .unwrap();
    assert_eq!(who, "e1");
}

/// PostgreSQL over TLS (issue 45 item 3): a store URL with
/// `sslmode=verify-full&sslrootcert=CA` connects, migrates and works, on a
/// session the server itself reports as TLS (`pg_stat_ssl`); without the
/// CA the server's certificate is refused, and without TLS the server's
/// `hostssl`-only rules refuse the session.
#[tokio::test]
async fn postgres_over_tls_verifies_the_server() {
    use sqlx::Connection;
    let Some(tls) = crate::common::pg::tls_url() else {
        return;
    };
    let fresh = crate::common::pg::fresh_database("tls").await.unwrap();
    let db = fresh.split('?').next().unwrap().rsplit('/').next().unwrap();
    let url = crate::common::pg::with_database(&tls, db);
    let st = Store::connect(&Location::Postgres(url.clone()))
        .await
        .unwrap();
    queue(&st, "e1").await;
    assert_eq!(
        st.claim("sim", "w1", 60_000).await.unwrap().unwrap().id,
        "e1"
    );
    let mut c = sqlx::PgConnection::connect(&url).await.unwrap();
    let (ssl, version): (bool, Option<String>) =
        sqlx::query_as("SELECT ssl, version FROM pg_stat_ssl WHERE pid = pg_backend_pid()")
            .fetch_one(&mut c)
            .await
            .unwrap();
    assert!(ssl, "the server says the session is not TLS");
    assert!(version.is_some_and(|v| v.starts_with("TLSv1.")));
    // The CA left out: the certificate is not trusted (the system's roots
    // do not hold the throwaway CA).
    let no_ca = url.split("&sslrootcert=").next().unwrap().to_string();
    let e = sqlx::PgConnection::connect(&no_ca).await.unwrap_err();
    assert!(e.to_string().to_lowercase().contains("certificate"), "{e}");
    // No TLS: refused by the server (no `host` rule for plain TCP).
    let plain = url.replace("sslmode=verify-full", "sslmode=disable");
    let e = sqlx::PgConnection::connect(&plain).await.unwrap_err();
    assert!(e.to_string().contains("pg_hba.conf"), "{e}");
}
