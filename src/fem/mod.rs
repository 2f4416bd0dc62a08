//! Interior elasticity on the lattice: corotational FEM, mass, backward Euler.

// Numerical kernels index small fixed-size arrays by axis; iterator forms obscure them.
#![allow(clippy::needless_range_loop)]

pub mod bench;
pub mod cg;
pub mod corot;
pub mod dynamics;
pub mod frame;
pub mod interior;
pub mod matfree;
pub mod tangent;

pub use dynamics::{
    triplet_layout_key, BackwardEuler, ExtraTerms, LinearSolver, SolveReport, SolveStatus,
    StepSettings, Tangent, AUTO_CG_DOFS,
};
pub use frame::FrameAcceleration;
pub use interior::{FrozenInterior, Interior};

use serde::{Deserialize, Serialize};

/// Standard gravity (m/s²).
pub const GRAVITY: f64 = 9.81;

/// An isotropic elastic material.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Material {
    /// Young's modulus (Pa).
    pub young: f64,
    /// Poisson's ratio (dimensionless, in [0, 0.5)).
    pub poisson: f64,
    /// Mass density (kg/m³).
    pub density: f64,
}

impl Default for Material {
    /// Soft tissue: E = 10 kPa, ν = 0.45, ρ = 1000 kg/m³.
    fn default() -> Self {
        Self {
            young: 1.0e4,
            poisson: 0.45,
            density: 1000.0,
        }
    }
}

impl Material {
    /// Check the fields; the error names the one that is wrong.
    pub fn validate(&self) -> Result<(), FemError> {
        let bad = |field: &'static str, msg: String| Err(FemError::Settings { field, msg });
        if !(self.young.is_finite() && self.young > 0.0) {
            return bad(
                "young",
                format!("Young's modulus must be positive (Pa), got {}", self.young),
            );
        }
        if !(self.poisson.is_finite() && (0.0..0.5).contains(&self.poisson)) {
            return bad(
                "poisson",
                format!("Poisson's ratio must be in [0, 0.5), got {}", self.poisson),
            );
        }
        if !(self.density.is_finite() && self.density > 0.0) {
            return bad(
                "density",
                format!("density must be positive (kg/m³), got {}", self.density),
            );
        }
        Ok(())
    }

    /// Lamé parameters (μ, λ) in Pa.
    pub fn lame(&self) -> (f64, f64) {
        let (e, nu) = (self.young, self.poisson);
        (
            e / (2.0 * (1.0 + nu)),
            e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        )
    }
}

/// Errors of the interior simulation (bad input; numerical outcomes are a [`SolveStatus`]).
#[derive(Debug, thiserror::Error)]
pub enum FemError {
    /// A settings field is out of range.
    #[error("setting `{field}`: {msg}")]
    Settings {
        /// The offending field.
        field: &'static str,
        /// What is wrong and what is expected.
        msg: String,
    },
    /// Input vectors of the wrong size, or similar misuse.
    #[error("{0}")]
    Input(String),
    /// Sparse assembly or factorisation failed.
    #[error(transparent)]
    Sparse(#[from] crate::math::sparse::SparseError),
}
