//! The haptic controller both simulations share: the estimator runs on every
//! encoder sample; every render period the wall force
//! `−(K(y − x_wall) + B·v̂)` is computed (only past the wall when the wall is
//! unilateral, 2011 paper eq. 12), delayed by `delay_samples` render
//! periods, added to a constant motor bias, rounded to the force command's
//! resolution (a DAC step, when the scene names one), saturated at the force
//! limit and held (zero-order) until the next render.

use super::scene::Scene;
use crate::estimators::{Estimator, VelocityEstimator};

pub struct Controller {
    est: Estimator,
    k: f64,
    b: f64,
    wall: f64,
    bias: f64,
    unilateral: bool,
    ratio: usize,
    phase: usize,
    delay: usize,
    line: Vec<f64>,
    head: usize,
    limit: Option<f64>,
    /// The force command's step (N), if any.
    resolution: Option<f64>,
    /// The motor force being held (N).
    pub applied: f64,
    /// Render updates whose force the limit clipped.
    pub saturated: u64,
}

impl Controller {
    /// `bias`: constant motor force added to the wall's (N).
    pub fn new(scene: &Scene, k: f64, b: f64, bias: f64, unilateral: bool) -> Self {
        let s = &scene.spec;
        let delay = s.control.delay_samples as usize;
        let limit = s.device.force_limit;
        Self {
            est: scene.estimator(),
            k,
            b,
            wall: s.wall.position,
            bias,
            unilateral,
            ratio: scene.ratio,
            phase: 0,
            delay,
            line: vec![0.0; delay + 1],
            head: 0,
            limit,
            resolution: s.device.force_resolution,
            applied: limit.map_or(bias, |l| bias.clamp(-l, l)),
            saturated: 0,
        }
    }

    /// One encoder sample `y` (m): returns the velocity estimate (m/s) and
    /// updates `applied` at render instants.
    #[inline(always)]
    pub fn sample(&mut self, y: f64) -> f64 {
        let v_est = self.est.update(y);
        if self.phase == 0 {
            let f_wall = if !self.unilateral || y > self.wall {
                -(self.k * (y - self.wall) + self.b * v_est)
            } else {
                0.0
            };
            let delayed = if self.delay == 0 {
                f_wall
            } else {
                self.line[self.head] = f_wall;
                self.head = if self.head == self.delay {
                    0
                } else {
                    self.head + 1
                };
                // After the write, `head` is the oldest entry: written `delay` renders ago.
                self.line[self.head]
            };
            let f = self.bias + delayed;
            // The DAC: a whole number of steps (round to nearest), then the
            // actuator's limit.
            let f = match self.resolution {
                Some(r) => (f / r).round() * r,
                None => f,
            };
            self.applied = match self.limit {
                Some(l) if f.abs() > l => {
                    self.saturated += 1;
                    f.clamp(-l, l)
                }
                _ => f,
            };
        }
        self.phase = if self.phase + 1 == self.ratio {
            0
        } else {
            self.phase + 1
        };
        v_est
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::scene::SceneSpec;

    #[test]
    fn a_unilateral_wall_pushes_only_past_its_surface() {
        // 2011 paper eq. 12: F = −(K(y − x_w) + B·v̂) for y > x_w, else 0.
        // FDM at 1 kHz, K = 100 N/m, B = 10 N·s/m: from y = −1 mm to 0 the
        // estimate is 1 m/s, but y = 0 is on the wall, not past it: 0 N;
        // at y = 1 mm, −(100·0.001 + 10·1) = −10.1 N.
        let sc = SceneSpec::from_json(
            r#"{"device":{"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap()
        .validate()
        .unwrap();
        let mut c = Controller::new(&sc, 100.0, 10.0, 0.0, true);
        c.sample(-0.001);
        assert!((c.sample(0.0) - 1.0).abs() < 1e-12);
        assert_eq!(c.applied, 0.0);
        assert!((c.sample(0.001) - 1.0).abs() < 1e-12);
        assert!((c.applied + 10.1).abs() < 1e-12, "{}", c.applied);
    }

    #[test]
    fn delay_and_render_hold() {
        // FDM at 1 kHz sample / 500 Hz render, delay 1 render period, K = 100,
        // B = 0, bilateral: the force from sample 0 (y = 0.01 → −1 N) is
        // applied from sample 2 (the next render) and held for 2 samples.
        let sc = SceneSpec::from_json(
            r#"{"loop":{"sample_hz":1000,"render_hz":500,"delay_samples":1}}"#,
        )
        .unwrap()
        .validate()
        .unwrap();
        let mut c = Controller::new(&sc, 100.0, 0.0, 0.0, false);
        let mut applied = Vec::new();
        for y in [0.01, 0.02, 0.03, 0.04, 0.05] {
            c.sample(y);
            applied.push(c.applied);
        }
        assert_eq!(applied, vec![0.0, 0.0, -1.0, -1.0, -3.0]);
        // Saturation and bias: limit 4 N.
        let sc = SceneSpec::from_json(
            r#"{"device":{"force_limit":4},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap()
        .validate()
        .unwrap();
        let mut c = Controller::new(&sc, 1e6, 0.0, 0.5, true);
        c.sample(-1.0); // before the wall: bias only
        assert_eq!((c.applied, c.saturated), (0.5, 0));
        c.sample(1.0); // deep in: saturated, and counted
        assert_eq!((c.applied, c.saturated), (-4.0, 1));
        // A 0.3 N command step: −(100·0.01) = −1 N rounds to −0.9 N
        // (3 steps); with a 0.5 N limit, −5 N rounds to −5.1 and clips to −0.5.
        let sc_dac = SceneSpec::from_json(
            r#"{"device":{"force_limit":0.5,"force_resolution":0.3},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        )
        .unwrap()
        .validate()
        .unwrap();
        let mut c = Controller::new(&sc_dac, 100.0, 0.0, 0.0, false);
        c.sample(0.001); // −0.1 N: rounds to 0
        assert_eq!((c.applied, c.saturated), (0.0, 0));
        c.sample(0.002); // −0.2 N: rounds to −0.3 N
        assert!(
            (c.applied + 0.3).abs() < 1e-15 && c.saturated == 0,
            "{}",
            c.applied
        );
        c.sample(0.05); // −5 N: −5.1 N, clipped
        assert_eq!((c.applied, c.saturated), (-0.5, 1));
        // 4 N exactly is at the limit, not past it: not counted.
        let mut c = Controller::new(&sc, 4.0, 0.0, 0.0, false);
        c.sample(-1.0);
        assert_eq!((c.applied, c.saturated), (4.0, 0));
    }
}
