//! Tests of `probe.rs` (the multisine probe: its verdicts, settling and
//! the BLA realizations).

use super::*;
use crate::zwidth::analytic::LinearModel;
use crate::zwidth::scene::SceneSpec;

#[test]
fn remaining_transient_by_aitken() {
    let c = |re: f64| C::new(re, 0.0);
    // Decaying by r = 0.5 per period with d = 1: what remains is
    // d·r/(r − 1) = −1, so 1 N·s/m.
    assert!((remaining_transient(&[c(10.0)], &[c(1.0)], &[c(2.0)]) - 1.0).abs() < 1e-12);
    // r = 0.25: d·r/(r − 1) = 0.25/(−0.75), so 1/3 remains.
    assert!((remaining_transient(&[c(10.0)], &[c(1.0)], &[c(4.0)]) - 1.0 / 3.0).abs() < 1e-12);
    // Growing (r = 2) or not a number: never settled.
    assert_eq!(
        remaining_transient(&[c(10.0)], &[c(2.0)], &[c(1.0)]),
        f64::INFINITY
    );
    assert_eq!(
        remaining_transient(&[c(10.0)], &[c(f64::NAN)], &[c(1.0)]),
        f64::INFINITY
    );
    // No change at all: nothing remains; the worst line counts.
    assert_eq!(remaining_transient(&[c(10.0)], &[c(0.0)], &[c(1.0)]), 0.0);
    let two = remaining_transient(&[c(10.0), c(10.0)], &[c(0.0), c(1.0)], &[c(1.0), c(2.0)]);
    assert!((two - 1.0).abs() < 1e-12);
}

#[test]
fn tail_verdict_needs_re_z_three_standard_errors_above_zero() {
    // Four periods; the tail is the last two. One line, Re Z in the
    // tail 2 ± 0.001: mean 2, se = √((2·0.001²)/1/2) = 0.001, so
    // 2 − 3·0.001 > 0 is passive. Re Z 10 ± 8: se = 8, 10 − 24 < 0
    // is not (a spread like a growing oscillation's).
    let hist = |a: f64, b: f64| {
        vec![vec![C::new(-50.0, 0.0)]; 2]
            .into_iter()
            .chain([vec![C::new(a, 1.0)], vec![C::new(b, 3.0)]])
            .collect::<Vec<_>>()
    };
    let (mean, passive) = tail_verdict(&hist(1.999, 2.001)).unwrap();
    assert!((mean[0] - C::new(2.0, 2.0)).norm() < 1e-12, "{mean:?}");
    assert!(passive);
    let (mean, passive) = tail_verdict(&hist(2.0, 18.0)).unwrap();
    assert!((mean[0].re - 10.0).abs() < 1e-12);
    assert!(!passive);
    // Exactly three standard errors: 3 ± 1 has se 1, 3 − 3·1 = 0 passes.
    assert!(tail_verdict(&hist(2.0, 4.0)).unwrap().1);
    // Fewer than two periods in the tail: no verdict.
    assert!(tail_verdict(&hist(1.0, 1.0)[2..]).is_none());
    assert!(tail_verdict(&[vec![C::new(1.0, 0.0)]]).is_none());
}

const KNOBS: ProbeKnobs = ProbeKnobs {
    periods: 2,
    settle_tol: 1e-6,
    max_periods: 400,
    realizations: 8,
};

