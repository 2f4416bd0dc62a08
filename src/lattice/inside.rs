//! Inside/outside and depth classification of points against the embedded surface.
//!
//! - Closed meshes (every edge shared by exactly two triangles): a point is flesh when its
//!   generalised winding number (Jacobson et al. 2013) exceeds ½.
//! - Open meshes (a face mask): the winding number of a point just behind an open sheet is
//!   about +½ and just in front about −½ (it jumps by exactly 1 across the sheet), so its sign
//!   tells behind from in front robustly even near holes, where the local normal of the
//!   nearest triangle is ambiguous. A point is flesh when it is behind (w > 0) and within the
//!   flesh depth of the surface; it is bone (pinned) when it is behind and deeper than that.
//!
//! Winding numbers are summed exactly over triangles bucketed in the 3×3×3 cells around the
//! query and with a dipole (area-vector) far-field approximation for the other cells
//! (a one-level Barnes–Hut; error ~ (cluster size / distance)² per cluster, far below the
//! ½ margin the decisions use).

use super::geom::{closest_point_on_triangle, solid_angle};
use crate::mesh::TriMesh;
use nalgebra::Vector3;

type V = Vector3<f64>;

struct Cluster {
    cell: [i64; 3],
    tris: Vec<usize>,
    centroid: V,
    area_vec: V,
}

/// Point classification against one mesh on one lattice grid.
pub(crate) struct InsideTest<'a> {
    mesh: &'a TriMesh,
    lo: V,
    h: f64,
    dims: [usize; 3],
    /// Triangles overlapping each cell (flat cell index).
    cell_tris: &'a [Vec<usize>],
    /// Bounding box of the triangles of each cell (for distance pruning).
    cell_box: Vec<Option<(V, V)>>,
    clusters: Vec<Cluster>,
    /// Whether the mesh is closed (winding threshold ½) or open (sign and depth).
    pub closed: bool,
    /// Flesh depth behind an open surface (m).
    pub depth: f64,
}

impl<'a> InsideTest<'a> {
    pub fn new(
        mesh: &'a TriMesh,
        lo: V,
        h: f64,
        dims: [usize; 3],
        cell_tris: &'a [Vec<usize>],
        closed: bool,
        depth: f64,
    ) -> Self {
        let p = &mesh.positions;
        let cell_box = cell_tris
            .iter()
            .map(|ts| {
                let mut it = ts
                    .iter()
                    .flat_map(|&t| mesh.triangles[t].iter().map(|&v| p[v]));
                let first = it.next()?;
                Some(it.fold((first, first), |(a, b), q| (a.inf(&q), b.sup(&q))))
            })
            .collect();
        let mut map: std::collections::HashMap<[i64; 3], usize> = Default::default();
        let mut clusters: Vec<Cluster> = Vec::new();
        for (t, &[a, b, c]) in mesh.triangles.iter().enumerate() {
            let cen = (p[a] + p[b] + p[c]) / 3.0;
            let cell = Self::cell_of(lo, h, &cen);
            let av = 0.5 * (p[b] - p[a]).cross(&(p[c] - p[a]));
            let k = *map.entry(cell).or_insert_with(|| {
                clusters.push(Cluster {
                    cell,
                    tris: Vec::new(),
                    centroid: V::zeros(),
                    area_vec: V::zeros(),
                });
                clusters.len() - 1
            });
            let cl = &mut clusters[k];
            cl.tris.push(t);
            let w = av.norm();
            cl.centroid += cen * w;
            cl.area_vec += av;
        }
        for cl in &mut clusters {
            let wsum: f64 = cl.tris.iter().map(|&t| mesh.triangle_area(t)).sum();
            if wsum > 0.0 {
                cl.centroid /= wsum;
            } else {
                let t = mesh.triangles[cl.tris[0]];
                cl.centroid = (p[t[0]] + p[t[1]] + p[t[2]]) / 3.0;
            }
        }
        Self {
            mesh,
            lo,
            h,
            dims,
            cell_tris,
            cell_box,
            clusters,
            closed,
            depth,
        }
    }

    fn cell_of(lo: V, h: f64, p: &V) -> [i64; 3] {
        let r = (p - lo) / h;
        [r.x.floor() as i64, r.y.floor() as i64, r.z.floor() as i64]
    }

    /// Generalised winding number of the surface at `p` (1 inside a closed outward surface).
    pub fn winding(&self, p: &V) -> f64 {
        let c = Self::cell_of(self.lo, self.h, p);
        let pos = &self.mesh.positions;
        let mut omega = 0.0;
        for cl in &self.clusters {
            let near = (0..3).all(|d| (cl.cell[d] - c[d]).abs() <= 1);
            if near {
                for &t in &cl.tris {
                    let [a, b, cc] = self.mesh.triangles[t];
                    omega += solid_angle(p, &pos[a], &pos[b], &pos[cc]);
                }
            } else {
                let r = cl.centroid - p;
                let d = r.norm();
                omega += cl.area_vec.dot(&r) / (d * d * d);
            }
        }
        omega / (4.0 * std::f64::consts::PI)
    }

    /// Distance (m) from `p` to the surface if it is at most `max`, else `f64::INFINITY`.
    pub fn distance_within(&self, p: &V, max: f64) -> f64 {
        let c = Self::cell_of(self.lo, self.h, p);
        let reach = (max / self.h).ceil() as i64 + 1;
        let mut best = f64::INFINITY;
        let pos = &self.mesh.positions;
        let [nx, ny, nz] = self.dims.map(|d| d as i64);
        for ring in 0..=reach {
            // Every cell of ring k is at least (k − 1)·h away from p.
            if (ring - 1) as f64 * self.h > best.min(max) {
                break;
            }
            for k in (c[2] - ring).max(0)..=(c[2] + ring).min(nz - 1) {
                for j in (c[1] - ring).max(0)..=(c[1] + ring).min(ny - 1) {
                    for i in (c[0] - ring).max(0)..=(c[0] + ring).min(nx - 1) {
                        let cheb = (i - c[0]).abs().max((j - c[1]).abs()).max((k - c[2]).abs());
                        if cheb != ring {
                            continue;
                        }
                        let cell = (i + nx * (j + ny * k)) as usize;
                        let Some((blo, bhi)) = &self.cell_box[cell] else {
                            continue;
                        };
                        let q = p.sup(blo).inf(bhi);
                        if (q - p).norm() >= best {
                            continue;
                        }
                        for &t in &self.cell_tris[cell] {
                            let [a, b, cc] = self.mesh.triangles[t];
                            let q = closest_point_on_triangle(p, &pos[a], &pos[b], &pos[cc]);
                            best = best.min((q - p).norm());
                        }
                    }
                }
            }
        }
        if best <= max {
            best
        } else {
            f64::INFINITY
        }
    }

    /// Is `p` in the simulated flesh (see the module notes)?
    pub fn is_flesh(&self, p: &V) -> bool {
        if self.closed {
            self.winding(p) > 0.5
        } else {
            self.distance_within(p, self.depth).is_finite() && self.winding(p) > 0.0
        }
    }

    /// Is `p` bone: behind an open surface and deeper than the flesh depth? Never for closed
    /// meshes.
    pub fn is_bone(&self, p: &V) -> bool {
        !self.closed && self.distance_within(p, self.depth).is_infinite() && self.winding(p) > 0.0
    }
}
