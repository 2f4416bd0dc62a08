//! Step "cut" of the build for slits: the boundary edges of an open mesh extruded into cut
//! walls that flesh may not cross, so the two sides of a slit get separate flesh.

use super::grid::Grid;
use super::V;
use crate::lattice::geom::segment_crosses_triangle;
use crate::mesh::TriMesh;

/// Step "cut" for slits: each boundary edge of an open mesh extruded backwards (against the
/// vertex normals) by the flesh depth (m) into two triangles. Flesh may not connect across a
/// cut, so the two sides of a slit (mouth, eyelids) get separate flesh down to the bone.
pub(super) struct SlitCuts {
    /// Cut triangles (m).
    tris: Vec<[V; 3]>,
    /// Cut triangles overlapping each cell.
    per_cell: Vec<Vec<usize>>,
}

impl SlitCuts {
    /// The cut walls under the `boundary` edges, `depth` (m) deep, hashed on `grid`.
    pub(super) fn extrude(
        mesh: &TriMesh,
        boundary: &[(usize, usize)],
        depth: f64,
        grid: &Grid,
    ) -> Self {
        let pos = &mesh.positions;
        let normals = mesh.vertex_normals();
        let mut tris: Vec<[V; 3]> = Vec::new();
        for &(a, b) in boundary {
            let (pa, pb) = (pos[a], pos[b]);
            let (qa, qb) = (pa - normals[a] * depth, pb - normals[b] * depth);
            tris.push([pa, pb, qb]);
            tris.push([pa, qb, qa]);
        }
        let mut per_cell: Vec<Vec<usize>> = vec![Vec::new(); grid.cell_count()];
        for (t, [a, b, c]) in tris.iter().enumerate() {
            for ci in grid.cells_touching_triangle(a, b, c) {
                per_cell[ci].push(t);
            }
        }
        SlitCuts { tris, per_cell }
    }

    /// Does the segment [p, q] (m) cross a cut wall hashed in either of the two cells?
    pub(super) fn between(&self, p: &V, q: &V, cells: [usize; 2]) -> bool {
        cells.iter().any(|&ci| {
            self.per_cell[ci].iter().any(|&t| {
                let [a, b, c] = &self.tris[t];
                segment_crosses_triangle(p, q, a, b, c, 1e-9)
            })
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::boundary_edges;
    use crate::lattice::build::grid::Bounds;
    use crate::lattice::build::test_meshes::*;

    /// Step "cut": a lone triangle (z = 0.05 m, facing +z) has three slit edges, each
    /// extruded 0.1 m down into two cut triangles; a segment leaving the triangle's prism
    /// crosses a cut, one inside it does not.
    #[test]
    fn slit_cuts_wall_off_the_boundary() {
        let m = triangle();
        let (_, boundary) = boundary_edges(&m);
        let g = Grid::fit(&Bounds::of(&m).unwrap(), 0.1, &cell(0.5)).unwrap();
        assert_eq!(g.cell_count(), 1);
        let cuts = SlitCuts::extrude(&m, &boundary, 0.1, &g);
        assert_eq!(cuts.tris.len(), 6);
        assert_eq!(cuts.per_cell[0], vec![0, 1, 2, 3, 4, 5]);
        assert_eq!(
            cuts.tris[0],
            [m.positions[0], m.positions[1], v(0.18, 0.02, -0.05)]
        );
        let inside = v(0.05, 0.05, 0.0);
        assert!(cuts.between(&inside, &v(0.05, -0.05, 0.0), [0, 0]));
        assert!(cuts.between(&inside, &v(0.2, 0.2, 0.0), [0, 0]));
        assert!(!cuts.between(&inside, &v(0.06, 0.04, -0.04), [0, 0]));
    }
}
