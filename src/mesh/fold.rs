//! Folds of a morphing surface: the dihedral turn between adjacent triangles (the angle
//! between their normals, 0 for a flat pair, 180° for a pair folded flat onto itself) on the
//! mesh welded by position, so a surface split at texture seams or into primitives counts as
//! the one surface it shows.
//!
//! A blend shape folds the surface where some turn grows past a threshold (150° here by
//! default): a lip rolled in over itself, lips or lids pressed together so that their margins
//! tuck in. [`WeldedSurface::folds`] measures that per shape against rest: the largest turn
//! among the edges the shape changes, the largest growth of an edge's turn, and how many
//! edges pass the threshold at the shape's weight that did not at rest.

use super::grid::PointGrid;
use nalgebra::Vector3;
use std::collections::BTreeMap;

/// The turn (deg) past which an edge counts as folded.
pub const FOLD_DEG: f64 = 150.0;

/// Twice the area (m²) under which a triangle is taken as degenerate and has no normal.
const DEGENERATE: f64 = 1e-16;

/// For each vertex, the first vertex (by index) within `tol` m of it: its representative on
/// the mesh welded by position (a representative is its own).
pub fn weld_by_position(positions: &[Vector3<f64>], tol: f64) -> Vec<usize> {
    let mut grid = PointGrid::new(tol, std::iter::empty());
    let mut rep = Vec::with_capacity(positions.len());
    for (i, p) in positions.iter().enumerate() {
        let found = grid
            .near(p)
            .filter(|&j| (positions[j] - p).norm() <= tol)
            .min();
        match found {
            Some(j) => rep.push(j),
            None => {
                grid.insert(i, p);
                rep.push(i);
            }
        }
    }
    rep
}

/// What a shape does to the folds of a surface.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Folds {
    /// The largest turn with the shape applied among the edges whose turn it changes, deg
    /// (0 when it changes none).
    pub max_turn_deg: f64,
    /// The largest growth of an edge's turn against rest, deg.
    pub max_gain_deg: f64,
    /// The largest turn anywhere at rest, deg.
    pub rest_max_turn_deg: f64,
    /// Edges whose turn passes the threshold with the shape applied and not at rest.
    pub edges_past: usize,
}

/// A triangle surface welded by position: its triangles on representative vertices and its
/// interior edges (each shared by exactly two triangles).
#[derive(Debug, Clone)]
pub struct WeldedSurface {
    /// Each vertex's representative ([`weld_by_position`]).
    pub representative: Vec<usize>,
    /// Triangles on representatives (triangles that collapse under the weld are dropped).
    pub triangles: Vec<[usize; 3]>,
    /// Interior edges: the two triangles (indices into `triangles`) on each.
    pub edges: Vec<(usize, usize)>,
}

impl WeldedSurface {
    /// The surface of `triangles` over `positions` (m) welded within `tol` m.
    pub fn new(positions: &[Vector3<f64>], triangles: &[[usize; 3]], tol: f64) -> Self {
        let representative = weld_by_position(positions, tol);
        let triangles: Vec<[usize; 3]> = triangles
            .iter()
            .map(|t| t.map(|v| representative[v]))
            .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
            .collect();
        let mut on_edge: BTreeMap<(usize, usize), Vec<usize>> = BTreeMap::new();
        for (ti, t) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                on_edge.entry((a.min(b), a.max(b))).or_default().push(ti);
            }
        }
        let edges = on_edge
            .values()
            .filter(|ts| ts.len() == 2)
            .map(|ts| (ts[0], ts[1]))
            .collect();
        Self {
            representative,
            triangles,
            edges,
        }
    }

    /// The turn (rad) at each interior edge for vertex positions `positions` (m, the unwelded
    /// vertex order); `None` where a triangle on the edge is degenerate.
    pub fn turns(&self, positions: &[Vector3<f64>]) -> Vec<Option<f64>> {
        let normals: Vec<Option<Vector3<f64>>> = self
            .triangles
            .iter()
            .map(|&[a, b, c]| {
                let n = (positions[b] - positions[a]).cross(&(positions[c] - positions[a]));
                (n.norm() > DEGENERATE).then(|| n.normalize())
            })
            .collect();
        self.edges
            .iter()
            .map(|&(s, t)| {
                let (a, b) = (normals[s]?, normals[t]?);
                Some(a.dot(&b).clamp(-1.0, 1.0).acos())
            })
            .collect()
    }

    /// The folds of shape `deltas` (m, one per vertex) at `weight` on rest positions `rest`
    /// (m), against threshold `threshold_deg` (deg).
    pub fn folds(
        &self,
        rest: &[Vector3<f64>],
        deltas: &[Vector3<f64>],
        weight: f64,
        threshold_deg: f64,
    ) -> Folds {
        let moved: Vec<Vector3<f64>> = rest
            .iter()
            .zip(deltas)
            .map(|(p, d)| p + d * weight)
            .collect();
        let (r, m) = (self.turns(rest), self.turns(&moved));
        let limit = threshold_deg.to_radians();
        let mut f = Folds {
            max_turn_deg: 0.0,
            max_gain_deg: 0.0,
            rest_max_turn_deg: 0.0,
            edges_past: 0,
        };
        for (r, m) in r.iter().zip(&m) {
            let (r0, m0) = (r.unwrap_or(0.0), m.unwrap_or(0.0));
            f.rest_max_turn_deg = f.rest_max_turn_deg.max(r0.to_degrees());
            if (m0 - r0).abs() > 1e-9 {
                f.max_turn_deg = f.max_turn_deg.max(m0.to_degrees());
                f.max_gain_deg = f.max_gain_deg.max((m0 - r0).to_degrees());
            }
            if m0 > limit && r0 <= limit {
                f.edges_past += 1;
            }
        }
        f
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two squares side by side, the right one split from the left along the shared edge
    /// (duplicate vertices): welded they are one strip; folding the right square up by 160°
    /// turns the two triangles on the middle edge 160° apart and no other edge.
    #[test]
    fn a_hinged_strip_folds_at_its_hinge_only_after_welding() {
        let p = |x: f64, y: f64| Vector3::new(x, y, 0.0);
        let positions = vec![
            p(0.0, 0.0),
            p(1.0, 0.0),
            p(1.0, 1.0),
            p(0.0, 1.0),
            p(1.0, 0.0),
            p(2.0, 0.0),
            p(2.0, 1.0),
            p(1.0, 1.0),
        ];
        let triangles = vec![[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]];
        let s = WeldedSurface::new(&positions, &triangles, 1e-9);
        assert_eq!(s.representative[4], 1);
        assert_eq!(s.representative[7], 2);
        // Edges 0-2, 1-2 (the hinge) and 1-6.
        assert_eq!(s.edges.len(), 3);
        let a = 160f64.to_radians();
        let mut deltas = vec![Vector3::zeros(); 8];
        for v in [5, 6] {
            let q = positions[v];
            let folded = Vector3::new(1.0 + (q.x - 1.0) * a.cos(), q.y, (q.x - 1.0) * a.sin());
            deltas[v] = folded - q;
        }
        let f = s.folds(&positions, &deltas, 1.0, FOLD_DEG);
        assert!((f.max_turn_deg - 160.0).abs() < 1e-9, "{f:?}");
        assert!((f.max_gain_deg - 160.0).abs() < 1e-9, "{f:?}");
        assert_eq!(f.rest_max_turn_deg, 0.0);
        assert_eq!(f.edges_past, 1);
        let half = s.folds(&positions, &deltas, 0.5, FOLD_DEG);
        assert_eq!(half.edges_past, 0);
    }
}
