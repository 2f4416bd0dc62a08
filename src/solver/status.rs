//! Outcome of a nonlinear solve: a status and the measurements a report needs.

/// How a solve ended: the one outcome type of every solver in furrow (the skin's statics,
/// the interior's backward Euler, the muscles' equilibrium and the activation QP). Only
/// `Converged` means the returned state is a solution within tolerance; the others must be
/// reported, never silently used. Serialised in snake_case (`"converged"`, …).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SolveStatus {
    /// Residual below tolerance (for a QP: clarabel's `Solved` or `AlmostSolved`).
    #[default]
    Converged,
    /// The line search found no step that reduces the residual norm enough (Armijo).
    LineSearchFailed,
    /// The iteration limit was reached before convergence (for a QP: clarabel's
    /// `MaxIterations` or `MaxTime`).
    IterationLimit,
    /// A NaN or infinity appeared in the energy, residual, step or answer.
    NotFinite,
    /// The line search could not lower the potential; the last good state is kept (the
    /// interior's and the muscles' equilibrium solves, and clarabel's `InsufficientProgress`).
    Stalled,
    /// The skin's solve ended with the skin through itself.
    SelfIntersecting,
    /// A QP has no feasible point, or its dual none (clarabel's infeasibility statuses).
    Infeasible,
    /// A QP's solver failed for another reason (set-up error, numerical error).
    Failed,
}

impl SolveStatus {
    /// The snake_case name written to reports and JSON.
    pub fn as_str(&self) -> &'static str {
        match self {
            SolveStatus::Converged => "converged",
            SolveStatus::LineSearchFailed => "line_search_failed",
            SolveStatus::IterationLimit => "iteration_limit",
            SolveStatus::NotFinite => "not_finite",
            SolveStatus::Stalled => "stalled",
            SolveStatus::SelfIntersecting => "self_intersecting",
            SolveStatus::Infeasible => "infeasible",
            SolveStatus::Failed => "failed",
        }
    }

    /// Whether the solve met its tolerance.
    pub fn is_converged(&self) -> bool {
        *self == SolveStatus::Converged
    }
}

impl std::fmt::Display for SolveStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.as_str())
    }
}

/// Report of one quasi-static solve.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SolveReport {
    /// How the solve ended.
    pub status: SolveStatus,
    /// Newton iterations taken (factorisations used for a step).
    pub iterations: usize,
    /// Final residual norm ‖[∇E − f + γCᵀμ ; γ(Cx − d)]‖₂ over free dofs (N).
    pub residual: f64,
    /// Residual norm at the start (N).
    pub initial_residual: f64,
    /// Largest constraint violation |Cx − d| at the end (units of the constraint, m).
    pub constraint_violation: f64,
    /// Energy at the end, including the work of external forces (J).
    pub energy: f64,
    /// Iterations whose step used a projected or shifted Hessian because the exact one was
    /// not positive definite on the constraint null space.
    pub modified_hessian_steps: usize,
    /// Numeric factorisations done (more than `iterations` when inertia correction retried).
    pub factorizations: usize,
    /// Newton directions (and pinned-motion predictor steps) solved by GMRES with a lagged
    /// factorisation, of an earlier iterate or of the previous solve, instead of a new one
    /// (see `StaticSettings::lagged_solves`).
    #[serde(default)]
    pub lagged_directions: usize,
    /// Solves with a factor (one per GMRES iteration).
    pub linear_solves: usize,
    /// Seconds evaluating Hessians and assembling the KKT matrix.
    pub assembly_s: f64,
    /// Seconds in the symbolic analysis (first call, or when the pattern changes).
    pub symbolic_s: f64,
    /// Seconds in numeric factorisations (including the symbolic analysis).
    pub factor_s: f64,
    /// Seconds in GMRES (triangular solves with a factor and matrix products).
    pub solve_s: f64,
    /// Seconds in energy/gradient evaluations of the line search and residuals.
    pub line_search_s: f64,
    /// Wall-clock seconds of the whole solve.
    pub total_s: f64,
    /// Equal load increments of the solve that ended it: 1 when solved directly, 2ᵏ when
    /// [`StaticSolver::solve_in_increments`](super::StaticSolver::solve_in_increments) had to
    /// split the change of constraint target and pinned positions (0 before any solve).
    #[serde(default)]
    pub increments: usize,
    /// Newton directions (and predictor steps) solved with the lagged global factor and
    /// fresh factors of the changed patches ([`super::patch`]).
    #[serde(default)]
    pub patch_directions: usize,
    /// Patch factorisations made (each of one patch's block, not of the whole system).
    #[serde(default)]
    pub patch_factorizations: usize,
    /// Patches corrected, summed over the patched directions.
    #[serde(default)]
    pub patches_active: usize,
    /// Patch factorisations that needed a shift to pass their inertia test.
    #[serde(default)]
    pub patch_shifts: usize,
}

impl SolveReport {
    /// Add the work of `other` (iterations, factorisations, solves, seconds) to this report;
    /// the outcome fields (status, residuals, energy) are left alone.
    pub fn add_work(&mut self, other: &SolveReport) {
        self.iterations += other.iterations;
        self.modified_hessian_steps += other.modified_hessian_steps;
        self.factorizations += other.factorizations;
        self.lagged_directions += other.lagged_directions;
        self.patch_directions += other.patch_directions;
        self.patch_factorizations += other.patch_factorizations;
        self.patches_active += other.patches_active;
        self.patch_shifts += other.patch_shifts;
        self.linear_solves += other.linear_solves;
        self.assembly_s += other.assembly_s;
        self.symbolic_s += other.symbolic_s;
        self.factor_s += other.factor_s;
        self.solve_s += other.solve_s;
        self.line_search_s += other.line_search_s;
        self.total_s += other.total_s;
    }
}
