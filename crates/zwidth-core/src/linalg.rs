//! Small dense matrices for linear device models: the matrix exponential
//! (exact zero-order-hold discretization) and a state-space system's
//! transfer function. Sizes here are at most a handful of states.

/// A square or rectangular matrix, row-major.
pub type Mat = Vec<Vec<f64>>;

pub fn identity(n: usize) -> Mat {
    (0..n)
        .map(|i| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect())
        .collect()
}

pub fn mul(a: &Mat, b: &Mat) -> Mat {
    let (n, m) = (a.len(), b.first().map_or(0, Vec::len));
    (0..n)
        .map(|i| {
            (0..m)
                .map(|j| (0..b.len()).map(|k| a[i][k] * b[k][j]).sum())
                .collect()
        })
        .collect()
}

/// X with `A·X = B` (A square, B with any number of columns) by Gaussian
/// elimination with partial pivoting; None when a pivot falls below
/// 1e-12 of A's largest entry (singular to working precision).
pub fn solve(a: &Mat, b: &Mat) -> Option<Mat> {
    let n = a.len();
    let m = b.first().map_or(0, Vec::len);
    let big = a.iter().flatten().fold(0.0f64, |x, v| x.max(v.abs()));
    let mut w: Mat = a
        .iter()
        .zip(b)
        .map(|(ra, rb)| ra.iter().chain(rb).copied().collect())
        .collect();
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| w[i][col].abs().total_cmp(&w[j][col].abs()))?;
        let pivot = w[piv][col].abs();
        if pivot.is_nan() || pivot <= 1e-12 * big {
            return None;
        }
        w.swap(col, piv);
        let pivot = w[col].clone();
        for (r, row) in w.iter_mut().enumerate() {
            if r != col {
                let f = row[col] / pivot[col];
                for (v, p) in row.iter_mut().zip(&pivot).skip(col) {
                    *v -= f * p;
                }
            }
        }
    }
    let x: Mat = w
        .iter()
        .enumerate()
        .map(|(i, row)| row[n..n + m].iter().map(|v| v / row[i]).collect())
        .collect();
    x.iter().flatten().all(|v| v.is_finite()).then_some(x)
}

/// `A·X = B` for a symmetric positive (semi)definite A whose diagonal spans
/// many decades (k ~ 1e5 N/m beside τ ~ 1e-4 s): solved as
/// `(D A D)(D⁻¹ X) = D B` with D = diag(1/√A_ii), so the pivot test sees
/// the problem's conditioning, not its units.
pub fn solve_scaled(a: &Mat, b: &Mat) -> Option<Mat> {
    let d: Vec<f64> = (0..a.len())
        .map(|i| 1.0 / a[i][i].abs().sqrt().max(1e-300))
        .collect();
    let scaled: Mat = (0..a.len())
        .map(|i| (0..a.len()).map(|j| d[i] * a[i][j] * d[j]).collect())
        .collect();
    let rhs: Mat = b
        .iter()
        .zip(&d)
        .map(|(row, di)| row.iter().map(|v| v * di).collect())
        .collect();
    let y = solve(&scaled, &rhs)?;
    Some(
        y.iter()
            .zip(&d)
            .map(|(row, di)| row.iter().map(|v| v * di).collect())
            .collect(),
    )
}

/// `A·x`.
pub fn apply(a: &Mat, x: &[f64]) -> Vec<f64> {
    a.iter()
        .map(|row| row.iter().zip(x).map(|(a, x)| a * x).sum())
        .collect()
}

