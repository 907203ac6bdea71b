//! The scene: device, control loop, estimator, wall, hit protocol and probe —
//! one serde document (field names are a contract). Everything optional
//! defaults to the seeds' values; `SceneSpec::validate` checks every field
//! once and returns a [`Scene`] the engines trust.

use serde::{Deserialize, Serialize};

use crate::error::{require_non_negative, require_positive, require_range, SpecError};
use crate::estimators::{Estimator, EstimatorKind, EstimatorSpec, Sampling};

mod device;
use device::validate_friction;
pub use device::{
    DeviceSpec, EncoderSide, FrictionSide, FrictionSpec, TransmissionSpec, MAX_FRICTION_SUBSTEPS,
};

/// The encoder step the estimators are built for when the scene's sensor is
/// ideal (`quantization: 0`): Kalman needs `r = d²/3 > 0`. 1 nm is finer than
/// any encoder the papers consider.
pub const IDEAL_SENSOR_ESTIMATOR_STEP: f64 = 1e-9;

/// Most excited lines a probe may have.
pub const MAX_PROBE_LINES: usize = 1000;
/// Fastest loop whose amplifier lag or transmission the analytic engine
/// answers: its pulse transfer function's coefficients (3 to 5 poles near
/// z = 1) lose digits as the rate grows (an independent check: G_d wrong by
/// 3e-7 at 10 kHz, 1.2e-2 at 100 kHz); above it the simulations answer.
pub const MAX_ANALYTIC_DRIVE_HZ: f64 = 20_000.0;
/// Most simulation steps in one probe period (memory: one f64 per step, twice).
pub const MAX_PROBE_PERIOD_STEPS: usize = 4_000_000;

/// The control loop (2011 paper §2.3: encoder and estimators at 10 kHz, wall
/// rendered at 1 kHz).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct LoopSpec {
    /// Rate the encoder is read and the estimator runs (Hz).
    #[serde(default = "d_sample_hz")]
    pub sample_hz: f64,
    /// Rate the wall force is computed and held, zero-order (Hz); divides `sample_hz`.
    #[serde(default = "d_render_hz")]
    pub render_hz: f64,
    /// Extra whole render periods between reading and applying the force.
    #[serde(default)]
    pub delay_samples: u32,
}

fn d_sample_hz() -> f64 {
    10_000.0
}
fn d_render_hz() -> f64 {
    1_000.0
}

impl Default for LoopSpec {
    fn default() -> Self {
        Self {
            sample_hz: d_sample_hz(),
            render_hz: d_render_hz(),
            delay_samples: 0,
        }
    }
}

/// The virtual wall's location (m); it pushes back on the handle when the
/// measured position is past it (2011 paper eq. 12).
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct WallSpec {
    #[serde(default)]
    pub position: f64,
}

/// The wall-hit protocol (2011 paper §2.4).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct HitSpec {
    /// Start this far before the wall (m).
    #[serde(default = "d_home")]
    pub home_distance: f64,
    /// Constant motor force driving the handle into the wall (N).
    #[serde(default = "d_push")]
    pub push_force: f64,
    /// Wait this long before measuring (s).
    #[serde(default = "d_settle")]
    pub settle_s: f64,
    /// Measure the RMS about the mean position over this long (s).
    #[serde(default = "d_measure")]
    pub measure_s: f64,
    /// Stable iff that RMS is below this (m); 1.06e-4 mm in the paper.
    #[serde(default = "d_threshold")]
    pub threshold: f64,
    /// Hits per verdict (1–32): replicate r starts `r/R` of an encoder step
    /// (1 µm with an ideal sensor) farther from the wall, so the hits see
    /// the quantization grid and the approach at different phases. With
    /// more than one the verdict is the majority (a tie is unstable),
    /// decided only when every hit agrees, and the map's boundary carries
    /// intervals (`search.rs`). 1, the default, is the paper's single hit.
    #[serde(default = "d_replicates", skip_serializing_if = "is_one")]
    pub replicates: u32,
}

/// Most hits per time-domain verdict (`hit.replicates`).
pub const MAX_HIT_REPLICATES: u32 = 32;

fn d_replicates() -> u32 {
    1
}
fn is_one(n: &u32) -> bool {
    *n == 1
}

fn d_home() -> f64 {
    0.07
}
fn d_push() -> f64 {
    0.3572
}
fn d_settle() -> f64 {
    4.0
}
fn d_measure() -> f64 {
    2.0
}
fn d_threshold() -> f64 {
    1.06e-7
}

impl Default for HitSpec {
    fn default() -> Self {
        Self {
            home_distance: d_home(),
            push_force: d_push(),
            settle_s: d_settle(),
            measure_s: d_measure(),
            threshold: d_threshold(),
            replicates: d_replicates(),
        }
    }
}

