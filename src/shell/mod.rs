//! The skin: discrete thin shell energies (membrane and hinge bending).

pub mod bench;
