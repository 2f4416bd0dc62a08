//! One quasi-static solve as the Newton core's problem ([`crate::solver::newton`]): the
//! convergence check, the direction, and the search line along it with its trial points.

use super::forcing::forcing;
use super::model::{Model, Point};
use super::{SolverError, StaticSolver};
use crate::solver::linesearch::{judge, EnergyMerit, Trial};
use crate::solver::newton::{Check, NewtonProblem, Rejection, Verdict};
use crate::solver::status::{SolveReport, SolveStatus};
use std::time::Instant;

/// The search line of the last Newton direction.
#[derive(Default)]
pub(super) struct SearchLine {
    /// The direction [Δx over free dofs (m); μ⁺ − μ].
    step: Vec<f64>,
    /// It came from a lagged factor (a rejected search retries with a fresh one).
    lagged: bool,
    /// Whether trials evaluate the energy merit ψ (the settings ask for it).
    with_merit: bool,
    /// ψ(0) and ψ'(0) when they can judge steps (ψ'(0) < 0).
    merit0: Option<EnergyMerit>,
    /// μ⁺ = μ + Δμ, held fixed in ψ.
    mu_plus: Vec<f64>,
    /// The last trial point evaluated.
    trial: Option<Point>,
}

impl SearchLine {
    /// The line from `at` along `step`. The energy merit (when `with_merit`) is
    /// ψ(t) = E − fᵀx + γ μ⁺ᵀ (Cx − d) with μ⁺ = μ + Δμ fixed, so
    /// ψ'(0) = r_xᵀ Δx + γ Δμᵀ C Δx.
    fn new(m: &Model, at: &Point, step: Vec<f64>, lagged: bool, with_merit: bool) -> Self {
        let (nf, nc, gamma) = (m.free(), m.rows(), m.gamma);
        let merit0 = if with_merit {
            let mut cdx = vec![0.0; nc];
            for &(row, j, v) in &m.s.cfree {
                cdx[row] += v * step[j];
            }
            let slope = at.r[..nf]
                .iter()
                .zip(&step[..nf])
                .map(|(a, b)| a * b)
                .sum::<f64>()
                + gamma * step[nf..].iter().zip(&cdx).map(|(a, b)| a * b).sum::<f64>();
            let viol = m.p.constraints.apply(&at.x);
            let value = at.energy
                + gamma
                    * viol
                        .iter()
                        .zip(&m.p.constraints.rhs)
                        .zip(&at.mu)
                        .zip(&step[nf..])
                        .map(|(((cx, d), m), dm)| (m + dm) * (cx - d))
                        .sum::<f64>();
            Some(EnergyMerit { value, slope })
        } else {
            None
        };
        let mu_plus: Vec<f64> = at.mu.iter().zip(&step[nf..]).map(|(m, d)| m + d).collect();
        Self {
            step,
            lagged,
            with_merit,
            merit0: merit0.and_then(EnergyMerit::descending),
            mu_plus,
            trial: None,
        }
    }

    /// The point at step length `t` from `at` (free dofs and multipliers move).
    fn point_at(&self, m: &Model, at: &Point, t: f64) -> Point {
        let nf = m.free();
        let mut x = at.x.clone();
        for (k, &d) in m.s.free.iter().enumerate() {
            x[d] = at.x[d] + t * self.step[k];
        }
        let mu: Vec<f64> = (0..at.mu.len())
            .map(|i| at.mu[i] + t * self.step[nf + i])
            .collect();
        m.point(x, mu)
    }

    /// The energy merit ψ at `pt` (J), NaN when the line has none.
    fn merit(&self, m: &Model, pt: &Point) -> f64 {
        if !self.with_merit {
            return f64::NAN;
        }
        let cx = m.p.constraints.apply(&pt.x);
        pt.energy
            + m.gamma
                * cx.iter()
                    .zip(&m.p.constraints.rhs)
                    .zip(&self.mu_plus)
                    .map(|((c, d), m)| m * (c - d))
                    .sum::<f64>()
    }
}

/// One quasi-static solve as a [`NewtonProblem`]: the solver's linear algebra (KKT LDLᵀ
/// with inertia control, lagged factors, GMRES) and the current iterate.
pub(super) struct StaticNewton<'a, 'm> {
    /// The solver whose linear algebra the directions use.
    pub(super) solver: &'a mut StaticSolver,
    /// The solve's fixed data.
    pub(super) model: Model<'m>,
    /// The current iterate.
    pub(super) at: Point,
    /// ‖r‖ before the last accepted step (N), for the inexact-Newton forcing term.
    pub(super) rn_prev: Option<f64>,
    /// Which Hessian the solver holds at `at.x` (`Some(projected)`), if any.
    pub(super) have_hessian: Option<bool>,
    /// The report the work is counted in.
    pub(super) rep: &'a mut SolveReport,
    /// The search line of the last direction.
    pub(super) line: SearchLine,
}

