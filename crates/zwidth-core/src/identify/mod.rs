//! Device identification from an open-loop trace: the mass m, viscous
//! damping b and Coulomb friction f_c of `m ẍ + b ẋ + f_c·sign(ẋ) = F`
//! (the 2018 paper's model, §V), with uncertainties.
//!
//! Method: modulating functions (Shinbrot 1957; Preisig & Rippin 1993). A
//! window φ on [t0, t0 + T] that vanishes with its slope at both ends turns
//! the equation, by parts, into one without derivatives of x:
//!
//! `m ∫ x φ'' dt − b ∫ x φ' dt + f_c·s ∫ φ dt = ∫ F φ dt`
//!
//! wherever the handle moves one way (s = sign ẋ) through the whole window.
//! Encoder quantization enters only through integrals against a smooth φ'',
//! which average it out; nothing is differentiated. The paper estimated
//! friction a priori and fitted m, b in the frequency domain; here all three
//! come from one least-squares fit over every window, at three window
//! lengths. Uncertainty: the trace is cut into blocks, each fitted alone,
//! and the blocks' spread gives a Student-t interval (batch means), honest
//! about the windows' overlap that a residual-based covariance ignores.

pub mod estimate;
pub mod mode;
pub mod record;
pub mod scene;
pub mod trace;

use serde::Serialize;

use crate::error::SpecError;
use crate::zwidth::stats::student_t_quantile;
pub use estimate::Estimate;
pub use trace::Trace;

/// The window φ(τ) = (τ(1 − τ))^N on τ ∈ [0, 1]. φ and its derivatives
/// up to order N − 1 vanish at both ends, so the trapezoid rule over the
/// samples is accurate to O(h^N) there (Euler–Maclaurin: its error terms are
/// odd derivatives of the integrand at the ends), not O(h²).
const N: i32 = 6;
/// dφ/dτ = N w^{N−1} w', w = τ(1 − τ), w' = 1 − 2τ.
fn dphi(u: f64) -> f64 {
    let w = u * (1.0 - u);
    N as f64 * w.powi(N - 1) * (1.0 - 2.0 * u)
}
/// d²φ/dτ² = N(N − 1) w^{N−2} w'² − 2N w^{N−1}.
fn ddphi(u: f64) -> f64 {
    let w = u * (1.0 - u);
    let n = N as f64;
    n * (n - 1.0) * w.powi(N - 2) * (1.0 - 2.0 * u).powi(2) - 2.0 * n * w.powi(N - 1)
}
/// ∫₀^τ φ = Σ_k C(N, k)(−1)^k τ^{N+k+1}/(N + k + 1) (binomial expansion of
/// τ^N (1 − τ)^N); ∫₀¹ φ = B(N + 1, N + 1).
fn phi_integral(u: f64) -> f64 {
    let mut c = 1.0; // C(N, k)
    let mut sum = 0.0;
    for k in 0..=N {
        let p = N + k + 1;
        let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
        sum += sign * c * u.powi(p) / p as f64;
        c = c * (N - k) as f64 / (k + 1) as f64;
    }
    sum
}

/// The model to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Model {
    /// m, b and f_c.
    MassDamperCoulomb,
    /// m and b (f_c = 0).
    MassDamper,
    /// m, b, f_c of the whole device, then its transmission mode (motor
    /// and handle masses, cable stiffness and damping, the damping split)
    /// from the response around the mode; the encoder on the motor side
    /// ([`mode`]).
    TwoMass,
}

/// What `identify` found.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Identified {
    pub model: Model,
    /// kg.
    pub mass: Estimate,
    /// N·s/m.
    pub damping: Estimate,
    /// N (0 with no uncertainty for `mass_damper`).
    pub coulomb: Estimate,
    /// Encoder step found in the positions (m; 0: unquantized).
    pub quantization: f64,
    pub sample_hz: f64,
    pub duration_s: f64,
    /// Windows where the handle moved one way, used in the fit, of all windows tried.
    pub windows_used: usize,
    pub windows_tried: usize,
    /// Blocks the interval comes from.
    pub blocks: usize,
    /// RMS of the fit's residual force (N), per window.
    pub residual_rms_n: f64,
    /// The transmission mode (`two_mass` only); `mass`, `damping` and
    /// `coulomb` are then the whole device's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mode: Option<mode::ModeFit>,
}

