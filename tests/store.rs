//! The store's own rules, checked through its public methods.

use zwidth::store::{Location, NewExperiment, Store};
use zwidth::zwidth::search::{Point, StoredTrial};

mod common;

/// The stores every test body runs on: a fresh SQLite file, and a fresh
/// PostgreSQL database when one is configured (`common::pg`).
async fn stores(name: &str) -> Vec<(Store, Option<tempdir::Dir>)> {
    let dir = tempdir::Dir::new(name);
    let mut v = vec![(
        Store::connect(&Location::Sqlite(dir.0.join("z.db")))
            .await
            .unwrap(),
        Some(dir),
    )];
    if let Some(url) = common::pg::fresh_database(name).await {
        v.push((
            Store::connect(&Location::Postgres(url)).await.unwrap(),
            None,
        ));
    }
    for (st, _) in &v {
        st.insert(NewExperiment {
            id: "e1",
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
    v
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
        st.add_trials("e1", &stored[..3]).await.unwrap();
        st.add_trials("e1", &stored[3..]).await.unwrap();
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
        st.add_trials("e1", std::slice::from_ref(&t)).await.unwrap();
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
        st.add_trials("e1", &[other]).await.unwrap();
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
        st.add_trials("e1", &all).await.unwrap();
        st.drop_columns("e1", 0, 2).await.unwrap();
        assert_eq!(
            st.trials("e1").await.unwrap(),
            [all[0].clone(), all[1].clone(), all[4].clone()]
        );
        assert_eq!(st.trial_count("e1").await.unwrap(), 3);
    }
}