#[test]
fn friction_is_simulated_wherever_the_scene_names_it() {
    // The seed device at 1 kHz, K = 2e4 N/m, B = 5 N·s/m, with and
    // without its 0.19 N Coulomb friction and its 1 µm encoder: each
    // noisy variant is judged by the BLA (a confidence), and friction
    // adds damping (its describing function, 4f_c/(πAω) > 0, Gelb &
    // Vander Velde 1968), so it raises the least band's Re Z well beyond
    // both standard errors.
    let margin = |coulomb: f64, q: f64| {
        let j = format!(
            r#"{{"device":{{"coulomb":{coulomb},"quantization":{q}}},"loop":{{"sample_hz":1000,"render_hz":1000}}}}"#
        );
        let sc = SceneSpec::from_json(&j).unwrap().validate().unwrap();
        let c = probe(&sc, 2e4, 5.0, KNOBS)
            .confidence
            .expect("a BLA verdict");
        (c.margin, c.margin_se)
    };
    // (Without friction or quantization the scene is linear and has no
    // BLA: the friction-only variant's twin has a 1e-12 m encoder.)
    for q in [0.0, 1e-6] {
        let (with, se_w) = margin(0.19, q);
        let (without, se_wo) = margin(0.0, q.max(1e-12));
        assert!(
            with - without > 3.0 * (se_w + se_wo),
            "q={q}: {with}±{se_w} vs {without}±{se_wo}"
        );
    }
}

#[test]
fn tfestimate_is_welchs_h1_of_the_exact_response() {
    // A quantization step of 1e-12 m makes the scene "noisy" (so the
    // `tfestimate` verdict runs) while the loop stays linear to ~1e-9.
    // K = 5000 N/m, B = 5 N·s/m on the seed device settle within the
    // transient period (time constant m/(b + B) ≈ 29 ms against 0.5 s).
    // Expected, computed in the frequency domain, independently of the
    // code's time-domain windows: the steady response on bin j is
    // V_j = G(ω_j)·F_j (G = 1/Z from the analytic formula, DESIGN.md),
    // F_j the design's lines (0 off them); a Hann window one period
    // long makes bin k 0.5·X_k − 0.25·(X_{k−1} + X_{k+1}) for a segment
    // starting on a period, and 0.5·X_k + 0.25·(X_{k−1} + X_{k+1}) (up
    // to a common sign) for one starting half a period in; P periods
    // give P of the first and P − 1 of the second; Ĝ = Σ V·F̄ / Σ |F|².
    let (k, b) = (5000.0, 5.0);
    let j = r#"{"device":{"coulomb":0,"quantization":1e-12},"loop":{"sample_hz":1000,"render_hz":1000},"probe":{"f_min_hz":2,"f_max_hz":100,"method":"tfestimate"}}"#;
    let sc = SceneSpec::from_json(j).unwrap().validate().unwrap();
    let setup = ProbeSetup::new(&sc);
    let o = probe_with(&setup, &sc, k, b, KNOBS);
    assert!(o.confidence.is_none(), "the baseline states no confidence");
    let p = tfestimate_periods(KNOBS.periods);
    assert_eq!(p, 3 * (1 + 2) - 1);
    assert_eq!(o.periods_run, 1 + p);
    let mut lin = SceneSpec::from_json(j).unwrap();
    lin.device.quantization = 0.0;
    let m = LinearModel::new(&lin.validate().unwrap()).unwrap();
    let (jj, h) = (C::new(0.0, 1.0), setup.h);
    let hold = |w: f64| (C::new(1.0, 0.0) - C::from_polar(1.0, -w * h)) / (jj * w * h);
    // Bins as the code sees them: sampled force F_true/hold, mean
    // velocity G·F_true/v_correction.
    let bins = setup.lines.len() + 2;
    let (mut v, mut f) = (
        vec![C::new(0.0, 0.0); bins + 1],
        vec![C::new(0.0, 0.0); bins + 1],
    );
    for (l, &bin) in setup.lines.iter().enumerate() {
        let w = setup.omegas[l];
        let g = C::new(1.0, 0.0) / m.impedance_at(k, b, w);
        f[bin] = setup.f_lines[l] / hold(w);
        v[bin] = g * setup.f_lines[l] / setup.v_correction[l];
    }
    let mut smoothing = 0.0f64;
    for (l, &bin) in setup.lines.iter().enumerate() {
        let w = setup.omegas[l];
        let win = |x: &[C], sign: f64| 0.5 * x[bin] + sign * 0.25 * (x[bin - 1] + x[bin + 1]);
        let (pe, po) = (p as f64, (p - 1) as f64);
        let num =
            pe * win(&v, -1.0) * win(&f, -1.0).conj() + po * win(&v, 1.0) * win(&f, 1.0).conj();
        let den = pe * win(&f, -1.0).norm_sqr() + po * win(&f, 1.0).norm_sqr();
        let g = num / den * setup.v_correction[l] / hold(w);
        let want = C::new(1.0, 0.0) / g;
        let got = C::from_polar(
            o.impedance.magnitude[l],
            o.impedance.phase_deg[l].to_radians(),
        );
        assert!(
            (got - want).norm() < 1e-5 * want.norm(),
            "line {l} ({} Hz): {got} vs {want}",
            w / std::f64::consts::TAU
        );
        let plain = m.impedance_at(k, b, w);
        smoothing = smoothing.max((got - plain).norm() / plain.norm());
    }
    // The window's smoothing is far above the tolerance (the check can
    // tell a windowed estimate from the plain ratio of lines).
    assert!(smoothing > 1e-3, "{smoothing}");
    assert_eq!(
        o.passive,
        o.impedance.phase_deg.iter().all(|p| p.abs() <= 90.0)
    );
}

