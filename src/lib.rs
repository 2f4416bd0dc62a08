//! furrow: physically wrinkled skin for blend-shape face animation.
//!
//! The method is "Embedded Thin Shells for Wrinkle Simulation" (Rémillard and Kry, SIGGRAPH
//! 2013): a coarse quadratic B-spline hexahedral lattice simulates the soft interior, and a
//! high-resolution thin shell (the skin) is tied to it only at low spatial frequency so that
//! wrinkles form at the critical wavelength.
//!
//! Layers, bottom to top ([`LAYERS`]; each module uses only layers below it, and
//! `tests/module_layers.rs` checks every `crate::` path in `src/` against this list):
//!
//! | layer | modules | what it is |
//! | ---: | --- | --- |
//! | 0 | [`math`] | sparse assembly, dense helpers, finite-difference checkers, the `Energy` trait |
//! | 1 | [`mesh`] | triangle meshes, topology, quality, local smooth refinement (red-green, butterfly) |
//! | 2 | [`solver`] | Newton and line search, KKT, sparse factorisations, statics status |
//! | 3 | [`io`] | glTF in and out: meshes, morph targets, animations; nothing physical |
//! | 4 | [`rig`] | the project's own face rig generator (for `rigs/`, tests and benchmarks) |
//! | 5 | [`lattice`] | hex lattice, B-spline basis, node duplication, embedding B |
//! | 6 | [`fem`], [`shell`] | interior energy and backward Euler; skin energy |
//! | 7 | [`coupling`] | embedded shell, cluster constraints, refinement, bilayer wavelength |
//! | 8 | [`muscle`] | muscle model, activation QP |
//! | 9 | [`scene`] | what a run needs, its settings, validation |
//! | 10 | [`validate`] | physics checks and measurements (slab, dense reference, wavelength) |
//! | 11 | [`render`] | plots, rasterised previews, colour maps: pictures, nothing physical |
//! | 12 | [`pipeline`] | set-up stages, then per frame blend → drive → interior → skin → compose |
//! | 13 | [`studies`] | tradeoff, stability and benchmark reports: they run the pipeline |
//! | 14 | [`cli`] | the command line (a thin `main` calls it) |
//!
//! `rig` sits low because it only generates meshes and morph targets (the solver benchmarks in
//! `fem::bench`, `shell::bench` and `muscle::bench` build their inputs with it); `validate`
//! sits below the pipeline because it never runs it (synthetic scenes measure their wrinkles
//! with `validate::measure` and build their block lattice with `validate::slab`).

pub mod cli;
pub mod coupling;
pub mod fem;
pub mod io;
pub mod lattice;
pub mod math;
pub mod mesh;
pub mod muscle;
pub mod pipeline;
pub mod render;
pub mod rig;
pub mod scene;
pub mod shell;
pub mod solver;
pub mod studies;
pub mod validate;

/// The layers of the crate, bottom to top: a module may use modules of lower layers only
/// (modules of one layer do not use each other).
pub const LAYERS: &[&[&str]] = &[
    &["math"],
    &["mesh"],
    &["solver"],
    &["io"],
    &["rig"],
    &["lattice"],
    &["fem", "shell"],
    &["coupling"],
    &["muscle"],
    &["scene"],
    &["validate"],
    &["render"],
    &["pipeline"],
    &["studies"],
    &["cli"],
];
