//! Step 1 of the build: the mesh's bounding box and the regular grid of cubic cells sized
//! over it, with the cell indexing, geometry and neighbours the later steps use.

use super::V;
use crate::lattice::geom::triangle_box_overlap;
use crate::lattice::{LatticeError, LatticeSettings, DEFAULT_TARGET_CELLS, MAX_CELLS};
use crate::mesh::TriMesh;

/// The mesh's axis-aligned bounding box (m).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Bounds {
    /// Lowest corner (m).
    pub(super) lo: V,
    /// Highest corner (m).
    pub(super) hi: V,
    /// Length of the diagonal (m), positive.
    pub(super) diag: f64,
}

impl Bounds {
    /// The bounding box of a checked (non-empty) mesh; an error when all vertices coincide.
    pub(super) fn of(mesh: &TriMesh) -> Result<Bounds, LatticeError> {
        let (lo, hi) = mesh.bounding_box().expect("non-empty");
        let diag = (hi - lo).norm();
        if diag <= 0.0 {
            return Err(LatticeError::Mesh("all vertices coincide".into()));
        }
        Ok(Bounds { lo, hi, diag })
    }
}

/// The regular grid of cubic cells: cell (i, j, k) spans `lo + h·[i, i+1] × [j, j+1] × [k, k+1]`;
/// cells are numbered `i + nx (j + ny k)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Grid {
    /// Corner of cell (0, 0, 0) (m).
    pub(super) lo: V,
    /// Cell edge length (m).
    pub(super) h: f64,
    /// Number of cells along x, y, z.
    pub(super) dims: [usize; 3],
    /// Tolerance (m, 10⁻⁹ h) by which cells are grown so that surface on a cell face
    /// belongs to both cells.
    pub(super) eps: f64,
}

impl Grid {
    /// The grid over the bounding box grown by `pad` (m) on every side (the flesh depth for
    /// an open mesh, 0 for a closed one): cell size from the settings, or the cube root of
    /// the padded box volume over the target cell count (each side at least 10⁻³ of the
    /// diagonal, so that flat meshes get a sensible size). Refuses more than [`MAX_CELLS`].
    pub(super) fn fit(b: &Bounds, pad: f64, s: &LatticeSettings) -> Result<Grid, LatticeError> {
        let lo = b.lo - V::repeat(pad);
        let ext = (b.hi - b.lo) + V::repeat(2.0 * pad);
        let h = match s.cell_size {
            Some(h) => h,
            None => {
                let target = s.target_cells.unwrap_or(DEFAULT_TARGET_CELLS) as f64;
                let e = ext.map(|c| c.max(1e-3 * b.diag));
                (e.x * e.y * e.z / target).cbrt()
            }
        };
        let dims = [0, 1, 2].map(|d| ((ext[d] / h - 1e-9).ceil() as usize).max(1));
        let ncell = dims[0] as f64 * dims[1] as f64 * dims[2] as f64;
        if ncell > MAX_CELLS as f64 {
            return Err(LatticeError::TooManyCells {
                cells: ncell as usize,
            });
        }
        Ok(Grid {
            lo,
            h,
            dims,
            eps: 1e-9 * h,
        })
    }

    /// Number of cells.
    pub(super) fn cell_count(&self) -> usize {
        self.dims[0] * self.dims[1] * self.dims[2]
    }

    /// Flat index of cell `c`.
    pub(super) fn index(&self, c: [usize; 3]) -> usize {
        c[0] + self.dims[0] * (c[1] + self.dims[1] * c[2])
    }

    /// Integer coordinates of cell `i`.
    pub(super) fn coord(&self, i: usize) -> [usize; 3] {
        let d = self.dims;
        [i % d[0], (i / d[0]) % d[1], i / (d[0] * d[1])]
    }

    /// Lowest corner of cell `c` (m).
    pub(super) fn corner(&self, c: [usize; 3]) -> V {
        self.lo + V::new(c[0] as f64, c[1] as f64, c[2] as f64) * self.h
    }

    /// Centre of cell `c` (m).
    pub(super) fn center(&self, c: [usize; 3]) -> V {
        let f = |i: usize| i as f64 + 0.5;
        self.lo + V::new(f(c[0]), f(c[1]), f(c[2])) * self.h
    }

    /// Closed box of cell `c` grown by `eps` (m).
    pub(super) fn cell_box(&self, c: [usize; 3]) -> (V, V) {
        let l = self.corner(c);
        (l - V::repeat(self.eps), l + V::repeat(self.h + self.eps))
    }

    /// The cell holding `p` (m), clamped to the grid.
    pub(super) fn clamp_cell(&self, p: &V) -> [usize; 3] {
        let r = (p - self.lo) / self.h;
        [0, 1, 2].map(|d| (r[d].floor().max(0.0) as usize).min(self.dims[d] - 1))
    }

