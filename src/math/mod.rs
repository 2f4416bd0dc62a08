//! Numerical building blocks shared by every physical layer: sparse assembly and factorisation,
//! finite-difference checkers, and the [`Energy`] interface that solvers work on.

pub mod energy;
pub mod fd;
pub mod hash;
pub mod modes;
pub mod rng;
pub mod sparse;
pub mod vector;

pub use energy::Energy;
