//! One minimisation of Φ by the Newton core ([`crate::solver::newton`]): the Newton
//! direction (the consistent tangent first, projected when it gives no descent), the
//! backtracking line search on Φ, and the report of the solve.

use super::newton_system::NewtonSolve;
use super::potential::Terms;
use super::settings::{LinearSolver, Tangent};
use super::system::NONE;
use super::{BackwardEuler, ExtraTerms, SolveReport};
use crate::fem::FemError;
use crate::solver::newton::{self, Check, NewtonLimits, NewtonProblem, Rejection, Verdict};
use crate::solver::SolveStatus;
use nalgebra::Vector3;
use std::time::Instant;

/// The interior's outcome from the Newton core's: a failed line search, a step too short to
/// make progress and (never produced here) a non-finite residual are all `Stalled`, since the
/// stepper keeps its last good state.
fn interior_status(s: SolveStatus) -> SolveStatus {
    match s {
        SolveStatus::LineSearchFailed | SolveStatus::NotFinite => SolveStatus::Stalled,
        other => other,
    }
}

impl BackwardEuler {
    /// Minimise Φ over the free nodes from `y` (updated in place) by the Newton core
    /// ([`crate::solver::newton`]); `inertia` is the target y₀ + h v and the time step h
    /// (s) of a backward Euler step, `None` for a quasi-static solve.
    pub(super) fn minimise(
        &mut self,
        y: &mut [f64],
        x0: &[f64],
        inertia: Option<(&[f64], f64)>,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.eval_clock.set((0.0, 0));
        let gvec = Vector3::from(self.settings.gravity);
        let fg = self.interior.gravity_force(gvec);
        let force: Vec<f64> = fg.iter().zip(f_ext).map(|(a, b)| a + b).collect();
        let terms = Terms {
            x0,
            inertia,
            force: &force,
            extra,
        };
        let (phi, g) = self.potential(&terms, y, true);
        let res = self.free_norm(&g);
        let reference = self.reference_force(res, &terms);
        let limits = NewtonLimits {
            max_iterations: self.settings.max_newton,
            max_trials: 30,
        };
        let mut problem = EulerNewton {
            report: SolveReport {
                status: SolveStatus::IterationLimit,
                iterations: 0,
                residual: res,
                relative_residual: res / reference,
                assembly_s: 0.0,
                solve_s: 0.0,
                cg_iterations: 0,
                energy_s: 0.0,
                evaluations: 0,
            },
            be: self,
            terms,
            y,
            phi,
            g,
            res,
            reference,
            line: EulerLine::default(),
        };
        let record = newton::solve(&mut problem, &limits)?;
        let mut report = problem.report;
        report.status = interior_status(record.status);
        report.iterations = record.iterations;
        let (es, en) = self.eval_clock.get();
        report.energy_s = es;
        report.evaluations = en;
        Ok(report)
    }
}

/// The search line of the last Newton direction of Φ.
#[derive(Default)]
struct EulerLine {
    /// Direction over all DOFs (m; zero at pinned nodes).
    dir: Vec<f64>,
    /// ∇Φ · dir (J per unit step).
    slope: f64,
    /// Largest |dir| component (m).
    step_max: f64,
    /// Positions of the last trial (m).
    trial: Vec<f64>,
    /// Φ (J) and ∇Φ (N) of the last trial when it was accepted.
    accepted: Option<(f64, Vec<f64>)>,
}

/// One minimisation of Φ as a [`NewtonProblem`]: the interior's own linear solvers
/// (Cholesky or CG, matrix-free or assembled) and the iterate y with Φ(y), ∇Φ(y).
struct EulerNewton<'a, 't> {
    be: &'a mut BackwardEuler,
    terms: Terms<'t>,
    y: &'a mut [f64],
    /// Φ(y) (J).
    phi: f64,
    /// ∇Φ(y) (N, all DOFs).
    g: Vec<f64>,
    /// ‖∇Φ‖ over free DOFs (N).
    res: f64,
    /// Force scale of the tolerance (N).
    reference: f64,
    report: SolveReport,
    line: EulerLine,
}

impl EulerNewton<'_, '_> {
    fn converged(&self) -> bool {
        self.res <= self.be.settings.tolerance * self.reference
    }

    /// Right-hand side −K_coef ∇Φ over free DOFs.
    fn newton_rhs(&self) -> Vec<f64> {
        let sys = self.be.system.as_ref().expect("system built");
        let stiff_coef = self.terms.coefficients().1;
        let mut rhs = vec![0.0; 3 * sys.nfree];
        for (n, &f) in sys.free.iter().enumerate() {
            if f != NONE {
                for i in 0..3 {
                    rhs[3 * f + i] = -stiff_coef * self.g[3 * n + i];
                }
            }
        }
        rhs
    }

    /// The free-DOF solution `dy` scattered over all DOFs.
    fn scatter(&self, dy: &[f64]) -> Vec<f64> {
        let sys = self.be.system.as_ref().expect("system built");
        let mut dir = vec![0.0; self.y.len()];
        for (n, &f) in sys.free.iter().enumerate() {
            if f != NONE {
                for i in 0..3 {
                    dir[3 * n + i] = dy[3 * f + i];
                }
            }
        }
        dir
    }

