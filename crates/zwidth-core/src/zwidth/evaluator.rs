//! One verdict at (K, B): the engine a scene and criterion call for
//! (closed forms, the frequency probe, wall hits), chosen and checked once
//! ([`Evaluator::new`]), then asked point by point. No observer, no
//! cancel, no storage: that is the map run's ([`super::classify`]).

use super::analytic::{ImpedanceCurve, LinearModel};
use super::hit::{replicated_hits, wall_hit, NoTrace};
use super::point::Point;
use super::probe::{probe_seeded, ProbeSetup};
use super::scene::{ProbeMethod, Scene, SceneSpec};
use super::settings::{Criterion, Method, Resolved, SearchKind};
use crate::error::SpecError;

/// Whether a verdict of engine `method` on `scene` is a random draw: the
/// BLA probe of a scene with friction or quantization, each trial with
/// random phases of its own (`bla::trial_seed`). The Psi search needs it
/// (a failure probability rising with K); a replicated wall hit is noisy
/// but the same K gives the same verdict, so Psi falls back to bisection
/// there (docs/zwidth.md, "Not for the rig's wall hits yet").
pub fn random_verdicts(scene: &SceneSpec, method: Method) -> bool {
    let d = &scene.device;
    method == Method::Frequency
        && (d.coulomb > 0.0 || d.quantization > 0.0)
        && scene.probe.method == ProbeMethod::Bla
}

/// Whether engine `method` gives verdicts with a confidence on `scene`:
/// the BLA probe of a scene with friction or quantization (a nonlinear
/// frequency-domain probe), or replicated wall hits.
pub fn noisy_verdicts(scene: &SceneSpec, method: Method) -> bool {
    random_verdicts(scene, method) || (method == Method::Time && scene.hit.replicates > 1)
}

/// The chosen engine for one scene and criterion.
pub struct Evaluator {
    pub scene: Scene,
    pub method: Method,
    pub criterion: Criterion,
    pub res: Resolved,
    pub(super) model: Option<LinearModel>,
    probe_setup: Option<ProbeSetup>,
}

impl Evaluator {
    /// Resolve `auto`, and check the engine can answer the criterion.
    pub fn new(
        scene: Scene,
        method: Method,
        criterion: Criterion,
        res: Resolved,
    ) -> Result<Self, SpecError> {
        let method = match method {
            Method::Auto if scene.is_linear() => Method::Analytic,
            Method::Auto => match criterion {
                Criterion::Stability => Method::Time,
                Criterion::Impedance => Method::Frequency,
                Criterion::StrictPassivity => {
                    return Err(SpecError::new(
                        "criterion",
                        "strict_passivity",
                        format!(
                            "needs the analytic engine, and this scene is not linear ({})",
                            scene.linear_reason().unwrap_or_default()
                        ),
                    ))
                }
            },
            m => m,
        };
        let d = &scene.spec.device;
        if criterion == Criterion::StrictPassivity
            && (d.amplifier_hz.is_some() || d.transmission.is_some())
        {
            return Err(SpecError::new(
                "criterion",
                "strict_passivity",
                "Colgate & Schenkel's condition is for a rigid device driven without lag; with device.amplifier_hz or device.transmission use impedance or stability",
            ));
        }
        let bad = |allowed: &str| {
            Err(SpecError::new(
                "criterion",
                format!("{criterion:?}").to_lowercase(),
                format!(
                    "method {} answers {allowed} only",
                    format!("{method:?}").to_lowercase()
                ),
            ))
        };
        match (method, criterion) {
            (Method::Time, Criterion::Stability)
            | (Method::Frequency, Criterion::Impedance)
            | (Method::Analytic, _) => {}
            (Method::Time, _) => return bad("stability"),
            (Method::Frequency, _) => return bad("impedance"),
            (Method::Auto, _) => unreachable!("resolved above"),
        }
        let model = if method == Method::Analytic {
            Some(LinearModel::new(&scene)?)
        } else {
            None
        };
        let probe_setup = (method == Method::Frequency).then(|| ProbeSetup::new(&scene));
        Ok(Self {
            scene,
            method,
            criterion,
            res,
            model,
            probe_setup,
        })
    }

