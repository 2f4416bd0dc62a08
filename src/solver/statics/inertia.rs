//! Inertia control: the ladder of Hessians a Newton direction is factorised with (exact,
//! exact shifted by τ I, element-projected) until the KKT inertia says the Hessian is
//! positive definite on the constraints' null space, and the stability check built on it.

use super::direction::FactorLayout;
use super::layout::energy_identity;
use super::model::Model;
use super::newton_problem::StaticNewton;
use super::{HessianMode, SolverError, StaticProblem, StaticSolver};
use crate::math::Energy;
use crate::solver::kkt::KktFactorInfo;

impl StaticSolver {
    /// Inertia check of the exact Hessian at `x`: whether it is positive definite on the
    /// null space of the constraints (a stable equilibrium if x is one).
    pub fn stability(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &[f64],
    ) -> Result<KktFactorInfo, SolverError> {
        let s = self.setup(e, p, x)?;
        self.trip_owner = Some(energy_identity(e));
        self.evaluate_layout(e, x, false);
        let gamma = self.gamma_for(&s);
        let m = Model { e, p, s: &s, gamma };
        let sym_s = self.assemble_at(&m, x, false)?;
        let mut info = self.factor_fresh(0.0, false, &m);
        info.symbolic_s = sym_s;
        Ok(info)
    }

    /// Numeric factorisation of the assembled KKT matrix shifted by `shift` (N/m), recording
    /// whether the factor may serve as a lagged preconditioner (exact, unshifted Hessian,
    /// inertia test passed).
    pub(super) fn factor_fresh(&mut self, shift: f64, projected: bool, m: &Model) -> KktFactorInfo {
        let info = self.kkt.factor(shift);
        self.lag_last_iterations = 0;
        self.fresh_next &= !(info.inertia_ok && !projected && shift == 0.0);
        if let Some((p, _)) = &mut self.patches {
            p.clear();
        }
        self.lag_layout = (info.inertia_ok && !projected && shift == 0.0).then(|| FactorLayout {
            cfree: m.s.cfree.clone(),
            pinned: m.p.pinned.clone(),
            dofs: m.s.free_of.len(),
            gamma: m.gamma,
        });
        info
    }

    /// Hessians Newton tries for a direction, in order, as (element-projected, shift / γ).
    ///
    /// First the exact Hessian, unless the lagged direction just showed it indefinite (a
    /// converged exact Newton direction with non-positive curvature: the factorisation at
    /// τ = 0 would only confirm it) or the last exact factorisation found two or more negative
    /// directions and the direction after it has not yet skipped the exact Hessian (a
    /// buckling state loses about one negative direction per Newton iteration, so skipping one
    /// direction in two limits a wrong guess to one shifted step where an exact one would do).
    ///
    /// Then the exact Hessian shifted by τ I, up to γ, by the inertia correction of IPOPT
    /// (Wächter and Biegler 2006, §3.1): τ starts at a third of the last shift that worked (at
    /// least 1e-10 γ) and grows ×8, or, when no shift has been needed yet, starts at 1e-4 γ and
    /// grows ×100, so the shifts a buckling skin needs are reached in few factorisations (a
    /// shift keeps the negative-curvature information, so Newton escapes saddles quickly).
    ///
    /// Last, in [`HessianMode::Auto`], the element-projected Hessian unshifted, then shifted by
    /// 1e-6 γ and by γ. [`HessianMode::Exact`] tries only the exact ladder;
    /// [`HessianMode::Projected`] the projected Hessian unshifted and then with the τ ladder.
    pub(super) fn hessian_attempts(&self) -> Vec<(bool, f64)> {
        let (start, growth) = if self.last_shift > 0.0 {
            ((self.last_shift / 3.0).max(1e-10), 8.0)
        } else {
            (1e-4, 100.0)
        };
        let mut shifts: Vec<f64> = (0..40)
            .map(|k| start * f64::powi(growth, k))
            .take_while(|&t| t < 1.0)
            .collect();
        shifts.push(1.0);
        let mut modes: Vec<(bool, f64)> = Vec::new();
        let exact = !self.seen_indefinite && !self.expect_indefinite;
        match self.settings.hessian {
            HessianMode::Exact => {
                modes.extend(exact.then_some((false, 0.0)));
                modes.extend(shifts.iter().map(|&t| (false, t)));
            }
            HessianMode::Projected => {
                modes.push((true, 0.0));
                modes.extend(shifts.iter().map(|&t| (true, t)));
            }
            HessianMode::Auto => {
                modes.extend(exact.then_some((false, 0.0)));
                modes.extend(shifts.iter().map(|&t| (false, t)));
                modes.push((true, 0.0));
                modes.push((true, 1e-6));
                modes.push((true, 1.0));
            }
        }
        modes
    }
}

impl StaticNewton<'_, '_> {
    /// Factorise the KKT matrix with the first Hessian of
    /// [`StaticSolver::hessian_attempts`] that has the right inertia (or the last one, when
    /// none does but it factorised). Returns whether a factor was made.
    pub(super) fn factor_with_inertia_control(&mut self) -> Result<bool, SolverError> {
        let (m, solver, rep) = (&self.model, &mut *self.solver, &mut *self.rep);
        let modes = solver.hessian_attempts();
        solver.seen_indefinite = false;
        solver.expect_indefinite = false;
        for (k, &(project, shift)) in modes.iter().enumerate() {
            let last = k + 1 == modes.len();
            solver.assemble_hessian(m, &self.at.x, project, &mut self.have_hessian, rep)?;
            let info = solver.factor_fresh(shift * m.gamma, project, m);
            rep.factor_s += info.numeric_s;
            rep.factorizations += 1;
            if (project, shift) == (false, 0.0) && solver.kkt.is_factored() {
                solver.expect_indefinite = info.negative_pivots >= m.rows() + 2;
            }
            if info.inertia_ok || (last && solver.kkt.is_factored()) {
                if k > 0 {
                    rep.modified_hessian_steps += 1;
                }
                if !project && shift > 0.0 {
                    solver.last_shift = shift;
                }
                return Ok(true);
            }
        }
        Ok(false)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::Wells;
    use super::super::StaticSettings;
    use super::*;
    use crate::solver::SolveStatus;

    /// Six double wells (E = Σ (x_i² − 1)² / 4) started on their hills, where the exact
    /// Hessian has six negative directions: after an exact factorisation with two or more,
    /// the next direction starts at a shift without factorising the exact Hessian again, and
    /// the solve still ends in a minimum (every x_i = ±1).
    #[test]
    fn the_inertia_correction_skips_an_exact_hessian_expected_indefinite() {
        let mut solver = StaticSolver::new(StaticSettings {
            tolerance: 1e-10,
            gamma: Some(1.0),
            lagged_solves: 0,
            energy_merit: true,
            ..Default::default()
        })
        .unwrap();
        let mut x = vec![0.05, 0.1, 0.15, 0.2, 0.25, 0.3];
        let rep = solver
            .solve(&Wells { k: 1.0, w: 1.0 }, &StaticProblem::default(), &mut x)
            .unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        assert!(x.iter().all(|v| (v.abs() - 1.0).abs() < 1e-9), "{x:?}");
        // 7 iterations either way; the second direction skips the exact factorisation that
        // the first showed indefinite (12 factorisations without the skip).
        assert_eq!((rep.iterations, rep.factorizations), (7, 11), "{rep:?}");
    }
}
