//! Self-intersection of a deformed triangle mesh: whether some edge passes through a triangle
//! it does not touch. furrow's skin has no contact, so a solve that ends with the skin through
//! itself is reported as such rather than as converged.
//!
//! Triangles are binned by their bounding boxes on a uniform grid (cell about the mean
//! edge; a sorted list of (cell, triangle), in parallel); pairs sharing a cell and no vertex
//! are tested edge against triangle
//! (Möller–Trumbore). Pairs sharing a vertex are not judged (adjacent triangles touch by
//! construction), nor crossings within [`MARGIN`] of the triangle's border or the edge's ends:
//! two pieces of skin a hair apart (a seam left by degenerate triangles that are not simulated)
//! graze each other there without the skin passing through itself.

use super::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;

type V3 = Vector3<f64>;

/// Crossings closer than this fraction of the triangle (barycentric) or of the edge (its
/// parameter) to their borders are grazing, not passing through.
pub const MARGIN: f64 = 1e-2;

/// The first pair of triangles of `mesh` (topology) at positions `x` (flat, m) that pass
/// through each other (in the order of the grid's cell keys), or `None`.
pub fn first_self_intersection(mesh: &TriMesh, x: &[f64]) -> Option<(usize, usize)> {
    first_self_intersection_beyond(mesh, x, None)
}

/// [`first_self_intersection`] of positions `x`, leaving out pairs that also pass through
/// each other at the `reference` positions (flat, m) when given: the skin's own crossings,
/// not those of the surface it is embedded on (the interior's B q, whose closed lips cross
/// by its miss of the artist's shape).
pub fn first_self_intersection_beyond(
    mesh: &TriMesh,
    x: &[f64],
    reference: Option<&[f64]>,
) -> Option<(usize, usize)> {
    let scan = CellScan::new(mesh, x)?;
    scan.starts.par_windows(2).find_map_first(|w| {
        scan.crossing_in(&scan.entries[w[0]..w[1]], reference)
            .into_iter()
            .next()
    })
}

/// Every pair of triangles of `mesh` (topology) at positions `x` (flat, m) that pass through
/// each other, leaving out pairs that also do at the `reference` positions when given; each
/// pair once, smaller triangle first, sorted.
pub fn self_intersections_beyond(
    mesh: &TriMesh,
    x: &[f64],
    reference: Option<&[f64]>,
) -> Vec<(usize, usize)> {
    let Some(scan) = CellScan::new(mesh, x) else {
        return Vec::new();
    };
    let mut pairs: Vec<(usize, usize)> = scan
        .starts
        .par_windows(2)
        .flat_map_iter(|w| scan.crossing_in(&scan.entries[w[0]..w[1]], reference))
        .collect();
    pairs.par_sort_unstable();
    pairs.dedup();
    pairs
}

/// Triangles binned by their bounding boxes on a uniform grid: the candidate pairs of a
/// self-intersection test.
struct CellScan<'a> {
    tris: &'a [[usize; 3]],
    x: &'a [f64],
    boxes: Vec<(V3, V3)>,
    /// (cell key, triangle), sorted by key: each run of one key is a cell's list (hash
    /// collisions only add candidate pairs).
    entries: Vec<(u64, u32)>,
    /// Where each run of `entries` starts, and its end.
    starts: Vec<usize>,
}

impl<'a> CellScan<'a> {
    /// The grid of `mesh`'s triangles at `x` (cell half the mean edge); `None` without
    /// triangles.
    fn new(mesh: &'a TriMesh, x: &'a [f64]) -> Option<Self> {
        let tris = &mesh.triangles;
        if tris.is_empty() {
            return None;
        }
        let p = |v: usize| V3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
        let edge_sum: f64 = tris
            .iter()
            .map(|t| (p(t[1]) - p(t[0])).norm() + (p(t[2]) - p(t[1])).norm())
            .sum();
        let cell = (0.5 * edge_sum / tris.len() as f64).max(1e-12);
        let boxes: Vec<(V3, V3)> = tris
            .par_iter()
            .map(|tri| {
                let pts = tri.map(p);
                (
                    pts[0].inf(&pts[1]).inf(&pts[2]),
                    pts[0].sup(&pts[1]).sup(&pts[2]),
                )
            })
            .collect();
        let mut entries: Vec<(u64, u32)> = boxes
            .par_iter()
            .enumerate()
            .flat_map_iter(|(t, &(lo, hi))| {
                let a = (lo / cell).map(|c| c.floor() as i64);
                let b = (hi / cell).map(|c| c.floor() as i64);
                (a.x..=b.x).flat_map(move |i| {
                    (a.y..=b.y)
                        .flat_map(move |j| (a.z..=b.z).map(move |k| (key(i, j, k), t as u32)))
                })
            })
            .collect();
        entries.par_sort_unstable();
        let mut starts: Vec<usize> = (0..entries.len())
            .filter(|&n| n == 0 || entries[n].0 != entries[n - 1].0)
            .collect();
        starts.push(entries.len());
        Some(Self {
            tris,
            x,
            boxes,
            entries,
            starts,
        })
    }

