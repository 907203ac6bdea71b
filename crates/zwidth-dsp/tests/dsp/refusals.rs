//! Every refusal names its parameter, says what is allowed and never shows
//! NaN or inf (the C ABI copies the parameter's name and the message).

use zwidth_dsp::estimator::{KindSpec, Spec};
use zwidth_dsp::{Discretization, Error, FoawFit, ImplicitOutput, QModel, RigEstimator};

fn refused(kind: KindSpec, rate: f64, q: f64) -> Error {
    RigEstimator::new(&Spec::from(kind), rate, q).unwrap_err()
}

#[test]
fn refusals_name_the_parameter_and_what_is_allowed() {
    let fdm = KindSpec::Fdm;
    for (rate, q, name) in [
        (0.0, 1e-6, "rate_hz"),
        (f64::NAN, 1e-6, "rate_hz"),
        (-1e3, 1e-6, "rate_hz"),
        (f64::INFINITY, 1e-6, "rate_hz"),
        (1e3, 0.0, "quantization"),
        (1e3, f64::NAN, "quantization"),
    ] {
        let e = refused(fdm, rate, q);
        assert_eq!(e.parameter(), name, "{rate} {q}");
        let text = e.to_string();
        assert!(text.starts_with(name), "{text}");
        assert!(text.contains("must be a finite number > 0"), "{text}");
        assert!(!text.contains("NaN") && !text.contains("inf"), "{text}");
    }
    // A finite value is shown as it is.
    assert_eq!(
        refused(fdm, -1e3, 1e-6).to_string(),
        "rate_hz = -1000 is not allowed: must be a finite number > 0"
    );
    assert_eq!(
        refused(fdm, f64::NAN, 1e-6).to_string(),
        "rate_hz (not a finite number) is not allowed: must be a finite number > 0"
    );
    // Capacity: the cap named.
    let e = refused(
        KindSpec::Foaw {
            fit: FoawFit::Best,
            d: None,
            max_window: 65,
            outlier_tolerance: false,
        },
        1e3,
        1e-6,
    );
    assert_eq!(e.parameter(), "max_window");
    assert_eq!(
        e.to_string(),
        "max_window = 65 is beyond this build's capacity of 64"
    );
    let e = refused(
        KindSpec::Butterworth {
            cutoff_hz: 10.0,
            order: 11,
        },
        1e3,
        1e-6,
    );
    assert_eq!(e.parameter(), "order");
    for (kind, name) in [
        (
            KindSpec::Butterworth {
                cutoff_hz: 500.0,
                order: 2,
            },
            "cutoff_hz",
        ),
        (
            KindSpec::Butterworth {
                cutoff_hz: 0.0,
                order: 2,
            },
            "cutoff_hz",
        ),
        (
            KindSpec::Kalman {
                q: -1.0,
                model: QModel::WhiteJerk,
                rho: None,
            },
            "q",
        ),
        (
            KindSpec::Kalman {
                q: 1.0,
                model: QModel::WhiteJerk,
                rho: Some(1.0),
            },
            "rho",
        ),
        (
            KindSpec::Levant {
                alpha: 0.0,
                lambda: 1.0,
                discretization: Discretization::Explicit,
                output: ImplicitOutput::State,
            },
            "alpha",
        ),
        (
            KindSpec::Levant {
                alpha: 1.0,
                lambda: f64::NAN,
                discretization: Discretization::Implicit,
                output: ImplicitOutput::State,
            },
            "lambda",
        ),
    ] {
        let e = refused(kind, 1e3, 1e-6);
        assert_eq!(e.parameter(), name, "{kind:?}");
        assert!(e.to_string().starts_with(name), "{e}");
    }
}