/// Window lengths (s): the shortest sees the mass, the longest the
/// damping; all fit between the seed device's velocity reversals under the
/// default excitation.
const WINDOWS_S: [f64; 3] = [0.04, 0.08, 0.16];
/// Fewest samples in a window. The trapezoid's end error falls as h^N, but
/// only once a window has enough samples: measured on a noiseless linear
/// trace (seed device, 1 kHz), the fitted b is off by 4e-2 with 10-sample
/// windows, 4e-4 with 20, 3e-6 with 40 and 1e-8 with 80.
const MIN_WINDOW_SAMPLES: usize = 40;
/// Blocks for the interval.
const BLOCKS: usize = 10;

/// One window's equation: regressors (∫xφ'', −∫xφ', s∫φ) and ∫Fφ, each
/// divided by ∫φ so every row is in newtons.
struct Row {
    start: usize,
    a: [f64; 3],
    y: f64,
}

/// The velocity sign over samples [i0, i1] when the handle clearly moves
/// one way throughout: the displacement over ±h samples stays beyond
/// `min_move` at every sample (see [`stop_test`] for why that excludes a stop).
fn one_way(x: &[f64], i0: usize, i1: usize, h: usize, v_min_step: f64) -> Option<f64> {
    if i0 < h || i1 + h >= x.len() {
        return None;
    }
    let s = if x[i0 + h] > x[i0 - h] { 1.0 } else { -1.0 };
    (i0..=i1)
        .all(|i| s * (x[i + h] - x[i - h]) > v_min_step)
        .then_some(s)
}

/// The sign test's half-span h (samples) and the displacement over ±h a
/// sample must exceed. A window is kept when the handle cannot have stopped
/// (and so stuck) inside it: if v(τ) = 0 somewhere in [t − hΔ, t + hΔ],
/// then |v| ≤ a_max·2hΔ there and the displacement over that span is at
/// most a_max·(2hΔ)²; a displacement beyond that plus three encoder steps
/// rules a stop out. h: ±1 ms; a_max: 1.5× the largest second difference
/// over ±h, an acceleration bound read from the data. `q`: the encoder
/// step ([`Trace::quantization`]).
fn stop_test(trace: &Trace, q: f64) -> (usize, f64) {
    let (x, dt) = (&trace.position, trace.dt);
    let n = x.len();
    let h = ((0.001 / dt).round() as usize).max(1);
    let span = 2.0 * h as f64 * dt;
    let a_max = 1.5
        * (h..n.saturating_sub(h))
            .map(|k| (x[k + h] - 2.0 * x[k] + x[k - h]).abs())
            .fold(0.0, f64::max)
        / (h as f64 * dt).powi(2);
    (h, a_max * span * span + 3.0 * q.max(1e-9))
}