    pub fn model_description(&self) -> String {
        let s = &self.scene.spec;
        let est = s.estimator.label();
        match self.method {
            Method::Analytic => format!(
                "analytic: linear single-rate loop at {} Hz, ZOH plant m = {} kg, b = {} N·s/m{}, estimator {est} (exact V(z)), delay {} samples",
                s.control.sample_hz,
                s.device.mass,
                s.device.damping,
                drive_description(&s.device),
                s.control.delay_samples
            ),
            Method::Time | Method::Frequency => {
                let mut parts = vec![format!("exact ZOH plant m = {} kg, b = {} N·s/m", s.device.mass, s.device.damping)];
                match (&s.device.friction, s.device.coulomb > 0.0) {
                    (Some(f), _) => parts.push(format!(
                        "LuGre friction on the {} F_c = {} N, F_s = {} N, v_s = {} m/s, σ0 = {} N/m, σ1 = {} N·s/m",
                        if f.on == super::scene::FrictionSide::Motor { "motor side" } else { "handle" },
                        s.device.coulomb,
                        s.device.static_friction(),
                        f.stribeck_velocity,
                        f.bristle_stiffness,
                        f.bristle_damping
                    )),
                    (None, true) => {
                        parts.push(format!("Coulomb stick-slip f_c = {} N", s.device.coulomb))
                    }
                    (None, false) => {}
                }
                if s.device.quantization > 0.0 {
                    parts.push(format!("quantization {} m", s.device.quantization));
                }
                if let Some(f) = s.device.force_limit {
                    parts.push(format!("saturation ±{f} N"));
                }
                if let Some(r) = s.device.force_resolution {
                    parts.push(format!("force command in steps of {r} N"));
                }
                let drive = drive_description(&s.device);
                if !drive.is_empty() {
                    parts.push(drive.trim_start_matches(", ").to_string());
                }
                parts.push(format!("encoder {} Hz, render {} Hz, delay {}", s.control.sample_hz, s.control.render_hz, s.control.delay_samples));
                parts.push(format!("estimator {est}"));
                let noisy = self.noisy();
                let kind = if self.method == Method::Time && noisy {
                    format!(
                        "time-domain wall-hit simulation ({} replicate hits per verdict, each started a further 1/{} encoder step from the wall; the majority decides, decided only when all agree)",
                        s.hit.replicates, s.hit.replicates
                    )
                } else if self.method == Method::Time {
                    "time-domain wall-hit simulation".to_string()
                } else if noisy {
                    format!(
                        "frequency-domain multisine simulation (bilateral wall; best linear approximation from random-phase realizations, seed {} shared by every map with this seed, verdicts at {} % confidence)",
                        s.probe.seed,
                        100.0 * s.probe.confidence
                    )
                } else if self.method == Method::Frequency
                    && (s.device.coulomb > 0.0 || s.device.quantization > 0.0)
                {
                    format!(
                        "frequency-domain multisine simulation (bilateral wall; the 2018 paper's tfestimate verdict: one Schroeder multisine, {} periods Welch-averaged, taken as certain: no confidence, no intervals)",
                        super::probe::tfestimate_periods(self.res.probe.periods)
                    )
                } else {
                    "frequency-domain multisine simulation (bilateral wall)".to_string()
                };
                format!("{kind}: {}", parts.join(", "))
            }
            Method::Auto => unreachable!(),
        }
    }

    fn probe(&self, k: f64, b: f64) -> super::probe::ProbeOutcome {
        self.probe_seeded(k, b, self.scene.spec.probe.seed)
    }

    /// The probe with its realizations drawn from `seed`.
    fn probe_seeded(&self, k: f64, b: f64, seed: u64) -> super::probe::ProbeOutcome {
        let setup = self
            .probe_setup
            .as_ref()
            .expect("frequency method has a probe setup");
        probe_seeded(setup, &self.scene, k, b, self.res.probe, seed)
    }

    /// The impedance curve at (K, B) from whichever engine can give one.
    pub fn impedance(&self, k: f64, b: f64) -> Option<ImpedanceCurve> {
        match (&self.model, self.method) {
            (Some(m), _) => Some(m.impedance(k, b)),
            (None, Method::Frequency) => Some(self.probe(k, b).impedance),
            _ => None,
        }
    }

