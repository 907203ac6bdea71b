//! Finite-difference method: `v_k = (y_k − y_{k−1})/T` (2011 paper eq. 2;
//! Janabi-Sharifi et al. 2000 eq. 2). The first output is 0. The
//! implementation is `zwidth_dsp::Fdm` (one implementation, here and on
//! the rig).

use super::streaming::VelocityEstimator;

#[derive(Debug, Clone)]
pub struct Fdm(zwidth_dsp::Fdm);

impl Fdm {
    /// `t`: sample period (s), already validated > 0.
    pub fn new(t: f64) -> Self {
        Self(zwidth_dsp::Fdm::new(t))
    }
}

impl VelocityEstimator for Fdm {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        self.0.step(y)
    }

    fn reset(&mut self) {
        self.0.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hand_computed_steps() {
        // T = 1 ms: (0.003 − 0.001)/0.001 = 2 m/s; (0.002 − 0.003)/0.001 = −1 m/s.
        let mut f = Fdm::new(1e-3);
        assert_eq!(f.update(0.001), 0.0);
        assert!((f.update(0.003) - 2.0).abs() < 1e-12);
        assert!((f.update(0.002) + 1.0).abs() < 1e-12);
        f.reset();
        assert_eq!(f.update(5.0), 0.0);
    }
}
