//! Causal running median of the last W samples (Janabi-Sharifi et al. 2000,
//! §III-B). The implementation is `zwidth_dsp::Median`: windows up to the
//! rig's cap in the rig's state, longer ones (up to `MAX_MEDIAN_WINDOW`)
//! in the simulator's; boxed, so an estimator stays small.

use super::streaming::MAX_MEDIAN_WINDOW;
use crate::error::SpecError;
use zwidth_dsp::estimator::RIG_MEDIAN;

#[derive(Debug, Clone)]
pub enum RunningMedian {
    Small(Box<zwidth_dsp::Median<RIG_MEDIAN>>),
    Large(Box<zwidth_dsp::Median<MAX_MEDIAN_WINDOW>>),
}

impl RunningMedian {
    /// `window` from 1 to `MAX_MEDIAN_WINDOW`.
    pub fn new(window: usize) -> Result<Self, SpecError> {
        let m = if window <= RIG_MEDIAN {
            zwidth_dsp::Median::new(window).map(|m| Self::Small(Box::new(m)))
        } else {
            zwidth_dsp::Median::new(window).map(|m| Self::Large(Box::new(m)))
        };
        m.map_err(|_| {
            SpecError::new(
                "median window",
                window,
                format!("must be 1 to {MAX_MEDIAN_WINDOW} samples"),
            )
        })
    }

    #[inline]
    pub fn push(&mut self, x: f64) -> f64 {
        match self {
            Self::Small(m) => m.step(x),
            Self::Large(m) => m.step(x),
        }
    }

    pub fn reset(&mut self) {
        match self {
            Self::Small(m) => m.reset(),
            Self::Large(m) => m.reset(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        // Independent computation: sort the window from scratch each step.
        #[test]
        fn equals_sort_of_window(xs in proptest::collection::vec(-1e3f64..1e3, 1..80), w in prop_oneof![1usize..9, 60usize..70]) {
            let mut m = RunningMedian::new(w).unwrap();
            for k in 0..xs.len() {
                let mut win: Vec<f64> = xs[k.saturating_sub(w - 1)..=k].to_vec();
                win.sort_by(|a, b| a.partial_cmp(b).unwrap());
                let n = win.len();
                let expect = if n % 2 == 1 { win[n / 2] } else { 0.5 * (win[n / 2 - 1] + win[n / 2]) };
                prop_assert_eq!(m.push(xs[k]), expect);
            }
        }
    }
}
