//! Lattice muscles and the activation QP: the face's interior is moved by muscles, and the
//! muscle activations of each frame are fitted to the blend-shape animation.
//!
//! * [`model`]: a muscle is a named set of lattice elements with a unit fibre direction per
//!   element, a maximum contraction c and activation bounds (default [0, 1]). Activation a
//!   adds the active energy a σ Σ w [(‖F f‖ − 1) − (det F − 1)/3], σ = 3 μ c (Pa): a fibre
//!   tension made deviatoric so the tissue shortens along the fibre with its volume kept.
//! * [`forward`]: quasi-static equilibrium of interior + muscles (bone pinned) and its linear
//!   response to activations.
//! * [`rigfile`]: muscles from a TOML rig file.
//! * [`generate`]: muscles from the blend-shape basis when there is no file.
//! * [`qp`]: the per-frame convex QP (clarabel) with exact active-set polishing.
//! * [`fit`]: the per-frame fit with Gauss–Newton re-linearisations.
//!
//! # Muscles generated from blend shapes
//!
//! When a rig has no muscle file, furrow makes one muscle per blend shape:
//!
//! 1. Fit the lattice to each blend shape: node displacements u minimise
//!    ‖B u − Δ‖² + α uᵀ K u over the free (non-bone) nodes, with B the embedding of the
//!    surface in the lattice, Δ the shape's vertex displacements and K the interior's rest
//!    stiffness; α = β · tr(BᵀB)/tr(K) (β = [`generate::GenerateSettings::regulariser`],
//!    default 10⁻³) makes the elastic term a light smoothness regulariser. One sparse
//!    Cholesky factorisation serves all shapes (one solve per shape).
//! 2. In each element, average the small-strain tensor ε = sym(∇u) over its Gauss points,
//!    take its deviatoric part ε − tr(ε) I/3 (the active stress is deviatoric, so muscles can
//!    only make the shape-changing part of a strain) and its most negative eigenvalue (the
//!    principal compression) with that eigenvector (the fibre direction).
//! 3. The shape's muscle is the set of elements whose principal compression is at least
//!    [`generate::GenerateSettings::threshold`] (default 0.25) of the largest compression of
//!    that shape, each with its own fibre. Its maximum contraction is twice the mean
//!    compression of its elements (clamped to [0.02, 0.6]), so that activations of order one
//!    reproduce the shape. Shapes with no compression above 10⁻⁵ (for example an all-zero
//!    shape) make no muscle and are listed as skipped.
//! 4. Muscles keep the blend shape's name, so symmetric pairs (`_L`/`_R`, `Left`/`Right`,
//!    `left`/`right`) stay separate muscles; repeated names get a `#2`, `#3` suffix.
//!
//! Muscles from a rig file (see [`rigfile`]) take the place of generated ones.

pub mod bench;
pub mod fit;
pub mod forward;
pub mod generate;
pub mod model;
pub mod qp;
pub mod rigfile;

pub use fit::{FitSettings, Fitter, FrameFit, FrameStatus};
pub use forward::{Forward, ForwardReport, ForwardStatus};
pub use generate::{generate_muscles, GenerateSettings, Generated};
pub use model::{linearised_terms, unit_forces, ActiveEnergy, Muscle, DEFAULT_MAX_CONTRACTION};
pub use qp::{solve_qp, QpProblem, QpSolution, QpStatus};

/// Errors of the muscle layer (bad input; numerical outcomes are statuses).
#[derive(Debug, thiserror::Error)]
pub enum MuscleError {
    /// Inconsistent or invalid input; the message says what to change.
    #[error("{0}")]
    Input(String),
    /// A settings field is out of range.
    #[error("muscle setting `{field}`: {msg}")]
    Settings {
        /// The offending field.
        field: &'static str,
        /// What is wrong and what is expected.
        msg: String,
    },
    /// The rig file could not be read or understood.
    #[error("{path}: {msg}")]
    RigFile {
        /// The file.
        path: String,
        /// What is wrong in it.
        msg: String,
    },
    /// Sparse assembly or factorisation failed.
    #[error(transparent)]
    Sparse(#[from] crate::math::sparse::SparseError),
    /// The interior could not be built.
    #[error(transparent)]
    Fem(#[from] crate::fem::FemError),
}
