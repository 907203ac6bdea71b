//! zwidth's pure numerics, with no I/O: the velocity estimators
//! ([`estimators`]), test signals and spectra ([`signals`], [`spectral`]),
//! the device model ([`plant`]; [`linalg`] discretizes it exactly), the
//! estimators' accuracy and Lipschitz checks ([`accuracy`], [`lipschitz`]),
//! the Z-width engines and searches ([`zwidth`]), their plots ([`plot`])
//! and the tuner ([`tune`]).
//!
//! The `zwidth` crate (service, store, queue, CLI) builds on this one and
//! re-exports each module under its own name. Keeping the numerics apart
//! keeps their imports pointing one way and makes them cheap to rebuild:
//! a mutation run or a change to an estimator recompiles this crate only.

pub mod accuracy;
pub mod error;
pub mod estimators;
pub mod friction;
pub mod identify;
pub mod linalg;
pub mod lipschitz;
pub mod plant;
pub mod plot;
pub mod signals;
pub mod spectral;
pub mod tune;
pub mod zwidth;

pub use error::SpecError;
