//! A map's columns of B taken in order: the automatic B range run on the
//! threads here (`in_order`) or in a farm's batches (`farmed_batches`), where
//! it ends (two surely empty columns in a row), the columns' units for a
//! farm, and the progress reported. Used by the bisection (`search.rs`) and
//! the Psi search (`psi_search.rs`).

use rayon::prelude::*;

use super::classify::Classifier;
use super::farm::Unit;
use super::point::{BoundaryPoint, Point};
use super::settings::MapSpec;

/// How many B values an automatic search will likely visit: until the
/// boundary, extrapolated linearly from its last two points, reaches K = 0
/// (plus the two empty ones that end it); at most `n_auto`.
pub(super) fn planned_b(boundary: &[BoundaryPoint], n_auto: usize, b_step: f64) -> usize {
    let nz: Vec<&BoundaryPoint> = boundary.iter().filter(|p| p.k_max > 0.0).collect();
    let done = boundary.len();
    if let [.., p, q] = nz.as_slice() {
        if q.k_max < p.k_max && q.b > p.b {
            let b_end = q.b + q.k_max * (q.b - p.b) / (p.k_max - q.k_max);
            let n = (b_end / b_step).ceil() as usize + 3;
            return n.clamp(done + 1, n_auto.max(done + 1));
        }
    }
    n_auto.max(done + 1)
}

/// The units of the columns at `bs` (each B's place in the map's list).
pub(super) fn column_units(ev: &Classifier, bs: &[f64]) -> Vec<Unit> {
    bs.iter()
        .map(|&b| Unit::Column {
            column: ev.columns.get(&b.to_bits()).copied().unwrap_or(0),
            b,
        })
        .collect()
}

/// One column of a bisection map (`bisect_column` with its spec bound).
pub(super) type ColumnOf<'a> = dyn Fn(f64) -> (BoundaryPoint, Vec<Point>) + Sync + 'a;

/// The automatic B range computed here: each thread takes the next column
/// in B order as soon as it is free, so none waits for a batch's slowest
/// column. No column is started past a pair of surely empty columns in a
/// row once both are done (the range ends there or before); those started
/// past the range's end are dropped, trials and all, as a batch's are, so
/// the map is the same on any number of threads (issue 14).
pub(super) fn in_order(
    ev: &Classifier,
    b_auto: &[f64],
    one: &ColumnOf,
) -> Vec<(BoundaryPoint, Vec<Point>)> {
    use std::sync::atomic::{AtomicUsize, Ordering::Relaxed};
    let k_floor = ev.res.k_step;
    let n = b_auto.len();
    let next = AtomicUsize::new(0);
    // Columns from this index on are not started.
    let limit = AtomicUsize::new(n);
    let done = std::sync::Mutex::new(
        (0..n)
            .map(|_| None)
            .collect::<Vec<Option<(BoundaryPoint, Vec<Point>)>>>(),
    );
    let cancelled = || ev.observer.as_ref().is_some_and(|o| o.cancelled());
    let empty = |c: &Option<(BoundaryPoint, Vec<Point>)>| {
        c.as_ref().is_some_and(|(bp, _)| bp.surely_empty(k_floor))
    };
    let work = || loop {
        let i = next.fetch_add(1, Relaxed);
        if i >= limit.load(Relaxed) {
            return;
        }
        let column = one(b_auto[i]);
        let mut d = done.lock().unwrap_or_else(|e| e.into_inner());
        d[i] = Some(column);
        // A cancelled run answers every trial "not passive": its columns
        // say nothing about where the map ends.
        if cancelled() {
            limit.store(0, Relaxed);
            return;
        }
        if empty(&d[i]) {
            // The pair ending at i, or the one ending after it.
            for j in [i, i + 1] {
                if (1..n).contains(&j) && empty(&d[j - 1]) && empty(&d[j]) {
                    limit.fetch_min(j + 1, Relaxed);
                }
            }
        }
        let first: Vec<BoundaryPoint> = d
            .iter()
            .map_while(|c| c.as_ref().map(|(bp, _)| *bp))
            .collect();
        report_done(ev, &first, n);
    };
    rayon::scope(|s| {
        for _ in 0..rayon::current_num_threads().max(1) {
            s.spawn(|_| work());
        }
    });
    // Every column below the limit is done (the limit only falls), so the
    // first empty pair among the columns done is the range's end.
    let done = done.into_inner().unwrap_or_else(|e| e.into_inner());
    let mut columns: Vec<(BoundaryPoint, Vec<Point>)> = done.into_iter().flatten().collect();
    if let Some(end) = end_of_auto_range(&columns, 0, k_floor).filter(|_| !cancelled()) {
        cut_at_end(ev, &mut columns, b_auto, end);
    }
    columns
}

