//! Tests of `search.rs`'s automatic B range taken in order (`in_order`):
//! the order, where it stops, the progress it reports.

use super::tests::auto_b_map;
use super::*;

/// How many of the columns `started` lie at B ≥ `b`.
fn started_from(started: &std::sync::Mutex<Vec<f64>>, b: f64) -> usize {
    started.lock().unwrap().iter().filter(|&&x| x >= b).count()
}

#[test]
fn columns_are_taken_in_order_and_none_is_started_past_the_known_end() {
    // A stand-in column: K_max 1000 N/m below B = 500 N·s/m, nothing
    // from there on, so the range ends with the columns at 500 and 600
    // (7 columns; the first dropped is at 700). Column 0 is the slowest,
    // so on several threads the others finish first and wait for it.
    let spec = auto_b_map(SearchKind::Bisect);
    for threads in [1, 2, 3] {
        let o = std::sync::Arc::new(Observer::default());
        let (ev, b_auto) = map_evaluator(&spec, Some(o.clone()), 0).unwrap();
        assert_eq!(
            b_auto[..8],
            [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0]
        );
        let started = std::sync::Mutex::new(Vec::new());
        let seen = std::sync::Mutex::new(None);
        let column = |b: f64| {
            started.lock().unwrap().push(b);
            if b == 0.0 {
                std::thread::sleep(std::time::Duration::from_millis(50));
            }
            if b == 600.0 {
                // Progress when the 7th column starts: on one thread the
                // first 6 are done, of the 51 planned (planned_b: no
                // falling boundary to extrapolate yet).
                *seen.lock().unwrap() = Some(o.fraction());
            }
            let k = if b < 500.0 { 1000.0 } else { 0.0 };
            (BoundaryPoint::new(b, k), Vec::new())
        };
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        let columns = pool.install(|| in_order(&ev, &b_auto, &column));
        let bs: Vec<f64> = columns.iter().map(|(bp, _)| bp.b).collect();
        assert_eq!(
            bs,
            [0.0, 100.0, 200.0, 300.0, 400.0, 500.0, 600.0],
            "{threads} threads"
        );
        assert_eq!(o.take_dropped(), [(0, 700.0)], "{threads} threads");
        let past = started_from(&started, 700.0);
        assert!(
            past < threads,
            "{threads} threads started {past} columns past the end"
        );
        if threads == 1 {
            let f = seen.lock().unwrap().unwrap();
            assert!((f - 6.0 / 51.0).abs() < 1e-12, "progress {f}");
        }
    }
}

#[test]
fn a_pair_of_empty_columns_closed_by_its_first_stops_the_other_threads() {
    // Columns from B = 500 on render nothing but 700–2000 (a column past
    // the end may render: the range still ends at 500, 600). Column 500
    // finishes last: while it runs, the other thread goes on through
    // 600, 700, 800, …, each taking 100 ms from 800 on. When 500 ends,
    // the pair it closes with 600 stops the other thread at its next
    // column; without that, it would run on to the empty pair at 2100,
    // 2200.
    let spec = auto_b_map(SearchKind::Bisect);
    let (ev, b_auto) = map_evaluator(&spec, None, 0).unwrap();
    let started = std::sync::Mutex::new(Vec::new());
    let column = |b: f64| {
        started.lock().unwrap().push(b);
        if b == 500.0 {
            // Until the other thread is into the columns past the end
            // (at most 10 s, should that never come).
            for _ in 0..2000 {
                if started.lock().unwrap().contains(&800.0) {
                    break;
                }
                std::thread::sleep(std::time::Duration::from_millis(5));
            }
        } else if b >= 800.0 {
            std::thread::sleep(std::time::Duration::from_millis(100));
        }
        let k = if b < 500.0 || (700.0..=2000.0).contains(&b) {
            1000.0
        } else {
            0.0
        };
        (BoundaryPoint::new(b, k), Vec::new())
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build()
        .unwrap();
    let columns = pool.install(|| in_order(&ev, &b_auto, &column));
    assert_eq!(columns.len(), 7);
    let past = started_from(&started, 700.0);
    assert!(past <= 4, "{past} columns started past the end");
}
