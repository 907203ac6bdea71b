//! Use the estimator library directly: build estimators from their JSON
//! specs, run them over a quantized trace, and compare their RMS errors.
//!
//! Run: `cargo run --release --example estimate_trace`

use zwidth::estimators::{EstimatorSpec, Sampling, VelocityEstimator};
use zwidth::signals::{sample, DampedSine};

fn main() -> Result<(), zwidth::SpecError> {
    let sampling = Sampling::new(10_000.0, 1e-6)?; // 10 kHz, 1 µm encoder
    let signal = DampedSine::chawda_2011();
    let (positions, exact) = sample(&signal, sampling.rate_hz, 2.0, sampling.quantization);
    for json in [
        r#"{"kind":"fdm"}"#,
        r#"{"kind":"butterworth","cutoff_hz":100}"#,
        r#"{"kind":"foaw","fit":"best","max_window":32}"#,
        r#"{"kind":"levant","mu1":1.06,"mu2":0.65,"lipschitz":1.68,"discretization":"implicit"}"#,
    ] {
        let spec = EstimatorSpec::from_json(json)?;
        let mut est = spec.build(sampling)?;
        let (mut sum, mut n) = (0.0, 0);
        for (k, (&y, &v)) in positions.iter().zip(&exact).enumerate() {
            let e = est.update(y) - v;
            if k >= 10_000 {
                sum += e * e;
                n += 1;
            }
        }
        println!(
            "{:<50} RMS error {:.3} mm/s",
            spec.label(),
            1e3 * (sum / n as f64).sqrt()
        );
    }
    Ok(())
}
