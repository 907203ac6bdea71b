use super::*;
use crate::zwidth::stats::SplitMix64;

#[test]
fn the_likelihood_is_kontsevich_and_tylers_weibull_with_its_threshold_at_one_half() {
    // F(K*) = 1 − e^{−ln 2} = ½ exactly, so P = ε + (1 − 2ε)/2 = ½.
    assert!((fail_probability(40.0, 0.0) - 0.5).abs() < 1e-15);
    // At K = K*·e^{0.05} with β = 20: F = 1 − exp(−ln 2 · e^1) (computed
    // by hand: e = 2.718281828…, ln 2 · e = 1.884169…, 1 − e^−1.884169 =
    // 0.848045), P = 0.02 + 0.96·F.
    let f = 1.0 - (-std::f64::consts::LN_2 * std::f64::consts::E).exp();
    assert!((f - 0.848_045).abs() < 1e-6, "{f}");
    assert!((fail_probability(20.0, 0.05) - (0.02 + 0.96 * f)).abs() < 1e-15);
    // Far below the boundary only the lapse fails; far above only it passes.
    assert!((fail_probability(40.0, -1.0) - LAPSE).abs() < 1e-15);
    assert!((fail_probability(40.0, 1.0) - (1.0 - LAPSE)).abs() < 1e-15);
    // The tables hold it at the lattice's offsets: a failure without an
    // escape tells P, surviving the horizon 1 − P.
    let model = PsiModel::new(1000.0, 1e6, 24);
    let (m, i, j) = (model.floor + 500, model.floor + 475, 3);
    let want = fail_probability(BETAS[j], STEP * 25.0);
    assert!((model.p(m, i, j) - want).abs() < 1e-15);
    assert!((model.ln_like(Outcome::Failed, m, i, j) - want.ln()).abs() < 1e-12);
    let survived = Outcome::Survived { realizations: 24 };
    assert!((model.ln_like(survived, m, i, j) - (1.0 - want).ln()).abs() < 1e-12);
}

#[test]
fn an_escape_tells_its_time_by_the_exposure_likelihood() {
    // λ per realization = ln 2·e^{β·d}/H (F = 1 − e^{−λH}). An escape in
    // realization r: e^{−λ(r−1)}·(1 − e^{−λ}); surviving n: e^{−λn}; a
    // lapse (probability 2ε) fails or passes with ½ each, an escape's time
    // uniform over the H realizations. Computed here from the formula, at
    // an offset no table of common outcomes holds (r = 5, n = 7).
    let model = PsiModel::new(1000.0, 1e6, 24);
    let (m, i, j) = (model.floor + 510, model.floor + 500, 5);
    let lambda = std::f64::consts::LN_2 * (BETAS[j] * STEP * 10.0).exp() / 24.0;
    let mix = |lapse: f64, p: f64| (lapse + (1.0 - 2.0 * LAPSE) * p).ln();
    let escaped = (-4.0 * lambda).exp() * (1.0 - (-lambda).exp());
    let got = model.ln_like(Outcome::Escaped { at: 5 }, m, i, j);
    assert!((got - mix(LAPSE / 24.0, escaped)).abs() < 1e-12, "{got}");
    let got = model.ln_like(Outcome::Survived { realizations: 7 }, m, i, j);
    assert!(
        (got - mix(LAPSE, (-7.0 * lambda).exp())).abs() < 1e-12,
        "{got}"
    );
    // The tabled common outcomes agree with the formula.
    let got = model.ln_like(Outcome::Escaped { at: 1 }, m, i, j);
    assert!((got - mix(LAPSE / 24.0, 1.0 - (-lambda).exp())).abs() < 1e-12);
    // An escape in the first realization far above the boundary, with
    // the hazard capped: finite (no inf·0).
    assert!(model
        .ln_like(Outcome::Escaped { at: 1 }, model.cap, model.floor, 8)
        .is_finite());
    assert!(model
        .ln_like(Outcome::Escaped { at: 3 }, model.cap, model.floor, 8)
        .is_finite());
}

