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
//! Cost: each candidate window checks up to n samples, so a window that grows
//! to N costs O(N²) comparisons; the history is kept contiguous (a mirrored
//! ring) so the checks are plain slice loops.

use serde::{Deserialize, Serialize};

use super::VelocityEstimator;
use crate::error::SpecError;

/// Largest `max_window` accepted (samples).
pub const MAX_WINDOW_LIMIT: usize = 4096;

/// `max_window` default: 15, the bound Janabi-Sharifi et al. used (§IV-C).
pub const DEFAULT_MAX_WINDOW: usize = 15;

#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FoawFit {
    End,
    Best,
    BestR,
}

impl FoawFit {
    pub fn name(self) -> &'static str {
        match self {
            FoawFit::End => "end",
            FoawFit::Best => "best",
            FoawFit::BestR => "best_r",
        }
    }
}

/// JSON: `{"kind":"foaw","fit":"best","d":1e-6,"max_window":16,"outlier_tolerance":false}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
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

#[derive(Debug, Clone)]
pub struct Foaw {
    fit: FoawFit,
    d: f64,
    max_window: usize,
    outlier_tolerance: bool,
    t: f64,
    /// Mirrored ring of the last `cap = max_window + 1` samples: sample j is at
    /// `j % cap` and `j % cap + cap`, so the newest `cap` are contiguous.
    buf: Vec<f64>,
    cap: usize,
    count: usize,
    last_window: usize,
}

impl Foaw {
    /// `d` ≥ 0 already checked by the caller; `t` > 0.
    pub fn new(spec: &FoawSpec, d: f64, t: f64) -> Result<Self, SpecError> {
        if !(1..=MAX_WINDOW_LIMIT).contains(&spec.max_window) {
            return Err(SpecError::new("max_window", spec.max_window, format!("must be 1 to {MAX_WINDOW_LIMIT} samples")));
        }
        let cap = spec.max_window + 1;
        Ok(Self {
            fit: spec.fit,
            d,
            max_window: spec.max_window,
            outlier_tolerance: spec.outlier_tolerance,
            t,
            buf: vec![0.0; 2 * cap],
            cap,
            count: 0,
            last_window: 0,
        })
    }

    /// Window length n used for the last estimate (0 before the second sample).
    pub fn last_window(&self) -> usize {
        self.last_window
    }

    /// Does every residual fit in ±d? With outlier tolerance, only two
    /// consecutive misses fail.
    #[inline]
    fn fits(&self, residuals: impl Iterator<Item = f64>) -> bool {
        let d = self.d;
        if !self.outlier_tolerance {
            // `fold` rather than `all`: no early exit lets the loop vectorize.
            residuals.fold(true, |ok, r| ok & (r.abs() <= d))
        } else {
            let mut prev_miss = false;
            for r in residuals {
                let miss = r.abs() > d;
                if miss && prev_miss {
                    return false;
                }
                prev_miss = miss;
            }
            true
        }
    }
}

impl VelocityEstimator for Foaw {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        let slot = self.count % self.cap;
        self.buf[slot] = y;
        self.buf[slot + self.cap] = y;
        self.count += 1;
        let avail = (self.count - 1).min(self.max_window);
        if avail == 0 {
            self.last_window = 0;
            return 0.0;
        }
        // w[0..=avail] oldest..newest, so y_{k−i} = w[avail − i].
        let end = slot + self.cap + 1;
        let w = &self.buf[end - avail - 1..end];
        let yk = w[avail];
        let t = self.t;
        let mut best = (yk - w[avail - 1]) / t;
        let mut best_n = 1;
        // Running sums over i = 0..=n of y_{k−i} and i·y_{k−i} for eq. 17.
        let (mut s0, mut s1) = (yk + w[avail - 1], w[avail - 1]);
        let mut failed_once = false;
        for n in 1..=avail {
            if n > 1 {
                let yn = w[avail - n];
                s0 += yn;
                s1 += n as f64 * yn;
            }
            let nf = n as f64;
            let win = &w[avail - n..=avail]; // y_{k−n} … y_k
            let (ok, slope) = match self.fit {
                FoawFit::End => {
                    // Line through y_k and y_{k−n}; interior samples checked.
                    let step = (yk - win[0]) / nf; // rise per sample
                    let ok = n == 1 || self.fits(win[1..n].iter().enumerate().map(|(j, &v)| v - (win[0] + step * (j + 1) as f64)));
                    (ok, step / t)
                }
                FoawFit::Best | FoawFit::BestR => {
                    // Eq. 17: b_n = (n Σ y_{k−i} − 2 Σ i y_{k−i}) / (T n(n+1)(n+2)/6).
                    let step = (nf * s0 - 2.0 * s1) / (nf * (nf + 1.0) * (nf + 2.0) / 6.0);
                    let ok = if self.fit == FoawFit::Best {
                        // Anchored at y_k: L(k−i) = y_k − step·i.
                        self.fits(win[..n].iter().enumerate().map(|(j, &v)| v - (yk - step * (n - j) as f64)))
                    } else {
                        // Through the centroid (mean at i = n/2).
                        let mean = s0 / (nf + 1.0);
                        let half = 0.5 * nf;
                        self.fits(win.iter().enumerate().map(|(j, &v)| v - (mean + step * (j as f64 - half))))
                    };
                    (ok, step / t)
                }
            };
            if !ok {
                // With tolerance a single failing length (an outlier at the
                // far end of the window) is skipped; two in a row stop growth.
                if self.outlier_tolerance && !failed_once {
                    failed_once = true;
                    continue;
                }
                break;
            }
            failed_once = false;
            best = slope;
            best_n = n;
        }
        self.last_window = best_n;
        best
    }

    fn reset(&mut self) {
        self.count = 0;
        self.last_window = 0;
        self.buf.iter_mut().for_each(|v| *v = 0.0);
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
        let ys: Vec<f64> = (0..12).map(|k| k as f64 + if k == 5 { 3.0 } else { 0.0 }).collect();
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
        spec.max_window = 0;
        assert_eq!(Foaw::new(&spec, 0.1, 1.0).unwrap_err().field, "max_window");
    }
}
