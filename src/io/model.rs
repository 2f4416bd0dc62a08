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

/// The scale a rig is simulated at, and why (in the report as `rig_scale`).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RigScale {
    /// Metres per file unit used in the simulation (1: as in the file).
    pub metres_per_unit: f64,
    /// Height of the region the face's blend shapes move, in file units (its bounding box's
    /// largest side; the whole face when the shapes move one vertex or none).
    pub face_size: f64,
    /// Why this scale, in words (said on the terminal).
    pub why: String,
}

impl Default for RigScale {
    fn default() -> Self {
        Self {
            metres_per_unit: 1.0,
            face_size: f64::NAN,
            why: "the file's units are metres (as glTF says)".into(),
        }
    }
}
