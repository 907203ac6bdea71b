//! One estimator at the rig's caps, stepped N times: what
//! `.ci/callgrind-dsp` runs under callgrind (at two N, so the difference
//! is the instructions of N₂ − N₁ steps alone, without the setup).
//!
//! usage: step_cost KIND N   (KIND from benches/support/cases.rs; prints the checksum)

#[path = "../benches/support/cases.rs"]
mod cases;

use cases::{case, signal, CASES};
use zwidth_dsp::estimator::RigEstimator;

fn main() {
    let args: Vec<String> = std::env::args().collect();
    let (Some(kind), Some(n)) = (
        args.get(1),
        args.get(2).and_then(|n| n.parse::<usize>().ok()),
    ) else {
        eprintln!("usage: step_cost KIND N (KIND: {})", CASES.join(", "));
        std::process::exit(2);
    };
    let Some((spec, constant)) = case(kind) else {
        eprintln!("kind = {kind} is not allowed: one of {}", CASES.join(", "));
        std::process::exit(2);
    };
    let (rate, q) = (1e4, 1e-6);
    // 10 000 samples whatever N, stepped through cyclically, so the
    // instructions of N₂ − N₁ steps hold nothing else.
    let signal = signal(constant, rate, q);
    let y = |k: usize| std::hint::black_box(signal[k % signal.len()]);
    let mut e = RigEstimator::new(&spec, rate, q).expect("a valid case");
    let mut acc = 0.0;
    if kind == "bare" {
        // The baseline: a backward difference written out, no estimator.
        let mut prev = y(0);
        for k in 0..n {
            let yk = y(k);
            acc += (yk - prev) * rate;
            prev = yk;
        }
    } else {
        for k in 0..n {
            acc += e.step(y(k));
        }
    }
    println!("{kind} {n} {acc:e}");
}
