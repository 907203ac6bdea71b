//! Small statistics the noisy-scene verdict needs: Student's t quantile,
//! and a reproducible stream of uniform numbers for random phases.
//!
//! The t distribution's CDF is the regularized incomplete beta function
//! (Abramowitz & Stegun 26.7.1: P(T ≤ t) = 1 − ½·I_{ν/(ν+t²)}(ν/2, ½) for
//! t ≥ 0), evaluated by its continued fraction (A&S 26.5.8, modified Lentz)
//! with ln Γ from Lanczos' approximation (g = 7, n = 9; Press et al.,
//! *Numerical Recipes* 3rd ed. §6.1). The quantile is found by bisection.

/// ln Γ(x) for x > 0 (Lanczos, g = 7; relative error ≈ 1e-15).
fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection: Γ(x)Γ(1 − x) = π / sin(πx).
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Continued fraction of the incomplete beta (A&S 26.5.8), modified Lentz.
fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    const TINY: f64 = 1e-300;
    let (qab, qap, qam) = (a + b, a + 1.0, a - 1.0);
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < TINY {
        d = TINY;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..300 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        d = 1.0 + aa * d;
        d = if d.abs() < TINY { TINY } else { d };
        c = 1.0 + aa / c;
        c = if c.abs() < TINY { TINY } else { c };
        d = 1.0 / d;
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Regularized incomplete beta I_x(a, b), 0 ≤ x ≤ 1.
fn inc_beta(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let front =
        (ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln()).exp();
    // The fraction converges fast for x < (a + 1)/(a + b + 2); else use symmetry.
    if x < (a + 1.0) / (a + b + 2.0) {
        front * beta_cf(a, b, x) / a
    } else {
        1.0 - front * beta_cf(b, a, 1.0 - x) / b
    }
}

/// P(T ≤ t) for Student's t with `nu` > 0 degrees of freedom (A&S 26.7.1).
pub fn student_t_cdf(t: f64, nu: f64) -> f64 {
    let tail = 0.5 * inc_beta(0.5 * nu, 0.5, nu / (nu + t * t));
    if t >= 0.0 {
        1.0 - tail
    } else {
        tail
    }
}

/// The t value with P(T ≤ t) = p, for 0.5 ≤ p < 1 (bisection to 1e-12),
/// kept per thread by (p, ν): a noisy map asks for the same few quantiles
/// at every look of every verdict, and the bisection (≈ 40 incomplete beta
/// functions) cost 2.5 % of its time (perf, issue 34). The value kept is the
/// value computed, bit for bit.
pub fn student_t_quantile(p: f64, nu: f64) -> f64 {
    use std::cell::RefCell;
    use std::collections::HashMap;
    thread_local! {
        static KEPT: RefCell<HashMap<(u64, u64), f64>> = RefCell::new(HashMap::new());
    }
    KEPT.with(|kept| {
        let key = (p.to_bits(), nu.to_bits());
        if let Some(&t) = kept.borrow().get(&key) {
            return t;
        }
        let t = t_quantile_by_bisection(p, nu);
        keep(&mut kept.borrow_mut(), key, t);
        t
    })
}

/// Most quantiles kept per thread (a few dozen in practice).
const MAX_KEPT_QUANTILES: usize = 4096;

/// Keep `t` under `key`, starting afresh when the cap is reached.
fn keep(kept: &mut std::collections::HashMap<(u64, u64), f64>, key: (u64, u64), t: f64) {
    if kept.len() >= MAX_KEPT_QUANTILES {
        kept.clear();
    }
    kept.insert(key, t);
}

fn t_quantile_by_bisection(p: f64, nu: f64) -> f64 {
    debug_assert!((0.5..1.0).contains(&p) && nu > 0.0);
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    while student_t_cdf(hi, nu) < p && hi < 1e12 {
        hi *= 2.0;
    }
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if student_t_cdf(mid, nu) < p {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo <= 1e-12 * hi {
            break;
        }
    }
    0.5 * (lo + hi)
}

/// SplitMix64 (Steele, Lea & Flood 2014): a reproducible stream from a
/// seed, the same on every platform, so a realization is a function of
/// (seed, index) alone — the common random numbers of two maps.
pub struct SplitMix64(u64);

impl SplitMix64 {
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in [0, 1), 53 random bits.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Standard normal from two uniforms (Box & Muller 1958: √(−2 ln u)·cos 2πv).
    pub fn standard_normal(&mut self) -> f64 {
        let (u, v) = (self.next_f64().max(1e-300), self.next_f64());
        (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn t_quantiles_match_published_tables() {
        // Student's t table (e.g. NIST/SEMATECH e-Handbook §1.3.6.7.2;
        // scipy.stats.t.ppf gives the same digits).
        let table = [
            (0.975, 1.0, 12.706_204_736),
            (0.975, 2.0, 4.302_652_730),
            (0.95, 5.0, 2.015_048_373),
            (0.995, 10.0, 3.169_272_673),
            (0.999, 29.0, 3.396_240_288),
            (0.975, 1000.0, 1.962_339_081),
            // Far tails of the degrees of freedom (scipy.stats.t.ppf; the
            // Cornish–Fisher series z + (z³ + z)/(4ν) gives 1.9599663568):
            // where the continued fraction needs its symmetric form.
            (0.975, 1e6, 1.959_966_356_814),
            (0.9995, 1e6, 3.290_536_461_249),
        ];
        for (p, nu, want) in table {
            let got = student_t_quantile(p, nu);
            assert!(
                (got / want - 1.0).abs() < 1e-8,
                "t({p}, {nu}) = {got}, table {want}"
            );
            // Asked again: the kept value, the bisection's to the bit.
            assert_eq!(student_t_quantile(p, nu).to_bits(), got.to_bits());
            assert_eq!(t_quantile_by_bisection(p, nu).to_bits(), got.to_bits());
        }
        // Symmetry and the median.
        assert!((student_t_cdf(0.0, 3.0) - 0.5).abs() < 1e-15);
        let (a, b) = (student_t_cdf(1.7, 4.0), student_t_cdf(-1.7, 4.0));
        assert!((a + b - 1.0).abs() < 1e-14);
    }

    #[test]
    fn the_kept_quantiles_never_pass_their_cap() {
        let mut kept = std::collections::HashMap::new();
        for i in 0..MAX_KEPT_QUANTILES as u64 {
            keep(&mut kept, (i, 0), 1.0);
        }
        assert_eq!(kept.len(), MAX_KEPT_QUANTILES);
        // Full: the next one starts afresh.
        keep(&mut kept, (u64::MAX, 0), 2.0);
        assert_eq!(kept.len(), 1);
        assert_eq!(kept[&(u64::MAX, 0)], 2.0);
    }

    #[test]
    fn t_cdf_of_one_degree_is_the_cauchy_cdf() {
        // ν = 1 is the Cauchy distribution: ½ + atan(t)/π.
        for t in [-30.0, -2.0, -0.3, 0.1, 1.0, 7.5] {
            let want = 0.5 + f64::atan(t) / std::f64::consts::PI;
            assert!((student_t_cdf(t, 1.0) - want).abs() < 1e-13, "{t}");
        }
    }

    #[test]
    fn far_tails_keep_their_relative_precision() {
        // ν = 1 (Cauchy): F(t) = atan(1/|t|)/π for t < 0; ν = 2: F(t) =
        // 1/(s(s + |t|)) with s = √(2 + t²) (F = ½ + t/(2s), rearranged).
        let rel = |a: f64, b: f64| ((a - b) / b).abs();
        let cauchy = (1e-6f64).atan() / std::f64::consts::PI;
        assert!(rel(student_t_cdf(-1e6, 1.0), cauchy) < 1e-12);
        let s = (2.0f64 + 1e8).sqrt();
        assert!(rel(student_t_cdf(-1e4, 2.0), 1.0 / (s * (s + 1e4))) < 1e-12);
        assert!(rel(1.0 - student_t_cdf(1e6, 1.0), cauchy) < 1e-6);
    }

    #[test]
    fn ln_gamma_matches_factorials() {
        for (n, fact) in [(1.0, 1.0), (5.0, 24.0), (11.0, 3_628_800.0)] {
            assert!((ln_gamma(n) - f64::ln(fact)).abs() < 1e-12, "{n}");
        }
        // Γ(½) = √π.
        assert!((ln_gamma(0.5) - 0.5 * std::f64::consts::PI.ln()).abs() < 1e-13);
        // Below ½ by the reflection formula: Γ(¼) = 3.625 609 908 221 908
        // (OEIS A068466).
        assert!((ln_gamma(0.25) - 3.625_609_908_221_908f64.ln()).abs() < 1e-12);
    }

    #[test]
    fn splitmix_is_the_reference_stream() {
        // First outputs of SplitMix64 seeded with 1234567 (the reference
        // C implementation by Vigna, prng.di.unimi.it/splitmix64.c).
        let mut r = SplitMix64::new(1_234_567);
        assert_eq!(r.next_u64(), 6_457_827_717_110_365_317);
        assert_eq!(r.next_u64(), 3_203_168_211_198_807_973);
        let mut r = SplitMix64::new(7);
        let u: Vec<f64> = (0..1000).map(|_| r.next_f64()).collect();
        assert!(u.iter().all(|&x| (0.0..1.0).contains(&x)));
        let mean = u.iter().sum::<f64>() / 1000.0;
        assert!((mean - 0.5).abs() < 0.03, "{mean}");
    }
}
