//! What a running map shares with whoever runs it: trials done, a cancel
//! flag, trials and tune evaluations replayed from an interrupted run, the
//! new ones to store, the progress, the runaway limit and the hold while
//! storing fails.

use serde::Serialize;

use super::control::RunControl;
use super::point::StoredTrial;

/// Shared with whoever runs a map: trials done so far, a cancel flag the
/// searches honour between trials (a cancelled map ends within one trial),
/// trials already done by an earlier, interrupted run (replayed, not
/// redone: the searches are deterministic), and the new ones to store.
#[derive(Debug, Default)]
pub struct Observer {
    pub trials: std::sync::atomic::AtomicUsize,
    pub cancel: std::sync::atomic::AtomicBool,
    done: std::sync::RwLock<std::collections::HashMap<(u32, u64, u64), StoredTrial>>,
    new: std::sync::Mutex<Vec<StoredTrial>>,
    /// Trials asked so far per (scope, column), replayed ones included:
    /// the next trial's `index`.
    asked: std::sync::Mutex<std::collections::HashMap<(u32, u32), u32>>,
    /// Columns dropped from a map after they ran (an automatic B range
    /// searched past its end): (scope, B of the first dropped column; the
    /// automatic range grows with B), for whoever stored their trials to
    /// delete them.
    dropped: std::sync::Mutex<Vec<(u32, f64)>>,
    /// Maps expected in the experiment (0 counts as 1) and each one's
    /// fraction done, for the progress and ETA.
    scopes: std::sync::atomic::AtomicUsize,
    progress: std::sync::Mutex<std::collections::HashMap<u32, f64>>,
    /// Whole evaluations (a tune's objective at some parameters) done by an
    /// earlier run, by key; the new ones to store; the best so far.
    evals_done: std::collections::HashMap<String, serde_json::Value>,
    evals_new: std::sync::Mutex<Vec<StoredEvaluation>>,
    best: std::sync::Mutex<Option<serde_json::Value>>,
    /// Trials after which the run is stopped as runaway (0: no limit), and
    /// why it was, once it is.
    trial_limit: std::sync::atomic::AtomicUsize,
    runaway: std::sync::Mutex<Option<String>>,
    /// Set while finished trials cannot be stored: the searches wait
    /// between trials, and the reason is shown with the progress.
    held: std::sync::Mutex<Option<String>>,
    /// Set while an attached rig cannot take the next trial: why.
    waiting: std::sync::Mutex<Option<String>>,
    /// Where trials run when not in this process (an attached rig).
    backend: Option<std::sync::Arc<dyn super::trial::TrialBackend>>,
    /// Where a map's units are computed when not in this process (other
    /// workers), and the trials they have done so far, by map, not yet
    /// replayed here (counted in [`Observer::trials_done`]).
    farm: Option<std::sync::Arc<dyn super::farm::Farm>>,
    elsewhere: std::sync::Mutex<std::collections::HashMap<u32, usize>>,
}

impl std::fmt::Debug for dyn super::farm::Farm {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Farm")
    }
}

impl std::fmt::Debug for dyn super::trial::TrialBackend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("TrialBackend")
    }
}

/// A finished evaluation of a tune (the record is the tune's own JSON).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize, utoipa::ToSchema)]
pub struct StoredEvaluation {
    /// Identifies the evaluation: accuracy and exact parameter values.
    pub key: String,
    pub record: serde_json::Value,
}

impl Observer {
    /// An observer that replays `done` instead of recomputing those trials.
    pub fn resuming(done: Vec<StoredTrial>) -> Self {
        let o = Self::default();
        o.add_done(done);
        o
    }

    /// Replay `trials` too (computed elsewhere since: a farm's units).
    pub fn add_done(&self, trials: Vec<StoredTrial>) {
        let mut d = self.done.write().unwrap_or_else(|e| e.into_inner());
        for t in trials {
            d.insert((t.scope, t.point.k.to_bits(), t.point.b.to_bits()), t);
        }
    }

    /// Hand maps' units to `farm` instead of computing them here.
    pub fn with_farm(mut self, farm: std::sync::Arc<dyn super::farm::Farm>) -> Self {
        self.farm = Some(farm);
        self
    }

    pub(super) fn farm(&self) -> Option<&std::sync::Arc<dyn super::farm::Farm>> {
        self.farm.as_ref()
    }

    /// Map `scope` has `n` trials done elsewhere, not yet replayed here.
    pub fn set_elsewhere(&self, scope: u32, n: usize) {
        let mut e = self.elsewhere.lock().unwrap_or_else(|e| e.into_inner());
        if n == 0 {
            e.remove(&scope);
        } else {
            e.insert(scope, n);
        }
    }