#[test]
fn the_lattice_spans_a_factor_two_beyond_the_floor_and_the_cap() {
    let model = PsiModel::new(1000.0, 1e6, 24);
    assert!(model.lattice(model.k(1234)) == 1234 && model.lattice(1e-300) == 0);
    assert!((model.k_floor() / 1000.0 - 1.0).abs() < STEP);
    assert!((model.k_cap() / 1e6 - 1.0).abs() < STEP);
    assert!((model.k(0) / 500.0 - 1.0).abs() < STEP);
    assert!((model.k(model.n - 1) / 2e6 - 1.0).abs() < 2.0 * STEP);
}

/// Run a column against the model's own law (boundary `k_star`,
/// steepness `beta`, horizon 24) until it is no longer open: escapes at a
/// constant hazard per realization when `timed`, else pass or fail alone.
/// Its estimate, trials, realizations and state.
fn simulate(
    k_star: f64,
    beta: f64,
    seed: u64,
    rel_tol: f64,
    timed: bool,
) -> (PsiEstimate, usize, u32, PsiState) {
    let model = PsiModel::new(1488.24, 1e7, 24);
    let (e, t, r, state, _) = simulate_from(&model, None, k_star, beta, seed, rel_tol, timed);
    (e, t, r, state)
}

/// The same from `prior`; also the column's marginal at the end.
fn simulate_from(
    model: &PsiModel,
    prior: Option<Prior>,
    k_star: f64,
    beta: f64,
    seed: u64,
    rel_tol: f64,
    timed: bool,
) -> (PsiEstimate, usize, u32, PsiState, PsiMarginal) {
    let model = model.clone();
    let mut col = PsiColumn::with_prior(&model, prior);
    let mut rng = SplitMix64::new(seed);
    let alpha = 0.05;
    let mut realizations = 0;
    loop {
        let state = col.state(&model, alpha, rel_tol, 200);
        if state != PsiState::Open {
            return (
                col.estimate(&model, alpha),
                col.trials(),
                realizations,
                state,
                col.marginal_of(),
            );
        }
        let m = col.ask(&model);
        let d = (model.k(m) / k_star).ln();
        let outcome = if timed {
            let lambda = std::f64::consts::LN_2 * (beta * d).exp() / 24.0;
            (1..=24)
                .find(|_| rng.next_f64() < -(-lambda).exp_m1())
                .map_or(Outcome::Survived { realizations: 24 }, |at| {
                    Outcome::Escaped { at }
                })
        } else if rng.next_f64() < fail_probability(beta, d) {
            Outcome::Failed
        } else {
            Outcome::Survived { realizations: 24 }
        };
        realizations += match outcome {
            Outcome::Escaped { at } => at,
            _ => 24,
        };
        col.tell(&model, m, outcome);
    }
}

/// Coverage of `n` columns resolved to ±1 % (each end wrong with
/// posterior probability 5 %, so 90 % nominal) and their mean cost.
fn coverage(beta: f64, timed: bool, n: u64, rel_tol: f64) -> (u64, f64, f64) {
    let k_star = 4.2e5;
    let (mut covered, mut trials, mut realizations) = (0, 0, 0);
    for seed in 0..n {
        let (e, t, r, state) = simulate(k_star, beta, seed, rel_tol, timed);
        assert_eq!(
            state,
            PsiState::Resolved,
            "seed {seed}: {e:?} after {t} trials"
        );
        assert!(e.k_lo <= e.k_mid && e.k_mid <= e.k_hi);
        // Resolved: half-width within 1 % (the quantiles sit on the lattice).
        assert!((e.k_hi - e.k_lo) <= (2.0 * rel_tol + 2.0 * STEP) * (e.k_hi + e.k_lo) / 2.0);
        covered += u64::from(e.k_lo <= k_star && k_star <= e.k_hi);
        trials += t;
        realizations += r;
    }
    (
        covered,
        trials as f64 / n as f64,
        f64::from(realizations) / n as f64,
    )
}

