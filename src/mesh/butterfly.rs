//! The modified butterfly rule (Zorin, Schröder and Sweldens 1996): where an interpolating
//! subdivision puts the new vertex of an edge, as weights over the vertices around it. Old
//! vertices never move, so the refined surface passes through the coarse one; new vertices
//! move off the flat triangles towards a smooth surface (C¹ for every valence).
//!
//! - both ends regular (valence 6, interior): the 10-point stencil ½ (a + b) + ⅛ (c + d) −
//!   1⁄16 (the four wings);
//! - an interior end of valence k ≠ 6: its own stencil ¾ v + Σ s_j r_j over its ring (r_0 the
//!   edge's other end; k = 3: 5⁄12, −1⁄12, −1⁄12; k = 4: ⅜, 0, −⅛, 0; k ≥ 5:
//!   s_j = (¼ + cos 2πj/k + ½ cos 4πj/k) / k); two such ends: the mean of both;
//! - one end interior and the other on the boundary: the interior end's stencil;
//! - a boundary edge: the four-point rule 9⁄16 (a + b) − 1⁄16 (a′ + b′) along the boundary,
//!   where a corner of the boundary (it turns by more than [`CORNER_TURN`] there) stands for
//!   its missing neighbour by reflection, a′ = 2a − b, so corners stay sharp (a mouth's
//!   corners, a sheet's) and an edge between two corners gets its midpoint;
//! - otherwise (an interior edge between two boundary vertices, non-manifold edges or
//!   vertices): no stencil, and the caller takes the midpoint.
//!
//! Every stencil's weights sum to one, so it is affine: a flat mesh stays flat.

use nalgebra::Vector3;
use std::collections::HashMap;

/// Turning angle of a boundary (rad) beyond which a boundary vertex is a corner: 45°.
pub const CORNER_TURN: f64 = std::f64::consts::FRAC_PI_4;

/// The ordered neighbours of a vertex (its link), when the triangles around it form one fan.
#[derive(Debug, Clone, PartialEq)]
pub enum Ring {
    /// An interior vertex: the neighbours in order around it (a closed loop).
    Closed(Vec<usize>),
    /// A boundary vertex: the neighbours in order from one boundary neighbour to the other.
    Open(Vec<usize>),
    /// Several fans meet at the vertex, or an edge at it has more than two triangles.
    NonManifold,
}

/// The rings of every vertex of a triangle mesh and how many triangles each edge has.
#[derive(Debug, Clone)]
pub struct Rings {
    /// Ring of each vertex.
    pub ring: Vec<Ring>,
    /// Triangles per undirected edge `(min, max)`.
    pub edge_triangles: HashMap<(usize, usize), usize>,
    /// Per vertex: a corner of the boundary (see [`CORNER_TURN`]).
    pub corner: Vec<bool>,
}

impl Rings {
    /// The rings of the vertices at `positions` (m) of the mesh with `triangles` (any
    /// winding).
    pub fn new(positions: &[Vector3<f64>], triangles: &[[usize; 3]]) -> Self {
        let mut link: Vec<Vec<[usize; 2]>> = vec![Vec::new(); positions.len()];
        let mut edge_triangles = HashMap::new();
        for t in triangles {
            for k in 0..3 {
                let (v, a, b) = (t[k], t[(k + 1) % 3], t[(k + 2) % 3]);
                link[v].push([a, b]);
                *edge_triangles.entry((v.min(a), v.max(a))).or_insert(0) += 1;
            }
        }
        let ring: Vec<Ring> = link.iter().map(|l| order_link(l)).collect();
        let cos_turn = CORNER_TURN.cos();
        let corner = ring
            .iter()
            .enumerate()
            .map(|(v, r)| match r {
                Ring::Open(r) => {
                    let p = |i: usize| positions[i];
                    let into = (p(v) - p(r[0])).try_normalize(0.0);
                    let out = (p(r[r.len() - 1]) - p(v)).try_normalize(0.0);
                    into.zip(out).is_none_or(|(i, o)| i.dot(&o) < cos_turn)
                }
                _ => false,
            })
            .collect();
        Self {
            ring,
            edge_triangles,
            corner,
        }
    }

    /// Triangles on the edge (a, b) (0 when it is no edge).
    pub fn triangles_on(&self, a: usize, b: usize) -> usize {
        self.edge_triangles
            .get(&(a.min(b), a.max(b)))
            .copied()
            .unwrap_or(0)
    }

