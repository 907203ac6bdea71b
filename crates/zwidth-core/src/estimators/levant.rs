//! Levant's first-order robust exact differentiator (super-twisting), with
//! gains given directly, by a rule, or normalized, and a report of which
//! sufficient convergence conditions the gains meet.
//!
//! Units: `alpha` in m/s², `lambda` in m^½/s, `lipschitz` C in m/s² (a bound
//! on |ẍ|, 2011 paper eqs. 4–5).
//!
//! Discretizations:
//! - `explicit` (default) — exactly the 2011 paper's eqs. 6–8 with explicit Euler:
//!   `e = x − y_k; u = u1 − λ·√|e|·sign(e)`; output `u`; then
//!   `x += T·u; u1 −= T·α·sign(e)`; start `x = y_0, u1 = 0`; `sign(0) = 0`.
//! - `implicit` — the implicit (backward) Euler discretization of the same
//!   differential inclusion (Mojallizadeh, Brogliato & Acary 2021; Brogliato &
//!   Polyakov 2015), with the set-valued sign solved exactly. With the
//!   predicted error `w = x_k + T·u1_k − y_{k+1}`:
//!   if `|w| ≤ T²α`: `e_{k+1} = 0`, `s = w/(T²α)` (sliding, s ∈ [−1, 1]);
//!   else `s = sign(w)` and `r = √|e_{k+1}|` solves `r² + Tλr = |w| − T²α`.
//!   Then `u1_{k+1} = u1_k − Tαs`, `x_{k+1} = y_{k+1} + s·r²`, and the output is
//!   `u1_{k+1}`, the integrator state (Levant's later notation, z1): on the
//!   sliding set it takes every value in between instead of switching by
//!   ±Tα every sample, which is the numerical chattering the explicit scheme has.
//!   With `"implicit_output":"eq7"` it is instead the 2011 paper's eq. 7 at
//!   the new state, `u = u1_{k+1} − λ·√|e_{k+1}|·sign(e_{k+1})`: equal while
//!   sliding (e = 0), different while reaching. The Z-width figures use the
//!   default, `state` (docs/estimators.md).

use serde::{Deserialize, Serialize};

use super::streaming::VelocityEstimator;
use crate::error::{require_positive, require_range, SpecError};

#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum Discretization {
    #[default]
    Explicit,
    Implicit,
}

/// What the implicit scheme outputs (the explicit one always outputs eq. 7's u).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ImplicitOutput {
    /// `u1_{k+1}`, the integrator state (Levant's later z1).
    #[default]
    State,
    /// The 2011 paper's eq. 7 at the new state: `u1_{k+1} − λ√|e_{k+1}|·sign(e_{k+1})`.
    Eq7,
}

impl ImplicitOutput {
    fn is_state(&self) -> bool {
        *self == ImplicitOutput::State
    }
}

/// Gain rules of the 2018 paper §III, all proportional to the Lipschitz bound C.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum GainRule {
    /// Levant's "special case" α = 1.1C, λ = √C (2018 eq. 11). It does NOT meet
    /// Levant's own condition (eq. 10) nor Moreno–Osorio's (eq. 14).
    HbaSc,
    /// A pair meeting Levant's condition (2018 eq. 10) with the same 10 %
    /// margin as the special case: μ1 = 2, μ2 = √(1.1·12) ≈ 3.633
    /// (eq. 10 at μ1 = 2 needs μ2² ≥ 4·3/1 = 12).
    Hba,
    /// A pair meeting Moreno–Osorio's Lyapunov condition (2018 eq. 14) with a
    /// 10 % margin: μ2 = 2, μ1 = 1.1·(3 + 2/μ2²) = 3.85.
    Lfba,
}

impl GainRule {
    /// Normalized gains (μ1, μ2): α = μ1·C, λ = μ2·√C.
    pub fn normalized(self) -> (f64, f64) {
        match self {
            GainRule::HbaSc => (1.1, 1.0),
            GainRule::Hba => (2.0, (1.1f64 * 12.0).sqrt()),
            GainRule::Lfba => (1.1 * (3.0 + 2.0 / 4.0), 2.0),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            GainRule::HbaSc => "hba_sc",
            GainRule::Hba => "hba",
            GainRule::Lfba => "lfba",
        }
    }
}