#[test]
fn matches_analytic_impedance_on_a_linear_scene() {
    // Independent formula: DESIGN.md's X/F(jω) (analytic.rs). A stable,
    // well-damped point: the measured Z must agree on every line.
    // With an amplifier lag the simulation steps (x, v, F_a) exactly
    // and the formula carries L(jω) = 1/(1 + jωτ): the two must agree.
    // So with a two-mass transmission (encoder on either side): the
    // formula's G_he, G_hm, G_ee against the exact five-state steps.
    let cable = |enc: &str| {
        format!(r#"{{"motor_mass":0.22,"stiffness":5e4,"damping":2,"encoder":"{enc}"}}"#)
    };
    for (est, amp, tr) in [
        (r#"{"kind":"fdm"}"#, "null", "null".to_string()),
        (
            r#"{"kind":"butterworth","cutoff_hz":200}"#,
            "null",
            "null".into(),
        ),
        (r#"{"kind":"fdm"}"#, "100", "null".into()),
        (
            r#"{"kind":"butterworth","cutoff_hz":200}"#,
            "300",
            "null".into(),
        ),
        (r#"{"kind":"fdm"}"#, "null", cable("motor")),
        (
            r#"{"kind":"butterworth","cutoff_hz":200}"#,
            "300",
            cable("handle"),
        ),
    ] {
        let j = format!(
            r#"{{"device":{{"coulomb":0,"quantization":0,"amplifier_hz":{amp},"transmission":{tr}}},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{est},"probe":{{"f_min_hz":2,"f_max_hz":100}}}}"#
        );
        let sc = SceneSpec::from_json(&j).unwrap().validate().unwrap();
        let m = LinearModel::new(&sc).unwrap();
        // Settled to 1e-9 of the damping scale: the cable mode (2 N·s/m
        // over 0.127 kg reduced mass) keeps 2 % a period.
        let tight = ProbeKnobs {
            settle_tol: 1e-9,
            ..KNOBS
        };
        let o = probe(&sc, 5000.0, 5.0, tight);
        assert!(o.settled, "{est}: {o:?}");
        let want = m.impedance(5000.0, 5.0);
        // The formula keeps each line's fundamental only; the handle
        // encoder's path, (cs + k)/(s·P₃), rolls off more slowly than
        // the rigid 1/s², and the phase there differs by up to 1.05e-3°
        // at 74 Hz (|Z| by 2.3e-6): 2e-3° for the transmission rows.
        let phase_tol = if tr == "null" { 1e-3 } else { 2e-3 };
        for i in 0..want.magnitude.len() {
            let rel = (o.impedance.magnitude[i] / want.magnitude[i] - 1.0).abs();
            let dphi = (o.impedance.phase_deg[i] - want.phase_deg[i]).abs();
            assert!(
                rel < 1e-5 && dphi < phase_tol,
                "{est} {tr} line {i}: |Z| {} vs {}, phase {} vs {}",
                o.impedance.magnitude[i],
                want.magnitude[i],
                o.impedance.phase_deg[i],
                want.phase_deg[i]
            );
        }
    }
}

#[test]
fn settles_before_judging_a_barely_passive_wall() {
    // Seed device, 1 kHz, FDM, B = 0, K = 23 812 N/m: the analytic
    // impedance (DESIGN.md formula) has Re Z = b − KT/2-like 1.294 N·s/m
    // at 1 Hz, the smallest on the band; the wall mode (34 Hz) decays
    // by only ~0.26 per period. The standard knobs must not stop early.
    let sc = SceneSpec::from_json(
        r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
    )
    .unwrap()
    .validate()
    .unwrap();
    let want = LinearModel::new(&sc).unwrap().impedance(23_812.0, 0.0);
    let o = probe(
        &sc,
        23_812.0,
        0.0,
        ProbeKnobs {
            periods: 4,
            settle_tol: 1e-3,
            max_periods: 150,
            realizations: 8,
        },
    );
    assert!(o.passive && o.settled, "{o:?}");
    let re = |c: &ImpedanceCurve, i: usize| c.magnitude[i] * c.phase_deg[i].to_radians().cos();
    for i in 0..want.magnitude.len() {
        assert!(
            (re(&o.impedance, i) - re(&want, i)).abs() < 0.05,
            "line {i}: {} vs {}",
            re(&o.impedance, i),
            re(&want, i)
        );
    }
}

/// The 2018 device at 1 kHz with the given extra scene JSON fields.
fn scene_1khz(device: &str, probe: &str) -> Scene {
    SceneSpec::from_json(&format!(
        r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}},"probe":{probe}}}"#
    ))
    .unwrap()
    .validate()
    .unwrap()
}

