//! Nonlinear solvers: Newton with line search, sparse KKT systems, quasi-static equilibrium.

pub mod gmres;
pub mod kkt;
pub mod linesearch;
pub mod newton;
pub mod ordering;
pub mod patch;
pub mod statics;
pub mod status;
pub mod tree;
pub mod tree_factor;

pub use statics::{
    HessianMode, LinearAlgebra, LinearConstraints, StaticProblem, StaticSettings, StaticSolver,
};
pub use status::{SolveReport, SolveStatus};