    /// Position (m) of grid node `g` whose node 0 sits `offset` cells from the origin.
    pub(super) fn node_position(&self, g: [usize; 3], offset: f64) -> V {
        let f = |i: usize| i as f64 + offset;
        self.lo + V::new(f(g[0]), f(g[1]), f(g[2])) * self.h
    }

    /// Flat indices of the (grown) cells that triangle (a, b, c) overlaps, z-major order.
    pub(super) fn cells_touching_triangle(&self, a: &V, b: &V, c: &V) -> Vec<usize> {
        let (tlo, thi) = (a.inf(b).inf(c), a.sup(b).sup(c));
        let (c0, c1) = (
            self.clamp_cell(&(tlo - V::repeat(self.eps))),
            self.clamp_cell(&(thi + V::repeat(self.eps))),
        );
        let mut out = Vec::new();
        for kz in c0[2]..=c1[2] {
            for ky in c0[1]..=c1[1] {
                for kx in c0[0]..=c1[0] {
                    let (bl, bh) = self.cell_box([kx, ky, kz]);
                    if triangle_box_overlap(a, b, c, &bl, &bh) {
                        out.push(self.index([kx, ky, kz]));
                    }
                }
            }
        }
        out
    }

    /// The face neighbours of cell `c` inside the grid, in the order −x, +x, −y, +y, −z, +z.
    pub(super) fn face_neighbours(&self, c: [usize; 3]) -> Vec<[usize; 3]> {
        let mut out = Vec::with_capacity(6);
        for d in 0..3 {
            for s in [-1i64, 1] {
                let nb = c[d] as i64 + s;
                if nb >= 0 && nb < self.dims[d] as i64 {
                    let mut cn = c;
                    cn[d] = nb as usize;
                    out.push(cn);
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::test_meshes::*;

    #[test]
    fn bounds_and_grid_sizes() {
        let b = Bounds::of(&triangle()).unwrap();
        assert_eq!((b.lo, b.hi), (v(0.02, 0.02, 0.05), v(0.18, 0.12, 0.05)));
        assert!((b.diag - (0.16f64.powi(2) + 0.1f64.powi(2)).sqrt()).abs() < 1e-15);
        let point = TriMesh::new(vec![v(1., 1., 1.); 3], vec![[0, 1, 2]]);
        assert!(Bounds::of(&point).is_err());
        // Unpadded: 0.16 × 0.1 × 0 m in 0.1 m cells; the flat z side still gets one cell.
        let g = Grid::fit(&b, 0.0, &cell(0.1)).unwrap();
        assert_eq!(
            (g.lo, g.h, g.dims, g.eps),
            (b.lo, 0.1, [2, 1, 1], 1e-9 * 0.1)
        );
        // Padded by 0.05 m: 0.26 × 0.2 × 0.1 m.
        let g = Grid::fit(&b, 0.05, &cell(0.1)).unwrap();
        assert_eq!(g.dims, [3, 2, 1]);
        assert_eq!(g.lo, v(0.02 - 0.05, 0.02 - 0.05, 0.0));
        // Target cell count: a unit cube in 8 cells has 0.5 m cells.
        let t = Bounds::of(&tetra()).unwrap();
        let s = LatticeSettings {
            target_cells: Some(8),
            ..Default::default()
        };
        let g = Grid::fit(&t, 0.0, &s).unwrap();
        assert_eq!((g.h, g.dims), (0.5, [2, 2, 2]));
        assert!(matches!(
            Grid::fit(&t, 0.0, &cell(1e-3)),
            Err(LatticeError::TooManyCells {
                cells: 1_000_000_000
            })
        ));
    }

    #[test]
    fn grid_cells_index_locate_and_neighbour() {
        let g = Grid {
            lo: v(-1., 0., 0.),
            h: 0.5,
            dims: [4, 3, 2],
            eps: 5e-10,
        };
        assert_eq!(g.cell_count(), 24);
        assert_eq!(g.index([3, 2, 1]), 23);
        assert!((0..24).all(|i| g.index(g.coord(i)) == i));
        assert_eq!(g.coord(5), [1, 1, 0]);
        assert_eq!(g.corner([1, 1, 1]), v(-0.5, 0.5, 0.5));
        assert_eq!(g.center([0, 0, 0]), v(-0.75, 0.25, 0.25));
        assert_eq!(g.node_position([0, 0, 0], -0.5), v(-1.25, -0.25, -0.25));
        assert_eq!(g.clamp_cell(&v(-0.9, 0.6, 0.4)), [0, 1, 0]);
        assert_eq!(g.clamp_cell(&v(-5., 5., -5.)), [0, 2, 0]);
        assert_eq!(g.face_neighbours([0, 0, 0]).len(), 3);
        assert_eq!(
            g.face_neighbours([1, 1, 0]),
            vec![[0, 1, 0], [2, 1, 0], [1, 0, 0], [1, 2, 0], [1, 1, 1]]
        );
    }
}
