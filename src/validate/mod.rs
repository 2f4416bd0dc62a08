//! Validation that the physics is right: wrinkle wavelength measurement, the compressed-slab
//! scene of the paper against the film-on-substrate formula, and a dense plane-strain reference
//! simulation of the same bilayer.

pub mod dense;
pub mod measure;
pub mod slab;
pub mod wavelength;
