//! The C ABI of zwidth's velocity estimators (`include/zwidth.h`, written
//! by cbindgen 0.29.4; `tests/abi/header.rs` fails when it drifts).
//!
//! - **Caller-owned state.** A `zw_estimator` is a plain struct of
//!   `ZW_ESTIMATOR_WORDS` 64-bit words: a lab puts it on the stack, in a
//!   static or in a Simulink DWork. Nothing here allocates after `init`
//!   (and the per-kind inits not at all); `step` is bounded work
//!   (zwidth-dsp's header).
//! - **Status codes**, never a panic across the boundary (each call runs
//!   under `catch_unwind`): null pointers, a bad parameter (named in the
//!   optional `zw_error`), a window or order beyond this build's capacity,
//!   malformed JSON, a struct no `init` has filled (or whose last init
//!   refused), a non-finite position (refused, the state unchanged), an
//!   estimate that would overflow (the state reset). One limit, one code:
//!   a window or order beyond this build's capacity is `ZW_CAPACITY`
//!   through the JSON init and the per-kind inits alike. Nothing printed.
//! - **Threads**: reentrant, no global state; one estimator per thread at
//!   a time (`zw_estimator`'s comment, in the header).
//! - The same estimators, bit for bit, as the simulator: `zw_init_json`
//!   takes the JSON estimator spec the API takes (`{"kind":"butterworth",
//!   "cutoff_hz":100,"order":2}`), checked with the service's messages.

#![allow(non_camel_case_types)]

use std::ffi::{c_char, CStr};
use std::panic::{catch_unwind, AssertUnwindSafe};

use zwidth_dsp::estimator::{RIG_FOAW_WINDOW, RIG_MEDIAN};
use zwidth_dsp::{
    Discretization, Error, FoawFit, ImplicitOutput, KindSpec, QModel, RigEstimator, Spec,
};

/// The ABI's version: a change of any signature, struct or meaning
/// increments it.
pub const ZW_ABI_VERSION: u32 = 1;

/// 64-bit words of a `zw_estimator` (8 KiB: the estimator at its caps
/// takes under 6 KiB; the rest keeps the ABI when the state grows).
pub const ZW_ESTIMATOR_WORDS: usize = 1024;

/// The longest FOAW window this build holds (samples).
pub const ZW_FOAW_MAX_WINDOW: u32 = 64;

/// The longest median window this build holds (samples).
pub const ZW_MEDIAN_MAX_WINDOW: u32 = 63;

/// The highest Butterworth order.
pub const ZW_BUTTERWORTH_MAX_ORDER: u32 = 10;

const _: () = assert!(
    ZW_FOAW_MAX_WINDOW as usize == RIG_FOAW_WINDOW
        && ZW_MEDIAN_MAX_WINDOW as usize == RIG_MEDIAN
        && ZW_BUTTERWORTH_MAX_ORDER == zwidth_dsp::butterworth::MAX_ORDER
);

/// An estimator's state and coefficients, owned by the caller. Fill it with
/// one of the `zw_init_*` functions before any other call; a zeroed struct
/// is refused with `ZW_NOT_INITIALIZED`, and so is one whose last init
/// refused (a failed re-init never leaves the old estimator stepping).
///
/// Threads: every function is reentrant and keeps nothing between calls
/// but the caller's struct (the one global is a panic hook installed on
/// first use, silent for the library's own panics only), so different
/// estimators may be used from different threads at once. One estimator
/// is used by one thread at a time: calls on the same struct from two
/// threads at once must be serialized by the caller (a mutex), as for any
/// C struct written in place. The library never prints:
/// a panic inside it (a bug) returns `ZW_INTERNAL` silently.
#[repr(C)]
pub struct zw_estimator {
    pub words: [u64; ZW_ESTIMATOR_WORDS],
}

