//! The solvers a tune drives, all minimizing a cost over the unit cube:
//! argmin's Brent (Brent 1973, ch. 5) and golden-section search for one
//! parameter, Nelder–Mead (Nelder & Mead 1965) and particle swarm (Kennedy
//! & Eberhart 1995; argmin's defaults from Zambrano-Bigiarini et al. 2013)
//! for more; a brute-force grid; and a Halton design (Halton 1960) for
//! Pareto fronts. The cost function itself keeps the log: solvers only
//! steer, so a solver stopped by the budget or a cancel loses nothing.

use argmin::core::observers::{Observe, ObserverMode};
use argmin::core::{CostFunction, Error, Executor, KV};
use std::sync::Arc;

use crate::zwidth::search::Observer;
use argmin::solver::brent::BrentOpt;
use argmin::solver::goldensectionsearch::GoldenSectionSearch;
use argmin::solver::neldermead::NelderMead;
use argmin::solver::particleswarm::ParticleSwarm;
use rand::{Rng, SeedableRng};

/// Evaluate the objective at u (unit cube); Err stops the solver (budget
/// spent, or cancelled).
pub trait Cost {
    fn cost(&self, u: &[f64]) -> Result<f64, Error>;
    /// Who to ask after each iteration whether to stop.
    fn observer(&self) -> Option<Arc<Observer>> {
        None
    }
}

/// An argmin observer that ends the run after any iteration once the
/// experiment is cancelled (the cost function also refuses to start a new
/// evaluation then, so a cancel never waits for a whole iteration).
struct CancelCheck(Arc<Observer>);

impl<I> Observe<I> for CancelCheck {
    fn observe_iter(&mut self, _state: &I, _kv: &KV) -> Result<(), Error> {
        if self.0.cancelled() {
            return Err(Error::msg("cancelled"));
        }
        Ok(())
    }
}

/// Run an executor with the cancel check attached, if there is an observer.
macro_rules! run_with_cancel {
    ($c:expr, $exec:expr) => {{
        let exec = $exec;
        let exec = match $c.observer() {
            Some(o) => exec.add_observer(CancelCheck(o), ObserverMode::Always),
            None => exec,
        };
        let _ = exec.run();
    }};
}

struct OneD<'a, C: Cost>(&'a C);

impl<C: Cost> CostFunction for OneD<'_, C> {
    type Param = f64;
    type Output = f64;
    fn cost(&self, u: &f64) -> Result<f64, Error> {
        self.0.cost(&[*u])
    }
}

struct ManyD<'a, C: Cost>(&'a C);

impl<C: Cost> CostFunction for ManyD<'_, C> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, u: &Vec<f64>) -> Result<f64, Error> {
        self.0.cost(u)
    }
}

/// Brent's method on [lo, hi] (one parameter) to absolute tolerance `tol` in u.
pub fn brent<C: Cost>(c: &C, lo: f64, hi: f64, tol: f64, max_iters: u64) {
    let solver = BrentOpt::new(lo, hi).set_tolerance(1e-8, tol);
    run_with_cancel!(
        c,
        Executor::new(OneD(c), solver).configure(|s| s.max_iters(max_iters))
    );
}

/// Golden-section search on [0, 1] to tolerance `tol` in u.
pub fn golden<C: Cost>(c: &C, tol: f64, max_iters: u64) -> Result<(), Error> {
    let solver = GoldenSectionSearch::new(0.0, 1.0)?.with_tolerance(tol)?;
    run_with_cancel!(
        c,
        Executor::new(OneD(c), solver).configure(|s| s.param(0.5).max_iters(max_iters))
    );
    Ok(())
}

/// Nelder–Mead from the simplex around `start` (steps of `step` in u).
pub fn nelder_mead<C: Cost>(c: &C, start: &[f64], step: f64, max_iters: u64) -> Result<(), Error> {
    let n = start.len();
    let mut simplex = vec![start.to_vec()];
    for i in 0..n {
        let mut p = start.to_vec();
        // Step inwards when the start sits near the upper bound.
        p[i] = if p[i] + step <= 1.0 {
            p[i] + step
        } else {
            p[i] - step
        };
        simplex.push(p);
    }
    // argmin's Nelder–Mead unwraps the costs of its first simplex (it would
    // panic on a spent budget or a cancel): evaluate the vertices here first
    // and stop quietly if one is refused. The tune caches evaluations, so
    // argmin's own pass over them computes nothing again.
    for p in &simplex {
        if c.cost(p).is_err() {
            return Ok(());
        }
    }
    let solver = NelderMead::new(simplex).with_sd_tolerance(1e-6)?;
    run_with_cancel!(
        c,
        Executor::new(ManyD(c), solver).configure(|s| s.max_iters(max_iters))
    );
    Ok(())
}