/// JSON: `{"kind":"levant","alpha":A,"lambda":L}`, or
/// `{"kind":"levant","rule":"hba_sc","lipschitz":C}`, or
/// `{"kind":"levant","mu1":6.6,"mu2":2.45,"lipschitz":C}`; optional
/// `"discretization":"explicit"|"implicit"`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LevantSpec {
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub alpha: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lambda: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rule: Option<GainRule>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mu1: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mu2: Option<f64>,
    /// Lipschitz bound C of the derivative (m/s²); required with `rule` or `mu1/mu2`,
    /// optional with explicit gains (then it is used for the gain report only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lipschitz: Option<f64>,
    #[serde(default)]
    pub discretization: Discretization,
    /// Implicit scheme only: `state` (default) or `eq7`.
    #[serde(default, skip_serializing_if = "ImplicitOutput::is_state")]
    pub implicit_output: ImplicitOutput,
}

/// Resolved gains, with C when known.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LevantGains {
    pub alpha: f64,
    pub lambda: f64,
    pub lipschitz: Option<f64>,
}

impl LevantSpec {
    pub fn label(&self) -> String {
        // A spec not yet validated may lack a value: say so, never "NaN".
        let show = |v: Option<f64>| v.map_or_else(|| "unset".to_string(), |x| x.to_string());
        let g = match (self.rule, self.mu1, self.alpha) {
            (Some(r), _, _) => format!("{}, C={}", r.name(), show(self.lipschitz)),
            (_, Some(m1), _) => format!(
                "mu1={m1}, mu2={}, C={}",
                show(self.mu2),
                show(self.lipschitz)
            ),
            _ => format!("alpha={}, lambda={}", show(self.alpha), show(self.lambda)),
        };
        match self.discretization {
            Discretization::Explicit => g,
            Discretization::Implicit if !self.implicit_output.is_state() => {
                format!("{g}, implicit, eq. 7 output")
            }
            Discretization::Implicit => format!("{g}, implicit"),
        }
    }

    /// Resolve and validate the gains from whichever form was given.
    pub fn gains(&self) -> Result<LevantGains, SpecError> {
        // Gains and C within 1e-12 … 1e12 keep every quantity of the
        // conditions below (α/C, λ², 4C(α+C)/(α−C)) finite.
        if let Some(c) = self.lipschitz {
            require_range(
                "lipschitz",
                c,
                GAIN_MIN,
                GAIN_MAX,
                "m/s², a bound on |acceleration|",
            )?;
        }
        let explicit = self.alpha.is_some() || self.lambda.is_some();
        let normalized = self.mu1.is_some() || self.mu2.is_some();
        let forms = [explicit, self.rule.is_some(), normalized]
            .iter()
            .filter(|&&b| b)
            .count();
        if forms != 1 {
            return Err(SpecError::new(
                "levant",
                if forms == 0 { "no gains" } else { "several gain forms" },
                "give exactly one of: alpha + lambda; rule (hba_sc|hba|lfba) + lipschitz; mu1 + mu2 + lipschitz",
            ));
        }
        let need_c = |form: &str| {
            self.lipschitz.ok_or_else(|| {
                SpecError::new(
                    "lipschitz",
                    "missing",
                    format!("{form} needs lipschitz, the bound C on |acceleration| (m/s²)"),
                )
            })
        };
        let (alpha, lambda) = if explicit {
            let a = self.alpha.ok_or_else(|| {
                SpecError::new("alpha", "missing", "alpha and lambda go together")
            })?;
            let l = self.lambda.ok_or_else(|| {
                SpecError::new("lambda", "missing", "alpha and lambda go together")
            })?;
            (a, l)
        } else if let Some(rule) = self.rule {
            let c = need_c("rule")?;
            let (m1, m2) = rule.normalized();
            (m1 * c, m2 * c.sqrt())
        } else {
            let m1 = self
                .mu1
                .ok_or_else(|| SpecError::new("mu1", "missing", "mu1 and mu2 go together"))?;
            let m2 = self
                .mu2
                .ok_or_else(|| SpecError::new("mu2", "missing", "mu1 and mu2 go together"))?;
            require_positive("mu1", m1, "alpha = mu1·C")?;
            require_positive("mu2", m2, "lambda = mu2·√C")?;
            let c = need_c("mu1/mu2")?;
            (m1 * c, m2 * c.sqrt())
        };
        require_range("alpha", alpha, GAIN_MIN, GAIN_MAX, "m/s²")?;
        require_range("lambda", lambda, GAIN_MIN, GAIN_MAX, "m^½/s")?;
        Ok(LevantGains {
            alpha,
            lambda,
            lipschitz: self.lipschitz,
        })
    }
}