    /// Trials done so far: here (replayed ones included) and elsewhere.
    pub fn trials_done(&self) -> usize {
        let elsewhere: usize = self
            .elsewhere
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .values()
            .sum();
        self.trials.load(std::sync::atomic::Ordering::Relaxed) + elsewhere
    }

    /// Also replay the evaluations `evals` (a resumed tune).
    pub fn with_evaluations(mut self, evals: Vec<StoredEvaluation>) -> Self {
        self.evals_done = evals.into_iter().map(|e| (e.key, e.record)).collect();
        self
    }

    /// Run new trials on `backend` instead of in this process (replayed
    /// trials are still replayed, new ones still recorded here).
    pub fn with_backend(mut self, backend: std::sync::Arc<dyn super::trial::TrialBackend>) -> Self {
        self.backend = Some(backend);
        self
    }

    pub(super) fn backend(&self) -> Option<&std::sync::Arc<dyn super::trial::TrialBackend>> {
        self.backend.as_ref()
    }

    /// Stop the run once it has done more than `limit` trials (a runaway:
    /// far beyond what its spec was estimated to cost).
    pub fn limit_trials(&self, limit: usize) {
        self.trial_limit
            .store(limit, std::sync::atomic::Ordering::Relaxed);
    }

    /// Why the run was stopped as a runaway, if it was.
    pub fn runaway(&self) -> Option<String> {
        self.runaway
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Stop the run as failed, saying why (a check that can only be made
    /// while it runs, e.g. an attached rig's capabilities at dispatch).
    pub fn fail(&self, why: String) {
        let mut r = self.runaway.lock().unwrap_or_else(|e| e.into_inner());
        if r.is_none() {
            *r = Some(why);
        }
        self.cancel
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }

    /// The trial backend is waiting for its rig (Some(why)) or not (None).
    pub fn set_waiting(&self, why: Option<String>) {
        *self.waiting.lock().unwrap_or_else(|e| e.into_inner()) = why;
    }

    /// Why the run waits for its rig, if it does.
    pub fn waiting(&self) -> Option<String> {
        self.waiting
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .clone()
    }

    /// Hold the run (Some(why)) until released (None).
    pub fn hold(&self, why: Option<String>) {
        *self.held.lock().unwrap_or_else(|e| e.into_inner()) = why;
    }

    /// Why the run is held, if it is.
    pub fn held(&self) -> Option<String> {
        self.held.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Wait (between trials) while the run is held and not cancelled.
    pub(super) fn wait_while_held(&self) {
        while self.held().is_some() && !self.cancelled() {
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }

    /// Count one trial; past the limit, stop the run and say why.
    pub(super) fn count_trial(&self) {
        use std::sync::atomic::Ordering::Relaxed;
        let n = self.trials.fetch_add(1, Relaxed) + 1;
        let limit = self.trial_limit.load(Relaxed);
        if limit > 0 && n > limit && !self.cancelled() {
            *self.runaway.lock().unwrap_or_else(|e| e.into_inner()) = Some(format!(
                "stopped after {n} trials: more than {limit}, four times what the spec was estimated to cost (plus 1000); the scene may not have a boundary the search can find"
            ));
            self.cancel.store(true, Relaxed);
        }
    }

    /// An evaluation stored by an earlier run.
    pub fn stored_evaluation(&self, key: &str) -> Option<serde_json::Value> {
        self.evals_done.get(key).cloned()
    }

    /// A new evaluation to store.
    pub fn record_evaluation(&self, key: String, record: serde_json::Value) {
        self.evals_new
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(StoredEvaluation { key, record });
    }

    /// The evaluations finished since the last call.
    pub fn take_new_evaluations(&self) -> Vec<StoredEvaluation> {
        std::mem::take(&mut *self.evals_new.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// The best result so far (shown while running).
    pub fn set_best(&self, best: serde_json::Value) {
        *self.best.lock().unwrap_or_else(|e| e.into_inner()) = Some(best);
    }

    pub fn best(&self) -> Option<serde_json::Value> {
        self.best.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    pub fn cancelled(&self) -> bool {
        self.cancel.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// The trials finished since the last call.
    pub fn take_new(&self) -> Vec<StoredTrial> {
        std::mem::take(&mut *self.new.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// How many maps the experiment runs (for [`Observer::fraction`]).
    pub fn set_scopes(&self, n: usize) {
        self.scopes.store(n, std::sync::atomic::Ordering::Relaxed);
    }

    /// Map `scope` is `fraction` (0 to 1) done. Progress never goes back:
    /// parallel columns may report out of order, and a search that plans
    /// more work than it first estimated stalls rather than rewinds.
    pub fn report(&self, scope: u32, fraction: f64) {
        if fraction.is_finite() {
            let mut p = self.progress.lock().unwrap_or_else(|e| e.into_inner());
            let f = p.entry(scope).or_insert(0.0);
            *f = f.max(fraction.clamp(0.0, 1.0));
        }
    }

    /// The fraction of the whole experiment done, 0 to 1.
    pub fn fraction(&self) -> f64 {
        let n = self
            .scopes
            .load(std::sync::atomic::Ordering::Relaxed)
            .max(1);
        let p = self.progress.lock().unwrap_or_else(|e| e.into_inner());
        (p.values().sum::<f64>() / n as f64).clamp(0.0, 1.0)
    }

    /// The place of the next trial asked in `column` of map `scope`.
    pub(super) fn next_index(&self, scope: u32, column: u32) -> u32 {
        let mut a = self.asked.lock().unwrap_or_else(|e| e.into_inner());
        let n = a.entry((scope, column)).or_insert(0);
        *n += 1;
        *n - 1
    }

    /// The stored trial at exactly (scope, K, B), if an earlier run did it.
    pub(super) fn replay(&self, scope: u32, k: f64, b: f64) -> Option<StoredTrial> {
        self.done
            .read()
            .unwrap_or_else(|e| e.into_inner())
            .get(&(scope, k.to_bits(), b.to_bits()))
            .cloned()
    }

    pub(super) fn record(&self, trial: StoredTrial) {
        self.new
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push(trial);
    }

    /// Drop the columns of map `scope` from B = `from_b` on (an automatic
    /// range, whose B grows with the column): their trials not yet taken
    /// are forgotten, and [`Observer::take_dropped`] tells whoever stored
    /// the others (by B, so also trials stored before their place was
    /// known, and by an earlier attempt).
    pub(super) fn drop_columns(&self, scope: u32, from_b: f64) {
        self.new
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .retain(|t| t.scope != scope || t.point.b < from_b);
        self.dropped
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .push((scope, from_b));
    }

    /// Columns dropped since the last call: (scope, B of the first dropped
    /// column). Delete their stored trials after storing
    /// [`Observer::take_new`]'s.
    pub fn take_dropped(&self) -> Vec<(u32, f64)> {
        std::mem::take(&mut *self.dropped.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl RunControl for Observer {
    fn cancelled(&self) -> bool {
        Observer::cancelled(self)
    }
    fn cancel(&self) {
        self.cancel
            .store(true, std::sync::atomic::Ordering::Relaxed);
    }
    fn fail(&self, why: String) {
        Observer::fail(self, why)
    }
    fn set_elsewhere(&self, scope: u32, n: usize) {
        Observer::set_elsewhere(self, scope, n)
    }
    fn set_waiting(&self, why: Option<String>) {
        Observer::set_waiting(self, why)
    }
    fn add_done(&self, trials: Vec<StoredTrial>) {
        Observer::add_done(self, trials)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::point::Point;

    #[test]
    fn a_run_is_stopped_only_past_its_trial_limit() {
        // Limit 3: three trials are allowed, the fourth stops the run.
        let o = Observer::default();
        o.limit_trials(3);
        for _ in 0..3 {
            o.count_trial();
        }
        assert!(!o.cancelled() && o.runaway().is_none());
        o.count_trial();
        assert!(o.cancelled());
        assert!(o
            .runaway()
            .unwrap()
            .starts_with("stopped after 4 trials: more than 3"));
        // No limit (0): never stopped.
        let free = Observer::default();
        for _ in 0..10 {
            free.count_trial();
        }
        assert!(!free.cancelled());
    }

    #[test]
    fn stored_trials_are_replayed_by_their_exact_scope_k_and_b() {
        let p = Point {
            k: 1500.0,
            b: 20.0,
            passive: Some(true),
            ..Point::default()
        };
        let o = Observer::default();
        let t = StoredTrial {
            scope: 3,
            column: 2,
            index: 5,
            point: p.clone(),
        };
        o.record(t.clone());
        let new = o.take_new();
        assert_eq!(new, std::slice::from_ref(&t));
        assert!(o.take_new().is_empty(), "taken once");
        let r = Observer::resuming(new);
        assert_eq!(r.replay(3, 1500.0, 20.0), Some(t.clone()));
        // The key is the exact bits of K and B, and the map's scope.
        assert_eq!(r.replay(2, 1500.0, 20.0), None);
        assert_eq!(r.replay(3, 1500.0, 20.000_001), None);
        assert_eq!(r.replay(3, 1_500.000_001, 20.0), None);
        // Evaluations the same way, by key.
        let e = Observer::default().with_evaluations(vec![StoredEvaluation {
            key: "a".into(),
            record: serde_json::json!(1),
        }]);
        assert_eq!(e.stored_evaluation("a"), Some(serde_json::json!(1)));
        assert_eq!(e.stored_evaluation("b"), None);
    }

    #[test]
    fn trials_are_numbered_per_column_and_dropped_columns_are_forgotten() {
        let o = Observer::default();
        // Each (scope, column) counts its own trials from 0.
        assert_eq!(o.next_index(0, 0), 0);
        assert_eq!(o.next_index(0, 0), 1);
        assert_eq!(o.next_index(0, 1), 0);
        assert_eq!(o.next_index(1, 0), 0);
        assert_eq!(o.next_index(0, 0), 2);
        // Column c at B = 10 c.
        let t = |scope, column: u32| StoredTrial {
            scope,
            column,
            index: 0,
            point: Point {
                b: 10.0 * f64::from(column),
                ..Point::default()
            },
        };
        for (s, c) in [(0, 1), (0, 2), (0, 3), (1, 3)] {
            o.record(t(s, c));
        }
        // Dropping scope 0 from B = 20: its columns 2 and 3 go, column 1
        // and the other scope's column 3 stay; the drop is told once.
        o.drop_columns(0, 20.0);
        assert_eq!(o.take_new(), [t(0, 1), t(1, 3)]);
        assert_eq!(o.take_dropped(), [(0, 20.0)]);
        assert!(o.take_dropped().is_empty());
    }

    #[test]
    fn a_held_run_waits_until_released_or_cancelled() {
        use std::sync::Arc;
        let o = Arc::new(Observer::default());
        o.hold(Some("disk full".into()));
        assert_eq!(o.held().as_deref(), Some("disk full"));
        let waiter = {
            let o = o.clone();
            std::thread::spawn(move || o.wait_while_held())
        };
        // Still waiting after a while (it would return at once if it did not
        // wait), then released.
        std::thread::sleep(std::time::Duration::from_millis(300));
        assert!(!waiter.is_finished());
        o.hold(None);
        waiter.join().unwrap();
        assert_eq!(o.held(), None);
        // A cancel ends the wait too (within a few of its 50 ms looks; a
        // waiter that never ends fails here rather than hanging the suite).
        o.hold(Some("disk full".into()));
        o.cancel.store(true, std::sync::atomic::Ordering::Relaxed);
        let waiter = {
            let o = o.clone();
            std::thread::spawn(move || o.wait_while_held())
        };
        let start = std::time::Instant::now();
        while !waiter.is_finished() && start.elapsed().as_secs() < 5 {
            std::thread::sleep(std::time::Duration::from_millis(10));
        }
        assert!(waiter.is_finished(), "a cancelled run stops waiting");
        assert!(o.held().is_some());
    }

    #[test]
    fn trials_done_elsewhere_count_until_they_are_replayed_here() {
        // A farm's units: 5 trials of map 2 and 4 of map 3 done by other
        // workers, 3 replayed or computed here.
        let o = Observer::default();
        for _ in 0..3 {
            o.count_trial();
        }
        o.set_elsewhere(2, 5);
        o.set_elsewhere(3, 4);
        assert_eq!(o.trials_done(), 3 + 5 + 4);
        o.set_elsewhere(2, 6);
        assert_eq!(o.trials_done(), 3 + 6 + 4, "replaced, not added");
        // Map 2 replayed here: its count moves to this process's.
        o.set_elsewhere(2, 0);
        assert_eq!(o.trials_done(), 3 + 4);
        o.set_elsewhere(3, 0);
        assert_eq!(o.trials_done(), 3);
    }

    #[test]
    fn progress_is_the_mean_of_the_maps_fractions_and_never_goes_back() {
        let o = Observer::default();
        o.set_scopes(4);
        o.report(0, 0.5);
        o.report(1, 1.0);
        o.report(0, 0.25); // out of order: kept at 0.5
        o.report(2, f64::NAN); // ignored
        o.report(3, 7.0); // clamped to 1
        assert_eq!(o.fraction(), (0.5 + 1.0 + 1.0) / 4.0);
    }
}