#[test]
fn intervals_cover_the_boundary_at_their_stated_level() {
    // 300 columns of the seed device's shape (K* = 4.2e5 N/m, β = 40:
    // docs/zwidth.md's fit at B = 238) resolved to ±1 %, the loop escaping
    // at a constant hazard. At 90 % coverage at least 250 of 300 cover with
    // probability 0.9999, at 80 % with probability 0.08 (binomial tails,
    // computed exactly). (Measured 2026-12-07: 260 of 300, 87 %: stopping
    // once the interval is narrow costs a little coverage, docs/zwidth.md.)
    let (covered, trials, realizations) = coverage(40.0, true, 300, 0.01);
    assert!(
        covered >= 250,
        "covered {covered} of 300 ({trials} trials a column)"
    );
    // The Fisher information of one realization about ln K* is β²·λ
    // (Poisson exposure), λ = ln 2/24 at the boundary: a standard error of
    // 1 %/1.645 takes 1/(1600·0.0289·(0.01/1.645)²) ≈ 580 realizations
    // there, fewer where escapes come faster above it. A search that needs
    // twice as many is broken; one that needs a fifth cannot be honest.
    assert!(
        (120.0..1200.0).contains(&realizations),
        "{realizations} realizations, {trials} trials"
    );
}

#[test]
fn pass_or_fail_alone_covers_too() {
    // Verdicts without an escape's time (Re Z crossing zero): the Weibull
    // alone, β = 25, resolved to ±2 %. 120 columns at 90 %: at least 100
    // cover with probability 0.992 (binomial).
    let (covered, _, _) = coverage(25.0, false, 120, 0.02);
    assert!(covered >= 100, "covered {covered} of 120");
}

#[test]
fn a_column_where_every_trial_fails_is_empty_and_one_where_none_does_reaches_the_cap() {
    let model = PsiModel::new(1488.24, 1e7, 24);
    let mut col = PsiColumn::new(&model);
    while col.state(&model, 0.05, 0.01, 200) == PsiState::Open {
        let m = col.ask(&model);
        col.tell(&model, m, Outcome::Escaped { at: 1 });
        assert!(
            col.trials() < 60,
            "still open after {} escapes",
            col.trials()
        );
    }
    assert_eq!(col.state(&model, 0.05, 0.01, 200), PsiState::Empty);
    let e = col.estimate(&model, 0.05);
    assert_eq!((e.k_lo, e.k_mid, e.k_hi), (0.0, 0.0, 0.0));

    let mut col = PsiColumn::new(&model);
    while col.state(&model, 0.05, 0.01, 200) == PsiState::Open {
        let m = col.ask(&model);
        col.tell(&model, m, Outcome::Survived { realizations: 24 });
        assert!(col.trials() < 60);
    }
    assert_eq!(col.state(&model, 0.05, 0.01, 200), PsiState::AboveCap);
    let e = col.estimate(&model, 0.05);
    assert_eq!(e.k_hi, model.k_cap());
}

#[test]
fn the_budget_ends_a_column_and_a_repeat_runs_at_a_k_of_its_own() {
    // A coin at every K: the posterior never narrows to 1 %.
    let model = PsiModel::new(1488.24, 1e7, 24);
    let mut col = PsiColumn::new(&model);
    let mut rng = SplitMix64::new(9);
    let mut seen = std::collections::BTreeSet::new();
    while col.state(&model, 0.05, 0.01, 30) == PsiState::Open {
        let m = col.ask(&model);
        assert!((model.floor..=model.cap).contains(&m));
        let k = repeat_k(model.k(m), col.repeats(m));
        assert!(seen.insert(k.to_bits()), "K {k} twice");
        assert!(k <= model.k(m) && model.lattice(k) == m);
        let o = if rng.next_f64() < 0.5 {
            Outcome::Failed
        } else {
            Outcome::Survived { realizations: 24 }
        };
        col.tell(&model, m, o);
    }
    assert_eq!(col.state(&model, 0.05, 0.01, 30), PsiState::Budget);
    assert_eq!(col.trials(), 30);
    // Rebuilt from its history, the column is the same.
    let again = PsiColumn::from_history(&model, None, col.history());
    assert_eq!(again.estimate(&model, 0.05), col.estimate(&model, 0.05));
    assert_eq!(again.ask(&model), col.ask(&model));
    assert_eq!(repeat_k(1e5, 0), 1e5);
    assert_eq!(repeat_k(1e5, 3), 1e5 * (1.0 - 3e-9));
}

