//! The procedural face rig of `rigs/face.glb`.

use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;

/// A blend-shape face rig: neutral mesh (metres), named position-delta targets and a weights
/// animation.
#[derive(Debug, Clone)]
pub struct FaceRig {
    /// Neutral face surface, metres, +Y up, facing +Z.
    pub mesh: TriMesh,
    /// Blend shapes as per-vertex position deltas (m).
    pub targets: Vec<MorphTarget>,
    /// Weights animation (seconds, one weight per target per key).
    pub keys: WeightKeys,
    /// Named vertex regions (for tests and masks), e.g. "upper_lip".
    pub regions: Vec<(String, Vec<usize>)>,
}

/// Generate the face rig.
pub fn generate() -> FaceRig {
    todo!("face rig generator")
}
