//! An open-loop identification run on the simulated device: a
//! Schroeder-phased multisine force (the input the 2018 paper identified its
//! device with, §V, ref. [35]) into the exact plant, the encoder quantized
//! each sample. What `zwidth record` writes, so `identify` can be checked
//! against the parameters that made the trace.

use serde::{Deserialize, Serialize};

use super::trace::Trace;
use crate::error::{require_positive, require_range, SpecError};
use crate::signals::quantize;
use crate::spectral::Multisine;
use crate::zwidth::scene::Scene;

/// The excitation: lines every `1/period_s` Hz up to `f_max_hz`, scaled so
/// the command peaks at `peak_force` (N).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Excitation {
    /// Length of one multisine period (s); its inverse is the lowest line.
    pub period_s: f64,
    /// Highest line (Hz), below the sample rate's Nyquist.
    pub f_max_hz: f64,
    /// Largest force command (N).
    pub peak_force: f64,
    /// Record length (s).
    pub duration_s: f64,
    /// A second multisine on the same period, added to the first: a band of
    /// lines around a transmission mode for `identify --model two_mass`,
    /// riding on the slow motion above so friction keeps sliding.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub band: Option<Band>,
}

/// The mode band: lines every `1/period_s` Hz from `f_min_hz` to `f_max_hz`
/// peaking at `peak_force` (N) on their own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Band {
    pub f_min_hz: f64,
    pub f_max_hz: f64,
    pub peak_force: f64,
}

impl Default for Excitation {
    /// 2 s periods, lines 0.5–20 Hz (the seed device's 4 Hz corner m/b in
    /// the middle), 1 N peak (≈ 5× its Coulomb friction), 20 s.
    fn default() -> Self {
        Self {
            period_s: 2.0,
            f_max_hz: 20.0,
            peak_force: 1.0,
            duration_s: 20.0,
            band: None,
        }
    }
}

/// The largest peak force a record's excitation may ask for (N).
pub const MAX_PEAK_FORCE: f64 = 1e4;

/// Most samples one recorded trace may hold (10 million: 240 MB of
/// columns, ~600 MB of CSV).
pub const MAX_RECORD_SAMPLES: f64 = 1e7;

impl Excitation {
    pub fn validate(&self, scene: &Scene) -> Result<(), SpecError> {
        require_range("period_s", self.period_s, 0.01, 1000.0, "s")?;
        require_positive("peak_force", self.peak_force, "N")?;
        // A force no haptic device makes (1e300 N was taken, issue 45).
        require_range("peak_force", self.peak_force, 0.0, MAX_PEAK_FORCE, "N")?;
        let nyquist = 0.5 / scene.dt;
        require_range(
            "f_max_hz",
            self.f_max_hz,
            1.0 / self.period_s,
            nyquist,
            "Hz; from the lowest line 1/period_s to the Nyquist frequency",
        )?;
        require_range("duration_s", self.duration_s, 1.0, 3600.0, "s")?;
        // A trace is kept whole (and written as CSV, ~60 bytes a row): at
        // 1 MHz an hour would be 3.6e9 samples and end the process.
        if self.duration_s / scene.dt > MAX_RECORD_SAMPLES {
            return Err(SpecError::new(
                "duration_s",
                self.duration_s,
                format!(
                    "would record {:.3e} samples at the scene's {} Hz; at most {MAX_RECORD_SAMPLES:e} (shorten it or lower loop.sample_hz)",
                    self.duration_s / scene.dt,
                    1.0 / scene.dt
                ),
            ));
        }
        if (self.duration_s / scene.dt) < super::trace::MIN_SAMPLES as f64 {
            return Err(SpecError::new(
                "duration_s",
                self.duration_s,
                format!(
                    "must hold at least {} samples at the scene's {} Hz",
                    super::trace::MIN_SAMPLES,
                    1.0 / scene.dt
                ),
            ));
        }
        if let Some(band) = &self.band {
            require_positive("band.peak_force", band.peak_force, "N")?;
            require_range("band.peak_force", band.peak_force, 0.0, MAX_PEAK_FORCE, "N")?;
            require_range(
                "band.f_max_hz",
                band.f_max_hz,
                1.0 / self.period_s,
                nyquist,
                "Hz; from the lowest line 1/period_s to the Nyquist frequency",
            )?;
            require_range(
                "band.f_min_hz",
                band.f_min_hz,
                1.0 / self.period_s,
                band.f_max_hz,
                "Hz; from the lowest line 1/period_s to band.f_max_hz",
            )?;
        }
        if let Some(limit) = scene.spec.device.force_limit {
            let (field, value) = match &self.band {
                None => ("peak_force", self.peak_force),
                // The command's own peak over a period, as the rig would send it.
                Some(_) => {
                    let per_period = (self.period_s / scene.dt).round().max(1.0) as usize;
                    let peak = self
                        .command_period(per_period, scene.dt)
                        .iter()
                        .fold(0.0f64, |m, f| m.max(f.abs()));
                    ("band.peak_force", peak)
                }
            };
            if value > limit {
                return Err(SpecError::new(
                    field,
                    value,
                    format!("must not exceed the device's force_limit {limit} N (a clipped command cannot be identified from; with a band, the value is the summed command's peak)"),
                ));
            }
        }
        Ok(())
    }