impl NewtonProblem for StaticNewton<'_, '_> {
    type Error = SolverError;

    fn check(&mut self) -> Check {
        if !self.at.rn.is_finite() {
            Check::NotFinite
        } else if self.at.rn <= self.solver.settings.tolerance {
            Check::Converged
        } else {
            Check::Continue
        }
    }

    /// Solve `[K γCᵀ; γC 0] [Δx; μ⁺] = [−(∇E − f + γCᵀμ); −γ(Cx − d)]`: with the γCᵀμ term
    /// on the right-hand side the multiplier part of the solution is μ⁺ − μ directly.
    fn direction(&mut self, _iteration: usize) -> Result<Option<SolveStatus>, SolverError> {
        let st = self.solver.settings;
        let lin_tol = forcing(st.linear_tolerance, st.tolerance, self.at.rn, self.rn_prev);
        let mut step: Vec<f64> = self.at.r.iter().map(|v| -v).collect();
        let lagged = self.try_lagged(lin_tol, &mut step)?;
        let factored = lagged || self.factor_with_inertia_control()?;
        self.have_hessian = None;
        if !factored {
            return Ok(Some(SolveStatus::NotFinite));
        }
        if !lagged {
            self.solver.solve_fresh(&mut step, lin_tol, self.rep);
        }
        if step.iter().any(|v| !v.is_finite()) {
            return Ok(Some(SolveStatus::NotFinite));
        }
        let t = Instant::now();
        self.line = SearchLine::new(&self.model, &self.at, step, lagged, st.energy_merit);
        self.rep.line_search_s += t.elapsed().as_secs_f64();
        Ok(None)
    }

    fn trial(&mut self, t: f64) -> Verdict {
        let clock = Instant::now();
        let pt = self.line.point_at(&self.model, &self.at, t);
        let merit = self.line.merit(&self.model, &pt);
        let tr = Trial {
            residual: pt.rn,
            merit,
        };
        self.line.trial = Some(pt);
        self.rep.line_search_s += clock.elapsed().as_secs_f64();
        judge(self.at.rn, self.line.merit0, t, tr)
    }

    fn accept(&mut self, _t: f64) -> Option<SolveStatus> {
        let pt = self
            .line
            .trial
            .take()
            .expect("the accepted trial was evaluated");
        self.rn_prev = Some(self.at.rn);
        self.at = pt;
        None
    }

    /// A lagged direction that the line search rejects is retried from the same point
    /// with a fresh factorisation; a fresh one ends the solve.
    fn rejected(&mut self) -> Rejection {
        if self.line.lagged {
            self.solver.lag_layout = None;
            Rejection::Retry
        } else {
            Rejection::Stop(SolveStatus::LineSearchFailed)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::{quartic_problem, QUARTIC};
    use super::super::{StaticSettings, StaticSolver};
    use crate::solver::SolveStatus;

    /// Pinned x0 = 0.5; x1 + x2 = 2 → x1 = x2 = 1, multiplier λ = −1; force 8 on x3 →
    /// x3 = 2; force −1 on x4 → x4 = −1; x5 free, no force → 0 (Hessian singular there at
    /// the solution, so the solver must cope with a vanishing curvature).
    #[test]
    fn newton_finds_known_constrained_minimum_and_reuses_analysis() {
        let p = quartic_problem();
        let settings = StaticSettings {
            tolerance: 1e-10,
            gamma: Some(1.0),
            ..Default::default()
        };
        let mut solver = StaticSolver::new(settings).unwrap();
        let mut x = vec![0.5, 3.0, -0.5, 1.0, 1.0, 0.0];
        let rep = solver.solve(&QUARTIC, &p, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        let exact = [0.5, 1.0, 1.0, 2.0, -1.0, 0.0];
        for (a, b) in x.iter().zip(exact) {
            assert!((a - b).abs() < 1e-9, "{x:?}");
        }
        assert!((solver.multipliers()[0] + 1.0).abs() < 1e-9);
        // Warm start at the answer: zero iterations; new rhs: one analysis in total.
        let rep2 = solver.solve(&QUARTIC, &p, &mut x).unwrap();
        assert_eq!((rep2.status, rep2.iterations), (SolveStatus::Converged, 0));
        let mut p3 = p.clone();
        p3.constraints.rhs[0] = -4.0;
        let rep3 = solver.solve(&QUARTIC, &p3, &mut x).unwrap();
        assert_eq!(rep3.status, SolveStatus::Converged);
        assert!((x[1] + 2.0).abs() < 1e-9 && (x[2] + 2.0).abs() < 1e-9);
        assert_eq!(solver.symbolic_analyses(), 1);
        // Bad input is an error naming the problem.
        let mut short = vec![0.0; 3];
        assert!(solver.solve(&QUARTIC, &p, &mut short).is_err());
        let mut nan = vec![f64::NAN; 6];
        assert!(solver.solve(&QUARTIC, &p, &mut nan).is_err());
    }
}
