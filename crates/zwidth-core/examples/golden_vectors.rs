//! Writes zwidth-dsp's golden vectors: the velocity bits of every estimator
//! kind on a chirp, a step, a long rest, ±0, positions of ±10 m and the
//! 2011 paper's eq. 11 quantized at 1 µm (docs/dsp.md, "Golden vectors").
//!
//! cargo run --release -p zwidth-core --example golden_vectors -- crates/zwidth-dsp/golden/vectors.txt
//!
//! Re-baselining (a change of the estimators' bits) is one commit that says
//! so; `tests/golden.rs` checks the file bit for bit.

use std::fmt::Write as _;

use zwidth_core::estimators::{EstimatorSpec, Sampling, VelocityEstimator};
use zwidth_core::signals::{quantize, DampedSine};
use zwidth_dsp::fingerprint::Fingerprint;

/// The estimators: every kind and variant (JSON as the API takes it).
pub const SPECS: [(&str, &str); 15] = [
    ("fdm", r#"{"kind":"fdm"}"#),
    (
        "fdm_medians",
        r#"{"kind":"fdm","median_position":5,"median_velocity":4}"#,
    ),
    (
        "butterworth_2",
        r#"{"kind":"butterworth","cutoff_hz":100,"order":2}"#,
    ),
    (
        "butterworth_9",
        r#"{"kind":"butterworth","cutoff_hz":40,"order":9}"#,
    ),
    (
        "kalman",
        r#"{"kind":"kalman","q":10000,"q_model":"white_jerk"}"#,
    ),
    (
        "kalman_diagonal",
        r#"{"kind":"kalman","q":10000,"q_model":"diagonal"}"#,
    ),
    (
        "adaptive_kalman",
        r#"{"kind":"adaptive_kalman","q":25000,"rho":0.95}"#,
    ),
    ("foaw_end", r#"{"kind":"foaw","fit":"end","max_window":16}"#),
    (
        "foaw_best",
        r#"{"kind":"foaw","fit":"best","max_window":16}"#,
    ),
    (
        "foaw_best_r",
        r#"{"kind":"foaw","fit":"best_r","max_window":16}"#,
    ),
    (
        "foaw_end_tolerant",
        r#"{"kind":"foaw","fit":"end","max_window":16,"outlier_tolerance":true}"#,
    ),
    (
        "foaw_best_r_tolerant",
        r#"{"kind":"foaw","fit":"best_r","d":2e-6,"max_window":32,"outlier_tolerance":true}"#,
    ),
    ("levant", r#"{"kind":"levant","alpha":13.2,"lambda":3.46}"#),
    (
        "levant_implicit",
        r#"{"kind":"levant","alpha":13.2,"lambda":3.46,"discretization":"implicit"}"#,
    ),
    (
        "levant_implicit_eq7",
        r#"{"kind":"levant","rule":"lfba","lipschitz":40,"discretization":"implicit","implicit_output":"eq7"}"#,
    ),
];

/// A signal: its name, rate (Hz), encoder step (m), positions, and the
/// stride at which outputs are written (all are hashed).
struct Signal {
    name: &'static str,
    rate_hz: f64,
    quantization: f64,
    positions: Vec<f64>,
    stride: usize,
}

fn signals() -> Vec<Signal> {
    let pi = std::f64::consts::PI;
    // A 5 mm chirp from 1 Hz to 200 Hz over 0.1 s at 10 kHz, 1 µm steps.
    let chirp: Vec<f64> = (0..1000)
        .map(|k| {
            let t = k as f64 / 1e4;
            let phase = 2.0 * pi * (t + 0.5 * (199.0 / 0.1) * t * t);
            quantize(5e-3 * phase.sin(), 1e-6)
        })
        .collect();
    // At rest, a 1 mm step at sample 20, 300 samples.
    let step: Vec<f64> = (0..300).map(|k| if k < 20 { 0.0 } else { 1e-3 }).collect();
    // The step, then 6 s of rest at 10 kHz: every state decays (into the
    // subnormal range, but for the flush).
    let rest: Vec<f64> = (0..60_000)
        .map(|k| if k < 20 { 0.0 } else { 1e-3 })
        .collect();
    // +0 and −0 alternating, 64 samples.
    let zeros: Vec<f64> = (0..64)
        .map(|k| if k % 2 == 0 { 0.0 } else { -0.0 })
        .collect();
    // 400 samples of the chirp 10 m from the origin, then 400 at −10 m.
    let far: Vec<f64> = (0..800)
        .map(|k| {
            let c = chirp[k % 400];
            if k < 400 {
                10.0 + c
            } else {
                -10.0 + c
            }
        })
        .collect();
    // The 2011 paper's eq. 11 (A = 0.05 m, a = 1 1/s, f0 = 1 Hz) at 1 kHz
    // for 1 s, quantized at 1 µm.
    let s = DampedSine::chawda_2011();
    let eq11: Vec<f64> = (0..1000)
        .map(|k| quantize(s.position(k as f64 / 1e3), 1e-6))
        .collect();
    let sig = |name, rate_hz, positions, stride| Signal {
        name,
        rate_hz,
        quantization: 1e-6,
        positions,
        stride,
    };
    vec![
        sig("chirp", 1e4, chirp, 1),
        sig("step", 1e4, step, 1),
        sig("rest", 1e4, rest, 250),
        sig("zeros", 1e4, zeros, 1),
        sig("far", 1e4, far, 1),
        sig("eq11", 1e3, eq11, 1),
    ]
}

/// Positions as runs: `p <bits>` or `r <count> <bits>`.
fn write_positions(out: &mut String, ys: &[f64]) {
    let mut i = 0;
    while i < ys.len() {
        let bits = ys[i].to_bits();
        let mut j = i + 1;
        while j < ys.len() && ys[j].to_bits() == bits {
            j += 1;
        }
        if j - i > 2 {
            writeln!(out, "r {} {bits:016x}", j - i).unwrap();
        } else {
            for _ in i..j {
                writeln!(out, "p {bits:016x}").unwrap();
            }
        }
        i = j;
    }
}

fn main() {
    let path = std::env::args()
        .nth(1)
        .unwrap_or_else(|| "crates/zwidth-dsp/golden/vectors.txt".into());
    let mut out = String::new();
    // Beside it, the built coefficients' fingerprints of every case and
    // the identity's references (what a rig advertises at hello).
    let mut prints = String::new();
    writeln!(prints, "zwidth-dsp golden fingerprints 1").unwrap();
    writeln!(
        prints,
        "# written with vectors.txt by the golden_vectors example"
    )
    .unwrap();
    writeln!(
        prints,
        "# case SIGNAL ESTIMATOR FINGERPRINT | identity KIND FINGERPRINT"
    )
    .unwrap();
    let mut out_prints = Vec::new();
    writeln!(out, "zwidth-dsp golden vectors 1").unwrap();
    writeln!(out, "# cargo run --release -p zwidth-core --example golden_vectors -- crates/zwidth-dsp/golden/vectors.txt").unwrap();
    writeln!(out, "# signal NAME RATE_HZ QUANTIZATION_M N / p BITS | r COUNT BITS (positions, f64 bits in hex)").unwrap();
    writeln!(out, "# estimator NAME STRIDE FNV1A64 SPEC / v BITS (outputs 0, STRIDE, 2·STRIDE, …; FNV-1a over every output's 8 little-endian bytes)").unwrap();
    for s in signals() {
        writeln!(
            out,
            "signal {} {} {:e} {}",
            s.name,
            s.rate_hz,
            s.quantization,
            s.positions.len()
        )
        .unwrap();
        write_positions(&mut out, &s.positions);
        let sampling = Sampling::new(s.rate_hz, s.quantization).unwrap();
        for (name, json) in SPECS {
            let mut e = EstimatorSpec::from_json(json)
                .and_then(|spec| spec.build(sampling))
                .unwrap_or_else(|e| panic!("{name} on {}: {e}", s.name));
            let v: Vec<f64> = s.positions.iter().map(|&y| e.update(y)).collect();
            let hash = v
                .iter()
                .fold(Fingerprint::default(), |h, x| h.f64(*x))
                .finish();
            writeln!(out, "estimator {name} {} {hash:016x} {json}", s.stride).unwrap();
            let dsp = EstimatorSpec::from_json(json).unwrap().to_dsp().unwrap();
            let print =
                zwidth_dsp::estimator::fingerprint(&dsp, s.rate_hz, s.quantization).unwrap();
            out_prints.push(format!("case {} {name} {print:016x}", s.name));
            for x in v.iter().step_by(s.stride) {
                writeln!(out, "v {:016x}", x.to_bits()).unwrap();
            }
        }
    }
    std::fs::write(&path, out).unwrap_or_else(|e| panic!("{path}: {e}"));
    eprintln!("wrote {path}");
    for line in out_prints {
        writeln!(prints, "{line}").unwrap();
    }
    for kind in zwidth_dsp::identity::KINDS {
        let print = zwidth_dsp::identity::reference_fingerprint(kind).unwrap();
        writeln!(prints, "identity {kind} {print:016x}").unwrap();
    }
    let prints_path = std::path::Path::new(&path).with_file_name("fingerprints.txt");
    std::fs::write(&prints_path, prints).unwrap_or_else(|e| panic!("{prints_path:?}: {e}"));
    eprintln!("wrote {}", prints_path.display());
}
