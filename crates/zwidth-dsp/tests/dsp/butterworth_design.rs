//! The Butterworth design against scipy and closed forms: the sections of
//! `butter(N, fc, fs=fs, output='sos')`, the order-2 bilinear transform
//! with prewarping written out, and unit DC gain at every order.
// Reference values are kept exactly as scipy printed them.
#![allow(clippy::excessive_precision)]

use zwidth_dsp::butterworth::{Sos, MAX_ORDER};
use zwidth_dsp::Error;

/// The design's sections.
fn design_lowpass(order: u32, cutoff_hz: f64, fs: f64) -> Result<Vec<Sos>, Error> {
    let (sos, n) = zwidth_dsp::butterworth::design_lowpass(order, cutoff_hz, fs)?;
    Ok(sos[..n].to_vec())
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * b.abs().max(1e-3)
}

fn assert_sos(got: &[Sos], want: &[Sos]) {
    assert_eq!(got.len(), want.len());
    for (g, w) in got.iter().zip(want) {
        for (x, y) in g.iter().zip(w) {
            assert!(close(*x, *y), "got {g:?}\nwant {w:?}");
        }
    }
}

// Reference rows printed by scipy 1.17.1:
//   scipy.signal.butter(N, fc, fs=fs, output='sos')
#[test]
fn matches_scipy_butter_sos() {
    assert_sos(
        &design_lowpass(2, 100.0, 10_000.0).unwrap(),
        &[[
            9.4469184384015075e-04,
            1.8893836876803015e-03,
            9.4469184384015075e-04,
            1.0,
            -1.9111970674260730e+00,
            9.1497583480143363e-01,
        ]],
    );
    assert_sos(
        &design_lowpass(3, 100.0, 1000.0).unwrap(),
        &[
            [
                0.01809893300751443,
                0.03619786601502886,
                0.01809893300751443,
                1.0,
                -0.5095254494944288,
                0.0,
            ],
            [1.0, 1.0, 0.0, 1.0, -1.2505164308487402, 0.5457233155094579],
        ],
    );
    assert_sos(
        &design_lowpass(4, 499.0, 10_000.0).unwrap(),
        &[
            [
                4.1356578315955415e-04,
                8.2713156631910830e-04,
                4.1356578315955415e-04,
                1.0,
                -1.4806119459353926e+00,
                5.5649007494548652e-01,
            ],
            [
                1.0,
                2.0,
                1.0,
                1.0,
                -1.7016592711978158e+00,
                7.8886559292555125e-01,
            ],
        ],
    );
    assert_sos(
        &design_lowpass(1, 30.0, 1000.0).unwrap(),
        &[[
            0.08636402701376217,
            0.08636402701376217,
            0.0,
            1.0,
            -0.8272719459724756,
            0.0,
        ]],
    );
}

// Independent closed form for N = 2 (bilinear with prewarping):
// K = tan(π fc/fs), n = 1/(1 + √2 K + K²),
// b = K² n [1, 2, 1], a = [1, 2(K² − 1) n, (1 − √2 K + K²) n].
#[test]
fn order_two_closed_form() {
    for (fc, fs) in [
        (30.0, 1000.0),
        (499.0, 10_000.0),
        (4_000.0, 10_000.0),
        (10.0, 1e6),
    ] {
        let k: f64 = (std::f64::consts::PI * fc / fs).tan();
        let s2 = std::f64::consts::SQRT_2;
        let n = 1.0 / (1.0 + s2 * k + k * k);
        let b0 = k * k * n;
        let want = [
            b0,
            2.0 * b0,
            b0,
            1.0,
            2.0 * (k * k - 1.0) * n,
            (1.0 - s2 * k + k * k) * n,
        ];
        let got = design_lowpass(2, fc, fs).unwrap();
        for (x, y) in got[0].iter().zip(want) {
            assert!(
                (x - y).abs() <= 1e-11 * y.abs().max(1e-6),
                "{fc}/{fs}: {got:?} vs {want:?}"
            );
        }
    }
}

// Unit DC gain: the product over sections of B(1)/A(1) is 1 for any order.
// At fc/fs = 5e-5 the poles sit within ~3e-4 of z = 1, so A(1) is tiny and
// the rounding of the coefficients shows at the 1e-9 level: allow 1e-7.
#[test]
fn unit_dc_gain() {
    for order in 1..=MAX_ORDER {
        for (fc, fs) in [
            (30.0, 1000.0),
            (100.0, 10_000.0),
            (2_000.0, 5_000.0),
            (50.0, 1e6),
        ] {
            let sos = design_lowpass(order, fc, fs).unwrap();
            let g: f64 = sos
                .iter()
                .map(|c| (c[0] + c[1] + c[2]) / (c[3] + c[4] + c[5]))
                .product();
            assert!((g - 1.0).abs() < 1e-7, "order {order} fc {fc} fs {fs}: {g}");
        }
    }
}