/// Every window's equation (those where the handle moved one way) at the
/// lengths `WINDOWS_S`, and how many windows were tried. `q`: the encoder step.
fn rows(trace: &Trace, q: f64) -> (Vec<Row>, usize) {
    let (x, f, dt) = (&trace.position, &trace.force, trace.dt);
    let n = x.len();
    let (h, v_min_step) = stop_test(trace, q);
    let mut out = Vec::new();
    let mut tried = 0;
    for &len_s in &WINDOWS_S {
        let len = ((len_s / dt).round() as usize).max(MIN_WINDOW_SAMPLES);
        let big_t = len as f64 * dt;
        let hop = (len / 4).max(1);
        let norm = big_t * phi_integral(1.0); // ∫φ dt over the window
        let mut i0 = 0;
        while i0 + len < n {
            tried += 1;
            let i1 = i0 + len;
            if let Some(s) = one_way(x, i0, i1, h, v_min_step) {
                // Trapezoid over the samples for x (smooth); F is held, so
                // ∫Fφ is exact interval by interval.
                // Positions about the window's first sample: φ' and φ''
                // integrate to 0, so the offset only costs rounding.
                let x0 = x[i0];
                let (mut ixpp, mut ixp, mut ifp) = (0.0, 0.0, 0.0);
                for j in 0..=len {
                    let u = j as f64 / len as f64;
                    let xj = x[i0 + j] - x0; // (φ' = φ'' = 0 at the ends: no end weights)
                    ixpp += xj * ddphi(u);
                    ixp += xj * dphi(u);
                    if j < len {
                        let u1 = (j + 1) as f64 / len as f64;
                        ifp += f[i0 + j] * (phi_integral(u1) - phi_integral(u));
                    }
                }
                // d/dt = (1/T) d/dτ; dt = T dτ.
                let ixpp = ixpp * dt / (big_t * big_t);
                let ixp = ixp * dt / big_t;
                let ifp = ifp * big_t;
                out.push(Row {
                    start: i0,
                    a: [ixpp / norm, -ixp / norm, s],
                    y: ifp / norm,
                });
            }
            i0 += hop;
        }
    }
    (out, tried)
}

/// Least squares over `rows` for the first `p` parameters (normal
/// equations on column-scaled regressors, Gaussian elimination with partial
/// pivoting). None when the rows do not determine them.
fn fit(rows: &[&Row], p: usize) -> Option<[f64; 3]> {
    if rows.len() < 2 * p {
        return None;
    }
    let mut scale = [0.0; 3];
    for r in rows {
        for (s, a) in scale.iter_mut().zip(&r.a).take(p) {
            *s += a * a;
        }
    }
    for s in scale.iter_mut().take(p) {
        *s = (*s / rows.len() as f64).sqrt();
        if s.is_nan() || *s <= 0.0 {
            return None;
        }
    }
    let mut m = [[0.0; 4]; 3];
    for r in rows {
        for i in 0..p {
            let ai = r.a[i] / scale[i];
            for j in 0..p {
                m[i][j] += ai * r.a[j] / scale[j];
            }
            m[i][3] += ai * r.y;
        }
    }
    for col in 0..p {
        let piv = (col..p).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        m.swap(col, piv);
        // A pivot this small against the scaled (unit-diagonal) system: singular.
        if m[col][col].abs() < 1e-9 * rows.len() as f64 {
            return None;
        }
        let pivot = m[col];
        for (r, row) in m.iter_mut().enumerate().take(p) {
            if r != col {
                let k = row[col] / pivot[col];
                for (v, pv) in row.iter_mut().zip(pivot).skip(col) {
                    *v -= k * pv;
                }
            }
        }
    }
    let mut theta = [0.0; 3];
    for i in 0..p {
        theta[i] = m[i][3] / m[i][i] / scale[i];
    }
    theta.iter().all(|v| v.is_finite()).then_some(theta)
}

/// Identify `model` from `trace` (already checked by [`Trace::parse_csv`]).
/// An estimate worth reporting: every figure finite and, for a parameter
/// the model fits, a standard error above zero (an interval of zero width
/// would claim a certainty the arithmetic lost). A parameter the model
/// leaves out is 0 ± 0.
fn usable(e: &Estimate, fitted: bool) -> bool {
    let finite = [e.value, e.std_error, e.lo, e.hi]
        .iter()
        .all(|x| x.is_finite());
    finite && (!fitted || e.std_error > 0.0)
}

