//! A column's boundary from every trial it ran: a Bayesian grid posterior
//! over the boundary K* and the steepness β of the failure probability, the
//! Psi method (Kontsevich & Tyler 1999, Vision Res. 39:2729–2737). Pure: it
//! is told verdicts and asked for the next K; it knows nothing of engines,
//! threads, stores, farms or rigs (the driver is `search.rs`'s `psi_all`).
//!
//! The model (docs/zwidth.md, "The seed device's boundary is an escape
//! hazard"): near the boundary a trial fails when the loop escapes (or
//! clips, or Re Z falls below zero) at a rate λ(K) ∝ K^β, so a trial of a
//! fixed length fails with probability
//!
//! ```text
//! F(K) = 1 − exp(−ln 2 · (K/K*)^β)                (Weibull, F(K*) = ½)
//! P(K) = ε + (1 − 2ε)·F(K)                        (lapse ε both ways)
//! ```
//!
//! Kontsevich & Tyler's eq. 1 is this psychometric function with the
//! threshold at ½; the lapse ε keeps one wrong verdict (each has
//! probability at most α) from excluding the truth.
//!
//! A trial tells more than pass or fail where the loop escapes: with the
//! hazard per realization λ = ln 2·(K/K*)^β / H over a horizon of H
//! realizations (so that F above is 1 − e^{−λH}), an escape in realization
//! r has probability e^{−λ(r−1)}·(1 − e^{−λ}) and surviving n realizations
//! (a verdict decided passive before the horizon) e^{−λn}: the exposure
//! likelihood of a Poisson process (docs/zwidth.md, "The seed device's
//! boundary is an escape hazard"). A trial that fails without escaping
//! (Re Z below zero, the force limit's cycle) tells F alone.
//!
//! The posterior lives on a lattice of ln K* with step `h` (uniform prior:
//! log-uniform in K*) times a geometric list of β. Candidates for the next
//! trial lie on the same lattice, so the likelihood of a trial at lattice
//! point m for boundary i depends on m − i alone and is tabulated once
//! per model ([`PsiModel`]); the next K minimises the expected posterior
//! variance of ln K* (Kontsevich & Tyler §2.3, with the variance of the
//! threshold in place of the joint entropy: only K* is reported).

/// Lapse: the probability of a verdict wrong either way (a point's error
/// rate is at most α = 5 % at the default confidence, and far from the
/// boundary much lower).
pub const LAPSE: f64 = 0.02;

/// Lattice step in ln K: 0.2 %, a fifth of the standard preset's
/// resolution (coarser over a range wider than [`MAX_POINTS`] steps).
pub const STEP: f64 = 0.002;

/// Lattice points between the floor and the cap at most: a wider range
/// than e^{STEP·MAX_POINTS} = 2.2e4 takes a coarser step.
pub const MAX_POINTS: usize = 5000;

/// The steepness values of the grid, in ln K: from 4 (the failure
/// probability rising from ¼ to ¾ over a factor 1.5 in K) to 256 (over
/// 0.6 %). The seed device's measured β: 18.5 at B = 0, 40 at B = 238
/// (docs/zwidth.md).
pub const BETAS: [f64; 9] = [4.0, 6.4, 10.0, 16.0, 25.0, 40.0, 64.0, 100.0, 160.0];

/// Lattice blocks the planning of the next trial weighs at most.
const PLAN_POINTS: usize = 400;

/// What starting a trial costs, in realizations (`PsiColumn::ask`).
pub const TRIAL_OVERHEAD: f64 = 4.0;

/// A neighbour prior's smallest spread in ln K (its σ): 5 %, a boundary
/// that bends between neighbouring columns (the seed device's moves 1–10 %
/// a column where it is smooth, docs/zwidth.md).
pub const PRIOR_SPREAD: f64 = 0.05;

/// The weight of the log-uniform part of a neighbour prior: what keeps a
/// jump in the boundary between neighbours findable (a few trials that
/// contradict the neighbours move the posterior there, `psi_tests.rs`).
pub const PRIOR_UNIFORM: f64 = 0.03;

