//! The `zwidth` binary as users call it: outputs, exit codes, error lines.

use std::io::Write;
use std::process::{Command, Stdio};

struct Out {
    code: i32,
    stdout: String,
    stderr: String,
}

fn zwidth(args: &[&str], stdin: &str) -> Out {
    let mut child = Command::new(env!("CARGO_BIN_EXE_zwidth"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn zwidth");
    // The program may exit before reading stdin (bad flags): ignore EPIPE.
    let _ = child.stdin.take().unwrap().write_all(stdin.as_bytes());
    let o = child.wait_with_output().unwrap();
    Out {
        code: o.status.code().unwrap_or(-1),
        stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        stderr: String::from_utf8_lossy(&o.stderr).into_owned(),
    }
}

#[test]
fn estimate_fdm_prints_backward_differences() {
    // T = 1 ms: 0, (0.002−0.001)/1e-3 = 1, (0.0015−0.002)/1e-3 = −0.5 m/s.
    let o = zwidth(
        &[
            "estimate",
            "--rate",
            "1000",
            "--estimator",
            r#"{"kind":"fdm"}"#,
        ],
        "0.001\n0.002\n\n0.0015\n",
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let v: Vec<f64> = o.stdout.lines().map(|l| l.parse().unwrap()).collect();
    assert_eq!(v.len(), 3);
    assert_eq!(v[0], 0.0);
    assert!(
        (v[1] - 1.0).abs() < 1e-12 && (v[2] + 0.5).abs() < 1e-12,
        "{v:?}"
    );
}

#[test]
fn estimate_every_kind_runs() {
    let input: String = (0..300)
        .map(|k| format!("{}\n", ((k as f64 * 0.01).sin() * 1e4).round() * 1e-6))
        .collect();
    for spec in [
        r#"{"kind":"butterworth","cutoff_hz":100}"#,
        r#"{"kind":"kalman","q":2.5e4}"#,
        r#"{"kind":"adaptive_kalman","q":2.5e4}"#,
        r#"{"kind":"foaw","fit":"best","max_window":16}"#,
        r#"{"kind":"levant","rule":"lfba","lipschitz":5}"#,
        r#"{"kind":"levant","alpha":13,"lambda":1.58,"discretization":"implicit","median_velocity":3}"#,
    ] {
        let o = zwidth(
            &[
                "estimate",
                "--rate",
                "1000",
                "--estimator",
                spec,
                "--quantization",
                "1e-6",
            ],
            &input,
        );
        assert_eq!(o.code, 0, "{spec}: {}", o.stderr);
        assert_eq!(o.stdout.lines().count(), 300);
        assert!(
            o.stdout
                .lines()
                .all(|l| l.parse::<f64>().unwrap().is_finite()),
            "{spec}"
        );
    }
}

/// Exit 0 and JSON on stdout, parsed.
fn json_ok(args: &[&str], stdin: &str) -> serde_json::Value {
    let o = zwidth(args, stdin);
    assert_eq!(o.code, 0, "{args:?}: {}", o.stderr);
    serde_json::from_str(&o.stdout).unwrap()
}

/// Exit 2, nothing on stdout, one stderr line containing `needle`.
fn rejects(args: &[&str], stdin: &str, needle: &str) {
    let o = zwidth(args, stdin);
    assert_eq!(
        o.code, 2,
        "{args:?}: stdout {} stderr {}",
        o.stdout, o.stderr
    );
    assert!(o.stdout.is_empty(), "{args:?} printed {}", o.stdout);
    assert!(
        o.stderr.contains(needle),
        "{args:?}: {:?} lacks {needle:?}",
        o.stderr
    );
    assert_eq!(
        o.stderr.trim_end().lines().count(),
        1,
        "{args:?}: {}",
        o.stderr
    );
}

#[test]
fn estimate_bad_inputs_exit_2_with_one_clear_line() {
    let est = |spec: &'static str| ["estimate", "--rate", "1000", "--estimator", spec];
    rejects(&est("{kind:fdm"), "0\n", "not a valid estimator spec");
    rejects(
        &est(r#"{"kind":"magic"}"#),
        "0\n",
        "unknown variant `magic`",
    );
    rejects(
        &est(r#"{"kind":"butterworth","cutoff_hz":500}"#),
        "0\n",
        "cutoff_hz = 500",
    );
    rejects(
        &est(r#"{"kind":"butterworth","cutoff_hz":900}"#),
        "0\n",
        "Nyquist",
    );
    rejects(&est(r#"{"kind":"kalman","q":0}"#), "0\n", "q = 0");
    rejects(
        &est(r#"{"kind":"adaptive_kalman","q":-5}"#),
        "0\n",
        "q = -5",
    );
    rejects(
        &est(r#"{"kind":"foaw","fit":"end","d":-1e-6}"#),
        "0\n",
        "d = -0.000001",
    );
    rejects(
        &est(r#"{"kind":"foaw","fit":"end","max_window":0}"#),
        "0\n",
        "max_window = 0",
    );
    rejects(
        &est(r#"{"kind":"fdm","median_position":0}"#),
        "0\n",
        "median_position = 0",
    );
    rejects(
        &est(r#"{"kind":"levant","rule":"hba"}"#),
        "0\n",
        "lipschitz",
    );
    rejects(
        &[
            "estimate",
            "--rate",
            "1000",
            "--estimator",
            r#"{"kind":"fdm"}"#,
            "--quantization",
            "0",
        ],
        "0\n",
        "quantization = 0",
    );
    rejects(
        &["estimate", "--rate=-1", "--estimator", r#"{"kind":"fdm"}"#],
        "0\n",
        "rate = -1",
    );
    rejects(&est(r#"{"kind":"fdm"}"#), "0.1\nNaN\n", "line 2");
    rejects(&est(r#"{"kind":"fdm"}"#), "0.1\ninf\n", "line 2");
    rejects(
        &est(r#"{"kind":"fdm"}"#),
        "0.1\n0.2\nabc\n",
        "line 3 = \"abc\"",
    );
    // Missing required flag: clap's usage error, also exit 2.
    let o = zwidth(&["estimate", "--rate", "1000"], "");
    assert_eq!(o.code, 2);
}

#[test]
fn accuracy_json_has_every_estimator_and_svg() {
    let tmp = Scratch::new("accuracy");
    let svg = tmp.path("accuracy.svg");
    let v = json_ok(
        &[
            "accuracy",
            "--rates",
            "1000,10000",
            "--json",
            "--svg",
            svg.to_str().unwrap(),
        ],
        "",
    );
    let rows = v["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 10);
    for r in rows {
        let e = r["rms_error"].as_array().unwrap();
        assert_eq!(e.len(), 2);
        assert!(e.iter().all(|x| x.as_f64().unwrap() > 0.0));
    }
    // FDM's error grows with the rate (2011 paper §2.2: noise amplification).
    let fdm = &rows[0]["rms_error"];
    assert!(fdm[1].as_f64().unwrap() > 5.0 * fdm[0].as_f64().unwrap());
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("<svg") && text.contains("levant"));
    let _ = std::fs::remove_file(svg);
    rejects(&["accuracy", "--rates", "0"], "", "rates = 0");
}

#[test]
fn lipschitz_and_gains_commands() {
    // y = 0.5·4·t² at 1 kHz: C = 4 m/s².
    let input: String = (0..200)
        .map(|k| format!("{}\n", 2.0 * (k as f64 * 1e-3).powi(2)))
        .collect();
    let v = json_ok(
        &[
            "lipschitz",
            "--rate",
            "1000",
            "--quantization",
            "1e-12",
            "--json",
        ],
        &input,
    );
    assert!((v["lipschitz"].as_f64().unwrap() - 4.0).abs() < 1e-6, "{v}");
    rejects(
        &["lipschitz", "--rate", "1000"],
        "1\n2\n",
        "need at least 5 samples",
    );

    let o = zwidth(
        &[
            "gains",
            "--estimator",
            r#"{"kind":"levant","rule":"hba_sc","lipschitz":12}"#,
        ],
        "",
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(
        o.stdout.contains("Levant 1998") && o.stdout.contains("NOT met"),
        "{}",
        o.stdout
    );
    rejects(&["gains", "--estimator", r#"{"kind":"fdm"}"#], "", "levant");
}

/// A test's own temporary directory, removed when the test ends (passed or
/// failed).
struct Scratch(std::path::PathBuf);

impl Scratch {
    fn new(tag: &str) -> Self {
        let d = std::env::temp_dir().join(format!("zwidth-cli-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        Scratch(d)
    }

    fn path(&self, name: &str) -> std::path::PathBuf {
        self.0.join(name)
    }

    /// A scene file with this JSON; its path.
    fn scene(&self, name: &str, json: &str) -> String {
        let p = self.path(&format!("{name}.json"));
        std::fs::write(&p, json).unwrap();
        p.to_str().unwrap().to_string()
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

#[test]
fn trial_impedance_map_commands() {
    let tmp = Scratch::new("maps");
    let lin = tmp.scene(
        "lin",
        r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
    );
    // A soft, damped wall is stable; its trace has a header and one row per sample.
    let csv = tmp.path("trace.csv");
    let v = json_ok(
        &[
            "trial",
            "--scene",
            &lin,
            "--k",
            "2000",
            "--b",
            "20",
            "--json",
            "--trace",
            csv.to_str().unwrap(),
        ],
        "",
    );
    assert_eq!(v["stable"], true);
    let trace = std::fs::read_to_string(&csv).unwrap();
    assert!(trace.starts_with("t_s,x_true_m,y_measured_m,v_est_m_per_s,v_true_m_per_s,force_n"));
    assert_eq!(
        trace.lines().count() as u64,
        v["samples"].as_u64().unwrap() + 1
    );
    // Impedance, analytic (linear scene): 100 lines, passive at a soft wall.
    let v = json_ok(
        &[
            "impedance",
            "--scene",
            &lin,
            "--k",
            "2000",
            "--b",
            "5",
            "--json",
        ],
        "",
    );
    assert_eq!(v["freq_hz"].as_array().unwrap().len(), 100);
    assert_eq!(v["passive"], true);
    assert!(v["model"].as_str().unwrap().starts_with("analytic"));
    // Strict-passivity map: b > KT/2 + |B| gives 2(13.2 − 5)/1e-3 = 16 400 N/m at B = 5.
    let svg = tmp.path("map.svg");
    let v = json_ok(
        &[
            "map",
            "--scene",
            &lin,
            "--criterion",
            "strict_passivity",
            "--b",
            "0,5",
            "--json",
            "--svg",
            svg.to_str().unwrap(),
        ],
        "",
    );
    let k5 = v["boundary"][1]["k_max"].as_f64().unwrap();
    assert!((k5 - 16_400.0).abs() < 1e-6, "{k5}");
    for key in [
        "model",
        "method",
        "criterion",
        "boundary",
        "k_width",
        "b_width",
        "max_fidelity_error",
        "points",
        "trials",
        "elapsed_s",
    ] {
        assert!(v.get(key).is_some(), "missing {key}");
    }
    let text = std::fs::read_to_string(&svg).unwrap();
    assert!(text.contains("wall stiffness K (N/m)") && text.contains("fidelity error"));
}

#[test]
fn zwidth_commands_reject_bad_input() {
    let tmp = Scratch::new("bad");
    let lin = tmp.scene(
        "lin2",
        r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
    );
    let seed = tmp.scene("seed", "{}");
    let bad = tmp.scene("bad", r#"{"device":{"mass":-1}}"#);
    rejects(
        &["trial", "--scene", &bad, "--k", "1", "--b", "1"],
        "",
        "device.mass = -1",
    );
    rejects(
        &[
            "trial",
            "--scene",
            "/nonexistent.json",
            "--k",
            "1",
            "--b",
            "1",
        ],
        "",
        "cannot be read",
    );
    rejects(
        &["trial", "--scene", &lin, "--k=-5", "--b", "1"],
        "",
        "k = -5",
    );
    rejects(
        &["map", "--scene", &lin, "--method", "magic"],
        "",
        "--method = \"magic\"",
    );
    rejects(
        &["map", "--scene", &seed, "--method", "analytic"],
        "",
        "analytic engine needs a linear single-rate scene",
    );
    rejects(
        &["map", "--scene", &seed, "--criterion", "strict_passivity"],
        "",
        "strict_passivity",
    );
    rejects(
        &[
            "map",
            "--scene",
            &lin,
            "--method",
            "time",
            "--criterion",
            "impedance",
        ],
        "",
        "answers stability only",
    );
    rejects(
        &["map", "--scene", &lin, "--k-rel-tol", "0"],
        "",
        "accuracy.k_rel_tol = 0",
    );
    rejects(
        &["map", "--scene", &lin, "--accuracy", "fast"],
        "",
        "--accuracy = \"fast\"",
    );
    let nyq = tmp.scene("nyq", r#"{"probe":{"f_max_hz":700}}"#);
    rejects(
        &["impedance", "--scene", &nyq, "--k", "1", "--b", "1"],
        "",
        "probe.f_max_hz = 700",
    );
}

#[test]
fn compare_default_path_pins_c_and_the_ranking() {
    // `zwidth compare` with no scene: the 2018 paper's simulated device at
    // 1 kHz, its four estimators with its parameters, Levant's gains from C
    // estimated on an FDM + Butterworth wall hit (the papers' procedure).
    // docs/zwidth.md (standard accuracy) records C = 1.098 m/s² from that
    // hit at K = 7 441.2 N/m, B = 29.76 N·s/m, and the K-width order
    // AKF > FDM+filter > FOAW ≫ Levant (6.0e5, 4.4e5, 4.1e5, 7.7e4 N/m).
    let r = json_ok(&["compare", "--accuracy", "draft", "--json"], "");
    let c = &r["lipschitz"];
    let lip = c["estimate"]["lipschitz"].as_f64().unwrap();
    assert!((lip / 1.098 - 1.0).abs() < 0.005, "C = {lip}");
    assert!((c["wall_k"].as_f64().unwrap() - 7441.2).abs() < 0.1, "{c}");
    assert!((c["wall_b"].as_f64().unwrap() - 29.76).abs() < 1e-9, "{c}");
    assert_eq!(c["estimator"]["kind"], "butterworth", "{c}");
    let rows = r["rows"].as_array().unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["FDM+filter", "FOAW", "AKF", "Levant"]);
    // Levant's gains are the paper's μ1 = 6.6, μ2 = 2.45 times that C.
    let lev = &rows[3]["estimator"];
    assert_eq!(
        (lev["mu1"].as_f64(), lev["mu2"].as_f64()),
        (Some(6.6), Some(2.45))
    );
    assert_eq!(lev["lipschitz"].as_f64(), Some(lip));
    let k: Vec<f64> = rows
        .iter()
        .map(|r| r["map"]["k_width"].as_f64().unwrap())
        .collect();
    let mut order: Vec<usize> = (0..4).collect();
    order.sort_by(|&a, &b| k[b].total_cmp(&k[a]));
    let ranked: Vec<&str> = order.iter().map(|&i| names[i]).collect();
    assert_eq!(ranked, ["AKF", "FDM+filter", "FOAW", "Levant"], "{k:?}");
    // Each within a factor 1.5 of the documented standard-accuracy value
    // (draft resolves K to 5 % with at most 10 realizations per point).
    for (got, want) in k.iter().zip([4.405e5, 4.078e5, 6.012e5, 7.664e4]) {
        assert!(got / want > 1.0 / 1.5 && got / want < 1.5, "{k:?}");
    }
}

/// A scene file `zwidth trial` accepts and runs (K = 1000 N/m, B = 0).
fn runs_a_trial(scene: &str) {
    let o = zwidth(&["trial", "--scene", scene, "--k", "1000", "--b", "0"], "");
    assert_eq!(o.code, 0, "{}", o.stderr);
}

#[test]
fn record_then_identify_round_trips_the_seed_device() {
    // Reference: examples/seed_2018.json's device (the 2018 paper §V: 0.52 kg,
    // 13.2 N·s/m, 0.19 N, 1 µm encoder) made the trace; identify must give
    // it back within 2 % (issue 12's target) and write it as a scene.
    let s = Scratch::new("identify");
    let seed = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/seed_2018.json");
    let trace = s.path("trace.csv");
    let (trace, out) = (trace.to_str().unwrap(), s.path("scene.json"));
    let o = zwidth(&["record", "--scene", seed, "--out", trace], "");
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(o.stdout.contains("20000 samples"), "{}", o.stdout);
    let id = json_ok(
        &[
            "identify",
            trace,
            "--json",
            "--out",
            out.to_str().unwrap(),
            "--scene",
            seed,
        ],
        "",
    );
    for (name, want) in [("mass", 0.52), ("damping", 13.2), ("coulomb", 0.19)] {
        let v = id[name]["value"].as_f64().unwrap();
        assert!((v / want - 1.0).abs() < 0.02, "{name}: {v} vs {want}");
        let (lo, hi) = (
            id[name]["lo"].as_f64().unwrap(),
            id[name]["hi"].as_f64().unwrap(),
        );
        assert!(
            lo <= want && want <= hi,
            "{name}: {want} outside [{lo}, {hi}]"
        );
    }
    let scene: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    assert_eq!(scene["device"]["mass"], id["mass"]["value"]);
    assert_eq!(scene["device"]["coulomb"], id["coulomb"]["value"]);
    // Everything else comes from the base scene.
    assert_eq!(scene["estimator"]["cutoff_hz"], 499.0);
    runs_a_trial(out.to_str().unwrap());
    // The text report names the parameters and units.
    let o = zwidth(&["identify", trace], "");
    assert!(
        o.stdout.contains("mass") && o.stdout.contains("N·s/m") && o.stdout.contains("95 %"),
        "{}",
        o.stdout
    );
}

#[test]
fn record_and_identify_reject_bad_input() {
    let s = Scratch::new("identify-bad");
    let seed = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/seed_2018.json");
    let t = s.path("t.csv");
    let t = t.to_str().unwrap();
    rejects(
        &["record", "--scene", seed, "--out", t, "--f-max", "900"],
        "",
        "--f-max = 900",
    );
    rejects(
        &["record", "--scene", seed, "--out", t, "--peak-force", "0"],
        "",
        "--peak-force = 0",
    );
    rejects(
        &["record", "--scene", seed, "--out", t, "--duration", "0.5"],
        "",
        "--duration = 0.5",
    );
    let limited = s.scene(
        "limited",
        r#"{"device":{"force_limit":0.5},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
    );
    rejects(
        &[
            "record",
            "--scene",
            &limited,
            "--out",
            t,
            "--peak-force",
            "1",
        ],
        "",
        "force_limit",
    );
    assert!(
        !std::path::Path::new(t).exists(),
        "nothing written on bad input"
    );
    rejects(&["identify", t], "", "cannot be read");
    let mut rows = String::from("t_s,force_n,position_m\n");
    for k in 0..1500 {
        rows += &format!(
            "{},{},0\n",
            k as f64 * 1e-3,
            if k == 700 {
                "inf".to_string()
            } else {
                "0.1".into()
            }
        );
    }
    std::fs::write(t, &rows).unwrap();
    rejects(
        &["identify", t],
        "",
        "trace line 702, column 2 (force_n) = inf",
    );
    std::fs::write(t, rows.replace("t_s,force_n,position_m", "time,force")).unwrap();
    rejects(&["identify", t], "", "trace line 1 (header)");
    rejects(
        &["identify", t, "--model", "three_mass"],
        "",
        "--model = \"three_mass\"",
    );
    rejects(
        &["identify", t, "--mode-trace", t],
        "",
        "read by --model two_mass only",
    );
    rejects(
        &[
            "record",
            "--scene",
            seed,
            "--out",
            t,
            "--band-min",
            "300",
            "--band-max",
            "100",
            "--band-force",
            "0.1",
        ],
        "",
        "--band-min = 300",
    );
    // A band needs all three of its flags (clap's usage error: exit 2,
    // the missing ones listed).
    let o = zwidth(
        &["record", "--scene", seed, "--out", t, "--band-min", "50"],
        "",
    );
    assert_eq!(o.code, 2, "{}", o.stderr);
    assert!(
        o.stderr.contains("--band-max") && o.stderr.contains("--band-force"),
        "{}",
        o.stderr
    );
}

#[test]
fn two_mass_identify_writes_the_transmission() {
    // examples/two_mass_motor_encoder.json: 0.4 kg handle, 0.12 kg motor
    // side, 2e5 N/m cable, encoder on the motor, LuGre friction on the
    // handle, 1 µm steps. A slow trace and a band trace (50–600 Hz around
    // the 234 Hz mode); identify gives the masses and k within 5 %
    // (issue 12's target with a mode) and writes a two-mass scene.
    let s = Scratch::new("identify-two-mass");
    let scene = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/examples/two_mass_motor_encoder.json"
    );
    let (slow, band, out) = (s.path("slow.csv"), s.path("band.csv"), s.path("id.json"));
    let (slow, band) = (slow.to_str().unwrap(), band.to_str().unwrap());
    let o = zwidth(
        &[
            "record",
            "--scene",
            scene,
            "--out",
            slow,
            "--duration",
            "10",
        ],
        "",
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    let o = zwidth(
        &[
            "record",
            "--scene",
            scene,
            "--out",
            band,
            "--duration",
            "10",
            "--peak-force",
            "1.5",
            "--band-min",
            "50",
            "--band-max",
            "600",
            "--band-force",
            "1.5",
        ],
        "",
    );
    assert_eq!(o.code, 0, "{}", o.stderr);
    assert!(o.stdout.contains("band 50–600 Hz"), "{}", o.stdout);
    let id = json_ok(
        &[
            "identify",
            slow,
            "--model",
            "two_mass",
            "--mode-trace",
            band,
            "--json",
            "--out",
            out.to_str().unwrap(),
        ],
        "",
    );
    let mode = &id["mode"];
    for (got, want) in [
        (&id["mass"], 0.52),
        (&mode["handle_mass"], 0.4),
        (&mode["motor_mass"], 0.12),
        (&mode["stiffness"], 2e5),
    ] {
        let v = got["value"].as_f64().unwrap();
        assert!((v / want - 1.0).abs() < 0.05, "{v} vs {want}");
    }
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap();
    let d = &written["device"];
    assert_eq!(d["mass"], mode["handle_mass"]["value"]);
    assert_eq!(d["transmission"]["motor_mass"], mode["motor_mass"]["value"]);
    assert_eq!(d["transmission"]["stiffness"], mode["stiffness"]["value"]);
    assert_eq!(d["transmission"]["encoder"], "motor");
    assert_eq!(d["damping"], mode["handle_damping"]["value"]);
    assert_eq!(
        d["transmission"]["motor_damping"],
        mode["motor_damping"]["value"]
    );
    assert_eq!(d["transmission"]["damping"], mode["cable_damping"]["value"]);
    assert_eq!(d["coulomb"], id["coulomb"]["value"]);
    // Friction on the handle: the side a successful mode fit implies.
    assert_eq!(d["friction"]["on"], "handle");
    // No amplifier in the example, none resolved, none written.
    assert!(
        mode.get("amplifier_hz").is_none() && d.get("amplifier_hz").is_none(),
        "{d}"
    );
    runs_a_trial(out.to_str().unwrap());
    // The text report names the mode.
    let o = zwidth(
        &[
            "identify",
            slow,
            "--model",
            "two_mass",
            "--mode-trace",
            band,
        ],
        "",
    );
    assert!(
        o.stdout.contains("resonance") && o.stdout.contains("k_cable"),
        "{}",
        o.stdout
    );
}

#[test]
fn compare_tuned_tunes_each_estimator_and_shows_its_parameters() {
    // The linear seed device (examples/linear_1khz.json: the 2018 paper's
    // m, b without friction or quantization), draft, 3 search maps each.
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/linear_1khz.json");
    let args = ["compare", scene, "--accuracy", "draft", "--json"];
    let fixed = json_ok(&args, "");
    let tuned = json_ok(
        &[&args[..], &["--tuned", "k_width", "--max-evaluations", "3"]].concat(),
        "",
    );
    assert_eq!(tuned["tuned_for"], "k_width");
    assert!(fixed.get("tuned_for").is_none());
    let rows = tuned["rows"].as_array().unwrap();
    let fixed_rows = fixed["rows"].as_array().unwrap();
    for (i, name) in ["FDM+filter", "FOAW", "AKF", "Levant"].iter().enumerate() {
        assert_eq!(rows[i]["name"], *name);
        let t = &rows[i]["tuning"];
        if *name == "FOAW" {
            // The paper's FOAW has no tunable parameter: its fixed row.
            assert!(t.is_null() && rows[i]["estimator"] == fixed_rows[i]["estimator"]);
            continue;
        }
        // At most 3 search maps plus 3 finalists; the row's estimator
        // carries the tuned values the tuning reports.
        let evals = t["evaluations"].as_u64().unwrap();
        assert!((1..=6).contains(&evals), "{name}: {t}");
        for (p, v) in t["params"].as_object().unwrap() {
            assert_eq!(
                rows[i]["estimator"][p.as_str()].as_f64(),
                v.as_f64(),
                "{name}.{p}"
            );
        }
        let shown = rows[i]["parameters"].as_str().unwrap();
        assert!(shown.ends_with("(tuned)"), "{shown}");
        // The row names the tuned value in the paper's terms.
        let symbol = ["ωc = ", "", "q = ", "μ1 = "][i];
        assert!(shown.contains(symbol), "{name}: {shown}");
    }
    // Each fixed value lies inside its tuned range, so no tune may end
    // below it (5 %: draft's K resolution). Levant with the paper's μ1 = 6.6,
    // μ2 = 2.45 renders 3.1e4 N/m here; tuned, 4.3e5 (measured when
    // written; docs/tuning.md found the same order on the seed device):
    // the fixed gains are far from this scene's best.
    let k = |r: &serde_json::Value| r["map"]["k_width"].as_f64().unwrap();
    for i in [0, 2, 3] {
        assert!(
            k(&rows[i]) >= 0.95 * k(&fixed_rows[i]),
            "row {i}: {} vs {}",
            k(&rows[i]),
            k(&fixed_rows[i])
        );
    }
    assert!(
        k(&rows[3]) > 5.0 * k(&fixed_rows[3]),
        "Levant: {} vs {}",
        k(&rows[3]),
        k(&fixed_rows[3])
    );
    // The text table says which parameters it used.
    let o = zwidth(&["compare", scene, "--accuracy", "draft"], "");
    assert!(
        o.stdout.contains("the 2018 paper's fixed values"),
        "{}",
        o.stdout
    );
}

#[test]
fn compare_tuned_rejects_bad_input() {
    let scene = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/linear_1khz.json");
    rejects(
        &["compare", scene, "--tuned", "fastest"],
        "",
        "--tuned = \"fastest\"",
    );
    rejects(
        &[
            "compare",
            scene,
            "--tuned",
            r#"{"pareto":["k_width","b_width"]}"#,
        ],
        "",
        "--tuned",
    );
    rejects(
        &[
            "compare",
            scene,
            "--tuned",
            "k_width",
            "--max-evaluations",
            "0",
        ],
        "",
        "--max-evaluations = 0",
    );
    rejects(
        &["compare", scene, "--criterion", "passivity"],
        "",
        "--criterion = \"passivity\"",
    );
    // Refinement rounds: 0 to 3 (compare::MAX_RESOLVE_ROUNDS).
    rejects(
        &["compare", scene, "--resolve-rounds", "4"],
        "",
        "--resolve-rounds = 4 is not allowed: must be 0 to 3",
    );
}

/// `bench tradeoff --search` takes the map's own searches: anything else
/// exits 2 naming the flag and the value before any map runs (serde's list
/// of the variants is the allowed set).
#[test]
fn bench_tradeoff_refuses_an_unknown_search() {
    rejects(
        &[
            "bench", "tradeoff", "--scene", "linear", "--search", "newton",
        ],
        "",
        "--search = \"newton\" is not allowed: unknown variant `newton`, expected one of",
    );
}

/// `bench scale` measures PostgreSQL with counts it can run: anything else
/// exits 2 naming the flag, the value and what is allowed, before it
/// connects to anything (the URL below is never reached).
#[test]
fn bench_scale_refuses_counts_out_of_range_and_a_sqlite_database() {
    let pg = "postgres://nobody@127.0.0.1:1/none";
    for (flag, value, allowed) in [
        ("--maps", "1", "--maps must be 2 to 1000 (got 1)"),
        ("--sweeps", "0", "--sweeps 1 to 100 (got 0)"),
        ("--claims", "9", "--claims 10 to 1000000 (got 9)"),
        ("--repeat", "11", "--repeat 1 to 10 (got 11)"),
    ] {
        rejects(&["bench", "scale", "--db", pg, flag, value], "", allowed);
    }
    rejects(
        &["bench", "scale", "--db", "runs.db"],
        "",
        "bench scale measures a PostgreSQL database",
    );
}

/// `bench ui` seeds a new database with counts it can hold: anything else
/// exits 2 naming the flag and what is allowed, and a database that holds
/// experiments is refused, untouched.
#[test]
fn bench_ui_refuses_counts_out_of_range_and_a_database_in_use() {
    for (flag, value, allowed) in [
        (
            "--experiments",
            "4",
            "--experiments must be 5 to 1000000 (got 4)",
        ),
        ("--trials", "0", "--trials 1 to 100000000 (got 0)"),
        ("--repeat", "0", "--repeat 1 to 100 (got 0)"),
        (
            "--big",
            "2000000",
            "--big 1 to 1000000 and at most --trials",
        ),
    ] {
        rejects(
            &["bench", "ui", "--db", "never.db", flag, value],
            "",
            allowed,
        );
    }
    rejects(
        &[
            "bench", "ui", "--db", "x.db", "--trials", "10", "--big", "11",
        ],
        "",
        "at most --trials (got 11)",
    );
    assert!(!std::path::Path::new("never.db").exists());
    // A database in use: seeded once (tiny), then refused.
    let dir = std::env::temp_dir().join(format!("zwidth-bench-ui-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let db = dir.join("b.db");
    let db = db.to_str().unwrap();
    let args = [
        "bench",
        "ui",
        "--db",
        db,
        "--experiments",
        "5",
        "--trials",
        "30",
        "--big",
        "10",
        "--repeat",
        "1",
        "--json",
    ];
    let o = zwidth(&args, "");
    assert_eq!(o.code, 0, "{}", o.stderr);
    let r: serde_json::Value = serde_json::from_str(&o.stdout).unwrap();
    assert_eq!(r["seeded"]["trials"], 30, "{r}");
    assert!(
        r["pages"]
            .as_array()
            .unwrap()
            .iter()
            .all(|p| p["status"] == 200 || p["status"] == 204),
        "{r}"
    );
    rejects(
        &args,
        "",
        "holds experiments: bench ui seeds a new, empty database",
    );
    let _ = std::fs::remove_dir_all(&dir);
}
