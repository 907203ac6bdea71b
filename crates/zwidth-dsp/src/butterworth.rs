//! FDM cascaded with a digital Butterworth low-pass (2011 paper §2.1,
//! 2018 paper §II-A). The design is the analog Butterworth prototype, scaled
//! to the prewarped cutoff `ω_a = 2·fs·tan(π·fc/fs)` and mapped by the
//! bilinear transform `z = (2fs + s)/(2fs − s)`, then grouped into
//! second-order sections with the "nearest" pole–zero pairing, so the
//! coefficients equal `scipy.signal.butter(order, fc, fs=fs, output='sos')`
//! and the filtering equals `scipy.signal.sosfilt` (transposed direct form
//! II, zero initial state).

use crate::complex::Cx;
use crate::fdm::Fdm;
use crate::math;
use crate::math::flush;
use crate::Error;

/// Highest order accepted: beyond this the sections become so sharp that
/// their rounding, not the design, dominates.
pub const MAX_ORDER: u32 = 10;

/// Sections at most: ⌈MAX_ORDER/2⌉.
pub const MAX_SECTIONS: usize = (MAX_ORDER as usize).div_ceil(2);

/// One second-order section `[b0, b1, b2, a0=1, a1, a2]`, as scipy's rows.
pub type Sos = [f64; 6];

/// Roots of the design: up to MAX_ORDER, padded to even.
const ROOTS: usize = 2 * MAX_SECTIONS;

/// A short list of roots in a fixed array.
#[derive(Clone, Copy)]
struct Roots {
    r: [Cx; ROOTS],
    n: usize,
}

impl Roots {
    fn new() -> Self {
        Self {
            r: [Cx::ZERO; ROOTS],
            n: 0,
        }
    }

    fn push(&mut self, c: Cx) {
        self.r[self.n] = c;
        self.n += 1;
    }

    fn all(&self) -> &[Cx] {
        &self.r[..self.n]
    }

    fn remove(&mut self, i: usize) -> Cx {
        let c = self.r[i];
        self.r.copy_within(i + 1..self.n, i);
        self.n -= 1;
        c
    }
}

/// The sections of the low-pass (see module doc): `order` in
/// 1..=MAX_ORDER, `cutoff_hz` in (0, fs/2). Returns the sections and how
/// many of them are used.
pub fn design_lowpass(
    order: u32,
    cutoff_hz: f64,
    fs: f64,
) -> Result<([Sos; MAX_SECTIONS], usize), Error> {
    if order == 0 {
        return Err(Error::Parameter {
            name: "order",
            value: 0.0,
            allowed: "must be at least 1",
        });
    }
    if order > MAX_ORDER {
        return Err(Error::Capacity {
            name: "order",
            value: order as usize,
            cap: MAX_ORDER as usize,
        });
    }
    crate::error::positive("rate_hz", fs)?;
    let nyq = fs / 2.0;
    if !(cutoff_hz.is_finite() && cutoff_hz > 0.0 && cutoff_hz < nyq) {
        return Err(Error::Parameter {
            name: "cutoff_hz",
            value: cutoff_hz,
            allowed: "must be > 0 and below the Nyquist frequency (half the sample rate)",
        });
    }
    let n = order as usize;
    let fs2 = 2.0 * fs;
    let pi = core::f64::consts::PI;
    // Prewarped analog cutoff (rad/s).
    let warped = fs2 * math::tan(pi * cutoff_hz / fs);
    // Analog prototype poles −exp(jπm/(2N)), m = −N+1, −N+3, …, N−1, scaled
    // by ω_a; bilinear transform of each; all N zeros go to z = −1.
    let mut poles = Roots::new();
    let mut zeros = Roots::new();
    let mut denom = Cx::new(1.0, 0.0);
    for i in 0..n {
        let m = -(n as f64) + 1.0 + 2.0 * i as f64;
        let p = (-Cx::from_polar(1.0, pi * m / (2.0 * n as f64))).scale(warped);
        // As num-complex evaluates `fs2 ± p` (f64 − Complex: 0 − im).
        let minus = Cx::new(fs2 - p.re, 0.0 - p.im);
        poles.push(Cx::new(fs2 + p.re, p.im) / minus);
        denom = denom * minus;
        zeros.push(Cx::new(-1.0, 0.0));
    }
    let gain = math::powi(warped, order as i32) / denom.re;
    Ok(zpk_to_sos_nearest(zeros, poles, gain))
}

