//! `step` allocates nothing: every kind and variant at its caps, stepped
//! through a chirp under a counting global allocator (the crate is
//! `no_std` without `alloc`, so this holds by construction; the test keeps
//! it so if that ever changes).

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;

use zwidth_dsp::estimator::{RIG_FOAW_WINDOW, RIG_MEDIAN};
use zwidth_dsp::{Discretization, FoawFit, ImplicitOutput, KindSpec, QModel, RigEstimator, Spec};

struct Counting;

thread_local! {
    /// This thread's allocations (the harness's own threads not counted).
    static ALLOCATIONS: Cell<usize> = const { Cell::new(0) };
}

fn allocations() -> usize {
    ALLOCATIONS.with(Cell::get)
}

unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let _ = ALLOCATIONS.try_with(|n| n.set(n.get() + 1));
        unsafe { System.alloc(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

/// Every kind at its caps (order 10, FOAW window 64 with outlier
/// tolerance, medians of 63).
fn specs() -> Vec<Spec> {
    let mut kinds = vec![
        KindSpec::Fdm,
        KindSpec::Butterworth {
            cutoff_hz: 100.0,
            order: 10,
        },
        KindSpec::Kalman {
            q: 1e4,
            model: QModel::WhiteJerk,
            rho: None,
        },
        KindSpec::Kalman {
            q: 1e4,
            model: QModel::Diagonal,
            rho: Some(0.95),
        },
    ];
    for fit in [FoawFit::End, FoawFit::Best, FoawFit::BestR] {
        for outlier_tolerance in [false, true] {
            kinds.push(KindSpec::Foaw {
                fit,
                d: None,
                max_window: RIG_FOAW_WINDOW,
                outlier_tolerance,
            });
        }
    }
    for (discretization, output) in [
        (Discretization::Explicit, ImplicitOutput::State),
        (Discretization::Implicit, ImplicitOutput::State),
        (Discretization::Implicit, ImplicitOutput::Eq7),
    ] {
        kinds.push(KindSpec::Levant {
            alpha: 13.2,
            lambda: 3.46,
            discretization,
            output,
        });
    }
    kinds
        .into_iter()
        .map(|kind| Spec {
            kind,
            median_position: Some(RIG_MEDIAN),
            median_velocity: Some(RIG_MEDIAN),
        })
        .collect()
}

#[test]
fn step_reset_and_build_allocate_nothing() {
    let specs = specs();
    let ys: Vec<f64> = (0..5000)
        .map(|k| ((0.002 * (k as f64).powf(1.4)).sin() * 5e-3 / 1e-6).round() * 1e-6)
        .collect();
    let mut out = vec![0.0; ys.len()];
    for spec in &specs {
        let before = allocations();
        let mut e = RigEstimator::new(spec, 1e4, 1e-6).unwrap();
        for &y in &ys {
            std::hint::black_box(e.step(y));
        }
        e.reset();
        e.step_n(&ys, &mut out);
        let after = allocations();
        assert_eq!(after, before, "{spec:?} allocated");
        assert!(out.iter().all(|v| v.is_finite()), "{spec:?}");
    }
    // The counter counts: an allocation here is seen.
    let before = allocations();
    std::hint::black_box(vec![1u8; 16]);
    assert!(allocations() > before);
}
