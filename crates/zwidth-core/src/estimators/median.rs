//! Causal running median of the last W samples (Janabi-Sharifi et al. 2000,
//! §III-B: median smoothing keeps transients that averaging would blur).
//! Until W samples have arrived the median is over those that have. For even
//! W it is the mean of the two middle values. O(W) per sample, no allocation.

#[derive(Debug, Clone)]
pub struct RunningMedian {
    /// Ring of the last W samples in arrival order.
    ring: Vec<f64>,
    /// The same samples, kept sorted.
    sorted: Vec<f64>,
    head: usize,
    window: usize,
}

impl RunningMedian {
    /// `window` ≥ 1, validated by the caller.
    pub fn new(window: usize) -> Self {
        Self {
            ring: Vec::with_capacity(window),
            sorted: Vec::with_capacity(window),
            head: 0,
            window,
        }
    }

    #[inline]
    pub fn push(&mut self, x: f64) -> f64 {
        if self.ring.len() < self.window {
            self.ring.push(x);
        } else {
            let old = std::mem::replace(&mut self.ring[self.head], x);
            self.head = (self.head + 1) % self.window;
            let i = self.sorted.partition_point(|&v| v < old);
            self.sorted.remove(i);
        }
        let i = self.sorted.partition_point(|&v| v < x);
        self.sorted.insert(i, x);
        let n = self.sorted.len();
        if n % 2 == 1 {
            self.sorted[n / 2]
        } else {
            0.5 * (self.sorted[n / 2 - 1] + self.sorted[n / 2])
        }
    }

    pub fn reset(&mut self) {
        self.ring.clear();
        self.sorted.clear();
        self.head = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        // Independent computation: sort the window from scratch each step.
        #[test]
        fn equals_sort_of_window(xs in proptest::collection::vec(-1e3f64..1e3, 1..80), w in 1usize..9) {
            let mut m = RunningMedian::new(w);
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
