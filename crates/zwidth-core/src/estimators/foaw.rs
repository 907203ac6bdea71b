//! First-order adaptive windowing, FOAW (Janabi-Sharifi, Hayward & Chen 2000, §III).
//!
//! At sample k the window grows, n = 1, 2, …, `max_window` (never past the
//! samples seen), while a straight line fits every sample in it within the
//! uncertainty band ±d (eq. 13); the estimate is the slope for the longest
//! window that fits. Growth stops at the first window that fails (Step 5).
//! Which line each sample is checked against:
//!
//! - `end` (end-fit, eqs. 13–14): the line through `y_k` and `y_{k−n}`, slope
//!   `(y_k − y_{k−n})/(nT)`; the interior samples `y_{k−1} … y_{k−n+1}` are checked.
//! - `best` (best-fit): the paper's Steps 2–5 unchanged except that Step 3
//!   takes the least-squares slope `b_n` of eq. 17 over `y_k … y_{k−n}`; the line
//!   keeps its anchor at the last sample, `L(k−i) = y_k − b_n·i·T`, and
//!   `y_{k−1} … y_{k−n}` are checked.
//! - `best_r` (best-fit-R): the window is decided on the least-squares line
//!   itself — slope `b_n`, through the window's centroid — and all n+1 samples
//!   `y_k … y_{k−n}` are checked against it.
//!
//! With `outlier_tolerance` (§III-B: "stop the window growth if at least two
//! consecutive samples fall out of the fit"), a window passes unless two
//! consecutive samples miss the band, and a single failing window length (an
//! outlier at the far end of the window) is skipped: growth stops only when
//! two consecutive lengths fail.
//!
//! The first output is 0 (one sample has no slope). With `d = 0` end-fit grows
//! only over exactly collinear samples, whose end-fit slope is the FDM slope,
//! so it equals FDM (tested).
//!
//! Cost: `end` and `best` lines are anchored at y_k, so the slopes that fit
//! each sample form an interval and the window test is an interval
//! intersection that grows by one sample per n: O(N) per sample for a window
//! of N. `best_r` (and outlier tolerance) rescan the window for each n, O(N²),
//! in a branch-free loop over contiguous slices.
//!
//! The estimator is `zwidth_dsp::Foaw` (one implementation, here and on the
//! rig): windows up to the rig's cap in the rig's state, longer ones in
//! the simulator's.

use serde::{Deserialize, Serialize};

use super::streaming::{spec_error, VelocityEstimator};
use crate::error::SpecError;
use zwidth_dsp::estimator::RIG_FOAW_WINDOW;

pub use zwidth_dsp::foaw::{BAND_SLACK, DEFAULT_MAX_WINDOW};

/// Largest `max_window` accepted (samples).
pub const MAX_WINDOW_LIMIT: usize = 4096;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum FoawFit {
    End,
    Best,
    BestR,
}

impl FoawFit {
    pub fn dsp(self) -> zwidth_dsp::FoawFit {
        match self {
            FoawFit::End => zwidth_dsp::FoawFit::End,
            FoawFit::Best => zwidth_dsp::FoawFit::Best,
            FoawFit::BestR => zwidth_dsp::FoawFit::BestR,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            FoawFit::End => "end",
            FoawFit::Best => "best",
            FoawFit::BestR => "best_r",
        }
    }
}

/// JSON: `{"kind":"foaw","fit":"best","d":1e-6,"max_window":16,"outlier_tolerance":false}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct FoawSpec {
    pub fit: FoawFit,
    /// Half-width of the uncertainty band (m); defaults to the quantization step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub d: Option<f64>,
    /// Longest window n (samples), 1 to 4096.
    #[serde(default = "default_max_window")]
    pub max_window: usize,
    #[serde(default)]
    pub outlier_tolerance: bool,
}

fn default_max_window() -> usize {
    DEFAULT_MAX_WINDOW
}

/// FOAW: windows up to the rig's cap in its state (3 KiB), longer ones
/// in the simulator's (4097 samples, 192 KiB); boxed, so an estimator
/// stays small.
#[derive(Debug, Clone)]
pub enum Foaw {
    Small(Box<zwidth_dsp::Foaw<{ RIG_FOAW_WINDOW + 1 }>>),
    Large(Box<zwidth_dsp::Foaw<{ MAX_WINDOW_LIMIT + 1 }>>),
}

