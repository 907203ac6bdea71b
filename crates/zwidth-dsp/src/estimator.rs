//! One estimator of any kind, with optional median smoothing of its input
//! positions and output velocities (Janabi-Sharifi et al. 2000, §III-B),
//! built from a plain [`Spec`] (the JSON spec is parsed above this crate:
//! `zwidth-core` and the C ABI).

use crate::fingerprint::Fingerprint;
use crate::{
    Butterworth, Discretization, Error, Fdm, Foaw, FoawFit, ImplicitOutput, Kalman, Levant, Median,
    QModel,
};

/// The kind and its resolved parameters.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum KindSpec {
    Fdm,
    Butterworth {
        cutoff_hz: f64,
        order: u32,
    },
    /// `rho`: Some for the adaptive filter.
    Kalman {
        q: f64,
        model: QModel,
        rho: Option<f64>,
    },
    /// `d`: None for the encoder step.
    Foaw {
        fit: FoawFit,
        d: Option<f64>,
        max_window: usize,
        outlier_tolerance: bool,
    },
    Levant {
        alpha: f64,
        lambda: f64,
        discretization: Discretization,
        output: ImplicitOutput,
    },
}

#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spec {
    pub kind: KindSpec,
    pub median_position: Option<usize>,
    pub median_velocity: Option<usize>,
}

impl From<KindSpec> for Spec {
    fn from(kind: KindSpec) -> Self {
        Self {
            kind,
            median_position: None,
            median_velocity: None,
        }
    }
}

/// The built core, FOAW windows up to `F − 1`.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind<const F: usize> {
    Fdm(Fdm),
    Butterworth(Butterworth),
    Kalman(Kalman),
    Foaw(Foaw<F>),
    Levant(Levant),
}

/// An estimator whose FOAW windows reach `F − 1` samples and whose
/// medians reach `M`.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimator<const F: usize, const M: usize> {
    kind: Kind<F>,
    median_position: Option<Median<M>>,
    median_velocity: Option<Median<M>>,
    fingerprint: u64,
}

/// The rig build's caps: FOAW windows of up to 64 samples (best-R: at most
/// 2 144 residuals a sample), medians of up to 63 samples.
pub const RIG_FOAW_WINDOW: usize = 64;
pub const RIG_MEDIAN: usize = 63;

/// The estimator a controller embeds (the C ABI's state).
pub type RigEstimator = Estimator<{ RIG_FOAW_WINDOW + 1 }, RIG_MEDIAN>;

impl<const F: usize> Kind<F> {
    /// Build from `spec` at `rate_hz` with the encoder step `quantization` (m).
    pub fn new(spec: &KindSpec, rate_hz: f64, quantization: f64) -> Result<Self, Error> {
        crate::error::positive("rate_hz", rate_hz)?;
        crate::error::positive("quantization", quantization)?;
        let t = 1.0 / rate_hz;
        Ok(match *spec {
            KindSpec::Fdm => Kind::Fdm(Fdm::new(t)),
            KindSpec::Butterworth { cutoff_hz, order } => {
                Kind::Butterworth(Butterworth::new(cutoff_hz, order, rate_hz)?)
            }
            KindSpec::Kalman { q, model, rho } => {
                Kind::Kalman(Kalman::new(q, model, rho, rate_hz, quantization)?)
            }
            KindSpec::Foaw {
                fit,
                d,
                max_window,
                outlier_tolerance,
            } => Kind::Foaw(Foaw::new(
                fit,
                d.unwrap_or(quantization),
                max_window,
                outlier_tolerance,
                t,
            )?),
            KindSpec::Levant {
                alpha,
                lambda,
                discretization,
                output,
            } => Kind::Levant(Levant::new(alpha, lambda, discretization, output, t)?),
        })
    }

    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        match self {
            Kind::Fdm(e) => e.step(y),
            Kind::Butterworth(e) => e.step(y),
            Kind::Kalman(e) => e.step(y),
            Kind::Foaw(e) => e.step(y),
            Kind::Levant(e) => e.step(y),
        }
    }

    pub fn reset(&mut self) {
        match self {
            Kind::Fdm(e) => e.reset(),
            Kind::Butterworth(e) => e.reset(),
            Kind::Kalman(e) => e.reset(),
            Kind::Foaw(e) => e.reset(),
            Kind::Levant(e) => e.reset(),
        }
    }

    /// The coefficients' fingerprint (see [`crate::fingerprint`]): the kind,
    /// then every built constant its step reads.
    pub fn fingerprint(&self) -> Fingerprint {
        let h = Fingerprint::default();
        match self {
            Kind::Fdm(e) => h.u64(1).f64(e.inv_t()),
            Kind::Butterworth(e) => {
                let h = e
                    .sections()
                    .iter()
                    .flatten()
                    .fold(h.u64(2), |h, &c| h.f64(c));
                h.f64(e.inv_t())
            }
            Kind::Kalman(e) => {
                let (q, r, p0) = e.coefficients();
                let h = q.iter().chain(&p0).fold(h.u64(3).f64(r), |h, &c| h.f64(c));
                h.f64(e.period()).f64(e.rho().unwrap_or(-1.0))
            }
            Kind::Foaw(e) => {
                let (d, t) = e.coefficients();
                let (fit, window, tolerant) = e.shape();
                foaw_fingerprint(d, t, fit, window, tolerant)
            }
            Kind::Levant(e) => {
                let (a, l) = e.gains();
                let (disc, out) = e.scheme();
                h.u64(5)
                    .f64(a)
                    .f64(l)
                    .f64(e.period())
                    .u64(disc as u64)
                    .u64(out as u64)
            }
        }
    }
}

