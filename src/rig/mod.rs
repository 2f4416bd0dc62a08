//! Procedural rigs made by furrow itself (`furrow rig generate`).

pub mod animation;
pub mod avatar;
pub mod avatar_head;
pub mod avatar_meshes;
pub mod avatar_shapes;
pub mod face;
pub mod head;
pub mod head_animation;
pub mod head_shapes;
pub mod regions;
pub mod shapes;
pub mod surface;
