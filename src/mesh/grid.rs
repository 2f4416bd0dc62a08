//! A uniform grid over points, for neighbour queries: the points hashed into the 27 cells
//! about a place hold every point within one cell size of it.

use nalgebra::Vector3;
use std::collections::HashMap;

/// Points (by index) hashed on a uniform grid of cubes `cell` (m) wide.
pub struct PointGrid {
    cell: f64,
    cells: HashMap<[i64; 3], Vec<usize>>,
}

impl PointGrid {
    /// The grid of cell size `cell` (m, floored at 1e-12) over `points` (index, position m).
    pub fn new(cell: f64, points: impl IntoIterator<Item = (usize, Vector3<f64>)>) -> Self {
        let mut grid = Self {
            cell: cell.max(1e-12),
            cells: HashMap::new(),
        };
        for (i, p) in points {
            grid.insert(i, &p);
        }
        grid
    }

    /// Add point `i` at `p` (m); [`Self::near`] lists a cell's points in insertion order.
    pub fn insert(&mut self, i: usize, p: &Vector3<f64>) {
        let k = self.key(p);
        self.cells.entry(k).or_default().push(i);
    }

    fn key(&self, p: &Vector3<f64>) -> [i64; 3] {
        [0, 1, 2].map(|d| (p[d] / self.cell).floor() as i64)
    }

    /// The points in the 27 cells about `p` (m): a superset of those within one cell size,
    /// cell by cell in a fixed order (x slowest, z fastest), each cell's in insertion order.
    pub fn near(&self, p: &Vector3<f64>) -> impl Iterator<Item = usize> + '_ {
        let k = self.key(p);
        (0..27i64).flat_map(move |d| {
            let c = [k[0] + d / 9 - 1, k[1] + (d / 3) % 3 - 1, k[2] + d % 3 - 1];
            self.cells.get(&c).into_iter().flatten().copied()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every point within one cell size is near, across cell borders and negative
    /// coordinates; a point two cells away is not.
    #[test]
    fn points_within_a_cell_are_near() {
        let pts = [
            Vector3::new(-0.05, 0.0, 0.0),
            Vector3::new(0.04, 0.09, -0.09),
            Vector3::new(0.25, 0.0, 0.0),
        ];
        let grid = PointGrid::new(0.1, pts.iter().copied().enumerate());
        let mut near: Vec<usize> = grid.near(&Vector3::new(0.0, 0.0, 0.0)).collect();
        near.sort_unstable();
        assert_eq!(near, vec![0, 1]);
    }
}
