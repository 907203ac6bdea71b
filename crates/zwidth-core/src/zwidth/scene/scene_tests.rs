//! Tests of the scene (`scene/mod.rs`): its spec, defaults, checks and
//! the built scene.

use super::*;

#[test]
fn quantization_up_to_a_centimetre_and_numbers_only_where_numbers_are() {
    let with_q = |q: f64| {
        let mut s = SceneSpec::default();
        s.device.quantization = q;
        s.validate().map(|_| ()).map_err(|e| e.field)
    };
    // The documented bound is "at most 0.01 m": 0.01 itself is allowed.
    assert_eq!(with_q(0.01), Ok(()));
    assert_eq!(with_q(0.010_000_1), Err("device.quantization".into()));
    // A number cannot replace a non-number (the estimator's kind).
    let e = SceneSpec::default()
        .with_number("estimator.kind", 1.0, "params")
        .unwrap_err();
    assert!(
        e.field == "params" && e.value.contains("estimator.kind"),
        "{e}"
    );
    assert!(
        e.allowed.starts_with("must name a number in the scene"),
        "{e}"
    );
}

#[test]
fn issue_example_parses_and_defaults_fill_in() {
    let json = r#"{
      "device":   {"mass": 0.52, "damping": 13.2, "coulomb": 0.19, "quantization": 1e-6, "force_limit": null},
      "loop":     {"sample_hz": 10000, "render_hz": 1000, "delay_samples": 0},
      "estimator": {"kind": "fdm"},
      "wall":     {"position": 0.0},
      "hit":      {"home_distance": 0.07, "push_force": 0.3572, "settle_s": 4, "measure_s": 2, "threshold": 1.06e-7},
      "probe":    {"f_min_hz": 1, "f_max_hz": 100, "amplitude": 0.5, "periods": 4}
    }"#;
    let s = SceneSpec::from_json(json).unwrap();
    assert_eq!(s, SceneSpec::default());
    assert_eq!(SceneSpec::from_json("{}").unwrap(), SceneSpec::default());
    let partial = SceneSpec::from_json(r#"{"device":{"coulomb":0}}"#).unwrap();
    assert_eq!(partial.device.mass, 0.52);
    let sc = s.validate().unwrap();
    assert_eq!(sc.ratio, 10);
    assert!(!sc.is_linear());
}