pub fn identify(trace: &Trace, model: Model) -> Result<Identified, SpecError> {
    let p = match model {
        Model::MassDamperCoulomb | Model::TwoMass => 3,
        Model::MassDamper => 2,
    };
    // One scan for the encoder step: the stop test and the result share it.
    let quantization = trace.quantization();
    let (all, tried) = rows(trace, quantization);
    let (plus, minus) = (
        all.iter().filter(|r| r.a[2] > 0.0).count(),
        all.iter().filter(|r| r.a[2] < 0.0).count(),
    );
    const MIN_EACH_WAY: usize = 30;
    if plus < MIN_EACH_WAY || minus < MIN_EACH_WAY {
        return Err(SpecError::new(
            "trace",
            format!("{plus} windows moving forward, {minus} backward"),
            format!("needs at least {MIN_EACH_WAY} windows each way where the handle moves without reversing: excite longer or with more force"),
        ));
    }
    let refs: Vec<&Row> = all.iter().collect();
    let theta = fit(&refs, p).ok_or_else(|| {
        SpecError::new("trace", "(excitation)", "does not determine the parameters: the windows' motions are too alike (excite a band of frequencies, e.g. with `zwidth record`)")
    })?;
    // Batch means: each block of the trace fitted alone.
    let n = trace.position.len();
    let block_len = n.div_ceil(BLOCKS);
    let mut per_block: Vec<[f64; 3]> = Vec::new();
    for b in 0..BLOCKS {
        let mine: Vec<&Row> = all.iter().filter(|r| r.start / block_len == b).collect();
        if let Some(t) = fit(&mine, p) {
            per_block.push(t);
        }
    }
    if per_block.len() < 4 {
        return Err(SpecError::new(
            "trace",
            format!("{} of {BLOCKS} blocks fit alone", per_block.len()),
            "needs at least 4 blocks of the trace that each determine the parameters, for the interval: record longer",
        ));
    }
    let nb = per_block.len() as f64;
    let tq = student_t_quantile(0.975, nb - 1.0);
    let est = |c: usize| {
        if c >= p {
            return Estimate {
                value: 0.0,
                std_error: 0.0,
                lo: 0.0,
                hi: 0.0,
            };
        }
        let mean = per_block.iter().map(|t| t[c]).sum::<f64>() / nb;
        let var = per_block.iter().map(|t| (t[c] - mean).powi(2)).sum::<f64>() / (nb - 1.0);
        let se = (var / nb).sqrt();
        Estimate {
            value: theta[c],
            std_error: se,
            lo: theta[c] - tq * se,
            hi: theta[c] + tq * se,
        }
    };
    let residual = (all
        .iter()
        .map(|r| {
            let pred: f64 = (0..p).map(|c| r.a[c] * theta[c]).sum();
            (r.y - pred).powi(2)
        })
        .sum::<f64>()
        / all.len() as f64)
        .sqrt();
    let rigid = Identified {
        model,
        mass: est(0),
        damping: est(1),
        coulomb: est(2),
        mode: None,
        quantization,
        sample_hz: trace.sample_hz(),
        duration_s: n as f64 * trace.dt,
        windows_used: all.len(),
        windows_tried: tried,
        blocks: per_block.len(),
        residual_rms_n: residual,
    };
    // Every figure a number and every interval of a fitted parameter of
    // nonzero width: what underflow or overflow in the sums would break.
    for (name, e, fitted) in [
        ("mass", &rigid.mass, true),
        ("damping", &rigid.damping, true),
        ("coulomb", &rigid.coulomb, p > 2),
    ] {
        if !usable(e, fitted) {
            return Err(SpecError::new(
                "trace",
                format!("{name} = {} ± {}", e.value, e.std_error),
                "gives no usable interval: the trace's forces and motions are out of the range the fit's arithmetic holds (rescale to SI units)",
            ));
        }
    }
    match model {
        Model::TwoMass => with_mode(rigid, trace),
        _ => Ok(rigid),
    }
}