#[test]
fn the_largest_boundary_over_columns_multiplies_their_distributions_above() {
    // Two columns with the same posterior, resolved: the largest of two
    // independent draws has CDF F², so its upper end is F's √0.95
    // quantile, above either column's; its median and lower end are the
    // columns' own (the largest median, the largest lower end).
    let model = PsiModel::new(1488.24, 1e7, 24);
    let one = {
        let mut col = PsiColumn::new(&model);
        let mut rng = SplitMix64::new(3);
        while col.state(&model, 0.05, 0.02, 200) == PsiState::Open {
            let m = col.ask(&model);
            let d = (model.k(m) / 2e5).ln();
            let o = if rng.next_f64() < fail_probability(25.0, d) {
                Outcome::Failed
            } else {
                Outcome::Survived { realizations: 24 }
            };
            col.tell(&model, m, o);
        }
        col
    };
    let mg = one.marginal_of();
    let alone = max_estimate(&model, std::slice::from_ref(&mg), 0.05);
    assert_eq!(
        alone,
        one.estimate(&model, 0.05),
        "one column: its own quantiles"
    );
    let two = max_estimate(&model, &[mg.clone(), mg.clone()], 0.05);
    let quantile = |q: f64| {
        let m = (0..model.n).find(|&m| mg.cdf(m) >= q).unwrap();
        model.k(m)
    };
    assert_eq!((two.k_lo, two.k_mid), (alone.k_lo, alone.k_mid));
    assert_eq!(two.k_hi, quantile(0.95f64.sqrt()));
    assert!(two.k_hi > alone.k_hi);
    // A column far below changes nothing.
    let mut low = PsiColumn::new(&model);
    for _ in 0..6 {
        let m = model.lattice(2e4);
        low.tell(&model, m, Outcome::Escaped { at: 1 });
    }
    let with_low = max_estimate(&model, &[mg.clone(), low.marginal_of()], 0.05);
    assert_eq!(with_low, alone);
}

/// Two neighbours resolved to ±4 % at `k_a` and `k_b` (N/m), β = 40: the
/// prior between them.
fn neighbours_prior(model: &PsiModel, k_a: f64, k_b: f64, seed: u64) -> Prior {
    let (.., a) = simulate_from(model, None, k_a, 40.0, seed, 0.04, true);
    let (.., b) = simulate_from(model, None, k_b, 40.0, seed + 1000, 0.04, true);
    Prior::between(model, &a, &b)
}

#[test]
fn a_prior_between_neighbours_sits_halfway_in_ln_k_and_spreads_with_their_gap() {
    let model = PsiModel::new(1488.24, 1e7, 24);
    let p = neighbours_prior(&model, 4.0e5, 4.0e5, 1);
    // Halfway in ln K: within the neighbours' ±4 % of ln 4e5.
    let centre = model.k(p.centre.round() as usize);
    assert!((centre / 4.0e5 - 1.0).abs() < 0.04, "{centre}");
    // Neighbours that agree: at least PRIOR_SPREAD, in lattice steps.
    assert!(p.sigma >= PRIOR_SPREAD / STEP, "{p:?}");
    // Neighbours a factor 2 apart: at least half their gap (ln 2 / 2).
    let wide = neighbours_prior(&model, 2.0e5, 4.0e5, 1);
    assert!(
        wide.sigma * STEP >= 0.95 * std::f64::consts::LN_2 / 2.0,
        "{wide:?}"
    );
    let halfway = model.k(wide.centre.round() as usize);
    assert!(
        (halfway / (2.0e5f64 * 4.0e5).sqrt() - 1.0).abs() < 0.04,
        "{halfway}"
    );
}

#[test]
fn a_neighbour_prior_saves_trials_where_the_boundary_is_smooth() {
    // Both neighbours and the column at K* = 4.2e5 (a smooth boundary):
    // 60 columns to ±4 % (the first pass's resolution) from the prior and
    // 60 from nothing, the same draws.
    let model = PsiModel::new(1488.24, 1e7, 24);
    let (mut with, mut without, mut covered) = (0, 0, 0);
    for seed in 0..60 {
        let prior = neighbours_prior(&model, 4.2e5, 4.2e5, 500 + seed);
        let (e, t, ..) = simulate_from(&model, Some(prior), 4.2e5, 40.0, seed, 0.04, true);
        let (_, t0, ..) = simulate_from(&model, None, 4.2e5, 40.0, seed, 0.04, true);
        with += t;
        without += t0;
        covered += u64::from(e.k_lo <= 4.2e5 && 4.2e5 <= e.k_hi);
    }
    // The uninformed column starts from a lattice spanning 6 700× (the
    // seed device's floor to 1e7 N/m): halving that to ±4 % takes ~13
    // bits; the prior's σ of 5 % leaves ~1.
    assert!(
        4 * with < 3 * without,
        "{with} trials with the prior, {without} without"
    );
    // 90 % nominal: at least 48 of 60 with probability 0.98 (binomial).
    assert!(covered >= 48, "{covered} of 60");
}