/// What a call did.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum zw_status {
    ZwOk = 0,
    /// A pointer argument was null.
    ZwNull = 1,
    /// A parameter is out of its range (named in `zw_error`); or a
    /// position is not a finite number (the state is unchanged); or a
    /// position so far out that the estimate would not be a finite number
    /// (±1e308 m into a difference): the state is then reset, as by
    /// `zw_reset`, and the estimate not written. No call returns `ZW_OK`
    /// with a non-finite estimate.
    ZwBadParameter = 2,
    /// A window or order beyond this build's capacity (named, with the cap).
    ZwCapacity = 3,
    /// The JSON spec is not JSON (or not UTF-8).
    ZwParse = 4,
    /// The struct was not filled by a `zw_init_*` function.
    ZwNotInitialized = 5,
    /// A bug in this library (it did not panic across the boundary).
    ZwInternal = 6,
}

/// Why an init refused: the parameter and a sentence naming its value and
/// what is allowed, NUL-terminated (cut to fit).
#[repr(C)]
pub struct zw_error {
    pub parameter: [c_char; 32],
    pub message: [c_char; 224],
}

/// The Kalman filter's process-noise model.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum zw_q_model {
    ZwWhiteJerk = 0,
    ZwDiagonal = 1,
}

/// The FOAW line fit.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum zw_foaw_fit {
    ZwFoawEnd = 0,
    ZwFoawBest = 1,
    ZwFoawBestR = 2,
}

/// Levant's discretization and output.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum zw_levant_scheme {
    ZwLevantExplicit = 0,
    /// Implicit Euler, the integrator state as output.
    ZwLevantImplicit = 1,
    /// Implicit Euler, the 2011 paper's eq. 7 as output.
    ZwLevantImplicitEq7 = 2,
}

/// "zwidth" and the ABI version: the first word of a filled struct.
const MAGIC: u64 = 0x7a77_6964_7468_0000 | ZW_ABI_VERSION as u64;

/// The struct's contents once filled.
struct Slot {
    magic: u64,
    est: RigEstimator,
}

const _: () = assert!(
    std::mem::size_of::<Slot>() <= 8 * ZW_ESTIMATOR_WORDS
        && std::mem::align_of::<Slot>() <= std::mem::align_of::<zw_estimator>()
);

thread_local! {
    /// True while this thread runs inside `guarded`.
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Installs, once, a panic hook that stays silent for panics inside
/// `guarded` (they become `ZW_INTERNAL`; the library prints nothing) and
/// passes every other panic to the hook that was there before.
static QUIET_HOOK: std::sync::Once = std::sync::Once::new();

/// Run `f`, turning a panic into `ZW_INTERNAL`, silently.
fn guarded(f: impl FnOnce() -> zw_status) -> zw_status {
    QUIET_HOOK.call_once(|| {
        let before = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(std::cell::Cell::get) {
                before(info);
            }
        }));
    });
    let outer = GUARDED.with(|g| g.replace(true));
    let status = catch_unwind(AssertUnwindSafe(f)).unwrap_or(zw_status::ZwInternal);
    GUARDED.with(|g| g.set(outer));
    status
}

/// An init: `f` under `guarded`; when it refuses, the struct behind `e`
/// (if any) is marked unfilled, so a failed re-init never leaves the old
/// estimator stepping: every later call answers `ZW_NOT_INITIALIZED`
/// until an init succeeds.
fn init_guarded(e: *mut zw_estimator, f: impl FnOnce() -> zw_status) -> zw_status {
    let status = guarded(f);
    if status != zw_status::ZwOk && !e.is_null() {
        // SAFETY: a non-null `e` is a caller-owned zw_estimator (every
        // init's contract), large and aligned enough for a Slot (asserted
        // above); the magic is plain data, written where the Slot has it.
        unsafe { std::ptr::addr_of_mut!((*e.cast::<Slot>()).magic).write(0) };
    }
    status
}

/// The filled estimator behind `e`.
///
/// # Safety
/// `e` is null or points to a `zw_estimator` the caller owns.
unsafe fn filled<'a>(e: *mut zw_estimator) -> Result<&'a mut RigEstimator, zw_status> {
    if e.is_null() {
        return Err(zw_status::ZwNull);
    }
    let slot = e.cast::<Slot>();
    // SAFETY: `e` is a valid, 8-aligned zw_estimator of at least
    // size_of::<Slot>() bytes (the assertion above); the magic word tells a
    // filled one from a zeroed one.
    unsafe {
        if std::ptr::addr_of!((*slot).magic).read() != MAGIC {
            return Err(zw_status::ZwNotInitialized);
        }
        Ok(&mut (*slot).est)
    }
}