/// Cells whose log posterior lies this far below the largest are dropped
/// for good (e^−30 = 1e-13: no run of trials brings them back into the
/// quantiles).
const PRUNE: f64 = 30.0;

/// The probability that a trial fails `d` = ln K − ln K* from the
/// boundary, at steepness `beta`: Kontsevich & Tyler's eq. 1 (a Weibull
/// with the threshold where F = ½), the lapse both ways.
pub fn fail_probability(beta: f64, d: f64) -> f64 {
    let f = -(-std::f64::consts::LN_2 * (beta * d).exp()).exp_m1();
    LAPSE + (1.0 - 2.0 * LAPSE) * f
}

/// The K of trial `repeat` (0 first) at the same `k` (N/m): lowered by
/// 1e-9 per repeat, so each trial of a column has a K of its own (a trial
/// is stored, and replayed, by its K and B) and none passes `k`; the
/// likelihood takes it at its lattice point.
pub fn repeat_k(k: f64, repeat: usize) -> f64 {
    k * (1.0 - 1e-9 * repeat as f64)
}

/// What a trial told: how its verdict came about.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Outcome {
    /// The loop escaped (diverged) in realization `at` (1-based).
    Escaped { at: u32 },
    /// It rendered: `realizations` ran without an escape (the horizon, or
    /// fewer when decided passive earlier).
    Survived { realizations: u32 },
    /// It failed without escaping.
    Failed,
}

impl Outcome {
    pub fn failed(self) -> bool {
        !matches!(self, Outcome::Survived { .. })
    }
}

/// What the model of a map's columns shares: the lattice and the
/// likelihood tables.
#[derive(Debug, Clone)]
pub struct PsiModel {
    /// ln K at lattice point 0 and the step.
    ln_k0: f64,
    h: f64,
    n: usize,
    /// Lattice points of the smallest and the largest K a trial may use.
    floor: usize,
    cap: usize,
    /// The horizon H (realizations a trial runs at most).
    horizon: f64,
    /// Per β at offset d = m − i, stored at d + n − 1: the hazard over the
    /// horizon, λH = ln 2·e^{β·h·d}, and the probability of failing, P.
    hazard: Vec<Vec<f64>>,
    p_fail: Vec<Vec<f64>>,
    /// ln-likelihood tables (per β, at offset d + n − 1) of the outcomes
    /// most trials have: a failure without escape, an escape in the first
    /// realization, surviving the horizon.
    common: Vec<(Outcome, Vec<Vec<f64>>)>,
    /// For planning (`PsiColumn::ask`): the escape's realization in bins
    /// (a, b] doubling from 1 up to the horizon, then survival; per bin,
    /// β and offset, its probability; and a trial's expected realizations,
    /// E min(T, H) = (1 − e^{−λH})/(1 − e^{−λ}) for a geometric T.
    /// Per β: the bins' probabilities at offset d, stored at
    /// (d + n − 1)·outcomes + bin.
    p_bin: Vec<Vec<f64>>,
    outcomes: usize,
    cost: Vec<Vec<f64>>,
}