#[test]
fn a_jump_between_neighbours_is_still_found() {
    // The neighbours agree at 2e5 N/m; the column's own boundary is twice
    // that (the seed device's boundary jumps by half between B = 74 and
    // 89 N·s/m, docs/zwidth.md): ~13σ outside the prior's log-normal part,
    // inside its log-uniform part (PRIOR_UNIFORM). Resolved to ±1 %, its
    // interval covers its own boundary at the stated 90 % (at least 48 of
    // 60 with probability 0.98, binomial), and never stops short of it.
    // (With no log-uniform part the prior prunes the lattice ~7.7σ above
    // its centre, ~3.05e5 here, and the columns end there: checked
    // 2026-12-07 with PRIOR_UNIFORM = 0, this test fails.)
    let model = PsiModel::new(1488.24, 1e7, 24);
    let (mut covered, mut trials) = (0, 0);
    for seed in 0..60 {
        let prior = neighbours_prior(&model, 2.0e5, 2.0e5, 500 + seed);
        let (e, t, _, state, _) = simulate_from(&model, Some(prior), 4.0e5, 40.0, seed, 0.01, true);
        assert_eq!(state, PsiState::Resolved, "seed {seed}: {e:?}");
        assert!(
            e.k_lo > 3.6e5,
            "seed {seed}: {e:?} stuck at the neighbours'"
        );
        covered += u64::from(e.k_lo <= 4.0e5 && 4.0e5 <= e.k_hi);
        trials += t;
    }
    assert!(covered >= 48, "{covered} of 60 ({trials} trials)");
}

/// A marginal uniform over the lattice points lo..lo + n.
fn uniform_marginal(lo: usize, n: usize) -> PsiMarginal {
    PsiMarginal {
        lo,
        p: vec![1.0 / n as f64; n],
        beta: [1.0 / BETAS.len() as f64; BETAS.len()],
    }
}

#[test]
fn a_prior_s_spread_adds_each_neighbour_s_own_in_quadrature() {
    // Two neighbours uniform over 331 lattice points from 1000: their
    // quantiles by hand (the first point where the running sum reaches q,
    // k + 1 ≥ 331q): 5 % at 1016, ½ at 1165, 95 % at 1314, so each σ is
    // (1314 − 1016)/(2·1.645) = 90.58 steps; no gap, so the smooth part
    // is PRIOR_SPREAD/STEP = 25 steps: σ = √(25² + 2·90.58²) = 130.52.
    let model = PsiModel::new(1488.24, 1e7, 24);
    let a = uniform_marginal(1000, 331);
    assert_eq!(
        (a.quantile(0.05), a.quantile(0.5), a.quantile(0.95)),
        (1016, 1165, 1314)
    );
    let p = Prior::between(&model, &a, &a);
    let sd: f64 = 298.0 / 3.29;
    assert!(
        (p.sigma - (625.0 + 2.0 * sd * sd).sqrt()).abs() < 1e-9,
        "{p:?}"
    );
    assert_eq!(p.centre, 1165.0);
    // A neighbour 400 steps above: the gap's half (200) replaces the
    // smooth part and the centre lies halfway.
    let b = uniform_marginal(1400, 331);
    let p = Prior::between(&model, &a, &b);
    assert!(
        (p.sigma - (200.0f64.powi(2) + 2.0 * sd * sd).sqrt()).abs() < 1e-9,
        "{p:?}"
    );
    assert_eq!(p.centre, 1365.0);
}

#[test]
fn a_quantile_past_the_mass_is_the_last_point() {
    // Half the mass on 10 points (a marginal cut at its ends): every
    // quantile above ½ is the last point, 20 + 9.
    let mut m = uniform_marginal(20, 10);
    for p in &mut m.p {
        *p /= 2.0;
    }
    assert_eq!(m.quantile(0.9), 29);
    assert_eq!(m.quantile(0.04), 20);
}

