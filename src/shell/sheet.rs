//! Flat test sheets: a rectangle meshed with (nearly) equilateral triangles, rows along x.

use crate::mesh::TriMesh;
use nalgebra::Vector3;

/// A flat rectangular sheet in the z = 0 plane and its vertex rows.
#[derive(Debug, Clone)]
pub struct Sheet {
    /// The mesh (positions in m).
    pub mesh: TriMesh,
    /// Vertex indices of each row (constant y), ordered by increasing x.
    pub rows: Vec<Vec<usize>>,
    /// Edge length a (m) of the equilateral triangles.
    pub edge: f64,
}

/// Mesh `[0, nx·a] × [0, ny·a·√3/2]` with equilateral triangles of edge `a`: even rows have
/// vertices at x = i a, odd rows at (i + ½) a plus the two ends, so each row spans the full
/// length (the triangles at the ends of odd rows are half-equilateral).
/// Triangles: 2 nx + 1 per row of triangles, ny rows.
pub fn equilateral_sheet(nx: usize, ny: usize, a: f64) -> Sheet {
    assert!(nx >= 1 && ny >= 1 && a > 0.0);
    let dy = a * 3f64.sqrt() / 2.0;
    let mut positions = Vec::new();
    let mut rows = Vec::with_capacity(ny + 1);
    for j in 0..=ny {
        let y = j as f64 * dy;
        let mut row = Vec::new();
        let mut push = |x: f64| {
            row.push(positions.len());
            positions.push(Vector3::new(x, y, 0.0));
        };
        if j % 2 == 0 {
            for i in 0..=nx {
                push(i as f64 * a);
            }
        } else {
            push(0.0);
            for i in 0..nx {
                push((i as f64 + 0.5) * a);
            }
            push(nx as f64 * a);
        }
        rows.push(row);
    }
    let mut tris = Vec::new();
    for j in 0..ny {
        let (lo, hi) = (&rows[j], &rows[j + 1]);
        if j % 2 == 0 {
            let (e, o) = (lo, hi);
            tris.push([e[0], o[1], o[0]]);
            for i in 0..nx {
                tris.push([e[i], e[i + 1], o[i + 1]]);
                if i + 1 < nx {
                    tris.push([e[i + 1], o[i + 2], o[i + 1]]);
                }
            }
            tris.push([e[nx], o[nx + 1], o[nx]]);
        } else {
            let (o, e) = (lo, hi);
            tris.push([o[0], o[1], e[0]]);
            for i in 0..nx {
                tris.push([o[i + 1], e[i + 1], e[i]]);
                if i + 1 < nx {
                    tris.push([o[i + 1], o[i + 2], e[i + 1]]);
                }
            }
            tris.push([o[nx], o[nx + 1], e[nx]]);
        }
    }
    Sheet {
        mesh: TriMesh::new(positions, tris),
        rows,
        edge: a,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::topology::Topology;

    #[test]
    fn sheet_area_counts_and_orientation() {
        let s = equilateral_sheet(6, 4, 0.1);
        let ly = 4.0 * 0.1 * 3f64.sqrt() / 2.0;
        assert!((s.mesh.area() - 0.6 * ly).abs() < 1e-12);
        assert_eq!(s.mesh.triangle_count(), 4 * 13);
        for t in 0..s.mesh.triangle_count() {
            let [a, b, c] = s.mesh.triangles[t];
            let p = &s.mesh.positions;
            assert!(
                (p[b] - p[a]).cross(&(p[c] - p[a])).z > 0.0,
                "triangle {t} not ccw"
            );
        }
        Topology::new(&s.mesh).unwrap();
    }
}
