//! Procedural rigs made by furrow itself (`furrow rig generate`).

pub mod animation;
pub mod face;
pub mod regions;
pub mod shapes;
pub mod surface;
