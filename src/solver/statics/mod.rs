//! Quasi-static equilibrium: minimise E(x) − fᵀx subject to linear equality constraints
//! C x = d and pinned dofs, by Newton's method on the KKT system with the residual-norm
//! line search of [`crate::solver::linesearch`], from a warm start.
//!
//! Each iteration solves
//! `[K γCᵀ; γC 0] [Δx; μ⁺] = [−(∇E − f); −γ(Cx − d)]` over the free dofs (see
//! [`crate::solver::kkt`]) and searches along (Δx, μ⁺ − μ) on ‖r‖,
//! r = [∇E − f + γCᵀμ; γ(Cx − d)]. The multiplier of the constraints in newtons is λ = γ μ.
//! The Hessian is the exact one when the KKT inertia says it is positive definite on the
//! constraint null space, else the exact one shifted by τ I (inertia correction), else the
//! element-projected one ([`HessianMode::Auto`]). The solver object keeps the sparsity
//! pattern, the symbolic factorisation, γ and the multipliers between calls, so frame after
//! frame only numeric work is done.
//!
//! It also keeps the previous solution: when a solve starts with the same pinned set but
//! moved pinned values, a pinned-motion predictor first takes the linearised response of
//! the free dofs to that motion about the previous solution (one factorisation), so a
//! frame-to-frame boundary change does not start Newton from a state with suddenly
//! compressed boundary elements, which costs Newton iterations and factorisations.
//!
//! This file holds the solver object and its entry points; the parts live in:
//!
//! - `problem`: the problem (pinned dofs, linear constraints, forces) and its checks;
//! - `settings`: the settings and the linear-algebra presets;
//! - `setup`: the free-dof set-up of a problem, cached between solves;
//! - `layout`: the Hessian's layout and the assembly of the KKT matrix from it;
//! - `model`: one solve's fixed data and a Newton iterate with its KKT residual;
//! - `direction`: a Newton direction from a lagged factor, patches or a fresh factor;
//! - `inertia`: the ladder of Hessians a direction is factorised with (inertia correction);
//! - `predictor`: the pinned-motion predictor that gives Newton its start;
//! - `continuation`: solving in load increments;
//! - `newton_problem`: one solve as the Newton core's problem (search line and steps).

mod continuation;
mod direction;
mod forcing;
mod inertia;
mod layout;
mod model;
mod newton_problem;
mod predictor;
mod problem;
mod settings;
mod setup;
#[cfg(test)]
mod test_energies;

pub use problem::{LinearConstraints, StaticProblem};
pub use settings::{HessianMode, LinearAlgebra, StaticSettings};

use super::kkt::KktSolver;
use super::newton::{self, NewtonLimits};
use super::patch::PatchSet;
use super::status::{SolveReport, SolveStatus};
use crate::math::sparse::SparseError;
use crate::math::Energy;
use direction::FactorLayout;
use layout::energy_identity;
use model::{Model, Point};
use newton_problem::{SearchLine, StaticNewton};
use setup::{Setup, SetupInput};
use std::sync::Arc;
use std::time::Instant;

