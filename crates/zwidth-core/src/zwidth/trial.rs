//! One trial, as something a backend other than this process can run: the
//! searches ask for a verdict at (K, B) and whoever answers — the engines in
//! this process (the default), or an attached rig over the agent protocol —
//! returns a [`Point`]. A request carries everything the trial needs (the
//! scene, the engine, the criterion and the accuracy spec), so the answer
//! does not depend on where it was computed: [`run`] is what the simulated
//! agent runs, and it gives the bits the in-process search gives.

use serde::{Deserialize, Serialize};

use super::control::RunControl;
use super::evaluator::{noisy_verdicts, Evaluator};
use super::point::Point;
use super::scene::SceneSpec;
use super::settings::{Accuracy, Criterion, Method};
use crate::error::SpecError;

/// One trial of map `scope`: the wall (K, B) on `scene`, judged by
/// `criterion` with engine `method` (never `auto`: resolved by the map).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct TrialRequest {
    pub scope: u32,
    /// Wall stiffness (N/m).
    pub k: f64,
    /// Wall damping (N·s/m).
    pub b: f64,
    pub scene: SceneSpec,
    pub method: Method,
    pub criterion: Criterion,
    pub accuracy: Accuracy,
}

/// Runs trials somewhere else. `trial` blocks until the verdict is in; None
/// when the run was cancelled meanwhile (see `observer.cancelled()`): the
/// search then ends as it does on a cancel.
pub trait TrialBackend: Send + Sync {
    fn trial(&self, request: &TrialRequest, observer: &dyn RunControl) -> Option<Point>;
}

/// Run a trial in this process, as the map's own search would.
pub fn run(request: &TrialRequest) -> Result<Point, SpecError> {
    let scene = request.scene.validate().map_err(|e| e.within("scene"))?;
    let res = request.accuracy.resolve(&scene)?;
    if request.method == Method::Auto {
        return Err(SpecError::new(
            "method",
            "auto",
            "a trial names its engine: time, frequency or analytic",
        ));
    }
    super::scene::validate_wall(request.k, request.b)?;
    let ev = Evaluator::new(scene, request.method, request.criterion, res)?;
    Ok(ev.evaluate_point(request.k, request.b))
}

impl TrialRequest {
    /// Whether `p` is exactly a verdict this trial's criterion and engine
    /// produce (`Evaluator::evaluate`): at (K, B) to the bit, the verdict
    /// field the criterion sets and no other, the confidence fields when
    /// the verdict is noisy and only then, every number finite and in its
    /// range. An attached rig's answer is checked so before it is stored.
    /// Err names the field.
    pub fn check_verdict(&self, p: &Point) -> Result<(), SpecError> {
        if p.k.to_bits() != self.k.to_bits() || p.b.to_bits() != self.b.to_bits() {
            return Err(SpecError::new(
                "point",
                format!("(K, B) = ({}, {})", p.k, p.b),
                format!("the trial's wall ({}, {})", self.k, self.b),
            ));
        }
        let scene = self.scene.validate().map_err(|e| e.within("scene"))?;
        let res = self.accuracy.resolve(&scene)?;
        let noisy = noisy_verdicts(&scene.spec, self.method);
        let max_realizations = match self.criterion {
            Criterion::Stability => scene.spec.hit.replicates,
            _ => res.probe.realizations,
        };
        check_verdict_shape(p, self.criterion, noisy, max_realizations)
    }
}

