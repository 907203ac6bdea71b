//! FDM cascaded with a digital Butterworth low-pass (2011 paper §2.1,
//! 2018 paper §II-A). The design is the analog Butterworth prototype, scaled
//! to the prewarped cutoff `ω_a = 2·fs·tan(π·fc/fs)` and mapped by the bilinear
//! transform `z = (2fs + s)/(2fs − s)`, then grouped into second-order sections
//! with the "nearest" pole–zero pairing, so the coefficients equal
//! `scipy.signal.butter(order, fc, fs=fs, output='sos')` and the filtering
//! equals `scipy.signal.sosfilt` (transposed direct form II, zero initial state).

use num_complex::Complex64 as C;

use super::{Fdm, Sampling, VelocityEstimator};
use crate::error::SpecError;

/// Highest order accepted: beyond this the sections become so sharp that
/// their rounding, not the design, dominates.
pub const MAX_ORDER: u32 = 10;

/// One second-order section `[b0, b1, b2, a0=1, a1, a2]`, as scipy's rows.
pub type Sos = [f64; 6];

/// Design the low-pass (see module doc). `cutoff_hz` in (0, fs/2), `order` in 1..=MAX_ORDER.
pub fn design_lowpass(order: u32, cutoff_hz: f64, fs: f64) -> Result<Vec<Sos>, SpecError> {
    if !(1..=MAX_ORDER).contains(&order) {
        return Err(SpecError::new(
            "order",
            order,
            format!("must be a whole number from 1 to {MAX_ORDER}"),
        ));
    }
    let nyq = fs / 2.0;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyq) {
        return Err(SpecError::new(
            "cutoff_hz",
            cutoff_hz,
            format!("must be > 0 and below the Nyquist frequency {nyq} Hz (half the sample rate {fs} Hz)"),
        ));
    }
    let n = order as usize;
    let fs2 = 2.0 * fs;
    // Prewarped analog cutoff (rad/s).
    let warped = fs2 * (std::f64::consts::PI * cutoff_hz / fs).tan();
    // Analog prototype poles −exp(jπm/(2N)), m = −N+1, −N+3, …, N−1, scaled by ω_a.
    let analog: Vec<C> = (0..n)
        .map(|i| {
            let m = -(n as f64) + 1.0 + 2.0 * i as f64;
            -C::from_polar(1.0, std::f64::consts::PI * m / (2.0 * n as f64)) * warped
        })
        .collect();
    // Bilinear transform of poles; all N zeros go to z = −1.
    let poles: Vec<C> = analog.iter().map(|&p| (fs2 + p) / (fs2 - p)).collect();
    let denom: C = analog.iter().map(|&p| fs2 - p).product();
    let gain = warped.powi(order as i32) / denom.re;
    let zeros = vec![C::new(-1.0, 0.0); n];
    Ok(zpk_to_sos_nearest(zeros, poles, gain))
}

/// Keep one of each conjugate pair (imag > 0) and the real roots; tiny
/// imaginary parts from rounding are treated as real.
fn cplx_real(roots: Vec<C>) -> Vec<C> {
    let tol = 100.0 * f64::EPSILON;
    let mut out: Vec<C> = roots
        .into_iter()
        .filter_map(|r| {
            if r.im.abs() <= tol * r.norm().max(1.0) {
                Some(C::new(r.re, 0.0))
            } else if r.im > 0.0 {
                Some(r)
            } else {
                None
            }
        })
        .collect();
    // Complex first (by real part), then reals (by value), as scipy's _cplxreal.
    out.sort_by(|a, b| {
        (a.im == 0.0)
            .cmp(&(b.im == 0.0))
            .then(a.re.total_cmp(&b.re))
    });
    out
}

fn is_real(c: C) -> bool {
    c.im == 0.0
}

/// Index of the root nearest `to`, restricted to real roots when `real_only`.
fn nearest(roots: &[C], to: C, real_only: bool) -> Option<usize> {
    roots
        .iter()
        .enumerate()
        .filter(|(_, r)| !real_only || is_real(**r))
        .min_by(|a, b| (*a.1 - to).norm().total_cmp(&(*b.1 - to).norm()))
        .map(|(i, _)| i)
}

/// Index of the pole nearest the unit circle ("worst" first), optionally among reals.
fn worst(poles: &[C], real_only: bool) -> usize {
    poles
        .iter()
        .enumerate()
        .filter(|(_, p)| !real_only || is_real(**p))
        .min_by(|a, b| {
            (1.0 - a.1.norm())
                .abs()
                .total_cmp(&(1.0 - b.1.norm()).abs())
        })
        .map(|(i, _)| i)
        .expect("a pole remains")
}

/// Monic quadratic coefficients `[1, c1, c2]` of `(x − r1)(x − r2)` with one
/// root, a conjugate pair or two reals; a missing root is a root at 0.
fn quad(r1: C, r2: C) -> [f64; 3] {
    [1.0, -(r1 + r2).re, (r1 * r2).re]
}