/// The filled estimator behind `e`, read only.
///
/// # Safety
/// `e` is null or points to a `zw_estimator` the caller owns.
unsafe fn filled_ref<'a>(e: *const zw_estimator) -> Result<&'a RigEstimator, zw_status> {
    if e.is_null() {
        return Err(zw_status::ZwNull);
    }
    let slot = e.cast::<Slot>();
    // SAFETY: as `filled`.
    unsafe {
        if std::ptr::addr_of!((*slot).magic).read() != MAGIC {
            return Err(zw_status::ZwNotInitialized);
        }
        Ok(&(*slot).est)
    }
}

/// Copy `text` into `dst`, cut to fit, NUL-terminated.
fn copy_c(dst: &mut [c_char], text: &str) {
    let n = text.len().min(dst.len().saturating_sub(1));
    // Cut on a character boundary.
    let n = (0..=n)
        .rev()
        .find(|&i| text.is_char_boundary(i))
        .unwrap_or(0);
    for (d, s) in dst.iter_mut().zip(text.as_bytes()[..n].iter()) {
        *d = *s as c_char;
    }
    if let Some(z) = dst.get_mut(n) {
        *z = 0;
    }
}

/// Say why in `err` (when not null) and return `status`.
///
/// # Safety
/// `err` is null or points to a `zw_error` the caller owns.
unsafe fn explain(
    err: *mut zw_error,
    status: zw_status,
    parameter: &str,
    message: &str,
) -> zw_status {
    // SAFETY: as the function's contract.
    if let Some(err) = unsafe { err.as_mut() } {
        copy_c(&mut err.parameter, parameter);
        copy_c(&mut err.message, message);
    }
    status
}

/// Fill `e` from a resolved spec, or explain the refusal.
///
/// # Safety
/// `e` is null or points to a `zw_estimator`; `err` null or a `zw_error`.
unsafe fn fill(
    e: *mut zw_estimator,
    spec: &Spec,
    rate_hz: f64,
    quantization_m: f64,
    err: *mut zw_error,
) -> zw_status {
    if e.is_null() {
        // SAFETY: `err` as the contract.
        return unsafe {
            explain(
                err,
                zw_status::ZwNull,
                "estimator",
                "the estimator pointer is null",
            )
        };
    }
    match RigEstimator::new(spec, rate_hz, quantization_m) {
        Ok(est) => {
            // SAFETY: `e` is valid for a write of a Slot (size and alignment
            // asserted above); the old contents need no drop (plain data).
            unsafe {
                e.cast::<Slot>().write(Slot { magic: MAGIC, est });
            }
            // SAFETY: `err` as the contract.
            unsafe { explain(err, zw_status::ZwOk, "", "") }
        }
        Err(x) => {
            let status = match x {
                Error::Capacity { .. } => zw_status::ZwCapacity,
                Error::Parameter { .. } => zw_status::ZwBadParameter,
            };
            // SAFETY: `err` as the contract.
            unsafe { explain(err, status, x.parameter(), &x.to_string()) }
        }
    }
}

/// The ABI version this library implements (`ZW_ABI_VERSION`).
#[no_mangle]
pub extern "C" fn zw_abi_version() -> u32 {
    ZW_ABI_VERSION
}

/// The estimator library's version, NUL-terminated (static storage).
#[no_mangle]
pub extern "C" fn zw_version() -> *const c_char {
    concat!(env!("CARGO_PKG_VERSION"), "\0").as_ptr().cast()
}

/// `sizeof(zw_estimator)` as this library sees it (a check for callers
/// whose header and library might differ).
#[no_mangle]
pub extern "C" fn zw_estimator_size() -> usize {
    std::mem::size_of::<zw_estimator>()
}

