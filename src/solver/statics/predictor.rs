//! The pinned-motion predictor: when the pinned dofs moved since the previous solve, the
//! linearised response of the free dofs to that motion about the previous solution, which
//! becomes Newton's first iterate when its residual is smaller than the warm start's.

use super::forcing::forcing;
use super::model::{Model, Point};
use super::{SolverError, StaticSolver};
use crate::solver::status::SolveReport;
use std::time::Instant;

impl StaticSolver {
    /// Right-hand side of the pinned-motion predictor about `x_prev` (the previous solution
    /// with the new free values of `x`): `[−(r_x(x_prev) + K_fp Δp); −γ(Cx − d)]`, with the
    /// KKT matrix assembled at `x_prev` (its K_fp is the Hessian's coupling of free rows to
    /// pinned dofs). Returns it and the symbolic-analysis time (s).
    fn predictor_rhs(
        &mut self,
        m: &Model,
        x: &[f64],
        x_prev: &[f64],
        mu: &[f64],
        dp: &[f64],
    ) -> Result<(Vec<f64>, f64), SolverError> {
        let (r_prev, _, _) = m.residual(x_prev, mu);
        let sym_s = self.assemble_at(m, x_prev, false)?;
        let mut rhs: Vec<f64> = r_prev[..m.free()].iter().map(|v| -v).collect();
        let (pairs, values) = self.kkt.pinned_coupling();
        for (&(fr, col), &v) in pairs.iter().zip(values) {
            rhs[fr] -= v * dp[col];
        }
        let cx = m.p.constraints.apply(x);
        rhs.extend(
            cx.iter()
                .zip(&m.p.constraints.rhs)
                .map(|(a, b)| -m.gamma * (a - b)),
        );
        Ok((rhs, sym_s))
    }

    /// Pinned-motion predictor: when the pinned dofs moved since the previous solve (same
    /// pinned set), take the linearised response of the free dofs to that motion about the
    /// previous state, `[K γCᵀ; γC 0] [Δx; μ⁺] = [−(r_x(x_prev) + K_fp Δp); −γ(Cx − d)]`,
    /// so Newton starts near the new equilibrium instead of from a state whose elements
    /// at the boundary are suddenly compressed. Returns the predicted point, or `None` when
    /// nothing moved or the Hessian there is not positive definite on the constraint null
    /// space.
    fn pinned_predictor(
        &mut self,
        m: &Model,
        at: &Point,
        lin_tol: f64,
        rep: &mut SolveReport,
    ) -> Result<Option<Point>, SolverError> {
        let (x, p) = (&at.x[..], m.p);
        if self.last_x.len() != x.len() || self.last_pinned != p.pinned {
            return Ok(None);
        }
        let mut dp = vec![0.0; x.len()];
        let mut moved = false;
        let mut x_prev = x.to_vec();
        for &d in &p.pinned {
            dp[d] = x[d] - self.last_x[d];
            x_prev[d] = self.last_x[d];
            moved |= dp[d] != 0.0;
        }
        if !moved {
            return Ok(None);
        }
        let t = Instant::now();
        let (mut rhs, sym_s) = self.predictor_rhs(m, x, &x_prev, &at.mu, &dp)?;
        rep.symbolic_s += sym_s;
        rep.factor_s += sym_s;
        rep.assembly_s += t.elapsed().as_secs_f64() - sym_s;
        if !(self.lag_usable(m) && self.lagged_direction(m, lin_tol, &mut rhs, rep)) {
            let info = self.factor_fresh(0.0, false, m);
            rep.factor_s += info.numeric_s;
            rep.factorizations += 1;
            if !info.inertia_ok {
                return Ok(None);
            }
            self.solve_fresh(&mut rhs, lin_tol, rep);
        }
        if rhs.iter().any(|v| !v.is_finite()) {
            return Ok(None);
        }
        rep.iterations += 1;
        let t = Instant::now();
        let nf = m.free();
        let mut xn = x.to_vec();
        for (k, &d) in m.s.free.iter().enumerate() {
            xn[d] = x_prev[d] + rhs[k];
        }
        let mn: Vec<f64> = at.mu.iter().zip(&rhs[nf..]).map(|(m, d)| m + d).collect();
        let predicted = m.point(xn, mn);
        rep.line_search_s += t.elapsed().as_secs_f64();
        Ok(Some(predicted))
    }

    /// The first Newton iterate: the warm start (x, μ), or the pinned-motion prediction when
    /// it has the smaller residual. `have_hessian` is cleared when the predictor evaluated
    /// a Hessian elsewhere.
    pub(super) fn start_point(
        &mut self,
        m: &Model,
        x: &[f64],
        mu: Vec<f64>,
        have_hessian: &mut Option<bool>,
        rep: &mut SolveReport,
    ) -> Result<Point, SolverError> {
        let st = self.settings;
        let t = Instant::now();
        let mut at = m.point(x.to_vec(), mu);
        rep.line_search_s += t.elapsed().as_secs_f64();
        rep.initial_residual = at.rn;
        let lin_tol = forcing(st.linear_tolerance, st.tolerance, at.rn, None);
        if let Some(predicted) = self.pinned_predictor(m, &at, lin_tol, rep)? {
            if predicted.rn.is_finite() && predicted.rn < at.rn {
                at = predicted;
            }
            *have_hessian = None;
        }
        Ok(at)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::LINEAR_CHAIN;
    use super::super::{StaticProblem, StaticSettings};
    use super::*;
    use crate::solver::SolveStatus;

    /// Moving a pinned end of a linear spring chain: the pinned-motion predictor is the exact
    /// answer (x_i = i/4 · x4), so the re-solve takes that one step, by GMRES with the
    /// factorisation the first solve ended with (the Hessian is constant) and no new one.
    #[test]
    fn pinned_motion_predictor_solves_a_linear_problem_in_one_step() {
        let p = StaticProblem {
            pinned: vec![0, 4],
            ..Default::default()
        };
        let settings = StaticSettings {
            tolerance: 1e-12,
            gamma: Some(1.0),
            ..Default::default()
        };
        let mut solver = StaticSolver::new(settings).unwrap();
        let mut x = vec![0.0, 0.3, -0.2, 0.1, 1.0];
        let rep = solver.solve(&LINEAR_CHAIN, &p, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        x[4] = 2.0;
        let rep = solver.solve(&LINEAR_CHAIN, &p, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        assert_eq!(
            (rep.iterations, rep.factorizations, rep.lagged_directions),
            (1, 0, 1),
            "{rep:?}"
        );
        for (i, xi) in x.iter().enumerate() {
            assert!((xi - 0.5 * i as f64).abs() < 1e-12, "{x:?}");
        }
    }
}
