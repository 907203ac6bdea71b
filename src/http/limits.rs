//! How big a request may be: its body and its target.

/// Largest request body accepted (bytes).
pub const BODY_LIMIT: usize = 1 << 20;
/// Longest request target (path and query) accepted, bytes; longer is a 414.
/// (hyper itself answers a bare 414 beyond 64 KiB.)
pub const URI_LIMIT: usize = 16 * 1024;
