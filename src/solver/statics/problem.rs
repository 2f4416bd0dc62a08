//! A quasi-static problem: the pinned dofs, the linear equality constraints C x = d and
//! the external forces, and the check of their sizes against an energy and a start state.

use super::SolverError;

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

/// Check the sizes of `p`'s forces and constraint right-hand side and the start `x` for
/// `n` dofs (its length, all finite).
pub(super) fn check_start(n: usize, p: &StaticProblem, x: &[f64]) -> Result<(), SolverError> {
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
