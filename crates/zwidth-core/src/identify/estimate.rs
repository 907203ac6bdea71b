//! One identified parameter: its value, standard error and 95 % interval,
//! the shape every fit of `identify` reports (the whole device's and the
//! mode's alike).

use serde::Serialize;

/// One identified parameter with its 95 % interval (SI units).
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Estimate {
    pub value: f64,
    /// Standard error (from the blocks' spread).
    pub std_error: f64,
    pub lo: f64,
    pub hi: f64,
}
