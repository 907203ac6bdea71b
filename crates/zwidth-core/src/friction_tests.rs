use super::*;
use crate::plant::{Plant, PlantState, Transmission};

/// Fc = 1 N, Fs = 1.5 N, v_s = 0.1 m/s, σ0 = 1e5 N/m, σ1 = √1e5 N·s/m.
fn model() -> LuGre {
    LuGre {
        kinetic: 1.0,
        static_force: 1.5,
        stribeck_velocity: 0.1,
        stiffness: 1e5,
        damping: 1e5f64.sqrt(),
        on_motor: false,
    }
}

/// A 0.1 kg motor side (2 N·s/m) on a 1e4 N/m, 10 N·s/m cable, encoder on
/// the motor.
fn cable() -> Transmission {
    Transmission {
        motor_mass: 0.1,
        motor_damping: 2.0,
        stiffness: 1e4,
        damping: 10.0,
        encoder_on_motor: true,
    }
}

fn run(p: &Plant, s: &mut PlantState, force: impl Fn(usize) -> f64, steps: usize) {
    for i in 0..steps {
        p.step_driven(s, force(i), 0.0, true);
    }
}

#[test]
fn the_stribeck_curve_and_the_bristle_step_are_their_formulas() {
    let m = model();
    // g(0) = F_s, g(v_s) = F_c + (F_s − F_c)/e, g(∞) = F_c, even in v.
    assert_eq!(m.level(0.0), 1.5);
    assert!((m.level(0.1) - (1.0 + 0.5 / std::f64::consts::E)).abs() < 1e-15);
    assert!((m.level(-0.1) - m.level(0.1)).abs() < 1e-15);
    assert!((m.level(10.0) - 1.0).abs() < 1e-15);
    // ż = v − σ0|v| z/g(v) for v = 0.1: from z = 0 the exponential toward
    // z_ss = g/σ0 at rate σ0|v|/g; at rest z stays.
    let (g, h) = (m.level(0.1), 1e-5);
    let want = g / 1e5 * (1.0 - (-1e5 * 0.1 / g * h).exp());
    assert!((m.bristle(0.0, 0.1, h) - want).abs() < 1e-18);
    assert!((m.bristle(0.0, -0.1, h) + want).abs() < 1e-18);
    assert_eq!(m.bristle(3e-6, 0.0, h), 3e-6);
    // Long at one velocity: the steady deflection g(v)/σ0.
    assert!((m.bristle(-1e-5, 0.1, 1.0) - g / 1e5).abs() < 1e-18);
    // Substeps: 3 % of √(m/σ0) = 6.708e-5 s, a tenth of m/σ1 = 1.58e-4 s.
    assert_eq!(lugre_substeps(0.5, 1e5, 1e5f64.sqrt(), 1e-3), 15.0);
    assert_eq!(lugre_substeps(0.5, 1e5, 1e4, 1e-3), 200.0);
    assert_eq!(lugre_substeps(0.5, 1e5, 0.0, 1e-3), 15.0);
    assert_eq!(lugre_substeps(0.5, 1e5, 0.0, 1e-6), 1.0);
}

#[test]
fn steady_sliding_settles_on_the_stribeck_curve() {
    // m v̇ = F − b v − g(v) at rest when F = b v + g(v): with b = 5 N·s/m
    // and F = 1 + 5·0.1 + 0.5/e the handle slides at exactly 0.1 m/s
    // (stable: b > −g'(0.1) = 3.68), and the bristle at g(0.1)/σ0 (1995
    // paper: steady state F = g(v) sign v + σ2 v).
    let f = 1.0 + 0.5 + 0.5 / std::f64::consts::E;
    let p = Plant::new(0.5, 5.0, 1.0, 1e-3).with_lugre(Some(model()));
    let mut s = PlantState::default();
    run(&p, &mut s, |_| f, 20_000);
    assert!((s.v - 0.1).abs() < 1e-9, "{s:?}");
    assert!((s.z - model().level(0.1) / 1e5).abs() < 1e-15, "{s:?}");
    // The same force from the hand (an external force on the handle, as
    // the probe's excitation) instead of the motor.
    let mut s = PlantState::default();
    for _ in 0..20_000 {
        p.step_driven(&mut s, 0.0, f, true);
    }
    assert!((s.v - 0.1).abs() < 1e-9, "{s:?}");
    // The same on the motor side of a transmission: b = 3 + 2 on the two
    // masses, the motor pulls the handle through the cable.
    let t = cable();
    let on_motor = LuGre {
        on_motor: true,
        ..model()
    };
    let p = Plant::new(0.4, 3.0, 1.0, 1e-3)
        .with_drive(None, Some(t))
        .with_lugre(Some(on_motor));
    let mut s = p.at_rest(0.0);
    run(&p, &mut s, |_| f, 20_000);
    assert!(
        (s.v - 0.1).abs() < 1e-9 && (s.vm - 0.1).abs() < 1e-9,
        "{s:?}"
    );
}

