//! The plant's tests: its closed forms, steps and the exact-step parts
//! (`plant.rs`).

use super::*;

#[test]
fn a_velocity_keeps_its_sign_only_where_it_surely_stops_after_the_step() {
    // The seed device at 1 kHz sliding at 10 mm/s, decelerated by a net
    // force f < 0. The exact velocity after the step, v0·e^{−a} +
    // f·dt·φ(a)/m with a = b·dt/m, is zero at f* = −v0·c_vv/c_vf; the
    // closed-form stopping time τ·ln(1 − v0·b/f) is then exactly dt.
    let p = Plant::new(0.52, 13.2, 0.19, 1e-3);
    let v0 = 0.01;
    let f_star = -v0 * p.c_vv / p.c_vf;
    for (scale, keeps) in [
        (0.5, true),          // stops long after the step
        (1.0 - 1e-6, true),   // just after it, far beyond rounding
        (1.0 - 1e-12, false), // within 1e-9 of the terms: unsure
        (1.0 + 1e-12, false),
        (2.0, false), // stops within the step
    ] {
        let f = f_star * scale;
        assert_eq!(p.keeps_sign(v0, f, 1.0), keeps, "f = {scale}·f*");
        if keeps {
            assert!(p.time_to_stop(v0, f) > p.dt, "{scale}");
        }
        // The mirror image: sliding the other way.
        assert_eq!(p.keeps_sign(-v0, -f, -1.0), keeps, "mirror {scale}");
    }
    assert!(p.time_to_stop(v0, 2.0 * f_star) < p.dt);
    // At rest with no force there is no sign to keep (strictly above the
    // margin, never at it).
    assert!(!p.keeps_sign(0.0, 0.0, 1.0));
    // The margin is relative to the terms' sum, at any speed: 0.1 mm/s
    // ending 1e-10 of the way from zero is unsure too.
    let slow = 1e-4;
    let f_slow = -slow * p.c_vv / p.c_vf;
    assert!(!p.keeps_sign(slow, f_slow * (1.0 - 1e-10), 1.0));
    assert!(p.keeps_sign(slow, f_slow * (1.0 - 1e-6), 1.0));
}