/// Fill `e` from the JSON estimator spec the API takes, at `rate_hz` with
/// the encoder step `quantization_m`. `err` may be null.
///
/// # Safety
/// `e` null or a `zw_estimator`; `spec_json` null or a NUL-terminated
/// string; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_json(
    e: *mut zw_estimator,
    spec_json: *const c_char,
    rate_hz: f64,
    quantization_m: f64,
    err: *mut zw_error,
) -> zw_status {
    init_guarded(e, || {
        if spec_json.is_null() {
            // SAFETY: `err` as the contract.
            return unsafe {
                explain(
                    err,
                    zw_status::ZwNull,
                    "spec_json",
                    "the spec pointer is null",
                )
            };
        }
        // SAFETY: a NUL-terminated string, as the contract.
        let Ok(text) = unsafe { CStr::from_ptr(spec_json) }.to_str() else {
            // SAFETY: `err` as the contract.
            return unsafe {
                explain(
                    err,
                    zw_status::ZwParse,
                    "spec_json",
                    "the spec is not UTF-8",
                )
            };
        };
        if let Err(x) = serde_json::from_str::<serde_json::Value>(text) {
            // SAFETY: `err` as the contract.
            return unsafe {
                explain(
                    err,
                    zw_status::ZwParse,
                    "spec_json",
                    &format!("not JSON: {x}"),
                )
            };
        }
        let mut parsed = None;
        let checked =
            zwidth_core::estimators::Sampling::new(rate_hz, quantization_m).and_then(|s| {
                let spec = parsed.insert(zwidth_core::estimators::EstimatorSpec::from_json(text)?);
                // The service's checks and messages first.
                spec.build(s)?;
                spec.to_dsp()
            });
        match checked {
            // SAFETY: as the contract.
            Ok(spec) => unsafe { fill(e, &spec, rate_hz, quantization_m, err) },
            Err(x) => {
                // One limit, one code through every entry point: a window
                // or order beyond this build's capacity is ZW_CAPACITY
                // even where the service's own (wider) limit refused it
                // first, as `zw_init_foaw` and `zw_init_butterworth` say.
                let capacity = parsed
                    .and_then(|spec| spec.to_dsp().ok())
                    .and_then(|d| RigEstimator::new(&d, rate_hz, quantization_m).err())
                    .filter(|c| matches!(c, Error::Capacity { .. }));
                if let Some(c) = capacity {
                    // SAFETY: `err` as the contract.
                    return unsafe {
                        explain(err, zw_status::ZwCapacity, c.parameter(), &c.to_string())
                    };
                }
                // SAFETY: `err` as the contract.
                // The parameter as the spec names it (`q`, not `estimator.q`),
                // as the build's own checks name it.
                unsafe {
                    explain(
                        err,
                        zw_status::ZwBadParameter,
                        x.field.strip_prefix("estimator.").unwrap_or(&x.field),
                        &x.to_string(),
                    )
                }
            }
        }
    })
}

/// Fill `e` with the finite-difference method (2011 paper eq. 2).
///
/// # Safety
/// `e` null or a `zw_estimator`; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_fdm(
    e: *mut zw_estimator,
    rate_hz: f64,
    err: *mut zw_error,
) -> zw_status {
    // SAFETY: as the contract (the quantization is unused by FDM).
    init_guarded(e, || unsafe {
        fill(e, &KindSpec::Fdm.into(), rate_hz, 1.0, err)
    })
}

/// Fill `e` with FDM and a Butterworth low-pass of `order` (1 to
/// `ZW_BUTTERWORTH_MAX_ORDER`) at `cutoff_hz` (below rate_hz/2).
///
/// # Safety
/// `e` null or a `zw_estimator`; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_butterworth(
    e: *mut zw_estimator,
    rate_hz: f64,
    cutoff_hz: f64,
    order: u32,
    err: *mut zw_error,
) -> zw_status {
    let spec = KindSpec::Butterworth { cutoff_hz, order }.into();
    // SAFETY: as the contract.
    init_guarded(e, || unsafe { fill(e, &spec, rate_hz, 1.0, err) })
}

