//! Quasi-static equilibrium: minimise E(x) − fᵀx subject to linear equality constraints
//! C x = d and pinned dofs, by Newton's method on the KKT system with the residual-norm
//! line search of DESIGN.md, from a warm start.
//!
//! Each iteration solves
//! `[K γCᵀ; γC 0] [Δx; μ⁺] = [−(∇E − f); −γ(Cx − d)]` over the free dofs (see
//! [`super::kkt`]) and searches along (Δx, μ⁺ − μ) on ‖r‖, r = [∇E − f + γCᵀμ; γ(Cx − d)].
//! The multiplier of the constraints in newtons is λ = γ μ. The Hessian is the exact one
//! when the KKT inertia says it is positive definite on the constraint null space, else the
//! exact one shifted by τ I (inertia correction), else the element-projected one
//! ([`HessianMode::Auto`]). The solver object keeps the
//! sparsity pattern, the symbolic factorisation, γ and the multipliers between calls, so
//! frame after frame only numeric work is done.
//!
//! It also keeps the previous solution: when a solve starts with the same pinned set but
//! moved pinned values, a pinned-motion predictor first takes the linearised response of
//! the free dofs to that motion about the previous solution (one factorisation), so a
//! frame-to-frame boundary change does not start Newton from a state with suddenly
//! compressed boundary elements (the shell bench at 20k faces: 9 → 4 iterations,
//! 22 → 4 factorisations).

use super::gmres::GmresReport;
use super::kkt::{FactorPrecision, HessianValues, KktBlocks, KktFactorInfo, KktSolver};
use super::linesearch::{judge, EnergyMerit, Trial};
use super::newton::{self, Check, NewtonLimits, NewtonProblem, Rejection, Verdict};
use super::patch::{PatchSet, PatchSettings};
use super::status::{SolveReport, SolveStatus};
use crate::math::hash::Fnv1a;
use crate::math::sparse::SparseError;
use crate::math::vector::norm;
use crate::math::Energy;
use std::sync::Arc;
use std::time::Instant;

/// Linear equality constraints C x = d over the flat dofs (c rows × 3n columns).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LinearConstraints {
    /// Number of rows c.
    pub rows: usize,
    /// Nonzeros `(row, dof, coefficient)` of C (dimensionless weights for position
    /// constraints); duplicates are summed.
    pub entries: Vec<(usize, usize, f64)>,
    /// Right-hand side d (length `rows`, units of the constrained quantity, m).
    pub rhs: Vec<f64>,
}

impl LinearConstraints {
    /// No constraints.
    pub fn none() -> Self {
        Self::default()
    }

    /// C x (length `rows`).
    pub fn apply(&self, x: &[f64]) -> Vec<f64> {
        let mut y = vec![0.0; self.rows];
        for &(r, j, v) in &self.entries {
            y[r] += v * x[j];
        }
        y
    }
}

/// A quasi-static problem: which dofs are pinned (held at their value in the start state),
/// the linear constraints, and the external forces.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct StaticProblem {
    /// Pinned dof indices (3 × vertex + axis); their values are taken from the start state.
    pub pinned: Vec<usize>,
    /// Linear equality constraints.
    pub constraints: LinearConstraints,
    /// External forces per dof (N); empty for none.
    pub forces: Vec<f64>,
}

/// Which Hessian Newton uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum HessianMode {
    /// The exact Hessian always (quadratic convergence; may head for saddles).
    Exact,
    /// Element Hessians projected to PSD always (robust, linear convergence near the end).
    Projected,
    /// Exact when it is positive definite on the constraint null space (checked by the
    /// inertia of the KKT factorisation), else projected, else shifted.
    Auto,
}