#[test]
fn a_clear_bla_verdict_is_taken_at_the_first_look() {
    // A 1e-12 m encoder: noisy by the scene (BLA) but linear to ~1e-9.
    // K = 5000, B = 5 is far inside the passive region (Re Z ≈ 15 N·s/m
    // with a standard error near 1e-9), so the first look, after
    // MIN_REALIZATIONS = 3 realizations (bla.rs), decides; each ran one
    // transient period and KNOBS.periods = 2 averaged ones.
    let sc = scene_1khz(
        r#"{"coulomb":0,"quantization":1e-12}"#,
        r#"{"f_min_hz":2,"f_max_hz":100}"#,
    );
    let o = probe(&sc, 5000.0, 5.0, KNOBS);
    let c = o.confidence.expect("a BLA verdict");
    assert!(c.decided && o.passive, "{c:?}");
    assert_eq!(c.realizations, 3);
    assert_eq!(o.periods_run, 3 * (1 + 2));
    assert!(c.noise_se > 0.0 && c.margin > 100.0 * c.margin_se, "{c:?}");
    // Its Z is the analytic one (DESIGN.md's formula, analytic.rs).
    let lin = scene_1khz(
        r#"{"coulomb":0,"quantization":0}"#,
        r#"{"f_min_hz":2,"f_max_hz":100}"#,
    );
    let want = LinearModel::new(&lin).unwrap().impedance(5000.0, 5.0);
    for i in 0..want.magnitude.len() {
        let rel = (o.impedance.magnitude[i] / want.magnitude[i] - 1.0).abs();
        let dphi = (o.impedance.phase_deg[i] - want.phase_deg[i]).abs();
        assert!(rel < 1e-3 && dphi < 0.1, "line {i}: {rel} {dphi}");
    }
}