fn foaw_fingerprint(d: f64, t: f64, fit: FoawFit, window: usize, tolerant: bool) -> Fingerprint {
    Fingerprint::default()
        .u64(4)
        .f64(d)
        .f64(t)
        .u64(fit as u64)
        .u64(window as u64)
        .u64(u64::from(tolerant))
}

/// The medians' part of a fingerprint.
fn with_medians(h: Fingerprint, spec: &Spec) -> u64 {
    h.u64(spec.median_position.unwrap_or(0) as u64)
        .u64(spec.median_velocity.unwrap_or(0) as u64)
        .finish()
}

/// The fingerprint an estimator built from `spec` has (equal to
/// [`Estimator::fingerprint`] whatever the caps), without building its
/// state: how a host with longer windows than a rig names the same
/// coefficients.
pub fn fingerprint(spec: &Spec, rate_hz: f64, quantization: f64) -> Result<u64, Error> {
    let h = match spec.kind {
        KindSpec::Foaw {
            fit,
            d,
            max_window,
            outlier_tolerance,
        } => {
            crate::error::positive("rate_hz", rate_hz)?;
            crate::error::positive("quantization", quantization)?;
            foaw_fingerprint(
                crate::foaw::band(d.unwrap_or(quantization)),
                1.0 / rate_hz,
                fit,
                max_window,
                outlier_tolerance,
            )
        }
        other => Kind::<1>::new(&other, rate_hz, quantization)?.fingerprint(),
    };
    Ok(with_medians(h, spec))
}

impl<const F: usize, const M: usize> Estimator<F, M> {
    pub fn new(spec: &Spec, rate_hz: f64, quantization: f64) -> Result<Self, Error> {
        let kind = Kind::new(&spec.kind, rate_hz, quantization)?;
        let median = |name: &'static str, w: Option<usize>| -> Result<Option<Median<M>>, Error> {
            w.map(|w| {
                Median::new(w).map_err(|e| match e {
                    Error::Capacity { value, cap, .. } => Error::Capacity { name, value, cap },
                    Error::Parameter { value, allowed, .. } => Error::Parameter {
                        name,
                        value,
                        allowed,
                    },
                })
            })
            .transpose()
        };
        let median_position = median("median_position", spec.median_position)?;
        let median_velocity = median("median_velocity", spec.median_velocity)?;
        let fingerprint = with_medians(kind.fingerprint(), spec);
        Ok(Self {
            kind,
            median_position,
            median_velocity,
            fingerprint,
        })
    }

    /// One position sample (m) in, one velocity estimate (m/s) out.
    #[inline]
    pub fn step(&mut self, y: f64) -> f64 {
        let y = match &mut self.median_position {
            Some(m) => m.step(y),
            None => y,
        };
        let v = self.kind.step(y);
        match &mut self.median_velocity {
            Some(m) => m.step(v),
            None => v,
        }
    }

    /// `step` over a block: `out[i]` from `positions[i]` (the shorter length).
    pub fn step_n(&mut self, positions: &[f64], out: &mut [f64]) {
        for (y, v) in positions.iter().zip(out.iter_mut()) {
            *v = self.step(*y);
        }
    }

    /// Forget all history, as if newly built.
    pub fn reset(&mut self) {
        self.kind.reset();
        if let Some(m) = &mut self.median_position {
            m.reset();
        }
        if let Some(m) = &mut self.median_velocity {
            m.reset();
        }
    }

    pub fn kind(&self) -> &Kind<F> {
        &self.kind
    }

    /// The fingerprint of the built coefficients (and median windows).
    pub fn fingerprint(&self) -> u64 {
        self.fingerprint
    }
}