impl PsiModel {
    /// The model for trials between `k_floor` and `k_cap` (N/m, 0 <
    /// k_floor < k_cap). The lattice reaches a factor 2 below the floor and
    /// above the cap, so a column where nothing renders (K* below the
    /// floor) and one that renders up to the cap are told apart.
    pub fn new(k_floor: f64, k_cap: f64, horizon: u32) -> Self {
        let ln_k0 = k_floor.ln() - std::f64::consts::LN_2;
        let span = (k_cap / k_floor).ln().max(STEP);
        // At most MAX_POINTS between floor and cap (a posterior of ~400 kB).
        let h = STEP.max(span / MAX_POINTS as f64);
        let floor = (std::f64::consts::LN_2 / h).round() as usize;
        let cap = floor + (span / h).round() as usize;
        let n = cap + floor + 1;
        let table = |f: &dyn Fn(f64, f64) -> f64| -> Vec<Vec<f64>> {
            BETAS
                .iter()
                .map(|&beta| {
                    (0..2 * n - 1)
                        .map(|j| f(beta, h * (j as f64 - (n - 1) as f64)))
                        .collect()
                })
                .collect()
        };
        let hz = f64::from(horizon.max(1));
        let lambda = |beta: f64, d: f64| (std::f64::consts::LN_2 * (beta * d).exp()).min(1e6) / hz;
        let mut edges = vec![0u32];
        while *edges.last().unwrap_or(&0) < horizon.max(1) {
            let next = (2 * edges[edges.len() - 1]).max(1).min(horizon.max(1));
            edges.push(next);
        }
        let outcomes = edges.len();
        let p_bin: Vec<Vec<f64>> = BETAS
            .iter()
            .map(|&beta| {
                (0..2 * n - 1)
                    .flat_map(|j| {
                        let l = lambda(beta, h * (j as f64 - (n - 1) as f64));
                        let survive = (-l * hz).exp();
                        edges
                            .windows(2)
                            .map(move |e| {
                                (-l * f64::from(e[0])).exp() - (-l * f64::from(e[1])).exp()
                            })
                            .chain(std::iter::once(survive))
                    })
                    .collect()
            })
            .collect();
        let cost = table(&|beta, d| {
            let l = lambda(beta, d);
            if l < 1e-12 {
                hz
            } else {
                -(-l * hz).exp_m1() / -(-l).exp_m1()
            }
        });
        let mut model = Self {
            ln_k0,
            h,
            n,
            floor,
            cap,
            horizon: hz,
            p_bin,
            outcomes,
            cost,
            // Capped where e^{−λH} is 0 already: no inf·0 in the likelihood.
            hazard: table(&|beta, d| (std::f64::consts::LN_2 * (beta * d).exp()).min(1e6)),
            p_fail: table(&fail_probability),
            common: Vec::new(),
        };
        model.common = [
            Outcome::Failed,
            Outcome::Escaped { at: 1 },
            Outcome::Survived {
                realizations: horizon.max(1),
            },
        ]
        .into_iter()
        .map(|o| {
            let t = model
                .hazard
                .iter()
                .map(|row| row.iter().map(|&x| model.ln_like_computed(o, x)).collect())
                .collect();
            (o, t)
        })
        .collect();
        model
    }

    /// K at lattice point `m` (N/m).
    pub fn k(&self, m: usize) -> f64 {
        (self.ln_k0 + self.h * m as f64).exp()
    }

    /// The lattice point nearest K (N/m), within the lattice.
    pub fn lattice(&self, k: f64) -> usize {
        let m = ((k.max(f64::MIN_POSITIVE).ln() - self.ln_k0) / self.h).round();
        if m.is_nan() || m < 0.0 {
            0
        } else {
            (m as usize).min(self.n - 1)
        }
    }

    /// The smallest and largest K a trial may use (N/m).
    pub fn k_floor(&self) -> f64 {
        self.k(self.floor)
    }

    pub fn k_cap(&self) -> f64 {
        self.k(self.cap)
    }

    #[cfg(test)]
    /// P(fail | trial at m, boundary at i, β index j).
    fn p(&self, m: usize, i: usize, j: usize) -> f64 {
        self.p_fail[j][m + self.n - 1 - i]
    }

    /// ln P(outcome | trial at m, boundary at i, β index j), the lapse
    /// mixed in.
    #[cfg(test)]
    fn ln_like(&self, outcome: Outcome, m: usize, i: usize, j: usize) -> f64 {
        self.ln_like_at(outcome, j, m + self.n - 1 - i)
    }

    /// The same at table index `d` (offset + n − 1), from the tables of the
    /// common outcomes where there is one.
    #[cfg(test)]
    fn ln_like_at(&self, outcome: Outcome, j: usize, d: usize) -> f64 {
        match self.table(outcome) {
            Some(t) => t[j][d],
            None => self.ln_like_computed(outcome, self.hazard[j][d]),
        }
    }