/// The multisine impedance probe (2018 paper §V). Defaults are ours: the
/// band 1–100 Hz covers the device's 30 Hz bandwidth and the paper's Fig. 6;
/// 0.5 N peak stays well inside the 4 N motor; 4 averaged periods.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct ProbeSpec {
    /// Lowest excited line and line spacing (Hz); one period is 1/f_min s.
    #[serde(default = "d_fmin")]
    pub f_min_hz: f64,
    /// Highest excited line (Hz), below the render Nyquist frequency.
    #[serde(default = "d_fmax")]
    pub f_max_hz: f64,
    /// Peak force of the multisine (N).
    #[serde(default = "d_amp")]
    pub amplitude: f64,
    /// Periods averaged once the response is periodic; on a noisy scene,
    /// the steady-state periods of each random-phase realization.
    #[serde(default = "d_periods")]
    pub periods: u32,
    /// Noisy scenes (friction, quantization): the confidence of a decided
    /// verdict, 1 − the error rate of each kind (passive called not
    /// passive, and the reverse); see docs/zwidth.md.
    #[serde(default = "d_confidence")]
    pub confidence: f64,
    /// Noisy scenes: seed of the random-phase realizations. Maps with the
    /// same seed see the same realizations (common random numbers), so a
    /// difference between them is their parameters', not the noise's.
    #[serde(default = "d_seed")]
    pub seed: u64,
    /// Noisy scenes: how a point is judged. `bla` (default): the best
    /// linear approximation from random-phase realizations, with a stated
    /// confidence (docs/zwidth.md). `tfestimate`: the 2018 paper's own
    /// method, the baseline: one Schroeder multisine record, a Welch
    /// estimate of the admittance, passive iff Re Z ≥ 0 on every line; no
    /// confidence and no intervals. Linear scenes use neither (exact).
    #[serde(default, skip_serializing_if = "ProbeMethod::is_bla")]
    pub method: ProbeMethod,
}

/// How a noisy scene's point is judged (`ProbeSpec::method`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProbeMethod {
    #[default]
    Bla,
    Tfestimate,
}

impl ProbeMethod {
    fn is_bla(&self) -> bool {
        *self == Self::Bla
    }
}

fn d_confidence() -> f64 {
    0.95
}
fn d_seed() -> u64 {
    1
}

fn d_fmin() -> f64 {
    1.0
}
fn d_fmax() -> f64 {
    100.0
}
fn d_amp() -> f64 {
    0.5
}
fn d_periods() -> u32 {
    4
}

impl Default for ProbeSpec {
    fn default() -> Self {
        Self {
            f_min_hz: d_fmin(),
            f_max_hz: d_fmax(),
            amplitude: d_amp(),
            periods: d_periods(),
            confidence: d_confidence(),
            seed: d_seed(),
            method: ProbeMethod::Bla,
        }
    }
}

fn d_estimator() -> EstimatorSpec {
    EstimatorKind::Fdm {}.into()
}

/// The whole scene document.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
#[serde(deny_unknown_fields)]
pub struct SceneSpec {
    #[serde(default)]
    pub device: DeviceSpec,
    #[serde(default, rename = "loop")]
    pub control: LoopSpec,
    #[serde(default = "d_estimator")]
    pub estimator: EstimatorSpec,
    #[serde(default)]
    pub wall: WallSpec,
    #[serde(default)]
    pub hit: HitSpec,
    #[serde(default)]
    pub probe: ProbeSpec,
}

impl Default for SceneSpec {
    fn default() -> Self {
        Self {
            device: DeviceSpec::default(),
            control: LoopSpec::default(),
            estimator: d_estimator(),
            wall: WallSpec::default(),
            hit: HitSpec::default(),
            probe: ProbeSpec::default(),
        }
    }
}

/// A validated scene. Fields are public for reading; build one only through
/// [`SceneSpec::validate`].
#[derive(Debug, Clone)]
pub struct Scene {
    pub spec: SceneSpec,
    /// Encoder samples per render period.
    pub ratio: usize,
    /// Sample period (s) and render period (s).
    pub dt: f64,
    pub render_dt: f64,
    /// What the estimator is built for.
    pub sampling: Sampling,
}

fn is_whole(x: f64) -> bool {
    (x - x.round()).abs() <= 1e-9 * x.abs().max(1.0)
}

impl SceneSpec {
    pub fn from_json(text: &str) -> Result<Self, SpecError> {
        crate::error::parse_json(text, "scene", "scene")
    }