/// Particle swarm over the unit cube with `particles`, seeded.
pub fn particle_swarm<C: Cost>(c: &C, n: usize, particles: usize, max_iters: u64, seed: u64) {
    let solver = ParticleSwarm::new((vec![0.0; n], vec![1.0; n]), particles)
        .with_rng_generator(rand::rngs::StdRng::seed_from_u64(seed));
    run_with_cancel!(
        c,
        Executor::new(ManyD(c), solver).configure(|s| s.max_iters(max_iters))
    );
}

/// `count` evenly spaced points of [0, 1] (both ends), in order.
pub fn grid(count: usize) -> Vec<f64> {
    match count {
        0 => vec![],
        1 => vec![0.5],
        n => (0..n).map(|i| i as f64 / (n - 1) as f64).collect(),
    }
}

/// The i-th point of the Halton sequence in `dim` dimensions (bases 2, 3,
/// 5, …), shifted by a seeded random offset mod 1 (Cranley–Patterson
/// rotation) so different seeds give different, equally even designs.
pub fn halton(count: usize, dim: usize, seed: u64) -> Vec<Vec<f64>> {
    const PRIMES: [u64; 12] = [2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37];
    let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
    let shift: Vec<f64> = (0..dim).map(|_| rng.random::<f64>()).collect();
    (1..=count as u64)
        .map(|i| {
            (0..dim)
                .map(|d| {
                    let base = PRIMES[d % PRIMES.len()];
                    let (mut f, mut r, mut k) = (1.0, 0.0, i);
                    while k > 0 {
                        f /= base as f64;
                        r += f * (k % base) as f64;
                        k /= base;
                    }
                    (r + shift[d]).fract()
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::cell::RefCell;

    struct Quad(RefCell<usize>);
    impl Cost for Quad {
        fn cost(&self, u: &[f64]) -> Result<f64, Error> {
            *self.0.borrow_mut() += 1;
            // Minimum 0 at u = (0.3, 0.7, …).
            Ok(u.iter()
                .enumerate()
                .map(|(i, x)| (x - if i % 2 == 0 { 0.3 } else { 0.7 }).powi(2))
                .sum())
        }
    }

    struct Best<'a>(&'a Quad, RefCell<(f64, Vec<f64>)>);
    impl Cost for Best<'_> {
        fn cost(&self, u: &[f64]) -> Result<f64, Error> {
            let c = self.0.cost(u)?;
            let mut b = self.1.borrow_mut();
            if c < b.0 {
                *b = (c, u.to_vec());
            }
            Ok(c)
        }
    }

    fn best() -> (Quad, RefCell<(f64, Vec<f64>)>) {
        (Quad(RefCell::new(0)), RefCell::new((f64::MAX, vec![])))
    }

    #[test]
    fn solvers_find_a_quadratic_minimum() {
        let (q, b) = best();
        let c = Best(&q, b);
        brent(&c, 0.0, 1.0, 1e-6, 100);
        assert!((c.1.borrow().1[0] - 0.3).abs() < 1e-4, "{:?}", c.1.borrow());
        let (q, b) = best();
        let c = Best(&q, b);
        golden(&c, 1e-6, 200).unwrap();
        assert!((c.1.borrow().1[0] - 0.3).abs() < 1e-3, "{:?}", c.1.borrow());
        let (q, b) = best();
        let c = Best(&q, b);
        nelder_mead(&c, &[0.5, 0.5], 0.2, 200).unwrap();
        let u = c.1.borrow().1.clone();
        assert!(
            (u[0] - 0.3).abs() < 1e-3 && (u[1] - 0.7).abs() < 1e-3,
            "{u:?}"
        );
        let (q, b) = best();
        let c = Best(&q, b);
        particle_swarm(&c, 2, 20, 50, 7);
        let u = c.1.borrow().1.clone();
        assert!(
            (u[0] - 0.3).abs() < 1e-2 && (u[1] - 0.7).abs() < 1e-2,
            "{u:?}"
        );
    }

    /// Refuses every evaluation after the first `budget` (as a tune does
    /// when its budget is spent or it is cancelled).
    struct Budget(RefCell<usize>, usize);
    impl Cost for Budget {
        fn cost(&self, u: &[f64]) -> Result<f64, Error> {
            let mut n = self.0.borrow_mut();
            if *n >= self.1 {
                return Err(Error::msg("evaluation budget spent"));
            }
            *n += 1;
            Ok(u.iter().map(|x| x * x).sum())
        }
    }

    #[test]
    fn nelder_mead_stops_quietly_when_refused_during_its_first_simplex() {
        // Two parameters: the simplex has 3 vertices. Refused at the 1st,
        // 2nd or 3rd, argmin's init used to panic (unwrap on the cost).
        for budget in 0..3 {
            let c = Budget(RefCell::new(0), budget);
            nelder_mead(&c, &[0.5, 0.5], 0.2, 100).unwrap();
            assert_eq!(*c.0.borrow(), budget);
        }
        // With room, it runs past the simplex.
        let c = Budget(RefCell::new(0), 50);
        nelder_mead(&c, &[0.5, 0.5], 0.2, 100).unwrap();
        assert!(*c.0.borrow() > 3);
    }

    /// Records every point it is asked about (a constant cost).
    struct Seen(RefCell<Vec<Vec<f64>>>);
    impl Cost for Seen {
        fn cost(&self, u: &[f64]) -> Result<f64, Error> {
            self.0.borrow_mut().push(u.to_vec());
            Ok(0.0)
        }
    }

    #[test]
    fn the_first_simplex_steps_inwards_near_the_upper_bound() {
        // Start (0.95, 0.2), step 0.15: 0.95 + 0.15 > 1, so that vertex is
        // 0.95 − 0.15 = 0.8; the other steps up to 0.35.
        let c = Seen(RefCell::new(Vec::new()));
        nelder_mead(&c, &[0.95, 0.2], 0.15, 1).unwrap();
        let seen = c.0.borrow();
        let close =
            |u: &[f64], w: [f64; 2]| (u[0] - w[0]).abs() < 1e-12 && (u[1] - w[1]).abs() < 1e-12;
        for w in [[0.95, 0.2], [0.8, 0.2], [0.95, 0.35]] {
            assert!(seen.iter().any(|u| close(u, w)), "{w:?} not in {seen:?}");
        }
    }

    #[test]
    fn grids_are_evenly_spaced_with_both_ends() {
        assert_eq!(grid(0), Vec::<f64>::new());
        assert_eq!(grid(1), vec![0.5]);
        assert_eq!(grid(3), vec![0.0, 0.5, 1.0]);
        assert_eq!(grid(5), vec![0.0, 0.25, 0.5, 0.75, 1.0]);
    }

    #[test]
    fn particle_swarm_is_reproducible_with_a_seed() {
        let run = |seed| {
            let (q, b) = best();
            let c = Best(&q, b);
            particle_swarm(&c, 2, 8, 5, seed);
            let r = c.1.borrow().clone();
            r
        };
        assert_eq!(run(3), run(3));
        assert_ne!(run(3), run(4));
    }

    #[test]
    fn halton_is_the_radical_inverse() {
        // Base 2: 1/2, 1/4, 3/4; base 3: 1/3, 2/3, 1/9 (the definition),
        // here shifted by the seed's offset mod 1.
        let h = halton(3, 2, 0);
        let off = (h[0][0] - 0.5).rem_euclid(1.0);
        for (p, want) in h.iter().zip([0.5, 0.25, 0.75]) {
            assert!(((p[0] - want).rem_euclid(1.0) - off).abs() < 1e-12);
        }
        let off = (h[0][1] - 1.0 / 3.0).rem_euclid(1.0);
        for (p, want) in h.iter().zip([1.0 / 3.0, 2.0 / 3.0, 1.0 / 9.0]) {
            let d = (p[1] - want).rem_euclid(1.0) - off;
            assert!(d.abs() < 1e-12 || (d.abs() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn shifted_halton_points_stay_in_the_unit_cube() {
        // A Cranley–Patterson rotation adds the seed's offset mod 1: every
        // coordinate in [0, 1).
        for seed in 0..5 {
            for p in halton(16, 2, seed) {
                assert!(p.iter().all(|x| (0.0..1.0).contains(x)), "{seed}: {p:?}");
            }
        }
    }
}