    /// The table of ln-likelihoods of `outcome` (per β, at offset d + n −
    /// 1), if it is one of the common outcomes.
    fn table(&self, outcome: Outcome) -> Option<&[Vec<f64>]> {
        self.common
            .iter()
            .find(|(o, _)| *o == outcome)
            .map(|(_, t)| t.as_slice())
    }

    /// ln(2ε·L + (1 − 2ε)·P(outcome)) for a hazard over the horizon λH =
    /// `x`, where L is the outcome's probability under a lapse (a verdict
    /// that says nothing of K: fail or pass with ½ each, an escape's time
    /// uniform over the horizon).
    fn ln_like_computed(&self, outcome: Outcome, x: f64) -> f64 {
        let lambda = x / self.horizon;
        let model = match outcome {
            // e^{−λ(r−1)}·(1 − e^{−λ}): no escape in r − 1, one in the r-th.
            Outcome::Escaped { at } => {
                (-lambda * f64::from(at.max(1) - 1)).exp() * -(-lambda).exp_m1()
            }
            Outcome::Survived { realizations } => (-lambda * f64::from(realizations)).exp(),
            Outcome::Failed => -(-x).exp_m1(),
        };
        let lapse = match outcome {
            Outcome::Escaped { .. } => LAPSE / self.horizon,
            _ => LAPSE,
        };
        (lapse + (1.0 - 2.0 * LAPSE) * model).ln()
    }
}

/// Where a column's search stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PsiState {
    /// More trials would narrow the interval.
    Open,
    /// The interval is within the resolution asked.
    Resolved,
    /// K* lies below the smallest K searched: nothing renders, surely.
    Empty,
    /// K* lies above the largest K searched.
    AboveCap,
    /// The trial budget ran out first.
    Budget,
}

/// The posterior of one column and the trials told to it.
#[derive(Debug, Clone)]
pub struct PsiColumn {
    /// Log posterior (unnormalised), lattice-major: cell i·|β| + j.
    ln_post: Vec<f64>,
    /// Lattice points still carrying mass: lo..hi.
    lo: usize,
    hi: usize,
    /// The trials told, in order: lattice point and outcome.
    history: Vec<(usize, Outcome)>,
    /// The marginal posterior of K* on lo..hi (kept from the last tell).
    mg: Vec<f64>,
    /// The live cells' weights relative to the largest, and their sum
    /// (kept from the last tell: planning and the marginals read them).
    w: Vec<f64>,
    total: f64,
}

/// The posterior of one column's K* on the lattice.
#[derive(Debug, Clone, PartialEq)]
pub struct PsiMarginal {
    lo: usize,
    p: Vec<f64>,
    /// The marginal posterior of β over [`BETAS`].
    beta: [f64; BETAS.len()],
}

impl PsiMarginal {
    /// P(K* ≤ K at lattice point m).
    pub fn cdf(&self, m: usize) -> f64 {
        if m < self.lo {
            return 0.0;
        }
        self.p.iter().take(m - self.lo + 1).sum::<f64>().min(1.0)
    }

    /// P(K* > K at lattice point m).
    pub fn tail(&self, m: usize) -> f64 {
        (1.0 - self.cdf(m)).max(0.0)
    }

    /// The lattice point at quantile q.
    pub fn quantile(&self, q: f64) -> usize {
        PsiColumn::quantile(&self.p, self.lo, q)
    }
}

/// A column's prior from its neighbours' posteriors: K* log-normal, mixed
/// with the log-uniform ([`PRIOR_UNIFORM`]), on the lattice.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Prior {
    /// The centre, a (fractional) lattice point.
    pub centre: f64,
    /// The spread σ in lattice steps.
    pub sigma: f64,
    /// The prior of β: the neighbours' β posteriors averaged, mixed with
    /// the uniform as K*'s is (the steepness changes slowly with B, and a
    /// column whose trials cluster near its prior's centre learns little
    /// of it by itself).
    pub beta: [f64; BETAS.len()],
}