    /// The butterfly stencil of the new vertex on edge (a, b): (vertex, weight) pairs summing
    /// to one, or `None` where no rule applies (the caller takes the midpoint).
    pub fn stencil(&self, a: usize, b: usize) -> Option<Vec<(usize, f64)>> {
        match self.triangles_on(a, b) {
            1 => self.boundary_stencil(a, b),
            2 => self.interior_stencil(a, b),
            _ => None,
        }
    }

    /// The four-point rule along the boundary through a and b (a corner reflected).
    fn boundary_stencil(&self, a: usize, b: usize) -> Option<Vec<(usize, f64)>> {
        let other_end = |v: usize, w: usize| match &self.ring[v] {
            Ring::Open(r) if r.len() >= 2 && r[0] == w => Some(r[r.len() - 1]),
            Ring::Open(r) if r.len() >= 2 && r[r.len() - 1] == w => Some(r[0]),
            _ => None,
        };
        let mut s = vec![(a, 9.0 / 16.0), (b, 9.0 / 16.0)];
        for (v, w) in [(a, b), (b, a)] {
            let beyond = other_end(v, w)?;
            if self.corner[v] {
                // −1⁄16 (2v − w)
                s.extend([(v, -2.0 / 16.0), (w, 1.0 / 16.0)]);
            } else if beyond == w {
                return None;
            } else {
                s.push((beyond, -1.0 / 16.0));
            }
        }
        Some(s)
    }

    /// The rules of an interior edge (two triangles).
    fn interior_stencil(&self, a: usize, b: usize) -> Option<Vec<(usize, f64)>> {
        let ra = self.closed_from(a, b);
        let rb = self.closed_from(b, a);
        match (ra, rb) {
            (Some(ra), Some(rb)) if ra.len() == 6 && rb.len() == 6 => {
                let mut s = vec![(a, 0.5), (b, 0.5), (ra[1], 0.125), (ra[5], 0.125)];
                s.extend([ra[2], ra[4], rb[2], rb[4]].map(|w| (w, -1.0 / 16.0)));
                Some(s)
            }
            (Some(ra), Some(rb)) if ra.len() == 6 => Some(vertex_stencil(b, &rb)),
            (Some(ra), Some(rb)) if rb.len() == 6 => Some(vertex_stencil(a, &ra)),
            (Some(ra), Some(rb)) => {
                let mut s = vertex_stencil(a, &ra);
                s.extend(vertex_stencil(b, &rb));
                s.iter_mut().for_each(|p| p.1 *= 0.5);
                Some(s)
            }
            (Some(ra), None) => Some(vertex_stencil(a, &ra)),
            (None, Some(rb)) => Some(vertex_stencil(b, &rb)),
            (None, None) => None,
        }
    }

    /// The closed ring of `v` rotated to start at `w`, when `v` is interior.
    fn closed_from(&self, v: usize, w: usize) -> Option<Vec<usize>> {
        let Ring::Closed(r) = &self.ring[v] else {
            return None;
        };
        let i = r.iter().position(|&x| x == w)?;
        Some(r[i..].iter().chain(&r[..i]).copied().collect())
    }
}

/// The stencil of an interior vertex `v` of valence k = ring.len() for the edge to ring[0]:
/// ¾ v + Σ s_j ring[j] (module notes).
fn vertex_stencil(v: usize, ring: &[usize]) -> Vec<(usize, f64)> {
    let k = ring.len();
    let s: Vec<f64> = match k {
        3 => vec![5.0 / 12.0, -1.0 / 12.0, -1.0 / 12.0],
        4 => vec![3.0 / 8.0, 0.0, -1.0 / 8.0, 0.0],
        _ => (0..k)
            .map(|j| {
                let x = 2.0 * std::f64::consts::PI * j as f64 / k as f64;
                (0.25 + x.cos() + 0.5 * (2.0 * x).cos()) / k as f64
            })
            .collect(),
    };
    std::iter::once((v, 0.75))
        .chain(ring.iter().copied().zip(s))
        .filter(|p| p.1 != 0.0)
        .collect()
}

