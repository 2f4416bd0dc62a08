//! Validation that the physics is right: the compressed-slab scene of the paper and the
//! wrinkle wavelength it produces against the film-on-substrate formula.

pub mod slab;
pub mod wavelength;
