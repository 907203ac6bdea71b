//! What work done elsewhere (a farm's units, a rig's trials) sees of the
//! run it serves: whether it was cancelled, how to cancel or fail it, why
//! it waits, and where its trials go. [`super::observer::Observer`] is one; the farm and
//! trial backends take this, not the observer.

use super::point::StoredTrial;

/// The run a farm or a trial backend works for.
pub trait RunControl: Sync {
    /// Whether the run was cancelled (stop between trials).
    fn cancelled(&self) -> bool;
    /// Cancel the run (its searches end within one trial).
    fn cancel(&self);
    /// Stop the run, failed with `why`.
    fn fail(&self, why: String);
    /// Trials of map `scope` done elsewhere so far, not yet replayed here.
    fn set_elsewhere(&self, scope: u32, n: usize);
    /// Why the rig cannot take the next trial now (None: it can).
    fn set_waiting(&self, why: Option<String>);
    /// Trials done elsewhere: replayed, not redone, by the run's searches.
    fn add_done(&self, trials: Vec<StoredTrial>);
}