impl Prior {
    /// Between two neighbours (the columns next to it on either side): the
    /// centre halfway between their medians in ln K (a boundary straight
    /// between them), the spread from the larger of [`PRIOR_SPREAD`] and
    /// half their gap, with each one's own uncertainty (its 90 % interval
    /// as ±1.645σ) added in quadrature.
    pub fn between(model: &PsiModel, a: &PsiMarginal, b: &PsiMarginal) -> Self {
        let med = |m: &PsiMarginal| m.quantile(0.5) as f64;
        let sd = |m: &PsiMarginal| (m.quantile(0.95) - m.quantile(0.05)) as f64 / (2.0 * 1.645);
        let gap = (med(a) - med(b)).abs() / 2.0;
        let smooth = PRIOR_SPREAD / model.h;
        let sigma = (gap.max(smooth).powi(2) + sd(a).powi(2) + sd(b).powi(2))
            .sqrt()
            .max(1.0);
        let mut beta = [0.0; BETAS.len()];
        for (j, p) in beta.iter_mut().enumerate() {
            *p = (1.0 - PRIOR_UNIFORM) * (a.beta[j] + b.beta[j]) / 2.0
                + PRIOR_UNIFORM / BETAS.len() as f64;
        }
        Self {
            centre: (med(a) + med(b)) / 2.0,
            sigma,
            beta,
        }
    }
}

/// The largest K* over columns whose posteriors are independent (each
/// column's trials are its own) (N/m): the largest of the columns'
/// medians, as every search states the K-width; below it the largest of
/// their lower ends (the column whose lower end that is lies above it with
/// posterior probability α at most); above it the 1 − α quantile of the
/// largest, from P(max ≤ K) = Π_c P(K*_c ≤ K) — on a plateau of many
/// columns it lies above every column's own upper end: each of them may be
/// the largest.
pub fn max_estimate(model: &PsiModel, columns: &[PsiMarginal], alpha: f64) -> PsiEstimate {
    let k = |m: usize| {
        if m < model.floor {
            0.0
        } else {
            model.k(m.min(model.cap))
        }
    };
    let largest = |q: f64| columns.iter().map(|c| c.quantile(q)).max().unwrap_or(0);
    let lo = columns.iter().map(|c| c.lo).min().unwrap_or(0);
    let hi = columns
        .iter()
        .map(|c| c.lo + c.p.len())
        .max()
        .unwrap_or(0)
        .min(model.n);
    // Running CDFs, one pass over the lattice, to the first point where
    // the product reaches 1 − α.
    let mut acc: Vec<f64> = vec![0.0; columns.len()];
    let mut upper = hi.saturating_sub(1);
    for m in lo..hi {
        let mut prod = 1.0;
        for (a, c) in acc.iter_mut().zip(columns) {
            if m >= c.lo && m < c.lo + c.p.len() {
                *a += c.p[m - c.lo];
            }
            prod *= a.min(1.0);
        }
        if prod >= 1.0 - alpha {
            upper = m;
            break;
        }
    }
    PsiEstimate {
        k_lo: k(largest(alpha)),
        k_mid: k(largest(0.5)),
        k_hi: k(upper),
    }
}

/// A column's boundary: the posterior median and the quantiles at α and
/// 1 − α of K* (N/m); 0 below the floor, the cap above it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PsiEstimate {
    pub k_lo: f64,
    pub k_mid: f64,
    pub k_hi: f64,
}

impl PsiColumn {
    /// A column knowing nothing: K* log-uniform over the lattice, β uniform
    /// over [`BETAS`].
    pub fn new(model: &PsiModel) -> Self {
        Self {
            ln_post: vec![0.0; model.n * BETAS.len()],
            lo: 0,
            hi: model.n,
            history: Vec::new(),
            mg: vec![1.0 / model.n as f64; model.n],
            w: vec![1.0; model.n * BETAS.len()],
            total: (model.n * BETAS.len()) as f64,
        }
    }

