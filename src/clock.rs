//! The wall clock in unix milliseconds, shared by the store and the rigs'
//! leases (below both, so neither imports the other for it).

/// Now, in unix ms (0 if the clock is before 1970).
pub fn now_ms() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}
