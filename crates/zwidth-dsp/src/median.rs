//! Causal running median of the last W samples (Janabi-Sharifi et al.
//! 2000, §III-B: median smoothing keeps transients that averaging would
//! blur). Until W samples have arrived the median is over those that have.
//! For even W it is the mean of the two middle values. O(W) per sample; the
//! state holds at most `CAP` samples.

use crate::Error;

#[derive(Debug, Clone, PartialEq)]
pub struct Median<const CAP: usize> {
    /// Ring of the last W samples in arrival order.
    ring: [f64; CAP],
    /// The same samples, kept sorted (the first `len`).
    sorted: [f64; CAP],
    len: usize,
    head: usize,
    window: usize,
}

impl<const CAP: usize> Median<CAP> {
    /// `window` from 1 to `CAP`.
    pub fn new(window: usize) -> Result<Self, Error> {
        if window == 0 {
            return Err(Error::Parameter {
                name: "median window",
                value: 0.0,
                allowed: "must be at least 1 sample",
            });
        }
        if window > CAP {
            return Err(Error::Capacity {
                name: "median window",
                value: window,
                cap: CAP,
            });
        }
        Ok(Self {
            ring: [0.0; CAP],
            sorted: [0.0; CAP],
            len: 0,
            head: 0,
            window,
        })
    }

    pub fn window(&self) -> usize {
        self.window
    }

    #[inline]
    pub fn step(&mut self, x: f64) -> f64 {
        if self.len < self.window {
            self.ring[self.len] = x;
        } else {
            let old = core::mem::replace(&mut self.ring[self.head], x);
            self.head = (self.head + 1) % self.window;
            let i = self.sorted[..self.len].partition_point(|&v| v < old);
            self.sorted.copy_within(i + 1..self.len, i);
            self.len -= 1;
        }
        let i = self.sorted[..self.len].partition_point(|&v| v < x);
        self.sorted.copy_within(i..self.len, i + 1);
        self.sorted[i] = x;
        self.len += 1;
        let n = self.len;
        if n % 2 == 1 {
            self.sorted[n / 2]
        } else {
            0.5 * (self.sorted[n / 2 - 1] + self.sorted[n / 2])
        }
    }

    pub fn reset(&mut self) {
        self.len = 0;
        self.head = 0;
        self.ring = [0.0; CAP];
        self.sorted = [0.0; CAP];
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_medians() {
        // Window 3 over 5, 1, 4, 2, 2: medians of {5}, {5,1}, {5,1,4},
        // {1,4,2}, {4,2,2} = 5, 3, 4, 2, 2.
        let mut m = Median::<4>::new(3).unwrap();
        let out: [f64; 5] = [5.0, 1.0, 4.0, 2.0, 2.0].map(|x| m.step(x));
        assert_eq!(out, [5.0, 3.0, 4.0, 2.0, 2.0]);
        m.reset();
        assert_eq!(m.step(9.0), 9.0);
    }

    #[test]
    fn a_window_beyond_the_state_is_refused_naming_the_cap() {
        assert_eq!(
            Median::<8>::new(9),
            Err(Error::Capacity {
                name: "median window",
                value: 9,
                cap: 8
            })
        );
        assert!(Median::<8>::new(0).is_err());
    }
}
