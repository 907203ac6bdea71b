//! Numerical stability at the extremes the issue names: rates 100 Hz to
//! 1 MHz, quantization 1 nm to 1 mm, Kalman q from 1e-6 to 1e12, 1e7-sample
//! runs. Every output must be finite, variances non-negative, no drift.

use proptest::prelude::*;
use rayon::prelude::*;
use zwidth_core::estimators::{Core, EstimatorSpec, Sampling, VelocityEstimator};
use zwidth_core::signals::quantize;

fn specs() -> Vec<String> {
    let mut v: Vec<String> = vec![
        r#"{"kind":"fdm"}"#.into(),
        r#"{"kind":"foaw","fit":"end","max_window":32}"#.into(),
        r#"{"kind":"foaw","fit":"best","max_window":32}"#.into(),
        r#"{"kind":"foaw","fit":"best_r","max_window":32,"outlier_tolerance":true}"#.into(),
        r#"{"kind":"levant","rule":"hba_sc","lipschitz":10}"#.into(),
        r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":10,"discretization":"implicit"}"#
            .into(),
        r#"{"kind":"levant","alpha":1e6,"lambda":1e4}"#.into(),
        r#"{"kind":"fdm","median_position":5,"median_velocity":4}"#.into(),
    ];
    for q in ["1e-6", "1", "2.5e4", "1e12"] {
        for model in ["white_jerk", "diagonal"] {
            v.push(format!(
                r#"{{"kind":"kalman","q":{q},"q_model":"{model}"}}"#
            ));
            v.push(format!(
                r#"{{"kind":"adaptive_kalman","q":{q},"q_model":"{model}"}}"#
            ));
        }
    }
    v
}

/// A hit-like trace: approach at 0.2 m/s, a damped oscillation, then rest.
fn trace(rate: f64, quantization: f64, n: usize) -> Vec<f64> {
    (0..n)
        .map(|k| {
            let t = k as f64 / rate;
            let x = if t < 0.05 {
                0.2 * t
            } else {
                0.01 + 0.005 * (-(t - 0.05) * 20.0).exp() * ((t - 0.05) * 150.0).sin()
            };
            quantize(x, quantization)
        })
        .collect()
}

fn check_kalman_covariance(core: &Core) {
    if let Core::Kalman(k) = core {
        let p = k.covariance();
        assert!(p.iter().all(|v| v.is_finite()), "{p:?}");
        assert!(
            p[0] >= 0.0 && p[3] >= 0.0 && p[5] >= 0.0,
            "negative variance {p:?}"
        );
    }
}

#[test]
fn all_estimators_finite_across_rates_and_quantization() {
    let rates = [100.0, 1e3, 1e4, 1e5, 1e6];
    let quants = [1e-9, 1e-6, 1e-3];
    let cases: Vec<(f64, f64, String)> = rates
        .iter()
        .flat_map(|&r| {
            quants
                .iter()
                .flat_map(move |&q| specs().into_iter().map(move |s| (r, q, s)))
        })
        .collect();
    cases.par_iter().for_each(|(rate, q, json)| {
        let spec = EstimatorSpec::from_json(json).unwrap();
        let Ok(mut est) = spec.build(Sampling::new(*rate, *q).unwrap()) else {
            // Only a Kalman q·T⁵ overflow may refuse to build; none of these do.
            panic!("{json} at {rate} Hz, d = {q} did not build");
        };
        let n = ((0.2 * rate) as usize).clamp(200, 20_000);
        for (k, y) in trace(*rate, *q, n).into_iter().enumerate() {
            let v = est.update(y);
            assert!(
                v.is_finite(),
                "{json} at {rate} Hz, d = {q}: sample {k} gave {v}"
            );
            if k % 97 == 0 {
                check_kalman_covariance(est.core());
            }
        }
        check_kalman_covariance(est.core());
    });
}