    /// The crossing pairs among one cell's triangles `run` (in the cell's order), leaving out
    /// those that also cross at `reference`.
    fn crossing_in(&self, run: &[(u64, u32)], reference: Option<&[f64]>) -> Vec<(usize, usize)> {
        let at = |x: &[f64], v: usize| V3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
        let cross = |x: &[f64], ts: [usize; 3], tt: [usize; 3]| {
            let (a, b) = (ts.map(|v| at(x, v)), tt.map(|v| at(x, v)));
            pierces(a, b) || pierces(b, a)
        };
        let mut found = Vec::new();
        for (n, &(_, s)) in run.iter().enumerate() {
            for &(_, t) in &run[n + 1..] {
                let (s, t) = (s as usize, t as usize);
                let ((a0, a1), (b0, b1)) = (self.boxes[s], self.boxes[t]);
                if (0..3).any(|c| a1[c] < b0[c] || b1[c] < a0[c]) {
                    continue;
                }
                let (ts, tt) = (self.tris[s], self.tris[t]);
                if ts.iter().any(|v| tt.contains(v)) {
                    continue;
                }
                if cross(self.x, ts, tt) && !reference.is_some_and(|r| cross(r, ts, tt)) {
                    found.push((s.min(t), s.max(t)));
                }
            }
        }
        found
    }
}

/// A hash of grid cell (i, j, k).
fn key(i: i64, j: i64, k: i64) -> u64 {
    (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (j as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
        ^ (k as u64).wrapping_mul(0x1656_67B1_9E37_79F9)
}

/// Whether an edge of triangle `a` passes through triangle `b`.
fn pierces(a: [V3; 3], b: [V3; 3]) -> bool {
    (0..3).any(|k| segment_hits(a[k], a[(k + 1) % 3], b))
}

/// Möller–Trumbore: the segment p → q meets the interior of triangle `t`, clear of both
/// borders by [`MARGIN`].
fn segment_hits(p: V3, q: V3, t: [V3; 3]) -> bool {
    let d = q - p;
    let (e1, e2) = (t[1] - t[0], t[2] - t[0]);
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    let scale = d.norm() * e1.norm() * e2.norm();
    if det.abs() <= 1e-12 * scale {
        return false; // parallel: coplanar contact is not judged
    }
    let f = 1.0 / det;
    let s = p - t[0];
    let u = f * s.dot(&h);
    if !(MARGIN..=1.0 - MARGIN).contains(&u) {
        return false;
    }
    let qv = s.cross(&e1);
    let v = f * d.dot(&qv);
    if v < MARGIN || u + v > 1.0 - MARGIN {
        return false;
    }
    let along = f * e2.dot(&qv);
    (MARGIN..=1.0 - MARGIN).contains(&along)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two separate triangles, then the second pushed through the first.
    fn two(z: f64) -> (TriMesh, Vec<f64>) {
        let pos = vec![
            V3::new(0.0, 0.0, 0.0),
            V3::new(1.0, 0.0, 0.0),
            V3::new(0.0, 1.0, 0.0),
            V3::new(0.2, 0.2, z),
            V3::new(0.2, 0.2, z - 1.0),
            V3::new(0.6, 0.2, z - 0.5),
        ];
        let x = pos.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        (TriMesh::new(pos, vec![[0, 1, 2], [3, 4, 5]]), x)
    }

    #[test]
    fn a_triangle_through_another_is_found_and_one_beside_it_is_not() {
        let (m, x) = two(0.5);
        assert_eq!(first_self_intersection(&m, &x), Some((0, 1)));
        let (m, x) = two(2.0);
        assert_eq!(first_self_intersection(&m, &x), None);
    }

    /// A crossing the reference surface has too is not the skin's own; one it has not is.
    #[test]
    fn a_crossing_inherited_from_the_reference_is_left_out() {
        let (m, through) = two(0.5);
        let (_, apart) = two(2.0);
        let (_, less_through) = two(0.4);
        assert_eq!(
            first_self_intersection_beyond(&m, &through, Some(&less_through)),
            None
        );
        assert_eq!(
            first_self_intersection_beyond(&m, &through, Some(&apart)),
            Some((0, 1))
        );
        assert_eq!(
            first_self_intersection_beyond(&m, &through, None),
            Some((0, 1))
        );
    }

    #[test]
    fn a_flat_sheet_and_its_fold_over_itself() {
        let (n, h) = (6usize, 0.1);
        let id = |i: usize, j: usize| j * (n + 1) + i;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                pos.push(V3::new(h * i as f64, h * j as f64, 0.0));
            }
        }
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let m = TriMesh::new(pos.clone(), tris);
        let flat: Vec<f64> = pos.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        assert_eq!(first_self_intersection(&m, &flat), None);
        // Fold the right half back over the left, dipping through it.
        let folded: Vec<f64> = pos
            .iter()
            .flat_map(|p| {
                if p.x <= 0.3 {
                    [p.x, p.y, 0.0]
                } else {
                    [0.6 - p.x, p.y, 0.02 - (p.x - 0.3) * (p.y - 0.3)]
                }
            })
            .collect();
        assert!(first_self_intersection(&m, &folded).is_some());
    }

    /// Two triangles a hair apart along a seam, one tilted so its edge grazes the other's
    /// border: not the skin through itself. Tilted further, it passes through.
    #[test]
    fn pieces_grazing_at_a_seam_are_not_an_intersection() {
        let tilted = |dip: f64| {
            let pos = vec![
                V3::new(0.0, 0.0, 0.0),
                V3::new(1.0, 0.0, 0.0),
                V3::new(0.0, 1.0, 0.0),
                V3::new(1.0 - 1e-4, 1e-4, 1e-3),
                V3::new(0.5, 0.5 - 1e-4, -1e-3),
                V3::new(1.0, 1.0, 0.0),
            ];
            let mut x: Vec<f64> = pos.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
            x[3 * 4] -= dip;
            x[3 * 4 + 1] -= dip;
            (TriMesh::new(pos, vec![[0, 1, 2], [3, 4, 5]]), x)
        };
        let (m, x) = tilted(0.0);
        assert_eq!(first_self_intersection(&m, &x), None);
        let (m, x) = tilted(0.2);
        assert_eq!(first_self_intersection(&m, &x), Some((0, 1)));
    }
}