/// Settings of the quasi-static solve.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StaticSettings {
    /// Convergence tolerance on the residual norm (N).
    pub tolerance: f64,
    /// Maximum Newton iterations.
    pub max_iterations: usize,
    /// Hessian choice.
    pub hessian: HessianMode,
    /// Row balance γ of the KKT system (N/m); `None`: the mean diagonal of the first
    /// Hessian (of the order of E h for a shell).
    pub gamma: Option<f64>,
    /// Most GMRES iterations beyond the first when a KKT system is solved with its own fresh
    /// factor (each one linear solve with the factor); they remove the δ regularisation of
    /// the constraint block (see [`super::kkt`]).
    pub refinement_steps: usize,
    /// Tightest relative residual ‖r‖/‖b‖ a GMRES solve of a KKT system is asked for.
    /// Newton asks for less while it is far from the answer (inexact Newton: the forcing
    /// term of Eisenstat and Walker, at most 1e-3, and never tighter than needed to land 10×
    /// under `tolerance`); this is the floor, which gives the same wrinkles as solving every
    /// direction to 1e-10.
    pub linear_tolerance: f64,
    /// Most factor solves (GMRES iterations) a Newton direction may spend with a *lagged*
    /// factorisation, one of an earlier iterate or of the previous solve, before a fresh
    /// one is made; 0 factorises every direction. A lagged direction is the exact Newton
    /// direction to `linear_tolerance`, so the lag changes the cost, not the path. It is
    /// used only while the last factor was of the exact, unshifted Hessian with the right
    /// inertia, and only when the direction has positive curvature; else the direction is
    /// factorised afresh with the inertia test. A failed attempt costs its solves on top
    /// of the factorisation, so the cap is small: a larger one spends more on failed
    /// attempts than it saves in factorisations.
    pub lagged_solves: usize,
    /// Maximum trial steps per line search.
    pub max_line_search: usize,
    /// Also accept steps that satisfy Armijo on the energy merit (the Lagrangian with the
    /// new multipliers), not only on the residual norm. The residual rule alone is `false`;
    /// thin shells moving out of plane need `true` (see
    /// [`super::linesearch`]).
    pub energy_merit: bool,
    /// Solve Newton directions with the lagged global factor and fresh factors of only the
    /// patches whose Hessian changed ([`super::patch`]); `None`: the global reference (a
    /// fresh global factor whenever the lagged one does not do within `lagged_solves`).
    #[serde(default)]
    pub patches: Option<PatchSettings>,
    /// Precision of the KKT factors (they precondition GMRES on the double-precision
    /// system, so this changes the cost of a direction, not its accuracy; see
    /// [`FactorPrecision`]).
    #[serde(default)]
    pub factor_precision: FactorPrecision,
}

impl Default for StaticSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-8,
            max_iterations: 50,
            hessian: HessianMode::Auto,
            gamma: None,
            refinement_steps: 3,
            linear_tolerance: 1e-10,
            lagged_solves: 5,
            max_line_search: 30,
            energy_merit: false,
            patches: None,
            factor_precision: FactorPrecision::Double,
        }
    }
}

/// The linear algebra of the skin's Newton directions: how many GMRES solves a lagged factor
/// may spend on a direction before a fresh one is made, and the factors' precision.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinearAlgebra {
    /// [`StaticSettings::lagged_solves`].
    pub lagged_solves: usize,
    /// [`StaticSettings::factor_precision`].
    pub precision: FactorPrecision,
}

impl LinearAlgebra {
    /// The reference (`solver.skin_solver = "global"`): double-precision factors, a fresh
    /// one when the lagged one needs more than 5 solves.
    pub const REFERENCE: Self = Self {
        lagged_solves: 5,
        precision: FactorPrecision::Double,
    };

    /// The fast default (`solver.skin_solver = "lagged"`): single-precision factors, kept
    /// while they precondition a direction within 10 solves. On the demo's frames 0–39 the
    /// cap of 10 halved the factorisations against 5 (37 against 60, skin 16.6 s against
    /// 19.1 s); 20 was no faster.
    pub const FAST: Self = Self {
        lagged_solves: 10,
        precision: FactorPrecision::Single,
    };

    /// `settings` with this linear algebra.
    pub fn apply(self, settings: StaticSettings) -> StaticSettings {
        StaticSettings {
            lagged_solves: self.lagged_solves,
            factor_precision: self.precision,
            ..settings
        }
    }
}

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

impl StaticSettings {
    /// Check the settings; the error names the bad field.
    pub fn validate(&self) -> Result<(), SolverError> {
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return Err(SolverError::Settings(format!(
                "tolerance = {} must be > 0 (N)",
                self.tolerance
            )));
        }
        if self.max_iterations == 0 {
            return Err(SolverError::Settings(
                "max_iterations must be at least 1".into(),
            ));
        }
        if let Some(g) = self.gamma {
            if !(g.is_finite() && g > 0.0) {
                return Err(SolverError::Settings(format!(
                    "gamma = {g} must be > 0 (N/m)"
                )));
            }
        }
        if !(self.linear_tolerance > 0.0 && self.linear_tolerance < 1.0) {
            return Err(SolverError::Settings(format!(
                "linear_tolerance = {} must be in (0, 1)",
                self.linear_tolerance
            )));
        }
        if self.max_line_search == 0 {
            return Err(SolverError::Settings(
                "max_line_search must be at least 1".into(),
            ));
        }
        if let Some(p) = &self.patches {
            p.validate().map_err(SolverError::Settings)?;
        }
        Ok(())
    }
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
    kkt: KktSolver,
    gamma: Option<f64>,
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
    last_shift: f64,
    /// Final state of the previous solve and its pinned dofs (for the pinned-motion predictor).
    last_x: Vec<f64>,
    /// The previous solve's gradient at its end, which it evaluated anyway
    /// ([`StaticSolver::gradient_at`]).
    last_gradient: Option<EndGradient>,
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

