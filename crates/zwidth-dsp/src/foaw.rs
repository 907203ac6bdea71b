//! First-order adaptive windowing, FOAW (Janabi-Sharifi, Hayward & Chen
//! 2000, §III).
//!
//! At sample k the window grows, n = 1, 2, …, `max_window` (never past the
//! samples seen), while a straight line fits every sample in it within the
//! uncertainty band ±d (eq. 13); the estimate is the slope for the longest
//! window that fits. Growth stops at the first window that fails (Step 5).
//! Which line each sample is checked against:
//!
//! - `End` (end-fit, eqs. 13–14): the line through `y_k` and `y_{k−n}`, slope
//!   `(y_k − y_{k−n})/(nT)`; the interior samples `y_{k−1} … y_{k−n+1}` are checked.
//! - `Best` (best-fit): the paper's Steps 2–5 unchanged except that Step 3
//!   takes the least-squares slope `b_n` of eq. 17 over `y_k … y_{k−n}`; the line
//!   keeps its anchor at the last sample, `L(k−i) = y_k − b_n·i·T`, and
//!   `y_{k−1} … y_{k−n}` are checked.
//! - `BestR` (best-fit-R): the window is decided on the least-squares line
//!   itself — slope `b_n`, through the window's centroid — and all n+1 samples
//!   `y_k … y_{k−n}` are checked against it.
//!
//! With `outlier_tolerance` (§III-B: "stop the window growth if at least two
//! consecutive samples fall out of the fit"), a window passes unless two
//! consecutive samples miss the band, and a single failing window length (an
//! outlier at the far end of the window) is skipped: growth stops only when
//! two consecutive lengths fail.
//!
//! The first output is 0 (one sample has no slope).
//!
//! Cost (the bound of `step`): `End` and `Best` lines are anchored at y_k,
//! so the slopes that fit each sample form an interval and the window test
//! is an interval intersection that grows by one sample per n: at most N
//! iterations for a window of N. `BestR` (and outlier tolerance) rescan the
//! window for each n: at most N(N+3)/2 residuals, in a branch-free loop.
//! The state holds `max_window + 1 ≤ CAP` samples (mirrored: 2·CAP).

use crate::Error;

/// Relative slack on the band ±d: residuals within d·(1 + 1e-9) count as
/// inside. A quantized position n·q carries a rounding error of about
/// 1e-16·|y| (1e-16 m at 1 m from the origin: 1e-10 of a 1 µm step), so
/// ties decided by rounding fall inside the slack for |y| up to ~10 m,
/// while 1e-9 of a 1 µm step is a femtometre: no physical difference.
pub const BAND_SLACK: f64 = 1e-9;

/// The band's half-width with its slack (see [`BAND_SLACK`]).
pub fn band(d: f64) -> f64 {
    d * (1.0 + BAND_SLACK)
}

/// `max_window`'s default: 15, the bound Janabi-Sharifi et al. used (§IV-C).
pub const DEFAULT_MAX_WINDOW: usize = 15;

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FoawFit {
    End,
    Best,
    BestR,
}

/// FOAW holding windows of up to `CAP − 1` samples.
#[derive(Debug, Clone, PartialEq)]
pub struct Foaw<const CAP: usize> {
    fit: FoawFit,
    d: f64,
    max_window: usize,
    outlier_tolerance: bool,
    t: f64,
    /// Mirrored ring of the last `cap = max_window + 1` samples: sample j is
    /// at `j % cap` and `j % cap + cap` of the flattened pair, so the newest
    /// `cap` are contiguous.
    buf: [[f64; CAP]; 2],
    cap: usize,
    /// Scratch: u_i = y_{k−i} − y_k; and the constants i and 1/i as f64.
    u: [f64; CAP],
    idx: [f64; CAP],
    inv_idx: [f64; CAP],
    /// 6/(n(n+1)(n+2)), eq. 17's denominator.
    inv_lsq: [f64; CAP],
    /// Where the next sample goes (0..cap), and how many were seen (at
    /// most cap: no counter to wrap on a 32-bit controller running for days).
    next: usize,
    seen: usize,
    last_window: usize,
}

