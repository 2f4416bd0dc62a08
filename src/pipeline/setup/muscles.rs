//! The `muscles` and `fit` stages of the set-up: the muscles of the lattice (generated from the
//! rig's blend shapes, or read from a muscle file) and the fitter that turns each frame's
//! target into their activations (a clarabel QP on the linearised response).

use crate::fem::Interior;
use crate::io::mesh::MeshInstance;
use crate::io::model::MorphTarget;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::muscle::{generate_muscles, FitSettings, Fitter, GenerateSettings};
use crate::pipeline::record::StagePlan;
use crate::scene::Scene;
use anyhow::bail;
use std::path::Path;
use std::time::Instant;

use super::interior::MUSCLE_TRACKING;

/// Muscles of a run and their current activations.
pub struct MuscleDrive {
    /// The muscles and the per-frame activation fit.
    pub fitter: Fitter,
    /// Activation of each muscle at the current frame (dimensionless, in [0, 1]).
    pub activations: Vec<f64>,
    /// Where the muscles came from (for the report).
    pub origin: String,
}

/// The muscles from `source` (`auto`: generated from the blend shapes of `face` (from the rig
/// at `path`) on the welded skin,
/// whose vertex `i` is loaded vertex `welded_loaded[i]`; otherwise a muscle TOML file), with
/// their fitter and the `muscles` and `fit` records.
pub fn build_muscles(
    face: &MeshInstance,
    path: &str,
    scene: &Scene,
    lattice: &Lattice,
    welded_loaded: &[usize],
    source: &str,
) -> anyhow::Result<(MuscleDrive, [StagePlan; 2])> {
    let t = Instant::now();
    let material = scene.interior.material()?;
    let (muscles, origin) = if source == "auto" {
        let targets: Vec<MorphTarget> = face
            .targets
            .iter()
            .map(|t| MorphTarget {
                name: t.name.clone(),
                positions: welded_loaded.iter().map(|&i| t.positions[i]).collect(),
                normals: None,
            })
            .collect();
        let interior = Interior::new(lattice, &material)?;
        let g = generate_muscles(lattice, &interior, &targets, &GenerateSettings::default())?;
        (g.muscles, "generated from the blend shapes".to_string())
    } else {
        let welded_mesh = TriMesh::new(
            welded_loaded.iter().map(|&i| face.positions[i]).collect(),
            Vec::new(),
        );
        (
            crate::muscle::rigfile::load(Path::new(source), lattice, &welded_mesh)?,
            format!("from {source}"),
        )
    };
    if muscles.is_empty() {
        bail!(
            "{path}: no muscles ({source}): every blend shape is empty; give a muscle file or use muscles.source = \"none\""
        );
    }
    let n = muscles.len();
    let fitter = Fitter::new(lattice, &material, muscles, FitSettings::default())?;
    let drive = MuscleDrive {
        fitter,
        activations: vec![0.0; n],
        origin,
    };
    let records = [
        StagePlan::ran(
            "muscles",
            format!(
                "{n} muscles {}; a weak tracking (κ = {MUSCLE_TRACKING}) carries what they cannot make (bone motion)",
                drive.origin
            ),
            t.elapsed().as_secs_f64() * 1e3,
        ),
        StagePlan::ran(
            "fit",
            "activations per frame: clarabel QP on the linearised response (warm-started)",
            0.0,
        ),
    ];
    Ok((drive, records))
}

/// The `muscles` and `fit` records of a run without muscles.
pub fn skipped() -> [StagePlan; 2] {
    [
        StagePlan::skipped(
            "muscles",
            "muscles.source = none: the interior tracks the blended surface directly",
        ),
        StagePlan::skipped("fit", "no muscles: no activation QP"),
    ]
}
