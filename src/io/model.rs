//! Plain data for blend-shape meshes and their animation, independent of the file format.

use nalgebra::Vector3;

/// One morph target (blend shape): per-vertex deltas added at weight 1.
#[derive(Debug, Clone, PartialEq)]
pub struct MorphTarget {
    /// Target name (from `mesh.extras.targetNames` when the file has it).
    pub name: String,
    /// Position deltas (m), one per vertex.
    pub positions: Vec<Vector3<f64>>,
    /// Normal deltas (unitless), one per vertex, when the file has them.
    pub normals: Option<Vec<Vector3<f64>>>,
}

/// Linearly interpolated weight keys: `weights[k][t]` is target `t`'s weight at `times[k]` (s).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct WeightKeys {
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f64>,
    /// One row of target weights per key.
    pub weights: Vec<Vec<f64>>,
}