#[test]
fn ten_million_samples_no_drift() {
    // A quantized constant-velocity ramp, v = 0.01 m/s at 10 kHz with 1 µm
    // steps, for 1e7 samples (1000 s, 10 m of travel). The mean estimate over
    // the last 10 000 samples (1 s, 10 000 µm of travel, so quantization
    // averages out) must still be v.
    let (rate, q, v) = (1e4, 1e-6, 0.01);
    let specs = [
        r#"{"kind":"fdm"}"#,
        r#"{"kind":"butterworth","cutoff_hz":100}"#,
        r#"{"kind":"kalman","q":2.5e4}"#,
        r#"{"kind":"adaptive_kalman","q":2.5e4}"#,
        r#"{"kind":"foaw","fit":"best","max_window":16}"#,
        r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":1}"#,
        r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":1,"discretization":"implicit"}"#,
    ];
    specs.par_iter().for_each(|json| {
        let mut est = EstimatorSpec::from_json(json)
            .unwrap()
            .build(Sampling::new(rate, q).unwrap())
            .unwrap();
        let n = 10_000_000usize;
        let mut tail = 0.0;
        for k in 0..n {
            let y = quantize(v * k as f64 / rate, q);
            let e = est.update(y);
            assert!(e.is_finite(), "{json}: sample {k}");
            if k >= n - 10_000 {
                tail += e;
            }
        }
        let mean = tail / 10_000.0;
        assert!((mean - v).abs() < 1e-3 * v, "{json}: mean {mean} vs {v}");
        check_kalman_covariance(est.core());
    });
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, .. ProptestConfig::default() })]

    // Any valid Kalman/Levant/FOAW spec on any rate/quantization in range,
    // fed a bounded random walk: the output is always finite.
    #[test]
    fn random_specs_stay_finite(
        log_rate in 2.0f64..6.0,
        log_d in -9.0f64..-3.0,
        log_q in -6.0f64..12.0,
        which in 0usize..5,
        steps in proptest::collection::vec(-3i32..=3, 50..400),
    ) {
        let (rate, d, q) = (10f64.powf(log_rate), 10f64.powf(log_d), 10f64.powf(log_q));
        let json = match which {
            0 => format!(r#"{{"kind":"kalman","q":{q}}}"#),
            1 => format!(r#"{{"kind":"adaptive_kalman","q":{q},"q_model":"diagonal"}}"#),
            2 => format!(r#"{{"kind":"levant","alpha":{q},"lambda":{}}}"#, q.sqrt()),
            3 => r#"{"kind":"foaw","fit":"best_r","max_window":20}"#.to_string(),
            _ => format!(r#"{{"kind":"butterworth","cutoff_hz":{},"order":4}}"#, rate / 7.0),
        };
        let spec = EstimatorSpec::from_json(&json).unwrap();
        let mut est = spec.build(Sampling::new(rate, d).unwrap()).unwrap();
        let mut y = 0.0;
        for s in steps {
            y += s as f64 * d;
            let v = est.update(y);
            prop_assert!(v.is_finite(), "{} gave {}", json, v);
        }
    }
}

mod scenes {
    use zwidth_core::zwidth::hit::{wall_hit, HitKnobs, NoTrace};
    use zwidth_core::zwidth::probe::{probe, ProbeKnobs};
    use zwidth_core::zwidth::scene::SceneSpec;

    /// Scenes at the extremes the issue names: no NaN, no panic.
    #[test]
    fn extreme_scenes_give_finite_results() {
        let knobs = HitKnobs {
            settle_s: 0.05,
            measure_s: 0.02,
        };
        let pk = ProbeKnobs {
            periods: 1,
            settle_tol: 1e-2,
            max_periods: 4,
            realizations: 3,
        };
        for json in [
            // 1 MHz encoder, 1 kHz render, ideal sensor; short approach.
            r#"{"loop":{"sample_hz":1000000,"render_hz":1000},"hit":{"home_distance":0.0001}}"#,
            // 1 g and 100 kg handles, no damping at all.
            r#"{"device":{"mass":0.001,"damping":0,"coulomb":0},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"mass":100,"damping":0,"coulomb":0.19,"quantization":1e-9},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"damping":0,"force_limit":4},"estimator":{"kind":"kalman","q":1e12},"hit":{"home_distance":0.0001}}"#,
            r#"{"estimator":{"kind":"levant","rule":"hba_sc","lipschitz":1},"hit":{"home_distance":0.0001}}"#,
            // Amplifier lags from 0.1 Hz to the encoder's Nyquist frequency,
            // with friction and quantization (the averaged-force step).
            r#"{"device":{"amplifier_hz":0.1},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"amplifier_hz":5000,"coulomb":0,"quantization":0},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"amplifier_hz":5000,"force_limit":1},"hit":{"home_distance":0.0001}}"#,
            // Transmissions from a 1 mg motor side on a 1e8 N/m cable to a
            // 1e4 kg one on 1 N/m, encoder on either side.
            r#"{"device":{"coulomb":0,"transmission":{"motor_mass":1e-6,"stiffness":1e8}},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"coulomb":0,"amplifier_hz":50,"transmission":{"motor_mass":1e4,"stiffness":1,"encoder":"handle"}},"hit":{"home_distance":0.0001}}"#,
            // LuGre friction at its edges: the stiffest bristles the
            // substep bound allows at 10 kHz, undamped bristles, a Stribeck
            // dip over a nanometre per second, a 1e4 N static level the
            // push never breaks; on the motor side of a light motor.
            r#"{"device":{"friction":{"bristle_stiffness":1e9,"bristle_damping":0}},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"friction":{"static":1e4,"stribeck_velocity":1e-9,"bristle_stiffness":1}},"hit":{"home_distance":0.0001}}"#,
            r#"{"device":{"friction":{"on":"motor","static":0.3,"bristle_damping":1},"amplifier_hz":500,"transmission":{"motor_mass":0.01,"stiffness":1e4}},"loop":{"sample_hz":1000,"render_hz":1000},"hit":{"home_distance":0.0001}}"#,
        ] {
            let sc = SceneSpec::from_json(json).unwrap().validate().unwrap();
            for (k, b) in [(1e7, 0.0), (1e7, 1e3), (1.0, 0.0), (1e5, -50.0)] {
                let o = wall_hit(&sc, k, b, knobs, &mut NoTrace);
                assert!(o.mean_position.is_finite(), "{json} K={k} B={b}: {o:?}");
                // The documented variants: an RMS exactly when the trial did
                // not diverge, and a diverged trial is unstable.
                match o.rms {
                    Some(r) => assert!(
                        r.is_finite() && r >= 0.0 && !o.diverged,
                        "{json} K={k} B={b}: {o:?}"
                    ),
                    None => assert!(o.diverged && !o.stable, "{json} K={k} B={b}: {o:?}"),
                }
                // K = 1e7 N/m at a 1 kHz render is 400× past 2b/T for the
                // seed damping (and past any b here): never stable.
                if k == 1e7 && b == 0.0 {
                    assert!(!o.stable, "{json}: {o:?}");
                }
            }
            let o = probe(&sc, 1e7, 10.0, pk);
            assert!(
                o.impedance.magnitude.iter().all(|m| m.is_finite()),
                "{json}"
            );
            assert!(o.impedance.fidelity.is_finite());
            // 1e7 N/m is far past the impedance-test boundary of every one
            // of these devices (at most a few 1e4 N/m at a 1 kHz render).
            assert!(!o.passive, "{json}");
        }
    }

    /// Colgate & Schenkel's strict passivity, by brute force over θ:
    /// b ≥ (T/2)·Re{(1 − e^{−jθ})·H(e^{jθ})}/(1 − cos θ) for θ in (0, π],
    /// H = (K + B·V)·e^{−jdθ}.
    fn colgate_ok(m: &zwidth_core::zwidth::analytic::LinearModel, k: f64, b: f64) -> bool {
        use num_complex::Complex64 as C;
        (1..=4096).all(|i| {
            let th = std::f64::consts::PI * i as f64 / 4096.0;
            let h = (C::new(k, 0.0) + b * m.v(th)) * C::from_polar(1.0, -(m.delay as f64) * th);
            let rhs = 0.5 * m.t * ((C::new(1.0, 0.0) - C::from_polar(1.0, -th)) * h).re
                / (1.0 - th.cos());
            m.damping >= rhs
        })
    }

    #[test]
    fn analytic_engine_at_the_extremes() {
        use zwidth_core::zwidth::analytic::LinearModel;
        for json in [
            r#"{"device":{"mass":0.001,"damping":0,"coulomb":0,"quantization":0},"loop":{"sample_hz":1000000,"render_hz":1000000},"probe":{"f_max_hz":1000}}"#,
            r#"{"device":{"mass":100,"damping":0,"coulomb":0,"quantization":0},"loop":{"sample_hz":100,"render_hz":100},"probe":{"f_max_hz":40}}"#,
            r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000,"delay_samples":3},"estimator":{"kind":"kalman","q":1e12}}"#,
            // Amplifier lags at 0.01 Hz and at Nyquist (20 kHz and 100 Hz loops).
            r#"{"device":{"mass":0.001,"coulomb":0,"quantization":0,"amplifier_hz":10000},"loop":{"sample_hz":20000,"render_hz":20000},"probe":{"f_max_hz":1000}}"#,
            r#"{"device":{"coulomb":0,"quantization":0,"amplifier_hz":0.01},"loop":{"sample_hz":100,"render_hz":100},"probe":{"f_max_hz":40}}"#,
            r#"{"device":{"coulomb":0,"quantization":0,"transmission":{"motor_mass":1e-6,"stiffness":1e8,"damping":1}},"loop":{"sample_hz":20000,"render_hz":20000},"probe":{"f_max_hz":1000}}"#,
            r#"{"device":{"coulomb":0,"quantization":0,"transmission":{"motor_mass":1e4,"stiffness":1,"encoder":"handle"}},"loop":{"sample_hz":100,"render_hz":100},"probe":{"f_max_hz":40}}"#,
        ] {
            let sc = SceneSpec::from_json(json).unwrap().validate().unwrap();
            let m = LinearModel::new(&sc).unwrap();
            if sc.spec.device.amplifier_hz.is_some() || sc.spec.device.transmission.is_some() {
                for (k, b) in [(1e7, 0.0), (1.0, 1e3), (1e5, -5.0), (1.0, 0.0)] {
                    let c = m.impedance(k, b);
                    assert!(
                        c.magnitude
                            .iter()
                            .chain(&c.phase_deg)
                            .all(|v| v.is_finite())
                            && c.fidelity.is_finite()
                            && m.spectral_radius(k, b).is_finite(),
                        "{json} {k} {b}"
                    );
                }
                // A soft wall (1 N/m, no B) on a damped device is stable
                // whatever the lag; 1e7 N/m at 100 Hz is 4000× past the
                // lag-free 2b/T (a lag only lowers the boundary).
                assert!(m.spectral_radius(1.0, 0.0) < 1.0, "{json}");
                if sc.spec.control.sample_hz == 100.0 {
                    assert!(m.spectral_radius(1e7, 0.0) > 1.0, "{json}");
                }
                continue;
            }
            for (k, b) in [(1e7, 0.0), (1.0, 1e3), (1e5, -5.0)] {
                let c = m.impedance(k, b);
                assert!(
                    c.magnitude
                        .iter()
                        .chain(&c.phase_deg)
                        .all(|v| v.is_finite())
                        && c.fidelity.is_finite(),
                    "{json} {k} {b}"
                );
                assert!(m.spectral_radius(k, b).is_finite(), "{json} {k} {b}");
                // Colgate & Schenkel: strict passivity needs b ≥ |B| at
                // least, so B = 1e3 gets no passive K at all, nor does any
                // B ≠ 0 without damping (b = 0), where only the null wall
                // K = B = 0 is passive; the damped device at B = 0 has a
                // finite, ordered K range.
                let range = m.strict_passivity_range(b);
                let damping = sc.spec.device.damping;
                if damping == 0.0 && b == 0.0 {
                    assert_eq!(range, Some((0.0, 0.0)), "{json} B={b}");
                } else if b.abs() >= damping {
                    assert_eq!(range, None, "{json} B={b}");
                } else if b != 0.0 {
                    // Otherwise a brute-force check of Colgate's inequality
                    // (4096 θ) decides which variant is right.
                    match range {
                        Some((lo, hi)) => {
                            assert!(colgate_ok(&m, 0.5 * (lo + hi), b), "{json} B={b}");
                            assert!(!colgate_ok(&m, hi * 1.01 + 1.0, b), "{json} B={b}");
                        }
                        None => {
                            for k in [0.0, 1.0, 1e2, 1e3, 1e4, 1e5, 1e6] {
                                assert!(!colgate_ok(&m, k, b), "{json} B={b} K={k}");
                            }
                        }
                    }
                } else {
                    let (lo, hi) = range.unwrap_or_else(|| panic!("{json} B={b}: no range"));
                    assert!(
                        lo.is_finite() && hi.is_finite() && 0.0 <= lo && lo < hi,
                        "{json} B={b}: {lo} {hi}"
                    );
                }
            }
        }
    }

    #[test]
    fn a_line_on_an_undamped_mode_is_finite() {
        // No damping anywhere: two 1 kg masses on a cable of k = 2π²·100 N/m
        // have their mode at √(2k)/(2π) = 10 Hz, on the probe's 10th line.
        use zwidth_core::zwidth::analytic::LinearModel;
        let k = 2.0 * std::f64::consts::PI.powi(2) * 100.0;
        let sc = SceneSpec::from_json(&format!(
            r#"{{"device":{{"mass":1,"damping":0,"coulomb":0,"quantization":0,"transmission":{{"motor_mass":1,"stiffness":{k},"encoder":"handle"}}}},"loop":{{"sample_hz":1000,"render_hz":1000}}}}"#
        ))
        .unwrap()
        .validate()
        .unwrap();
        let c = LinearModel::new(&sc).unwrap().impedance(100.0, 1.0);
        assert!((c.freq_hz[9] - 10.0).abs() < 1e-12);
        assert!(
            c.magnitude
                .iter()
                .chain(&c.phase_deg)
                .all(|v| v.is_finite())
                && c.fidelity.is_finite(),
            "{c:?}"
        );
    }

    #[test]
    fn impossible_scenes_are_refused_with_the_field() {
        for (json, field) in [
            (r#"{"device":{"mass":0}}"#, "device.mass"),
            (r#"{"device":{"mass":1e9}}"#, "device.mass"),
            (r#"{"loop":{"sample_hz":1e9}}"#, "loop.sample_hz"),
            (r#"{"loop":{"render_hz":20000}}"#, "loop.render_hz"),
            (r#"{"loop":{"delay_samples":1000}}"#, "loop.delay_samples"),
            (r#"{"hit":{"settle_s":-1}}"#, "hit.settle_s"),
            (r#"{"probe":{"amplitude":0}}"#, "probe.amplitude"),
            // An amplifier bandwidth > 0 and at most Nyquist (5 kHz here).
            (r#"{"device":{"amplifier_hz":0}}"#, "device.amplifier_hz"),
            (r#"{"device":{"amplifier_hz":-100}}"#, "device.amplifier_hz"),
            (
                r#"{"device":{"amplifier_hz":5000.5}}"#,
                "device.amplifier_hz",
            ),
            // Inertias and stiffnesses > 0; friction only on a rigid device.
            (
                r#"{"device":{"coulomb":0,"transmission":{"motor_mass":0,"stiffness":1e4}}}"#,
                "device.transmission.motor_mass",
            ),
            (
                r#"{"device":{"coulomb":0,"transmission":{"motor_mass":0.1,"stiffness":-1}}}"#,
                "device.transmission.stiffness",
            ),
            (
                r#"{"device":{"coulomb":0,"transmission":{"motor_mass":0.1,"stiffness":0}}}"#,
                "device.transmission.stiffness",
            ),
            (
                r#"{"device":{"coulomb":0,"transmission":{"motor_mass":0.1,"stiffness":1e4,"damping":-1}}}"#,
                "device.transmission.damping",
            ),
            (
                r#"{"device":{"coulomb":0,"transmission":{"motor_mass":0.1,"stiffness":1e4,"motor_damping":-1}}}"#,
                "device.transmission.motor_damping",
            ),
            (
                r#"{"device":{"transmission":{"motor_mass":0.1,"stiffness":1e4}}}"#,
                "device.coulomb",
            ),
            // LuGre friction: a kinetic level > 0, static ≥ kinetic, a
            // Stribeck velocity > 0, bristles in range, on the motor only
            // with a transmission, at most 1000 substeps per sample.
            (
                r#"{"device":{"coulomb":0,"friction":{}}}"#,
                "device.coulomb",
            ),
            (
                r#"{"device":{"coulomb":0.2,"friction":{"static":0.19}}}"#,
                "device.friction.static",
            ),
            (
                r#"{"device":{"friction":{"stribeck_velocity":0}}}"#,
                "device.friction.stribeck_velocity",
            ),
            (
                r#"{"device":{"friction":{"stribeck_velocity":-1e-3}}}"#,
                "device.friction.stribeck_velocity",
            ),
            (
                r#"{"device":{"friction":{"bristle_stiffness":0}}}"#,
                "device.friction.bristle_stiffness",
            ),
            (
                r#"{"device":{"friction":{"bristle_damping":-1}}}"#,
                "device.friction.bristle_damping",
            ),
            (
                r#"{"device":{"friction":{"on":"motor"}}}"#,
                "device.friction.on",
            ),
            // 1 to 32 hits per time-domain verdict.
            (r#"{"hit":{"replicates":0}}"#, "hit.replicates"),
            (r#"{"hit":{"replicates":33}}"#, "hit.replicates"),
            // 1 kHz, 0.52 kg: 1e9 N/m needs 3 % of √(m/σ0) = 6.8e-7 s
            // steps, 1 467 per sample.
            (
                r#"{"device":{"friction":{"bristle_stiffness":1e9}},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
                "device.friction.bristle_stiffness",
            ),
        ] {
            let e = SceneSpec::from_json(json).unwrap().validate().unwrap_err();
            assert_eq!(e.field, field, "{json}: {e}");
        }
    }
}
