//! Wake-ups between the store's writers and its waiters: a queued unit is
//! claimed, and a finished one seen by its driver, without waiting out a
//! poll.

/// Wake-ups, so that a queued unit is claimed, and a finished one seen by
/// its driver, without waiting out a poll: notified in this process by the
/// writes themselves, and from other processes by PostgreSQL's
/// `NOTIFY` (channels `zwidth_units` and `zwidth_unit_done`, sent at the
/// commit), which [`Store::listen`] relays. Waiters poll as well (a
/// notification may be missed while a listener reconnects).
#[derive(Debug)]
pub struct Wakeups {
    /// Work was queued: units, or experiments (or the queue resumed).
    pub queued: tokio::sync::Notify,
    /// A unit of this experiment (its id) ended: each driver listens for
    /// its own experiment only.
    pub ended: tokio::sync::broadcast::Sender<String>,
    pub(super) listening: std::sync::atomic::AtomicBool,
}

impl Default for Wakeups {
    fn default() -> Self {
        Self {
            queued: tokio::sync::Notify::new(),
            ended: tokio::sync::broadcast::channel(1024).0,
            listening: Default::default(),
        }
    }
}

/// The PostgreSQL channels of [`Wakeups`]: work was queued (units, or
/// experiments), a unit ended.
pub(super) const QUEUED: &str = "zwidth_units";
pub(super) const ENDED: &str = "zwidth_unit_done";