impl<const CAP: usize> Foaw<CAP> {
    /// `d` ≥ 0 (m), the band's half-width; `max_window` from 1 to
    /// `CAP − 1`; the sample period `t` > 0 (s).
    pub fn new(
        fit: FoawFit,
        d: f64,
        max_window: usize,
        outlier_tolerance: bool,
        t: f64,
    ) -> Result<Self, Error> {
        crate::error::positive("period", t)?;
        if !(d.is_finite() && d >= 0.0) {
            return Err(Error::Parameter {
                name: "d",
                value: d,
                allowed: "must be a finite number >= 0 (m)",
            });
        }
        if max_window == 0 {
            return Err(Error::Parameter {
                name: "max_window",
                value: 0.0,
                allowed: "must be at least 1 sample",
            });
        }
        if max_window + 1 > CAP {
            return Err(Error::Capacity {
                name: "max_window",
                value: max_window,
                cap: CAP.saturating_sub(1),
            });
        }
        let cap = max_window + 1;
        let mut idx = [0.0; CAP];
        let mut inv_idx = [0.0; CAP];
        let mut inv_lsq = [0.0; CAP];
        for i in 1..cap {
            idx[i] = i as f64;
            inv_idx[i] = 1.0 / i as f64;
            inv_lsq[i] = 6.0 / (i * (i + 1) * (i + 2)) as f64;
        }
        Ok(Self {
            fit,
            // The band is closed (eq. 13: |residual| ≤ d). On quantized data
            // with d one encoder step, residuals of exactly d are common and
            // rounding would decide them, differently in metres and in
            // counts; a relative slack far below any physical length makes
            // the closed band exact (`BAND_SLACK`).
            d: band(d),
            max_window,
            outlier_tolerance,
            t,
            buf: [[0.0; CAP]; 2],
            cap,
            u: [0.0; CAP],
            idx,
            inv_idx,
            inv_lsq,
            next: 0,
            seen: 0,
            last_window: 0,
        })
    }

    /// Window length n used for the last estimate (0 before the second sample).
    pub fn last_window(&self) -> usize {
        self.last_window
    }

    /// The fit, the longest window and whether outliers are tolerated.
    pub fn shape(&self) -> (FoawFit, usize, bool) {
        (self.fit, self.max_window, self.outlier_tolerance)
    }

    /// The band's half-width with its slack (m) and the period (s).
    pub fn coefficients(&self) -> (f64, f64) {
        (self.d, self.t)
    }

    /// `End` and `Best` without outlier tolerance. The line y_k − s·i fits
    /// sample i iff s ∈ [(−d − u_i)/i, (d − u_i)/i], so a window fits iff its
    /// slope lies in the intersection over its samples, which grows by one
    /// sample per n. Returns (slope as rise per sample, window length).
    #[inline]
    fn anchored_window(&self, avail: usize) -> (f64, usize) {
        let d = self.d;
        let u = &self.u[1..=avail];
        let idx = &self.idx[1..=avail];
        let inv = &self.inv_idx[1..=avail];
        let (mut lo, mut hi) = (f64::NEG_INFINITY, f64::INFINITY);
        let mut best = (-u[0], 1);
        match self.fit {
            FoawFit::End => {
                // Window n = j + 1 checks the interior i = 1..n−1: add i = n−1 = j.
                for j in 1..u.len() {
                    let (a, b) = ((-d - u[j - 1]) * inv[j - 1], (d - u[j - 1]) * inv[j - 1]);
                    lo = if a > lo { a } else { lo };
                    hi = if b < hi { b } else { hi };
                    // Line through y_k and y_{k−n} (eq. 14).
                    let step = -u[j] * inv[j];
                    if !(lo <= step && step <= hi) {
                        break;
                    }
                    best = (step, j + 1);
                }
            }
            _ => {
                let lsq = &self.inv_lsq[1..=avail];
                let (mut s0, mut s1) = (0.0, 0.0);
                // Window n = j + 1 checks i = 1..n: add i = n.
                for j in 0..u.len() {
                    s0 += u[j];
                    s1 += idx[j] * u[j];
                    // Eq. 17: b_n·T = (n Σ u_i − 2 Σ i u_i) · 6/(n(n+1)(n+2)).
                    let step = (idx[j] * s0 - 2.0 * s1) * lsq[j];
                    let (a, b) = ((-d - u[j]) * inv[j], (d - u[j]) * inv[j]);
                    lo = if a > lo { a } else { lo };
                    hi = if b < hi { b } else { hi };
                    if !(lo <= step && step <= hi) {
                        break;
                    }
                    best = (step, j + 1);
                }
            }
        }
        best
    }