    /// ∇Φ at the trial point, evaluated now unless `gt` already holds it.
    fn trial_gradient(&self, gt: Vec<f64>) -> Vec<f64> {
        if gt.is_empty() {
            self.be.potential(&self.terms, &self.line.trial, true).1
        } else {
            gt
        }
    }
}

impl NewtonProblem for EulerNewton<'_, '_> {
    type Error = FemError;

    fn check(&mut self) -> Check {
        if self.converged() {
            Check::Converged
        } else {
            Check::Continue
        }
    }

    /// Solve [M_coef M + K_coef (K + K_x)] Δy = −K_coef ∇Φ. With the consistent tangent the
    /// exact Hessian is tried first (quadratic convergence); when it is not positive
    /// definite or gives no descent direction, its stress term is projected and the system
    /// solved again.
    fn direction(&mut self, iteration: usize) -> Result<Option<SolveStatus>, FemError> {
        let time_step = self.terms.inertia.is_some();
        let nfree = self.be.system.as_ref().expect("system built").nfree;
        let solver = self.be.resolved_solver(3 * nfree, time_step);
        // CG without coupling terms multiplies element by element (no assembly); with
        // K_x it multiplies the assembled matrix.
        let matrix_free =
            matches!(solver, LinearSolver::ConjugateGradient { .. }) && self.terms.extra.is_none();
        let consistent = self.be.settings.tangent == Tangent::Consistent;
        let warm = time_step && iteration == 0;
        for project in [false, true] {
            let last = project || !consistent;
            let t0 = Instant::now();
            let rotations = self.be.rotations_at(self.y);
            let corrections = self.be.corrections_at(self.y, project);
            self.be
                .prepare_matrix(&self.terms, rotations, corrections, matrix_free);
            self.report.assembly_s += t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let rhs = self.newton_rhs();
            let how = NewtonSolve {
                warm_start: warm,
                time_step,
                retry_projected: !last,
            };
            let solved = self.be.solve_newton_system(solver, matrix_free, rhs, how)?;
            let factored = time_step && solved.is_some() && solver == LinearSolver::Cholesky;
            self.be.factor_coefs = factored.then(|| self.terms.coefficients());
            self.report.solve_s += t1.elapsed().as_secs_f64();
            let Some((dy, cg_iterations)) = solved else {
                continue;
            };
            self.report.cg_iterations += cg_iterations;
            let dir = self.scatter(&dy);
            let slope: f64 = dir.iter().zip(&self.g).map(|(d, gi)| d * gi).sum();
            if slope < 0.0 || last {
                self.line = EulerLine {
                    slope,
                    step_max: dir.iter().fold(0.0f64, |m, d| m.max(d.abs())),
                    dir,
                    trial: self.y.to_vec(),
                    accepted: None,
                };
                break;
            }
        }
        Ok(None)
    }

    /// Armijo on Φ (c = 1e-4), or, near the solution where Φ changes by less than its
    /// round-off, a step that does not raise Φ beyond round-off and lowers the residual.
    /// The full step is evaluated with its gradient (it is usually accepted); shorter steps
    /// first by value only. Steps are halved.
    fn trial(&mut self, t: f64) -> Verdict {
        for i in 0..self.y.len() {
            self.line.trial[i] = self.y[i] + t * self.line.dir[i];
        }
        let (p, gt) = self.be.potential(&self.terms, &self.line.trial, t == 1.0);
        let phi = self.phi;
        let mut accepted = None;
        if p.is_finite() && p <= phi + 1e-4 * t * self.line.slope.min(0.0) {
            accepted = Some((p, self.trial_gradient(gt)));
        } else if p.is_finite() && p - phi <= 1e-12 * phi.abs().max(1e-300) {
            let gt = self.trial_gradient(gt);
            if self.be.free_norm(&gt) < self.res {
                accepted = Some((p, gt));
            }
        }
        self.line.accepted = accepted;
        Verdict {
            accepted: self.line.accepted.is_some(),
            fit: None,
        }
    }

    /// Move to the trial; a step shorter than 1e-14 cells ends the solve (converged when
    /// the residual meets the tolerance, else stalled).
    fn accept(&mut self, t: f64) -> Option<SolveStatus> {
        let (p, g) = self.line.accepted.take().expect("accepted trial");
        self.y.copy_from_slice(&self.line.trial);
        self.phi = p;
        self.res = self.be.free_norm(&g);
        self.g = g;
        self.report.residual = self.res;
        self.report.relative_residual = self.res / self.reference;
        if t * self.line.step_max < 1e-14 * self.be.interior.cell_size {
            return Some(if self.converged() {
                SolveStatus::Converged
            } else {
                SolveStatus::LineSearchFailed
            });
        }
        None
    }

    fn rejected(&mut self) -> Rejection {
        Rejection::Stop(SolveStatus::LineSearchFailed)
    }
}
