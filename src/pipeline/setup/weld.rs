//! Welding a loaded face into one manifold skin: glTF splits vertices along texture seams and
//! normal creases, but the skin must be one connected sheet to carry stress across them. A
//! slit modelled closed (lips that touch at rest) is not a seam: its blend shapes part it, so
//! its sides stay apart.

use crate::io::mesh::MeshInstance;
use crate::io::model::MorphTarget;
use crate::mesh::grid::PointGrid;
use crate::mesh::TriMesh;
use crate::pipeline::record::{Stage, StagePlan};
use anyhow::{bail, Context};
use nalgebra::Vector3;
use std::time::Instant;

/// Relative weld tolerance: vertices closer than this fraction of the face's bounding-box
/// diagonal are one skin vertex.
pub const WELD_TOLERANCE: f64 = 1e-7;

/// The `weld` stage: the loaded face welded into one skin (tolerance [`WELD_TOLERANCE`] of its
/// diagonal), with its record; `path` names the rig in errors (no vertices, no extent, no
/// triangles left).
pub fn weld_face(face: &MeshInstance, path: &str) -> anyhow::Result<(Welded, StagePlan)> {
    let t = Instant::now();
    let raw = TriMesh::new(face.positions.clone(), face.triangles.clone());
    let (lo, hi) = raw
        .bounding_box()
        .with_context(|| format!("{path}: the face '{}' has no vertices", face.name))?;
    let diag = (hi - lo).norm();
    if !(diag.is_finite() && diag > 0.0) {
        bail!("{path}: the face '{}' has no extent", face.name);
    }
    let welded = weld(
        &face.positions,
        &face.targets,
        &face.triangles,
        WELD_TOLERANCE * diag,
    );
    if welded.mesh.triangles.is_empty() {
        bail!("{path}: the face '{}' has no triangles", face.name);
    }
    let record = StagePlan::ran(
        Stage::Weld,
        format!(
            "{} loaded vertices → {} skin vertices ({} triangles dropped as collapsed; {} \
             vertices at a welded vertex kept apart, as blend shapes part them)",
            face.positions.len(),
            welded.mesh.positions.len(),
            welded.dropped_triangles,
            welded.kept_apart
        ),
        t.elapsed().as_secs_f64() * 1e3,
    );
    Ok((welded, record))
}

/// A welded mesh and the maps between it and the loaded vertices.
#[derive(Debug, Clone)]
pub struct Welded {
    /// The welded skin mesh (positions in metres).
    pub mesh: TriMesh,
    /// For each loaded vertex, its welded vertex.
    pub of_loaded: Vec<usize>,
    /// For each welded vertex, one loaded vertex at the same place.
    pub loaded_of: Vec<usize>,
    /// Triangles dropped because welding collapsed them (zero area or repeated corners).
    pub dropped_triangles: usize,
    /// For each welded triangle, the loaded triangle it comes from (same corner order).
    pub loaded_triangle: Vec<usize>,
    /// Loaded vertices left unwelded although they coincide with a skin vertex, because a
    /// blend shape moves them apart (the sides of a slit modelled closed).
    pub kept_apart: usize,
}