#[test]
fn below_breakaway_the_bristles_give_as_a_damped_spring() {
    // A force far below F_c deflects the bristles only (σ0|z| ≪ g): the
    // handle is the mass–spring–damper m ẍ + σ1 ẋ + σ0 x = F (1995 paper
    // its pre-sliding spring), with ω0 = √(σ0/m) = 447.2 rad/s and
    // ζ = σ1/(2√(σ0 m)) = 0.0224, so it rings at ω_d = ω0√(1 − ζ²) and comes
    // to rest at F/σ0, where ideal Coulomb friction holds it at 0.
    let lg = LuGre {
        damping: 10.0,
        ..model()
    };
    let p = Plant::new(0.5, 0.0, 1.0, 1e-3).with_lugre(Some(lg));
    let mut s = PlantState::default();
    let (f, w0, zeta) = (1e-3, (2e5f64).sqrt(), 10.0 / (2.0 * (5e4f64).sqrt()));
    let wd = w0 * (1.0 - zeta * zeta).sqrt();
    // Every sample of the first 0.1 s (seven cycles) against the linear
    // closed-form step response (to 2 %: it drops σ0|v|z/g, ≈ 1e-3 here)
    // and against the RK4 reference of the whole model (to 0.5 %).
    let reference = rk4_reference(&lg, 0.5, 0.0, 0.0, |_| f, 100, 1000);
    for (i, r) in reference.iter().enumerate() {
        p.step_driven(&mut s, f, 0.0, true);
        let t = (i + 1) as f64 * 1e-3;
        let x = f / 1e5
            * (1.0
                - (-zeta * w0 * t).exp()
                    * ((wd * t).cos() + zeta / (1.0 - zeta * zeta).sqrt() * (wd * t).sin()));
        assert!((s.x - x).abs() < 0.02 * f / 1e5, "t = {t}: {} vs {x}", s.x);
        assert!(
            (s.x - r[0]).abs() < 0.005 * f / 1e5,
            "t = {t}: {} vs RK4 {}",
            s.x,
            r[0]
        );
    }
    // At rest after 5 s: the bristles hold F (z = F/σ0 exactly); the
    // handle crept 1.9 % past that while ringing (x − z = ∫σ0|v|z/g dt),
    // as the reference did.
    run(&p, &mut s, |_| f, 4900);
    let reference = rk4_reference(&lg, 0.5, 0.0, 0.0, |_| f, 5000, 200);
    assert!(
        (s.x / reference[4999][0] - 1.0).abs() < 1e-3,
        "{s:?} vs {:?}",
        reference[4999]
    );
    assert!((s.x / (f / 1e5) - 1.0).abs() > 0.01, "{s:?}");
    assert!((s.z * 1e5 / f - 1.0).abs() < 1e-9, "{s:?}");
    let coulomb = Plant::new(0.5, 0.0, 1.0, 1e-3);
    let mut c = PlantState::default();
    run(&coulomb, &mut c, |_| f, 100);
    assert_eq!(c.x, 0.0);
}

#[test]
fn a_slow_ramp_breaks_loose_where_the_reference_does() {
    // F = 0.5 N/s · t from rest: the handle creeps in pre-sliding, then
    // breaks loose near F_s (Canudas de Wit 1995: break-away at F_s
    // for slow ramps); "loose" here is v > v_s, reached a little below F_s
    // as friction falls along the Stribeck curve. The sample it happens at
    // is the RK4 reference's (to one sample: 0.5 mN); with F_s = F_c it is
    // near F_c instead.
    for fs in [1.5, 1.0] {
        let lg = LuGre {
            static_force: fs,
            stribeck_velocity: 1e-3,
            ..model()
        };
        let ramp = |i: usize| 0.5 * i as f64 * 1e-3;
        let reference = rk4_reference(&lg, 0.5, 1.0, 0.0, ramp, 4000, 200);
        let want = reference.iter().position(|r| r[1] > 1e-3).expect("loose");
        let p = Plant::new(0.5, 1.0, 1.0, 1e-3).with_lugre(Some(lg));
        let mut s = PlantState::default();
        let got = (0..4000)
            .position(|i| {
                p.step_driven(&mut s, ramp(i), 0.0, true);
                s.v > 1e-3
            })
            .expect("it breaks loose");
        assert!(
            got.abs_diff(want) <= 1,
            "F_s = {fs}: sample {got} vs {want}"
        );
        let f = ramp(got);
        assert!((f / fs - 1.0).abs() < 0.03, "F_s = {fs}: at {f} N");
    }
}

