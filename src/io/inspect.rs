//! `furrow inspect`: what a glTF file holds (meshes, counts, morph targets, animations,
//! extensions), as text or JSON.

use super::accessor::AccessorReader;
use super::animation::{weight_track, AnimationInfo};
use super::container::{Container, ReadOptions};
use super::error::GltfResult;
use super::load::load_instances_with;
use super::mesh::MeshInstance;
use super::mesh::VertexTransform;
use serde::Serialize;
use std::path::Path;

/// One mesh instance in the summary.
#[derive(Debug, Clone, Serialize)]
pub struct MeshSummary {
    /// Node index.
    pub node: usize,
    /// Mesh index.
    pub mesh: usize,
    /// Mesh name.
    pub name: String,
    /// Triangle primitives merged.
    pub primitives: usize,
    /// Vertices (all primitives).
    pub vertices: usize,
    /// Triangles (all primitives).
    pub triangles: usize,
    /// Morph target names.
    pub targets: Vec<String>,
    /// Whether normal deltas are present in every target.
    pub normal_deltas: bool,
    /// Whether the mesh is skinned.
    pub skinned: bool,
    /// World-space bounding box size (m).
    pub size_m: [f64; 3],
    /// Triangles whose quality 2·r_in/r_circ is below [`SLIVER_QUALITY`] (slivers).
    pub slivers: usize,
    /// Worst triangle quality (1 equilateral, 0 degenerate).
    pub worst_quality: f64,
    /// For a mesh of several primitives with morph targets, which primitives would be
    /// simulated as skin and which ride along, and why.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parts: Option<super::parts::FaceParts>,
}

/// Quality 2·r_in/r_circ below which `inspect` counts a triangle as a sliver (a smallest
/// angle of about 3°).
pub const SLIVER_QUALITY: f64 = 0.1;

/// Summary of a file.
#[derive(Debug, Clone, Serialize)]
pub struct Summary {
    /// The file.
    pub file: String,
    /// "glb" or "gltf".
    pub container: String,
    /// `asset.generator`, if any.
    pub generator: Option<String>,
    /// Extensions used.
    pub extensions_used: Vec<String>,
    /// Extensions required.
    pub extensions_required: Vec<String>,
    /// Mesh instances in the displayed scene.
    pub meshes: Vec<MeshSummary>,
    /// Animations.
    pub animations: Vec<AnimationInfo>,
}

/// Read `path` and summarise it, with the default [`ReadOptions`] (see [`summarize_with`]).
pub fn summarize(path: &Path) -> GltfResult<Summary> {
    summarize_with(path, ReadOptions::default())
}

/// Read `path` with `opts` and summarise it. A weight animation that `animate` would refuse
/// (outputs that do not match keys × targets, key times that do not increase, non-finite
/// weights) is refused here too, with the same message.
pub fn summarize_with(path: &Path, opts: ReadOptions) -> GltfResult<Summary> {
    let (c, inst, animations) = load_instances_with(path, opts)?;
    check_weight_tracks(path, &c, &inst, &animations)?;
    let meshes = inst
        .iter()
        .map(|m| {
            let (lo, hi) = crate::mesh::TriMesh::new(m.positions.clone(), vec![])
                .bounding_box()
                .unwrap_or_default();
            let d = hi - lo;
            let q = crate::mesh::quality::check(
                &crate::mesh::TriMesh::new(m.positions.clone(), m.triangles.clone()),
                SLIVER_QUALITY,
            );
            MeshSummary {
                node: m.node,
                mesh: m.mesh,
                name: m.name.clone(),
                primitives: m.primitives.len(),
                vertices: m.positions.len(),
                triangles: m.triangles.len(),
                targets: m.targets.iter().map(|t| t.name.clone()).collect(),
                normal_deltas: !m.targets.is_empty()
                    && m.targets.iter().all(|t| t.normals.is_some()),
                skinned: matches!(m.to_world, VertexTransform::PerVertex(_)),
                size_m: [d.x, d.y, d.z],
                slivers: q.slivers.len(),
                worst_quality: q.worst_quality,
                parts: (m.primitives.len() > 1 && !m.targets.is_empty())
                    .then(|| {
                        super::parts::classify(
                            m,
                            &c.json["meshes"][m.mesh],
                            &c.json["materials"],
                            None,
                        )
                        .ok()
                    })
                    .flatten(),
            }
        })
        .collect();
    Ok(Summary {
        file: path.display().to_string(),
        container: if c.binary {
            "glb".into()
        } else {
            "gltf".into()
        },
        generator: c.root.asset.generator.clone(),
        extensions_used: c.root.extensions_used.clone(),
        extensions_required: c.root.extensions_required.clone(),
        meshes,
        animations,
    })
}

/// Read every `weights` channel that drives a mesh instance, as `animate` reads the face's.
fn check_weight_tracks(
    path: &Path,
    c: &Container,
    inst: &[MeshInstance],
    animations: &[AnimationInfo],
) -> GltfResult<()> {
    let reader = AccessorReader::new(path, c);
    for a in animations {
        for m in inst.iter().filter(|m| !m.targets.is_empty()) {
            weight_track(path, &reader, &c.json, a.index, m.node, m.targets.len())?;
        }
    }
    Ok(())
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{} ({}{})",
            self.file,
            self.container,
            self.generator
                .as_ref()
                .map(|g| format!(", made by {g}"))
                .unwrap_or_default()
        )?;
        if !self.extensions_used.is_empty() {
            writeln!(f, "extensions used: {}", self.extensions_used.join(", "))?;
        }
        if !self.extensions_required.is_empty() {
            writeln!(
                f,
                "extensions required: {}",
                self.extensions_required.join(", ")
            )?;
        }
        writeln!(f, "meshes ({} instances):", self.meshes.len())?;
        for m in &self.meshes {
            writeln!(
                f,
                "  node {:>3} mesh {:>3} {:<24} {:>7} vertices {:>7} triangles {:>2} primitives{}  size {:.3} x {:.3} x {:.3} m",
                m.node, m.mesh, format!("'{}'", m.name), m.vertices, m.triangles, m.primitives,
                if m.skinned { " skinned" } else { "" }, m.size_m[0], m.size_m[1], m.size_m[2]
            )?;
            if m.slivers > 0 {
                writeln!(
                    f,
                    "      {} sliver triangles (quality 2·r_in/r_circ below {SLIVER_QUALITY}; worst {:.2e})",
                    m.slivers, m.worst_quality
                )?;
            }
            if !m.targets.is_empty() {
                writeln!(
                    f,
                    "      {} morph targets{}: {}",
                    m.targets.len(),
                    if m.normal_deltas {
                        " (with normals)"
                    } else {
                        ""
                    },
                    m.targets.join(", ")
                )?;
            }
            if let Some(p) = &m.parts {
                writeln!(f, "      {}", p.summary())?;
            }
        }
        writeln!(f, "animations ({}):", self.animations.len())?;
        for a in &self.animations {
            let ch: Vec<String> = a.channels.iter().map(|(p, n)| format!("{n} {p}")).collect();
            writeln!(
                f,
                "  {:>3} {:<20} {:>7.3} s  channels: {}",
                a.index,
                format!("'{}'", a.name),
                a.duration_s,
                ch.join(", ")
            )?;
        }
        Ok(())
    }
}