#[test]
fn errors_name_the_field() {
    let bad = |j: &str| match SceneSpec::from_json(j) {
        Err(e) => e.to_string(),
        Ok(s) => s
            .validate()
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default(),
    };
    assert!(bad(r#"{"device":{"mass":0}}"#).contains("device.mass = 0"));
    // Parse errors name the field too (serde's path).
    let e = bad(r#"{"probe":{"method":"welch"}}"#);
    assert!(e.starts_with("scene.probe.method = "), "{e}");
    assert!(
        e.contains("unknown variant `welch`, expected `bla` or `tfestimate`"),
        "{e}"
    );
    assert!(bad(r#"{"device":{"mass":"heavy"}}"#).starts_with("scene.device.mass = "));
    assert!(bad(r#"{"device":{"mass":1}} x"#).starts_with("scene = (document)"));
    // At most 1e9 samples a trial: 999 + 1 s at 1 MHz is exactly that.
    let fast = |settle: f64| {
        format!(
            r#"{{"loop":{{"sample_hz":1e6,"render_hz":1000}},"hit":{{"settle_s":{settle},"measure_s":1}}}}"#
        )
    };
    assert_eq!(bad(&fast(999.0)), "");
    let e = bad(&fast(999.5));
    assert!(
        e.contains("hit.measure_s = 1") && e.contains("1e9 samples"),
        "{e}"
    );
    assert!(bad(r#"{"device":{"damping":-1}}"#).contains("device.damping = -1"));
    assert!(
        bad(r#"{"loop":{"sample_hz":10000,"render_hz":3000}}"#).contains("loop.render_hz = 3000")
    );
    assert!(bad(r#"{"probe":{"f_max_hz":600}}"#).contains("probe.f_max_hz = 600"));
    assert!(bad(r#"{"probe":{"f_min_hz":3}}"#).contains("probe.f_min_hz = 3"));
    for c in ["0", "1", "-0.5", "1.5"] {
        let e = bad(&format!(r#"{{"probe":{{"confidence":{c}}}}}"#));
        assert!(
            e.contains(&format!("probe.confidence = {c}")) && e.contains("between 0 and 1"),
            "{e}"
        );
    }
    let e = bad(r#"{"device":{"force_limit":0.4},"probe":{"amplitude":0.5}}"#);
    assert!(
        e.contains("probe.amplitude = 0.5") && e.contains("force_limit = 0.4"),
        "{e}"
    );
    assert!(bad(r#"{"probe":{"amplitude":0}}"#).contains("probe.amplitude"));
    assert!(
        bad(r#"{"estimator":{"kind":"butterworth","cutoff_hz":6000}}"#)
            .contains("estimator.cutoff_hz = 6000")
    );
    assert!(bad(r#"{"devise":{}}"#).contains("devise"));
    assert!(bad(r#"{"hit":{"threshold":0}}"#).contains("hit.threshold = 0"));
    assert!(validate_wall(-1.0, 0.0).is_err() && validate_wall(1.0, f64::NAN).is_err());
}

/// The scene's field that fails, or "" when it is valid.
fn failing(json: &str) -> String {
    match SceneSpec::from_json(json).unwrap().validate() {
        Ok(_) => String::new(),
        Err(e) => e.field,
    }
}

#[test]
fn each_documented_limit_is_inclusive() {
    // Each limit's own value is allowed, the next value out is not (the
    // bounds the messages state).
    let one_khz = r#""loop":{"sample_hz":1000,"render_hz":1000"#;
    for (ok, bad, field) in [
        (r#"{"device":{"mass":1e4}}"#.to_string(), r#"{"device":{"mass":1.0001e4}}"#.to_string(), "device.mass"),
        (
            r#"{"device":{"force_limit":1,"force_resolution":1},"probe":{"amplitude":1}}"#.into(),
            r#"{"device":{"force_limit":1,"force_resolution":1.01},"probe":{"amplitude":1}}"#.into(),
            "device.force_resolution",
        ),
        (r#"{"loop":{"delay_samples":100}}"#.into(), r#"{"loop":{"delay_samples":101}}"#.into(), "loop.delay_samples"),
        (
            r#"{"device":{"force_limit":0.5},"probe":{"amplitude":0.5}}"#.into(),
            r#"{"device":{"force_limit":0.5},"probe":{"amplitude":0.51}}"#.into(),
            "probe.amplitude",
        ),
        (
            r#"{"hit":{"settle_s":3000,"measure_s":600}}"#.into(),
            r#"{"hit":{"settle_s":3000,"measure_s":601}}"#.into(),
            "hit.settle_s",
        ),
        // The probe's highest line below the render Nyquist (500 Hz here).
        (
            format!(r#"{{{one_khz}}},"probe":{{"f_max_hz":499}}}}"#),
            format!(r#"{{{one_khz}}},"probe":{{"f_max_hz":500}}}}"#),
            "probe.f_max_hz",
        ),
        // At most MAX_PROBE_LINES = 1000 lines, f_max / f_min.
        (
            r#"{"loop":{"sample_hz":10000,"render_hz":10000},"probe":{"f_min_hz":2,"f_max_hz":2000}}"#.into(),
            r#"{"loop":{"sample_hz":10000,"render_hz":10000},"probe":{"f_min_hz":2,"f_max_hz":2002}}"#.into(),
            "probe.f_max_hz",
        ),
        // One probe period at most MAX_PROBE_PERIOD_STEPS = 4e6 steps:
        // 2 MHz / 0.5 Hz with one substep (40·100/2e6 < 1) is exactly 4e6.
        (
            r#"{"loop":{"sample_hz":2e6,"render_hz":1000},"probe":{"f_min_hz":0.5,"f_max_hz":100}}"#.into(),
            r#"{"loop":{"sample_hz":2e6,"render_hz":1000},"probe":{"f_min_hz":0.25,"f_max_hz":100}}"#.into(),
            "probe.f_min_hz",
        ),
    ] {
        assert_eq!(failing(&ok), "", "{ok}");
        assert_eq!(failing(&bad), field, "{bad}");
    }
    // An amplifier bandwidth at most the encoder's Nyquist frequency.
    assert_eq!(failing(r#"{"device":{"amplifier_hz":5000}}"#), "");
    assert_eq!(
        failing(r#"{"device":{"amplifier_hz":5001}}"#),
        "device.amplifier_hz"
    );
    assert_eq!(
        failing(r#"{"device":{"amplifier_hz":500},"loop":{"sample_hz":1000,"render_hz":1000}}"#),
        ""
    );
    assert_eq!(
        failing(r#"{"device":{"amplifier_hz":501},"loop":{"sample_hz":1000,"render_hz":1000}}"#),
        "device.amplifier_hz"
    );
    // f_max must lie above f_min.
    assert_eq!(
        failing(r#"{"probe":{"f_min_hz":1,"f_max_hz":1}}"#),
        "probe.f_max_hz"
    );
    assert_eq!(failing(r#"{"probe":{"f_max_hz":1e308}}"#), "probe.f_max_hz");
    // The wall: K in [0, 1e9] N/m, |B| ≤ 1e7 N·s/m.
    assert!(validate_wall(0.0, 1e7).is_ok() && validate_wall(1e9, -1e7).is_ok());
    assert_eq!(validate_wall(0.0, 2e7).unwrap_err().field, "b");
    assert_eq!(validate_wall(0.0, -2e7).unwrap_err().field, "b");
    assert_eq!(validate_wall(2e9, 0.0).unwrap_err().field, "k");
}

#[test]
fn the_first_nonlinearity_is_named_and_the_grid_follows_the_loop() {
    let reason = |j: &str| {
        SceneSpec::from_json(j)
            .unwrap()
            .validate()
            .unwrap()
            .linear_reason()
    };
    let lin =
        r#""device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}"#;
    assert_eq!(reason(&format!("{{{lin}}}")), None);
    let one = |device: &str, estimator: &str| {
        reason(&format!(
            r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{estimator}}}"#
        ))
    };
    assert_eq!(
        one(r#"{"coulomb":0}"#, r#"{"kind":"fdm"}"#).as_deref(),
        Some("quantization")
    );
    assert_eq!(
        one(r#"{"quantization":0}"#, r#"{"kind":"fdm"}"#).as_deref(),
        Some("Coulomb friction")
    );
    let flat = r#"{"coulomb":0,"quantization":0}"#;
    assert_eq!(
        one(flat, r#"{"kind":"fdm","median_velocity":3}"#).as_deref(),
        Some("median smoothing")
    );
    assert_eq!(
        one(flat, r#"{"kind":"fdm","median_position":3}"#).as_deref(),
        Some("median smoothing")
    );
    assert_eq!(
        one(
            r#"{"coulomb":0,"quantization":0,"force_resolution":0.01}"#,
            r#"{"kind":"fdm"}"#
        )
        .as_deref(),
        Some("force command resolution")
    );
    assert_eq!(one(flat, r#"{"kind":"kalman","q":1e3}"#), None);
    // A lag or a transmission: analytic up to 20 kHz, not above.
    let fast = |hz: u32, device: &str| {
        reason(&format!(
            r#"{{"device":{device},"loop":{{"sample_hz":{hz},"render_hz":{hz}}}}}"#
        ))
    };
    let lag = r#"{"coulomb":0,"quantization":0,"amplifier_hz":1000}"#;
    let cable =
        r#"{"coulomb":0,"quantization":0,"transmission":{"motor_mass":0.1,"stiffness":1e5}}"#;
    assert_eq!(fast(20_000, lag), None);
    assert_eq!(fast(20_000, cable), None);
    assert!(fast(25_000, lag)
        .unwrap()
        .starts_with("an amplifier lag or a transmission at 25000 Hz"));
    assert!(fast(25_000, cable).is_some());
    assert_eq!(
        fast(25_000, flat),
        None,
        "the rigid device is exact at any rate"
    );
    // The default (seed) scene: 10 kHz sampling, 1 kHz rendering.
    let sc = SceneSpec::default().validate().unwrap();
    assert_eq!((sc.dt, sc.render_dt, sc.ratio), (1e-4, 1e-3, 10));
    assert_eq!(sc.sampling.quantization, 1e-6);
    let ideal = SceneSpec::from_json(&format!("{{{lin}}}"))
        .unwrap()
        .validate()
        .unwrap();
    assert_eq!(ideal.sampling.quantization, IDEAL_SENSOR_ESTIMATOR_STEP);
    // At least 40 probe substeps per period of the highest line.
    assert_eq!(probe_substeps(100.0, 1000.0), 4);
    assert_eq!(probe_substeps(30.0, 1000.0), 2);
    assert_eq!(probe_substeps(100.0, 1e4), 1);
    // The probe method: BLA unless named, and kept by a parameter edit.
    assert!(ProbeMethod::default().is_bla() && !ProbeMethod::Tfestimate.is_bla());
    let tf = SceneSpec::from_json(r#"{"probe":{"method":"tfestimate"}}"#)
        .unwrap()
        .with_number("device.damping", 5.0, "p")
        .unwrap();
    assert_eq!(tf.probe.method, ProbeMethod::Tfestimate);
    assert!(serde_json::to_value(SceneSpec::default()).unwrap()["probe"]
        .get("method")
        .is_none());
}

#[test]
fn one_hit_per_verdict_is_not_written_so_stored_scenes_read_as_before() {
    // A stored scene from before `hit.replicates` reads as one hit, and
    // one hit is not written back: the scene's JSON (and so every
    // stored spec and its hash) is unchanged unless a scene asks for more.
    let one = serde_json::to_value(HitSpec::default()).unwrap();
    assert!(one.get("replicates").is_none(), "{one}");
    let three = HitSpec {
        replicates: 3,
        ..HitSpec::default()
    };
    let v = serde_json::to_value(&three).unwrap();
    assert_eq!(v["replicates"], 3);
    assert_eq!(serde_json::from_value::<HitSpec>(v).unwrap(), three);
    let old: HitSpec = serde_json::from_str(r#"{"home_distance":0.07}"#).unwrap();
    assert_eq!(old.replicates, 1);
}