    pub fn validate(&self) -> Result<Scene, SpecError> {
        let d = &self.device;
        let dev = |e: SpecError| e.within("device");
        require_positive("mass", d.mass, "kg").map_err(dev)?;
        if d.mass > 1e4 {
            return Err(SpecError::new(
                "device.mass",
                d.mass,
                "must be at most 1e4 kg",
            ));
        }
        require_non_negative("damping", d.damping, "N·s/m").map_err(dev)?;
        require_non_negative("coulomb", d.coulomb, "N").map_err(dev)?;
        require_non_negative("quantization", d.quantization, "m; 0 is an ideal sensor")
            .map_err(dev)?;
        if d.quantization > 0.01 {
            return Err(SpecError::new(
                "device.quantization",
                d.quantization,
                "must be at most 0.01 m",
            ));
        }
        if let Some(f) = d.force_limit {
            require_positive("force_limit", f, "N, or null for none").map_err(dev)?;
        }
        if let Some(r) = d.force_resolution {
            require_range(
                "force_resolution",
                r,
                1e-9,
                100.0,
                "N, the force command's step, or null for none",
            )
            .map_err(dev)?;
            if let Some(f) = d.force_limit {
                if r > f {
                    return Err(SpecError::new(
                        "device.force_resolution",
                        r,
                        format!("must not exceed device.force_limit = {f} N (the command would always round to 0)"),
                    ));
                }
            }
        }
        let l = &self.control;
        let lp = |e: SpecError| e.within("loop");
        require_positive("sample_hz", l.sample_hz, "Hz").map_err(lp)?;
        if !(10.0..=1e7).contains(&l.sample_hz) {
            return Err(SpecError::new(
                "loop.sample_hz",
                l.sample_hz,
                "must be 10 Hz to 10 MHz",
            ));
        }
        require_positive("render_hz", l.render_hz, "Hz").map_err(lp)?;
        let ratio = l.sample_hz / l.render_hz;
        if l.render_hz > l.sample_hz || !is_whole(ratio) {
            return Err(SpecError::new(
                "loop.render_hz",
                l.render_hz,
                format!(
                    "must divide loop.sample_hz = {} Hz a whole number of times",
                    l.sample_hz
                ),
            ));
        }
        if l.delay_samples > 100 {
            return Err(SpecError::new(
                "loop.delay_samples",
                l.delay_samples,
                "must be 0 to 100 render periods",
            ));
        }
        if let Some(t) = &d.transmission {
            let tp = |e: SpecError| e.within("device.transmission");
            require_range("motor_mass", t.motor_mass, 1e-6, 1e4, "kg").map_err(tp)?;
            require_non_negative("motor_damping", t.motor_damping, "N·s/m").map_err(tp)?;
            require_range("stiffness", t.stiffness, 1.0, 1e8, "N/m").map_err(tp)?;
            require_non_negative("damping", t.damping, "N·s/m").map_err(tp)?;
            if d.coulomb > 0.0 && d.friction.is_none() {
                return Err(SpecError::new(
                    "device.coulomb",
                    d.coulomb,
                    "must be 0 with a transmission unless device.friction names a LuGre model (ideal stick–slip is modelled on the rigid device only)",
                ));
            }
        }
        if let Some(f) = &d.friction {
            validate_friction(d, f, l.sample_hz)?;
        }
        if let Some(fa) = d.amplifier_hz {
            let nyq = l.sample_hz / 2.0;
            if !(fa.is_finite() && fa > 0.0 && fa <= nyq) {
                return Err(SpecError::new(
                    "device.amplifier_hz",
                    fa,
                    format!("must be a bandwidth > 0 Hz and at most the Nyquist frequency of loop.sample_hz, {nyq} Hz (null for an ideal amplifier)"),
                ));
            }
        }
        let h = &self.hit;
        let hp = |e: SpecError| e.within("hit");
        require_non_negative("home_distance", h.home_distance, "m").map_err(hp)?;
        if !(1..=MAX_HIT_REPLICATES).contains(&h.replicates) {
            return Err(SpecError::new(
                "hit.replicates",
                h.replicates,
                format!("must be 1 to {MAX_HIT_REPLICATES} hits per verdict"),
            ));
        }
        if !h.push_force.is_finite() {
            return Err(SpecError::new(
                "hit.push_force",
                h.push_force,
                "must be a finite force (N)",
            ));
        }
        require_positive("settle_s", h.settle_s, "s").map_err(hp)?;
        require_positive("measure_s", h.measure_s, "s").map_err(hp)?;
        require_positive("threshold", h.threshold, "m").map_err(hp)?;
        if h.settle_s + h.measure_s > 3600.0 {
            return Err(SpecError::new(
                "hit.settle_s",
                h.settle_s,
                "settle_s + measure_s must be at most 3600 s",
            ));
        }
        if (h.settle_s + h.measure_s) * l.sample_hz * f64::from(h.replicates) > 1e9 {
            return Err(SpecError::new(
                "hit.measure_s",
                h.measure_s,
                "a trial may have at most 1e9 samples (over its hit.replicates hits)",
            ));
        }
        let p = &self.probe;
        let pp = |e: SpecError| e.within("probe");
        require_positive("f_min_hz", p.f_min_hz, "Hz").map_err(pp)?;
        let nyq = l.render_hz / 2.0;
        if !(p.f_max_hz.is_finite() && p.f_max_hz > p.f_min_hz && p.f_max_hz < nyq) {
            return Err(SpecError::new(
                "probe.f_max_hz",
                p.f_max_hz,
                format!("must be above f_min_hz = {} Hz and below the render Nyquist frequency {nyq} Hz", p.f_min_hz),
            ));
        }
        if !is_whole(l.sample_hz / p.f_min_hz) {
            return Err(SpecError::new(
                "probe.f_min_hz",
                p.f_min_hz,
                format!("one period (1/f_min_hz) must be a whole number of samples at loop.sample_hz = {} Hz", l.sample_hz),
            ));
        }
        if p.f_max_hz / p.f_min_hz > MAX_PROBE_LINES as f64 {
            return Err(SpecError::new(
                "probe.f_max_hz",
                p.f_max_hz,
                format!("at most {MAX_PROBE_LINES} lines (f_max_hz / f_min_hz)"),
            ));
        }
        let per_period = l.sample_hz / p.f_min_hz * probe_substeps(p.f_max_hz, l.sample_hz) as f64;
        if per_period > MAX_PROBE_PERIOD_STEPS as f64 {
            return Err(SpecError::new(
                "probe.f_min_hz",
                p.f_min_hz,
                format!(
                    "one probe period would be {per_period:.0} simulation steps; at most {MAX_PROBE_PERIOD_STEPS} (raise f_min_hz or lower loop.sample_hz)"
                ),
            ));
        }
        require_positive("amplitude", p.amplitude, "N").map_err(pp)?;
        if let Some(limit) = d.force_limit {
            if p.amplitude > limit {
                return Err(SpecError::new(
                    "probe.amplitude",
                    p.amplitude,
                    format!("must not exceed device.force_limit = {limit} N"),
                ));
            }
        }
        if !(p.confidence > 0.0 && p.confidence < 1.0) {
            return Err(SpecError::new(
                "probe.confidence",
                p.confidence,
                "must be between 0 and 1 (exclusive), e.g. 0.95",
            ));
        }
        if !(1..=1000).contains(&p.periods) {
            return Err(SpecError::new(
                "probe.periods",
                p.periods,
                "must be 1 to 1000",
            ));
        }
        let step = if d.quantization > 0.0 {
            d.quantization
        } else {
            IDEAL_SENSOR_ESTIMATOR_STEP
        };
        let sampling = Sampling::new(l.sample_hz, step)?;
        self.estimator
            .build(sampling)
            .map_err(|e| e.within("estimator"))?;
        Ok(Scene {
            spec: self.clone(),
            ratio: ratio.round() as usize,
            dt: 1.0 / l.sample_hz,
            render_dt: 1.0 / l.render_hz,
            sampling,
        })
    }
}

