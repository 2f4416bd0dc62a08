//! The surface distance error of a run: each output vertex's distance to the reference
//! run's surface (point to nearest triangle, through a uniform grid over the triangles'
//! centroids), summed into RMS and max over vertices and frames.

use crate::lattice::geom::closest_point_on_triangle;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Distance from points to a triangle surface, with a uniform grid over triangle centroids.
pub struct SurfaceDistance<'a> {
    positions: &'a [Vector3<f64>],
    triangles: &'a [[usize; 3]],
    cell: f64,
    grid: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> SurfaceDistance<'a> {
    /// Index the surface (positions in m).
    pub fn new(positions: &'a [Vector3<f64>], triangles: &'a [[usize; 3]]) -> Self {
        let mut longest = 0.0f64;
        for t in triangles {
            for e in 0..3 {
                longest = longest.max((positions[t[e]] - positions[t[(e + 1) % 3]]).norm());
            }
        }
        let cell = longest.max(1e-12);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, t) in triangles.iter().enumerate() {
            let c = (positions[t[0]] + positions[t[1]] + positions[t[2]]) / 3.0;
            grid.entry(key(&c, cell)).or_default().push(i);
        }
        Self {
            positions,
            triangles,
            cell,
            grid,
        }
    }

    /// Distance from `p` to the nearest point of the surface (m); infinite for an empty
    /// surface.
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        if self.triangles.is_empty() {
            return f64::INFINITY;
        }
        let k = key(p, self.cell);
        let mut best = f64::INFINITY;
        // A triangle within distance d has its centroid within d + cell of p: ring r covers
        // centroids up to r·cell away.
        for r in 0i64.. {
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                            continue;
                        }
                        if let Some(ts) = self.grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            for &t in ts {
                                let [a, b, c] = self.triangles[t].map(|v| self.positions[v]);
                                let q = closest_point_on_triangle(p, &a, &b, &c);
                                best = best.min((q - p).norm());
                            }
                        }
                    }
                }
            }
            if (r as f64 - 1.0) * self.cell >= best || r > 1_000_000 {
                break;
            }
        }
        best
    }
}

/// The grid cell (side `cell`, m) holding point `p` (m).
pub(super) fn key(p: &Vector3<f64>, cell: f64) -> [i64; 3] {
    [0, 1, 2].map(|d| (p[d] / cell).floor() as i64)
}

/// Accumulates distances to a reference surface: (sum of squares, count, max).
#[derive(Debug, Clone, Copy, Default)]
pub(super) struct ErrorSum {
    /// Sum of squared distances (m²).
    sq: f64,
    /// Number of distances.
    n: usize,
    /// Largest distance (m).
    pub(super) max: f64,
}

impl ErrorSum {
    /// Add the distances of a frame's points `pts` (m) to the reference surface of
    /// `ref_pts` (m) and `tris`.
    pub(super) fn add_frame(
        &mut self,
        pts: &[Vector3<f64>],
        ref_pts: &[Vector3<f64>],
        tris: &[[usize; 3]],
    ) {
        let sd = SurfaceDistance::new(ref_pts, tris);
        for p in pts {
            let d = sd.distance(p);
            self.sq += d * d;
            self.n += 1;
            self.max = self.max.max(d);
        }
    }

    /// RMS of the distances (m); NaN when there are none.
    pub(super) fn rms(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            (self.sq / self.n as f64).sqrt()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_distance_matches_a_plane() {
        // A 10 × 10 grid in z = 0 over [0, 1]²; points above it at height d: distance d.
        let n = 10;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                pos.push(Vector3::new(i as f64 / n as f64, j as f64 / n as f64, 0.0));
            }
        }
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let id = |i: usize, j: usize| j * (n + 1) + i;
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let sd = SurfaceDistance::new(&pos, &tris);
        for (p, want) in [
            (Vector3::new(0.33, 0.71, 0.02), 0.02),
            (Vector3::new(0.5, 0.5, -0.3), 0.3),
            (Vector3::new(0.05, 0.95, 2.0), 2.0),
            // Outside the square: distance to the edge x = 1.
            (Vector3::new(1.4, 0.5, 0.3), 0.5),
        ] {
            let d = sd.distance(&p);
            assert!((d - want).abs() < 1e-12, "{p:?}: {d} vs {want}");
        }
    }
}
