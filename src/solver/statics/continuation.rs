//! Load continuation: a solve that fails from a far start is redone from the same state
//! with the change of load (constraint right-hand side and pinned values) applied in 2, 4,
//! … equal increments, each solved to equilibrium.

use super::{SolverError, StaticProblem, StaticSolver};
use crate::math::Energy;
use crate::solver::status::{SolveReport, SolveStatus};

impl StaticSolver {
    /// [`StaticSolver::solve`] with load continuation: when the direct solve stops at the
    /// iteration limit or in a failed line search, or converges after taking a step to a
    /// state `accept` refuses (an equilibrium through itself: the skin has no contact), start
    /// again from the same state (`x` and multipliers as given) and apply the change of load,
    /// from `rhs_from` (the constraint right-hand side of that state) and `pinned_from` (its
    /// pinned dof values, in the order of `p.pinned`) to those of `p` and `x`, in 2, then 4,
    /// … up to 2^`levels` equal increments, each solved to equilibrium, until the end is
    /// accepted.
    /// Large target jumps (a frame that moves the skin's clusters far, or a buckling event)
    /// converge along such a path where Newton from the far start does not, and wrinkles
    /// grown along it may stay clear of each other where Newton's long steps pass them
    /// through. The report sums the work of every attempt; its status and residual are those
    /// of the last solve, and `increments` says how many were needed.
    #[allow(clippy::too_many_arguments)]
    pub fn solve_in_increments(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &mut [f64],
        rhs_from: &[f64],
        pinned_from: &[f64],
        levels: usize,
        accept: &mut dyn FnMut(&[f64]) -> bool,
    ) -> Result<SolveReport, SolverError> {
        if rhs_from.len() != p.constraints.rhs.len() || pinned_from.len() != p.pinned.len() {
            return Err(SolverError::Problem(format!(
                "continuation start has {} constraint values and {} pinned values, the problem {} and {}",
                rhs_from.len(),
                pinned_from.len(),
                p.constraints.rhs.len(),
                p.pinned.len()
            )));
        }
        if levels == 0 {
            return self.solve(e, p, x);
        }
        let x_start = x.to_vec();
        let mu_start = self.multipliers.clone();
        let last_x_start = self.last_x.clone();
        let last_pinned_start = self.last_pinned.clone();
        let target_pinned: Vec<f64> = p.pinned.iter().map(|&d| x[d]).collect();
        let mut total = self.solve(e, p, x)?;
        // A solve that took no step ends where it started, which its caller had accepted.
        let retry = match total.status {
            SolveStatus::IterationLimit | SolveStatus::LineSearchFailed => true,
            SolveStatus::Converged => total.iterations > 0 && !accept(x),
            _ => false,
        };
        if !retry {
            return Ok(total);
        }
        let mut sub = p.clone();
        for level in 1..=levels {
            let m = 1usize << level;
            x.copy_from_slice(&x_start);
            self.multipliers = mu_start.clone();
            self.last_x = last_x_start.clone();
            self.last_pinned = last_pinned_start.clone();
            // The pinned-motion predictor compares with the start state's pinned values, so
            // it sees each increment's motion only (x's pinned values are set per increment).
            for (&d, &v) in p.pinned.iter().zip(pinned_from) {
                if let Some(l) = self.last_x.get_mut(d) {
                    *l = v;
                }
            }
            let mut done = true;
            for k in 1..=m {
                let t = k as f64 / m as f64;
                for ((r, &a), &b) in sub
                    .constraints
                    .rhs
                    .iter_mut()
                    .zip(rhs_from)
                    .zip(&p.constraints.rhs)
                {
                    *r = a + t * (b - a);
                }
                for ((&d, &a), &b) in p.pinned.iter().zip(pinned_from).zip(&target_pinned) {
                    x[d] = a + t * (b - a);
                }
                let rep = self.solve(e, &sub, x)?;
                total.add_work(&rep);
                total.status = rep.status;
                total.residual = rep.residual;
                total.constraint_violation = rep.constraint_violation;
                total.energy = rep.energy;
                total.increments = m;
                if rep.status != SolveStatus::Converged {
                    done = false;
                    break;
                }
            }
            if (done && accept(x)) || total.status == SolveStatus::NotFinite {
                break;
            }
        }
        Ok(total)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::SpringChain;
    use super::super::{LinearConstraints, StaticSettings};
    use super::*;

    /// Load continuation on a chain of hardening springs (k = 1, 3, 0.5, 2), x0 pinned and
    /// x4 held by the constraint x4 = d. From the equilibrium at x0 = 0, d = 1 the load jumps
    /// to x0 = −1, d = 30: with 4 Newton iterations allowed the direct solve stops at the
    /// iteration limit, the increments converge, and the answer is the series-spring one
    /// (the same force F in every spring, k_i (Δ_i + Δ_i³) = F, Σ Δ_i = 31), found here by
    /// bisection independently of the solver.
    #[test]
    fn load_increments_converge_where_the_direct_solve_does_not() {
        let k = [1.0, 3.0, 0.5, 2.0];
        let chain = SpringChain {
            k,
            quartic: 1.0,
            scatters: false,
        };
        let problem = |x4: f64| StaticProblem {
            pinned: vec![0],
            constraints: LinearConstraints {
                rows: 1,
                entries: vec![(0, 4, 1.0)],
                rhs: vec![x4],
            },
            forces: Vec::new(),
        };
        let settings = StaticSettings {
            tolerance: 1e-9,
            max_iterations: 4,
            gamma: Some(1.0),
            ..Default::default()
        };
        // A solver at the equilibrium of x0 = 0, d = 1 (found with up to 50 iterations),
        // then allowed 4 iterations, and the jumped start x0 = −1 (d moves with the problem).
        let start = || {
            let mut solver = StaticSolver::new(StaticSettings {
                max_iterations: 50,
                ..settings
            })
            .unwrap();
            let mut x = vec![0.0, 0.2, 0.4, 0.6, 0.8];
            let rep = solver.solve(&chain, &problem(1.0), &mut x).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
            solver.settings.max_iterations = 4;
            let x_start = x.clone();
            x[0] = -1.0;
            (solver, x_start, x)
        };
        // The direct solve fails within 4 iterations.
        let (mut direct, _, mut x) = start();
        let rep = direct.solve(&chain, &problem(30.0), &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::IterationLimit, "{rep:?}");
        assert!(rep.residual > 0.1 * rep.initial_residual, "{rep:?}");
        // The same jump in increments.
        let (mut solver, x_start, mut x) = start();
        let rep = solver
            .solve_in_increments(
                &chain,
                &problem(30.0),
                &mut x,
                &[x_start[4]],
                &[x_start[0]],
                4,
                &mut |_| true,
            )
            .unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        assert!(rep.increments >= 2 && rep.increments <= 16, "{rep:?}");
        // Series springs: Σ Δ_i(F) = 31 with Δ_i the real root of Δ + Δ³ = F / k_i.
        let f = series_force(&k, 31.0);
        let mut want = -1.0;
        for (i, &ki) in k.iter().enumerate() {
            want += stretch(f, ki);
            assert!((x[i + 1] - want).abs() < 1e-8, "dof {}: {x:?}", i + 1);
        }
        // A start of the wrong size is an error, not a guess.
        assert!(solver
            .solve_in_increments(&chain, &problem(30.0), &mut x, &[], &[0.0], 2, &mut |_| {
                true
            })
            .is_err());
        // A small jump converges directly; an end `accept` refuses (here the first) is
        // redone in increments and lands on the same equilibrium.
        let (mut direct, _, mut x_direct) = start();
        let (mut refused, x_start, mut x) = start();
        x_direct[0] = -0.01;
        x[0] = -0.01;
        let rep = direct.solve(&chain, &problem(1.0), &mut x_direct).unwrap();
        assert_eq!((rep.status, rep.increments), (SolveStatus::Converged, 1));
        let mut seen = 0;
        let rep = refused
            .solve_in_increments(
                &chain,
                &problem(1.0),
                &mut x,
                &[x_start[4]],
                &[x_start[0]],
                2,
                &mut |_| {
                    seen += 1;
                    seen > 1
                },
            )
            .unwrap();
        assert_eq!(
            (rep.status, rep.increments, seen),
            (SolveStatus::Converged, 2, 2)
        );
        let apart = x
            .iter()
            .zip(&x_direct)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        assert!(apart < 1e-8, "{x:?} vs {x_direct:?}");
    }

    /// The stretch Δ of a hardening spring of stiffness `ki` (N/m) under force `f` (N): the
    /// real root of ki (Δ + Δ³) = f, by bisection.
    fn stretch(f: f64, ki: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, f / ki + 1.0);
        for _ in 0..200 {
            let m = 0.5 * (lo + hi);
            if ki * (m + m * m * m) < f {
                lo = m;
            } else {
                hi = m;
            }
        }
        0.5 * (lo + hi)
    }

    /// The force F (N) that stretches hardening springs of stiffnesses `k` (N/m) in series
    /// by `total` (m) altogether, by bisection on Σ [`stretch`].
    fn series_force(k: &[f64], total: f64) -> f64 {
        let (mut lo, mut hi) = (0.0, 1e6);
        for _ in 0..200 {
            let f = 0.5 * (lo + hi);
            if k.iter().map(|&ki| stretch(f, ki)).sum::<f64>() < total {
                lo = f;
            } else {
                hi = f;
            }
        }
        0.5 * (lo + hi)
    }
}
