//! Real polynomials (coefficients in ascending powers) and their complex
//! roots by the Aberth–Ehrlich iteration (Aberth 1973; Ehrlich 1967), used
//! for the closed-loop eigenvalues of the analytic engine.

use num_complex::Complex64 as C;

/// `p[i]` is the coefficient of `zⁱ`.
pub type Poly = Vec<f64>;

pub fn mul(a: &[f64], b: &[f64]) -> Poly {
    let mut out = vec![0.0; a.len() + b.len() - 1];
    for (i, x) in a.iter().enumerate() {
        for (j, y) in b.iter().enumerate() {
            out[i + j] += x * y;
        }
    }
    out
}

pub fn add(a: &[f64], b: &[f64]) -> Poly {
    let mut out = vec![0.0; a.len().max(b.len())];
    for (i, x) in a.iter().enumerate() {
        out[i] += x;
    }
    for (i, x) in b.iter().enumerate() {
        out[i] += x;
    }
    out
}

pub fn scale(a: &[f64], s: f64) -> Poly {
    a.iter().map(|x| x * s).collect()
}

/// Multiply by zⁿ.
pub fn shift(a: &[f64], n: usize) -> Poly {
    let mut out = vec![0.0; n];
    out.extend_from_slice(a);
    out
}

pub fn eval(p: &[f64], z: C) -> C {
    p.iter().rev().fold(C::new(0.0, 0.0), |acc, &c| acc * z + c)
}

fn eval_with_derivative(p: &[C], z: C) -> (C, C) {
    let mut v = C::new(0.0, 0.0);
    let mut d = C::new(0.0, 0.0);
    for &c in p.iter().rev() {
        d = d * z + v;
        v = v * z + c;
    }
    (v, d)
}

/// All roots of `p` (trailing zero leading coefficients are dropped).
pub fn roots(p: &[f64]) -> Vec<C> {
    let mut p: Vec<f64> = p.to_vec();
    while p.len() > 1 && *p.last().expect("non-empty") == 0.0 {
        p.pop();
    }
    let n = p.len() - 1;
    if n == 0 {
        return vec![];
    }
    let lead = p[n];
    let pc: Vec<C> = p.iter().map(|&c| C::new(c / lead, 0.0)).collect();
    // Initial guesses on a circle of the Cauchy-bound-like radius, rotated off the axes.
    let radius = pc[..n]
        .iter()
        .map(|c| c.norm().powf(1.0 / n as f64))
        .fold(0.0, f64::max)
        .max(1e-3)
        * 1.1;
    let mut z: Vec<C> = (0..n)
        .map(|k| {
            C::from_polar(
                radius,
                2.0 * std::f64::consts::PI * (k as f64 + 0.25) / n as f64 + 0.4,
            )
        })
        .collect();
    for _ in 0..500 {
        let mut moved = 0.0f64;
        for i in 0..n {
            let (v, d) = eval_with_derivative(&pc, z[i]);
            if v.norm() == 0.0 {
                continue;
            }
            let ratio = v / d;
            let s: C = (0..n)
                .filter(|&j| j != i)
                .map(|j| C::new(1.0, 0.0) / (z[i] - z[j]))
                .sum();
            let w = ratio / (C::new(1.0, 0.0) - ratio * s);
            if w.is_finite() {
                z[i] -= w;
                moved = moved.max(w.norm() / z[i].norm().max(1e-300));
            }
        }
        if moved < 1e-15 {
            break;
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn constants_have_no_roots() {
        // A constant (zero included, with trailing zero coefficients) has
        // no roots; the trimming stops at the constant term.
        assert!(roots(&[3.0]).is_empty());
        assert!(roots(&[0.0]).is_empty());
        assert!(roots(&[2.0, 0.0, 0.0]).is_empty());
        // 0 + z + 0·z²: the trailing zero is dropped, z = 0 is the root.
        let r = roots(&[0.0, 1.0, 0.0]);
        assert_eq!(r.len(), 1);
        assert!(r[0].norm() < 1e-12, "{r:?}");
    }

    #[test]
    fn roots_of_known_polynomials() {
        // (z − 0.5)(z + 2)(z² + 1) = z⁴ + 1.5z³ + 0z² + 1.5z − 1 with roots 0.5, −2, ±j.
        let p = mul(&mul(&[-0.5, 1.0], &[2.0, 1.0]), &[1.0, 0.0, 1.0]);
        let r = roots(&p);
        assert_eq!(r.len(), 4);
        for w in [
            C::new(-2.0, 0.0),
            C::new(0.0, -1.0),
            C::new(0.0, 1.0),
            C::new(0.5, 0.0),
        ] {
            assert!(r.iter().any(|g| (g - w).norm() < 1e-12), "{w} not in {r:?}");
        }
        // Roots of unity, degree 12, on |z| = 1.
        let mut p = vec![0.0; 13];
        p[0] = -1.0;
        p[12] = 1.0;
        assert!(roots(&p).iter().all(|z| (z.norm() - 1.0).abs() < 1e-12));
    }
}