/// Whether a Newton direction `d` that GMRES left as `g` may be taken: GMRES converged, `d`
/// is finite and has positive curvature dᵀK d on the `nf` free dofs (a descent direction of
/// the energy on the constraints).
fn accepted(kkt: &KktSolver, g: &GmresReport, d: &[f64], nf: usize) -> bool {
    g.converged && d.iter().all(|v| v.is_finite()) && kkt.curvature(&d[..nf]) > 0.0
}

/// What a factorisation was built for besides the Hessian: the free constraint entries, the
/// pinned dofs, the dof count and γ.
#[derive(PartialEq)]
struct FactorLayout {
    cfree: Vec<(usize, usize, f64)>,
    pinned: Vec<usize>,
    dofs: usize,
    gamma: f64,
}

struct Setup {
    free_of: Vec<usize>,
    free: Vec<usize>,
    cfree: Vec<(usize, usize, f64)>,
    /// Hash of the free set and the constraint pattern (with the Hessian's layout, the KKT
    /// matrix's layout key).
    key: u64,
}

/// What a [`Setup`] was built from: the dof count, the pinned dofs and the constraint rows
/// and entries (values as bits).
struct SetupInput {
    dofs: usize,
    rows: usize,
    pinned: Vec<usize>,
    entries: Vec<(usize, usize, u64)>,
}

impl SetupInput {
    fn of(dofs: usize, p: &StaticProblem) -> Self {
        let c = &p.constraints;
        Self {
            dofs,
            rows: c.rows,
            pinned: p.pinned.clone(),
            entries: c
                .entries
                .iter()
                .map(|&(r, d, v)| (r, d, v.to_bits()))
                .collect(),
        }
    }

    /// Whether `p` for `dofs` dofs is what this was made from.
    fn is_of(&self, dofs: usize, p: &StaticProblem) -> bool {
        let c = &p.constraints;
        self.dofs == dofs
            && self.rows == c.rows
            && self.pinned == p.pinned
            && self.entries.len() == c.entries.len()
            && self
                .entries
                .iter()
                .zip(&c.entries)
                .all(|(a, b)| (a.0, a.1, a.2) == (b.0, b.1, b.2.to_bits()))
    }
}

/// Check the sizes of `p`'s forces and constraint right-hand side and the start `x` for
/// `n` dofs (its length, all finite).
fn check_start(n: usize, p: &StaticProblem, x: &[f64]) -> Result<(), SolverError> {
    if x.len() != n {
        return Err(SolverError::Problem(format!(
            "x has {} values, the energy has {n} dofs",
            x.len()
        )));
    }
    if !p.forces.is_empty() && p.forces.len() != n {
        return Err(SolverError::Problem(format!(
            "forces has {} values, expected {n} (or none)",
            p.forces.len()
        )));
    }
    let c = &p.constraints;
    if c.rhs.len() != c.rows {
        return Err(SolverError::Problem(format!(
            "constraint rhs has {} values for {} rows",
            c.rhs.len(),
            c.rows
        )));
    }
    if x.iter().any(|v| !v.is_finite()) {
        return Err(SolverError::Problem(
            "start state x contains NaN or infinity".into(),
        ));
    }
    Ok(())
}

/// FNV-1a hash of the free set `free_of` and the pattern of the constraint entries `cfree`.
fn setup_key(free_of: &[usize], cfree: &[(usize, usize, f64)]) -> u64 {
    let mut h = Fnv1a::new();
    h.mix_usize(free_of.len());
    free_of.iter().for_each(|&f| h.mix_usize(f));
    h.mix_usize(cfree.len());
    for &(r, j, _) in cfree {
        h.mix_usize(r);
        h.mix_usize(j);
    }
    h.finish()
}

/// Which energy a Hessian layout belongs to: its address and dof count.
fn energy_identity(e: &dyn Energy) -> (usize, usize) {
    (e as *const dyn Energy as *const () as usize, e.dofs())
}

const PINNED: usize = usize::MAX;

/// Largest relative tolerance of a KKT solve far from the solution (the loosest
/// Eisenstat–Walker forcing term).
const FORCING_MAX: f64 = 1e-3;

/// Largest relative tolerance of a KKT solve within 100× of the target residual, where
/// landing 10× below the target asks less than [`FORCING_MAX`]: a last Newton step solved
/// this loosely takes fewer GMRES solves with the lagged factor, which then lasts longer,
/// and lands on the same equilibrium.
const FORCING_NEAR: f64 = 0.1;