/// Fill `e` with the Kalman filter: `model` a `zw_q_model`; `rho` ≤ 0: the
/// plain filter; in (0, 1): the fading-factor filter with that
/// forgetting factor.
///
/// # Safety
/// `e` null or a `zw_estimator`; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_kalman(
    e: *mut zw_estimator,
    rate_hz: f64,
    quantization_m: f64,
    q: f64,
    model: i32,
    rho: f64,
    err: *mut zw_error,
) -> zw_status {
    init_guarded(e, || {
        let model = match model {
            m if m == zw_q_model::ZwWhiteJerk as i32 => QModel::WhiteJerk,
            m if m == zw_q_model::ZwDiagonal as i32 => QModel::Diagonal,
            // SAFETY: `err` as the contract.
            _ => {
                return unsafe {
                    explain(
                        err,
                        zw_status::ZwBadParameter,
                        "model",
                        "model must be ZW_WHITE_JERK or ZW_DIAGONAL",
                    )
                }
            }
        };
        let rho = if rho <= 0.0 { None } else { Some(rho) };
        let spec = KindSpec::Kalman { q, model, rho }.into();
        // SAFETY: as the contract.
        unsafe { fill(e, &spec, rate_hz, quantization_m, err) }
    })
}

/// Fill `e` with FOAW: `fit` a `zw_foaw_fit`, band half-width `d_m` ≥ 0 (usually the encoder
/// step), windows of 1 to `max_window` ≤ `ZW_FOAW_MAX_WINDOW` samples.
///
/// # Safety
/// `e` null or a `zw_estimator`; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_foaw(
    e: *mut zw_estimator,
    rate_hz: f64,
    fit: i32,
    d_m: f64,
    max_window: u32,
    outlier_tolerance: bool,
    err: *mut zw_error,
) -> zw_status {
    init_guarded(e, || {
        let fit = match fit {
            f if f == zw_foaw_fit::ZwFoawEnd as i32 => FoawFit::End,
            f if f == zw_foaw_fit::ZwFoawBest as i32 => FoawFit::Best,
            f if f == zw_foaw_fit::ZwFoawBestR as i32 => FoawFit::BestR,
            // SAFETY: `err` as the contract.
            _ => {
                return unsafe {
                    explain(
                        err,
                        zw_status::ZwBadParameter,
                        "fit",
                        "fit must be ZW_FOAW_END, ZW_FOAW_BEST or ZW_FOAW_BEST_R",
                    )
                }
            }
        };
        let spec = KindSpec::Foaw {
            fit,
            d: Some(d_m),
            max_window: max_window as usize,
            outlier_tolerance,
        }
        .into();
        // SAFETY: as the contract.
        unsafe { fill(e, &spec, rate_hz, 1.0, err) }
    })
}

/// Fill `e` with Levant's differentiator (`scheme` a `zw_levant_scheme`), gains `alpha` (m/s²) and
/// `lambda` (m^½/s), each 1e-12 to 1e12.
///
/// # Safety
/// `e` null or a `zw_estimator`; `err` null or a `zw_error`.
#[no_mangle]
pub unsafe extern "C" fn zw_init_levant(
    e: *mut zw_estimator,
    rate_hz: f64,
    alpha: f64,
    lambda: f64,
    scheme: i32,
    err: *mut zw_error,
) -> zw_status {
    use zw_levant_scheme as S;
    init_guarded(e, || {
        let (discretization, output) = match scheme {
            s if s == S::ZwLevantExplicit as i32 => {
                (Discretization::Explicit, ImplicitOutput::State)
            }
            s if s == S::ZwLevantImplicit as i32 => {
                (Discretization::Implicit, ImplicitOutput::State)
            }
            s if s == S::ZwLevantImplicitEq7 as i32 => {
                (Discretization::Implicit, ImplicitOutput::Eq7)
            }
            // SAFETY: `err` as the contract.
            _ => {
                return unsafe {
                    explain(err, zw_status::ZwBadParameter, "scheme", "scheme must be ZW_LEVANT_EXPLICIT, ZW_LEVANT_IMPLICIT or ZW_LEVANT_IMPLICIT_EQ7")
                }
            }
        };
        let spec = KindSpec::Levant {
            alpha,
            lambda,
            discretization,
            output,
        }
        .into();
        // SAFETY: as the contract.
        unsafe { fill(e, &spec, rate_hz, 1.0, err) }
    })
}

