//! Small meshes, grids and settings that the build's unit tests share.

use super::cuts::SlitCuts;
use super::grid::{Bounds, Grid};
use super::surface::{connected_pieces, hash_triangles, CellSurface};
use super::V;
use crate::lattice::LatticeSettings;
use crate::mesh::TriMesh;

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

pub(super) use crate::mesh::box_mesh;

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
