//! Coupling of the skin to the interior: the critical wrinkle wavelength that sets the
//! frequency limit of the constraints.

pub mod bench;
pub mod clusters;
pub mod embedded;
pub mod refine;
pub mod wavelength;