/// Range of α, λ and C accepted.
pub const GAIN_MIN: f64 = 1e-12;
pub const GAIN_MAX: f64 = 1e12;

/// Which sufficient convergence conditions a gain pair meets.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct GainReport {
    pub alpha: f64,
    pub lambda: f64,
    pub lipschitz: Option<f64>,
    /// α/C and λ/√C when C is known.
    pub mu1: Option<f64>,
    pub mu2: Option<f64>,
    /// Levant 1998: α > C and λ² ≥ 4C(α+C)/(α−C) (2018 paper eq. 10).
    pub levant_1998: Option<bool>,
    /// Moreno–Osorio 2008: α > 3C + 2C²/λ² (2018 paper eq. 14).
    pub moreno_osorio: Option<bool>,
}

impl LevantGains {
    pub fn report(&self) -> GainReport {
        let (a, l) = (self.alpha, self.lambda);
        let c = self.lipschitz;
        GainReport {
            alpha: a,
            lambda: l,
            lipschitz: c,
            mu1: c.map(|c| a / c),
            mu2: c.map(|c| l / c.sqrt()),
            levant_1998: c.map(|c| a > c && l * l >= 4.0 * c * (a + c) / (a - c)),
            moreno_osorio: c.map(|c| a > 3.0 * c + 2.0 * c * c / (l * l)),
        }
    }
}

impl std::fmt::Display for GainReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let yn = |b: Option<bool>| match b {
            Some(true) => "met",
            Some(false) => "NOT met",
            None => "unknown (no lipschitz C given)",
        };
        write!(
            f,
            "alpha = {:.6} m/s², lambda = {:.6} m^½/s",
            self.alpha, self.lambda
        )?;
        if let (Some(c), Some(m1), Some(m2)) = (self.lipschitz, self.mu1, self.mu2) {
            write!(f, ", C = {c:.6} m/s² (mu1 = {m1:.4}, mu2 = {m2:.4})")?;
        }
        write!(
            f,
            "; Levant 1998 (alpha > C, lambda² >= 4C(alpha+C)/(alpha-C)): {}; Moreno-Osorio (alpha > 3C + 2C²/lambda²): {}",
            yn(self.levant_1998),
            yn(self.moreno_osorio)
        )
    }
}

impl Discretization {
    pub fn dsp(self) -> zwidth_dsp::Discretization {
        match self {
            Discretization::Explicit => zwidth_dsp::Discretization::Explicit,
            Discretization::Implicit => zwidth_dsp::Discretization::Implicit,
        }
    }
}

impl ImplicitOutput {
    pub fn dsp(self) -> zwidth_dsp::ImplicitOutput {
        match self {
            ImplicitOutput::State => zwidth_dsp::ImplicitOutput::State,
            ImplicitOutput::Eq7 => zwidth_dsp::ImplicitOutput::Eq7,
        }
    }
}

/// The differentiator: `zwidth_dsp::Levant` (one implementation, here and
/// on the rig) with the gains it was built from.
#[derive(Debug, Clone)]
pub struct Levant {
    gains: LevantGains,
    discretization: Discretization,
    t: f64,
    inner: zwidth_dsp::Levant,
}

impl Levant {
    /// Gains already validated (`LevantSpec::gains`); `t` > 0.
    pub fn new(gains: LevantGains, discretization: Discretization, t: f64) -> Self {
        Self {
            gains,
            discretization,
            t,
            inner: zwidth_dsp::Levant::from_validated(
                gains.alpha,
                gains.lambda,
                discretization.dsp(),
                ImplicitOutput::State.dsp(),
                t,
            ),
        }
    }

    /// What the implicit scheme outputs.
    pub fn with_output(self, output: ImplicitOutput) -> Self {
        let g = self.gains;
        Self {
            inner: zwidth_dsp::Levant::from_validated(
                g.alpha,
                g.lambda,
                self.discretization.dsp(),
                output.dsp(),
                self.t,
            ),
            ..self
        }
    }

    pub fn gains(&self) -> LevantGains {
        self.gains
    }