/// scipy's `zpk2sos(..., pairing='nearest')` for digital filters with as many
/// zeros as poles: the poles nearest the unit circle go in the last section,
/// each paired with the zeros nearest to it; the gain goes in the first.
fn zpk_to_sos_nearest(zeros: Vec<C>, poles: Vec<C>, gain: f64) -> Vec<Sos> {
    let (mut z, mut p) = (zeros, poles);
    let n_sections = p.len().div_ceil(2);
    if p.len() % 2 == 1 {
        p.push(C::new(0.0, 0.0));
        z.push(C::new(0.0, 0.0));
    }
    let mut z = cplx_real(z);
    let mut p = cplx_real(p);
    let zero = C::new(0.0, 0.0);
    let mut sos = vec![[0.0; 6]; n_sections];
    for si in (0..n_sections).rev() {
        let p1 = p.remove(worst(&p, false));
        let (pz, pp): ((C, C), (C, C));
        if is_real(p1) && !p.iter().any(|&x| is_real(x)) {
            // The last real pole: one real zero, padded with roots at 0.
            let z1 = z.remove(nearest(&z, p1, true).expect("a real zero remains"));
            pz = (z1, zero);
            pp = (p1, zero);
        } else {
            let p2 = if is_real(p1) {
                p.remove(worst(&p, true))
            } else {
                p1.conj()
            };
            pp = (p1, p2);
            let z1 = z.remove(nearest(&z, p1, false).expect("a zero remains"));
            pz = if !is_real(z1) {
                (z1, z1.conj())
            } else {
                let z2 = z.remove(nearest(&z, p1, true).expect("a real zero remains"));
                (z1, z2)
            };
        }
        let b = quad(pz.0, pz.1);
        let a = quad(pp.0, pp.1);
        sos[si] = [b[0], b[1], b[2], a[0], a[1], a[2]];
    }
    for c in &mut sos[0][..3] {
        *c *= gain;
    }
    sos
}

/// The estimator: FDM, then the sections in cascade.
#[derive(Debug, Clone)]
pub struct Butterworth {
    fdm: Fdm,
    sos: Vec<Sos>,
    /// Transposed direct form II state, two per section.
    state: Vec<[f64; 2]>,
}

impl Butterworth {
    pub fn new(cutoff_hz: f64, order: u32, s: Sampling) -> Result<Self, SpecError> {
        let sos = design_lowpass(order, cutoff_hz, s.rate_hz)?;
        let state = vec![[0.0; 2]; sos.len()];
        Ok(Self {
            fdm: Fdm::new(s.period()),
            sos,
            state,
        })
    }

    pub fn sections(&self) -> &[Sos] {
        &self.sos
    }
}

/// Filter one sample through the cascade (transposed direct form II).
#[inline]
pub fn sos_step(sos: &[Sos], state: &mut [[f64; 2]], x: f64) -> f64 {
    let mut x = x;
    for (c, s) in sos.iter().zip(state.iter_mut()) {
        let y = c[0] * x + s[0];
        s[0] = c[1] * x - c[4] * y + s[1];
        s[1] = c[2] * x - c[5] * y;
        x = y;
    }
    x
}

impl VelocityEstimator for Butterworth {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        let v = self.fdm.update(y);
        sos_step(&self.sos, &mut self.state, v)
    }

    fn reset(&mut self) {
        self.fdm.reset();
        self.state.iter_mut().for_each(|s| *s = [0.0; 2]);
    }
}

#[cfg(test)]
// Reference values are kept exactly as scipy printed them.
#[allow(clippy::excessive_precision)]
mod tests {
    use super::*;

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

    // scipy.signal.sosfilt(butter(2, 100, fs=1000, output='sos'), x) for
    // x = [0,1,3,2,5,4,4,6,7,9.5] (scipy 1.17.1).
    #[test]
    fn filtering_matches_scipy_sosfilt() {
        let sos = design_lowpass(2, 100.0, 1000.0).unwrap();
        let mut st = vec![[0.0; 2]; sos.len()];
        let x = [0.0, 1.0, 3.0, 2.0, 5.0, 4.0, 4.0, 6.0, 7.0, 9.5];
        let want = [
            0.0,
            0.0674552738890719,
            0.4143764322940575,
            1.0528760029643751,
            1.8418247761849027,
            2.74982529387859,
            3.529428141386221,
            4.113130204924982,
            4.795745350955962,
            5.773467289245923,
        ];
        for (xi, wi) in x.iter().zip(want) {
            let y = sos_step(&sos, &mut st, *xi);
            assert!((y - wi).abs() < 1e-12, "{y} vs {wi}");
        }
    }

    #[test]
    fn rejects_cutoff_at_nyquist_and_bad_order() {
        let e = design_lowpass(2, 500.0, 1000.0).unwrap_err();
        assert_eq!(e.field, "cutoff_hz");
        assert!(e.allowed.contains("Nyquist frequency 500 Hz"));
        assert_eq!(design_lowpass(0, 10.0, 1000.0).unwrap_err().field, "order");
        assert_eq!(design_lowpass(11, 10.0, 1000.0).unwrap_err().field, "order");
        assert_eq!(
            design_lowpass(2, f64::NAN, 1000.0).unwrap_err().field,
            "cutoff_hz"
        );
        // Zero is not a cutoff (a filter that passes nothing).
        assert_eq!(
            design_lowpass(2, 0.0, 1000.0).unwrap_err().field,
            "cutoff_hz"
        );
        // Just inside both ends is a filter.
        assert!(design_lowpass(2, 1e-3, 1000.0).is_ok());
        assert!(design_lowpass(2, 499.999, 1000.0).is_ok());
    }
}
