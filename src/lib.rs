//! furrow: physically wrinkled skin for blend-shape face animation.
//!
//! The method is "Embedded Thin Shells for Wrinkle Simulation" (Rémillard and Kry, SIGGRAPH
//! 2013): a coarse quadratic B-spline hexahedral lattice simulates the soft interior, and a
//! high-resolution thin shell (the skin) is tied to it only at low spatial frequency so that
//! wrinkles form at the critical wavelength. Layers, bottom to top: [`math`], [`mesh`],
//! [`solver`], [`io`], [`lattice`], [`fem`], [`shell`], [`coupling`], [`muscle`], [`scene`],
//! [`validate`], [`report`], [`pipeline`], [`rig`], [`cli`].

pub mod cli;
pub mod coupling;
pub mod fem;
pub mod io;
pub mod lattice;
pub mod math;
pub mod mesh;
pub mod muscle;
pub mod pipeline;
pub mod report;
pub mod rig;
pub mod scene;
pub mod shell;
pub mod solver;
pub mod validate;