    /// `BestR`, or any fit with outlier tolerance: every window is rescanned.
    fn rescanned_window(&self, avail: usize) -> (f64, usize) {
        let (u, idx) = (&self.u[..=avail], &self.idx[..=avail]);
        let mut best = (-u[1], 1);
        let (mut s0, mut s1) = (0.0, 0.0);
        let mut failed_once = false;
        for n in 1..=avail {
            let nf = idx[n];
            s0 += u[n];
            s1 += nf * u[n];
            let step = match self.fit {
                FoawFit::End => -u[n] * self.inv_idx[n],
                FoawFit::Best | FoawFit::BestR => (nf * s0 - 2.0 * s1) * self.inv_lsq[n],
            };
            // Residual r_i = u_i + step·i − c over the checked samples.
            let ok = match self.fit {
                FoawFit::End => self.fits(&u[1..n], &idx[1..n], step, 0.0),
                FoawFit::Best => self.fits(&u[1..=n], &idx[1..=n], step, 0.0),
                // Through the centroid: c = ū + step·n/2.
                FoawFit::BestR => self.fits(
                    &u[..=n],
                    &idx[..=n],
                    step,
                    s0 / (nf + 1.0) + 0.5 * step * nf,
                ),
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
            best = (step, n);
        }
        best
    }

    /// Does every residual `u_i + step·i − c` fit in ±d? With outlier
    /// tolerance, only two consecutive misses fail.
    #[inline]
    fn fits(&self, u: &[f64], idx: &[f64], step: f64, c: f64) -> bool {
        let d = self.d;
        let abs = crate::math::abs;
        if !self.outlier_tolerance {
            // No early exit, so the loop vectorizes.
            let mut ok = true;
            for (&ui, &i) in u.iter().zip(idx) {
                ok &= abs(ui + step * i - c) <= d;
            }
            ok
        } else {
            let mut prev_miss = false;
            for (&ui, &i) in u.iter().zip(idx) {
                let miss = abs(ui + step * i - c) > d;
                if miss && prev_miss {
                    return false;
                }
                prev_miss = miss;
            }
            true
        }
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        let cap = self.cap;
        let slot = self.next;
        self.next = if slot + 1 == cap { 0 } else { slot + 1 };
        let flat = self.buf.as_flattened_mut();
        flat[slot] = y;
        flat[slot + cap] = y;
        self.seen = (self.seen + 1).min(cap);
        let avail = (self.seen - 1).min(self.max_window);
        if avail == 0 {
            self.last_window = 0;
            return 0.0;
        }
        // u_i = y_{k−i} − y_k, i = 0..=avail: positions relative to the newest
        // sample (small numbers even 10 m from the origin). Every line below
        // is written in these terms; a slope is "rise per sample" (m).
        let base = slot + cap;
        let flat = self.buf.as_flattened();
        for i in 0..=avail {
            self.u[i] = flat[base - i] - y;
        }
        let (best, best_n) = if !self.outlier_tolerance && self.fit != FoawFit::BestR {
            self.anchored_window(avail)
        } else {
            self.rescanned_window(avail)
        };
        self.last_window = best_n;
        best / self.t
    }

    pub fn reset(&mut self) {
        self.next = 0;
        self.seen = 0;
        self.last_window = 0;
        self.buf = [[0.0; CAP]; 2];
        self.u = [0.0; CAP];
    }
}