    /// One period of the command, `per_period` samples of `dt` (a whole
    /// number of samples, so the lines fall on DFT bins).
    pub fn command_period(&self, per_period: usize, dt: f64) -> Vec<f64> {
        let f0 = 1.0 / (per_period as f64 * dt);
        let mut one = Multisine::schroeder(f0, self.f_max_hz, self.peak_force).period(per_period);
        if let Some(b) = &self.band {
            let band = Multisine::schroeder_band(f0, b.f_min_hz, b.f_max_hz, b.peak_force)
                .period(per_period);
            for (a, b) in one.iter_mut().zip(band) {
                *a += b;
            }
        }
        one
    }
}

/// Simulate the scene's device (mass, damping, Coulomb friction with
/// stick–slip, encoder quantization, and an amplifier lag or a
/// transmission where the scene names them: the force is the motor's
/// command, the position what the encoder reads; the estimator and wall
/// are not used) under the multisine, one force update per encoder sample.
pub fn record(scene: &Scene, ex: &Excitation) -> Trace {
    let d = &scene.spec.device;
    let dt = scene.dt;
    let n = (ex.duration_s / dt).round() as usize;
    let per_period = (ex.period_s / dt).round().max(1.0) as usize;
    let one = ex.command_period(per_period, dt);
    let plant = d.plant(dt);
    let mut s = plant.at_rest(0.0);
    let (mut t, mut force, mut position) = (
        Vec::with_capacity(n),
        Vec::with_capacity(n),
        Vec::with_capacity(n),
    );
    for k in 0..n {
        let f = one[k % per_period];
        t.push(k as f64 * dt);
        force.push(f);
        let y = plant.encoder(&s);
        position.push(if d.quantization > 0.0 {
            quantize(y, d.quantization)
        } else {
            y
        });
        plant.step_driven(&mut s, f, 0.0, d.coulomb > 0.0);
    }
    Trace {
        dt,
        t,
        force,
        position,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::scene::SceneSpec;

    fn scene(json: &str) -> Scene {
        SceneSpec::from_json(json).unwrap().validate().unwrap()
    }

    #[test]
    fn bad_excitations_name_the_field() {
        let at_1k = scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#);
        let field = |sc: &Scene, ex: Excitation| ex.validate(sc).map_err(|e| e.field);
        let ex = Excitation::default();
        assert_eq!(field(&at_1k, ex.clone()), Ok(()));
        // The top line must be below Nyquist (500 Hz at 1 kHz).
        assert_eq!(
            field(
                &at_1k,
                Excitation {
                    f_max_hz: 400.0,
                    ..ex.clone()
                }
            ),
            Ok(())
        );
        assert_eq!(
            field(
                &at_1k,
                Excitation {
                    f_max_hz: 600.0,
                    ..ex.clone()
                }
            ),
            Err("f_max_hz".into())
        );
        // A peak force no device makes: 1e300 N was taken (issue 45); the
        // bound itself is allowed.
        for (peak, ok) in [
            (1e300, false),
            (MAX_PEAK_FORCE * 1.000001, false),
            (MAX_PEAK_FORCE, true),
        ] {
            let got = field(
                &at_1k,
                Excitation {
                    peak_force: peak,
                    ..ex.clone()
                },
            );
            assert_eq!(got.is_ok(), ok, "{peak}: {got:?}");
            if !ok {
                assert_eq!(got, Err("peak_force".into()));
            }
        }
        // At 1 MHz an hour is 3.6e9 samples, past MAX_RECORD_SAMPLES (1e7);
        // 10 s is exactly 1e7.
        let at_1m = scene(r#"{"loop":{"sample_hz":1e6,"render_hz":1000}}"#);
        let hour = Excitation {
            duration_s: 3600.0,
            ..ex.clone()
        };
        assert_eq!(field(&at_1m, hour), Err("duration_s".into()));
        let ten = Excitation {
            duration_s: 10.0,
            ..ex.clone()
        };
        assert_eq!(field(&at_1m, ten), Ok(()));
        // At 100 Hz, 5 s is 500 samples, fewer than a trace needs (1 000);
        // 10 s is exactly 1 000.
        let at_100 = scene(r#"{"loop":{"sample_hz":100,"render_hz":100},"probe":{"f_max_hz":20}}"#);
        let short = Excitation {
            duration_s: 5.0,
            f_max_hz: 20.0,
            ..ex.clone()
        };
        assert_eq!(field(&at_100, short), Err("duration_s".into()));
        let enough = Excitation {
            duration_s: 10.0,
            f_max_hz: 20.0,
            ..ex.clone()
        };
        assert_eq!(field(&at_100, enough), Ok(()));
        // The peak may reach the force limit, not pass it.
        let limited = scene(
            r#"{"device":{"force_limit":0.5},"loop":{"sample_hz":1000,"render_hz":1000},"probe":{"amplitude":0.4}}"#,
        );
        assert_eq!(
            field(
                &limited,
                Excitation {
                    peak_force: 0.5,
                    ..ex.clone()
                }
            ),
            Ok(())
        );
        assert_eq!(
            field(
                &limited,
                Excitation {
                    peak_force: 0.6,
                    ..ex
                }
            ),
            Err("peak_force".into())
        );
    }

    #[test]
    fn a_band_is_checked_and_adds_its_lines() {
        let sc = scene(
            r#"{"device":{"force_limit":2.5},"loop":{"sample_hz":1000,"render_hz":1000},"probe":{"amplitude":0.4}}"#,
        );
        let with = |f_min_hz: f64, f_max_hz: f64, peak_force: f64| Excitation {
            band: Some(Band {
                f_min_hz,
                f_max_hz,
                peak_force,
            }),
            ..Excitation::default()
        };
        let field = |ex: Excitation| ex.validate(&sc).map_err(|e| e.field);
        assert_eq!(field(with(50.0, 300.0, 1.0)), Ok(()));
        // Above Nyquist (500 Hz), below the lowest line (0.5 Hz), upside
        // down, no force.
        assert_eq!(field(with(50.0, 600.0, 1.0)), Err("band.f_max_hz".into()));
        assert_eq!(field(with(0.2, 300.0, 1.0)), Err("band.f_min_hz".into()));
        assert_eq!(field(with(300.0, 50.0, 1.0)), Err("band.f_min_hz".into()));
        assert_eq!(field(with(50.0, 300.0, 0.0)), Err("band.peak_force".into()));
        // The summed command's peak against the 2.5 N limit: 1 N + 1 N
        // peaks at most 2 N; 1 N + 2 N at least 2 N (the band alone) and
        // here more than 2.5 N.
        assert_eq!(field(with(50.0, 300.0, 1.0)), Ok(()));
        let e = with(50.0, 300.0, 2.0).validate(&sc).unwrap_err();
        assert_eq!(e.field, "band.peak_force");
        assert!(e.to_string().contains("summed"), "{e}");
        // The command is the two multisines' sum: its lines are the slow
        // band's 0.5–20 Hz and the band's 50–300 Hz at 0.5 Hz spacing,
        // nothing between (DFT of one 2 s period).
        let one = with(50.0, 300.0, 1.0).command_period(2000, 1e-3);
        let mut a = crate::spectral::LineAnalyzer::new(2000);
        let bins: Vec<usize> = (1..1000).collect();
        let mut out = vec![num_complex::Complex64::new(0.0, 0.0); bins.len()];
        a.lines(&one, &bins, &mut out);
        let excited: Vec<usize> = bins
            .iter()
            .zip(&out)
            .filter(|(_, c)| c.norm() > 1e-9)
            .map(|(&k, _)| k)
            .collect();
        let want: Vec<usize> = (1..=40).chain(100..=600).collect();
        assert_eq!(excited, want);
    }

    #[test]
    fn the_trace_is_the_motor_s_command_and_the_encoder_s_reading() {
        // A stiff cable (1e8 N/m) between a 0.3 kg handle and a 0.22 kg
        // motor side is the rigid 0.52 kg device (closed-form steps,
        // plant.rs): the encoder readings agree to 1e-3 of their range.
        let ex = Excitation::default();
        let rigid = record(
            &scene(
                r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
            ),
            &ex,
        );
        let stiff = record(
            &scene(
                r#"{"device":{"mass":0.3,"coulomb":0,"quantization":0,"transmission":{"motor_mass":0.22,"stiffness":1e8,"damping":10}},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
            ),
            &ex,
        );
        let range = rigid.position.iter().fold(0.0f64, |a, x| a.max(x.abs()));
        let worst = rigid
            .position
            .iter()
            .zip(&stiff.position)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        assert!(range > 0.0 && worst < 1e-3 * range, "{worst} of {range}");
        // A 0.05 Hz amplifier passes the 0.5–20 Hz multisine's force at a
        // tenth or less (|L| = 1/√(1 + (f/f_a)²)): the response is far
        // smaller than without it.
        let lagged = record(
            &scene(
                r#"{"device":{"coulomb":0,"quantization":0,"amplifier_hz":0.05},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
            ),
            &ex,
        );
        let rms = |p: &[f64]| {
            let m = p.iter().sum::<f64>() / p.len() as f64;
            (p.iter().map(|x| (x - m).powi(2)).sum::<f64>() / p.len() as f64).sqrt()
        };
        assert!(
            rms(&lagged.position) < 0.2 * rms(&rigid.position),
            "{} vs {}",
            rms(&lagged.position),
            rms(&rigid.position)
        );
    }
}
