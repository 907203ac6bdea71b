//! What the estimators expose besides `step` (their coefficients, for the
//! fingerprint; their state, for the subnormal test; FOAW's window and the
//! adaptive filter's fading factor, for reports), against the formulas.

use zwidth_dsp::foaw::band;
use zwidth_dsp::{
    Butterworth, Discretization, Fdm, Foaw, FoawFit, ImplicitOutput, Kalman, Levant, QModel,
};

const RATE: f64 = 1e4;
const T: f64 = 1.0 / RATE;
const Q: f64 = 1e-6;

#[test]
fn periods_and_gains_are_the_configurations() {
    assert_eq!(Fdm::new(T).inv_t(), 1.0 / T);
    assert_eq!(Butterworth::new(100.0, 2, RATE).unwrap().inv_t(), 1.0 / T);
    let l = Levant::new(
        13.2,
        3.46,
        Discretization::Explicit,
        ImplicitOutput::State,
        T,
    )
    .unwrap();
    assert_eq!((l.gains(), l.period()), ((13.2, 3.46), T));
    let k = Kalman::new(2.5e4, QModel::WhiteJerk, None, RATE, Q).unwrap();
    assert_eq!(k.period(), T);
}

/// The white-jerk model's process noise, scaled by the period
/// (Janabi-Sharifi et al. 2000, eq. 5: Q = q·[T⁵/20 T⁴/8 T³/6; T³/3 T²/2; T]
/// in the state (x, T ẋ, T² ẍ)), r = d²/3 (uniform quantization error),
/// and the initial covariance d²/3·diag-ish as built.
#[test]
fn the_kalman_coefficients_follow_the_model() {
    let q = 2.5e4;
    let (qq, r, p0) = Kalman::new(q, QModel::WhiteJerk, None, RATE, Q)
        .unwrap()
        .coefficients();
    let s5 = q * T * T * T * T * T;
    let want = [s5 / 20.0, s5 / 8.0, s5 / 6.0, s5 / 3.0, s5 / 2.0, s5];
    for (g, w) in qq.iter().zip(want) {
        assert!((g - w).abs() <= 1e-12 * w, "{qq:?} vs {want:?}");
    }
    assert_eq!(r, Q * Q / 3.0);
    assert_eq!(p0[0], Q * Q / 3.0);
    assert!(p0[3] > 0.0 && p0[5] > 0.0);
    let (qd, _, _) = Kalman::new(q, QModel::Diagonal, None, RATE, Q)
        .unwrap()
        .coefficients();
    assert_eq!(qd[..5], [0.0; 5]);
    assert!((qd[5] - q * T * T * T * T).abs() <= 1e-12 * qd[5]);
}

#[test]
fn the_states_track_a_held_position_and_reset() {
    let y = 1e-3;
    let mut k = Kalman::new(2.5e4, QModel::WhiteJerk, Some(0.95), RATE, Q).unwrap();
    let mut l = Levant::new(
        13.2,
        3.46,
        Discretization::Explicit,
        ImplicitOutput::State,
        T,
    )
    .unwrap();
    for _ in 0..2000 {
        k.step(y);
        l.step(y);
    }
    let (z, p, innovation) = k.state();
    assert!((z[0] - y).abs() < 1e-9, "{z:?}");
    assert!(p[0] > 0.0 && p[5] > 0.0, "{p:?}");
    assert!(innovation.is_some(), "the adaptive filter keeps one");
    let (x, u1) = l.state();
    assert!((x - y).abs() < 1e-6, "x = {x}");
    assert!(u1.abs() < 1e-2, "u1 = {u1}");
    k.reset();
    l.reset();
    assert_eq!(k.state(), ([0.0; 3], [0.0; 6], None));
    assert_eq!(l.state(), (0.0, 0.0));
    // The plain filter keeps no innovation covariance.
    let mut plain = Kalman::new(2.5e4, QModel::WhiteJerk, None, RATE, Q).unwrap();
    plain.step(y);
    plain.step(y);
    assert_eq!(plain.state().2, None);
}

/// The fading factor is 1 when innovations are as expected and above 1
/// after a jump the model did not predict (eqs. 8–10).
#[test]
fn the_fading_factor_rises_on_a_surprise() {
    let mut k = Kalman::new(2.5e4, QModel::WhiteJerk, Some(0.95), RATE, Q).unwrap();
    for _ in 0..2000 {
        k.step(0.0);
    }
    assert_eq!(k.last_lambda(), 1.0);
    k.step(1e-3);
    assert!(k.last_lambda() > 1.0, "{}", k.last_lambda());
    let mut plain = Kalman::new(2.5e4, QModel::WhiteJerk, None, RATE, Q).unwrap();
    plain.step(0.0);
    plain.step(1e-3);
    assert_eq!(plain.last_lambda(), 1.0);
}

/// FOAW on an exact ramp fits the longest window; its band is the
/// encoder step with its slack.
#[test]
fn foaw_fits_its_longest_window_on_a_ramp() {
    for fit in [FoawFit::End, FoawFit::Best, FoawFit::BestR] {
        let mut f = Foaw::<17>::new(fit, Q, 16, false, T).unwrap();
        assert_eq!(f.last_window(), 0);
        for i in 0..100 {
            f.step(i as f64 * Q);
        }
        assert_eq!(f.last_window(), 16, "{fit:?}");
        assert_eq!(f.coefficients(), (band(Q), T));
    }
    assert!(band(Q) > Q);
}
