//! The linear system of one Newton iteration, [M_coef M + K_coef (K + K_x)] Δy = r: the
//! element rotations and rotation corrections at the iterate, the matrix (assembled or
//! matrix-free) brought up to date, and its solve by Cholesky or conjugate gradients.

use super::potential::Terms;
use super::settings::{LinearSolver, Tangent, AUTO_CG_DOFS, AUTO_CG_REL_TOL};
use super::system::MatrixTerms;
use super::{BackwardEuler, M3};
use crate::fem::cg::pcg;
use crate::fem::matfree::ElementOperator;
use crate::fem::tangent::RotationCorrection;
use crate::fem::FemError;
use rayon::prelude::*;

/// How the Newton system of one iteration is to be solved.
#[derive(Debug, Clone, Copy)]
pub(super) struct NewtonSolve {
    /// The first Newton iteration of a time step: conjugate gradients start from the last
    /// step's first direction and record this one for the next step.
    pub warm_start: bool,
    /// A backward Euler time step (else a quasi-static solve, whose singular stiffness is
    /// reported as missing pins).
    pub time_step: bool,
    /// A projected matrix is tried next when this one is not positive definite, so a failed
    /// factorisation returns no direction instead of an error.
    pub retry_projected: bool,
}

impl BackwardEuler {
    /// Element rotations at `y`: those of the last gradient evaluation when it was at `y`
    /// (it usually is), else computed.
    pub(super) fn rotations_at(&self, y: &[f64]) -> Vec<M3> {
        let cache = self.rot_cache.borrow();
        if cache.0.as_slice() == y && cache.1.len() == self.interior.elements.len() {
            cache.1.clone()
        } else {
            drop(cache);
            let interior = &self.interior;
            (0..interior.elements.len())
                .into_par_iter()
                .map(|e| interior.element_rotation(y, e))
                .collect()
        }
    }

    /// The rotation-derivative part of each element's stiffness at `y` (exact, or with its
    /// stress term projected to positive semi-definite when `project`), or none when the
    /// settings ask for the frozen-rotation stiffness.
    pub(super) fn corrections_at(
        &self,
        y: &[f64],
        project: bool,
    ) -> Vec<Option<RotationCorrection>> {
        match self.settings.tangent {
            Tangent::Frozen => Vec::new(),
            Tangent::Consistent => {
                let interior = &self.interior;
                (0..interior.elements.len())
                    .into_par_iter()
                    .map(|e| interior.rotation_correction(y, e, project))
                    .collect()
            }
        }
    }

    /// The linear solver of the settings with [`LinearSolver::Auto`] resolved for a system
    /// of `free_dofs` (a `time_step` or a quasi-static solve).
    pub(super) fn resolved_solver(&self, free_dofs: usize, time_step: bool) -> LinearSolver {
        match self.settings.linear_solver {
            LinearSolver::Auto if time_step && free_dofs > AUTO_CG_DOFS => {
                LinearSolver::ConjugateGradient {
                    rel_tol: AUTO_CG_REL_TOL,
                    max_iter: 1000,
                }
            }
            LinearSolver::Auto => LinearSolver::Cholesky,
            other => other,
        }
    }

    /// Bring the Newton matrix M_coef·M + K_coef·(K(rotations) + K_x) up to date: the
    /// element operator when `matrix_free`, else the assembled matrix.
    pub(super) fn prepare_matrix(
        &mut self,
        terms: &Terms,
        rotations: Vec<M3>,
        corrections: Vec<Option<RotationCorrection>>,
        matrix_free: bool,
    ) {
        let (mass_coef, stiff_coef) = terms.coefficients();
        let lumped = if self.settings.lumped_mass {
            Some(self.lumped.as_slice())
        } else {
            None
        };
        let sys = self.system.as_mut().expect("system built");
        if matrix_free {
            let op = self
                .operator
                .get_or_insert_with(|| ElementOperator::new(&self.interior, &sys.free));
            let lumped_free = lumped.map(|m| sys.free_nodes.iter().map(|&nd| m[nd]).collect());
            op.update(
                &self.interior,
                rotations,
                corrections,
                mass_coef,
                stiff_coef,
                lumped_free,
            );
        } else {
            let coefs = MatrixTerms {
                mass_coef,
                stiff_coef,
                lumped,
                extra: terms.extra.map(|x| x.stiffness),
                corrections: &corrections,
            };
            sys.assemble(&self.interior, &rotations, &coefs);
        }
    }

    /// Solve the prepared Newton system for `rhs` (free DOFs) with `solver` (resolved);
    /// returns the solution and the CG iterations, or `None` when the matrix is not
    /// positive definite and `how` retries a projected one.
    pub(super) fn solve_newton_system(
        &mut self,
        solver: LinearSolver,
        matrix_free: bool,
        mut rhs: Vec<f64>,
        how: NewtonSolve,
    ) -> Result<Option<(Vec<f64>, usize)>, FemError> {
        let sys = self.system.as_mut().expect("system built");
        match solver {
            LinearSolver::Auto => unreachable!("resolved by the caller"),
            LinearSolver::Cholesky => {
                if let Err(e) = self.solver.factorize(&sys.mat) {
                    if how.retry_projected {
                        return Ok(None);
                    }
                    return Err(if how.time_step {
                        FemError::Sparse(e)
                    } else {
                        FemError::Input(format!(
                            "quasi-static solve: the stiffness is singular ({e}); pin nodes to remove rigid motions"
                        ))
                    });
                }
                self.solver.solve_in_place(&mut rhs);
                Ok(Some((rhs, 0)))
            }
            LinearSolver::ConjugateGradient { rel_tol, max_iter } => {
                // Warm start: the first Newton direction of the last time step (the
                // velocity change varies slowly between steps).
                let guess = if how.warm_start {
                    self.last_direction.as_deref()
                } else {
                    None
                };
                let (x, it) = if matrix_free {
                    let op = self.operator.as_ref().expect("updated before");
                    let inv = op.diag_inverses();
                    pcg(op, &inv, &rhs, guess, rel_tol, max_iter)
                } else {
                    sys.fill_bsr();
                    let inv = sys.bsr.diag_inverses();
                    pcg(&sys.bsr, &inv, &rhs, guess, rel_tol, max_iter)
                };
                if how.warm_start {
                    self.last_direction = Some(x.clone());
                }
                Ok(Some((x, it)))
            }
        }
    }
}
