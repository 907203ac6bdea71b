//! Periodic multisine excitation and excited-line estimation.
//!
//! The excitation is a Schroeder-phased multisine (Schroeder 1970; Pintelon &
//! Schoukens 2012, the 2018 paper's ref. [35]): lines at k·f0, k = 1…L,
//! equal amplitudes, phases `φ_k = −π·k(k−1)/L` for a low crest factor,
//! scaled to a given peak force. One period is 1/f0; records hold whole
//! periods, so each line falls exactly on a DFT bin and nothing leaks.

use num_complex::Complex64 as C;
use realfft::{RealFftPlanner, RealToComplex};
use std::collections::HashSet;
use std::sync::{Arc, Mutex, MutexGuard, OnceLock, PoisonError};

/// The process's FFT plans, kept by length. Planning a 4 000-point FFT
/// computes its twiddles (one `sincos` each): done afresh for every
/// realization it cost 15 % of a noisy map's time (perf, issue 34).
/// Planning is deterministic, so a kept plan is the plan a new planner would
/// make: results are the same bit for bit.
struct Plans {
    planner: RealFftPlanner<f64>,
    lengths: HashSet<usize>,
}

/// Distinct lengths kept before the cache starts afresh: a long-running
/// service sees a few per scene, and a stream of odd scenes must not grow
/// it without end.
const MAX_PLANNED_LENGTHS: usize = 64;

fn plans(n: usize) -> MutexGuard<'static, Plans> {
    static PLANS: OnceLock<Mutex<Plans>> = OnceLock::new();
    let mut p = PLANS
        .get_or_init(|| {
            Mutex::new(Plans {
                planner: RealFftPlanner::new(),
                lengths: HashSet::new(),
            })
        })
        .lock()
        // A panic while planning leaves the cache as it was: still usable.
        .unwrap_or_else(PoisonError::into_inner);
    if admit(&mut p.lengths, n) {
        p.planner = RealFftPlanner::new();
    }
    p
}

/// Record that length `n` is (about to be) planned; true when that makes
/// more than [`MAX_PLANNED_LENGTHS`] distinct lengths, and the cache starts
/// afresh with `n` alone.
fn admit(lengths: &mut HashSet<usize>, n: usize) -> bool {
    if lengths.insert(n) && lengths.len() > MAX_PLANNED_LENGTHS {
        lengths.clear();
        lengths.insert(n);
        return true;
    }
    false
}

#[derive(Debug, Clone)]
pub struct Multisine {
    /// Line spacing and lowest line (Hz).
    pub f0: f64,
    /// Harmonic numbers 1..=L.
    pub lines: Vec<usize>,
    /// One-sided complex amplitude per line: f(t) = Σ Re(A_k e^{jω_k t}) (N).
    pub amplitudes: Vec<C>,
}

impl Multisine {
    /// Lines f0, 2f0, …, ⌊f_max/f0⌋·f0 with Schroeder phases, scaled so the
    /// largest |f(t)| over a period is `peak`.
    pub fn schroeder(f0: f64, f_max: f64, peak: f64) -> Self {
        Self::schroeder_band(f0, f0, f_max, peak)
    }

    /// Lines k·f0 from the first at or above `f_min` to ⌊f_max/f0⌋·f0 (at
    /// least one), Schroeder phases over the band's own lines, scaled so the
    /// largest |f(t)| over a period is `peak`.
    pub fn schroeder_band(f0: f64, f_min: f64, f_max: f64, peak: f64) -> Self {
        let top = ((f_max / f0) + 1e-9).floor().max(1.0) as usize;
        let first = ((f_min / f0) - 1e-9).ceil().clamp(1.0, top as f64) as usize;
        let lines: Vec<usize> = (first..=top).collect();
        let l = lines.len();
        let phases: Vec<f64> = (1..=l)
            .map(|i| -std::f64::consts::PI * (i * (i - 1)) as f64 / l as f64)
            .collect();
        let unit = Self {
            f0,
            lines: lines.clone(),
            amplitudes: phases.iter().map(|&p| C::from_polar(1.0, p)).collect(),
        };
        // Peak on a grid 64 points per period of the highest line, the grid
        // synthesized by one inverse FFT (the direct sum is O(L) a point:
        // a 2 kHz band on 2 s periods took a minute).
        let n = 64 * top;
        let unit_peak = unit.period(n).iter().fold(0.0f64, |m, v| m.max(v.abs()));
        Self {
            amplitudes: unit
                .amplitudes
                .iter()
                .map(|a| a * (peak / unit_peak))
                .collect(),
            ..unit
        }
    }

