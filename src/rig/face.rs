//! The procedural face rig of `rigs/face.glb`.

use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;

use super::animation::demo_keys;
use super::regions::regions;
use super::shapes::{shape_deltas, SHAPE_NAMES};
use super::surface::build_mask;

/// Half the number of azimuth steps across the mask at the default resolution (even rows have
/// `2 K + 1` vertices).
pub const COLUMNS_HALF: usize = 45;
/// Number of lattice rows from the chin rim to the forehead rim at the default resolution.
pub const ROWS: usize = 110;

/// Resolution of the generated mask. The default gives 10 088 vertices with edges of 1.7 to
/// 5.1 mm (mean about 2.5 mm); keep `rows ≈ 2.44 columns_half` for near-equilateral triangles.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct FaceRigSettings {
    /// Half the number of azimuth steps across the mask (dimensionless, 10..=400).
    pub columns_half: usize,
    /// Number of lattice rows from the chin rim to the forehead rim (dimensionless, 24..=1000).
    pub rows: usize,
}

impl Default for FaceRigSettings {
    fn default() -> Self {
        Self {
            columns_half: COLUMNS_HALF,
            rows: ROWS,
        }
    }
}

impl FaceRigSettings {
    /// The default resolution scaled by `factor` in each direction (vertex count ∝ factor²,
    /// edge lengths ∝ 1 / factor).
    pub fn scaled(factor: f64) -> Self {
        Self {
            columns_half: (COLUMNS_HALF as f64 * factor).round().max(0.0) as usize,
            rows: (ROWS as f64 * factor).round().max(0.0) as usize,
        }
    }

    /// Check the settings; the error names the field that is out of range.
    pub fn validate(&self) -> Result<(), RigError> {
        if !(10..=400).contains(&self.columns_half) {
            return Err(RigError::Setting {
                field: "columns_half",
                message: format!(
                    "is {}, must be in 10..=400 (default {COLUMNS_HALF})",
                    self.columns_half
                ),
            });
        }
        if !(24..=1000).contains(&self.rows) {
            return Err(RigError::Setting {
                field: "rows",
                message: format!("is {}, must be in 24..=1000 (default {ROWS})", self.rows),
            });
        }
        Ok(())
    }
}

/// Why a rig could not be generated.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RigError {
    /// A setting is out of range.
    #[error("face rig setting `{field}` {message}")]
    Setting {
        /// Name of the offending field.
        field: &'static str,
        /// What is wrong and what is allowed.
        message: String,
    },
}

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
    build(FaceRigSettings::default())
}

/// [`generate`] at another resolution (for example finer, so that the skin mesh holds several
/// vertices per wrinkle wavelength). Same shapes, regions and animation.
pub fn generate_with(settings: &FaceRigSettings) -> Result<FaceRig, RigError> {
    settings.validate()?;
    Ok(build(*settings))
}

/// Build the rig at a validated resolution.
fn build(settings: FaceRigSettings) -> FaceRig {
    let mask = build_mask(settings.columns_half, settings.rows);
    let mesh = mask.mesh.clone();
    let neutral_normals = mesh.vertex_normals();
    let targets = shape_deltas(&mask)
        .into_iter()
        .map(|(name, positions)| {
            let normals = mesh.normal_deltas(&neutral_normals, &positions);
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