    /// A column starting from `prior` (its neighbours' estimate of K* and
    /// of β), or knowing nothing.
    pub fn with_prior(model: &PsiModel, prior: Option<Prior>) -> Self {
        let mut c = Self::new(model);
        if let Some(p) = prior {
            let nb = BETAS.len();
            let uniform = PRIOR_UNIFORM / model.n as f64;
            for i in 0..model.n {
                // (1 − w)·N(i; μ, σ) + w/n on the lattice (σ in steps).
                let z = (i as f64 - p.centre) / p.sigma;
                let normal = (-0.5 * z * z).exp() / (p.sigma * (2.0 * std::f64::consts::PI).sqrt());
                let ln = ((1.0 - PRIOR_UNIFORM) * normal + uniform).ln();
                for (j, &pb) in p.beta.iter().enumerate() {
                    c.ln_post[i * nb + j] = ln + pb.ln();
                }
            }
            c.settle();
        }
        c
    }

    /// The column from `prior`, told `history` in order (what
    /// [`PsiColumn::history`] returned): a column need not be kept between
    /// passes.
    pub fn from_history(
        model: &PsiModel,
        prior: Option<Prior>,
        history: &[(usize, Outcome)],
    ) -> Self {
        let mut c = Self::with_prior(model, prior);
        for &(m, outcome) in history {
            c.tell(model, m, outcome);
        }
        c
    }

    /// Trials told so far.
    pub fn trials(&self) -> usize {
        self.history.len()
    }

    /// The trials told, in order.
    pub fn history(&self) -> &[(usize, Outcome)] {
        &self.history
    }

    /// Tell the outcome of a trial at lattice point `m`.
    pub fn tell(&mut self, model: &PsiModel, m: usize, outcome: Outcome) {
        let nb = BETAS.len();
        // The outcome's table looked up once, not per cell.
        let table = model.table(outcome);
        for i in self.lo..self.hi {
            let d = m + model.n - 1 - i;
            let cells = &mut self.ln_post[i * nb..(i + 1) * nb];
            match table {
                Some(t) => {
                    for (j, c) in cells.iter_mut().enumerate() {
                        *c += t[j][d];
                    }
                }
                None => {
                    for (j, c) in cells.iter_mut().enumerate() {
                        *c += model.ln_like_computed(outcome, model.hazard[j][d]);
                    }
                }
            }
        }
        self.history.push((m, outcome));
        self.settle();
    }

    /// Drop the lattice ends that carry no mass; the marginal again.
    fn settle(&mut self) {
        let nb = BETAS.len();
        let top = self.ln_post[self.lo * nb..self.hi * nb]
            .iter()
            .fold(f64::NEG_INFINITY, |a, &b| a.max(b));
        let alive = |i: usize| {
            self.ln_post[i * nb..(i + 1) * nb]
                .iter()
                .any(|&v| v > top - PRUNE)
        };
        while self.lo + 1 < self.hi && !alive(self.lo) {
            self.lo += 1;
        }
        while self.hi > self.lo + 1 && !alive(self.hi - 1) {
            self.hi -= 1;
        }
        // The weights relative to the largest cell (alive, so within lo..hi).
        let cells = &self.ln_post[self.lo * nb..self.hi * nb];
        self.w.clear();
        self.w.extend(cells.iter().map(|&v| (v - top).exp()));
        self.total = self.w.iter().sum();
        let total = self.total;
        self.mg = self
            .w
            .chunks(nb)
            .map(|c| c.iter().sum::<f64>() / total)
            .collect();
    }

    /// The weights of the live cells (relative to the largest) and their
    /// sum, as the last tell left them.
    fn weights(&self) -> (&[f64], f64) {
        (&self.w, self.total)
    }

    /// The marginal posterior of K* on the live lattice points lo..hi.
    fn marginal(&self) -> &[f64] {
        &self.mg
    }

