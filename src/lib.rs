//! zwidth: how stiff and how damped a virtual wall a haptic device can render
//! (its Z-width), for each velocity estimator.
//!
//! Pure numerics live in [`estimators`], [`signals`], [`accuracy`] and
//! [`lipschitz`]; the CLI in `cli` only reads, calls them and prints.

pub mod accuracy;
pub mod cli;
pub mod client;
pub mod error;
pub mod estimators;
pub mod experiment;
pub mod http;
pub mod jobs;
pub mod lipschitz;
pub mod plant;
pub mod plot;
pub mod report;
pub mod rig;
pub mod signals;
pub mod spectral;
pub mod store;
pub mod tune;
pub mod zwidth;

pub use error::SpecError;