#[test]
fn a_diverged_probe_reads_minus_one_on_every_line() {
    // K = 1e7 N/m at 1 kHz diverges within the first period; the
    // outcome's Z stands at −1 (phase 180°, |Z| = 1: "no steady state").
    let check = |o: &ProbeOutcome| {
        assert!(o.diverged && !o.passive && !o.settled, "{o:?}");
        assert_eq!(o.periods_run, 1);
        assert_eq!(o.last_change, f64::MAX);
        assert!(o.impedance.phase_deg.iter().all(|&p| p == 180.0), "{o:?}");
        assert!(o.impedance.magnitude.iter().all(|&m| m == 1.0), "{o:?}");
    };
    let lin = scene_1khz(r#"{"coulomb":0,"quantization":0}"#, "{}");
    let o = probe(&lin, 1e7, 0.0, KNOBS);
    check(&o);
    assert_eq!(o.confidence, None);
    // A noisy scene: decided at once, with no doubt.
    let seed = scene_1khz("{}", "{}");
    let o = probe(&seed, 1e7, 0.0, KNOBS);
    check(&o);
    assert_eq!(
        o.confidence,
        Some(VerdictConfidence {
            decided: true,
            margin: -1.0,
            margin_se: 0.0,
            noise_se: 0.0,
            realizations: 1,
            bands: 0,
        })
    );
}

#[test]
fn a_linear_loop_settles_after_two_calm_looks_then_averages() {
    // The first Aitken estimate needs three periods (Z, its change, the
    // change before); two calm ones in a row settle it, then
    // KNOBS.periods are averaged. With a tolerance every look meets
    // (0.5 of the damping scale b + B), periods 3 and 4 are the calm
    // ones: 4 + 2 periods, the fewest the rule allows.
    let sc = scene_1khz(
        r#"{"coulomb":0,"quantization":0}"#,
        r#"{"f_min_hz":2,"f_max_hz":100}"#,
    );
    let loose = ProbeKnobs {
        settle_tol: 0.5,
        ..KNOBS
    };
    let o = probe(&sc, 5000.0, 5.0, loose);
    assert!(o.settled && o.passive, "{o:?}");
    assert_eq!(o.periods_run, 4 + KNOBS.periods);
    // A tight tolerance takes as long as the transient needs, never less.
    let o = probe(&sc, 5000.0, 5.0, KNOBS);
    assert!(o.settled && o.periods_run > 4 + KNOBS.periods, "{o:?}");
    assert!(o.last_change < KNOBS.settle_tol, "{o:?}");
    // With at most 2 periods nothing can settle, and a tail of one
    // period gives no verdict: not passive, Z at −1.
    let two = ProbeKnobs {
        max_periods: 2,
        ..KNOBS
    };
    let o = probe(&sc, 5000.0, 5.0, two);
    assert!(!o.settled && !o.diverged && !o.passive, "{o:?}");
    assert_eq!((o.periods_run, o.last_change), (2, f64::MAX));
    assert!(o.impedance.phase_deg.iter().all(|&p| p == 180.0), "{o:?}");
}

#[test]
fn the_tail_s_standard_error_divides_by_n_minus_one() {
    // Six periods; the tail is the last three with Re Z = 1 − d, 1,
    // 1 + d: sample variance d², se = d/√3. Passive iff 1 − 3d/√3 ≥ 0,
    // i.e. d ≤ 1/√3 = 0.577: 0.55 passes, 0.6 does not.
    let hist = |d: f64| {
        let mut h = vec![vec![C::new(-50.0, 0.0)]; 3];
        h.extend([1.0 - d, 1.0, 1.0 + d].map(|re| vec![C::new(re, 0.0)]));
        h
    };
    assert!(tail_verdict(&hist(0.55)).unwrap().1);
    assert!(!tail_verdict(&hist(0.6)).unwrap().1);
}

#[test]
fn a_negligible_change_is_no_transient_and_a_ratio_of_one_never_settles() {
    let c = |re: f64| C::new(re, 0.0);
    // |d| ≤ 1e-12·|Z|: nothing remains (module doc).
    assert_eq!(
        remaining_transient(&[c(10.0)], &[c(1e-12)], &[c(1e-13)]),
        0.0
    );
    assert!(remaining_transient(&[c(10.0)], &[c(1e-10)], &[c(1e-9)]) > 0.0);
    // r = 1: not decaying.
    assert_eq!(
        remaining_transient(&[c(10.0)], &[c(1.0)], &[c(1.0)]),
        f64::INFINITY
    );
}

#[test]
fn the_loop_stops_past_ten_metres_or_a_kilometre_per_second() {
    let sc = scene_1khz(r#"{"coulomb":0,"quantization":0}"#, "{}");
    let setup = ProbeSetup::new(&sc);
    let mut v = vec![0.0; 1];
    let mut lp = Loop::<false, false>::new(&setup, &sc, 0.0, 0.0);
    assert!(lp.period(&[0.0], &mut v), "at rest");
    lp.st.x = 50.0;
    assert!(!lp.period(&[0.0], &mut v));
    lp.st.x = 0.0;
    lp.st.v = 2000.0;
    assert!(!lp.period(&[0.0], &mut v));
}

#[test]
fn a_wall_that_clips_at_the_force_limit_is_decided_not_passive() {
    // The seed device at 1 kHz, B = 0: its loop goes unstable past about
    // 48 000 N/m (the standard map's boundary there, docs/zwidth.md). With
    // a 2 N force limit the unstable loop cannot diverge: it limit-cycles
    // at the limit, every realization clipping far more than CLIP_SHARE of
    // its renders. Decided not passive once P(X ≥ m | m, ½) = 2^−m is at
    // most the per-look rate: α/looks = 0.05/(8 − 3 + 1) = 0.0083 with
    // KNOBS' 8 realizations, so after m = 7 (2^−7 = 0.0078; 2^−6 = 0.016).
    // Without the rule a loop that neither diverges nor decides runs all 8.
    let limited = scene_1khz(r#"{"force_limit":2.0}"#, r#"{"amplitude":0.5}"#);
    let o = probe(&limited, 80_000.0, 0.0, KNOBS);
    let c = o.confidence.expect("a BLA verdict");
    assert!(c.decided && !o.passive && !o.diverged, "{c:?}");
    assert_eq!(c.realizations, 7);
    assert_eq!(o.periods_run, 7 * (1 + KNOBS.periods));
    // 7 × 2 measured periods of 1 000 renders: at least 1 % of each clipped.
    assert!(o.saturated_renders >= 7 * 20, "{}", o.saturated_renders);
    // Without the limit the same loop diverges.
    let free = scene_1khz("{}", r#"{"amplitude":0.5}"#);
    assert!(probe(&free, 80_000.0, 0.0, KNOBS).diverged);
    // A wall that renders (20 000 N/m, inside 2b/T = 26 400) never reaches
    // the limit: its verdict is the one without a limit, bit for bit.
    let inside = probe(&limited, 20_000.0, 0.0, KNOBS);
    assert_eq!(inside.saturated_renders, 0);
    assert_eq!(
        inside.confidence,
        probe(&free, 20_000.0, 0.0, KNOBS).confidence
    );
}

#[test]
fn clipped_realizations_decide_by_the_binomial_tails_at_one_half() {
    use bla::Clipping::*;
    // a = 0.05 / 22 looks (standard: 24 realizations) = 0.00227.
    let a = bla::look_alpha(0.05, 24);
    assert!((a - 0.05 / 22.0).abs() < 1e-15);
    assert_eq!(bla::clipping(0, 24, a), Unseen);
    // 9 of 9: 2^−9 = 0.00195 ≤ a; 8 of 8: 0.0039 > a.
    assert_eq!(bla::clipping(9, 9, a), Limit);
    assert_eq!(bla::clipping(8, 8, a), Open);
    // 11 of 12: (1 + 12)/4096 = 0.00317 > a; 12 of 13 … 13 of 14: (1 + 14)/16384 = 0.00092.
    assert_eq!(bla::clipping(11, 12, a), Open);
    assert_eq!(bla::clipping(13, 14, a), Limit);
    // 1 of 24: P(X ≤ 1) = 25/2^24 = 1.5e-6 ≤ a: rare, Re Z decides.
    assert_eq!(bla::clipping(1, 24, a), Rare);
    // 2 of 10: (1 + 10 + 45)/1024 = 0.055: open.
    assert_eq!(bla::clipping(2, 10, a), Open);
    // At 1000 realizations the tails stay finite: 500 of 1000 is open.
    assert_eq!(bla::clipping(500, 1000, a), Open);
    assert_eq!(bla::clipping(1000, 1000, a), Limit);
}

#[test]
fn clipping_counts_from_one_percent_of_the_renders() {
    // CLIP_SHARE = 1 %: of 4 000 renders, 40 clipped is the least that counts.
    assert!(bla::clipped(40, 4000.0));
    assert!(!bla::clipped(39, 4000.0));
    assert!(!bla::clipped(0, 0.0));
}

#[test]
fn a_realization_counts_the_renders_its_measured_periods_clipped() {
    // Renders per period: samples per period (sample_hz / f_min) over
    // samples per render. The seed device: 1 kHz, 1 Hz lines: 1 000 a
    // period, 4 000 in 4 periods. mode_lag_2011: sampled at 10 kHz, rendered
    // at 1 kHz: 1 000 a period as well. At 2 Hz: 500.
    let seed = scene_1khz("{}", r#"{"f_min_hz":1}"#);
    assert_eq!(ProbeSetup::new(&seed).renders(&seed, 4), 4000.0);
    let two = scene_1khz("{}", r#"{"f_min_hz":2}"#);
    assert_eq!(ProbeSetup::new(&two).renders(&two, 3), 1500.0);
    let ml = SceneSpec::from_json(
        &std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../examples/mode_lag_2011.json"
        ))
        .unwrap(),
    )
    .unwrap()
    .validate()
    .unwrap();
    assert_eq!(ProbeSetup::new(&ml).renders(&ml, 4), 4000.0);
    // The window opens with the first measured period (TRANSIENT_PERIODS
    // = 1): the count then was 100; 160 at the end: 60 clipped.
    let mut w = ClipWindow::default();
    for (i, count) in [(0, 30), (1, 100), (2, 150)] {
        w.at_period(i, count);
    }
    assert_eq!(w.clipped(160), 60);
}

#[test]
fn an_open_clipping_keeps_a_point_from_being_decided_passive() {
    use bla::Clipping::*;
    let v = |decided: bool, passive: bool| bla::BlaVerdict {
        decided,
        passive,
        z: Vec::new(),
        margin: if passive { 1.0 } else { -1.0 },
        margin_se: 0.5,
        noise_se: 0.1,
        realizations: 10,
        bands: 20,
    };
    // Open: decided passive becomes undecided, rendering only while fewer
    // than half of the 10 realizations clipped (4 yes, 5 and 6 no).
    for (clips, renders) in [(4, true), (5, false), (6, false)] {
        let w = with_clipping(v(true, true), Open, clips);
        assert_eq!((w.decided, w.passive), (false, renders), "{clips}");
    }
    // Re Z's "not passive" stands, decided or not.
    for decided in [true, false] {
        let w = with_clipping(v(decided, false), Open, 2);
        assert_eq!((w.decided, w.passive), (decided, false));
    }
    // Unseen and Rare: Re Z's verdict, unchanged.
    for c in [Unseen, Rare] {
        assert_eq!(with_clipping(v(true, true), c, 1), v(true, true));
    }
}

#[test]
fn clipping_decides_only_with_the_probe_at_most_half_the_limit() {
    // mode_lag_2011: 0.5 N against 4 N; the seed device with a 2 N limit.
    assert!(bla::clipping_decides(0.5, Some(4.0)));
    assert!(bla::clipping_decides(0.5, Some(1.0)));
    assert!(!bla::clipping_decides(0.5, Some(0.99)));
    assert!(!bla::clipping_decides(0.5, None));
    // A 0.5 N probe against a 0.5 N limit: a stable wall (20 000 N/m, B = 0,
    // inside 2b/T = 26 400) clips, but is not decided not passive by it.
    let tight = scene_1khz(r#"{"force_limit":0.5}"#, r#"{"amplitude":0.5}"#);
    let o = probe(&tight, 20_000.0, 0.0, KNOBS);
    assert!(o.saturated_renders > 0);
    let c = o.confidence.expect("a BLA verdict");
    assert!(o.passive, "{c:?}");
}