/// Weld vertices closer than `tol` (m) whose blend shapes move them alike (each target's
/// deltas, m, differ by at most `tol` too): seam copies become one skin vertex, while a slit
/// modelled closed (lips or eyelids that touch at rest) stays open, since its shapes part it.
/// Positions are snapped to a grid of `tol` and vertices in neighbouring cells are merged,
/// first come first served, so the result does not depend on thread count.
pub fn weld(
    positions: &[Vector3<f64>],
    targets: &[MorphTarget],
    triangles: &[[usize; 3]],
    tol: f64,
) -> Welded {
    let move_alike = |a: usize, b: usize| {
        targets
            .iter()
            .all(|t| (t.positions[a] - t.positions[b]).norm() <= tol)
    };
    let mut cells = PointGrid::new(tol, []);
    let mut of_loaded = vec![usize::MAX; positions.len()];
    let mut loaded_of = Vec::new();
    let mut welded_pos: Vec<Vector3<f64>> = Vec::new();
    let mut kept_apart = 0;
    for (i, p) in positions.iter().enumerate() {
        let mut found = None;
        let mut parted = false;
        for w in cells.near(p).filter(|&w| (welded_pos[w] - p).norm() <= tol) {
            if move_alike(loaded_of[w], i) {
                found = Some(w);
                break;
            }
            parted = true;
        }
        let w = found.unwrap_or_else(|| {
            kept_apart += usize::from(parted);
            let w = welded_pos.len();
            welded_pos.push(*p);
            loaded_of.push(i);
            cells.insert(w, p);
            w
        });
        of_loaded[i] = w;
    }
    let mut tris = Vec::with_capacity(triangles.len());
    let mut loaded_triangle = Vec::with_capacity(triangles.len());
    let mut dropped = 0;
    for (i, t) in triangles.iter().enumerate() {
        let w = [of_loaded[t[0]], of_loaded[t[1]], of_loaded[t[2]]];
        if w[0] == w[1] || w[1] == w[2] || w[0] == w[2] {
            dropped += 1;
            continue;
        }
        tris.push(w);
        loaded_triangle.push(i);
    }
    Welded {
        mesh: TriMesh::new(welded_pos, tris),
        of_loaded,
        loaded_of,
        dropped_triangles: dropped,
        loaded_triangle,
        kept_apart,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seam_vertices_merge_and_collapsed_triangles_drop() {
        let p = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0), // seam copy of 1
            Vector3::new(1.0, 1.0, 0.0),
            Vector3::new(0.0, 1.0, 1e-12), // seam copy of 2 within tolerance
        ];
        let t = vec![[0, 1, 2], [3, 4, 5], [0, 1, 3]];
        let w = weld(&p, &[], &t, 1e-9);
        assert_eq!(w.mesh.positions.len(), 4);
        assert_eq!(w.of_loaded, vec![0, 1, 2, 1, 3, 2]);
        assert_eq!(w.mesh.triangles, vec![[0, 1, 2], [1, 3, 2]]);
        assert_eq!(w.dropped_triangles, 1);
        assert_eq!(w.loaded_triangle, vec![0, 1]);
        assert_eq!(w.loaded_of, vec![0, 1, 2, 4]);
    }

    /// Lips modelled closed: two strips meet along a line with their own copies of its
    /// vertices. A shape that opens the mouth (moves the lower copies) keeps them apart; a
    /// shape that moves both copies alike (a texture seam) lets them weld.
    #[test]
    fn a_slit_that_blend_shapes_part_stays_open() {
        let line = |y: f64| (0..3).map(move |i| Vector3::new(i as f64, y, 0.0));
        // Upper lip: row y = 1 above the line y = 0; lower lip: the line's copies and y = -1.
        let p: Vec<Vector3<f64>> = line(1.0)
            .chain(line(0.0))
            .chain(line(0.0))
            .chain(line(-1.0))
            .collect();
        let strip = |a: usize, b: usize| {
            vec![
                [a, a + 1, b],
                [a + 1, b + 1, b],
                [a + 1, a + 2, b + 1],
                [a + 2, b + 2, b + 1],
            ]
        };
        let t: Vec<[usize; 3]> = strip(0, 3).into_iter().chain(strip(6, 9)).collect();
        let shape = |moved: &[usize], d: Vector3<f64>| MorphTarget {
            name: "s".into(),
            positions: (0..p.len())
                .map(|i| {
                    if moved.contains(&i) {
                        d
                    } else {
                        Vector3::zeros()
                    }
                })
                .collect(),
            normals: None,
        };
        let down = Vector3::new(0.0, -0.3, 0.0);
        let open = weld(&p, &[shape(&[6, 7, 8, 9, 10, 11], down)], &t, 1e-9);
        assert_eq!(open.mesh.positions.len(), 12);
        assert_eq!(open.kept_apart, 3);
        let seam = weld(&p, &[shape(&[3, 4, 5, 6, 7, 8], down)], &t, 1e-9);
        assert_eq!(seam.mesh.positions.len(), 9);
        assert_eq!(seam.kept_apart, 0);
        assert_eq!(seam.of_loaded[6..9], seam.of_loaded[3..6]);
    }
}