    pub fn value(&self, t: f64) -> f64 {
        self.lines
            .iter()
            .zip(&self.amplitudes)
            .map(|(&k, a)| {
                (a * C::from_polar(1.0, 2.0 * std::f64::consts::PI * self.f0 * k as f64 * t)).re
            })
            .sum()
    }

    /// One period sampled at `n` evenly spaced instants (n > 2·L), by one
    /// inverse real FFT: x[i] = Σ Re(A_k e^{j2πki/n}).
    pub fn period(&self, n: usize) -> Vec<f64> {
        let ifft = plans(n).planner.plan_fft_inverse(n);
        let mut spectrum = ifft.make_input_vec();
        for (&k, a) in self.lines.iter().zip(&self.amplitudes) {
            if k < spectrum.len() && 2 * k != n {
                spectrum[k] = a * 0.5;
            }
        }
        let mut out = ifft.make_output_vec();
        ifft.process(&mut spectrum, &mut out)
            .expect("sizes from the plan");
        out
    }

    /// Angular frequencies of the lines (rad/s).
    pub fn omegas(&self) -> Vec<f64> {
        self.lines
            .iter()
            .map(|&k| 2.0 * std::f64::consts::PI * self.f0 * k as f64)
            .collect()
    }
}

/// One-sided complex amplitudes at chosen DFT bins of one period of samples.
pub struct LineAnalyzer {
    fft: Arc<dyn RealToComplex<f64>>,
    input: Vec<f64>,
    spectrum: Vec<C>,
    scratch: Vec<C>,
}

impl LineAnalyzer {
    /// `n`: samples per period.
    pub fn new(n: usize) -> Self {
        let fft = plans(n).planner.plan_fft_forward(n);
        let input = fft.make_input_vec();
        let spectrum = fft.make_output_vec();
        let scratch = fft.make_scratch_vec();
        Self {
            fft,
            input,
            spectrum,
            scratch,
        }
    }

    /// `X_k = (2/N)·Σ x_n e^{−j2πkn/N}` for each bin k in `lines`, written to `out`.
    pub fn lines(&mut self, period: &[f64], lines: &[usize], out: &mut [C]) {
        self.input.copy_from_slice(period);
        self.fft
            .process_with_scratch(&mut self.input, &mut self.spectrum, &mut self.scratch)
            .expect("buffer sizes fixed at construction");
        let scale = 2.0 / period.len() as f64;
        for (o, &k) in out.iter_mut().zip(lines) {
            *o = self.spectrum[k] * scale;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_plan_cache_holds_at_most_its_cap_of_lengths() {
        let mut kept = HashSet::new();
        // Distinct lengths are kept up to the cap, a repeat changes nothing.
        for n in 1..=MAX_PLANNED_LENGTHS {
            assert!(!admit(&mut kept, n), "{n}");
            assert!(!admit(&mut kept, n), "{n} again");
            assert_eq!(kept.len(), n);
        }
        // One more starts afresh with it alone.
        assert!(admit(&mut kept, 1000));
        assert_eq!(kept, HashSet::from([1000]));
        assert!(!admit(&mut kept, 7));
        assert_eq!(kept.len(), 2);
    }

    #[test]
    fn lines_recover_the_designed_amplitudes() {
        let ms = Multisine::schroeder(1.0, 50.0, 0.5);
        let n = 2000;
        let x: Vec<f64> = (0..n).map(|i| ms.value(i as f64 / n as f64)).collect();
        // The FFT synthesis equals the direct sum.
        for (a, b) in x.iter().zip(ms.period(n)) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!((peak - 0.5).abs() < 0.01, "{peak}");
        let mut a = LineAnalyzer::new(n);
        let mut out = vec![C::new(0.0, 0.0); ms.lines.len()];
        a.lines(&x, &ms.lines, &mut out);
        for (o, w) in out.iter().zip(&ms.amplitudes) {
            assert!((o - w).norm() < 1e-12, "{o} vs {w}");
        }
        // Schroeder phases keep the crest factor low: peak/RMS well below the
        // √(2L) = 10 of all-zero phases.
        let rms = (x.iter().map(|v| v * v).sum::<f64>() / n as f64).sqrt();
        assert!(peak / rms < 2.0, "crest factor {}", peak / rms);
    }
}