/// The shape of a verdict of `criterion` (see [`TrialRequest::check_verdict`]):
/// stability sets `stable`; impedance and strict passivity set `passive`
/// and `fidelity` (≥ 0, N·s/m); a noisy verdict adds `decided` and
/// `realizations` (1 to `max_realizations`), and a noisy impedance verdict
/// `margin` and `margin_se` (≥ 0); `saturated` is absent or true.
pub fn check_verdict_shape(
    p: &Point,
    criterion: Criterion,
    noisy: bool,
    max_realizations: u32,
) -> Result<(), SpecError> {
    // "a stability verdict with a confidence", named once for both errors.
    let kind = format!(
        "a {} verdict {} a confidence",
        format!("{criterion:?}").to_lowercase(),
        if noisy { "with" } else { "without" }
    );
    let present = |name: &str, here: bool, wanted: bool| -> Result<(), SpecError> {
        match (here, wanted) {
            (true, false) => Err(SpecError::new(
                name,
                "(present)",
                format!("absent: {kind} has no {name}"),
            )),
            (false, true) => Err(SpecError::new(
                name,
                "(absent)",
                format!("present: {kind} carries it"),
            )),
            _ => Ok(()),
        }
    };
    let impedance = criterion != Criterion::Stability;
    present("stable", p.stable.is_some(), !impedance)?;
    present("passive", p.passive.is_some(), impedance)?;
    present("fidelity", p.fidelity.is_some(), impedance)?;
    present("decided", p.decided.is_some(), noisy)?;
    present("realizations", p.realizations.is_some(), noisy)?;
    present("margin", p.margin.is_some(), noisy && impedance)?;
    present("margin_se", p.margin_se.is_some(), noisy && impedance)?;
    let finite = |name: &str, v: Option<f64>, min: f64| match v {
        Some(x) if !(x.is_finite() && x >= min) => Err(SpecError::new(
            name,
            x,
            if min == f64::MIN {
                "a finite number".to_string()
            } else {
                format!("a finite number ≥ {min}")
            },
        )),
        _ => Ok(()),
    };
    finite("fidelity", p.fidelity, 0.0)?;
    finite("margin", p.margin, f64::MIN)?;
    finite("margin_se", p.margin_se, 0.0)?;
    if let Some(r) = p.realizations {
        if !(1..=max_realizations).contains(&r) {
            return Err(SpecError::new(
                "realizations",
                r,
                format!("1 to {max_realizations} (the trial's accuracy)"),
            ));
        }
    }
    if p.saturated == Some(false) {
        return Err(SpecError::new(
            "saturated",
            false,
            "absent, or true when the force limit clipped the wall force",
        ));
    }
    Ok(())
}

#[cfg(test)]
mod verdict_tests {
    use super::*;
    use proptest::prelude::*;

    /// A number an agent might send: ordinary, extreme or not a number.
    fn number() -> impl Strategy<Value = f64> {
        prop_oneof![
            -1e3f64..1e3,
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(-1e308),
            Just(1e308),
            Just(0.0),
            Just(-0.0),
        ]
    }

    fn point() -> impl Strategy<Value = Point> {
        (
            (
                proptest::option::of(any::<bool>()),
                proptest::option::of(any::<bool>()),
            ),
            (
                proptest::option::of(number()),
                proptest::option::of(any::<bool>()),
            ),
            (
                proptest::option::of(number()),
                proptest::option::of(number()),
            ),
            (
                proptest::option::of(any::<u32>()),
                proptest::option::of(any::<bool>()),
            ),
        )
            .prop_map(
                |(
                    (stable, passive),
                    (fidelity, decided),
                    (margin, margin_se),
                    (realizations, saturated),
                )| Point {
                    k: 1000.0,
                    b: 2.0,
                    stable,
                    passive,
                    fidelity,
                    decided,
                    margin,
                    margin_se,
                    realizations,
                    saturated,
                },
            )
    }

    proptest! {
        /// Issue 30: accepted ⇒ bounded. A verdict the shape check accepts
        /// has exactly one verdict field, every number finite and in its
        /// range, and realizations within the trial's.
        #[test]
        fn an_accepted_verdict_is_finite_and_in_range(
            p in point(),
            impedance in any::<bool>(),
            noisy in any::<bool>(),
            max in 1u32..64,
        ) {
            let c = if impedance { Criterion::Impedance } else { Criterion::Stability };
            if check_verdict_shape(&p, c, noisy, max).is_ok() {
                prop_assert!(p.stable.is_some() != p.passive.is_some());
                prop_assert_eq!(p.passive.is_some(), impedance);
                for x in [p.fidelity, p.margin, p.margin_se].into_iter().flatten() {
                    prop_assert!(x.is_finite());
                }
                prop_assert!(p.fidelity.is_none_or(|f| f >= 0.0));
                prop_assert!(p.margin_se.is_none_or(|s| s >= 0.0));
                prop_assert!(p.realizations.is_none_or(|r| (1..=max).contains(&r)));
                prop_assert_eq!(p.realizations.is_some(), noisy);
                prop_assert_ne!(p.saturated, Some(false));
            }
        }
    }

