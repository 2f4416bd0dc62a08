//! One solve's fixed data (energy, problem, free-dof set-up, γ) and a Newton iterate with
//! its KKT residual r = [∇E − f + γCᵀμ; γ(Cx − d)] over the free dofs and constraint rows.

use super::setup::Setup;
use super::StaticProblem;
use crate::math::vector::norm;
use crate::math::Energy;

/// The fixed data of one solve: the energy, the problem, its free-dof set-up and the row
/// scale γ (N/m) of the KKT system.
#[derive(Clone, Copy)]
pub(super) struct Model<'a> {
    /// The energy.
    pub(super) e: &'a dyn Energy,
    /// The problem.
    pub(super) p: &'a StaticProblem,
    /// Its free-dof set-up.
    pub(super) s: &'a Setup,
    /// Row scale γ of the KKT system (N/m).
    pub(super) gamma: f64,
}

/// A Newton iterate: positions x (all dofs, m), scaled multipliers μ (λ = γ μ), the residual
/// r over [free dofs; constraint rows] (N), the energy including the work of external forces
/// (J) and ‖r‖₂ (N).
pub(super) struct Point {
    /// Positions, all dofs (m).
    pub(super) x: Vec<f64>,
    /// Scaled multipliers μ, one per constraint row.
    pub(super) mu: Vec<f64>,
    /// Residual over [free dofs; constraint rows] (N).
    pub(super) r: Vec<f64>,
    /// Energy including the work of external forces (J).
    pub(super) energy: f64,
    /// ‖r‖₂ (N).
    pub(super) rn: f64,
    /// ∇E at x over all dofs (N): the energy's own gradient, before external forces and
    /// constraint terms.
    pub(super) grad: Vec<f64>,
}

impl Model<'_> {
    /// Free dofs.
    pub(super) fn free(&self) -> usize {
        self.s.free.len()
    }

    /// Constraint rows.
    pub(super) fn rows(&self) -> usize {
        self.p.constraints.rows
    }

    /// Residual vector over [free dofs; constraint rows] (N) and the energy (J), at (x, μ).
    pub(super) fn residual(&self, x: &[f64], mu: &[f64]) -> (Vec<f64>, f64, Vec<f64>) {
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
    pub(super) fn point(&self, x: Vec<f64>, mu: Vec<f64>) -> Point {
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