/// One position `y` (m) in, the velocity estimate (m/s) into `*v`. A
/// non-finite `y` is refused (`ZW_BAD_PARAMETER`) and changes nothing.
///
/// # Safety
/// `e` null or a `zw_estimator`; `v` null or a `double`.
#[no_mangle]
pub unsafe extern "C" fn zw_step(e: *mut zw_estimator, y: f64, v: *mut f64) -> zw_status {
    guarded(|| {
        if v.is_null() {
            return zw_status::ZwNull;
        }
        // SAFETY: as the contract.
        let est = match unsafe { filled(e) } {
            Ok(est) => est,
            Err(s) => return s,
        };
        if !y.is_finite() {
            return zw_status::ZwBadParameter;
        }
        match finite_step(est, y) {
            // SAFETY: `v` is a valid double, as the contract.
            Some(x) => unsafe { v.write(x) },
            None => return zw_status::ZwBadParameter,
        }
        zw_status::ZwOk
    })
}

/// `zw_step` over `n` positions: `v[i]` from `y[i]`. A non-finite position
/// refuses the whole block before any step (`ZW_BAD_PARAMETER`); a step
/// whose estimate would not be finite resets the state and returns
/// `ZW_BAD_PARAMETER`, the estimates before it written. `e` is checked
/// first (`ZW_NULL`, `ZW_NOT_INITIALIZED`), even when `n` is 0; with `n`
/// 0, `y` and `v` may be null.
///
/// # Safety
/// `e` null or a `zw_estimator`; `y` and `v` null or arrays of `n` doubles
/// (they may be the same array).
#[no_mangle]
pub unsafe extern "C" fn zw_step_n(
    e: *mut zw_estimator,
    y: *const f64,
    v: *mut f64,
    n: usize,
) -> zw_status {
    guarded(|| {
        // SAFETY: as the contract.
        let est = match unsafe { filled(e) } {
            Ok(est) => est,
            Err(s) => return s,
        };
        if n == 0 {
            return zw_status::ZwOk;
        }
        if y.is_null() || v.is_null() {
            return zw_status::ZwNull;
        }
        // Read through raw pointers: `y` and `v` may alias (in place).
        // SAFETY: `y` holds n doubles, as the contract.
        if (0..n).any(|i| !unsafe { y.add(i).read() }.is_finite()) {
            return zw_status::ZwBadParameter;
        }
        for i in 0..n {
            // SAFETY: both hold n doubles, as the contract.
            match finite_step(est, unsafe { y.add(i).read() }) {
                // SAFETY: as above.
                Some(x) => unsafe { v.add(i).write(x) },
                None => return zw_status::ZwBadParameter,
            }
        }
        zw_status::ZwOk
    })
}

/// One step whose estimate is a finite number, or `None` with the state
/// reset (as `zw_reset`): a position far enough out (±1e308 m into a
/// difference) overflows the estimator's arithmetic, and every later
/// estimate would be NaN.
fn finite_step(est: &mut RigEstimator, y: f64) -> Option<f64> {
    let x = est.step(y);
    if x.is_finite() {
        Some(x)
    } else {
        est.reset();
        None
    }
}

/// Forget all history, as if newly filled.
///
/// # Safety
/// `e` null or a `zw_estimator`.
#[no_mangle]
pub unsafe extern "C" fn zw_reset(e: *mut zw_estimator) -> zw_status {
    // SAFETY: as the contract.
    guarded(|| match unsafe { filled(e) } {
        Ok(est) => {
            est.reset();
            zw_status::ZwOk
        }
        Err(s) => s,
    })
}