    /// Each rule, with the field it names (a change to any is caught).
    #[test]
    fn each_rule_names_its_field() {
        let ok = Point {
            k: 1.0,
            b: 0.0,
            stable: Some(true),
            ..Point::default()
        };
        assert!(check_verdict_shape(&ok, Criterion::Stability, false, 8).is_ok());
        let noisy = Point {
            decided: Some(true),
            realizations: Some(8),
            ..ok.clone()
        };
        assert!(check_verdict_shape(&noisy, Criterion::Stability, true, 8).is_ok());
        let field = |p: &Point, c, n| check_verdict_shape(p, c, n, 8).unwrap_err().field;
        assert_eq!(field(&noisy, Criterion::Stability, false), "decided");
        assert_eq!(field(&ok, Criterion::Stability, true), "decided");
        assert_eq!(
            field(
                &Point {
                    realizations: Some(9),
                    ..noisy.clone()
                },
                Criterion::Stability,
                true
            ),
            "realizations"
        );
        assert_eq!(
            field(
                &Point {
                    realizations: Some(0),
                    ..noisy.clone()
                },
                Criterion::Stability,
                true
            ),
            "realizations"
        );
        assert_eq!(field(&ok, Criterion::Impedance, false), "stable");
        let imp = Point {
            k: 1.0,
            b: 0.0,
            passive: Some(true),
            fidelity: Some(0.5),
            ..Point::default()
        };
        assert!(check_verdict_shape(&imp, Criterion::Impedance, false, 8).is_ok());
        assert!(check_verdict_shape(&imp, Criterion::StrictPassivity, false, 8).is_ok());
        assert_eq!(
            field(
                &Point {
                    fidelity: None,
                    ..imp.clone()
                },
                Criterion::Impedance,
                false
            ),
            "fidelity"
        );
        assert_eq!(
            field(
                &Point {
                    fidelity: Some(-1e-9),
                    ..imp.clone()
                },
                Criterion::Impedance,
                false
            ),
            "fidelity"
        );
        let bla = Point {
            decided: Some(false),
            realizations: Some(3),
            margin: Some(-0.1),
            margin_se: Some(0.2),
            ..imp.clone()
        };
        assert!(check_verdict_shape(&bla, Criterion::Impedance, true, 8).is_ok());
        assert_eq!(
            field(
                &Point {
                    margin: None,
                    ..bla.clone()
                },
                Criterion::Impedance,
                true
            ),
            "margin"
        );
        assert_eq!(
            field(
                &Point {
                    margin: Some(f64::NAN),
                    ..bla.clone()
                },
                Criterion::Impedance,
                true
            ),
            "margin"
        );
        assert_eq!(
            field(
                &Point {
                    margin_se: Some(-1.0),
                    ..bla.clone()
                },
                Criterion::Impedance,
                true
            ),
            "margin_se"
        );
        assert_eq!(
            field(
                &Point {
                    margin_se: None,
                    ..bla.clone()
                },
                Criterion::Impedance,
                true
            ),
            "margin_se"
        );
        assert_eq!(
            field(
                &Point {
                    saturated: Some(false),
                    ..ok.clone()
                },
                Criterion::Stability,
                false
            ),
            "saturated"
        );
        assert!(check_verdict_shape(
            &Point {
                saturated: Some(true),
                ..ok
            },
            Criterion::Stability,
            false,
            8
        )
        .is_ok());
        // A request checks its wall to the bit and derives noisy and the cap.
        let scene = SceneSpec::from_json(r#"{"hit":{"replicates":3}}"#).unwrap();
        let r = TrialRequest {
            scope: 0,
            k: 1.0,
            b: 0.0,
            scene,
            method: Method::Time,
            criterion: Criterion::Stability,
            accuracy: Accuracy::default(),
        };
        let three = Point {
            k: 1.0,
            b: 0.0,
            stable: Some(true),
            decided: Some(true),
            realizations: Some(3),
            ..Point::default()
        };
        assert!(r.check_verdict(&three).is_ok());
        assert_eq!(
            r.check_verdict(&Point {
                realizations: Some(4),
                ..three.clone()
            })
            .unwrap_err()
            .field,
            "realizations"
        );
        assert_eq!(
            r.check_verdict(&Point {
                k: 1.0 + 1e-15,
                ..three
            })
            .unwrap_err()
            .field,
            "point"
        );
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::zwidth::observer::Observer;
    use crate::zwidth::search::{map, map_observed};
    use crate::zwidth::settings::MapSpec;
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Arc;

    /// A backend that sends each request through JSON (as the agent
    /// protocol does) and runs it with [`run`], counting the trials.
    #[derive(Default)]
    struct OverTheWire(AtomicUsize);
    impl TrialBackend for OverTheWire {
        fn trial(&self, request: &TrialRequest, _: &dyn RunControl) -> Option<Point> {
            self.0.fetch_add(1, Ordering::Relaxed);
            let wire = serde_json::to_string(request).unwrap();
            let back: TrialRequest = serde_json::from_str(&wire).unwrap();
            let p = run(&back).unwrap();
            Some(serde_json::from_str(&serde_json::to_string(&p).unwrap()).unwrap())
        }
    }

    /// Friction and quantization, wall hits at draft (nonlinear: the
    /// verdicts are the simulation's, not a closed form).
    const HITS: &str = r#"{"scene":{"device":{"coulomb":0.05,"quantization":1e-6},"loop":{"sample_hz":2000,"render_hz":1000}},
        "method":"time","criterion":"stability","b":[0,2],"accuracy":"draft"}"#;

    #[test]
    fn a_map_whose_trials_run_elsewhere_is_the_same_map_to_the_bit() {
        // The independent computation is the in-process map itself: every
        // trial computed from its request alone, after a JSON round trip,
        // gives the same boundary and the same points, bit for bit.
        let spec: MapSpec = serde_json::from_str(HITS).unwrap();
        let here = map(&spec).unwrap();
        let backend = Arc::new(OverTheWire::default());
        let o = Arc::new(Observer::default().with_backend(backend.clone()));
        let there = map_observed(&spec, Some(o.clone()), 0).unwrap();
        assert_eq!(backend.0.load(Ordering::Relaxed), here.trials);
        assert!(here.trials > 4, "{} trials", here.trials);
        let bits = |r: &crate::zwidth::search::MapResult| {
            r.boundary
                .iter()
                .map(|p| (p.b.to_bits(), p.k_max.to_bits()))
                .collect::<Vec<_>>()
        };
        assert_eq!(bits(&here), bits(&there));
        assert_eq!(here.points, there.points);
        assert!(here.k_width > 0.0);
        // Every remote trial was recorded for the store, as local ones are.
        assert_eq!(o.take_new().len(), here.trials);
    }

    #[test]
    fn a_cancelled_remote_trial_ends_the_map_as_a_cancel_does() {
        struct Gone;
        impl TrialBackend for Gone {
            fn trial(&self, _: &TrialRequest, o: &dyn RunControl) -> Option<Point> {
                o.cancel();
                None
            }
        }
        let spec: MapSpec = serde_json::from_str(HITS).unwrap();
        let o = Arc::new(Observer::default().with_backend(Arc::new(Gone)));
        let r = map_observed(&spec, Some(o.clone()), 0).unwrap();
        assert_eq!(r.k_width, 0.0);
        assert!(
            o.take_new().is_empty(),
            "nothing recorded for a trial never run"
        );
    }

    #[test]
    fn a_request_is_checked_before_it_runs() {
        let spec: MapSpec = serde_json::from_str(HITS).unwrap();
        let ok = TrialRequest {
            scope: 0,
            k: 1000.0,
            b: 1.0,
            scene: spec.scene.clone(),
            method: Method::Time,
            criterion: Criterion::Stability,
            accuracy: spec.accuracy.clone(),
        };
        assert!(run(&ok).unwrap().stable.is_some());
        let field = |r: TrialRequest| run(&r).unwrap_err().field;
        assert_eq!(
            field(TrialRequest {
                k: -1.0,
                ..ok.clone()
            }),
            "k"
        );
        assert_eq!(
            field(TrialRequest {
                b: f64::NAN,
                ..ok.clone()
            }),
            "b"
        );
        assert_eq!(
            field(TrialRequest {
                method: Method::Auto,
                ..ok.clone()
            }),
            "method"
        );
        assert_eq!(
            field(TrialRequest {
                method: Method::Time,
                criterion: Criterion::Impedance,
                ..ok
            }),
            "criterion"
        );
    }
}