    /// The lattice point at posterior quantile q of K*.
    fn quantile(marginal: &[f64], lo: usize, q: f64) -> usize {
        let mut acc = 0.0;
        for (i, p) in marginal.iter().enumerate() {
            acc += p;
            if acc >= q {
                return lo + i;
            }
        }
        lo + marginal.len().saturating_sub(1)
    }

    /// Posterior probability that K* lies below the lattice point `m`.
    fn below(marginal: &[f64], lo: usize, m: usize) -> f64 {
        marginal.iter().take(m.saturating_sub(lo)).sum()
    }

    /// The boundary at credibility 1 − 2α (each end wrong with posterior
    /// probability α).
    pub fn estimate(&self, model: &PsiModel, alpha: f64) -> PsiEstimate {
        let mg = self.marginal();
        let at = |q: f64| Self::quantile(mg, self.lo, q);
        let k = |m: usize| {
            if m < model.floor {
                0.0
            } else {
                model.k(m.min(model.cap))
            }
        };
        PsiEstimate {
            k_lo: k(at(alpha)),
            k_mid: k(at(0.5)),
            k_hi: k(at(1.0 - alpha)),
        }
    }

    /// The marginal posterior of K*, kept for the map's K-width
    /// (`max_estimate`) without the column's posterior.
    pub fn marginal_of(&self) -> PsiMarginal {
        // The lattice ends carrying less than 1e-12 are dropped.
        let mg = self.marginal();
        let first = mg.iter().position(|&p| p > 1e-12).unwrap_or(0);
        let last = mg.iter().rposition(|&p| p > 1e-12).unwrap_or(0).max(first);
        let nb = BETAS.len();
        let (w, total) = self.weights();
        let mut beta = [0.0; BETAS.len()];
        for (j, b) in beta.iter_mut().enumerate() {
            *b = w.iter().skip(j).step_by(nb).sum::<f64>() / total;
        }
        PsiMarginal {
            lo: self.lo + first,
            p: mg[first..=last].to_vec(),
            beta,
        }
    }

    /// Where the column stands against a half-width `rel_tol` (relative)
    /// of its interval at credibility 1 − 2α, with at most `budget` trials.
    pub fn state(&self, model: &PsiModel, alpha: f64, rel_tol: f64, budget: usize) -> PsiState {
        let mg = self.marginal();
        if Self::below(mg, self.lo, model.floor) >= 1.0 - alpha {
            return PsiState::Empty;
        }
        if 1.0 - Self::below(mg, self.lo, model.cap + 1) >= 1.0 - alpha {
            return PsiState::AboveCap;
        }
        let lo = Self::quantile(mg, self.lo, alpha);
        let hi = Self::quantile(mg, self.lo, 1.0 - alpha);
        let (k_lo, k_hi) = (model.k(lo), model.k(hi));
        if (k_hi - k_lo) <= rel_tol * (k_hi + k_lo) {
            return PsiState::Resolved;
        }
        if self.trials() >= budget {
            return PsiState::Budget;
        }
        PsiState::Open
    }