impl SceneSpec {
    /// This scene with the number at `path` (dot-separated JSON names, e.g.
    /// `estimator.cutoff_hz`, `device.damping`, `loop.sample_hz`) set to
    /// `value`, then validated like any scene. `field` names the request
    /// field to blame (e.g. `parameter.path`). The leaf need not be present
    /// (optional fields), but its parent object must be.
    pub fn with_number(&self, path: &str, value: f64, field: &str) -> Result<SceneSpec, SpecError> {
        self.with_numbers(&[(path, value)], &[], field)
    }

    /// The same for several numbers at once, after removing the `remove`
    /// paths (e.g. one gain form replaced by another).
    pub fn with_numbers(
        &self,
        set: &[(&str, f64)],
        remove: &[&str],
        field: &str,
    ) -> Result<SceneSpec, SpecError> {
        let mut doc = serde_json::to_value(self)
            .map_err(|e| SpecError::new(field, "(scene)", e.to_string()))?;
        for path in remove {
            let (parent, leaf) = path.rsplit_once('.').unwrap_or(("", path));
            if let Some(obj) = lookup(&mut doc, parent).and_then(|n| n.as_object_mut()) {
                obj.remove(leaf);
            }
        }
        for &(path, value) in set {
            let unknown = || {
                SpecError::new(
                    field,
                    format!("{path:?}"),
                    "must name a number in the scene, e.g. \"estimator.cutoff_hz\" or \"device.damping\"",
                )
            };
            if !value.is_finite() {
                return Err(SpecError::new(path, value, "must be a finite number"));
            }
            let (parent, leaf) = path.rsplit_once('.').unwrap_or(("", path));
            let obj = lookup(&mut doc, parent)
                .and_then(|n| n.as_object_mut())
                .ok_or_else(unknown)?;
            if leaf.is_empty()
                || obj
                    .get(leaf)
                    .is_some_and(|v| !v.is_number() && !v.is_null())
            {
                return Err(unknown());
            }
            // Whole numbers as integers, so counts (orders, windows) read back.
            let number = if value.fract() == 0.0 && value.abs() < 9e15 {
                serde_json::Value::from(value as i64)
            } else {
                serde_json::Value::from(value)
            };
            obj.insert(leaf.to_string(), number);
        }
        let spec: SceneSpec = serde_json::from_value(doc).map_err(|e| {
            let paths: Vec<&str> = set.iter().map(|(p, _)| *p).collect();
            SpecError::new(
                field,
                format!("{paths:?}"),
                format!("cannot be set on this scene: {e}"),
            )
        })?;
        spec.validate().map_err(|e| e.within("scene"))?;
        Ok(spec)
    }
}

