//! Procedural rigs made by furrow itself (`furrow rig generate`).

pub mod face;