#[test]
fn stiff_bristles_stop_where_ideal_coulomb_friction_stops() {
    // m = 0.5, b = 2, F_c = F_s = 1, v0 = 1, no force: ideal Coulomb stops
    // at t* = 0.25 ln 3 at x* = 0.25 − 0.125 ln 3 (plant.rs's closed form).
    // Stiff bristles (σ0 = 1e8 N/m, σ1 as the 1995 paper's) approach that
    // model (LuGre → Coulomb as σ0 → ∞), within the bristles' own
    // deflection g/σ0 = 1e-8 m.
    let lg = LuGre {
        static_force: 1.0,
        stiffness: 1e8,
        ..model()
    };
    let p = Plant::new(0.5, 2.0, 1.0, 1e-3).with_lugre(Some(lg));
    let mut s = PlantState {
        v: 1.0,
        ..PlantState::default()
    };
    run(&p, &mut s, |_| 0.0, 1000);
    let x_star = 0.25 - 0.125 * 3f64.ln();
    assert!((s.x - x_star).abs() < 1e-6, "{} vs {x_star}", s.x);
    assert!(s.v.abs() < 1e-6, "{s:?}");
}

/// An independent reference: the rigid device with LuGre friction as one
/// ODE in (x, v, z), `ẋ = v`, `ż = v − σ0|v|z/g(v)`,
/// `m v̇ = F(t) − b v − σ0 z − σ1 ż`, by classical RK4 at step `h` (no
/// splitting, no exponential, no hold). Returns (x, v, z) at the end of
/// every 1 ms sample for the force held over it.
fn rk4_reference(
    lg: &LuGre,
    m: f64,
    b: f64,
    v0: f64,
    force: impl Fn(usize) -> f64,
    samples: usize,
    per_sample: usize,
) -> Vec<[f64; 3]> {
    let deriv = |y: [f64; 3], f: f64| {
        let (v, z) = (y[1], y[2]);
        let g = lg.kinetic
            + (lg.static_force - lg.kinetic) * (-(v / lg.stribeck_velocity).powi(2)).exp();
        let zd = v - lg.stiffness * v.abs() * z / g;
        [v, (f - b * v - lg.stiffness * z - lg.damping * zd) / m, zd]
    };
    let h = 1e-3 / per_sample as f64;
    let mut y = [0.0, v0, 0.0];
    let mut out = Vec::with_capacity(samples);
    for i in 0..samples {
        let f = force(i);
        for _ in 0..per_sample {
            let k1 = deriv(y, f);
            let add = |a: [f64; 3], k: [f64; 3], s: f64| {
                [a[0] + s * k[0], a[1] + s * k[1], a[2] + s * k[2]]
            };
            let k2 = deriv(add(y, k1, h / 2.0), f);
            let k3 = deriv(add(y, k2, h / 2.0), f);
            let k4 = deriv(add(y, k3, h), f);
            for j in 0..3 {
                y[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
            }
        }
        out.push(y);
    }
    out
}

#[test]
fn a_step_below_static_friction_breaks_loose_when_its_rate_is_high() {
    // The seed device (0.52 kg, 13.2 N·s/m) with F_c = 0.19 N, F_s = 0.5 N,
    // v_s = 1 mm/s: a 0.3572 N step is below F_s, yet the bristle damper
    // lets the handle reach F/σ1 ≈ 1.1 mm/s > v_s within a millisecond,
    // the Stribeck curve drops to F_c, and it slides (LuGre's break-away
    // force falls as the force's rate rises, Canudas de Wit 1995). It
    // ends at the terminal velocity (F − F_c)/b, as the RK4 reference does.
    let lg = LuGre {
        kinetic: 0.19,
        static_force: 0.5,
        stribeck_velocity: 1e-3,
        ..model()
    };
    let p = Plant::new(0.52, 13.2, 0.19, 1e-3).with_lugre(Some(lg));
    let mut s = PlantState::default();
    let reference = rk4_reference(&lg, 0.52, 13.2, 0.0, |_| 0.3572, 1000, 1000);
    for r in &reference {
        p.step_driven(&mut s, 0.3572, 0.0, true);
        assert!(
            (s.x - r[0]).abs() <= 1e-3 * r[0].abs() + 1e-8,
            "{s:?} vs {r:?}"
        );
    }
    assert!((s.v / ((0.3572 - 0.19) / 13.2) - 1.0).abs() < 1e-9, "{s:?}");
}

#[test]
fn friction_holds_the_side_it_acts_on() {
    // A 0.01 N motor force, far below F_c, on the two-mass device. With the
    // friction on the motor side the bristles there take it all (z = F/σ0
    // = 1e-7 m) and the cable carries nothing: the handle rests where the
    // motor side does. With it on the handle the cable carries F and
    // stretches by F/k = 1e-6 m (statics of the model in plant.rs).
    let t = cable();
    for on_motor in [true, false] {
        let lg = LuGre {
            on_motor,
            ..model()
        };
        let p = Plant::new(0.4, 3.0, 1.0, 1e-3)
            .with_drive(None, Some(t))
            .with_lugre(Some(lg));
        let mut s = p.at_rest(0.0);
        run(&p, &mut s, |_| 0.01, 5000);
        let stretch = s.xm - s.x;
        let want = if on_motor { 0.0 } else { 0.01 / 1e4 };
        assert!((stretch - want).abs() < 1e-9, "on_motor {on_motor}: {s:?}");
        assert!(
            (s.z * 1e5 / 0.01 - 1.0).abs() < 1e-6,
            "on_motor {on_motor}: {s:?}"
        );
    }
}