/// The JSON node at a dot-separated path ("" is the root).
fn lookup<'a>(doc: &'a mut serde_json::Value, path: &str) -> Option<&'a mut serde_json::Value> {
    let mut node = doc;
    for name in path.split('.').filter(|n| !n.is_empty()) {
        node = node.get_mut(name)?;
    }
    Some(node)
}

impl Scene {
    /// A fresh estimator (validated at scene construction, so this cannot fail).
    pub fn estimator(&self) -> Estimator {
        self.spec
            .estimator
            .build(self.sampling)
            .expect("validated with the scene")
    }

    /// The same scene with another estimator (validated).
    pub fn with_estimator(&self, e: EstimatorSpec) -> Result<Scene, SpecError> {
        SceneSpec {
            estimator: e,
            ..self.spec.clone()
        }
        .validate()
    }

    /// Single-rate, no quantization, no friction, no saturation, and a linear
    /// estimator: the analytic engine is exact for it. (Also: an amplifier
    /// lag or a transmission only up to `MAX_ANALYTIC_DRIVE_HZ`.)
    pub fn linear_reason(&self) -> Option<String> {
        let d = &self.spec.device;
        let e = &self.spec.estimator;
        let rate = self.spec.control.sample_hz;
        if (d.amplifier_hz.is_some() || d.transmission.is_some()) && rate > MAX_ANALYTIC_DRIVE_HZ {
            return Some(format!(
                "an amplifier lag or a transmission at {rate} Hz, above {MAX_ANALYTIC_DRIVE_HZ} Hz (every pole of its pulse transfer function sits near z = 1, and the polynomial's coefficients lose the digits the verdict needs)"
            ));
        }
        if self.ratio != 1 {
            return Some(format!(
                "multi-rate loop (sample_hz/render_hz = {})",
                self.ratio
            ));
        }
        if d.quantization > 0.0 {
            return Some("quantization".into());
        }
        if d.coulomb > 0.0 {
            return Some("Coulomb friction".into());
        }
        if d.force_limit.is_some() {
            return Some("force saturation".into());
        }
        if d.force_resolution.is_some() {
            return Some("force command resolution".into());
        }
        if e.median_position.is_some() || e.median_velocity.is_some() {
            return Some("median smoothing".into());
        }
        match e.kind {
            EstimatorKind::Fdm {}
            | EstimatorKind::Butterworth { .. }
            | EstimatorKind::Kalman { .. } => None,
            _ => Some("a nonlinear or adaptive estimator".into()),
        }
    }

    pub fn is_linear(&self) -> bool {
        self.linear_reason().is_none()
    }
}

/// Substeps of the probe's excitation grid per encoder sample: at least 40
/// per period of the highest line.
pub fn probe_substeps(f_max_hz: f64, sample_hz: f64) -> usize {
    (40.0 * f_max_hz / sample_hz).ceil().max(1.0) as usize
}