#[test]
fn a_step_in_parts_is_the_whole_step_bit_for_bit() {
    // Φ 5×5 and Γ 5×3 with entries of mixed sign and scale (an LCG, so
    // the sums round differently row by row), and the 4×2 of a plant
    // without LuGre: the parts LuGre's predictor and corrector share,
    // completed by the last input, equal `step` to the last bit.
    let mut x = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = || {
        x = x.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        ((x >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 10f64.powi((x % 7) as i32 - 3)
    };
    for (n, m) in [(5, 3), (4, 2), (2, 2)] {
        let phi: Mat = (0..n).map(|_| (0..n).map(|_| next()).collect()).collect();
        let gamma: Mat = (0..n).map(|_| (0..m).map(|_| next()).collect()).collect();
        let zs = ZohStep::new(&phi, &gamma);
        for _ in 0..50 {
            let z = [next(), next(), next(), next(), next()];
            let u: Vec<f64> = (0..m).map(|_| next()).collect();
            let whole = zs.step(&z, &u);
            let (a, p) = zs.partial(&z, &u[..m - 1]);
            let parts = zs.finish(&a, &p, u[m - 1]);
            assert_eq!(whole.map(f64::to_bits), parts.map(f64::to_bits), "{n}×{m}");
            for (i, w) in whole.iter().enumerate().take(n) {
                assert_eq!(zs.row(i, &a, &p, u[m - 1]).to_bits(), w.to_bits());
                // The matrices' own rows summed in order.
                let want = dot(&phi[i], &z) + dot(&gamma[i], &u);
                assert_eq!(w.to_bits(), want.to_bits(), "row {i}");
            }
            assert!(whole[n..].iter().all(|&v| v == 0.0));
        }
    }
}

#[test]
fn series_and_closed_forms_agree() {
    // Reference: the closed forms φ(a) = (1 − e^{−a})/a and
    // ψ(a) = (a − 1 + e^{−a})/a² where they are well conditioned (a ≥
    // 0.1), their Taylor series φ = Σ (−a)^n/(n+1)!, ψ = Σ (−a)^n/(n+2)!
    // (twelve terms: the rest is below 1e-16 for a ≤ 0.1) below.
    let series = |a: f64, shift: u32| {
        let (mut sum, mut term) = (0.0, 1.0);
        for i in 1..=shift {
            term /= i as f64;
        }
        for n in 0..12 {
            sum += term;
            term *= -a / (n + shift + 1) as f64;
        }
        sum
    };
    for a in [1e-9f64, 1e-6, 5e-4, 1.5e-3, 0.01, 0.1, 1.0, 30.0] {
        let (p, q) = if a >= 0.1 {
            ((1.0 - (-a).exp()) / a, (a - 1.0 + (-a).exp()) / (a * a))
        } else {
            (series(a, 1), series(a, 2))
        };
        assert!(
            (phi(a) - p).abs() <= 1e-13 * p,
            "phi {a}: {} vs {p}",
            phi(a)
        );
        assert!(
            (psi(a) - q).abs() <= 1e-13 * q,
            "psi {a}: {} vs {q}",
            psi(a)
        );
    }
    assert_eq!(psi(0.0), 0.5);
    assert_eq!(phi(0.0), 1.0);
}

#[test]
fn exact_against_analytic_solution() {
    // m = 0.5, b = 2, F = 1 from rest: v(t) = (F/b)(1 − e^{−bt/m}),
    // x(t) = (F/b)(t − (m/b)(1 − e^{−bt/m})).
    let p = Plant::new(0.5, 2.0, 0.0, 1e-3);
    let mut s = PlantState::default();
    for _ in 0..1000 {
        p.step_linear(&mut s, 1.0);
    }
    let t: f64 = 1.0;
    let v = 0.5 * (1.0 - (-4.0 * t).exp());
    let x = 0.5 * (t - 0.25 * (1.0 - (-4.0 * t).exp()));
    assert!((s.v - v).abs() < 1e-12 && (s.x - x).abs() < 1e-12, "{s:?}");
    // b = 0: a pure mass, x = F t²/(2m).
    let p = Plant::new(2.0, 0.0, 0.0, 1e-2);
    let mut s = PlantState::default();
    for _ in 0..100 {
        p.step_linear(&mut s, 3.0);
    }
    assert!((s.x - 0.75).abs() < 1e-12 && (s.v - 1.5).abs() < 1e-12);
}

#[test]
fn damped_stop_time_and_position_are_the_closed_form() {
    // m = 0.5, b = 2, f_c = 1, v0 = 1, no applied force: net force −1 N,
    // v∞ = −0.5 m/s, τ = m/b = 0.25 s. v(t) = v∞ + (v0 − v∞)e^{−t/τ} is
    // zero at t* = τ·ln(1 − v0/v∞) = 0.25·ln 3, where
    // x(t*) = v∞·t* + τ(v0 − v∞)(1 − e^{−t*/τ}) = −0.125 ln 3 + 0.25.
    let p = Plant::new(0.5, 2.0, 1.0, 1.0);
    let t_star = 0.25 * 3f64.ln();
    assert!((p.time_to_stop(1.0, -1.0) - t_star).abs() < 1e-14);
    // One 1 s interval: it stops at t* and sticks for the rest.
    let mut s = PlantState {
        v: 1.0,
        ..PlantState::default()
    };
    p.step_friction(&mut s, 0.0);
    assert_eq!(s.v, 0.0);
    let x_star = -0.125 * 3f64.ln() + 0.25;
    assert!((s.x - x_star).abs() < 1e-12, "{s:?} vs {x_star}");
    // Moving the other way, pushed on by 0.5 N (< f_c): net −0.5 − 1·(−1)
    // = +0.5 N decelerates v0 = −1; v∞ = +0.25, t* = 0.25·ln(1 + 4).
    let mut s = PlantState {
        v: -1.0,
        ..PlantState::default()
    };
    assert!((p.time_to_stop(-1.0, 0.5) - 0.25 * 5f64.ln()).abs() < 1e-14);
    p.step_friction(&mut s, -0.5);
    assert_eq!(s.v, 0.0);
    let t = 0.25 * 5f64.ln();
    let x = 0.25 * t + 0.25 * (-1.25) * (1.0 - (-t / 0.25).exp());
    assert!((s.x - x).abs() < 1e-12, "{s:?} vs {x}");
}

#[test]
fn coulomb_stops_and_sticks() {
    // m = 1, b = 0, f_c = 1, v0 = 1, F = 0.5 (< f_c): decelerates at 0.5 m/s²,
    // stops at t = 2 s after x = v0²/(2·0.5) = 1 m, then sticks.
    let p = Plant::new(1.0, 0.0, 1.0, 0.3);
    let mut s = PlantState {
        v: 1.0,
        ..PlantState::default()
    };
    for _ in 0..20 {
        p.step_friction(&mut s, 0.5);
    }
    assert_eq!(s.v, 0.0);
    assert!((s.x - 1.0).abs() < 1e-12, "{s:?}");
    // From rest, a force above f_c slips: F = 3 gives a = 2 m/s².
    let p = Plant::new(1.0, 0.0, 1.0, 0.5);
    let mut s = PlantState::default();
    p.step_friction(&mut s, 3.0);
    assert!((s.v - 1.0).abs() < 1e-12 && (s.x - 0.25).abs() < 1e-12);
    // Reversal: moving at −1 m/s with F = +3: stops after 0.25 s (net 4 N),
    // then slips forward with net 2 N for the remaining 0.25 s.
    let mut s = PlantState {
        v: -1.0,
        ..PlantState::default()
    };
    p.step_friction(&mut s, 3.0);
    assert!((s.v - 0.5).abs() < 1e-12, "{s:?}");
    assert!((s.x - (-0.125 + 0.0625)).abs() < 1e-12, "{s:?}");
}

#[test]
fn an_amplifier_lag_is_stepped_exactly() {
    // A pure mass (m = 2 kg, b = 0) from rest, command c = 3 N from
    // F_a = 0, τ = 1/(2π·50 Hz): F_a = c(1 − e^{−t/τ}),
    // v = (c/m)(t − τ(1 − e^{−t/τ})), x = (c/m)(t²/2 − τt + τ²(1 − e^{−t/τ})).
    let (m, c, dt) = (2.0, 3.0, 1e-3);
    let tau = 1.0 / (2.0 * std::f64::consts::PI * 50.0);
    let p = Plant::new(m, 0.0, 0.0, dt).with_drive(Some(50.0), None);
    let mut s = PlantState::default();
    for _ in 0..100 {
        p.step_driven(&mut s, c, 0.0, false);
    }
    let t: f64 = 0.1;
    let e = 1.0 - (-t / tau).exp();
    let (f, v, x) = (
        c * e,
        c / m * (t - tau * e),
        c / m * (t * t / 2.0 - tau * t + tau * tau * e),
    );
    assert!(
        (s.f - f).abs() < 1e-12 && (s.v - v).abs() < 1e-13 && (s.x - x).abs() < 1e-14,
        "{s:?} vs {x} {v} {f}"
    );
    // An external force acts at once, not through the lag: with the
    // motor off, as the plant without an amplifier.
    let (lagged, plain) = (p.clone(), Plant::new(m, 0.0, 0.0, dt));
    let (mut a, mut b) = (PlantState::default(), PlantState::default());
    for _ in 0..10 {
        lagged.step_driven(&mut a, 0.0, 1.0, false);
        plain.step_driven(&mut b, 0.0, 1.0, false);
    }
    assert!(
        (a.x - b.x).abs() < 1e-16 && (a.v - b.v).abs() < 1e-15,
        "{a:?} vs {b:?}"
    );
    // Without an amplifier the motor force is applied as commanded.
    plain.step_driven(&mut b, 2.5, 0.0, false);
    assert_eq!(b.f, 2.5);
}

#[test]
fn with_friction_the_lagged_force_s_impulse_is_exact() {
    // The same mass sliding forward (never stopping) against f_c =
    // 0.5 N: each step applies the lagged force's mean, so the velocity
    // is the exact impulse, v = (c(t − τ(1 − e^{−t/τ})) − f_c·t)/m + v0.
    let (m, c, fc, dt, v0) = (2.0, 3.0, 0.5, 1e-3, 1.0);
    let tau = 1.0 / (2.0 * std::f64::consts::PI * 50.0);
    let p = Plant::new(m, 0.0, fc, dt).with_drive(Some(50.0), None);
    let mut s = PlantState {
        v: v0,
        ..PlantState::default()
    };
    for _ in 0..100 {
        p.step_driven(&mut s, c, 0.0, true);
    }
    let t: f64 = 0.1;
    let e = 1.0 - (-t / tau).exp();
    let v = v0 + (c * (t - tau * e) - fc * t) / m;
    assert!(
        (s.v - v).abs() < 1e-12 && (s.f - c * e).abs() < 1e-12,
        "{s:?} vs {v}"
    );
}

#[test]
fn a_stiff_cable_on_a_light_motor_conserves_energy_without_damping() {
    // No damping anywhere: the exact flow conserves E = ½m v² + ½m_m v_m²
    // + ½k(x_m − x)², and so must the discrete step (it samples the
    // flow). A 1e8 N/m cable on a 1 mg motor side at 1 kHz (a 1.6 MHz
    // mode, 1e4 radians a step) is the hardest validated case.
    let t = Transmission {
        motor_mass: 1e-6,
        motor_damping: 0.0,
        stiffness: 1e8,
        damping: 0.0,
        encoder_on_motor: true,
    };
    let p = Plant::new(0.52, 0.0, 0.0, 1e-3).with_drive(None, Some(t));
    let energy = |s: &PlantState| {
        0.5 * 0.52 * s.v * s.v + 0.5 * 1e-6 * s.vm * s.vm + 0.5 * 1e8 * (s.xm - s.x).powi(2)
    };
    let mut s = PlantState {
        xm: 1e-6,
        v: 0.01,
        ..PlantState::default()
    };
    let e0 = energy(&s);
    for _ in 0..1000 {
        p.step_driven(&mut s, 0.0, 0.0, false);
    }
    assert!(
        (energy(&s) / e0 - 1.0).abs() < 1e-6,
        "{} vs {e0}",
        energy(&s)
    );
    // With cable damping it only loses energy, step after step.
    let damped =
        Plant::new(0.52, 0.0, 0.0, 1e-3).with_drive(None, Some(Transmission { damping: 1.0, ..t }));
    let mut s = PlantState {
        xm: 1e-6,
        v: 0.01,
        ..PlantState::default()
    };
    let mut e = energy(&s);
    for _ in 0..1000 {
        damped.step_driven(&mut s, 0.0, 0.0, false);
        assert!(energy(&s) <= e * (1.0 + 1e-9), "{} after {e}", energy(&s));
        e = energy(&s);
    }
}