/// The automatic B range with its columns farmed out: batches of `batch`
/// columns, each computed elsewhere and replayed here, until the range's
/// end (the batch past it dropped).
pub(super) fn farmed_batches(
    ev: &Classifier,
    spec: &MapSpec,
    b_auto: &[f64],
    batch: usize,
    one: &ColumnOf,
) -> Vec<(BoundaryPoint, Vec<Point>)> {
    let k_floor = ev.res.k_step;
    let mut columns: Vec<(BoundaryPoint, Vec<Point>)> = Vec::new();
    for chunk in b_auto.chunks(batch) {
        let from = columns.len();
        let planned = {
            let boundary: Vec<BoundaryPoint> = columns.iter().map(|(bp, _)| *bp).collect();
            planned_b(&boundary, b_auto.len(), ev.res.b_step)
        };
        ev.farm_units(spec, &column_units(ev, chunk), &|n| {
            ev.report((from + n) as f64 / planned as f64)
        });
        columns.extend(chunk.par_iter().map(|&b| one(b)).collect::<Vec<_>>());
        // A cancelled run answers every trial "not passive": its columns
        // say nothing about where the map ends (and nothing is dropped).
        if ev.observer.as_ref().is_some_and(|o| o.cancelled()) {
            break;
        }
        if let Some(end) = end_of_auto_range(&columns, from, k_floor) {
            cut_at_end(ev, &mut columns, b_auto, end);
            break;
        }
        let boundary: Vec<BoundaryPoint> = columns.iter().map(|(bp, _)| *bp).collect();
        report_done(ev, &boundary, b_auto.len());
    }
    columns
}

/// End the automatic range after `end` columns: everything from the
/// column after the end on is not the map's, what this run computed past
/// it and whatever an earlier attempt (on more threads) stored there.
pub(super) fn cut_at_end(
    ev: &Classifier,
    columns: &mut Vec<(BoundaryPoint, Vec<Point>)>,
    b_auto: &[f64],
    end: usize,
) {
    columns.truncate(end);
    if let (Some(o), Some(&b)) = (&ev.observer, b_auto.get(end)) {
        o.drop_columns(ev.scope, b);
    }
}

/// Report the share of the automatic range's likely columns done, from the
/// boundary of the columns done in a row from the first.
pub(super) fn report_done(ev: &Classifier, boundary: &[BoundaryPoint], n_auto: usize) {
    ev.report(boundary.len() as f64 / planned_b(boundary, n_auto, ev.res.b_step) as f64);
}

/// Where an automatic B range ends, given its columns so far of which
/// those from `from` on are new: the length up to and including the first
/// pair of columns in a row that surely render nothing (a pair may span
/// the last batch and this one). None: not yet.
pub(super) fn end_of_auto_range(
    columns: &[(BoundaryPoint, Vec<Point>)],
    from: usize,
    k_floor: f64,
) -> Option<usize> {
    (from.max(1)..columns.len())
        .find(|&i| columns[i - 1].0.surely_empty(k_floor) && columns[i].0.surely_empty(k_floor))
        .map(|i| i + 1)
}
