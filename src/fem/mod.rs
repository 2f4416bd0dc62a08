//! Interior elasticity on the lattice: corotational FEM, mass, backward Euler.

pub mod bench;
