//! Backward Euler and quasi-static solves of the lattice interior.
//!
//! One time step (h = 0.02 s by default) minimises the incremental potential over the free
//! node positions y (pinned nodes stay where they are):
//!
//!   Φ(y) = 1/(2h²) dᵀ M d + E(y) − (f_ext + f_g)ᵀ y + E_x(y),   d = y − q − h v,
//!
//! whose stationarity is backward Euler: M (v⁺ − v)/h = f(q⁺) + f_ext + f_g, q⁺ = q + h v⁺.
//! E_x is the optional extra term of the skin coupling, a quadratic model about the positions
//! at the start of the step, E_x(y) = −F_xᵀ (y − q) + ½ (y − q)ᵀ K_x (y − q) (K_x symmetric,
//! e.g. Bᵀ K_shell B, and F_x e.g. Bᵀ F_shell); its first Newton iteration from y = q + h v is
//! exactly the paper's [M + h²(K_q + K_x)] Δv = h (F_q + F_x − h K_x v).
//!
//! Each Newton iteration solves [M + h² (K + K_x)] Δy = −h² ∇Φ with a sparse Cholesky
//! factorisation (faer, symbolic analysis cached across iterations and steps), then
//! backtracks on Φ (Armijo, c = 1e-4). K is the corotational stiffness of
//! [`crate::fem::Interior`]. The matrix is assembled straight into a compressed
//! lower-triangle pattern built once (node blocks of 3 × 3), in parallel over node columns,
//! through a precomputed map from (element, node pair) to block position; each block is
//! R_e K₀_ab R_eᵀ with K₀ precomputed. Conjugate gradients (block-Jacobi preconditioned,
//! [`super::cg::pcg`]) skip the assembly when there is no K_x: they multiply element by
//! element ([`crate::fem::matfree::ElementOperator`]: rotate, one shared K₀ + M₀ product per
//! chunk of elements, rotate back), which costs about what a product with the assembled
//! matrix costs and saves its assembly. With K_x they multiply the assembled matrix,
//! mirrored into full node-block rows. CG starts each time step from the
//! previous step's first Newton direction, scaled to minimise the quadratic along it. The
//! element rotations of the gradient evaluation at the Newton point are reused for its
//! matrix.
//!
//! The parts: `settings` (time step, Newton and linear-solver settings), `extra` (the skin
//! coupling's K_x, F_x), `system` (the compressed node-block pattern and its assembly),
//! `stiffness` (that assembly for other Newton loops), `stepper` (the [`BackwardEuler`]
//! state and its public steps), `potential` (Φ and ∇Φ), `newton_system` (one Newton
//! system's matrix and linear solve) and `newton` (one minimisation of Φ as a Newton
//! problem).

mod extra;
mod newton;
mod newton_system;
mod potential;
mod settings;
mod stepper;
mod stiffness;
mod system;

pub use crate::solver::SolveStatus;
pub use extra::{triplet_layout_key, ExtraTerms};
pub use settings::{LinearSolver, StepSettings, Tangent, AUTO_CG_DOFS, AUTO_CG_REL_TOL};
pub use stepper::{BackwardEuler, SolveReport};
pub use stiffness::StiffnessMatrix;

use nalgebra::Matrix3;

/// A 3 × 3 block: an element rotation or a node block of a matrix.
type M3 = Matrix3<f64>;

/// Node positions (flat, m) of `lat` twisted about z (2 rad/m), stretched along x by 20 %
/// and squashed along z by 10 %: a state with rotations and stress in every element.
#[cfg(test)]
fn twisted(lat: &crate::lattice::Lattice) -> Vec<f64> {
    lat.rest
        .iter()
        .flat_map(|p| {
            let t = 2.0 * p.z;
            let (c, s) = (t.cos(), t.sin());
            [1.2 * (c * p.x - s * p.y), c * p.y + s * p.x, 0.9 * p.z]
        })
        .collect()
}
