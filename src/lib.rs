//! zwidth: how stiff and how damped a virtual wall a haptic device can render
//! (its Z-width), for each velocity estimator.
//!
//! Pure numerics live in the `zwidth-core` crate (re-exported here: [`estimators`],
//! [`zwidth`], [`tune`], …); the CLI in `cli` only reads, calls them and prints.

pub mod agent;
pub mod cli;
pub mod client;
pub mod clock;
pub mod experiment;
pub mod http;
pub mod jobs;
pub mod report;
pub mod rig;
pub mod store;
pub mod tls;

// The numerics live in `zwidth-core` (crates/zwidth-core); they keep their
// paths here (`zwidth::estimators`, `crate::zwidth::search`, …).
pub use zwidth_core::{
    accuracy, error, estimators, identify, lipschitz, plant, plot, signals, spectral, tune, zwidth,
};

pub use error::SpecError;
