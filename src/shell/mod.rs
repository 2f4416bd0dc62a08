//! The skin: discrete thin shell energies (membrane and hinge bending).

pub mod bench;
pub mod bending;
pub mod material;
pub mod membrane;
pub mod model;
pub mod psd;
pub mod scatter;
pub mod sheet;
pub mod tension_field;

pub use material::ShellMaterial;
pub use model::Shell;
