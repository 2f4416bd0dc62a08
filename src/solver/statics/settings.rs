//! Settings of the quasi-static solve: tolerances and limits, the Hessian choice, and the
//! linear algebra of the Newton directions (lagged factors, patches, factor precision).

use super::SolverError;
use crate::solver::kkt::FactorPrecision;
use crate::solver::patch::PatchSettings;

/// Which Hessian Newton uses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum HessianMode {
    /// The exact Hessian always (quadratic convergence; may head for saddles).
    Exact,
    /// Element Hessians projected to PSD always (robust, linear convergence near the end).
    Projected,
    /// Exact when it is positive definite on the constraint null space (checked by the
    /// inertia of the KKT factorisation), else exact shifted by τ I, else projected.
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
    /// the constraint block (see [`crate::solver::kkt`]).
    pub refinement_steps: usize,
    /// Tightest relative residual ‖r‖/‖b‖ a GMRES solve of a KKT system is asked for.
    /// Newton asks for less while it is far from the answer (inexact Newton: the forcing
    /// term of Eisenstat and Walker, at most 1e-3, and never tighter than needed to land 10×
    /// under `tolerance`); this is the floor, and the looser solves above it land on the
    /// same equilibrium as solving every direction to it.
    pub linear_tolerance: f64,
    /// Most factor solves (GMRES iterations) a Newton direction may spend with a *lagged*
    /// factorisation, one of an earlier iterate or of the previous solve, before a fresh
    /// one is made; 0 factorises every direction. A lagged direction is the exact Newton
    /// direction to `linear_tolerance`, so the lag changes the cost, not the path. It is
    /// used only while the last factor was of the exact, unshifted Hessian with the right
    /// inertia, and only when the direction has positive curvature; else the direction is
    /// factorised afresh with the inertia test. The cap is small because a failed attempt
    /// costs its solves on top of the factorisation that follows it.
    pub lagged_solves: usize,
    /// Maximum trial steps per line search.
    pub max_line_search: usize,
    /// Also accept steps that satisfy Armijo on the energy merit (the Lagrangian with the
    /// new multipliers), not only on the residual norm. The residual rule alone is `false`;
    /// thin shells moving out of plane need `true` (see
    /// [`crate::solver::linesearch`]).
    pub energy_merit: bool,
    /// Solve Newton directions with the lagged global factor and fresh factors of only the
    /// patches whose Hessian changed ([`crate::solver::patch`]); `None`: the global reference
    /// (a fresh global factor whenever the lagged one does not do within `lagged_solves`).
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
    /// while they precondition a direction within 10 solves: a cap of 10 needs about half
    /// the factorisations of a cap of 5 on the demo's frames, and a larger one saves no time.
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
