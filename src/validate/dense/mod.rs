//! A dense reference simulation of wrinkling: a plane-strain strip of stiff skin bonded on a
//! deep soft substrate, compressed along its length beyond the critical strain.
//!
//! Model and choices:
//! - Geometry: strip of length L = `periods` × λ_pred (λ_pred from
//!   [`crate::coupling::wavelength::Bilayer::critical_wavelength`]), skin of thickness h on a
//!   substrate of depth `depth` × λ_pred. Units are SI; energies are per metre of depth
//!   (plane strain), so "forces" are N/m.
//! - Elements: 9-node quadratic Lagrange quadrilaterals (Q2), 3×3 Gauss quadrature. A Q2 element
//!   reproduces pure bending exactly (quadratic displacement field), so thin skin elements do not
//!   shear-lock the way bilinear ones do; a cantilever test of the energy (`svk`) checks the
//!   bending stiffness against beam theory with elements of aspect ratio 10. The skin has
//!   `skin_layers` (≥ 2) element layers of its own material; substrate layers grow
//!   geometrically (factor 1.3) from the skin down to the bottom.
//! - Material: St. Venant–Kirchhoff in plane strain, W = λ_L/2 (tr E)² + μ E:E with the 2×2
//!   Green strain E = ½(FᵀF − I) (E_zz = 0) and the 3D Lamé constants of (E, ν). Geometrically
//!   nonlinear (rotations of the wrinkled skin are exact); strains stay at a few percent here.
//! - Boundary conditions: sliding sides (u_x = 0 on the left side, u_x = −εL on the right side,
//!   u_y free) and a sliding bottom (u_y = 0, u_x free) so the pre-buckling state is a uniform
//!   plane-strain compression, as in the classical analysis. With sliding sides the strip
//!   admits wavelengths 2L/m (m an integer), so the measurement resolution is about λ/(4 ×
//!   periods); `periods` defaults to a non-integer (10.3) so that the selected mode is never
//!   exactly λ_pred by construction.
//! - Imperfection: the reference geometry is shifted vertically by η(X) = a Σ_m s_m
//!   cos(mπX/L), every mode the sliding sides admit down to λ/4 with the same amplitude and a
//!   pseudo-random sign s_m (RMS ≈ `imperfection` × h / √2 at the top, tapering linearly to
//!   zero at the bottom). It does not depend on the mesh, so every resolution sees the same
//!   imperfection; it breaks the symmetry of the flat state, so the strip wrinkles in a mode
//!   that goes unstable first instead of staying on the flat branch. Near ε_c the critical
//!   strain of neighbouring modes differs by a fraction of a percent, so which mode wins also
//!   depends on the imperfection: the measured λ scatters by about ±5 % with the seed at every
//!   resolution from 6 elements per λ up. That scatter is the precision of this experiment,
//!   not a discretisation error; [`ensemble`] averages seeds for a sharper number.
//! - Loading: compressive strain ε in `load_steps` steps from 0.5 ε_c to `strain_factor` × ε_c,
//!   with ε_c = ¼ (3 Ē_q / Ē_x)^{2/3} (Ē = E / (1 − ν²)); each step is solved to equilibrium
//!   by [`crate::solver::statics::StaticSolver`] (Newton, KKT, line search) from the previous one.
//! - Measurement: λ from the top surface height with [`super::measure::wavelength`], both
//!   against the reference (material) position along the strip — the quantity the small-strain
//!   formula predicts — and against the current position (shorter by about the factor 1 − ε).
//!
//! The parts: `mesh` (the structured Q2 mesh), `svk` (the plane-strain St. Venant–Kirchhoff
//! energy on it), `case` (a case and its results), `strip` (the strip of a case: layers,
//! imperfection, sliding supports), `run` (the compression and measurement of one case),
//! `readout` (amplitude, onset and profiles read off the top surface) and `studies`
//! (sweeps, seed ensembles and resolution studies over cases).

mod case;
mod mesh;
mod readout;
mod run;
mod strip;
mod studies;
mod svk;

pub use case::{DenseCase, DenseResult, StepRecord};
pub use mesh::QuadMesh;
pub use run::run;
pub use studies::{ensemble, resolution_study, sweep, Ensemble, ResolutionRow, SweepRow};
pub use svk::{lame, PlaneStrainSvk};