/// Bad input to the quasi-static solver.
#[derive(Debug, thiserror::Error)]
pub enum SolverError {
    /// Settings out of range (the field is named).
    #[error("static solver settings: {0}")]
    Settings(String),
    /// Sizes or indices that do not match the energy.
    #[error("static problem: {0}")]
    Problem(String),
    /// Sparse assembly failure.
    #[error(transparent)]
    Sparse(#[from] SparseError),
}

/// Where a solve ended and the energy's gradient there.
#[derive(Debug, Clone)]
struct EndGradient {
    /// The energy's identity ([`energy_identity`]).
    owner: (usize, usize),
    /// The final state (flat, m).
    x: Vec<f64>,
    /// ∇E at `x` (flat, N).
    grad: Vec<f64>,
}

/// A quasi-static Newton solver that keeps its factorisation analysis, γ and the constraint
/// multipliers between calls (hold one per skin, call [`StaticSolver::solve`] every frame).
#[derive(Default)]
pub struct StaticSolver {
    /// Settings used by every solve.
    pub settings: StaticSettings,
    /// The KKT factorisation with its cached pattern and symbolic analysis.
    kkt: KktSolver,
    /// Row balance γ of the KKT system (N/m), once the settings or a first Hessian gave it.
    gamma: Option<f64>,
    /// Scaled constraint multipliers μ of the last solve (λ = γ μ).
    multipliers: Vec<f64>,
    /// Hessian triplets of the last full evaluation (their indices give the layout).
    trip: Vec<(usize, usize, f64)>,
    /// `trip` holds the layout of the energy of the current solve (set by its first Hessian;
    /// later Hessians are scattered into the KKT matrix by that layout).
    trip_current: bool,
    /// The energy whose layout `trip` holds (its address and dof count): a solve of the same
    /// energy keeps the layout, so a frame's first Hessian costs values only.
    trip_owner: Option<(usize, usize)>,
    /// Hash of the indices of `trip` (with the free set and constraint pattern, the KKT
    /// layout key).
    trip_key: u64,
    /// The triplet count of the layout (`trip` is emptied once the KKT matrix holds the
    /// layout and the energy scatters its values).
    trip_len: usize,
    /// Shift / γ of the last shifted exact Hessian a direction was factorised with (0 before
    /// any).
    last_shift: f64,
    /// Final state of the previous solve and its pinned dofs (for the pinned-motion predictor).
    last_x: Vec<f64>,
    /// The previous solve's gradient at its end, which it evaluated anyway
    /// ([`StaticSolver::gradient_at`]).
    last_gradient: Option<EndGradient>,
    /// The pinned dofs of the previous solve.
    last_pinned: Vec<usize>,
    /// Layout of the current factorisation when it may precondition later directions (a
    /// lagged factor): it was of the exact, unshifted Hessian and passed the inertia test.
    lag_layout: Option<FactorLayout>,
    /// The last lagged direction solved the exact Newton system but had non-positive
    /// curvature: the Hessian at the iterate is not positive definite on the constraints'
    /// null space, so the inertia correction starts at a shift.
    seen_indefinite: bool,
    /// The last exact (τ = 0) factorisation of this solve found at least two negative
    /// directions beyond the constraints' and no direction has skipped the exact Hessian
    /// since: the next direction's inertia correction starts at a shift.
    expect_indefinite: bool,
    /// The next solve's directions are factorised afresh until an exact factor passes the
    /// inertia test ([`StaticSolver::factorise_next_solve`]).
    fresh_next: bool,
    /// GMRES iterations of the last lagged direction (0 after a fresh factorisation).
    lag_last_iterations: usize,
    /// The patches of the current KKT layout (with `settings.patches`), and the count of
    /// symbolic analyses when they were built (a new analysis is a new layout).
    patches: Option<(PatchSet, usize)>,
    /// The set-up of the last solve and what it was built from.
    last_setup: Option<(SetupInput, Arc<Setup>)>,
}

/// A report before any work (status `IterationLimit` until the solve says otherwise).
fn empty_report() -> SolveReport {
    SolveReport {
        status: SolveStatus::IterationLimit,
        iterations: 0,
        residual: f64::NAN,
        initial_residual: f64::NAN,
        constraint_violation: 0.0,
        energy: f64::NAN,
        modified_hessian_steps: 0,
        factorizations: 0,
        lagged_directions: 0,
        linear_solves: 0,
        assembly_s: 0.0,
        symbolic_s: 0.0,
        factor_s: 0.0,
        solve_s: 0.0,
        line_search_s: 0.0,
        total_s: 0.0,
        increments: 1,
        patch_directions: 0,
        patch_factorizations: 0,
        patches_active: 0,
        patch_shifts: 0,
    }
}

impl StaticSolver {
    /// A solver with `settings` (validated).
    pub fn new(settings: StaticSettings) -> Result<Self, SolverError> {
        settings.validate()?;
        Ok(Self {
            settings,
            ..Default::default()
        })
    }

    /// Have the next solve factorise its directions afresh, each checked by the inertia
    /// test, until an exact factor passes it: a lagged factor made at a stable state cannot
    /// show that the state it is now used at has become a saddle (a flat skin compressed past
    /// its onset), and converges there.
    pub fn factorise_next_solve(&mut self) {
        self.fresh_next = true;
    }

    /// Forget every solve so far, keeping only what is independent of them (the sparsity
    /// layout, its symbolic analysis and patches): the next solve starts as a new solver's
    /// first would (γ from its first Hessian, no multipliers, no lagged factor, no predictor).
    pub fn forget_solves(&mut self) {
        self.gamma = None;
        self.multipliers.clear();
        self.last_shift = 0.0;
        self.last_x.clear();
        self.last_gradient = None;
        self.last_pinned.clear();
        self.lag_layout = None;
        self.seen_indefinite = false;
        self.expect_indefinite = false;
        self.fresh_next = false;
        self.lag_last_iterations = 0;
    }

    /// Number of symbolic analyses done so far (1 while the problem's structure is fixed).
    pub fn symbolic_analyses(&self) -> usize {
        self.kkt.symbolic_count
    }

    /// Constraint forces multipliers λ = γ μ (N per unit of constraint), one per row.
    pub fn multipliers(&self) -> Vec<f64> {
        let g = self.gamma.unwrap_or(1.0);
        self.multipliers.iter().map(|m| g * m).collect()
    }

    /// Record the end point: residual, energy and constraint violation into `rep`, the
    /// positions into `x`, and the multipliers and state for the next solve.
    fn finish(&mut self, m: &Model, end: Point, x: &mut [f64], rep: &mut SolveReport) {
        let p = m.p;
        rep.residual = end.rn;
        rep.energy = end.energy;
        let cx = p.constraints.apply(&end.x);
        rep.constraint_violation = cx
            .iter()
            .zip(&p.constraints.rhs)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        x.copy_from_slice(&end.x);
        self.multipliers = end.mu;
        self.last_gradient = Some(EndGradient {
            owner: energy_identity(m.e),
            x: end.x.clone(),
            grad: end.grad,
        });
        self.last_x = end.x;
        self.last_pinned = p.pinned.clone();
    }