/// Keep one of each conjugate pair (imag > 0) and the real roots; tiny
/// imaginary parts from rounding are treated as real. Complex first (by
/// real part), then reals (by value), as scipy's `_cplxreal`.
fn cplx_real(roots: &Roots) -> Roots {
    let tol = 100.0 * f64::EPSILON;
    let mut out = Roots::new();
    for &r in roots.all() {
        if math::abs(r.im) <= tol * r.norm().max(1.0) {
            out.push(Cx::new(r.re, 0.0));
        } else if r.im > 0.0 {
            out.push(r);
        }
    }
    // Stable insertion sort: complex before real, then by real part.
    let before = |a: &Cx, b: &Cx| {
        (a.im == 0.0)
            .cmp(&(b.im == 0.0))
            .then(a.re.total_cmp(&b.re))
            .is_lt()
    };
    for i in 1..out.n {
        let mut j = i;
        while j > 0 && before(&out.r[j], &out.r[j - 1]) {
            out.r.swap(j, j - 1);
            j -= 1;
        }
    }
    out
}

fn is_real(c: Cx) -> bool {
    c.im == 0.0
}

/// Index of the root nearest `to`, restricted to real roots when `real_only`
/// (the first of equals).
fn nearest(roots: &Roots, to: Cx, real_only: bool) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, r) in roots.all().iter().enumerate() {
        if real_only && !is_real(*r) {
            continue;
        }
        let d = (*r - to).norm();
        if best.is_none_or(|(_, b)| d.total_cmp(&b).is_lt()) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// Index of the pole nearest the unit circle ("worst" first), optionally
/// among reals (the first of equals).
fn worst(poles: &Roots, real_only: bool) -> Option<usize> {
    let mut best: Option<(usize, f64)> = None;
    for (i, p) in poles.all().iter().enumerate() {
        if real_only && !is_real(*p) {
            continue;
        }
        let d = math::abs(1.0 - p.norm());
        if best.is_none_or(|(_, b)| d.total_cmp(&b).is_lt()) {
            best = Some((i, d));
        }
    }
    best.map(|(i, _)| i)
}

/// Monic quadratic coefficients `[1, c1, c2]` of `(x − r1)(x − r2)`.
fn quad(r1: Cx, r2: Cx) -> [f64; 3] {
    [1.0, -(r1 + r2).re, (r1 * r2).re]
}

/// scipy's `zpk2sos(..., pairing='nearest')` for digital filters with as
/// many zeros as poles: the poles nearest the unit circle go in the last
/// section, each paired with the zeros nearest to it; the gain goes in the
/// first.
fn zpk_to_sos_nearest(zeros: Roots, poles: Roots, gain: f64) -> ([Sos; MAX_SECTIONS], usize) {
    let (mut z, mut p) = (zeros, poles);
    let n_sections = p.n.div_ceil(2);
    if p.n % 2 == 1 {
        p.push(Cx::ZERO);
        z.push(Cx::ZERO);
    }
    let mut z = cplx_real(&z);
    let mut p = cplx_real(&p);
    let mut sos = [[0.0; 6]; MAX_SECTIONS];
    // A design always has a pole and a matching zero left for each section
    // (N zeros at −1 for N poles); `unwrap_or(0)` never decides anything.
    for si in (0..n_sections).rev() {
        let p1 = p.remove(worst(&p, false).unwrap_or(0));
        let (pz, pp): ((Cx, Cx), (Cx, Cx));
        if is_real(p1) && !p.all().iter().any(|&x| is_real(x)) {
            // The last real pole: one real zero, padded with roots at 0.
            let z1 = z.remove(nearest(&z, p1, true).unwrap_or(0));
            pz = (z1, Cx::ZERO);
            pp = (p1, Cx::ZERO);
        } else {
            let p2 = if is_real(p1) {
                p.remove(worst(&p, true).unwrap_or(0))
            } else {
                p1.conj()
            };
            pp = (p1, p2);
            let z1 = z.remove(nearest(&z, p1, false).unwrap_or(0));
            pz = if !is_real(z1) {
                (z1, z1.conj())
            } else {
                let z2 = z.remove(nearest(&z, p1, true).unwrap_or(0));
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
    (sos, n_sections)
}

/// Filter one sample through the cascade (transposed direct form II); the
/// states are flushed below [`crate::FLUSH`].
#[inline]
pub fn sos_step(sos: &[Sos], state: &mut [[f64; 2]], x: f64) -> f64 {
    let mut x = x;
    for (c, s) in sos.iter().zip(state.iter_mut()) {
        let y = c[0] * x + s[0];
        s[0] = flush(c[1] * x - c[4] * y + s[1]);
        s[1] = flush(c[2] * x - c[5] * y);
        x = y;
    }
    x
}

/// The estimator: FDM, then the sections in cascade.
#[derive(Debug, Clone, PartialEq)]
pub struct Butterworth {
    fdm: Fdm,
    sos: [Sos; MAX_SECTIONS],
    sections: usize,
    /// Transposed direct form II state, two per section.
    state: [[f64; 2]; MAX_SECTIONS],
}

impl Butterworth {
    pub fn new(cutoff_hz: f64, order: u32, rate_hz: f64) -> Result<Self, Error> {
        let (sos, sections) = design_lowpass(order, cutoff_hz, rate_hz)?;
        Ok(Self {
            fdm: Fdm::new(1.0 / rate_hz),
            sos,
            sections,
            state: [[0.0; 2]; MAX_SECTIONS],
        })
    }

    /// 1/T of its difference (1/s).
    pub fn inv_t(&self) -> f64 {
        self.fdm.inv_t()
    }

    pub fn sections(&self) -> &[Sos] {
        &self.sos[..self.sections]
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        let v = self.fdm.step(y);
        let n = self.sections;
        sos_step(&self.sos[..n], &mut self.state[..n], v)
    }

    pub fn reset(&mut self) {
        self.fdm.reset();
        self.state = [[0.0; 2]; MAX_SECTIONS];
    }

    /// The state, for the subnormal test.
    pub fn state(&self) -> &[[f64; 2]] {
        &self.state[..self.sections]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Order 0 is a bad parameter, 1 to MAX_ORDER are designed, beyond is
    /// past the capacity (one limit, one code: the C ABI's `ZW_CAPACITY`).
    #[test]
    fn orders_from_one_to_the_cap_and_the_two_refusals() {
        assert!(matches!(
            design_lowpass(0, 100.0, 1000.0),
            Err(Error::Parameter { name: "order", .. })
        ));
        for order in [1, MAX_ORDER] {
            let (_, used) = design_lowpass(order, 100.0, 1000.0).unwrap();
            assert_eq!(used, (order as usize).div_ceil(2), "{order}");
        }
        assert_eq!(
            design_lowpass(MAX_ORDER + 1, 100.0, 1000.0).err(),
            Some(Error::Capacity {
                name: "order",
                value: MAX_ORDER as usize + 1,
                cap: MAX_ORDER as usize
            })
        );
    }

    /// scipy's `_cplxreal` order: one of each conjugate pair (imag > 0),
    /// complex by real part, then the reals by value; an input that needs
    /// each root moved more than one place.
    #[test]
    fn roots_are_paired_and_ordered_as_scipy_orders_them() {
        let mut r = Roots::new();
        for c in [
            Cx::new(0.5, 0.0),
            Cx::new(-0.2, 1e-18), // real within rounding
            Cx::new(0.1, 0.2),
            Cx::new(0.1, -0.2),
            Cx::new(-0.3, 0.4),
            Cx::new(-0.3, -0.4),
        ] {
            r.push(c);
        }
        let got = cplx_real(&r);
        assert_eq!(
            got.all(),
            &[
                Cx::new(-0.3, 0.4),
                Cx::new(0.1, 0.2),
                Cx::new(-0.2, 0.0),
                Cx::new(0.5, 0.0)
            ]
        );
    }
}
