//! Coupling of the skin to the interior: the embedding of the skin in the lattice, the
//! embedded thin shell and its constraint clusters, the cluster width for a wavelength, the
//! two-step solve, and the critical wrinkle wavelength that sets the frequency limit of the
//! constraints.

pub mod bench;
pub mod cluster_width;
pub mod clusters;
pub mod embedded;
pub mod embedding;
pub mod refine;
pub mod two_step;
pub mod wavelength;
