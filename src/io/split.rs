//! The refined face as the export writes it, seams and primitives kept: one export vertex per
//! refined vertex and side of a seam, each refined triangle in its loaded triangle's
//! primitive.
//!
//! A refined triangle lies in a loaded triangle (its ancestor, [`LoadedCorners`]); each of its
//! corners is a refined vertex with barycentric coordinates in that loaded triangle. Where the
//! loaded mesh splits a vertex (a UV seam, a material boundary) the loaded triangles on either
//! side name different loaded vertices, so a refined vertex on the seam is seen through
//! different loaded vertices from each side: the export vertex is the pair (refined vertex,
//! the loaded vertices it lies on), and the two sides get their own vertex with their own UVs.
//! Away from seams every side names the same loaded vertices and the refined vertex stays one.
//! Only ancestors are used, never how the refinement numbers its triangles.

use super::mesh::MeshInstance;
use super::origin::VertexOrigin;
use anyhow::bail;
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// Barycentric coordinates below this are zero: the corner lies on the opposite edge.
const ON_EDGE: f64 = 1e-9;

/// Where a refined triangle lies in the loaded face.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LoadedCorners {
    /// The loaded triangle (index into the face's merged triangles).
    pub triangle: usize,
    /// Barycentric coordinates of each corner of the refined triangle in it (in the loaded
    /// triangle's corner order; each sums to one).
    pub bary: [[f64; 3]; 3],
}

/// How the refined skin maps onto the loaded face: what the export takes from a run.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct FaceMap {
    /// Triangles of the refined skin (refined vertex indices, counter-clockwise).
    pub triangles: Vec<[usize; 3]>,
    /// The subdivision S: for each refined vertex, (welded vertex, weight) pairs; blend-shape
    /// deltas and the rest shape are carried onto the refined skin with it.
    pub subdivision: Vec<Vec<(usize, f64)>>,
    /// For each loaded vertex, its welded vertex.
    pub welded_of_loaded: Vec<usize>,
    /// Number of welded vertices.
    pub welded_count: usize,
    /// For each refined triangle, its loaded triangle and corners.
    pub corners: Vec<LoadedCorners>,
}

impl FaceMap {
    /// Number of refined vertices.
    pub fn refined_count(&self) -> usize {
        self.subdivision.len()
    }

    /// Check the map fits `face` (the loaded face it was made from); the error says what
    /// does not match.
    pub fn check(&self, face: &MeshInstance) -> anyhow::Result<()> {
        let n = self.refined_count();
        if self.corners.len() != self.triangles.len() {
            bail!(
                "{} triangles but {} ancestors",
                self.triangles.len(),
                self.corners.len()
            );
        }
        if self.welded_of_loaded.len() != face.positions.len() {
            bail!(
                "the map is for a face of {} vertices, this face has {}",
                self.welded_of_loaded.len(),
                face.positions.len()
            );
        }
        if self.triangles.iter().flatten().any(|&v| v >= n)
            || self
                .welded_of_loaded
                .iter()
                .any(|&w| w >= self.welded_count)
            || self
                .subdivision
                .iter()
                .flatten()
                .any(|&(w, _)| w >= self.welded_count)
            || self
                .corners
                .iter()
                .any(|c| c.triangle >= face.triangles.len())
        {
            bail!("the map indexes past the face's vertices or triangles");
        }
        Ok(())
    }
}

/// One primitive of the exported face.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitPrimitive {
    /// Index of the primitive in the face mesh's JSON (its material and attributes).
    pub json: usize,
    /// First export vertex of the primitive (its vertices are contiguous).
    pub first: usize,
    /// Number of export vertices.
    pub count: usize,
    /// Triangles in the primitive's own vertex numbering (counter-clockwise).
    pub triangles: Vec<[usize; 3]>,
}

/// The face's export vertices and primitives.
#[derive(Debug, Clone, PartialEq)]
pub struct SplitFace {
    /// For each export vertex, its refined vertex.
    pub refined: Vec<usize>,
    /// For each export vertex, the loaded triangle's corners and its barycentric coordinates
    /// there (UVs, colours and skin weights are interpolated with these).
    pub origin: Vec<VertexOrigin>,
    /// The primitives, in the face mesh's order.
    pub primitives: Vec<SplitPrimitive>,
    /// JSON indices of the face mesh's primitives that are not refined skin: those that ride
    /// along (not skin, or not triangles) and skin ones with no triangle left after welding.
    /// They are written unchanged.
    pub unrefined: Vec<usize>,
}