/// The rigid fit `rigid` (m, b, f_c of the whole device) completed with the
/// transmission mode fitted on `mode_trace` (which may be the same trace,
/// or a second one recorded with a band around the mode).
pub fn with_mode(rigid: Identified, mode_trace: &Trace) -> Result<Identified, SpecError> {
    let mode = mode::fit_mode(mode_trace, &rigid.mass, &rigid.damping)?;
    Ok(Identified {
        model: Model::TwoMass,
        mode: Some(mode),
        ..rigid
    })
}

#[cfg(test)]
mod tests {
    use super::record::{record, Excitation};
    use super::*;
    use crate::zwidth::scene::{Scene, SceneSpec};

    pub(super) fn scene(json: &str) -> Scene {
        SceneSpec::from_json(json).unwrap().validate().unwrap()
    }

    /// `got` within `rel` of `want`.
    pub(super) fn within(got: &Estimate, want: f64, rel: f64, what: &str) {
        assert!(
            (got.value - want).abs() <= rel * want.abs(),
            "{what}: {} vs {want} (±{} %)",
            got.value,
            rel * 100.0
        );
    }

    #[test]
    fn window_shape_and_its_integral() {
        // ∫₀¹ (τ(1 − τ))⁶ dτ = B(7, 7) = 6!·6!/13! = 1/12012.
        assert!((phi_integral(1.0) * 12012.0 - 1.0).abs() < 1e-10);
        assert_eq!(phi_integral(0.0), 0.0);
        // The derivatives against central differences of φ = (τ(1 − τ))⁶
        // and of the antiderivative.
        let phi = |u: f64| (u * (1.0 - u)).powi(6);
        let h = 1e-5;
        for u in [0.1, 0.33, 0.5, 0.71, 0.9] {
            let d1 = (phi(u + h) - phi(u - h)) / (2.0 * h);
            let d2 = (phi(u + h) - 2.0 * phi(u) + phi(u - h)) / (h * h);
            let d0 = (phi_integral(u + h) - phi_integral(u - h)) / (2.0 * h);
            assert!((dphi(u) - d1).abs() < 1e-8, "φ' at {u}");
            assert!((ddphi(u) - d2).abs() < 1e-4, "φ'' at {u}");
            assert!((phi(u) - d0).abs() < 1e-10, "φ at {u}");
        }
        assert_eq!(
            (dphi(0.0), dphi(1.0), ddphi(0.0), ddphi(1.0)),
            (0.0, 0.0, 0.0, 0.0)
        );
    }

    /// A trace of `n` samples every `dt` s, (force, position) from t.
    fn sampled(dt: f64, n: usize, f: impl Fn(f64) -> (f64, f64)) -> Trace {
        let t: Vec<f64> = (0..n).map(|k| k as f64 * dt).collect();
        let (force, position) = t.iter().map(|&t| f(t)).unzip();
        Trace {
            dt,
            t,
            force,
            position,
        }
    }

    #[test]
    fn stop_test_bound_by_hand() {
        // x = ½·a·t² + v0·t + x0 at 2 kHz, a = 3 m/s², ideal sensor (v0, x0
        // irrational: no encoder step fits every position): h = 1 ms / 0.5 ms =
        // 2 samples; the second difference over ±h is exactly a·(hΔ)², so
        // a_max = 1.5·3 = 4.5 m/s², and the bound is a_max·(2hΔ)² + 3 nm
        // = 4.5·(2e-3)² + 3e-9 = 1.8003e-5 m.
        let tr = sampled(5e-4, 2000, |t| {
            (
                0.0,
                1.5 * t * t + 2f64.sqrt() * 1e-3 * t + std::f64::consts::PI * 1e-4,
            )
        });
        let (h, bound) = stop_test(&tr, tr.quantization());
        assert_eq!(h, 2);
        assert!((bound - 1.8003e-5).abs() < 1e-12, "{bound}");
    }