/// Relative tolerance of the KKT solve for the Newton direction at residual norm `rn` (N)
/// after a step from `rn_prev` (inexact Newton, Eisenstat and Walker 1996, choice 2):
/// 0.9 (rn / rn_prev)², at most [`FORCING_MAX`], and never tighter than needed to land
/// 10× below the target `tolerance` (N) (up to [`FORCING_NEAR`]) nor than `floor` (the
/// settings' linear tolerance).
fn forcing(floor: f64, tolerance: f64, rn: f64, rn_prev: Option<f64>) -> f64 {
    let ew = rn_prev.map_or(FORCING_MAX, |p| 0.9 * (rn / p).powi(2));
    ew.min(FORCING_MAX)
        .max((0.1 * tolerance / rn).min(FORCING_NEAR))
        .max(floor)
}

/// Where [`StaticSolver::assemble_at`] takes the Hessian's values from.
enum Source {
    Triplets,
    Values,
    Scatter,
}

/// Regularisation δ of the constraint block, relative to γ. The factorisation sees the
/// penalty K + (γ²/δ) CᵀC on the free block; δ = 1e-6 γ keeps that penalty (1e6 γ) strong
/// enough for the inertia test yet small enough that its round-off (1e6 γ × 1e-16) stays far
/// below the soft bending eigenvalues of a thin skin (a much smaller δ loses a thin strip's
/// lowest buckling mode in round-off). GMRES preconditioned with the factor removes δ from
/// the solution.
const KKT_DELTA: f64 = 1e-6;

/// The fixed data of one solve: the energy, the problem, its free-dof set-up and the row
/// scale γ (N/m) of the KKT system.
#[derive(Clone, Copy)]
struct Model<'a> {
    e: &'a dyn Energy,
    p: &'a StaticProblem,
    s: &'a Setup,
    gamma: f64,
}

/// A Newton iterate: positions x (all dofs, m), scaled multipliers μ (λ = γ μ), the residual
/// r over [free dofs; constraint rows] (N), the energy including the work of external forces
/// (J) and ‖r‖₂ (N).
struct Point {
    x: Vec<f64>,
    mu: Vec<f64>,
    r: Vec<f64>,
    energy: f64,
    rn: f64,
    /// ∇E at x over all dofs (N): the energy's own gradient, before external forces and
    /// constraint terms.
    grad: Vec<f64>,
}

