//! Finite-difference method: `v_k = (y_k − y_{k−1})/T` (2011 paper eq. 2;
//! Janabi-Sharifi et al. 2000 eq. 2). The first output is 0.

#[derive(Debug, Clone, PartialEq)]
pub struct Fdm {
    inv_t: f64,
    prev: f64,
    started: bool,
}

impl Fdm {
    /// `t`: sample period (s), > 0 (checked by the caller).
    pub fn new(t: f64) -> Self {
        Self {
            inv_t: 1.0 / t,
            prev: 0.0,
            started: false,
        }
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        let v = if self.started {
            (y - self.prev) * self.inv_t
        } else {
            0.0
        };
        self.prev = y;
        self.started = true;
        v
    }

    pub fn reset(&mut self) {
        self.started = false;
        self.prev = 0.0;
    }

    /// 1/T (1/s), the one coefficient.
    pub fn inv_t(&self) -> f64 {
        self.inv_t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_steps() {
        // T = 1 ms: (0.003 − 0.001)/0.001 = 2 m/s; (0.002 − 0.003)/0.001 = −1 m/s.
        let mut f = Fdm::new(1e-3);
        assert_eq!(f.step(0.001), 0.0);
        assert!((f.step(0.003) - 2.0).abs() < 1e-12);
        assert!((f.step(0.002) + 1.0).abs() < 1e-12);
        f.reset();
        assert_eq!(f.step(5.0), 0.0);
    }
}
