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
#[path = "scene_tests.rs"]
mod tests;