    #[test]
    fn motion_one_way_only_is_refused_in_either_direction() {
        // Sliding one way at v = ±(0.1 + 0.05·sin t) m/s under
        // F = m·a + b·v ± f_c: every window moves the same way, so f_c cannot
        // be told from a force offset.
        for dir in [1.0, -1.0] {
            let tr = sampled(1e-3, 20_000, |t| {
                (
                    dir * (0.52 * 0.05 * t.cos() + 13.2 * (0.1 + 0.05 * t.sin()) + 0.19),
                    dir * (0.1 * t + 0.05 * (1.0 - t.cos())),
                )
            });
            let e = identify(&tr, Model::MassDamperCoulomb).unwrap_err();
            assert!(e.allowed.contains("at least 30 windows each way"), "{e}");
            let (fwd, back) = if dir > 0.0 {
                ("forward", "0 backward")
            } else {
                ("0 windows moving forward", "backward")
            };
            assert!(
                e.value.contains(fwd) && e.value.contains(back),
                "{}",
                e.value
            );
        }
    }

    #[test]
    fn where_the_device_sits_does_not_matter() {
        // The same motion 1 m further along the rail: the equation has no
        // position term, so every estimate must agree (to rounding: each
        // window's positions are taken about its first sample).
        let sc = scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#);
        let tr = record(&sc, &Excitation::default());
        let mut moved = tr.clone();
        moved.position.iter_mut().for_each(|x| *x += 1.0);
        let (a, b) = (
            identify(&tr, Model::MassDamperCoulomb).unwrap(),
            identify(&moved, Model::MassDamperCoulomb).unwrap(),
        );
        for (x, y) in [
            (a.mass, b.mass),
            (a.damping, b.damping),
            (a.coulomb, b.coulomb),
        ] {
            assert!((x.value / y.value - 1.0).abs() < 1e-9, "{x:?} vs {y:?}");
        }
    }

    #[test]
    fn a_fit_needs_twice_as_many_windows_as_parameters() {
        // Five consistent rows of m = 1, b = 2, f_c = 3 (y = a·θ): enough
        // equations to solve, but fewer than 2·3, so no fit is claimed.
        let rows: Vec<Row> = (0..6)
            .map(|i| {
                let a = [
                    1.0 + i as f64,
                    (i * i) as f64 - 2.0,
                    if i % 2 == 0 { 1.0 } else { -1.0 },
                ];
                Row {
                    start: 0,
                    a,
                    y: a[0] + 2.0 * a[1] + 3.0 * a[2],
                }
            })
            .collect();
        let refs: Vec<&Row> = rows.iter().collect();
        assert!(fit(&refs[..5], 3).is_none());
        let theta = fit(&refs, 3).unwrap();
        for (got, want) in theta.iter().zip([1.0, 2.0, 3.0]) {
            assert!((got - want).abs() < 1e-9, "{theta:?}");
        }
    }

    #[test]
    fn recovers_a_linear_device_to_its_parameters() {
        // Reference: the m, b the trace was simulated with (exact ZOH plant,
        // ideal sensor): only the quadrature's O(h³) error remains.
        let sc = scene(
            r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
        );
        let tr = record(&sc, &Excitation::default());
        let id = identify(&tr, Model::MassDamper).unwrap();
        within(&id.mass, 0.52, 1e-3, "m");
        within(&id.damping, 13.2, 1e-3, "b");
        assert_eq!((id.coulomb.value, id.coulomb.std_error), (0.0, 0.0));
        assert_eq!(id.quantization, 0.0);
        assert_eq!((id.sample_hz, id.duration_s), (1000.0, 20.0));
        let with_fc = identify(&tr, Model::MassDamperCoulomb).unwrap();
        assert!(with_fc.coulomb.value.abs() < 1e-3, "{:?}", with_fc.coulomb);
        assert!(id.residual_rms_n < 1e-3 && id.blocks == 10);
    }

