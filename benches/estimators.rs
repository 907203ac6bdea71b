//! ns per sample for every estimator, on the 2011 paper's eq. 11 signal
//! quantized to 1 µm at 10 kHz (the papers' loop rate), plus a bare
//! hand-written FDM loop as the in-run baseline.
//!
//! Run: `cargo bench --bench estimators` (figures in docs/benchmarks.md).

use criterion::{criterion_group, criterion_main, BatchSize, Criterion, Throughput};
use std::hint::black_box;
use zwidth::estimators::{EstimatorSpec, Sampling, VelocityEstimator};
use zwidth::signals::{sample, DampedSine};

const RATE: f64 = 1e4;
const Q: f64 = 1e-6;

fn bench(c: &mut Criterion) {
    let (pos, _) = sample(&DampedSine::chawda_2011(), RATE, 2.0, Q);
    let pos = &pos[10_000..]; // t in [1 s, 2 s): 10 000 samples
    let constant = vec![0.0123; pos.len()]; // FOAW worst case: the window always fills
    let mut g = c.benchmark_group("estimator_ns_per_sample");
    g.throughput(Throughput::Elements(pos.len() as u64));
    g.sample_size(30);

    g.bench_function("baseline_bare_fdm_loop", |b| {
        b.iter(|| {
            let inv_t = RATE;
            let mut prev = pos[0];
            let mut acc = 0.0;
            for &y in pos {
                acc += (y - prev) * inv_t;
                prev = y;
            }
            black_box(acc)
        })
    });

    let cases: &[(&str, &str, &[f64])] = &[
        ("fdm", r#"{"kind":"fdm"}"#, pos),
        (
            "butterworth_2",
            r#"{"kind":"butterworth","cutoff_hz":100,"order":2}"#,
            pos,
        ),
        ("kalman", r#"{"kind":"kalman","q":2.5e4}"#, pos),
        (
            "adaptive_kalman",
            r#"{"kind":"adaptive_kalman","q":2.5e4}"#,
            pos,
        ),
        (
            "levant_explicit",
            r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":1.68}"#,
            pos,
        ),
        (
            "levant_implicit",
            r#"{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":1.68,"discretization":"implicit"}"#,
            pos,
        ),
        (
            "foaw_end_32",
            r#"{"kind":"foaw","fit":"end","max_window":32}"#,
            pos,
        ),
        (
            "foaw_best_32",
            r#"{"kind":"foaw","fit":"best","max_window":32}"#,
            pos,
        ),
        (
            "foaw_best_r_32",
            r#"{"kind":"foaw","fit":"best_r","max_window":32}"#,
            pos,
        ),
        (
            "foaw_best_32_constant_input",
            r#"{"kind":"foaw","fit":"best","max_window":32}"#,
            &constant,
        ),
        (
            "fdm_median_velocity_5",
            r#"{"kind":"fdm","median_velocity":5}"#,
            pos,
        ),
    ];
    for (name, json, input) in cases {
        let est = EstimatorSpec::from_json(json)
            .unwrap()
            .build(Sampling::new(RATE, Q).unwrap())
            .unwrap();
        g.bench_function(*name, |b| {
            b.iter_batched_ref(
                || est.clone(),
                |e| {
                    let mut acc = 0.0;
                    for &y in input.iter() {
                        acc += e.update(y);
                    }
                    black_box(acc)
                },
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
