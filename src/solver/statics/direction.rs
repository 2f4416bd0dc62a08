//! A Newton direction: its solve by GMRES with a lagged factor (alone or with fresh factors
//! of changed patches) or with a fresh factor, and the test a lagged direction must pass.

use super::model::Model;
use super::newton_problem::StaticNewton;
use super::{HessianMode, SolverError, StaticSolver};
use crate::solver::gmres::GmresReport;
use crate::solver::kkt::KktSolver;
use crate::solver::patch::{PatchSet, PatchSettings};
use crate::solver::status::SolveReport;
use std::time::Instant;

/// Whether a Newton direction `d` that GMRES left as `g` may be taken: GMRES converged, `d`
/// is finite and has positive curvature dᵀK d on the `nf` free dofs (a descent direction of
/// the energy on the constraints).
fn accepted(kkt: &KktSolver, g: &GmresReport, d: &[f64], nf: usize) -> bool {
    g.converged && d.iter().all(|v| v.is_finite()) && kkt.curvature(&d[..nf]) > 0.0
}

/// What a factorisation was built for besides the Hessian: the free constraint entries, the
/// pinned dofs, the dof count and γ.
#[derive(PartialEq)]
pub(super) struct FactorLayout {
    /// Constraint entries over the free dofs.
    pub(super) cfree: Vec<(usize, usize, f64)>,
    /// Pinned dofs.
    pub(super) pinned: Vec<usize>,
    /// Dof count.
    pub(super) dofs: usize,
    /// Row scale γ (N/m).
    pub(super) gamma: f64,
}

impl StaticSolver {
    /// Whether the current factor may precondition a direction of the model: lagging is on,
    /// the factor exists, was of the exact unshifted Hessian with the right inertia for the
    /// same free dofs, constraint matrix and γ, no fresh factor is asked for
    /// ([`StaticSolver::factorise_next_solve`]), and, without patches, the last lagged
    /// direction used at most half of the allowed solves.
    pub(super) fn lag_usable(&self, m: &Model) -> bool {
        let cap = self.settings.lagged_solves;
        cap > 0
            && !self.fresh_next
            && self.kkt.is_factored()
            && (self.settings.patches.is_some() || 2 * self.lag_last_iterations <= cap)
            && self.lag_layout.as_ref().is_some_and(|l| {
                l.dofs == m.s.free_of.len()
                    && l.gamma == m.gamma
                    && l.pinned == m.p.pinned
                    && l.cfree == m.s.cfree
            })
    }

    /// Try the Newton direction for the assembled (exact) KKT matrix by GMRES with the lagged
    /// factor, which the caller has found usable ([`Self::lag_usable`]): `rhs` becomes the
    /// direction and true is returned when GMRES converged within
    /// [`super::StaticSettings::lagged_solves`] solves and the direction has positive
    /// curvature dᵀK d on the free dofs; else `rhs` is left alone.
    pub(super) fn lagged_direction(
        &mut self,
        m: &Model,
        lin_tol: f64,
        rhs: &mut [f64],
        rep: &mut SolveReport,
    ) -> bool {
        let cap = self.settings.lagged_solves;
        let t = Instant::now();
        let mut d = rhs.to_vec();
        let g = self.kkt.solve_lagged(&mut d, cap, lin_tol);
        rep.linear_solves += g.iterations;
        rep.solve_s += t.elapsed().as_secs_f64();
        self.lag_last_iterations = g.iterations;
        let ok = accepted(&self.kkt, &g, &d, m.free());
        self.seen_indefinite = !ok && g.converged && d.iter().all(|v| v.is_finite());
        if ok {
            rhs.copy_from_slice(&d);
            rep.lagged_directions += 1;
        } else {
            // The next direction is factorised afresh.
            self.lag_last_iterations = cap;
        }
        ok
    }