/// The fingerprint of the built coefficients (FNV-1a over their bits):
/// equal fingerprints, equal velocities from equal positions.
///
/// # Safety
/// `e` null or a `zw_estimator`; `out` null or a `uint64_t`.
#[no_mangle]
pub unsafe extern "C" fn zw_fingerprint(e: *const zw_estimator, out: *mut u64) -> zw_status {
    guarded(|| {
        if out.is_null() {
            return zw_status::ZwNull;
        }
        // SAFETY: as the contract; only read.
        match unsafe { filled_ref(e) } {
            Ok(est) => {
                // SAFETY: `out` is a valid uint64_t, as the contract.
                unsafe { out.write(est.fingerprint()) };
                zw_status::ZwOk
            }
            Err(s) => s,
        }
    })
}

/// The library's identity as JSON, NUL-terminated:
/// `{"version":"…","fingerprints":{"fdm":"<16 hex digits>",…}}`, the
/// reference fingerprint of every kind. A rig's driver puts it under
/// `"dsp"` in its capabilities; the server compares it with its own
/// (docs/rigs.md, "bit-identical estimators"). `*needed` (when not null)
/// gets the bytes it takes with the NUL; a `len` below that writes nothing
/// and returns `ZW_CAPACITY`. 512 bytes always suffice.
///
/// # Safety
/// `buf` null or `len` writable bytes; `needed` null or a `size_t`.
#[no_mangle]
pub unsafe extern "C" fn zw_dsp_identity(
    buf: *mut c_char,
    len: usize,
    needed: *mut usize,
) -> zw_status {
    guarded(|| {
        let json = serde_json::to_string(&zwidth_core::estimators::identity::DspIdentity::ours())
            .unwrap_or_default();
        let size = json.len() + 1;
        // SAFETY: `needed` null or a size_t, as the contract.
        if let Some(n) = unsafe { needed.as_mut() } {
            *n = size;
        }
        if buf.is_null() {
            return zw_status::ZwNull;
        }
        if len < size {
            return zw_status::ZwCapacity;
        }
        // SAFETY: `buf` holds `len` >= `size` writable bytes, as the contract.
        let dst = unsafe { std::slice::from_raw_parts_mut(buf, size) };
        copy_c(dst, &json);
        zw_status::ZwOk
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// Panics the process's own hook saw.
    static SEEN: AtomicUsize = AtomicUsize::new(0);

    /// The library prints nothing of its own panics (issue 45: two threads
    /// on one struct printed caught panics from inside `zw_step`), and
    /// passes every other panic to the hook that was there before. The
    /// only test of this binary: it owns the process's panic hook.
    #[test]
    fn a_panic_inside_is_internal_and_silent_and_others_reach_the_old_hook() {
        std::panic::set_hook(Box::new(|info| {
            eprintln!("{info}");
            SEEN.fetch_add(1, Ordering::SeqCst);
        }));
        assert_eq!(guarded(|| panic!("a bug")), zw_status::ZwInternal);
        assert_eq!(
            SEEN.load(Ordering::SeqCst),
            0,
            "the library's panic was printed"
        );
        assert_eq!(guarded(|| zw_status::ZwOk), zw_status::ZwOk);
        // Outside the library, after the quiet hook is installed: the old
        // hook still sees the panic.
        assert!(std::panic::catch_unwind(|| panic!("the host's")).is_err());
        assert_eq!(SEEN.load(Ordering::SeqCst), 1);
        // A failed init marks the struct unfilled.
        let mut e = Box::new(zw_estimator {
            words: [0; ZW_ESTIMATOR_WORDS],
        });
        let p: *mut zw_estimator = &mut *e;
        // SAFETY: `p` is a valid struct; `err` null is allowed.
        unsafe {
            assert_eq!(zw_init_fdm(p, 1e3, std::ptr::null_mut()), zw_status::ZwOk);
            assert_eq!(init_guarded(p, || panic!("a bug")), zw_status::ZwInternal);
            let mut v = 0.0;
            assert_eq!(zw_step(p, 0.0, &mut v), zw_status::ZwNotInitialized);
        }
        assert_eq!(SEEN.load(Ordering::SeqCst), 1);
    }
}
