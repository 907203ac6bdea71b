//! How long a store write waits before it is tried again: 0.1 s, doubled
//! each time, at most 5 s.

use std::time::Duration;

/// The first wait before retrying a store write.
pub(super) const FIRST_RETRY: Duration = Duration::from_millis(100);

/// The wait after `wait`: doubled, at most 5 s (a full disk is retried
/// every 5 s all night, not in a storm and not once an hour).
pub(super) fn backoff(wait: Duration) -> Duration {
    (wait * 2).min(Duration::from_secs(5))
}