    /// The patches of the current KKT layout, built when there are none or the layout
    /// changed; free dof positions are read from `x` (m).
    fn ensure_patches(&mut self, m: &Model, x: &[f64], settings: PatchSettings) {
        let count = self.kkt.symbolic_count;
        let (nf, nc) = self.kkt.sizes();
        let current = self
            .patches
            .as_ref()
            .is_some_and(|(p, c)| *c == count && p.fits(nf, nc));
        if current {
            return;
        }
        let positions: Vec<[f64; 3]> =
            m.s.free
                .iter()
                .map(|&d| {
                    let v = 3 * (d / 3);
                    [x[v], x[v + 1], x[v + 2]]
                })
                .collect();
        self.patches = Some((
            PatchSet::build(nf, nc, &positions, settings, self.settings.factor_precision),
            count,
        ));
    }

    /// Try the Newton direction for the assembled (exact) KKT matrix by GMRES with the lagged
    /// global factor and fresh factors of the patches whose Hessian changed since it
    /// ([`crate::solver::patch`]; the caller has found the lagged factor usable): `rhs`
    /// becomes the direction and true is returned when GMRES converged within the patches'
    /// `max_solves` and the direction has positive curvature on the free dofs; false (and
    /// `rhs` left alone) when the changed patches hold too much of the skin or GMRES did not
    /// get there, so a fresh global factor is made.
    pub(super) fn patched_direction(
        &mut self,
        m: &Model,
        x: &[f64],
        lin_tol: f64,
        rhs: &mut [f64],
        rep: &mut SolveReport,
    ) -> bool {
        let Some(settings) = self.settings.patches else {
            return false;
        };
        self.ensure_patches(m, x, settings);
        let StaticSolver { kkt, patches, .. } = self;
        let set = &mut patches.as_mut().expect("patches built").0;
        let work = set.prepare(kkt);
        rep.patch_factorizations += work.factorizations;
        rep.patch_shifts += work.shifted;
        rep.factor_s += work.factor_s;
        if work.share > settings.max_share {
            self.lag_last_iterations = self.settings.lagged_solves;
            return false;
        }
        let t = Instant::now();
        let shifts = set.shifts();
        let (nf, _) = kkt.sizes();
        let mut shift = vec![0.0; nf];
        for &(i, tau) in &shifts {
            shift[i] = tau;
        }
        let delta = kkt.delta();
        let mut d = rhs.to_vec();
        let g = kkt.solve_lagged_with(&mut d, settings.max_solves, lin_tol, &shifts, |a, r, z| {
            set.correct(a, delta, &shift, r, z)
        });
        rep.linear_solves += g.iterations;
        rep.solve_s += t.elapsed().as_secs_f64();
        let ok = accepted(kkt, &g, &d, nf);
        if ok {
            rhs.copy_from_slice(&d);
            rep.lagged_directions += 1;
            rep.patch_directions += 1;
            rep.patches_active += work.active;
            self.lag_last_iterations = 0;
        } else {
            self.lag_last_iterations = self.settings.lagged_solves;
        }
        ok
    }

    /// Solve the factored KKT system for `rhs` in place by GMRES preconditioned with the
    /// fresh factor, to relative tolerance `lin_tol`.
    pub(super) fn solve_fresh(&mut self, rhs: &mut [f64], lin_tol: f64, rep: &mut SolveReport) {
        let t = Instant::now();
        rep.linear_solves += self.kkt.solve(rhs, self.settings.refinement_steps, lin_tol);
        rep.solve_s += t.elapsed().as_secs_f64();
    }
}