    #[test]
    fn recovers_the_seed_device_within_2_percent_and_the_intervals_cover_it() {
        // The 2018 paper's identified device (§V: 0.52 kg, 13.2 N·s/m,
        // 0.19 N, 1 µm encoder), 20 s of the default multisine.
        let sc = scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#);
        let tr = record(&sc, &Excitation::default());
        let id = identify(&tr, Model::MassDamperCoulomb).unwrap();
        for (e, want, name) in [
            (&id.mass, 0.52, "m"),
            (&id.damping, 13.2, "b"),
            (&id.coulomb, 0.19, "f_c"),
        ] {
            within(e, want, 0.02, name);
            assert!(
                e.lo <= want && want <= e.hi,
                "{name}: {want} outside [{}, {}]",
                e.lo,
                e.hi
            );
            assert!(
                e.std_error > 0.0 && e.hi - e.lo < 0.02 * want,
                "{name}: {e:?}"
            );
        }
        assert_eq!(id.quantization, 1e-6);
        assert!(
            id.windows_used > 300 && id.windows_used < id.windows_tried,
            "{id:?}"
        );
        // The standard error is the batch-means one, recomputed here from
        // the blocks' own fits: sd over the blocks / √(blocks).
        let (all, _) = rows(&tr, tr.quantization());
        let block_len = tr.position.len().div_ceil(BLOCKS);
        let masses: Vec<f64> = (0..BLOCKS)
            .filter_map(|b| {
                let mine: Vec<&Row> = all.iter().filter(|r| r.start / block_len == b).collect();
                fit(&mine, 3).map(|t| t[0])
            })
            .collect();
        let n = masses.len() as f64;
        let mean = masses.iter().sum::<f64>() / n;
        let sd = (masses.iter().map(|m| (m - mean).powi(2)).sum::<f64>() / (n - 1.0)).sqrt();
        assert_eq!(id.blocks, masses.len());
        let want = sd / n.sqrt();
        assert!(
            (id.mass.std_error / want - 1.0).abs() < 1e-9,
            "{:?} vs {want}",
            id.mass
        );
        // Issue 31: each interval is value ± t·se with t the Student
        // quantile t(0.975, blocks − 1): 2.2621571627409915 for 10 blocks
        // (scipy.stats.t.ppf(0.975, 9)); a normal 1.96 or 9 degrees' 2.26
        // with 10 (2.2281) is 13 % or 1.5 % off and fails.
        assert_eq!(id.blocks, 10);
        let t9 = 2.262_157_162_740_991_5;
        for e in [&id.mass, &id.damping, &id.coulomb] {
            let half = (e.hi - e.lo) / 2.0;
            assert!((half / (t9 * e.std_error) - 1.0).abs() < 1e-9, "{e:?}");
            assert!(
                ((e.hi + e.lo) / 2.0 - e.value).abs() < 1e-12 * e.value.abs(),
                "{e:?}"
            );
        }
    }

    #[test]
    fn recovers_a_light_sticky_device_at_2_khz() {
        // Friction 2.5× the seed's against a fifth of the mass, a coarser
        // 5 µm encoder: the handle sticks often, and windows with a stop in
        // them must be left out (with them, b came out 1.4 % high and f_c
        // 1.8 % low, outside their intervals).
        let sc = scene(
            r#"{"device":{"mass":0.1,"damping":2,"coulomb":0.5,"quantization":5e-6},"loop":{"sample_hz":2000,"render_hz":2000}}"#,
        );
        let ex = Excitation {
            peak_force: 2.0,
            ..Excitation::default()
        };
        let id = identify(&record(&sc, &ex), Model::MassDamperCoulomb).unwrap();
        for (e, want, name) in [
            (&id.mass, 0.1, "m"),
            (&id.damping, 2.0, "b"),
            (&id.coulomb, 0.5, "f_c"),
        ] {
            within(e, want, 0.005, name);
            assert!(
                e.lo <= want && want <= e.hi,
                "{name}: {want} outside [{}, {}]",
                e.lo,
                e.hi
            );
        }
        assert_eq!(id.quantization, 5e-6);
    }

