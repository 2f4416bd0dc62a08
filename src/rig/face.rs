//! The procedural face rig of `rigs/face.glb`.

use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;

use super::animation::demo_keys;
use super::regions::regions;
use super::shapes::{shape_deltas, SHAPE_NAMES};
use super::surface::build_mask;

/// Half the number of azimuth steps across the mask (even rows have `2 K + 1` vertices).
pub const COLUMNS_HALF: usize = 45;
/// Number of lattice rows from the chin rim to the forehead rim.
pub const ROWS: usize = 110;

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

impl FaceRig {
    /// Vertex list of the region `name`, if the rig has it.
    pub fn region(&self, name: &str) -> Option<&[usize]> {
        self.regions
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// The target called `name`, if the rig has it.
    pub fn target(&self, name: &str) -> Option<&MorphTarget> {
        self.targets.iter().find(|t| t.name == name)
    }
}

/// Generate the face rig: a mask of about 10k vertices, 0.2 m tall, open at the back, with the
/// mouth cut between the lips; the nine blend shapes of [`SHAPE_NAMES`] (position deltas in
/// metres plus the matching unit-normal deltas); and an 8.7 s weights animation keyed at 30 fps
/// that plays each shape alone and then four combinations. Deterministic.
pub fn generate() -> FaceRig {
    let mask = build_mask(COLUMNS_HALF, ROWS);
    let mesh = mask.mesh.clone();
    let neutral_normals = mesh.vertex_normals();
    let targets = shape_deltas(&mask)
        .into_iter()
        .map(|(name, positions)| {
            let moved: Vec<_> = mesh
                .positions
                .iter()
                .zip(&positions)
                .map(|(p, d)| p + d)
                .collect();
            let normals = mesh
                .vertex_normals_of(&moved)
                .iter()
                .zip(&neutral_normals)
                .map(|(n, n0)| n - n0)
                .collect();
            MorphTarget {
                name,
                positions,
                normals: Some(normals),
            }
        })
        .collect();
    FaceRig {
        keys: demo_keys(&SHAPE_NAMES),
        regions: regions(&mask),
        mesh,
        targets,
    }
}