    /// The estimate of the position x and the integrator u1 (m, m/s).
    pub fn state(&self) -> (f64, f64) {
        self.inner.state()
    }
}

impl VelocityEstimator for Levant {
    #[inline]
    fn update(&mut self, y: f64) -> f64 {
        self.inner.step(y)
    }

    fn reset(&mut self) {
        self.inner.reset();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with_gains(alpha: f64, lambda: f64, t: f64, d: Discretization) -> Levant {
        let g = LevantGains {
            alpha,
            lambda,
            lipschitz: None,
        };
        Levant::new(g, d, t)
    }

    fn explicit(alpha: f64, lambda: f64, t: f64) -> Levant {
        with_gains(alpha, lambda, t, Discretization::Explicit)
    }

    #[test]
    fn hand_computed_explicit_steps() {
        // α = 2, λ = 3, T = 0.5. y0 = 0: e = 0 → u = 0; x = 0, u1 = 0.
        // y1 = 1: e = −1, u = 0 + 3·1 = 3; x = 1.5, u1 = 0 + 0.5·2 = 1.
        // y2 = 1: e = 0.5, u = 1 − 3·√0.5 = −1.1213…; x = 1.5 − 0.5606…, u1 = 0.
        let mut l = explicit(2.0, 3.0, 0.5);
        assert_eq!(l.update(0.0), 0.0);
        assert_eq!(l.update(1.0), 3.0);
        let u = l.update(1.0);
        assert!((u - (1.0 - 3.0 * 0.5f64.sqrt())).abs() < 1e-15, "{u}");
        assert!((l.state().0 - (1.5 + 0.5 * u)).abs() < 1e-15);
        assert_eq!(l.state().1, 0.0);
    }

    fn implicit(alpha: f64, lambda: f64, t: f64) -> Levant {
        with_gains(alpha, lambda, t, Discretization::Implicit)
    }

    /// The backward-Euler equations the implicit step must satisfy
    /// (Mojallizadeh, Brogliato & Acary 2021): with e = x_{k+1} − y_{k+1},
    /// x_{k+1} = x_k + T·(u1_{k+1} − λ√|e|·s) and u1_{k+1} = u1_k − Tα·s,
    /// s ∈ Sign(e) (s = sign(e) if e ≠ 0, any value in [−1, 1] if e = 0).
    fn assert_backward_euler(before: (f64, f64), l: &Levant, y: f64) {
        let (x0, u0) = before;
        let (a, lam, t) = (l.gains.alpha, l.gains.lambda, l.t);
        let e = l.state().0 - y;
        let s = (u0 - l.state().1) / (t * a);
        assert!(s.abs() <= 1.0 + 1e-12, "s = {s}");
        if e != 0.0 {
            assert!((s - e.signum()).abs() < 1e-12, "s = {s}, e = {e}");
        }
        let x1 = x0 + t * (l.state().1 - lam * e.abs().sqrt() * s);
        assert!((l.state().0 - x1).abs() < 1e-12, "{} vs {x1}", l.state().0);
    }

    #[test]
    fn hand_computed_implicit_steps_of_both_branches() {
        // α = 2, λ = 3, T = 0.5: the sliding band is T²α = 0.5.
        let mut l = implicit(2.0, 3.0, 0.5);
        assert_eq!(l.update(0.0), 0.0); // x = 0, u1 = 0
                                        // y1 = 1: w = 0 + 0 − 1 = −1, outside the band: s = −1 and
                                        // r = √|e| solves r² + 1.5 r − 0.5 = 0, r = (−1.5 + √4.25)/2;
                                        // u1 = 0 + 0.5·2 = 1; x = 1 − r².
        let before = (l.state().0, l.state().1);
        assert_eq!(l.update(1.0), 1.0);
        let r = (-1.5 + 4.25f64.sqrt()) / 2.0;
        assert!(
            (l.state().0 - (1.0 - r * r)).abs() < 1e-15,
            "{}",
            l.state().0
        );
        assert_backward_euler(before, &l, 1.0);
        // y2 = 1.2: w = (1 − r²) + 0.5 − 1.2 = 0.3 − r² = 0.22116…, inside
        // the band: sliding, s = w/0.5, e = 0, u1 = 1 − 0.5·2·s, x = y2.
        let before = (l.state().0, l.state().1);
        let w = 0.3 - r * r;
        let u = l.update(1.2);
        assert!((u - (1.0 - w / 0.5)).abs() < 1e-15, "{u}");
        assert_eq!(l.state().0, 1.2);
        assert_backward_euler(before, &l, 1.2);
        // y3 = −2: w = 1.2 + 0.5·u − (−2) > 0.5: s = +1, e > 0.
        let before = (l.state().0, l.state().1);
        let u3 = l.update(-2.0);
        assert!((u3 - (u - 1.0)).abs() < 1e-15, "{u3}");
        assert!(l.state().0 > -2.0);
        assert_backward_euler(before, &l, -2.0);
    }

    #[test]
    fn eq7_output_differs_only_while_reaching() {
        // Same steps as `hand_computed_implicit_steps_of_both_branches`:
        // y1 = 1 is reached (e = −r², r = (−1.5 + √4.25)/2), so eq. 7 gives
        // u1 − λ·√|e|·sign(e) = 1 + 3r; y2 = 1.2 slides (e = 0): equal to u1.
        let eq7 = |l: Levant| l.with_output(ImplicitOutput::Eq7);
        let mut a = eq7(implicit(2.0, 3.0, 0.5));
        let mut b = implicit(2.0, 3.0, 0.5);
        assert_eq!(a.update(0.0), 0.0);
        b.update(0.0);
        let r = (-1.5 + 4.25f64.sqrt()) / 2.0;
        let (ua, ub) = (a.update(1.0), b.update(1.0));
        assert_eq!(ub, 1.0);
        assert!((ua - (1.0 + 3.0 * r)).abs() < 1e-15, "{ua}");
        let (ua, ub) = (a.update(1.2), b.update(1.2));
        assert_eq!(ua, ub);
        // The state itself is the same either way.
        assert_eq!(a.state(), b.state());
        // The spec field reaches the estimator; the default is not written out.
        let spec: LevantSpec = serde_json::from_str(
            r#"{"alpha":2,"lambda":3,"discretization":"implicit","implicit_output":"eq7"}"#,
        )
        .unwrap();
        assert_eq!(spec.implicit_output, ImplicitOutput::Eq7);
        let plain: LevantSpec = serde_json::from_str(r#"{"alpha":2,"lambda":3}"#).unwrap();
        assert!(!serde_json::to_string(&plain)
            .unwrap()
            .contains("implicit_output"));
    }

    #[test]
    fn implicit_steps_satisfy_backward_euler_on_a_quantized_sine() {
        // Every step of a long quantized run, both branches many times.
        let c = 0.395;
        let mut l = implicit(6.6 * c, 2.45 * c.sqrt(), 1e-4);
        let (mut sliding, mut outside) = (0, 0);
        for k in 0..30_000 {
            let y =
                (0.01 * (2.0 * std::f64::consts::PI * k as f64 * 1e-4).sin() * 1e6).round() * 1e-6;
            let before = (l.state().0, l.state().1);
            l.update(y);
            if k > 0 {
                assert_backward_euler(before, &l, y);
                if l.state().0 == y {
                    sliding += 1
                } else {
                    outside += 1
                }
            }
        }
        assert!(sliding > 1000 && outside > 100, "{sliding} / {outside}");
    }

    #[test]
    fn quantized_input_beats_plain_differencing_by_a_wide_margin() {
        // 1 µm encoder at 10 kHz, f = 0.01 sin(2π t) m. Differencing
        // independent uniform quantization errors gives an RMS velocity error
        // of d/(T√6) = 4.08e-3 m/s (variance 2·d²/12 over T²). Levant with
        // the 2018 paper's μ1 = 6.6, μ2 = 2.45 must do five times better
        // after the first second (about 11× for implicit, 5.5× explicit);
        // differencing cannot, by construction.
        let (t, d) = (1e-4, 1e-6);
        let c = 0.01 * (2.0 * std::f64::consts::PI).powi(2);
        let floor = d / (t * 6f64.sqrt());
        let spec = |disc| LevantSpec {
            mu1: Some(6.6),
            mu2: Some(2.45),
            lipschitz: Some(c),
            discretization: disc,
            ..Default::default()
        };
        let rms = |est: &mut dyn VelocityEstimator| {
            let (mut sum, mut n) = (0.0, 0);
            for k in 0..30_000 {
                let tk = k as f64 * t;
                let w = 2.0 * std::f64::consts::PI;
                let y = (0.01 * (w * tk).sin() / d).round() * d;
                let v = est.update(y);
                if tk >= 1.0 {
                    sum += (v - 0.01 * w * (w * tk).cos()).powi(2);
                    n += 1;
                }
            }
            (sum / n as f64).sqrt()
        };
        let fdm = rms(&mut crate::estimators::Fdm::new(t));
        assert!((fdm / floor - 1.0).abs() < 0.05, "{fdm} vs {floor}");
        for (disc, bound) in [
            (Discretization::Implicit, floor / 8.0),
            (Discretization::Explicit, floor / 4.0),
        ] {
            let mut l = Levant::new(spec(disc).gains().unwrap(), disc, t);
            let e = rms(&mut l);
            assert!(e < bound, "{disc:?}: RMS {e} m/s, bound {bound}");
        }
    }

    #[test]
    fn implicit_output_does_not_chatter_on_a_ramp() {
        // y = 0.05 t m at 10 kHz, unquantized: the exact derivative is
        // 0.05 m/s. Once sliding, backward Euler stays exactly on it
        // (w = x + T·u1 − y = 0 each step); explicit Euler switches u1 by
        // ±Tα every sample (numerical chattering).
        let t = 1e-4;
        let (a, lam) = (2.0, 1.5);
        let run = |mut l: Levant| {
            let out: Vec<f64> = (0..20_000).map(|k| l.update(0.05 * k as f64 * t)).collect();
            let tail = &out[10_000..];
            let spread = tail.iter().fold(0.0f64, |m, v| m.max((v - 0.05).abs()));
            spread
        };
        let imp = run(implicit(a, lam, t));
        assert!(imp < 1e-12, "implicit: {imp} m/s from 0.05");
        let exp = run(explicit(a, lam, t));
        assert!(exp > 0.5 * t * a, "explicit chatters by ±Tα: {exp}");
    }

    #[test]
    fn sign_of_zero_is_zero() {
        // A constant input keeps e = 0 exactly: no drift from signum(0) = 1.
        let mut l = explicit(10.0, 5.0, 1e-3);
        for _ in 0..10_000 {
            assert_eq!(l.update(0.25), 0.0);
        }
    }

    #[test]
    fn converges_to_the_exact_derivative() {
        // f = 0.01 sin(2π t) m: |f''| ≤ 0.01(2π)² ≈ 0.395 = C. Unquantized at
        // 100 kHz, after 1 s both discretizations track f' = 0.02π cos(2πt)
        // to within a few tenths of a percent of its amplitude (0.0628 m/s).
        let c = 0.01 * (2.0 * std::f64::consts::PI).powi(2);
        for disc in [Discretization::Explicit, Discretization::Implicit] {
            let spec = LevantSpec {
                mu1: Some(6.6),
                mu2: Some(2.45),
                lipschitz: Some(c),
                discretization: disc,
                ..Default::default()
            };
            let mut l = Levant::new(spec.gains().unwrap(), disc, 1e-5);
            let mut worst: f64 = 0.0;
            for k in 0..200_000 {
                let t = k as f64 * 1e-5;
                let v = l.update(0.01 * (2.0 * std::f64::consts::PI * t).sin());
                if t > 1.0 {
                    let exact =
                        0.02 * std::f64::consts::PI * (2.0 * std::f64::consts::PI * t).cos();
                    worst = worst.max((v - exact).abs());
                }
            }
            assert!(worst < 2e-4, "{disc:?}: worst error {worst} m/s");
        }
    }

    #[test]
    fn rule_gains_and_reports() {
        // 2011 paper §2.4: C = 1.2e4 mm/s² = 12 m/s² gives α = 13.2 m/s²,
        // λ = 109.54 mm^½/s = 109.54·√(1e-3) = 3.464 m^½/s.
        let spec = LevantSpec {
            rule: Some(GainRule::HbaSc),
            lipschitz: Some(12.0),
            ..Default::default()
        };
        let g = spec.gains().unwrap();
        assert!((g.alpha - 13.2).abs() < 1e-12);
        // (The paper prints λ rounded to 109.54; √12000 = 109.5445.)
        assert!((g.lambda - 109.54 * 1e-3f64.sqrt()).abs() < 1e-3);
        // DESIGN.md / 2018 paper §III: the special case meets neither condition.
        let r = g.report();
        assert_eq!((r.levant_1998, r.moreno_osorio), (Some(false), Some(false)));
        // The 2018 paper's tuned μ1 = 6.6, μ2 = 2.45 meet both:
        // 2.45² = 6.0025 ≥ 4·7.6/5.6 = 5.43; 6.6 > 3 + 2/6.0025 = 3.33.
        let r = LevantGains {
            alpha: 6.6 * 12.0,
            lambda: 2.45 * 12f64.sqrt(),
            lipschitz: Some(12.0),
        }
        .report();
        assert_eq!((r.levant_1998, r.moreno_osorio), (Some(true), Some(true)));
        for (rule, want) in [
            (GainRule::Hba, (Some(true), Some(false))),
            (GainRule::Lfba, (Some(false), Some(true))),
        ] {
            let spec = LevantSpec {
                rule: Some(rule),
                lipschitz: Some(3.0),
                ..Default::default()
            };
            let r = spec.gains().unwrap().report();
            assert_eq!((r.levant_1998, r.moreno_osorio), want, "{rule:?}");
        }
        // Without C the conditions cannot be judged.
        assert_eq!(explicit(1.0, 1.0, 1.0).gains().report().levant_1998, None);
        // The rules' normalized gains as their definitions give them
        // (2018 eqs. 10, 11, 14 with a 10 % margin): hba_sc (1.1, 1),
        // hba (2, √13.2), lfba (1.1·(3 + 2/2²), 2) = (3.85, 2).
        assert_eq!(GainRule::HbaSc.normalized(), (1.1, 1.0));
        let (h1, h2) = GainRule::Hba.normalized();
        assert!(
            h1 == 2.0 && (h2 - 13.2f64.sqrt()).abs() < 1e-12,
            "{h1} {h2}"
        );
        let (m1, m2) = GainRule::Lfba.normalized();
        assert!((m1 - 3.85).abs() < 1e-12 && m2 == 2.0, "{m1} {m2}");
        // The report's μ's invert α = μ1·C, λ = μ2·√C: α = 13.2, λ = 3.46,
        // C = 12 give μ1 = 1.1 and μ2 = 3.46/√12 = 0.99882.
        let r = LevantGains {
            alpha: 13.2,
            lambda: 3.46,
            lipschitz: Some(12.0),
        }
        .report();
        assert!((r.mu1.unwrap() - 1.1).abs() < 1e-12, "{:?}", r.mu1);
        assert!((r.mu2.unwrap() - 0.998_815).abs() < 1e-6, "{:?}", r.mu2);
        // Moreno–Osorio's bound 3C + 2C²/λ² at C = 12, λ = 1 is 36 + 288 =
        // 324: α = 100 misses it (the C² term decides), α = 325 meets it.
        for (alpha, want) in [(100.0, Some(false)), (325.0, Some(true))] {
            let r = LevantGains {
                alpha,
                lambda: 1.0,
                lipschitz: Some(12.0),
            }
            .report();
            assert_eq!(r.moreno_osorio, want, "α = {alpha}");
        }
        // A rule spec's label names the rule and C.
        let spec = LevantSpec {
            rule: Some(GainRule::Hba),
            lipschitz: Some(12.0),
            ..Default::default()
        };
        assert!(spec.label().contains("hba, C=12"), "{}", spec.label());
        // Without C (refused by validation, but labels are shown earlier).
        let spec = LevantSpec {
            rule: Some(GainRule::Hba),
            ..Default::default()
        };
        assert_eq!(spec.label(), "hba, C=unset");
        let spec = LevantSpec {
            mu1: Some(1.5),
            ..Default::default()
        };
        assert_eq!(spec.label(), "mu1=1.5, mu2=unset, C=unset");
    }

    #[test]
    fn gain_form_errors() {
        let bad = |s: LevantSpec| s.gains().unwrap_err().field;
        assert_eq!(bad(LevantSpec::default()), "levant");
        assert_eq!(
            bad(LevantSpec {
                alpha: Some(1.0),
                rule: Some(GainRule::Hba),
                ..Default::default()
            }),
            "levant"
        );
        assert_eq!(
            bad(LevantSpec {
                mu1: Some(1.0),
                mu2: Some(1.0),
                ..Default::default()
            }),
            "lipschitz"
        );
        assert_eq!(
            bad(LevantSpec {
                alpha: Some(-1.0),
                lambda: Some(1.0),
                ..Default::default()
            }),
            "alpha"
        );
    }
}
