//! zwidth-dsp's tests, one binary: the golden vectors and fingerprints
//! through this crate alone (`golden`), the Butterworth design against
//! scipy (`butterworth_design`), the refusals (`refusals`), the exposed
//! coefficients and states (`accessors`), no allocation (`no_alloc`).

mod accessors;
mod butterworth_design;
mod golden;
mod no_alloc;
mod refusals;