    /// The lattice point of the next trial: among the posterior's
    /// quantiles of K* and points above its bulk (between the floor and the
    /// cap), the one whose outcome removes the most expected posterior
    /// variance of ln K* per realization it is expected to cost.
    pub fn ask(&self, model: &PsiModel) -> usize {
        let mg = self.marginal();
        let q = |p: f64| Self::quantile(mg, self.lo, p);
        let (q25, q50, q75) = (q(0.25), q(0.5), q(0.75));
        let iqr = (q75 - q25).max(1) as f64;
        let mut candidates: Vec<usize> = [0.05, 0.2, 0.35, 0.5, 0.65, 0.8, 0.95]
            .iter()
            .map(|&p| q(p))
            // Above the bulk too: where escapes come quickly.
            .chain([1.0, 2.0, 3.0].iter().map(|&c| q50 + (c * iqr) as usize))
            .map(|m| m.clamp(model.floor, model.cap))
            .collect();
        candidates.sort_unstable();
        candidates.dedup();
        // The outcomes to plan with: an escape's time where this column's
        // failures have been escapes, else fail or pass alone.
        let escapes = self
            .history
            .iter()
            .any(|(_, o)| matches!(o, Outcome::Escaped { .. }));
        let failed = self.history.iter().any(|(_, o)| *o == Outcome::Failed);
        let timed = escapes && !failed;
        let (w, _) = self.weights();
        let nb = BETAS.len();
        // The cells that carry the posterior (those below 1e-6 of the
        // largest change no decision), lumped into at most PLAN_POINTS
        // blocks of neighbouring lattice points (planning needs no finer
        // a lattice): block centre, β index, weight.
        // Lumped over the lattice points that carry mass, not over lo..hi:
        // a block must stay narrow against the posterior's spread.
        let first = mg.iter().position(|&p| p > 1e-10).unwrap_or(0);
        let last = mg.iter().rposition(|&p| p > 1e-10).unwrap_or(0).max(first);
        let stride = (last + 1 - first).div_ceil(PLAN_POINTS).max(1);
        let mut live: Vec<(usize, usize, f64)> = Vec::new();
        let cells = &w[first * nb..(last + 1) * nb];
        for (bi, block) in cells.chunks(stride * nb).enumerate() {
            let centre = (self.lo + first + bi * stride + (stride - 1) / 2).min(self.hi - 1);
            for j in 0..nb {
                let wc: f64 = block.iter().skip(j).step_by(nb).sum();
                if wc >= 1e-6 {
                    live.push((centre, j, wc));
                }
            }
        }
        let total: f64 = live.iter().map(|c| c.2).sum();
        let u_mean: f64 = live.iter().map(|&(i, _, wc)| wc * i as f64).sum::<f64>() / total;
        let var_now: f64 = live
            .iter()
            .map(|&(i, _, wc)| wc * (i as f64 - u_mean).powi(2))
            .sum::<f64>()
            / total;
        let outcomes = if timed { model.outcomes } else { 2 };
        let mut best = (f64::NEG_INFINITY, candidates[0]);
        for &m in &candidates {
            // Σ w·P, Σ w·P·u, Σ w·P·u² for each outcome (u = lattice index,
            // centred), and the expected realizations.
            let mut s = vec![[0.0f64; 3]; outcomes];
            let mut cost = 0.0;
            for &(i, j, wc) in &live {
                let d = m + model.n - 1 - i;
                let u = i as f64 - u_mean;
                cost += wc * model.cost[j][d];
                let mut add = |o: usize, p: f64| {
                    let wp = wc * p;
                    s[o][0] += wp;
                    s[o][1] += wp * u;
                    s[o][2] += wp * u * u;
                };
                if timed {
                    let bins = &model.p_bin[j][d * outcomes..(d + 1) * outcomes];
                    for (o, &p) in bins.iter().enumerate() {
                        add(o, p);
                    }
                } else {
                    let pf = model.p_fail[j][d];
                    add(0, pf);
                    add(1, 1.0 - pf);
                }
            }
            let expected: f64 = s
                .iter()
                .filter(|t| t[0] > 0.0)
                .map(|t| t[2] - t[1] * t[1] / t[0])
                .sum::<f64>()
                / total;
            // Variance removed per realization expected, a trial's start
            // (its transient, on a rig its setting up) counted as one more.
            let score = (var_now - expected) / (cost / total + TRIAL_OVERHEAD);
            if score > best.0 {
                best = (score, m);
            }
        }
        best.1
    }

    /// Trials told at lattice point `m` so far (a repeat runs at a K
    /// distinct in its bits: `repeat_k`).
    pub fn repeats(&self, m: usize) -> usize {
        self.history.iter().filter(|&&(t, _)| t == m).count()
    }
}

#[cfg(test)]
#[path = "psi_tests.rs"]
mod tests;