/// Order a vertex's link (one [neighbour, neighbour] pair per triangle around it) into a
/// ring: one cycle (interior), one path (boundary), else non-manifold.
fn order_link(link: &[[usize; 2]]) -> Ring {
    if link.is_empty() {
        return Ring::NonManifold;
    }
    let mut adj: HashMap<usize, Vec<usize>> = HashMap::new();
    for &[a, b] in link {
        if a == b {
            return Ring::NonManifold;
        }
        adj.entry(a).or_default().push(b);
        adj.entry(b).or_default().push(a);
    }
    if adj.values().any(|n| n.len() > 2) {
        return Ring::NonManifold;
    }
    let ends: Vec<usize> = {
        let mut e: Vec<usize> = adj
            .iter()
            .filter(|(_, n)| n.len() == 1)
            .map(|(&v, _)| v)
            .collect();
        e.sort_unstable();
        e
    };
    let start = match ends.len() {
        0 => link[0][0],
        2 => ends[0],
        _ => return Ring::NonManifold,
    };
    let mut order = vec![start];
    let mut prev = usize::MAX;
    let mut cur = start;
    loop {
        let next = adj[&cur].iter().copied().find(|&n| n != prev);
        match next {
            Some(n) if n != start && !order.contains(&n) => {
                order.push(n);
                prev = cur;
                cur = n;
            }
            _ => break,
        }
        // A path's far end has one neighbour: stop there.
        if adj[&cur].len() == 1 {
            break;
        }
    }
    if order.len() != adj.len() {
        return Ring::NonManifold; // more than one fan
    }
    if ends.is_empty() && order.len() < 3 {
        Ring::NonManifold // two triangles on the same three vertices
    } else if ends.is_empty() {
        Ring::Closed(order)
    } else {
        Ring::Open(order)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hexagon fan: vertex 0 in the middle, 1..=6 around it.
    fn hexagon() -> Vec<[usize; 3]> {
        (0..6).map(|i| [0, 1 + i, 1 + (i + 1) % 6]).collect()
    }

    /// The hexagon's positions (m): the centre, then the rim at unit distance.
    fn hexagon_at() -> Vec<Vector3<f64>> {
        std::iter::once(Vector3::zeros())
            .chain((0..6).map(|i| {
                let a = std::f64::consts::PI / 3.0 * i as f64;
                Vector3::new(a.cos(), a.sin(), 0.0)
            }))
            .collect()
    }

    #[test]
    fn rings_of_a_fan_are_closed_in_the_middle_and_open_on_the_rim() {
        let r = Rings::new(&hexagon_at(), &hexagon());
        assert_eq!(r.ring[0], Ring::Closed(vec![1, 2, 3, 4, 5, 6]));
        assert_eq!(r.ring[1], Ring::Open(vec![2, 0, 6]));
        assert_eq!(r.triangles_on(0, 3), 2);
        assert_eq!(r.triangles_on(2, 3), 1);
        // Two fans sharing one vertex (a bow tie) are non-manifold there.
        let bow = Rings::new(&hexagon_at()[..5], &[[0, 1, 2], [0, 3, 4]]);
        assert_eq!(bow.ring[0], Ring::NonManifold);
    }

    #[test]
    fn every_stencil_sums_to_one() {
        for k in 3..=9 {
            let ring: Vec<usize> = (1..=k).collect();
            let s = vertex_stencil(0, &ring);
            let sum: f64 = s.iter().map(|p| p.1).sum();
            assert!((sum - 1.0).abs() < 1e-14, "valence {k}: {sum}");
        }
        let r = Rings::new(&hexagon_at(), &hexagon());
        // Centre (valence 6) to rim (boundary): the centre's stencil.
        let s = r.stencil(0, 1).unwrap();
        assert!((s.iter().map(|p| p.1).sum::<f64>() - 1.0).abs() < 1e-14);
        assert_eq!(s[0], (0, 0.75));
        // A rim edge: the four-point rule (the rim turns by 60° at every vertex: corners,
        // so the midpoint); on a finer rim (a 12-gon, 30°) the neighbours; no non-edges.
        let b = r.stencil(1, 2).unwrap();
        let sum = |v: usize| b.iter().filter(|p| p.0 == v).map(|p| p.1).sum::<f64>();
        assert_eq!((sum(1), sum(2), b.len()), (0.5, 0.5, 6));
        assert!(r.stencil(1, 4).is_none());
        let n = 12;
        let rim: Vec<[usize; 3]> = (0..n).map(|i| [0, 1 + i, 1 + (i + 1) % n]).collect();
        let at: Vec<Vector3<f64>> = std::iter::once(Vector3::zeros())
            .chain((0..n).map(|i| {
                let a = 2.0 * std::f64::consts::PI / n as f64 * i as f64;
                Vector3::new(a.cos(), a.sin(), 0.0)
            }))
            .collect();
        let r12 = Rings::new(&at, &rim);
        assert!(!r12.corner[1]);
        let b = r12.stencil(1, 2).unwrap();
        assert_eq!(
            b,
            vec![(1, 0.5625), (2, 0.5625), (12, -0.0625), (3, -0.0625)]
        );
    }
}