impl Foaw {
    /// `d` ≥ 0 already checked by the caller; `t` > 0.
    pub fn new(spec: &FoawSpec, d: f64, t: f64) -> Result<Self, SpecError> {
        if !(1..=MAX_WINDOW_LIMIT).contains(&spec.max_window) {
            return Err(SpecError::new(
                "max_window",
                spec.max_window,
                format!("must be 1 to {MAX_WINDOW_LIMIT} samples"),
            ));
        }
        let (fit, w, tol) = (spec.fit.dsp(), spec.max_window, spec.outlier_tolerance);
        let built = if w <= RIG_FOAW_WINDOW {
            zwidth_dsp::Foaw::new(fit, d, w, tol, t).map(|f| Foaw::Small(Box::new(f)))
        } else {
            zwidth_dsp::Foaw::new(fit, d, w, tol, t).map(|f| Foaw::Large(Box::new(f)))
        };
        built.map_err(spec_error)
    }

    /// Window length n used for the last estimate (0 before the second sample).
    pub fn last_window(&self) -> usize {
        match self {
            Foaw::Small(f) => f.last_window(),
            Foaw::Large(f) => f.last_window(),
        }
    }
}

impl VelocityEstimator for Foaw {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        match self {
            Foaw::Small(f) => f.step(y),
            Foaw::Large(f) => f.step(y),
        }
    }

    fn reset(&mut self) {
        match self {
            Foaw::Small(f) => f.reset(),
            Foaw::Large(f) => f.reset(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::estimators::Fdm;
    use proptest::prelude::*;

    fn foaw(fit: FoawFit, d: f64, max_window: usize, t: f64) -> Foaw {
        let spec = FoawSpec {
            fit,
            d: Some(d),
            max_window,
            outlier_tolerance: false,
        };
        Foaw::new(&spec, d, t).unwrap()
    }

    proptest! {
        // The anchor: end-fit with d = 0 equals FDM.
        #[test]
        fn end_fit_with_zero_band_is_fdm(ys in proptest::collection::vec(-1e-2f64..1e-2, 2..200), mw in 1usize..40) {
            let t = 1e-4;
            let mut f = foaw(FoawFit::End, 0.0, mw, t);
            let mut fdm = Fdm::new(t);
            for y in ys {
                let a = f.update(y);
                let b = fdm.update(y);
                prop_assert!((a - b).abs() <= 1e-9 * b.abs().max(1.0), "{} vs {}", a, b);
            }
        }
    }

    /// The definition written out plainly (y terms, every window rescanned):
    /// the independent reference for the interval-intersection shortcut.
    fn brute_force(
        fit: FoawFit,
        d: f64,
        max_window: usize,
        t: f64,
        ys: &[f64],
    ) -> Vec<(f64, usize)> {
        (0..ys.len())
            .map(|k| {
                if k == 0 {
                    return (0.0, 0);
                }
                let y = |i: usize| ys[k - i];
                let mut best = ((y(0) - y(1)) / t, 1);
                for n in 1..=k.min(max_window) {
                    let (slope, fits) = match fit {
                        FoawFit::End => {
                            let b = (y(0) - y(n)) / (n as f64 * t);
                            (
                                b,
                                (1..n).all(|i| (y(i) - (y(0) - b * i as f64 * t)).abs() <= d),
                            )
                        }
                        _ => {
                            let s0: f64 = (0..=n).map(y).sum();
                            let s1: f64 = (0..=n).map(|i| i as f64 * y(i)).sum();
                            let nf = n as f64;
                            let b = (nf * s0 - 2.0 * s1) / (t * nf * (nf + 1.0) * (nf + 2.0) / 6.0);
                            let fits = if fit == FoawFit::Best {
                                (1..=n).all(|i| (y(i) - (y(0) - b * i as f64 * t)).abs() <= d)
                            } else {
                                let mean = s0 / (nf + 1.0);
                                (0..=n).all(|i| {
                                    (y(i) - (mean + b * t * (nf / 2.0 - i as f64))).abs() <= d
                                })
                            };
                            (b, fits)
                        }
                    };
                    if !fits {
                        break;
                    }
                    best = (slope, n);
                }
                best
            })
            .collect()
    }

    proptest! {
        #[test]
        fn matches_brute_force_definition(
            steps in proptest::collection::vec(-2i32..=3, 2..150),
            mw in 1usize..40,
            which in 0usize..3,
        ) {
            // A quantized random walk (1 µm steps at 1 kHz), band d = 1.2345 µm
            // so that no residual (a rational in µm with a small denominator)
            // sits exactly on the band edge, where rounding would decide.
            let fit = [FoawFit::End, FoawFit::Best, FoawFit::BestR][which];
            let mut y = 0.0;
            let ys: Vec<f64> = steps.iter().map(|&s| { y += s as f64 * 1e-6; y }).collect();
            let want = brute_force(fit, 1.2345e-6, mw, 1e-3, &ys);
            let mut f = foaw(fit, 1.2345e-6, mw, 1e-3);
            for (k, (&yk, (wv, wn))) in ys.iter().zip(want).enumerate() {
                let v = f.update(yk);
                prop_assert_eq!(f.last_window(), wn, "k={}", k);
                prop_assert!((v - wv).abs() <= 1e-9 * wv.abs().max(1e-3), "k={}: {} vs {}", k, v, wv);
            }
        }
    }

    /// SplitMix64 -> uniform in [−1, 1): a small deterministic noise source.
    fn uniform(state: &mut u64) -> f64 {
        *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = *state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }

    #[test]
    fn band_edge_ties_do_not_depend_on_the_unit() {
        // Issue 11's case: end fit, 1 kHz, d = one encoder step. The third
        // sample's 2-sample window has its interior residual exactly d
        // (13 against the line 12 → 16 at 14): inside the closed band of
        // eq. 13, so the estimate is (16 − 12)/2 steps per ms = 2000 steps/s.
        for (unit, d) in [(1e-6, 1e-6), (1.0, 1.0), (1e-3, 1e-3)] {
            let mut f = foaw(FoawFit::End, d, 15, 1e-3);
            let out: Vec<f64> = [12.0, 13.0, 16.0]
                .iter()
                .map(|&c| f.update(c * unit))
                .collect();
            assert!(
                (out[2] / unit - 2000.0).abs() < 1e-6,
                "unit {unit}: {out:?}"
            );
            assert_eq!(f.last_window(), 2, "unit {unit}");
        }
        // A quantized sine in metres and in counts: every output the same
        // up to the unit, every window the same length.
        let q = 1e-6;
        for fit in [FoawFit::End, FoawFit::Best, FoawFit::BestR] {
            let mut fm = foaw(fit, q, 15, 1e-3);
            let mut fc = foaw(fit, 1.0, 15, 1e-3);
            for k in 0..3000 {
                let x = 3e-4 * (2.0 * std::f64::consts::PI * 1.3 * k as f64 * 1e-3).sin();
                let counts = (x / q).round();
                let (vm, vc) = (fm.update(counts * q), fc.update(counts));
                assert_eq!(fm.last_window(), fc.last_window(), "{fit:?} k={k}");
                assert!(
                    (vm / q - vc).abs() <= 1e-6 * vc.abs().max(1.0),
                    "{fit:?} k={k}: {vm} vs {vc}"
                );
            }
        }
    }

    #[test]
    fn end_fit_variance_follows_eq_16() {
        // Janabi-Sharifi eq. 16: with noise uniform in ±d, the end-fit slope
        // over a window of n has variance 2d²/(3n²T²). A band of 2d + ε
        // holds every interior sample (|e_i − interpolated endpoint error|
        // ≤ 2d), so the window is always n and eq. 16 applies exactly.
        let (d, t, v) = (1e-6, 1e-3, 0.05);
        let mut rng = 0x5EED;
        for n in [1usize, 4, 16] {
            let mut f = foaw(FoawFit::End, 2.0 * d + 1e-12, n, t);
            let (mut sum, mut sum2, mut count) = (0.0, 0.0, 0.0);
            for k in 0..200_000 {
                let y = v * k as f64 * t + d * uniform(&mut rng);
                let e = f.update(y);
                if k > n {
                    assert_eq!(f.last_window(), n);
                    sum += e;
                    sum2 += e * e;
                    count += 1.0;
                }
            }
            let mean = sum / count;
            let var = sum2 / count - mean * mean;
            let theory = 2.0 * d * d / (3.0 * (n * n) as f64 * t * t);
            // 2e5 samples: the sample variance's relative standard error is
            // below 1 %; allow 4 %.
            assert!(
                (var / theory - 1.0).abs() < 0.04,
                "n={n}: {var} vs {theory}"
            );
            assert!(
                (mean - v).abs() < 4.0 * (theory / count).sqrt() * (n as f64).sqrt(),
                "n={n}: mean {mean}"
            );
        }
    }

    #[test]
    fn exact_ramp_grows_to_max_window_and_is_exact() {
        for fit in [FoawFit::End, FoawFit::Best, FoawFit::BestR] {
            let mut f = foaw(fit, 1e-9, 16, 1e-3);
            let mut v = 0.0;
            for k in 0..100 {
                v = f.update(0.25 * k as f64 * 1e-3);
            }
            assert_eq!(f.last_window(), 16, "{fit:?}");
            assert!((v - 0.25).abs() < 1e-9, "{fit:?}: {v}");
        }
    }

    #[test]
    fn hand_computed_window() {
        // T = 1, d = 0.1: y = 0, 0, 0, 1. End-fit at k=3: n=1 slope 1; n=2 line
        // through y3=1 and y1=0 passes y2 at 0.5 (miss, |0 − 0.5| > 0.1) -> stop, v = 1.
        let mut f = foaw(FoawFit::End, 0.1, 8, 1.0);
        for y in [0.0, 0.0, 0.0] {
            f.update(y);
        }
        assert_eq!(f.update(1.0), 1.0);
        assert_eq!(f.last_window(), 1);
        // y = 0, 0.05, 0.1, 0.2 at k=3: n=3 end line slope 0.2/3 -> y1 at 1/15 (ok), y2 at 2/15 (ok): v = 0.2/3.
        let mut f = foaw(FoawFit::End, 0.1, 8, 1.0);
        for y in [0.0, 0.05, 0.1] {
            f.update(y);
        }
        assert!((f.update(0.2) - 0.2 / 3.0).abs() < 1e-15);
        assert_eq!(f.last_window(), 3);
    }

    #[test]
    fn eq17_is_least_squares_slope() {
        // Independent: closed-form LS slope of (t_i, y_i) by normal equations.
        let ys = [0.3, 0.1, 0.45, 0.2, 0.9, 0.7];
        let mut f = foaw(FoawFit::Best, 10.0, 5, 0.5); // huge band: window = 5
        let mut v = 0.0;
        for y in ys {
            v = f.update(y);
        }
        let ts: Vec<f64> = (0..6).map(|i| i as f64 * 0.5).collect();
        let (mt, my) = (ts.iter().sum::<f64>() / 6.0, ys.iter().sum::<f64>() / 6.0);
        let num: f64 = ts.iter().zip(ys).map(|(t, y)| (t - mt) * (y - my)).sum();
        let den: f64 = ts.iter().map(|t| (t - mt) * (t - mt)).sum();
        assert!((v - num / den).abs() < 1e-12, "{v} vs {}", num / den);
    }

    #[test]
    fn outlier_tolerance_skips_a_single_miss() {
        // Ramp with one spike at k=5: the plain end-fit window stops at the
        // spike; with tolerance it grows past it.
        let ys: Vec<f64> = (0..12)
            .map(|k| k as f64 + if k == 5 { 3.0 } else { 0.0 })
            .collect();
        let mut plain = foaw(FoawFit::End, 0.1, 10, 1.0);
        let mut spec = FoawSpec {
            fit: FoawFit::End,
            d: Some(0.1),
            max_window: 10,
            outlier_tolerance: true,
        };
        let mut tol = Foaw::new(&spec, 0.1, 1.0).unwrap();
        for &y in &ys {
            plain.update(y);
            tol.update(y);
        }
        assert_eq!(plain.last_window(), 5);
        assert_eq!(tol.last_window(), 10);
        // Two adjacent spikes (k = 5, 6): §III-B stops growth at two
        // consecutive misses. Windows ending on either spike fail (the
        // end-fit line runs through it), so growth stops before them: the
        // window of 4 (samples 7…11), as without tolerance.
        let ys2: Vec<f64> = (0..12)
            .map(|k| k as f64 + if k == 5 || k == 6 { 3.0 } else { 0.0 })
            .collect();
        let mut tol2 = Foaw::new(&spec, 0.1, 1.0).unwrap();
        let mut plain2 = foaw(FoawFit::End, 0.1, 10, 1.0);
        for &y in &ys2 {
            tol2.update(y);
            plain2.update(y);
        }
        assert_eq!((tol2.last_window(), plain2.last_window()), (4, 4));
        // A spike inside the window that sits exactly on the band's edge
        // (residual = d) is not a miss: the window is not cut there.
        let ys3: Vec<f64> = (0..12)
            .map(|k| k as f64 + if k == 8 { 0.1 } else { 0.0 })
            .collect();
        let mut tol3 = Foaw::new(&spec, 0.1, 1.0).unwrap();
        for &y in &ys3 {
            tol3.update(y);
        }
        assert_eq!(tol3.last_window(), 10);
        spec.max_window = 0;
        assert_eq!(Foaw::new(&spec, 0.1, 1.0).unwrap_err().field, "max_window");
    }
}
