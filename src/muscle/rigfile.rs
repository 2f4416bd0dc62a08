//! Muscles from a TOML rig file.
//!
//! ```toml
//! # muscles.toml: lengths in metres, in the rig's world space
//! [[muscle]]
//! name = "zygomaticus_L"
//! fibre = [0.6, 0.8, 0.0]        # direction of shortening (normalised), rest frame
//! max_contraction = 0.25         # optional (default 0.2): free fibre strain at activation 1
//! bounds = [0.0, 1.0]            # optional activation bounds (default [0, 1])
//! # the region, one or more of:
//! elements = [12, 13, 40]        # lattice element indices
//! box = { min = [0.02, -0.03, 0.05], max = [0.06, 0.01, 0.12] }
//! vertices = [101, 102, 103]     # face vertices: the elements holding them
//! ```
//!
//! A `box` selects the elements whose cell centre lies in it and the elements holding the
//! face vertices that lie in it (so superimposed elements, such as the two lips in one cell,
//! are told apart by their vertices).

use super::model::{Muscle, DEFAULT_MAX_CONTRACTION};
use super::MuscleError;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use serde::Deserialize;
use std::path::Path;

/// An axis-aligned box (m).
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BoxRegion {
    /// Lowest corner (m).
    pub min: [f64; 3],
    /// Highest corner (m).
    pub max: [f64; 3],
}

/// One `[[muscle]]` entry of the file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MuscleEntry {
    /// Name.
    pub name: String,
    /// Fibre direction (any length > 0).
    pub fibre: [f64; 3],
    /// Maximum contraction (dimensionless, in (0, 1)).
    pub max_contraction: Option<f64>,
    /// Activation bounds.
    pub bounds: Option<[f64; 2]>,
    /// Lattice element indices.
    pub elements: Option<Vec<usize>>,
    /// Region as an axis-aligned box (m).
    #[serde(rename = "box")]
    pub region: Option<BoxRegion>,
    /// Face vertex indices.
    pub vertices: Option<Vec<usize>>,
}

/// The whole file.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RigFile {
    /// The muscles.
    pub muscle: Vec<MuscleEntry>,
}

/// Parse rig-file text (`path` names errors) and resolve its regions on `lattice` over
/// `mesh` (the face at rest).
pub fn parse(
    path: &Path,
    text: &str,
    lattice: &Lattice,
    mesh: &TriMesh,
) -> Result<Vec<Muscle>, MuscleError> {
    let err = |msg: String| MuscleError::RigFile {
        path: path.display().to_string(),
        msg,
    };
    let file: RigFile = toml::from_str(text).map_err(|e| err(format!("not a muscle file: {e}")))?;
    if file.muscle.is_empty() {
        return Err(err("no [[muscle]] entries".into()));
    }
    let mut out: Vec<Muscle> = Vec::new();
    for m in &file.muscle {
        let name = &m.name;
        if out.iter().any(|o| &o.name == name) {
            return Err(err(format!("muscle '{name}' is defined twice")));
        }
        let f = Vector3::from(m.fibre);
        if !(f.iter().all(|v| v.is_finite()) && f.norm() > 1e-12) {
            return Err(err(format!(
                "muscle '{name}': fibre {:?} must be a non-zero direction",
                m.fibre
            )));
        }
        let mut elements = Vec::new();
        if let Some(es) = &m.elements {
            if let Some(&e) = es.iter().find(|&&e| e >= lattice.elements.len()) {
                return Err(err(format!(
                    "muscle '{name}': element {e} does not exist (the lattice has {} elements)",
                    lattice.elements.len()
                )));
            }
            elements.extend(es);
        }
        if let Some(b) = &m.region {
            let (lo, hi) = (Vector3::from(b.min), Vector3::from(b.max));
            if (0..3).any(|i| lo[i].is_nan() || hi[i].is_nan() || lo[i] > hi[i]) {
                return Err(err(format!(
                    "muscle '{name}': box min {:?} must be ≤ max {:?}",
                    b.min, b.max
                )));
            }
            let inside = |p: &Vector3<f64>| (0..3).all(|i| p[i] >= lo[i] && p[i] <= hi[i]);
            for e in 0..lattice.elements.len() {
                let c = lattice.cell_origin(e) + Vector3::repeat(0.5 * lattice.cell_size);
                if inside(&c) {
                    elements.push(e);
                }
            }
            for (v, p) in mesh.positions.iter().enumerate() {
                if inside(p) {
                    if let Some(mp) = lattice.vertex_points.get(v) {
                        elements.push(mp.element);
                    }
                }
            }
        }
        if let Some(vs) = &m.vertices {
            for &v in vs {
                let mp = lattice.vertex_points.get(v).ok_or_else(|| {
                    err(format!(
                        "muscle '{name}': vertex {v} does not exist (the face has {})",
                        lattice.vertex_points.len()
                    ))
                })?;
                elements.push(mp.element);
            }
        }
        if elements.is_empty() {
            return Err(err(format!(
                "muscle '{name}': its region selects no lattice element (give `elements`, a `box` that overlaps the face, or `vertices`)"
            )));
        }
        let mut mu = Muscle::uniform(name, elements, f);
        mu.max_contraction = m.max_contraction.unwrap_or(DEFAULT_MAX_CONTRACTION);
        if let Some(b) = m.bounds {
            mu.bounds = b;
        }
        mu.validate(lattice.elements.len()).map_err(err)?;
        out.push(mu);
    }
    Ok(out)
}

/// Read and parse the rig file at `path` (see [`parse`]).
pub fn load(path: &Path, lattice: &Lattice, mesh: &TriMesh) -> Result<Vec<Muscle>, MuscleError> {
    let text = std::fs::read_to_string(path).map_err(|e| MuscleError::RigFile {
        path: path.display().to_string(),
        msg: format!("cannot read: {e}"),
    })?;
    parse(path, &text, lattice, mesh)
}