/// Check a wall's stiffness K (N/m) and damping B (N·s/m).
pub fn validate_wall(k: f64, b: f64) -> Result<(), SpecError> {
    if !(k.is_finite() && (0.0..=1e9).contains(&k)) {
        return Err(SpecError::new(
            "k",
            k,
            "wall stiffness must be 0 to 1e9 N/m",
        ));
    }
    if !(b.is_finite() && b.abs() <= 1e7) {
        return Err(SpecError::new(
            "b",
            b,
            "wall damping must be finite, |B| <= 1e7 N·s/m",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quantization_up_to_a_centimetre_and_numbers_only_where_numbers_are() {
        let with_q = |q: f64| {
            let mut s = SceneSpec::default();
            s.device.quantization = q;
            s.validate().map(|_| ()).map_err(|e| e.field)
        };
        // The documented bound is "at most 0.01 m": 0.01 itself is allowed.
        assert_eq!(with_q(0.01), Ok(()));
        assert_eq!(with_q(0.010_000_1), Err("device.quantization".into()));
        // A number cannot replace a non-number (the estimator's kind).
        let e = SceneSpec::default()
            .with_number("estimator.kind", 1.0, "params")
            .unwrap_err();
        assert!(
            e.field == "params" && e.value.contains("estimator.kind"),
            "{e}"
        );
        assert!(
            e.allowed.starts_with("must name a number in the scene"),
            "{e}"
        );
    }

    #[test]
    fn issue_example_parses_and_defaults_fill_in() {
        let json = r#"{
          "device":   {"mass": 0.52, "damping": 13.2, "coulomb": 0.19, "quantization": 1e-6, "force_limit": null},
          "loop":     {"sample_hz": 10000, "render_hz": 1000, "delay_samples": 0},
          "estimator": {"kind": "fdm"},
          "wall":     {"position": 0.0},
          "hit":      {"home_distance": 0.07, "push_force": 0.3572, "settle_s": 4, "measure_s": 2, "threshold": 1.06e-7},
          "probe":    {"f_min_hz": 1, "f_max_hz": 100, "amplitude": 0.5, "periods": 4}
        }"#;
        let s = SceneSpec::from_json(json).unwrap();
        assert_eq!(s, SceneSpec::default());
        assert_eq!(SceneSpec::from_json("{}").unwrap(), SceneSpec::default());
        let partial = SceneSpec::from_json(r#"{"device":{"coulomb":0}}"#).unwrap();
        assert_eq!(partial.device.mass, 0.52);
        let sc = s.validate().unwrap();
        assert_eq!(sc.ratio, 10);
        assert!(!sc.is_linear());
    }

    #[test]
    fn errors_name_the_field() {
        let bad = |j: &str| match SceneSpec::from_json(j) {
            Err(e) => e.to_string(),
            Ok(s) => s
                .validate()
                .err()
                .map(|e| e.to_string())
                .unwrap_or_default(),
        };
        assert!(bad(r#"{"device":{"mass":0}}"#).contains("device.mass = 0"));
        // Parse errors name the field too (serde's path).
        let e = bad(r#"{"probe":{"method":"welch"}}"#);
        assert!(e.starts_with("scene.probe.method = "), "{e}");
        assert!(
            e.contains("unknown variant `welch`, expected `bla` or `tfestimate`"),
            "{e}"
        );
        assert!(bad(r#"{"device":{"mass":"heavy"}}"#).starts_with("scene.device.mass = "));
        assert!(bad(r#"{"device":{"mass":1}} x"#).starts_with("scene = (document)"));
        // At most 1e9 samples a trial: 999 + 1 s at 1 MHz is exactly that.
        let fast = |settle: f64| {
            format!(
                r#"{{"loop":{{"sample_hz":1e6,"render_hz":1000}},"hit":{{"settle_s":{settle},"measure_s":1}}}}"#
            )
        };
        assert_eq!(bad(&fast(999.0)), "");
        let e = bad(&fast(999.5));
        assert!(
            e.contains("hit.measure_s = 1") && e.contains("1e9 samples"),
            "{e}"
        );
        assert!(bad(r#"{"device":{"damping":-1}}"#).contains("device.damping = -1"));
        assert!(bad(r#"{"loop":{"sample_hz":10000,"render_hz":3000}}"#)
            .contains("loop.render_hz = 3000"));
        assert!(bad(r#"{"probe":{"f_max_hz":600}}"#).contains("probe.f_max_hz = 600"));
        assert!(bad(r#"{"probe":{"f_min_hz":3}}"#).contains("probe.f_min_hz = 3"));
        for c in ["0", "1", "-0.5", "1.5"] {
            let e = bad(&format!(r#"{{"probe":{{"confidence":{c}}}}}"#));
            assert!(
                e.contains(&format!("probe.confidence = {c}")) && e.contains("between 0 and 1"),
                "{e}"
            );
        }
        let e = bad(r#"{"device":{"force_limit":0.4},"probe":{"amplitude":0.5}}"#);
        assert!(
            e.contains("probe.amplitude = 0.5") && e.contains("force_limit = 0.4"),
            "{e}"
        );
        assert!(bad(r#"{"probe":{"amplitude":0}}"#).contains("probe.amplitude"));
        assert!(
            bad(r#"{"estimator":{"kind":"butterworth","cutoff_hz":6000}}"#)
                .contains("estimator.cutoff_hz = 6000")
        );
        assert!(bad(r#"{"devise":{}}"#).contains("devise"));
        assert!(bad(r#"{"hit":{"threshold":0}}"#).contains("hit.threshold = 0"));
        assert!(validate_wall(-1.0, 0.0).is_err() && validate_wall(1.0, f64::NAN).is_err());
    }

    /// The scene's field that fails, or "" when it is valid.
    fn failing(json: &str) -> String {
        match SceneSpec::from_json(json).unwrap().validate() {
            Ok(_) => String::new(),
            Err(e) => e.field,
        }
    }

    #[test]
    fn each_documented_limit_is_inclusive() {
        // Each limit's own value is allowed, the next value out is not (the
        // bounds the messages state).
        let one_khz = r#""loop":{"sample_hz":1000,"render_hz":1000"#;
        for (ok, bad, field) in [
            (r#"{"device":{"mass":1e4}}"#.to_string(), r#"{"device":{"mass":1.0001e4}}"#.to_string(), "device.mass"),
            (
                r#"{"device":{"force_limit":1,"force_resolution":1},"probe":{"amplitude":1}}"#.into(),
                r#"{"device":{"force_limit":1,"force_resolution":1.01},"probe":{"amplitude":1}}"#.into(),
                "device.force_resolution",
            ),
            (r#"{"loop":{"delay_samples":100}}"#.into(), r#"{"loop":{"delay_samples":101}}"#.into(), "loop.delay_samples"),
            (
                r#"{"device":{"force_limit":0.5},"probe":{"amplitude":0.5}}"#.into(),
                r#"{"device":{"force_limit":0.5},"probe":{"amplitude":0.51}}"#.into(),
                "probe.amplitude",
            ),
            (
                r#"{"hit":{"settle_s":3000,"measure_s":600}}"#.into(),
                r#"{"hit":{"settle_s":3000,"measure_s":601}}"#.into(),
                "hit.settle_s",
            ),
            // The probe's highest line below the render Nyquist (500 Hz here).
            (
                format!(r#"{{{one_khz}}},"probe":{{"f_max_hz":499}}}}"#),
                format!(r#"{{{one_khz}}},"probe":{{"f_max_hz":500}}}}"#),
                "probe.f_max_hz",
            ),
            // At most MAX_PROBE_LINES = 1000 lines, f_max / f_min.
            (
                r#"{"loop":{"sample_hz":10000,"render_hz":10000},"probe":{"f_min_hz":2,"f_max_hz":2000}}"#.into(),
                r#"{"loop":{"sample_hz":10000,"render_hz":10000},"probe":{"f_min_hz":2,"f_max_hz":2002}}"#.into(),
                "probe.f_max_hz",
            ),
            // One probe period at most MAX_PROBE_PERIOD_STEPS = 4e6 steps:
            // 2 MHz / 0.5 Hz with one substep (40·100/2e6 < 1) is exactly 4e6.
            (
                r#"{"loop":{"sample_hz":2e6,"render_hz":1000},"probe":{"f_min_hz":0.5,"f_max_hz":100}}"#.into(),
                r#"{"loop":{"sample_hz":2e6,"render_hz":1000},"probe":{"f_min_hz":0.25,"f_max_hz":100}}"#.into(),
                "probe.f_min_hz",
            ),
        ] {
            assert_eq!(failing(&ok), "", "{ok}");
            assert_eq!(failing(&bad), field, "{bad}");
        }
        // An amplifier bandwidth at most the encoder's Nyquist frequency.
        assert_eq!(failing(r#"{"device":{"amplifier_hz":5000}}"#), "");
        assert_eq!(
            failing(r#"{"device":{"amplifier_hz":5001}}"#),
            "device.amplifier_hz"
        );
        assert_eq!(
            failing(
                r#"{"device":{"amplifier_hz":500},"loop":{"sample_hz":1000,"render_hz":1000}}"#
            ),
            ""
        );
        assert_eq!(
            failing(
                r#"{"device":{"amplifier_hz":501},"loop":{"sample_hz":1000,"render_hz":1000}}"#
            ),
            "device.amplifier_hz"
        );
        // f_max must lie above f_min.
        assert_eq!(
            failing(r#"{"probe":{"f_min_hz":1,"f_max_hz":1}}"#),
            "probe.f_max_hz"
        );
        assert_eq!(failing(r#"{"probe":{"f_max_hz":1e308}}"#), "probe.f_max_hz");
        // The wall: K in [0, 1e9] N/m, |B| ≤ 1e7 N·s/m.
        assert!(validate_wall(0.0, 1e7).is_ok() && validate_wall(1e9, -1e7).is_ok());
        assert_eq!(validate_wall(0.0, 2e7).unwrap_err().field, "b");
        assert_eq!(validate_wall(0.0, -2e7).unwrap_err().field, "b");
        assert_eq!(validate_wall(2e9, 0.0).unwrap_err().field, "k");
    }

    #[test]
    fn the_first_nonlinearity_is_named_and_the_grid_follows_the_loop() {
        let reason = |j: &str| {
            SceneSpec::from_json(j)
                .unwrap()
                .validate()
                .unwrap()
                .linear_reason()
        };
        let lin =
            r#""device":{"coulomb":0,"quantization":0},"loop":{"sample_hz":1000,"render_hz":1000}"#;
        assert_eq!(reason(&format!("{{{lin}}}")), None);
        let one = |device: &str, estimator: &str| {
            reason(&format!(
                r#"{{"device":{device},"loop":{{"sample_hz":1000,"render_hz":1000}},"estimator":{estimator}}}"#
            ))
        };
        assert_eq!(
            one(r#"{"coulomb":0}"#, r#"{"kind":"fdm"}"#).as_deref(),
            Some("quantization")
        );
        assert_eq!(
            one(r#"{"quantization":0}"#, r#"{"kind":"fdm"}"#).as_deref(),
            Some("Coulomb friction")
        );
        let flat = r#"{"coulomb":0,"quantization":0}"#;
        assert_eq!(
            one(flat, r#"{"kind":"fdm","median_velocity":3}"#).as_deref(),
            Some("median smoothing")
        );
        assert_eq!(
            one(flat, r#"{"kind":"fdm","median_position":3}"#).as_deref(),
            Some("median smoothing")
        );
        assert_eq!(
            one(
                r#"{"coulomb":0,"quantization":0,"force_resolution":0.01}"#,
                r#"{"kind":"fdm"}"#
            )
            .as_deref(),
            Some("force command resolution")
        );
        assert_eq!(one(flat, r#"{"kind":"kalman","q":1e3}"#), None);
        // A lag or a transmission: analytic up to 20 kHz, not above.
        let fast = |hz: u32, device: &str| {
            reason(&format!(
                r#"{{"device":{device},"loop":{{"sample_hz":{hz},"render_hz":{hz}}}}}"#
            ))
        };
        let lag = r#"{"coulomb":0,"quantization":0,"amplifier_hz":1000}"#;
        let cable =
            r#"{"coulomb":0,"quantization":0,"transmission":{"motor_mass":0.1,"stiffness":1e5}}"#;
        assert_eq!(fast(20_000, lag), None);
        assert_eq!(fast(20_000, cable), None);
        assert!(fast(25_000, lag)
            .unwrap()
            .starts_with("an amplifier lag or a transmission at 25000 Hz"));
        assert!(fast(25_000, cable).is_some());
        assert_eq!(
            fast(25_000, flat),
            None,
            "the rigid device is exact at any rate"
        );
        // The default (seed) scene: 10 kHz sampling, 1 kHz rendering.
        let sc = SceneSpec::default().validate().unwrap();
        assert_eq!((sc.dt, sc.render_dt, sc.ratio), (1e-4, 1e-3, 10));
        assert_eq!(sc.sampling.quantization, 1e-6);
        let ideal = SceneSpec::from_json(&format!("{{{lin}}}"))
            .unwrap()
            .validate()
            .unwrap();
        assert_eq!(ideal.sampling.quantization, IDEAL_SENSOR_ESTIMATOR_STEP);
        // At least 40 probe substeps per period of the highest line.
        assert_eq!(probe_substeps(100.0, 1000.0), 4);
        assert_eq!(probe_substeps(30.0, 1000.0), 2);
        assert_eq!(probe_substeps(100.0, 1e4), 1);
        // The probe method: BLA unless named, and kept by a parameter edit.
        assert!(ProbeMethod::default().is_bla() && !ProbeMethod::Tfestimate.is_bla());
        let tf = SceneSpec::from_json(r#"{"probe":{"method":"tfestimate"}}"#)
            .unwrap()
            .with_number("device.damping", 5.0, "p")
            .unwrap();
        assert_eq!(tf.probe.method, ProbeMethod::Tfestimate);
        assert!(serde_json::to_value(SceneSpec::default()).unwrap()["probe"]
            .get("method")
            .is_none());
    }

    #[test]
    fn one_hit_per_verdict_is_not_written_so_stored_scenes_read_as_before() {
        // A stored scene from before `hit.replicates` reads as one hit, and
        // one hit is not written back: the scene's JSON (and so every
        // stored spec and its hash) is unchanged unless a scene asks for more.
        let one = serde_json::to_value(HitSpec::default()).unwrap();
        assert!(one.get("replicates").is_none(), "{one}");
        let three = HitSpec {
            replicates: 3,
            ..HitSpec::default()
        };
        let v = serde_json::to_value(&three).unwrap();
        assert_eq!(v["replicates"], 3);
        assert_eq!(serde_json::from_value::<HitSpec>(v).unwrap(), three);
        let old: HitSpec = serde_json::from_str(r#"{"home_distance":0.07}"#).unwrap();
        assert_eq!(old.replicates, 1);
    }
}
