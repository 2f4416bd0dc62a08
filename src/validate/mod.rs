//! Validation that the physics is right: the compressed-slab scene of the paper, the wrinkle
//! wavelength it produces against the film-on-substrate formula, wavelength measurement,
//! and a dense reference simulation.

pub mod crests;
pub mod dense;
pub mod measure;
pub mod slab;
pub mod wavelength;