    /// The gradient ∇E (flat, N) of energy `e` at `x` as the last solve evaluated it, when
    /// that solve was of `e` and ended exactly at `x`, and `e` has not changed since (the
    /// caller's word: [`StaticSolver::forget_gradient`] after changing it); `None`
    /// otherwise.
    pub fn gradient_at(&self, e: &dyn Energy, x: &[f64]) -> Option<&[f64]> {
        match &self.last_gradient {
            Some(g) if g.owner == energy_identity(e) && g.x == x => Some(&g.grad),
            _ => None,
        }
    }

    /// Forget the Hessian layout of the energy last solved, and its gradient: the next
    /// solve takes its layout from its energy's first Hessian. For an energy whose elements
    /// changed in place, which its address and dof count alone do not show.
    pub fn forget_layout(&mut self) {
        self.trip.clear();
        self.trip_current = false;
        self.trip_owner = None;
        self.trip_len = 0;
        self.last_gradient = None;
    }

    /// Drop the last solve's gradient (the energy changed: material, thickness, rest state).
    pub fn forget_gradient(&mut self) {
        self.last_gradient = None;
    }

    /// The residual norm ‖[∇E − f + γCᵀμ; γ(Cx − d)]‖ (N) of `x` with the multipliers of the
    /// last solve: the quantity every solve's convergence test compares with the tolerance,
    /// evaluated the way the global reference evaluates it.
    pub fn residual_norm(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &[f64],
    ) -> Result<f64, SolverError> {
        let s = self.setup(e, p, x)?;
        let gamma = self.gamma.unwrap_or(1.0);
        let m = Model { e, p, s: &s, gamma };
        let mu = if self.multipliers.len() == p.constraints.rows {
            self.multipliers.clone()
        } else {
            vec![0.0; p.constraints.rows]
        };
        Ok(m.point(x.to_vec(), mu).rn)
    }

    /// Solve for equilibrium from the warm start `x` (updated in place; pinned dofs keep
    /// their values) by the Newton core ([`crate::solver::newton`]) on the KKT system.
    /// Returns the report; check its status.
    pub fn solve(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &mut [f64],
    ) -> Result<SolveReport, SolverError> {
        let t_start = Instant::now();
        self.settings.validate()?;
        self.kkt.set_precision(self.settings.factor_precision);
        self.kkt.set_full_storage(self.settings.patches.is_some());
        let s = self.setup(e, p, x)?;
        let owner = Some(energy_identity(e));
        self.trip_current = self.trip_current && self.trip_owner == owner;
        self.trip_owner = owner;
        let mut rep = empty_report();
        self.expect_indefinite = false;
        if self.multipliers.len() != p.constraints.rows {
            self.multipliers = vec![0.0; p.constraints.rows];
        }
        self.hessian_for_gamma(e, x, &mut rep);
        let mut have_hessian = None;
        let gamma = self.gamma_for(&s);
        let m = Model { e, p, s: &s, gamma };
        let mu = std::mem::take(&mut self.multipliers);
        let at = self.start_point(&m, x, mu, &mut have_hessian, &mut rep)?;
        let limits = NewtonLimits {
            max_iterations: self.settings.max_iterations.saturating_sub(rep.iterations),
            max_trials: self.settings.max_line_search,
        };
        let mut problem = StaticNewton {
            solver: self,
            model: m,
            at,
            rn_prev: None,
            have_hessian,
            rep: &mut rep,
            line: SearchLine::default(),
        };
        let record = newton::solve(&mut problem, &limits)?;
        let end = problem.at;
        rep.status = record.status;
        rep.iterations += record.iterations;
        self.finish(&m, end, x, &mut rep);
        self.fresh_next = false;
        rep.total_s = t_start.elapsed().as_secs_f64();
        Ok(rep)
    }
}

#[cfg(test)]
mod tests {
    use super::test_energies::{quartic_problem, Wells, QUARTIC};
    use super::*;

    /// A solve keeps the energy's gradient where it ended, the same bits a fresh evaluation
    /// gives; it is offered only for that energy at exactly that state, and not after
    /// `forget_gradient`.
    #[test]
    fn the_gradient_a_solve_ends_with_is_the_energys_at_its_end() {
        let p = quartic_problem();
        let e = QUARTIC;
        let mut solver = StaticSolver::default();
        let mut x = vec![0.5, 3.0, -0.5, 1.0, 1.0, 0.0];
        assert!(solver.gradient_at(&e, &x).is_none());
        solver.solve(&e, &p, &mut x).unwrap();
        let mut fresh = vec![0.0; 6];
        e.eval(&x, Some(&mut fresh), None, false);
        assert_eq!(solver.gradient_at(&e, &x), Some(fresh.as_slice()));
        let mut moved = x.clone();
        moved[1] += 1e-12;
        assert!(solver.gradient_at(&e, &moved).is_none());
        let other = Wells { k: 1.0, w: 0.0 };
        assert!(solver.gradient_at(&other, &x).is_none());
        solver.forget_gradient();
        assert!(solver.gradient_at(&e, &x).is_none());
    }
}
