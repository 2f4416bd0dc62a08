//! Validation of the physics: wrinkle wavelength measurement and a dense reference simulation.

pub mod dense;
pub mod measure;