/// Balance `a` in place by a diagonal similarity `D⁻¹·a·D` with powers of
/// two (exact in floating point), evening out each state's row and column
/// norms (Parlett & Reinsch 1969, as LAPACK's gebal); returns D. A stiff
/// cable on a light motor side puts ~1e13 in the velocity rows against
/// ~1e-3 in the position rows: unbalanced, the exponential below needs ~46
/// squarings and loses up to 2 % (a spurious growing mode); balanced,
/// ~20 and 1e-9.
fn balance(a: &mut Mat) -> Vec<f64> {
    let n = a.len();
    let mut d = vec![1.0; n];
    for _ in 0..100 {
        let mut done = true;
        for i in 0..n {
            let c: f64 = (0..n).filter(|&j| j != i).map(|j| a[j][i].abs()).sum();
            let r: f64 = (0..n).filter(|&j| j != i).map(|j| a[i][j].abs()).sum();
            if c == 0.0 || r == 0.0 {
                continue;
            }
            let (mut f, mut cc, mut rr) = (1.0, c, r);
            while cc < rr / 2.0 {
                (f, cc, rr) = (f * 2.0, cc * 2.0, rr / 2.0);
            }
            while cc > rr * 2.0 {
                (f, cc, rr) = (f / 2.0, cc / 2.0, rr * 2.0);
            }
            if cc + rr < 0.95 * (c + r) {
                done = false;
                d[i] *= f;
                for row in a.iter_mut() {
                    row[i] *= f;
                }
                for x in a[i].iter_mut() {
                    *x /= f;
                }
            }
        }
        if done {
            break;
        }
    }
    d
}

/// e^A = D·e^{D⁻¹AD}·D⁻¹ ([`balance`]), the balanced exponential by scaling
/// and squaring (Moler & Van Loan 2003, "Nineteen dubious ways…", method
/// 3): A/2^s with ‖A/2^s‖∞ ≤ 1/2, its Taylor series to 18 terms (remainder
/// below 1/2^18/18! ≈ 6e-22 relative), squared s times.
pub fn expm(a: &Mat) -> Mat {
    let mut b = a.clone();
    let d = balance(&mut b);
    let e = expm_balanced(&b);
    e.iter()
        .enumerate()
        .map(|(i, row)| {
            row.iter()
                .enumerate()
                .map(|(j, x)| x * d[i] / d[j])
                .collect()
        })
        .collect()
}

fn expm_balanced(a: &Mat) -> Mat {
    let n = a.len();
    let norm = a
        .iter()
        .map(|r| r.iter().map(|x| x.abs()).sum::<f64>())
        .fold(0.0, f64::max);
    let s = if norm > 0.5 {
        (norm / 0.5).log2().ceil() as i32
    } else {
        0
    };
    let scale = 0.5f64.powi(s);
    let a: Mat = a
        .iter()
        .map(|r| r.iter().map(|x| x * scale).collect())
        .collect();
    let mut sum = identity(n);
    let mut term = identity(n);
    for k in 1..=18 {
        term = mul(&term, &a);
        for row in term.iter_mut() {
            for x in row.iter_mut() {
                *x /= k as f64;
            }
        }
        for (srow, trow) in sum.iter_mut().zip(&term) {
            for (s, t) in srow.iter_mut().zip(trow) {
                *s += t;
            }
        }
    }
    for _ in 0..s {
        sum = mul(&sum, &sum);
    }
    sum
}

/// The exact zero-order-hold discretization of `ẋ = A x + B u` over `t`:
/// `x_{k+1} = Φ x_k + Γ u_k` with `Φ = e^{At}`, `Γ = ∫₀ᵗ e^{As} ds B`, both
/// read off one exponential of the block matrix `[[A, B], [0, 0]]·t`
/// (Van Loan 1978, "Computing integrals involving the matrix exponential").
pub fn zoh(a: &Mat, b: &Mat, t: f64) -> (Mat, Mat) {
    let (n, m) = (a.len(), b.first().map_or(0, Vec::len));
    let mut big = vec![vec![0.0; n + m]; n + m];
    for i in 0..n {
        for j in 0..n {
            big[i][j] = a[i][j] * t;
        }
        for j in 0..m {
            big[i][n + j] = b[i][j] * t;
        }
    }
    let e = expm(&big);
    let phi = (0..n).map(|i| e[i][..n].to_vec()).collect();
    let gamma = (0..n).map(|i| e[i][n..].to_vec()).collect();
    (phi, gamma)
}

/// The transfer function `c·(zI − F)⁻¹·g = c·adj(zI − F)·g / det(zI − F)`
/// as (numerator, denominator) in ascending powers of z, by the
/// Faddeev–LeVerrier algorithm: `M₁ = I`, `c_{n−k} = −tr(F M_k)/k`,
/// `M_{k+1} = F M_k + c_{n−k} I`, `adj(zI − F) = Σ_k z^{n−k} M_k`.
pub fn transfer_function(f: &Mat, g: &[f64], c: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let n = f.len();
    let mut m = identity(n);
    let mut den = vec![0.0; n + 1];
    den[n] = 1.0;
    let mut num = vec![0.0; n];
    for k in 1..=n {
        num[n - k] = c.iter().zip(apply(&m, g)).map(|(c, x)| c * x).sum();
        let fm = mul(f, &m);
        let ck = -(0..n).map(|i| fm[i][i]).sum::<f64>() / k as f64;
        den[n - k] = ck;
        m = fm;
        for (i, row) in m.iter_mut().enumerate() {
            row[i] += ck;
        }
    }
    (num, den)
}

