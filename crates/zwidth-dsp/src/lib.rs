//! zwidth's velocity estimators for a real-time loop: `no_std`, no `alloc`,
//! the same bits in the simulator (`zwidth-core` builds its estimators from
//! this crate), the CLI, the service and a lab's controller.
//!
//! Each estimator is an immutable configuration (its coefficients, built
//! once) and a small mutable state in fixed arrays, with `step(y) -> v`
//! (one position sample in metres, one velocity estimate out in m/s) and
//! `reset()`.
//!
//! # Rules
//! - **One maths library.** Design-time maths (tan, sin, cos, sqrt, hypot)
//!   goes through [`math`], which is the `libm` crate in every build, so the
//!   coefficients have the same bits on every host and target; integer
//!   powers are the binary method of compiler-rt's `__powidf2`
//!   ([`math::powi`]).
//! - **No fused multiply–add, no fast-math.** Every expression is written
//!   as the sequence of IEEE-754 double operations it is evaluated as (Rust
//!   never contracts `a * b + c` into an FMA on its own).
//! - **Subnormals.** A resting device drives filter states toward zero
//!   geometrically; below 2.2e-308 they become subnormal, which costs 10–100×
//!   per operation on many CPUs and is flushed to zero by hosts that set
//!   FTZ/DAZ, so results would differ between hosts. Every state that can
//!   decay is set to exactly 0 once its magnitude falls below [`FLUSH`] =
//!   1e-100 (in its SI unit: nothing physical), at the end of each step: no
//!   operation then sees a subnormal from the state, and the output is the
//!   same with and without FTZ/DAZ (tested on a long rest).
//! - **Bounded work, no allocation in `step`.** State lives in arrays whose
//!   sizes are const generics (the FOAW window and the median length) or
//!   stated caps ([`butterworth::MAX_ORDER`]); `step` allocates nothing
//!   (there is no allocator here) and its work is bounded by the caps: FOAW
//!   `end`/`best` O(N), `best_r` and outlier tolerance O(N²) for a window
//!   of N (N(N+1)/2 residuals at most), the median O(W).
//! - Units are SI; every formula cites its paper and equation.

#![no_std]
#![forbid(unsafe_code)]

pub mod butterworth;
pub mod complex;
pub mod error;
pub mod estimator;
pub mod fdm;
pub mod fingerprint;
pub mod foaw;
pub mod identity;
pub mod kalman;
pub mod levant;
pub mod math;
pub mod median;

pub use butterworth::{Butterworth, Sos};
pub use error::Error;
pub use estimator::{Estimator, KindSpec, RigEstimator, Spec};
pub use fdm::Fdm;
pub use foaw::{Foaw, FoawFit};
pub use kalman::{Kalman, QModel};
pub use levant::{Discretization, ImplicitOutput, Levant};
pub use math::{flush, FLUSH};
pub use median::Median;

/// The library's version (the agent advertises it at hello).
pub const VERSION: &str = env!("CARGO_PKG_VERSION");