    #[test]
    fn a_trace_that_barely_moves_is_refused() {
        // 0.2 N peak against 0.19 N of friction: the handle mostly sticks.
        let sc = scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#);
        let ex = Excitation {
            peak_force: 0.2,
            ..Excitation::default()
        };
        let e = identify(&record(&sc, &ex), Model::MassDamperCoulomb).unwrap_err();
        assert_eq!(e.field, "trace");
        assert!(e.allowed.contains("at least 30 windows each way"), "{e}");
    }

    /// Issue 30: what an estimate must be to be reported (each clause).
    #[test]
    fn only_finite_estimates_with_a_spread_are_usable() {
        let e = |value: f64, std_error: f64| Estimate {
            value,
            std_error,
            lo: value - std_error,
            hi: value + std_error,
        };
        assert!(usable(&e(1.0, 0.1), true));
        assert!(!usable(&e(1.0, 0.0), true), "zero width, fitted");
        assert!(usable(&e(0.0, 0.0), false), "left out: 0 ± 0");
        assert!(!usable(&e(f64::NAN, 0.1), true));
        assert!(!usable(&e(f64::NAN, 0.0), false));
        assert!(!usable(&e(1.0, f64::INFINITY), false));
        assert!(!usable(
            &Estimate {
                hi: f64::INFINITY,
                ..e(1.0, 0.1)
            },
            true
        ));
        assert!(!usable(
            &Estimate {
                lo: f64::NEG_INFINITY,
                ..e(1.0, 0.1)
            },
            false
        ));
        // The coulomb term is fitted by the models with friction only.
        let tr = super::record::record(
            &scene(
                r#"{"device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}}"#,
            ),
            &Excitation::default(),
        );
        let id = identify(&tr, Model::MassDamper).unwrap();
        assert_eq!((id.coulomb.value, id.coulomb.std_error), (0.0, 0.0));
    }

    #[test]
    fn intervals_cover_the_truth_about_95_percent_of_the_time() {
        // 200 excitations (peak 0.8–2.2 N in 10 steps, periods 1–4 s, top
        // line 10–25 Hz) on the seed device: 600 nominal-95 % intervals.
        // Measured when written: 565 cover (94.2 %), the worst error 0.2 %;
        // with a 90 % quantile instead, 549.
        // The bound (issue 31): at 95 % the count is binomial(600, 0.95),
        // mean 570, sd 5.3, and below 555 with probability ≈ 0.3 %; at 90 %
        // (mean 540, sd 7.3) it reaches 555 with probability ≈ 2 %. So 555
        // tells the stated level from the next lower common one, which the
        // old 54-of-60 bound did not (a 90 % interval passes that 70 % of
        // the time).
        let sc = scene(r#"{"loop":{"sample_hz":1000,"render_hz":1000}}"#);
        let (mut covered, mut worst, mut n) = (0, 0.0f64, 0);
        for i in 0..200 {
            let ex = Excitation {
                peak_force: 0.8 + 1.4 * (i % 10) as f64 / 9.0,
                period_s: [1.0, 1.5, 2.0, 2.5, 3.0, 4.0][(i / 10) % 6],
                f_max_hz: [10.0, 12.0, 15.0, 18.0, 20.0, 25.0, 14.0][(i / 3) % 7],
                duration_s: 20.0,
                band: None,
            };
            let id = identify(&record(&sc, &ex), Model::MassDamperCoulomb).unwrap();
            for (e, want) in [(id.mass, 0.52), (id.damping, 13.2), (id.coulomb, 0.19)] {
                covered += usize::from(e.lo <= want && want <= e.hi);
                worst = worst.max((e.value / want - 1.0).abs());
                n += 1;
            }
        }
        assert_eq!(n, 600);
        assert!(covered >= 555, "{covered} of 600 intervals cover");
        assert!(worst < 0.01, "worst relative error {worst}");
    }
}
