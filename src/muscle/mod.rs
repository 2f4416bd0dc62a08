//! Lattice muscles and the activation QP: the face's interior is moved by muscles, and the
//! muscle activations of each frame are fitted to the blend-shape animation.
//!
//! * [`model`]: a muscle is a named set of lattice elements with activation bounds (default
//!   [0, 1]) that acts in one of two ways. An *actuation* muscle changes the interior's rest
//!   state (Phace-style: offsets of each element's rest nodes, those of the summed lattice
//!   rest change X + Σ a_m s_m ([`blend`]); a compatible
//!   actuation makes its shape whatever the stiffness). A *fibre* muscle (from a muscle file)
//!   adds the active energy a σ Σ w [(‖F f‖ − 1) − (det F − 1)/3], σ = 3 μ c (Pa): a fibre
//!   tension made deviatoric so the tissue shortens along the fibre with its volume kept.
//! * [`forward`]: quasi-static equilibrium of interior + muscles (bone pinned), with the
//!   pipeline's tracking when given ([`Coupling`]), and its linear response to activations.
//! * [`actuation`]: a shape's actuation fitted with that interior in the loop.
//! * [`blend`]: how actuation muscles combine at partial and mixed activations.
//! * [`rigfile`]: muscles from a TOML rig file.
//! * [`generate`]: muscles from the blend-shape basis when there is no file.
//! * [`samples`]: where each shape's lattice fit is held: the face's vertices and its
//!   subdivided surface between them.
//! * [`qp`]: the per-frame convex QP (clarabel) with exact active-set polishing.
//! * [`fit`]: the per-frame fit with Gauss–Newton re-linearisations.
//! * [`jaw`]: the jaw's hinge, fitted from the shape that opens it, and the bone nodes that
//!   turn about it with the jaw shape's muscle ([`jaw::JawBone`]).
//!
//! # Muscles generated from blend shapes
//!
//! When a rig has no muscle file, furrow makes one actuation muscle per blend shape:
//!
//! 1. Fit the lattice to each blend shape: node displacements u minimise
//!    ‖B u − Δ‖² + α uᵀ K u over the free (non-bone) nodes (the jaw's bone nodes turned by
//!    the jaw shape's full angle for that shape, the other bone at rest), with B the embedding
//!    of the [`samples`] in the lattice (the rig's vertices and its once-subdivided surface
//!    between them), Δ the shape's displacements there (the subdivision's rows of the
//!    vertices' displacements) and K the interior's rest stiffness; α = β · tr(BᵀB)/tr(K)
//!    (β = [`generate::GenerateSettings::regulariser`], default 10⁻³) makes the elastic term a
//!    light smoothness regulariser. Held at the vertices alone, a coarse lattice swings
//!    between them, and the refined skin there creases where the shape is still (the capture
//!    head's brow under its blink). One sparse Cholesky factorisation serves all shapes (one
//!    solve per shape). ‖B u − Δ‖ over the vertices is the lattice's own projection residual:
//!    no muscle on this lattice can do better there.
//! 2. Fit the actuation that makes u the equilibrium of the interior the pipeline runs with
//!    its tracking ([`actuation`]) and, with `muscles.skin_hold = "shapes"`, the skin's force at the
//!    shape: the rest change is u plus K_int⁻¹ (K_t u − Bᵀ k Δ − f_skin), what the tracking's
//!    pull leaves to the muscle (on the jaw's bone nodes the bone's own turn), and
//!    nonlinear corrections remove the corotational interior's departure from the
//!    linearisation.
//! 3. The muscle covers every element whose offset reaches 10⁻⁴ of the shape's largest.
//!    Shapes whose lattice displacement stays below [`generate::GenerateSettings::min_strain`]
//!    cells (for example an all-zero shape) make no muscle and are listed as skipped.
//! 4. Muscles keep the blend shape's name, so symmetric pairs (`_L`/`_R`, `Left`/`Right`,
//!    `left`/`right`) stay separate muscles; repeated names get a `#2`, `#3` suffix.
//!
//! Muscles from a rig file (see [`rigfile`]) take the place of generated ones.

pub mod actuation;
pub mod bench;
pub mod blend;
pub mod definition;
pub mod fit;
pub mod forward;
pub mod generate;
pub mod jaw;
pub mod model;
pub mod qp;
pub mod rigfile;
pub mod samples;

pub use fit::{FitSettings, Fitter, FrameFit, FrameStatus};
pub use forward::{Coupling, Forward, ForwardReport};
pub use generate::{generate_muscles, GenerateSettings, Generated};
pub use model::{
    full_forces, linearised_terms, unit_forces, ActiveEnergy, Muscle, DEFAULT_MAX_CONTRACTION,
};
pub use qp::{solve_qp, QpProblem, QpSolution};

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