#[test]
fn a_prior_s_beta_is_the_neighbours_averaged_with_a_little_of_the_uniform() {
    // One neighbour sure of the smallest β, the other of the largest: the
    // prior halves them and gives every β PRIOR_UNIFORM/9 besides.
    let model = PsiModel::new(1488.24, 1e7, 24);
    let (mut a, mut b) = (uniform_marginal(1000, 331), uniform_marginal(1000, 331));
    a.beta = [0.0; BETAS.len()];
    a.beta[0] = 1.0;
    b.beta = [0.0; BETAS.len()];
    b.beta[BETAS.len() - 1] = 1.0;
    let p = Prior::between(&model, &a, &b);
    let floor = PRIOR_UNIFORM / 9.0;
    let half = (1.0 - PRIOR_UNIFORM) / 2.0 + floor;
    for (j, &w) in p.beta.iter().enumerate() {
        let want = if j == 0 || j == BETAS.len() - 1 {
            half
        } else {
            floor
        };
        assert!((w - want).abs() < 1e-15, "β index {j}: {w}");
    }
    assert!((p.beta.iter().sum::<f64>() - 1.0).abs() < 1e-12);
}

#[test]
fn a_column_from_a_prior_starts_as_its_mixture() {
    // Told nothing, a column from the prior (centre 2000, σ 50 lattice
    // steps) has the prior as its posterior: at the centre the normal's
    // peak (1 − w)/(σ√(2π)) plus the uniform's w/n, far from it the
    // uniform's alone; its β marginal is the prior's β.
    let model = PsiModel::new(1488.24, 1e7, 24);
    let mut beta = [0.0; BETAS.len()];
    for (j, b) in beta.iter_mut().enumerate() {
        *b = (j + 1) as f64 / 45.0;
    }
    let prior = Prior {
        centre: 2000.0,
        sigma: 50.0,
        beta,
    };
    let m = PsiColumn::with_prior(&model, Some(prior)).marginal_of();
    let w = PRIOR_UNIFORM;
    let uniform = w / model.n as f64;
    let peak = (1.0 - w) / (50.0 * (2.0 * std::f64::consts::PI).sqrt()) + uniform;
    let at = |i: usize| m.p[i - m.lo];
    assert!((at(2000) / at(100) - peak / uniform).abs() < 1e-6 * peak / uniform);
    // One σ out: e^{-1/2} of the normal's peak.
    let one = (1.0 - w) / (50.0 * (2.0 * std::f64::consts::PI).sqrt()) * (-0.5f64).exp() + uniform;
    assert!((at(2050) / at(100) - one / uniform).abs() < 1e-6 * one / uniform);
    for (j, b) in m.beta.iter().enumerate() {
        assert!((b - beta[j]).abs() < 1e-12, "β index {j}");
    }
    // Without a prior: the column knowing nothing.
    assert_eq!(
        PsiColumn::with_prior(&model, None).marginal_of(),
        PsiColumn::new(&model).marginal_of()
    );
}

#[test]
fn one_failure_tells_each_lattice_point_its_own_offset() {
    // A column knowing nothing (uniform over K* and β), told one failure
    // without an escape at lattice point m: the posterior of K* at i is
    // ∝ Σ_j P(β_j, h·(m − i)) (Bayes over a uniform prior; P is
    // Kontsevich & Tyler's Weibull, `fail_probability`, checked by hand in
    // the first test). Two points' ratio checks the offset to the lattice
    // step: one step off is 0.2 % in K and moves the ratio by ~8 %.
    let model = PsiModel::new(1000.0, 1e6, 24);
    let m = model.floor + 500;
    let mut c = PsiColumn::new(&model);
    c.tell(&model, m, Outcome::Failed);
    let summed = |d: f64| -> f64 { BETAS.iter().map(|&b| fail_probability(b, STEP * d)).sum() };
    let mg = c.marginal_of();
    let at = |i: usize| mg.p[i - mg.lo];
    for (a, b) in [(m, m - 3), (m - 1, m + 2), (m + 5, m - 5)] {
        let want = summed((m as f64) - (a as f64)) / summed((m as f64) - (b as f64));
        let got = at(a) / at(b);
        assert!(
            (got / want - 1.0).abs() < 1e-9,
            "{a} {b}: {got} against {want}"
        );
    }
}
