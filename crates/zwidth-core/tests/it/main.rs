//! Every integration test of this crate, one binary (issue 33): one link
//! per test build instead of one per file. Each module is the file of one
//! surface; `common` holds what they share.

mod bit_identical;
mod engines;
mod extremes;
mod golden;
mod tune_noisy;