/// The frequency response `c·(jωI − A)⁻¹·b` of a continuous system at ω
/// (rad/s), by Gaussian elimination with partial pivoting.
pub fn frequency_response(a: &Mat, b: &[f64], c: &[f64], w: f64) -> num_complex::Complex64 {
    use num_complex::Complex64 as C;
    let n = a.len();
    // [jωI − A | b]
    let mut m: Vec<Vec<C>> = (0..n)
        .map(|i| {
            let mut row: Vec<C> = (0..n)
                .map(|j| C::new(-a[i][j], if i == j { w } else { 0.0 }))
                .collect();
            row.push(C::new(b[i], 0.0));
            row
        })
        .collect();
    for col in 0..n {
        let p = (col..n)
            .max_by(|&x, &y| m[x][col].norm().total_cmp(&m[y][col].norm()))
            .unwrap_or(col);
        m.swap(col, p);
        let (top, rest) = m.split_at_mut(col + 1);
        let pivot_row = &top[col];
        for row in rest.iter_mut() {
            let f = row[col] / pivot_row[col];
            for (x, p) in row.iter_mut().zip(pivot_row).skip(col) {
                *x -= f * p;
            }
        }
    }
    let mut x = vec![C::new(0.0, 0.0); n];
    for i in (0..n).rev() {
        let s: C = (i + 1..n).map(|k| m[i][k] * x[k]).sum();
        x[i] = (m[i][n] - s) / m[i][i];
    }
    c.iter().zip(&x).map(|(c, x)| c * x).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solve_inverts_and_refuses_singular() {
        // A = [[0, 2, 1], [1, 1, 0], [3, 0, 1]] (a zero first pivot: needs a
        // row swap), det = 0·1 − 2·(1 − 0) + 1·(0 − 3) = −5; A·x = (5, 3, 4)
        // for x = (1, 2, 1) by hand.
        let a = vec![
            vec![0.0, 2.0, 1.0],
            vec![1.0, 1.0, 0.0],
            vec![3.0, 0.0, 1.0],
        ];
        let x = solve(&a, &vec![vec![5.0], vec![3.0], vec![4.0]]).unwrap();
        for (xi, want) in x.iter().zip([1.0, 2.0, 1.0]) {
            assert!((xi[0] - want).abs() < 1e-14, "{x:?}");
        }
        // A·A⁻¹ = I.
        let inv = solve(&a, &identity(3)).unwrap();
        let eye = mul(&a, &inv);
        for (i, row) in eye.iter().enumerate() {
            for (j, v) in row.iter().enumerate() {
                assert!((v - if i == j { 1.0 } else { 0.0 }).abs() < 1e-14);
            }
        }
        // Rank 2 (row 3 = row 1 + row 2): no solution.
        let singular = vec![
            vec![1.0, 2.0, 3.0],
            vec![0.0, 1.0, 1.0],
            vec![1.0, 3.0, 4.0],
        ];
        assert!(solve(&singular, &identity(3)).is_none());
        // Singular but for rounding: [[0.1, 0.3], [0.3, 0.9]] (row 1 = row
        // 2 / 3) leaves a second pivot of −5.6e-17 (0.3 − (0.1/0.3)·0.9 in
        // f64), below 1e-12 of the largest entry: refused, not a solution
        // of size 1e16.
        let nearly = vec![vec![0.1, 0.3], vec![0.3, 0.9]];
        assert!(solve(&nearly, &identity(2)).is_none());
        // The test is relative to the largest entry: diag(1e6, 1e-9) has a
        // pivot 1e-15 of it (condition 1e15): refused; diag(1e6, 1e-5) is
        // solved (1e-6, 1e5).
        let ill = vec![vec![1e6, 0.0], vec![0.0, 1e-9]];
        assert!(solve(&ill, &identity(2)).is_none());
        let fine = solve(&vec![vec![1e6, 0.0], vec![0.0, 1e-5]], &identity(2)).unwrap();
        assert!((fine[0][0] - 1e-6).abs() < 1e-20 && (fine[1][1] - 1e5).abs() < 1e-9);
    }

    #[test]
    fn exponential_of_a_rotation_and_of_a_jordan_block() {
        // e^{[[0, −w], [w, 0]]} is the rotation by w (cos, sin);
        // e^{[[a, 1], [0, a]]} = e^a·[[1, 1], [0, 1]].
        let w = 2.5;
        let r = expm(&vec![vec![0.0, -w], vec![w, 0.0]]);
        let want = [[w.cos(), -w.sin()], [w.sin(), w.cos()]];
        for i in 0..2 {
            for j in 0..2 {
                assert!((r[i][j] - want[i][j]).abs() < 1e-14, "{r:?}");
            }
        }
        let a = -3.0f64;
        let e = expm(&vec![vec![a, 1.0], vec![0.0, a]]);
        let ea = a.exp();
        assert!((e[0][0] - ea).abs() < 1e-15 && (e[0][1] - ea).abs() < 1e-15);
        assert!(e[1][0].abs() < 1e-18 && (e[1][1] - ea).abs() < 1e-15);
        // A large norm is scaled down and squared back: e^{−40}.
        let big = expm(&vec![vec![-40.0]]);
        assert!((big[0][0] / (-40f64).exp() - 1.0).abs() < 1e-12, "{big:?}");
    }

    #[test]
    fn zoh_of_a_mass_damper_is_the_plant_s_closed_form() {
        // ẋ = v, m v̇ = −b v + F: the plant's closed-form step (plant.rs,
        // DESIGN.md "Plant between force updates").
        let (m, b, t) = (0.52, 13.2, 1e-3);
        let (phi, gamma) = zoh(
            &vec![vec![0.0, 1.0], vec![0.0, -b / m]],
            &vec![vec![0.0], vec![1.0 / m]],
            t,
        );
        let p = crate::plant::Plant::new(m, b, 0.0, t);
        let (a, g) = p.zoh();
        for i in 0..2 {
            for j in 0..2 {
                assert!((phi[i][j] - a[i][j]).abs() <= 1e-15 * a[i][j].abs().max(1e-3));
            }
            assert!(
                (gamma[i][0] - g[i]).abs() <= 1e-13 * g[i].abs(),
                "{gamma:?} vs {g:?}"
            );
        }
    }

    #[test]
    fn transfer_function_by_hand() {
        // F = [[1, 0.1], [0, 0.5]], g = [0, 1], c = [1, 0]:
        // det(zI − F) = (z − 1)(z − 0.5) = z² − 1.5z + 0.5;
        // adj(zI − F) = [[z − 0.5, 0.1], [0, z − 1]]: c·adj·g = 0.1.
        let f = vec![vec![1.0, 0.1], vec![0.0, 0.5]];
        let (num, den) = transfer_function(&f, &[0.0, 1.0], &[1.0, 0.0]);
        assert_eq!(den, [0.5, -1.5, 1.0]);
        assert!((num[0] - 0.1).abs() < 1e-15 && num[1] == 0.0, "{num:?}");
        // g = [1, 0]: c·adj·g = z − 0.5.
        let (num, _) = transfer_function(&f, &[1.0, 0.0], &[1.0, 0.0]);
        assert_eq!(num, [-0.5, 1.0]);
    }

    #[test]
    fn frequency_response_of_a_mass_damper() {
        // x/F = 1/(jω(jωm + b)) for ẋ = v, m v̇ = −b v + F.
        use num_complex::Complex64 as C;
        let (m, b, w) = (0.52, 13.2, 2.0 * std::f64::consts::PI * 30.0);
        let a = vec![vec![0.0, 1.0], vec![0.0, -b / m]];
        let got = frequency_response(&a, &[0.0, 1.0 / m], &[1.0, 0.0], w);
        let j = C::new(0.0, 1.0);
        let want = 1.0 / (j * w * (j * w * m + b));
        assert!((got - want).norm() < 1e-14 * want.norm(), "{got} vs {want}");
    }
}
