//! Steps "hash" and "one piece per cell" of the build: the triangles overlapping each cell,
//! and the connected pieces the cell's faces cut the surface into.

use super::grid::Grid;
use super::union_find::UnionFind;
use super::V;
use crate::lattice::geom::segment_box_overlap;
use crate::mesh::TriMesh;
use rayon::prelude::*;
use std::collections::HashMap;

/// Step "hash": the triangles overlapping each cell (flat cell index → ascending triangle
/// indices). A triangle on a cell face belongs to both cells.
pub(super) fn hash_triangles(mesh: &TriMesh, grid: &Grid) -> Vec<Vec<usize>> {
    let pos = &mesh.positions;
    let per_tri: Vec<Vec<usize>> = mesh
        .triangles
        .par_iter()
        .map(|&[a, b, c]| grid.cells_touching_triangle(&pos[a], &pos[b], &pos[c]))
        .collect();
    let mut cell_tris: Vec<Vec<usize>> = vec![Vec::new(); grid.cell_count()];
    for (t, cells) in per_tri.iter().enumerate() {
        for &c in cells {
            cell_tris[c].push(t);
        }
    }
    cell_tris
}

/// The connected pieces of the surface cut by one cell's faces.
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct CellPieces {
    /// Number of pieces (0 for a cell without surface).
    pub(super) count: usize,
    /// Piece (0..count) of each of the cell's triangles, in the order of the cell's list.
    pub(super) of: Vec<usize>,
}

/// Step "one element per connected piece in a cell": the pieces of every cell (see
/// [`cell_pieces`]).
pub(super) fn connected_pieces(
    mesh: &TriMesh,
    grid: &Grid,
    cell_tris: &[Vec<usize>],
) -> Vec<CellPieces> {
    cell_tris
        .par_iter()
        .enumerate()
        .map(|(ci, tris)| {
            if tris.is_empty() {
                return CellPieces::default();
            }
            cell_pieces(mesh, grid.cell_box(grid.coord(ci)), tris)
        })
        .collect()
}

/// The connected pieces of triangles `tris` inside the box (lo, hi) (m): triangles are joined
/// by a shared edge that passes through the box, or a shared vertex inside it. Pieces are
/// numbered in the order of their first triangle.
pub(super) fn cell_pieces(mesh: &TriMesh, (bl, bh): (V, V), tris: &[usize]) -> CellPieces {
    let pos = &mesh.positions;
    let mut uf = UnionFind::new(tris.len());
    let mut edge_first: HashMap<(usize, usize), usize> = HashMap::new();
    let mut vert_first: HashMap<usize, usize> = HashMap::new();
    for (l, &t) in tris.iter().enumerate() {
        let tri = mesh.triangles[t];
        for m in 0..3 {
            let v = tri[m];
            let p = pos[v];
            if (0..3).all(|d| p[d] >= bl[d] && p[d] <= bh[d]) {
                match vert_first.get(&v) {
                    Some(&o) => uf.union(o, l),
                    None => {
                        vert_first.insert(v, l);
                    }
                }
            }
            let (a, b) = (tri[m], tri[(m + 1) % 3]);
            let key = (a.min(b), a.max(b));
            match edge_first.get(&key) {
                Some(&o) => {
                    if segment_box_overlap(&pos[a], &pos[b], &bl, &bh) {
                        uf.union(o, l);
                    }
                }
                None => {
                    edge_first.insert(key, l);
                }
            }
        }
    }
    let mut label = HashMap::new();
    let of: Vec<usize> = (0..tris.len())
        .map(|l| {
            let r = uf.find(l);
            let n = label.len();
            *label.entry(r).or_insert(n)
        })
        .collect();
    CellPieces {
        count: label.len(),
        of,
    }
}

/// The mesh on the grid after hashing and cutting: what the later steps read.
pub(super) struct CellSurface<'a> {
    /// The surface mesh (m).
    pub(super) mesh: &'a TriMesh,
    /// The grid.
    pub(super) grid: Grid,
    /// Triangles overlapping each cell.
    pub(super) tris: Vec<Vec<usize>>,
    /// Connected pieces of each cell.
    pub(super) pieces: Vec<CellPieces>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::test_meshes::*;

    /// Step "hash": the triangle reaches three of the four cells of its 2 × 2 grid.
    #[test]
    fn hash_finds_the_cells_a_triangle_overlaps() {
        let m = triangle();
        let g = Grid {
            lo: V::zeros(),
            h: 0.1,
            dims: [2, 2, 1],
            eps: 1e-10,
        };
        assert_eq!(
            hash_triangles(&m, &g),
            vec![vec![0], vec![0], vec![0], vec![]]
        );
        // A box on the grid lines of 0.1 m cells: every cell of the 2 × 1 × 1 grid has all
        // the triangles of the four long faces (they touch the shared face x = 0.1 m) and its
        // own end cap.
        let b = box_mesh(V::zeros(), v(0.2, 0.1, 0.1), 2);
        let s = surface(&b, 0.1, 0.0);
        assert_eq!(s.grid.dims, [2, 1, 1]);
        assert_eq!(s.tris.iter().map(Vec::len).collect::<Vec<_>>(), [40, 40]);
    }

    /// Step "one piece per cell": two triangles hanging into a box from a shared edge
    /// outside it are two pieces there (upper and lower lip); a box holding the edge joins
    /// them; triangles sharing only a vertex inside the box are one piece.
    #[test]
    fn pieces_join_through_edges_and_vertices_inside_the_cell() {
        let m = TriMesh::new(
            vec![
                v(-0.5, 1.5, 0.5),
                v(1.5, 1.5, 0.5),
                v(0.5, 0.5, 0.2),
                v(0.5, 0.5, 0.8),
                v(0.9, 0.1, 0.2),
                v(0.9, 0.1, 0.8),
            ],
            vec![[0, 1, 2], [1, 0, 3], [2, 4, 5]],
        );
        let unit = (V::zeros(), V::repeat(1.0));
        let split = cell_pieces(&m, unit, &[0, 1]);
        assert_eq!(
            split,
            CellPieces {
                count: 2,
                of: vec![0, 1]
            }
        );
        let tall = (V::zeros(), v(1.0, 2.0, 1.0));
        assert_eq!(cell_pieces(&m, tall, &[0, 1]).count, 1);
        // Triangle 2 shares vertex 2 (inside the unit box) with triangle 0.
        let joined = cell_pieces(&m, unit, &[1, 0, 2]);
        assert_eq!(
            joined,
            CellPieces {
                count: 2,
                of: vec![0, 1, 1]
            }
        );
        // On a grid: cells without surface have no pieces.
        let tri = triangle();
        let s = surface(&tri, 0.1, 0.0);
        let counts: Vec<usize> = s.pieces.iter().map(|p| p.count).collect();
        assert_eq!(counts, [1, 1]);
        assert_eq!(
            connected_pieces(&m, &s.grid, &[vec![], vec![]]),
            vec![CellPieces::default(); 2]
        );
    }
}
