//! Small meshes, grids and settings that the build's unit tests share.

use super::cuts::SlitCuts;
use super::grid::{Bounds, Grid};
use super::surface::{connected_pieces, hash_triangles, CellSurface};
use super::V;
use crate::lattice::LatticeSettings;
use crate::mesh::TriMesh;
use std::collections::HashMap;

/// The point (x, y, z) (m).
pub(super) fn v(x: f64, y: f64, z: f64) -> V {
    V::new(x, y, z)
}

/// One triangle at z = 0.05 m over the cells (0,0), (1,0), (0,1) of a 0.1 m grid.
pub(super) fn triangle() -> TriMesh {
    TriMesh::new(
        vec![
            v(0.02, 0.02, 0.05),
            v(0.18, 0.02, 0.05),
            v(0.02, 0.12, 0.05),
        ],
        vec![[0, 1, 2]],
    )
}

/// A closed tetrahedron (outward normals).
pub(super) fn tetra() -> TriMesh {
    TriMesh::new(
        vec![v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.), v(0., 0., 1.)],
        vec![[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]],
    )
}

/// Closed box [lo, hi] (m), each face m × m quads, outward normals, welded vertices.
pub(super) fn box_mesh(lo: V, hi: V, m: usize) -> TriMesh {
    let mut pos: Vec<V> = Vec::new();
    let mut key: HashMap<[i64; 3], usize> = HashMap::new();
    let mut tris = Vec::new();
    let frames = [
        (0, 1.0, V::y(), V::z()),
        (0, 0.0, V::z(), V::y()),
        (1, 1.0, V::z(), V::x()),
        (1, 0.0, V::x(), V::z()),
        (2, 1.0, V::x(), V::y()),
        (2, 0.0, V::y(), V::x()),
    ];
    for (axis, side, t1, t2) in frames {
        let mut id = vec![vec![0usize; m + 1]; m + 1];
        for (i, row) in id.iter_mut().enumerate() {
            for (j, slot) in row.iter_mut().enumerate() {
                let mut u = t1 * (i as f64 / m as f64) + t2 * (j as f64 / m as f64);
                u[axis] = side;
                let k = [0, 1, 2].map(|d| (u[d] * m as f64).round() as i64);
                *slot = *key.entry(k).or_insert_with(|| {
                    pos.push(lo + u.component_mul(&(hi - lo)));
                    pos.len() - 1
                });
            }
        }
        for i in 0..m {
            for j in 0..m {
                let (a, b, c, d) = (id[i][j], id[i + 1][j], id[i + 1][j + 1], id[i][j + 1]);
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
    }
    TriMesh::new(pos, tris)
}

/// Default settings with cells of edge `h` (m).
pub(super) fn cell(h: f64) -> LatticeSettings {
    LatticeSettings {
        cell_size: Some(h),
        ..Default::default()
    }
}

/// Hash and cut `mesh` on the grid of cell size `h` padded by `pad` (m).
pub(super) fn surface(mesh: &TriMesh, h: f64, pad: f64) -> CellSurface<'_> {
    let grid = Grid::fit(&Bounds::of(mesh).unwrap(), pad, &cell(h)).unwrap();
    let tris = hash_triangles(mesh, &grid);
    let pieces = connected_pieces(mesh, &grid, &tris);
    CellSurface {
        mesh,
        grid,
        tris,
        pieces,
    }
}

/// No slit cuts, on the grid of `surf`.
pub(super) fn no_cuts(surf: &CellSurface) -> SlitCuts {
    SlitCuts::extrude(surf.mesh, &[], 0.0, &surf.grid)
}
