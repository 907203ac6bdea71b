//! ns per sample of each estimator at the rig's caps (the C ABI's
//! `RigEstimator`, its worst case: benches/support/cases.rs), 10 000 samples at
//! 10 kHz per iteration, with a bare backward-difference loop in the same
//! run as the baseline.
//!
//! Run: `cargo bench -p zwidth-dsp --bench step -- --warm-up-time 1
//! --measurement-time 3` (figures in docs/benchmarks.md).

#[path = "support/cases.rs"]
mod cases;

use cases::{case, signal, CASES};
use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use zwidth_dsp::estimator::RigEstimator;

const RATE: f64 = 1e4;
const Q: f64 = 1e-6;

fn bench(c: &mut Criterion) {
    let mut g = c.benchmark_group("rig_step_ns_per_sample");
    g.throughput(Throughput::Elements(10_000));
    g.sample_size(30);
    for kind in CASES {
        let (spec, constant) = case(kind).unwrap();
        let ys = signal(constant, RATE, Q);
        if kind == "bare" {
            g.bench_function(kind, |b| {
                b.iter(|| {
                    let mut prev = ys[0];
                    let mut acc = 0.0;
                    for &y in &ys {
                        let y = black_box(y);
                        acc += (y - prev) * RATE;
                        prev = y;
                    }
                    black_box(acc)
                })
            });
            continue;
        }
        let mut e = RigEstimator::new(&spec, RATE, Q).unwrap();
        g.bench_function(kind, |b| {
            b.iter(|| {
                let mut acc = 0.0;
                for &y in &ys {
                    acc += e.step(black_box(y));
                }
                black_box(acc)
            })
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
