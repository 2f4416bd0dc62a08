//! glTF in and out: meshes, morph targets and weight animations. Nothing physical.

pub mod accessor;
pub mod animation;
pub mod atomic;
pub mod carry;
pub mod compact;
pub mod container;
pub mod error;
pub mod export;
pub mod face_weights;
pub mod glb_write;
pub mod inspect;
pub mod layer;
pub mod load;
pub mod mesh;
pub mod meshopt_view;
pub mod model;
pub mod motion;
pub mod origin;
pub mod parts;
pub mod scene;
pub mod split;
pub mod units;
pub mod uri;

pub use error::{GltfError, GltfResult};
pub use load::{load, LoadOptions, Rig};