/// The loaded vertices a corner lies on (barycentric coordinate above [`ON_EDGE`]), sorted,
/// padded with `usize::MAX`.
fn support(loaded: [usize; 3], bary: &[f64; 3]) -> [usize; 3] {
    let mut s = [usize::MAX; 3];
    let mut n = 0;
    for j in 0..3 {
        if bary[j] > ON_EDGE {
            s[n] = loaded[j];
            n += 1;
        }
    }
    s[..n].sort_unstable();
    s
}

/// The corner's origin: the loaded corners and the barycentric coordinates, those on the
/// opposite edge set to zero and the rest renormalised.
fn corner_origin(loaded: [usize; 3], bary: &[f64; 3]) -> VertexOrigin {
    let mut w = bary.map(|b| if b > ON_EDGE { b } else { 0.0 });
    let s: f64 = w.iter().sum();
    w.iter_mut().for_each(|x| *x /= s);
    VertexOrigin {
        vertices: loaded,
        weights: w,
    }
}

/// Split the refined face of `map` for export: primitive by primitive (the face's spans, in
/// the mesh's order; `mesh_json` the face mesh's JSON), one vertex per refined vertex and the loaded
/// vertices it lies on.
pub fn split_face(
    face: &MeshInstance,
    mesh_json: &serde_json::Value,
    map: &FaceMap,
) -> anyhow::Result<SplitFace> {
    map.check(face)?;
    let range_of = |v: usize| {
        face.primitives
            .partition_point(|s| s.first <= v)
            .saturating_sub(1)
    };
    let mut by_range: Vec<Vec<usize>> = vec![Vec::new(); face.primitives.len()];
    for (t, c) in map.corners.iter().enumerate() {
        by_range[range_of(face.triangles[c.triangle][0])].push(t);
    }
    let mut out = SplitFace {
        refined: Vec::new(),
        origin: Vec::new(),
        primitives: Vec::new(),
        unrefined: Vec::new(),
    };
    for (r, tris) in by_range.iter().enumerate() {
        if tris.is_empty() {
            continue;
        }
        let first = out.refined.len();
        let mut index: HashMap<(usize, [usize; 3]), usize> = HashMap::new();
        let mut triangles = Vec::with_capacity(tris.len());
        for &t in tris {
            let c = &map.corners[t];
            let loaded = face.triangles[c.triangle];
            let tri = std::array::from_fn(|k| {
                let v = map.triangles[t][k];
                let key = (v, support(loaded, &c.bary[k]));
                *index.entry(key).or_insert_with(|| {
                    out.refined.push(v);
                    out.origin.push(corner_origin(loaded, &c.bary[k]));
                    out.refined.len() - 1 - first
                })
            });
            triangles.push(tri);
        }
        out.primitives.push(SplitPrimitive {
            json: face.primitives[r].json,
            first,
            count: out.refined.len() - first,
            triangles,
        });
    }
    let count = mesh_json["primitives"].as_array().map_or(0, |a| a.len());
    out.unrefined = (0..count)
        .filter(|j| !out.primitives.iter().any(|p| p.json == *j))
        .collect();
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::mesh::{PrimitiveSpan, VertexTransform};
    use nalgebra::{Matrix4, Vector3};

    /// Two loaded triangles sharing an edge, in two primitives with the edge's vertices
    /// duplicated (a seam): loaded 0 1 2 | 3 4 5 with 3 = 1 and 4 = 2 in space.
    fn seam_face() -> MeshInstance {
        let p = |x: f64, y: f64| Vector3::new(x, y, 0.0);
        MeshInstance {
            node: 0,
            mesh: 0,
            name: "seam".into(),
            positions: vec![
                p(0., 0.),
                p(1., 0.),
                p(0., 1.),
                p(1., 0.),
                p(0., 1.),
                p(1., 1.),
            ],
            normals: None,
            triangles: vec![[0, 1, 2], [3, 5, 4]],
            targets: vec![],
            default_weights: vec![],
            to_world: VertexTransform::Node(Matrix4::identity()),
            primitives: vec![
                PrimitiveSpan {
                    json: 0,
                    first: 0,
                    count: 3,
                },
                PrimitiveSpan {
                    json: 2,
                    first: 3,
                    count: 3,
                },
            ],
            skipped_primitives: 0,
        }
    }

    /// One level of midpoint refinement of the welded pair (welded 0 1 2 3 = loaded 0 1 2 5;
    /// refined 4 = mid(1, 2) on the seam, 5 = mid(0, 1), 6 = mid(0, 2), 7 = mid(1, 3),
    /// 8 = mid(2, 3)), built by hand.
    fn seam_map() -> FaceMap {
        let h = 0.5;
        let c = |t: usize, bary: [[f64; 3]; 3]| LoadedCorners { triangle: t, bary };
        FaceMap {
            triangles: vec![
                [0, 5, 6],
                [5, 1, 4],
                [6, 4, 2],
                [5, 4, 6],
                [1, 7, 4],
                [7, 3, 8],
                [4, 8, 2],
                [7, 8, 4],
            ],
            subdivision: vec![vec![(0, 1.0)]; 9],
            welded_of_loaded: vec![0, 1, 2, 1, 2, 3],
            welded_count: 4,
            corners: vec![
                c(0, [[1., 0., 0.], [h, h, 0.], [h, 0., h]]),
                c(0, [[h, h, 0.], [0., 1., 0.], [0., h, h]]),
                c(0, [[h, 0., h], [0., h, h], [0., 0., 1.]]),
                c(0, [[h, h, 0.], [0., h, h], [h, 0., h]]),
                // Loaded triangle 1 is (3, 5, 4) = welded (1, 3, 2).
                c(1, [[1., 0., 0.], [h, h, 0.], [h, 0., h]]),
                c(1, [[h, h, 0.], [0., 1., 0.], [0., h, h]]),
                c(1, [[h, 0., h], [0., h, h], [0., 0., 1.]]),
                c(1, [[h, h, 0.], [0., h, h], [h, 0., h]]),
            ],
        }
    }

    #[test]
    fn seam_vertices_split_per_side_and_primitives_keep_their_triangles() {
        let face = seam_face();
        let mesh_json = serde_json::json!({ "primitives": [
            { "attributes": {}, "mode": 4 }, { "attributes": {}, "mode": 1 }, { "attributes": {} } ] });
        let s = split_face(&face, &mesh_json, &seam_map()).unwrap();
        assert_eq!(s.primitives.len(), 2);
        assert_eq!(s.primitives[0].json, 0);
        assert_eq!(s.primitives[1].json, 2);
        assert_eq!(s.unrefined, vec![1]);
        // Primitive 0: refined 0 1 2 4 5 6; primitive 1: refined 1 3 2 4 7 8 (own copies of
        // the seam vertices 1, 2 and 4).
        assert_eq!(s.primitives[0].count, 6);
        assert_eq!(s.primitives[1].count, 6);
        assert_eq!(s.refined.len(), 12);
        let seam_copies = s.refined.iter().filter(|&&v| v == 4).count();
        assert_eq!(seam_copies, 2);
        // The seam midpoint's origin on side 1 is loaded 3 and 4 at ½ each.
        let i = s.primitives[1].first
            + (0..6)
                .find(|&j| s.refined[s.primitives[1].first + j] == 4)
                .unwrap();
        let o = s.origin[i];
        let w: f64 = (0..3)
            .filter(|&j| o.vertices[j] == 3 || o.vertices[j] == 4)
            .map(|j| o.weights[j])
            .sum();
        assert!((w - 1.0).abs() < 1e-15, "{o:?}");
        // Every triangle indexes its own primitive's vertices; all 8 are kept.
        let total: usize = s.primitives.iter().map(|p| p.triangles.len()).sum();
        assert_eq!(total, 8);
        for p in &s.primitives {
            assert!(p.triangles.iter().flatten().all(|&v| v < p.count));
        }
    }

    #[test]
    fn a_map_for_another_face_is_refused() {
        let mut face = seam_face();
        face.positions.pop();
        let e = split_face(&face, &serde_json::json!({}), &seam_map()).unwrap_err();
        assert!(e.to_string().contains("6 vertices"), "{e}");
    }
}
