//! Triangle meshes: positions in metres and index triples, plus derived geometry.

use nalgebra::Vector3;

pub mod butterfly;
pub mod fold;
pub mod grid;
pub mod intersect;
pub mod quality;
pub mod redgreen;
pub mod topology;

/// A triangle mesh. Positions are in metres (world space); triangles index into `positions`
/// with counter-clockwise winding seen from outside (the normal side).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct TriMesh {
    /// Vertex positions (m).
    pub positions: Vec<Vector3<f64>>,
    /// Vertex index triples, counter-clockwise.
    pub triangles: Vec<[usize; 3]>,
}

impl TriMesh {
    /// A mesh from positions and triangles.
    pub fn new(positions: Vec<Vector3<f64>>, triangles: Vec<[usize; 3]>) -> Self {
        Self {
            positions,
            triangles,
        }
    }

    /// Number of vertices.
    pub fn vertex_count(&self) -> usize {
        self.positions.len()
    }

    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.triangles.len()
    }

    /// Axis-aligned bounding box (min, max) in metres; `None` for an empty mesh.
    pub fn bounding_box(&self) -> Option<(Vector3<f64>, Vector3<f64>)> {
        let first = *self.positions.first()?;
        Some(
            self.positions
                .iter()
                .fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))),
        )
    }

    /// Area (m²) of triangle `t`.
    pub fn triangle_area(&self, t: usize) -> f64 {
        let [a, b, c] = self.triangles[t];
        let p = &self.positions;
        0.5 * (p[b] - p[a]).cross(&(p[c] - p[a])).norm()
    }

    /// Total surface area (m²).
    pub fn area(&self) -> f64 {
        (0..self.triangles.len())
            .map(|t| self.triangle_area(t))
            .sum()
    }

    /// Each vertex's share of the surface area at `positions` (m², same topology as
    /// `self`): a third of the areas of its triangles (the lumped mass of linear elements).
    pub fn vertex_areas_of(&self, positions: &[Vector3<f64>]) -> Vec<f64> {
        let mut area = vec![0.0; positions.len()];
        for &[a, b, c] in &self.triangles {
            let t = (positions[b] - positions[a])
                .cross(&(positions[c] - positions[a]))
                .norm()
                / 6.0;
            for v in [a, b, c] {
                area[v] += t;
            }
        }
        area
    }

    /// Area-weighted unit vertex normals for the given positions (same topology as `self`).
    /// Vertices with no non-degenerate incident triangle get +Z.
    pub fn vertex_normals_of(&self, positions: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
        let mut n = vec![Vector3::zeros(); positions.len()];
        for &[a, b, c] in &self.triangles {
            let fnrm = (positions[b] - positions[a]).cross(&(positions[c] - positions[a]));
            n[a] += fnrm;
            n[b] += fnrm;
            n[c] += fnrm;
        }
        n.into_iter()
            .map(|v| {
                let l = v.norm();
                if l > 0.0 && l.is_finite() {
                    v / l
                } else {
                    Vector3::z()
                }
            })
            .collect()
    }

    /// Area-weighted unit vertex normals of this mesh.
    pub fn vertex_normals(&self) -> Vec<Vector3<f64>> {
        self.vertex_normals_of(&self.positions)
    }

    /// A morph target's normal deltas: the unit vertex normals of the mesh moved by `deltas`
    /// (m) minus `neutral` (this mesh's own [`TriMesh::vertex_normals`], passed in so a rig
    /// with many targets computes them once).
    pub fn normal_deltas(
        &self,
        neutral: &[Vector3<f64>],
        deltas: &[Vector3<f64>],
    ) -> Vec<Vector3<f64>> {
        let moved: Vec<_> = self
            .positions
            .iter()
            .zip(deltas)
            .map(|(p, d)| p + d)
            .collect();
        self.vertex_normals_of(&moved)
            .iter()
            .zip(neutral)
            .map(|(a, b)| a - b)
            .collect()
    }

    /// Flat `[x0, y0, z0, x1, …]` copy of the positions (the layout solvers use).
    pub fn flat_positions(&self) -> Vec<f64> {
        self.positions
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect()
    }
}

/// Convert a flat `[x0, y0, z0, …]` vector into points.
pub fn points_from_flat(x: &[f64]) -> Vec<Vector3<f64>> {
    x.chunks_exact(3)
        .map(|c| Vector3::new(c[0], c[1], c[2]))
        .collect()
}

/// The triangles of a row-major grid of `nx` × `ny` vertices (vertex j nx + i at column i,
/// row j): two per cell, wound counter-clockwise seen from +z when rows run along +y.
pub fn grid_triangles(nx: usize, ny: usize) -> Vec<[usize; 3]> {
    let mut t = Vec::with_capacity(2 * nx.saturating_sub(1) * ny.saturating_sub(1));
    for j in 0..ny.saturating_sub(1) {
        for i in 0..nx.saturating_sub(1) {
            let a = j * nx + i;
            t.push([a, a + 1, a + nx + 1]);
            t.push([a, a + nx + 1, a + nx]);
        }
    }
    t
}

/// Closed box mesh [0, a]³ (a in m) with each face split into m × m quads (outward normals).
pub fn cube_mesh(a: f64, m: usize) -> TriMesh {
    box_mesh(Vector3::zeros(), Vector3::repeat(a), m)
}

/// Closed axis-aligned box [lo, hi] (m) with each face split into m × m quads (outward
/// normals, counter-clockwise triangles), vertices shared between faces.
pub fn box_mesh(lo: Vector3<f64>, hi: Vector3<f64>, m: usize) -> TriMesh {
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    let frames: [(usize, f64, Vector3<f64>, Vector3<f64>); 6] = [
        (0, 1.0, Vector3::y(), Vector3::z()),
        (0, 0.0, Vector3::z(), Vector3::y()),
        (1, 1.0, Vector3::z(), Vector3::x()),
        (1, 0.0, Vector3::x(), Vector3::z()),
        (2, 1.0, Vector3::x(), Vector3::y()),
        (2, 0.0, Vector3::y(), Vector3::x()),
    ];
    let mut key = std::collections::HashMap::new();
    for (axis, side, t1, t2) in frames {
        let mut idx = vec![vec![0usize; m + 1]; m + 1];
        for (i, row) in idx.iter_mut().enumerate() {
            for (j, id) in row.iter_mut().enumerate() {
                let mut u = t1 * (i as f64 / m as f64) + t2 * (j as f64 / m as f64);
                u[axis] = side;
                let k = [0, 1, 2].map(|d| (u[d] * m as f64).round() as i64);
                *id = *key.entry(k).or_insert_with(|| {
                    pos.push(lo + u.component_mul(&(hi - lo)));
                    pos.len() - 1
                });
            }
        }
        for i in 0..m {
            for j in 0..m {
                let (p, q, r, s) = (idx[i][j], idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]);
                tris.push([p, q, r]);
                tris.push([p, r, s]);
            }
        }
    }
    TriMesh::new(pos, tris)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unit_square_area_bbox_and_normals() {
        let m = TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        assert!((m.area() - 1.0).abs() < 1e-15);
        let (lo, hi) = m.bounding_box().unwrap();
        assert_eq!(lo, Vector3::zeros());
        assert_eq!(hi, Vector3::new(1.0, 1.0, 0.0));
        for n in m.vertex_normals() {
            assert!((n - Vector3::z()).norm() < 1e-15);
        }
        assert_eq!(points_from_flat(&m.flat_positions()), m.positions);
    }
}