impl Model<'_> {
    /// Free dofs.
    fn free(&self) -> usize {
        self.s.free.len()
    }

    /// Constraint rows.
    fn rows(&self) -> usize {
        self.p.constraints.rows
    }

    /// Residual vector over [free dofs; constraint rows] (N) and the energy (J), at (x, μ).
    fn residual(&self, x: &[f64], mu: &[f64]) -> (Vec<f64>, f64, Vec<f64>) {
        let (p, gamma) = (self.p, self.gamma);
        let n = x.len();
        let mut g = vec![0.0; n];
        let mut energy = self.e.eval(x, Some(&mut g), None, false);
        let grad = g.clone();
        if !p.forces.is_empty() {
            for i in 0..n {
                g[i] -= p.forces[i];
                energy -= p.forces[i] * x[i];
            }
        }
        for &(r, d, v) in &p.constraints.entries {
            g[d] += gamma * v * mu[r];
        }
        let cx = p.constraints.apply(x);
        let mut r: Vec<f64> = self.s.free.iter().map(|&d| g[d]).collect();
        r.extend(
            cx.iter()
                .zip(&p.constraints.rhs)
                .map(|(a, b)| gamma * (a - b)),
        );
        (r, energy, grad)
    }

    /// The iterate (x, μ) with its residual, energy and residual norm.
    fn point(&self, x: Vec<f64>, mu: Vec<f64>) -> Point {
        let (r, energy, grad) = self.residual(&x, &mu);
        let rn = norm(&r);
        Point {
            x,
            mu,
            r,
            energy,
            rn,
            grad,
        }
    }
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

    /// Assemble the regularised KKT matrix of the model with the Hessian at `x`
    /// (element-projected when `project`): after the energy's first Hessian (its triplets
    /// give the layout) the energy scatters its values straight into the matrix (when it
    /// says how many triplets it has and that is still the layout's count; else its values
    /// are gathered). Returns the symbolic-analysis time (s), zero when the cached analysis
    /// was reused.
    fn assemble_at(&mut self, m: &Model, x: &[f64], project: bool) -> Result<f64, SolverError> {
        let e = m.e;
        let mut values = Vec::new();
        let n = m.free() + m.rows();
        let key = |trip_key: u64| m.s.key ^ trip_key.rotate_left(29);
        let held = self.trip.len() == self.trip_len;
        let scatters = e.triplet_count() == Some(self.trip_len);
        let source = if !self.trip_current {
            self.evaluate_layout(e, x, project);
            Source::Triplets
        } else if scatters && (held || self.kkt.has_layout(n, key(self.trip_key))) {
            Source::Scatter
        } else if !held {
            self.evaluate_layout(e, x, project);
            Source::Triplets
        } else {
            e.hessian_values(x, &mut values, project);
            if values.len() == self.trip.len() {
                Source::Values
            } else {
                self.evaluate_layout(e, x, project);
                Source::Triplets
            }
        };
        let scatter = |slot: &[u32], out: &mut [f64]| e.hessian_scatter(x, slot, out, project);
        let pack = |slot: &[u32]| e.pack_slot_map(slot);
        let hessian_values = match source {
            Source::Triplets => HessianValues::Triplets,
            Source::Values => HessianValues::Values(&values),
            Source::Scatter => HessianValues::Scatter(&scatter, &pack),
        };
        let sym_s = self.kkt.assemble(&KktBlocks {
            free_of: &m.s.free_of,
            n_free: m.free(),
            n_cons: m.rows(),
            hessian: &self.trip,
            hessian_values,
            constraints: &m.s.cfree,
            gamma: m.gamma,
            delta: KKT_DELTA * m.gamma,
            layout_key: Some(key(self.trip_key)),
        })?;
        if e.triplet_count() == Some(self.trip_len) {
            // The analysed matrix keeps the layout and the energy scatters its values: the
            // triplets (24 bytes each, 16 million on a refined head) are not needed again.
            self.trip = Vec::new();
        }
        Ok(sym_s)
    }

    /// Evaluate the energy's Hessian triplets at `x` (their indices are the layout) and the
    /// hash of their indices.
    fn evaluate_layout(&mut self, e: &dyn Energy, x: &[f64], project: bool) {
        self.trip.clear();
        e.eval(x, None, Some(&mut self.trip), project);
        self.trip_len = self.trip.len();
        self.trip_current = true;
        let mut h = Fnv1a::new();
        h.mix_usize(self.trip.len());
        for &(r, c, _) in &self.trip {
            h.mix_usize(r);
            h.mix_usize(c);
        }
        self.trip_key = h.finish();
    }

    /// The free-dof set-up of `p` for energy `e`, after checking `p` and the start `x`: the
    /// last one when the dof count, pinned dofs and constraint entries are those of the last
    /// solve (the skin's cluster rows keep their entries from frame to frame, and hashing
    /// them took 5 ms of a held head frame's 13 ms), else built anew.
    fn setup(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &[f64],
    ) -> Result<Arc<Setup>, SolverError> {
        let n = e.dofs();
        check_start(n, p, x)?;
        if let Some((input, s)) = &self.last_setup {
            if input.is_of(n, p) {
                return Ok(Arc::clone(s));
            }
        }
        let s = Arc::new(self.build_setup(n, p)?);
        self.last_setup = Some((SetupInput::of(n, p), Arc::clone(&s)));
        Ok(s)
    }

    /// [`Self::setup`] built anew for `n` dofs (the start already checked).
    fn build_setup(&self, n: usize, p: &StaticProblem) -> Result<Setup, SolverError> {
        let c = &p.constraints;
        let mut free_of = vec![0usize; n];
        for &d in &p.pinned {
            if d >= n {
                return Err(SolverError::Problem(format!(
                    "pinned dof {d} out of range ({n} dofs)"
                )));
            }
            free_of[d] = PINNED;
        }
        let mut free = Vec::with_capacity(n);
        for (d, f) in free_of.iter_mut().enumerate() {
            if *f != PINNED {
                *f = free.len();
                free.push(d);
            }
        }
        let mut cfree = Vec::with_capacity(c.entries.len());
        for &(r, d, v) in &c.entries {
            if r >= c.rows || d >= n || !v.is_finite() {
                return Err(SolverError::Problem(format!(
                    "constraint entry ({r}, {d}, {v}) out of range ({} rows, {n} dofs) or not finite",
                    c.rows
                )));
            }
            if free_of[d] != PINNED {
                cfree.push((r, free_of[d], v));
            }
        }
        let key = setup_key(&free_of, &cfree);
        Ok(Setup {
            free_of,
            free,
            cfree,
            key,
        })
    }

    /// Mean |diagonal| of the free dofs of the Hessian in `trip` (N/m), 1 when it is zero.
    fn mean_diag(&self, s: &Setup) -> f64 {
        let nfree = s.free.len();
        let mut d = vec![0.0; nfree];
        for &(r, c, v) in &self.trip {
            if r == c && s.free_of[r] != PINNED {
                d[s.free_of[r]] += v;
            }
        }
        let m = d.iter().map(|v| v.abs()).sum::<f64>() / nfree.max(1) as f64;
        if m > 0.0 && m.is_finite() {
            m
        } else {
            1.0
        }
    }

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
    fn factor_fresh(&mut self, shift: f64, projected: bool, m: &Model) -> KktFactorInfo {
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

    /// Assemble the KKT matrix of the Hessian at `x` (element-projected when `project`),
    /// unless `have` (which Hessian the KKT matrix holds at `x`) says it is there; the times
    /// go to `rep`.
    fn assemble_hessian(
        &mut self,
        m: &Model,
        x: &[f64],
        project: bool,
        have: &mut Option<bool>,
        rep: &mut SolveReport,
    ) -> Result<(), SolverError> {
        if *have == Some(project) {
            return Ok(());
        }
        let t = Instant::now();
        let sym_s = self.assemble_at(m, x, project)?;
        *have = Some(project);
        rep.symbolic_s += sym_s;
        rep.factor_s += sym_s;
        rep.assembly_s += t.elapsed().as_secs_f64() - sym_s;
        Ok(())
    }

    /// Whether the current factor may precondition a direction of the model: lagging is on,
    /// the factor exists, was of the exact unshifted Hessian with the right inertia for the
    /// same free dofs, constraint matrix and γ, and the last lagged direction used at most
    /// half of the allowed solves.
    fn lag_usable(&self, m: &Model) -> bool {
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
    /// [`StaticSettings::lagged_solves`] solves and the direction has positive curvature
    /// dᵀK d on the free dofs; else `rhs` is left alone.
    fn lagged_direction(
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
    /// ([`super::patch`]; the caller has found the lagged factor usable): `rhs` becomes the
    /// direction and true is returned when GMRES converged within the patches'
    /// `max_solves` and the direction has positive curvature on the free dofs; false (and
    /// `rhs` left alone) when the changed patches hold too much of the skin or GMRES did not
    /// get there, so a fresh global factor is made.
    fn patched_direction(
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
    fn solve_fresh(&mut self, rhs: &mut [f64], lin_tol: f64, rep: &mut SolveReport) {
        let t = Instant::now();
        rep.linear_solves += self.kkt.solve(rhs, self.settings.refinement_steps, lin_tol);
        rep.solve_s += t.elapsed().as_secs_f64();
    }

    fn gamma_for(&mut self, s: &Setup) -> f64 {
        if let Some(g) = self.settings.gamma {
            self.gamma = Some(g);
        }
        match self.gamma {
            Some(g) => g,
            None => {
                let g = self.mean_diag(s);
                self.gamma = Some(g);
                g
            }
        }
    }

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

    /// Hessians Newton tries for a direction, in order, as (element-projected, shift / γ):
    /// the exact Hessian, unless the lagged direction just showed it indefinite (a converged
    /// exact Newton direction with non-positive curvature: the factorisation at τ = 0 would
    /// only confirm it) or the last exact factorisation found two or more negative
    /// directions and the direction after it has not yet skipped the exact Hessian (a
    /// buckling frame loses about one negative direction per Newton iteration: 6, 5, 5, 4,
    /// 4, 3, 0 on the capture head's frames 56–68, so the next exact factorisation would
    /// most likely only confirm it; skipping one direction in two keeps the cost of a wrong
    /// guess, a shifted step where an exact one would do, to one step); if it is not
    /// positive definite on the constraint null space, the
    /// exact Hessian shifted by τ I, up to γ, by the inertia correction of IPOPT (Wächter
    /// and Biegler 2006, §3.1): τ starts at a third of the last shift that worked and grows
    /// ×8, or, when no shift has been needed yet, starts at 1e-4 γ and grows ×100 (it keeps
    /// the negative-curvature information so Newton escapes saddles quickly); as a last
    /// resort (in [`HessianMode::Auto`]) the element-projected Hessian. The demo's first
    /// buckling frames needed shifts of 2.5e-4 to 1e-2 γ; the ×10 ladder from 1e-10 γ used
    /// before took up to 10 factorisations to get there.
    fn hessian_attempts(&self) -> Vec<(bool, f64)> {
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

    /// Evaluate the Hessian's triplets at `x` for γ when neither the settings nor an
    /// earlier solve gave γ (its mean diagonal, [`Self::gamma_for`]).
    fn hessian_for_gamma(&mut self, e: &dyn Energy, x: &[f64], rep: &mut SolveReport) {
        if self.gamma.is_some() || self.settings.gamma.is_some() {
            return;
        }
        let t = Instant::now();
        self.evaluate_layout(e, x, false);
        rep.assembly_s += t.elapsed().as_secs_f64();
    }

    /// The first Newton iterate: the warm start (x, μ), or the pinned-motion prediction when
    /// it has the smaller residual. `have_hessian` is cleared when the predictor evaluated
    /// a Hessian elsewhere.
    fn start_point(
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
    /// their values) by the Newton core ([`super::newton`]) on the KKT system. Returns the
    /// report; check its status.
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

/// The search line of the last Newton direction.
#[derive(Default)]
struct SearchLine {
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
struct StaticNewton<'a, 'm> {
    solver: &'a mut StaticSolver,
    model: Model<'m>,
    at: Point,
    /// ‖r‖ before the last accepted step (N), for the inexact-Newton forcing term.
    rn_prev: Option<f64>,
    /// Which Hessian the solver holds at `at.x` (`Some(projected)`), if any.
    have_hessian: Option<bool>,
    rep: &'a mut SolveReport,
    line: SearchLine,
}

impl StaticNewton<'_, '_> {
    /// The direction by GMRES with the lagged factor of the exact Hessian, when that factor
    /// may be used: returns whether `step` now holds it.
    fn try_lagged(&mut self, lin_tol: f64, step: &mut [f64]) -> Result<bool, SolverError> {
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

    /// Factorise the KKT matrix with the first Hessian of
    /// [`StaticSolver::hessian_attempts`] that has the right inertia (or the last one, when
    /// none does but it factorised). Returns whether a factor was made.
    fn factor_with_inertia_control(&mut self) -> Result<bool, SolverError> {
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
    use super::*;

    /// The set-up is reused while the dofs, pinned dofs and constraint entries are the last
    /// solve's (a frame's new right-hand side keeps it), built anew when any changes, and
    /// the start is checked either way.
    #[test]
    fn the_set_up_is_reused_while_the_problem_keeps_its_entries() {
        let mut solver = StaticSolver::default();
        let mut p = quartic_problem();
        let x = vec![0.5, 1.0, 1.0, 0.0, 0.0, 0.0];
        let first = solver.setup(&QUARTIC, &p, &x).unwrap();
        p.constraints.rhs[0] = 3.0;
        assert!(Arc::ptr_eq(
            &first,
            &solver.setup(&QUARTIC, &p, &x).unwrap()
        ));
        p.constraints.entries[1].2 = 2.0;
        let scaled = solver.setup(&QUARTIC, &p, &x).unwrap();
        assert!(!Arc::ptr_eq(&first, &scaled));
        assert_eq!(scaled.cfree[1].2, 2.0);
        p.pinned = vec![0, 5];
        let pinned = solver.setup(&QUARTIC, &p, &x).unwrap();
        assert_eq!(pinned.free, vec![1, 2, 3, 4]);
        let nan = vec![f64::NAN; 6];
        assert!(solver.setup(&QUARTIC, &p, &nan).is_err());
    }

    /// The forcing term: 1e-3 on a first step, Eisenstat–Walker's 0.9 (rn/rn_prev)² below
    /// that, loosened to land 10× below the target near it (up to 0.1), never under the floor.
    #[test]
    fn the_forcing_term_asks_no_more_than_the_target_needs() {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b;
        assert!(close(forcing(1e-10, 3.6e-4, 5.0, None), 1e-3));
        assert!(close(forcing(1e-10, 1e-9, 1e-3, Some(1.0)), 9e-7));
        // One step from the target: 10× below it needs 1.8e-2.
        assert!(close(forcing(1e-10, 3.6e-4, 2e-3, Some(5.0)), 1.8e-2));
        assert!(close(forcing(1e-10, 3.6e-4, 3e-4, Some(5.0)), 0.1));
        assert!(close(forcing(1e-2, 1e-9, 1.0, None), 1e-2));
    }

    /// E = k Σ (x_i² − w)² / 4 over 6 dofs: a quartic for w = 0; for w > 0 every dof is a
    /// double well, its curvature k (3 x_i² − w) negative for |x_i| < √(w/3).
    struct Wells {
        k: f64,
        w: f64,
    }
    /// E = Σ x_i⁴ / 4.
    const QUARTIC: Wells = Wells { k: 1.0, w: 0.0 };
    impl Energy for Wells {
        fn dofs(&self) -> usize {
            6
        }
        fn eval(
            &self,
            x: &[f64],
            grad: Option<&mut [f64]>,
            hess: Option<&mut Vec<(usize, usize, f64)>>,
            _p: bool,
        ) -> f64 {
            let (k, w) = (self.k, self.w);
            if let Some(g) = grad {
                for (gi, xi) in g.iter_mut().zip(x) {
                    *gi += k * xi * (xi * xi - w);
                }
            }
            if let Some(h) = hess {
                for (i, xi) in x.iter().enumerate() {
                    h.push((i, i, k * (3.0 * xi * xi - w)));
                }
            }
            k * x.iter().map(|v| (v * v - w).powi(2) / 4.0).sum::<f64>()
        }
    }

    /// Springs in series between dofs i and i + 1 of a chain of 5 dofs, with energy
    /// E_i(Δ) = k_i (Δ²/2 + quartic · Δ⁴/4) (hardening when quartic > 0).
    struct SpringChain {
        k: [f64; 4],
        quartic: f64,
        /// Say the triplet count (16), so the solver scatters its Hessians.
        scatters: bool,
    }
    /// Unit linear springs: E = Σ (x_{i+1} − x_i)² / 2.
    const LINEAR_CHAIN: SpringChain = SpringChain {
        k: [1.0; 4],
        quartic: 0.0,
        scatters: false,
    };
    impl Energy for SpringChain {
        fn dofs(&self) -> usize {
            5
        }
        fn triplet_count(&self) -> Option<usize> {
            self.scatters.then_some(16)
        }
        fn eval(
            &self,
            x: &[f64],
            grad: Option<&mut [f64]>,
            hess: Option<&mut Vec<(usize, usize, f64)>>,
            _p: bool,
        ) -> f64 {
            let (k, c) = (self.k, self.quartic);
            let d: Vec<f64> = (0..4).map(|i| x[i + 1] - x[i]).collect();
            if let Some(g) = grad {
                for i in 0..4 {
                    let f = k[i] * (d[i] + c * d[i].powi(3));
                    g[i] -= f;
                    g[i + 1] += f;
                }
            }
            if let Some(h) = hess {
                for i in 0..4 {
                    let s = k[i] * (1.0 + 3.0 * c * d[i] * d[i]);
                    h.extend([(i, i, s), (i + 1, i + 1, s), (i, i + 1, -s), (i + 1, i, -s)]);
                }
            }
            (0..4)
                .map(|i| k[i] * (d[i].powi(2) / 2.0 + c * d[i].powi(4) / 4.0))
                .sum()
        }
    }

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

    /// An energy that scatters its Hessian: once the KKT matrix holds the layout the solver
    /// lets its triplets go, and a solve with other pins (a new layout) evaluates them again;
    /// every answer is the exact one, as a fresh solver's.
    #[test]
    fn a_scattering_energy_drops_its_triplets_and_lays_out_again_for_new_pins() {
        let settings = StaticSettings {
            tolerance: 1e-12,
            gamma: Some(1.0),
            ..Default::default()
        };
        let ends = StaticProblem {
            pinned: vec![0, 4],
            ..Default::default()
        };
        let middle = StaticProblem {
            pinned: vec![0, 2, 4],
            ..Default::default()
        };
        let chain = SpringChain {
            scatters: true,
            ..LINEAR_CHAIN
        };
        let mut solver = StaticSolver::new(settings).unwrap();
        let cases: [(&StaticProblem, [f64; 5], [f64; 5]); 3] = [
            (
                &ends,
                [0.0, 0.3, -0.2, 0.1, 1.0],
                [0.0, 0.25, 0.5, 0.75, 1.0],
            ),
            (
                &middle,
                [0.0, 0.3, 1.0, 0.1, 0.0],
                [0.0, 0.5, 1.0, 0.5, 0.0],
            ),
            (&ends, [0.0, 0.3, -0.2, 0.1, 2.0], [0.0, 0.5, 1.0, 1.5, 2.0]),
        ];
        for (p, start, exact) in cases {
            let mut x = start.to_vec();
            let rep = solver.solve(&chain, p, &mut x).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
            assert!(solver.trip.is_empty() && solver.trip_len == 16);
            let mut fresh_x = start.to_vec();
            let mut fresh = StaticSolver::new(settings).unwrap();
            fresh.solve(&chain, p, &mut fresh_x).unwrap();
            for ((a, b), e) in x.iter().zip(&fresh_x).zip(exact) {
                assert!(
                    (a - e).abs() < 1e-12 && (a - b).abs() < 1e-12,
                    "{x:?} {fresh_x:?}"
                );
            }
        }
        assert_eq!(solver.symbolic_analyses(), 3);
    }

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
        let stretch = |f: f64, ki: f64| {
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
        };
        let (mut lo, mut hi) = (0.0, 1e6);
        for _ in 0..200 {
            let f = 0.5 * (lo + hi);
            if k.iter().map(|&ki| stretch(f, ki)).sum::<f64>() < 31.0 {
                lo = f;
            } else {
                hi = f;
            }
        }
        let f = 0.5 * (lo + hi);
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

    /// The [`QUARTIC`]'s test problem: x0 pinned, x1 + x2 = 2, forces 8 on x3 and −1 on x4.
    fn quartic_problem() -> StaticProblem {
        StaticProblem {
            pinned: vec![0],
            constraints: LinearConstraints {
                rows: 1,
                entries: vec![(0, 1, 1.0), (0, 2, 1.0)],
                rhs: vec![2.0],
            },
            forces: vec![0.0, 0.0, 0.0, 8.0, -1.0, 0.0],
        }
    }

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
