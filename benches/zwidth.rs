//! Z-width engine speed. Run: `cargo bench --bench zwidth` (figures in docs/benchmarks.md).
//!
//! - `sample/*`: one simulated encoder sample of a wall hit (exact ZOH plant
//!   step + FDM + wall force), through the engine and as a bare hand-written
//!   loop of the same arithmetic, in the same run (target: engine within 2×).
//! - `trace_seed_2011`: the 2011 boundary trace of the seed device at 10 kHz
//!   with one estimator (target: under 1 s).
//! - `probe/*`: the frequency engine's BLA verdict at one (K, B) of the seed
//!   device (1 kHz, Coulomb friction, quantization) and of the mode-and-lag
//!   scene (10 kHz, two masses, amplifier, LuGre), per simulated step of the
//!   excitation grid, beside `sample/bare_loop` (issue 34).

use criterion::{criterion_group, criterion_main, Criterion, Throughput};
use std::hint::black_box;
use zwidth::plant::Plant;
use zwidth::zwidth::hit::{wall_hit, HitKnobs, NoTrace};
use zwidth::zwidth::probe::{probe, substeps};
use zwidth::zwidth::scene::SceneSpec;
use zwidth::zwidth::search::map;
use zwidth::zwidth::settings::{Accuracy, Criterion as Crit, MapSpec, Method, Preset, SearchKind};

fn bench(c: &mut Criterion) {
    // Linear single-rate 10 kHz scene, FDM, K = 20 000 N/m, B = 30 N·s/m,
    // starting at the wall: 1 s = 10 000 samples.
    let sc = SceneSpec::from_json(r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":10000,"render_hz":10000},"hit":{"home_distance":0}}"#)
        .unwrap()
        .validate()
        .unwrap();
    let knobs = HitKnobs {
        settle_s: 0.5,
        measure_s: 0.5,
    };
    let n = 10_000u64;
    let mut g = c.benchmark_group("sample");
    g.throughput(Throughput::Elements(n));
    g.bench_function("engine_wall_hit", |b| {
        b.iter(|| {
            black_box(wall_hit(
                &sc,
                black_box(20_000.0),
                black_box(30.0),
                knobs,
                &mut NoTrace,
            ))
        })
    });
    let plant = Plant::new(0.52, 13.2, 0.0, 1e-4);
    let ([[_, axv], [_, avv]], [bxf, bvf]) = plant.zoh();
    g.bench_function("bare_loop", |b| {
        b.iter(|| {
            let (k, bb, push) = (black_box(20_000.0), black_box(30.0), black_box(0.3572));
            let (mut x, mut v, mut prev) = (0.0f64, 0.0f64, 0.0f64);
            let (mut mean, mut m2) = (0.0f64, 0.0f64);
            for i in 0..n {
                let vel = (x - prev) * 1e4;
                prev = x;
                let f = push + if x > 0.0 { -(k * x + bb * vel) } else { 0.0 };
                let d = x - mean;
                mean += d / (i + 1) as f64;
                m2 += d * (x - mean);
                let nx = x + v * axv + f * bxf;
                v = v * avv + f * bvf;
                x = nx;
            }
            black_box((mean, m2))
        })
    });
    g.finish();

    // One BLA verdict near each scene's boundary at standard accuracy (its
    // realizations, their transient and averaged periods), per grid step:
    // the steps are counted from the outcome's periods once, before timing.
    let mut g = c.benchmark_group("probe");
    g.sample_size(10);
    for (name, json, k, b) in [
        (
            "seed_2018_realization_step",
            include_str!("../examples/seed_2018.json"),
            40_000.0,
            0.0,
        ),
        (
            "mode_lag_2011_realization_step",
            include_str!("../examples/mode_lag_2011.json"),
            100_000.0,
            30.0,
        ),
    ] {
        let sc = SceneSpec::from_json(json).unwrap().validate().unwrap();
        let knobs = Accuracy::Preset(Preset::Standard)
            .resolve(&sc)
            .unwrap()
            .probe;
        let per_period = (sc.spec.control.sample_hz / sc.spec.probe.f_min_hz).round() as u64
            * substeps(&sc) as u64;
        let periods = u64::from(probe(&sc, k, b, knobs).periods_run);
        g.throughput(Throughput::Elements(periods * per_period));
        g.bench_function(name, |bch| {
            bch.iter(|| black_box(probe(&sc, black_box(k), black_box(b), knobs)))
        });
    }
    g.finish();

    let seed = SceneSpec::from_json(include_str!("../examples/seed_2011.json")).unwrap();
    let mut g = c.benchmark_group("trace");
    g.sample_size(10);
    g.bench_function("trace_seed_2011", |b| {
        b.iter(|| {
            map(&MapSpec {
                scene: seed.clone(),
                method: Method::Time,
                criterion: Crit::Stability,
                search: SearchKind::Trace,
                accuracy: Accuracy::default(),
                b: None,
                b_max: 1000.0,
                k_max: 1e7,
                prior: None,
            })
            .unwrap()
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