    /// The verdict at (K, B) from this process's engines (what a remote
    /// trial computes too: `trial::run`).
    pub(super) fn evaluate_point(&self, k: f64, b: f64) -> Point {
        self.evaluate(Point {
            k,
            b,
            ..Point::default()
        })
    }

    pub(super) fn evaluate(&self, p: Point) -> Point {
        self.evaluate_seeded(p, self.scene.spec.probe.seed)
    }

    /// The verdict with a noisy probe's realizations drawn from `seed` (a
    /// trial of its own, `bla::trial_seed`); the other engines draw nothing.
    pub(super) fn evaluate_seeded(&self, mut p: Point, seed: u64) -> Point {
        let (k, b) = (p.k, p.b);
        match (self.criterion, &self.model) {
            (Criterion::Stability, Some(m)) => p.stable = Some(m.spectral_radius(k, b) < 1.0),
            (Criterion::Stability, None) if self.scene.spec.hit.replicates > 1 => {
                let r = replicated_hits(&self.scene, k, b, self.res.hit);
                p.stable = Some(r.stable());
                p.decided = Some(r.decided());
                p.realizations = Some(r.hits);
                p.saturated = r.saturated.then_some(true);
            }
            (Criterion::Stability, None) => {
                let o = wall_hit(&self.scene, k, b, self.res.hit, &mut NoTrace);
                p.stable = Some(o.stable);
                p.saturated = (o.saturated_renders > 0).then_some(true);
            }
            (Criterion::Impedance, Some(m)) => {
                let c = m.impedance(k, b);
                p.passive = Some(c.passive);
                p.fidelity = Some(c.fidelity);
            }
            (Criterion::Impedance, None) => {
                let o = self.probe_seeded(k, b, seed);
                p.passive = Some(o.passive);
                p.fidelity = Some(o.impedance.fidelity);
                p.saturated = (o.saturated_renders > 0).then_some(true);
                if let Some(c) = o.confidence {
                    p.decided = Some(c.decided);
                    p.margin = Some(c.margin);
                    p.margin_se = Some(c.margin_se);
                    p.realizations = Some(c.realizations);
                }
            }
            (Criterion::StrictPassivity, Some(m)) => {
                p.passive = Some(
                    m.strict_passivity_range(b)
                        .is_some_and(|(lo, hi)| k >= lo && k <= hi),
                );
                p.fidelity = Some(m.impedance(k, b).fidelity);
            }
            (Criterion::StrictPassivity, None) => unreachable!("checked in new()"),
        }
        p
    }

    /// Whether verdicts carry uncertainty: a simulation with friction or
    /// quantization, judged by the BLA verdict (`bla.rs`). The
    /// `tfestimate` baseline takes its verdicts as certain.
    /// Verdicts with a confidence, so boundaries with intervals: the BLA
    /// probe of a nonlinear scene, or replicated wall hits.
    pub fn noisy(&self) -> bool {
        noisy_verdicts(&self.scene.spec, self.method)
    }

    /// Whether a map with `search` runs the Psi search here: asked for,
    /// on verdicts that are random draws (`random_verdicts`).
    pub fn runs_psi(&self, search: SearchKind) -> bool {
        search == SearchKind::Psi && random_verdicts(&self.scene.spec, self.method)
    }
}

/// The amplifier lag and transmission a device names, as ", …" (or "").
fn drive_description(d: &super::scene::DeviceSpec) -> String {
    let mut s = String::new();
    if let Some(t) = &d.transmission {
        s.push_str(&format!(
            ", two-mass transmission (motor side {} kg, {} N·s/m; cable {} N/m, {} N·s/m; encoder on the {})",
            t.motor_mass,
            t.motor_damping,
            t.stiffness,
            t.damping,
            if t.encoder == super::scene::EncoderSide::Motor { "motor" } else { "handle" }
        ));
    }
    if let Some(fa) = d.amplifier_hz {
        s.push_str(&format!(", amplifier lag {fa} Hz"));
    }
    s
}