impl StaticNewton<'_, '_> {
    /// The direction by GMRES with the lagged factor of the exact Hessian, when that factor
    /// may be used: returns whether `step` now holds it.
    pub(super) fn try_lagged(
        &mut self,
        lin_tol: f64,
        step: &mut [f64],
    ) -> Result<bool, SolverError> {
        let m = &self.model;
        if self.solver.settings.hessian == HessianMode::Projected || !self.solver.lag_usable(m) {
            return Ok(false);
        }
        let rep = &mut *self.rep;
        self.solver
            .assemble_hessian(m, &self.at.x, false, &mut self.have_hessian, rep)?;
        if !self.solver.lag_usable(m) {
            // The assembly found a new layout: the factor went with the old analysis.
            return Ok(false);
        }
        let done = if self.solver.settings.patches.is_some() {
            self.solver
                .patched_direction(m, &self.at.x, lin_tol, step, rep)
        } else {
            self.solver.lagged_direction(m, lin_tol, step, rep)
        };
        Ok(done)
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::{quartic_problem, Wells, QUARTIC};
    use super::super::{LinearConstraints, StaticProblem, StaticSettings};
    use super::*;
    use crate::math::Energy;
    use crate::solver::SolveStatus;

    /// Directions may come from a lagged factor (of an earlier iterate or the previous
    /// solve) by GMRES: the answer must be the exact one and the same as a solver's that
    /// factorises every direction, when the constraint target moves far (stale Hessian 3
    /// against 12 at the answer) and even when the energy itself changed between the solves
    /// (100× stiffer); a changed constraint matrix must not use the old factor at all. A
    /// unit force on x5 keeps every Hessian at the answers regular (without it x5 → 0, the
    /// last factor is a shifted one and may not be lagged).
    #[test]
    fn a_lagged_factor_changes_only_the_cost_not_the_answer() {
        let base = StaticProblem {
            forces: vec![0.0, 0.0, 0.0, 8.0, -1.0, 1.0],
            ..quartic_problem()
        };
        let settings = StaticSettings {
            tolerance: 1e-10,
            gamma: Some(1.0),
            ..Default::default()
        };
        let every = StaticSettings {
            lagged_solves: 0,
            ..settings
        };
        let start = vec![0.5, 3.0, -0.5, 1.0, 1.0, 0.0];
        let mut moved = base.clone();
        moved.constraints.rhs[0] = -4.0;
        // (energy, problem, exact answer, whether the old factor may serve)
        type Case = (Box<dyn Energy>, StaticProblem, [f64; 6], bool);
        let cases: Vec<Case> = vec![
            (
                Box::new(QUARTIC),
                moved.clone(),
                [0.5, -2.0, -2.0, 2.0, -1.0, 1.0],
                true,
            ),
            (
                Box::new(Wells { k: 100.0, w: 0.0 }),
                base.clone(),
                [
                    0.5,
                    1.0,
                    1.0,
                    0.08f64.cbrt(),
                    -(0.01f64.cbrt()),
                    0.01f64.cbrt(),
                ],
                true,
            ),
            (
                Box::new(QUARTIC),
                StaticProblem {
                    constraints: LinearConstraints {
                        rows: 1,
                        entries: vec![(0, 1, 1.0), (0, 2, 3.0)],
                        rhs: vec![4.0],
                    },
                    ..base.clone()
                },
                // x1³ = μ, x2³ = 3μ → x2 = ∛3 x1, x1 (1 + 3∛3) = 4.
                {
                    let x1 = 4.0 / (1.0 + 3.0 * 3f64.cbrt());
                    [0.5, x1, 3f64.cbrt() * x1, 2.0, -1.0, 1.0]
                },
                false,
            ),
        ];
        for (k, (energy, problem, exact, lag)) in cases.into_iter().enumerate() {
            let mut warm = StaticSolver::new(settings).unwrap();
            let mut x = start.clone();
            assert!(warm.solve(&QUARTIC, &base, &mut x).unwrap().status == SolveStatus::Converged);
            let set_up = warm.setup(energy.as_ref(), &problem, &x).unwrap();
            let model = Model {
                e: energy.as_ref(),
                p: &problem,
                s: &set_up,
                gamma: 1.0,
            };
            assert_eq!(warm.lag_usable(&model), lag, "case {k}");
            let rep = warm.solve(energy.as_ref(), &problem, &mut x).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged, "case {k}: {rep:?}");
            if lag {
                assert!(rep.lagged_directions > 0, "case {k}: {rep:?}");
            }
            let mut fresh = StaticSolver::new(every).unwrap();
            let mut y = start.clone();
            let rep = fresh.solve(energy.as_ref(), &problem, &mut y).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged, "case {k}: {rep:?}");
            assert_eq!(rep.lagged_directions, 0, "case {k}: {rep:?}");
            for i in 0..6 {
                assert!(
                    (x[i] - exact[i]).abs() < 1e-8,
                    "case {k}: {x:?} against {exact:?}"
                );
                assert!(
                    (y[i] - exact[i]).abs() < 1e-8,
                    "case {k}: {y:?} against {exact:?}"
                );
            }
        }
    }
}
