//! Local refinement of a triangle mesh with a conforming transition (red-green refinement):
//! the triangles of a region are split 1-to-4 ("red") a given number of levels, a band of
//! triangles around it is split fewer times (one level less per ring of vertices), and the
//! triangles beside the band that have new vertices on their edges are closed by "green"
//! splits, 1-to-2 (one such edge) or 1-to-3 (two; the quad is cut along its shorter
//! diagonal), or red with the existing midpoints (three). A green triangle is never split
//! further: refinement happens level by level on the red triangles of each coarse triangle,
//! and the closure runs once at the end, so the mesh has no T-junctions. The rest of the
//! mesh is left as it was.
//!
//! The new vertices are placed by one linear operator S (rows of weights over the coarse
//! vertices): with [`Smoothing::Butterfly`] by the interpolating modified butterfly rule
//! ([`super::butterfly`]), faded to the plain midpoint across the band (the fade τ is 1 on
//! the region's vertices and falls linearly to 0 over the band's rings of vertices), so the
//! coarse triangles beyond the band, and their green closures, stay exactly flat; with
//! [`Smoothing::Midpoint`] every new vertex is an edge midpoint. Where the smoothing would
//! fold the surface (a child triangle turned over against its parent, as near slivers of a
//! distorted mesh) or a parent is degenerate, its new vertices fall back to midpoints. Coarse
//! vertices keep their positions and indices and come first.
//!
//! Each refined triangle also knows its ancestor ([`Ancestor`]): the coarse triangle it lies
//! in and its corners' barycentric coordinates there, as midpoint subdivision would put them
//! (the flat position), which is what surface data (UVs, thickness, skin weights) follows.

use super::butterfly::Rings;
use super::quality::triangle_quality;
use super::TriMesh;
use nalgebra::Vector3;
use std::collections::{HashMap, VecDeque};

/// Where a refined triangle lies in the unrefined mesh: its ancestor triangle and the
/// barycentric coordinates of its three corners in it (in the ancestor's corner order). Data
/// that lives on the surface rather than moving with the shapes (UVs, thickness, skin
/// weights, which element a vertex embeds in) follows these, not the subdivision weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ancestor {
    /// The unrefined triangle this one lies in.
    pub triangle: usize,
    /// Barycentric coordinates of each corner in `triangle` (each sums to one).
    pub bary: [[f64; 3]; 3],
}

/// How the new vertices of a refinement are placed.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Smoothing {
    /// Edge midpoints: the refined surface is the coarse one, facets included.
    Midpoint,
    /// The interpolating modified butterfly rule, faded to midpoints across the transition.
    Butterfly,
}

impl Smoothing {
    /// The rule's name for reports.
    pub fn name(self) -> &'static str {
        match self {
            Smoothing::Midpoint => "midpoint",
            Smoothing::Butterfly => "modified butterfly",
        }
    }
}

/// Quality (2 r_in / r_circ) below which a triangle is too degenerate for its new vertices
/// to be smoothed: they stay at the midpoints of its edges.
pub const DEGENERATE_QUALITY: f64 = 1e-3;

/// Weights over the coarse vertices (vertex, weight), sorted by vertex, summing to one: a
/// refined vertex's row of S (dimensionless).
pub type Weights = Vec<(usize, f64)>;

/// A locally refined mesh.
#[derive(Debug, Clone)]
pub struct RedGreen {
    /// The refined mesh (m): coarse vertices first, with their indices and positions.
    pub mesh: TriMesh,
    /// Row of S per refined vertex: its position is Σ w p over the coarse positions p (m).
    pub weights: Vec<Weights>,
    /// Ancestor of each refined triangle.
    pub ancestor: Vec<Ancestor>,
    /// Per refined triangle: a green (transition) triangle.
    pub green: Vec<bool>,
    /// Red levels applied to each coarse triangle (the region's are the most).
    pub level: Vec<usize>,
}

/// One triangle while refining: corners, ancestor and the corners' barycentric coordinates.
#[derive(Debug, Clone, Copy)]
struct Piece {
    v: [usize; 3],
    anc: usize,
    bary: [[f64; 3]; 3],
}

impl Piece {
    /// The piece with its corners rotated to start at corner `i`.
    fn rotated(self, i: usize) -> Self {
        let r = |k: usize| (i + k) % 3;
        Self {
            v: [self.v[r(0)], self.v[r(1)], self.v[r(2)]],
            anc: self.anc,
            bary: [self.bary[r(0)], self.bary[r(1)], self.bary[r(2)]],
        }
    }
    /// A child of this piece with corners (vertex, barycentric coordinates).
    fn child(&self, c: [(usize, [f64; 3]); 3]) -> Self {
        Self {
            v: c.map(|p| p.0),
            anc: self.anc,
            bary: c.map(|p| p.1),
        }
    }
}

/// The midpoint of two barycentric coordinate triples.
fn mid(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        0.5 * (a[0] + b[0]),
        0.5 * (a[1] + b[1]),
        0.5 * (a[2] + b[2]),
    ]
}

/// The refinement under way: S, positions and the new vertex of every split edge.
struct Work<'a> {
    coarse: &'a TriMesh,
    smoothing: Smoothing,
    /// Fade of the smoothing per coarse vertex (1 on the region, 0 beyond the band).
    fade: Vec<f64>,
    weights: Vec<Weights>,
    positions: Vec<Vector3<f64>>,
    mids: HashMap<(usize, usize), usize>,
    /// Per new vertex (from the coarse vertex count on): its edge and whether it is the
    /// plain midpoint.
    edge: Vec<([usize; 2], bool)>,
}

impl Work<'_> {
    /// The new vertex on edge (a, b), which lies at `at` = (coarse triangle, barycentric
    /// coordinates there) when flat: made once, by the butterfly stencil of `rings` faded
    /// towards the midpoint by the fade τ at that point.
    fn midpoint(
        &mut self,
        a: usize,
        b: usize,
        at: (usize, [f64; 3]),
        rings: Option<&Rings>,
    ) -> usize {
        let key = (a.min(b), a.max(b));
        if let Some(&m) = self.mids.get(&key) {
            return m;
        }
        let (anc, bary) = at;
        let corners = self.coarse.triangles[anc];
        let tau: f64 = (0..3).map(|i| bary[i] * self.fade[corners[i]]).sum();
        let stencil = match (self.smoothing, rings) {
            (Smoothing::Butterfly, Some(r)) if tau > 0.0 => r.stencil(a, b),
            _ => None,
        };
        let plain = stencil.is_none();
        let mut terms = Vec::with_capacity(12);
        match stencil {
            Some(s) => {
                let half = 0.5 * (1.0 - tau);
                if half > 0.0 {
                    terms.extend([(a, half), (b, half)]);
                }
                terms.extend(s.into_iter().map(|(v, w)| (v, tau * w)));
            }
            None => terms.extend([(a, 0.5), (b, 0.5)]),
        }
        let row = combine(&terms, &self.weights);
        let p = apply(&row, &self.coarse.positions);
        let m = self.positions.len();
        self.weights.push(row);
        self.positions.push(p);
        self.mids.insert(key, m);
        self.edge.push(([a, b], plain));
        m
    }

    /// Put new vertex `v` at the plain midpoint of its edge.
    fn make_plain(&mut self, v: usize) {
        let i = v - self.coarse.positions.len();
        let ([a, b], plain) = self.edge[i];
        if !plain {
            self.weights[v] = combine(&[(a, 0.5), (b, 0.5)], &self.weights);
            self.positions[v] = apply(&self.weights[v], &self.coarse.positions);
            self.edge[i].1 = true;
        }
    }

    /// Fall back to midpoints where the smoothing would fold the surface: the new vertices of
    /// a child whose normal turns by more than 90° from its parent's (`split`: the first
    /// child's index in `pieces` and the parent's corners), and of every parent too
    /// degenerate to have a normal ([`DEGENERATE_QUALITY`]). Repeats until nothing folds
    /// (midpoints alone never fold: their children lie in the parent's plane).
    fn unfold(&mut self, pieces: &[Piece], split: &[(usize, [usize; 3])]) {
        let n0 = self.coarse.positions.len();
        loop {
            let mut fold = Vec::new();
            for &(at, parent) in split {
                let pp = parent.map(|v| self.positions[v]);
                let np = (pp[1] - pp[0]).cross(&(pp[2] - pp[0]));
                let degenerate = triangle_quality(pp).0 < DEGENERATE_QUALITY;
                for child in &pieces[at..at + 4] {
                    let c = child.v.map(|v| self.positions[v]);
                    let nc = (c[1] - c[0]).cross(&(c[2] - c[0]));
                    if degenerate || nc.dot(&np) <= 0.0 {
                        fold.extend(
                            child
                                .v
                                .iter()
                                .copied()
                                .filter(|&v| v >= n0 && !self.edge[v - n0].1),
                        );
                    }
                }
            }
            if fold.is_empty() {
                return;
            }
            fold.into_iter().for_each(|v| self.make_plain(v));
        }
    }

    /// The flat position (m) at barycentric `b` in coarse triangle `t`.
    fn flat(&self, t: usize, b: [f64; 3]) -> Vector3<f64> {
        let c = self.coarse.triangles[t];
        (0..3).map(|i| self.coarse.positions[c[i]] * b[i]).sum()
    }

    /// One red step: every piece whose ancestor wants more than `done` levels is split 1-to-4
    /// (children in the order corner a, b, c, middle), the others are kept, in order.
    fn red_step(&mut self, pieces: Vec<Piece>, level: &[usize], done: usize) -> Vec<Piece> {
        let rings = (self.smoothing == Smoothing::Butterfly).then(|| {
            let tris: Vec<[usize; 3]> = pieces.iter().map(|p| p.v).collect();
            Rings::new(&self.positions, &tris)
        });
        let first_new = self.positions.len();
        let mut out = Vec::with_capacity(pieces.len() * 2);
        let mut split = Vec::new();
        for p in pieces {
            if level[p.anc] <= done {
                out.push(p);
                continue;
            }
            split.push((out.len(), p.v));
            let [a, b, c] = p.v;
            let [ba, bb, bc] = p.bary;
            let (mab, mbc, mca) = (mid(ba, bb), mid(bb, bc), mid(bc, ba));
            let ab = self.midpoint(a, b, (p.anc, mab), rings.as_ref());
            let bcv = self.midpoint(b, c, (p.anc, mbc), rings.as_ref());
            let ca = self.midpoint(c, a, (p.anc, mca), rings.as_ref());
            out.extend(red_children(&p, [ab, bcv, ca], [mab, mbc, mca]));
        }
        if self.positions.len() > first_new {
            self.unfold(&out, &split);
        }
        out
    }

    /// Close the T-junctions: each piece with new vertices on its edges is split green (one
    /// or two such edges) or red (three). Returns the pieces and which are green.
    fn close(&self, pieces: Vec<Piece>) -> (Vec<Piece>, Vec<bool>) {
        let mut out = Vec::with_capacity(pieces.len());
        let mut green = Vec::with_capacity(pieces.len());
        for p in pieces {
            let on = |k: usize| {
                let (a, b) = (p.v[k], p.v[(k + 1) % 3]);
                self.mids.get(&(a.min(b), a.max(b))).copied()
            };
            let m = [on(0), on(1), on(2)];
            let bm = |k: usize| mid(p.bary[k], p.bary[(k + 1) % 3]);
            match m.iter().filter(|x| x.is_some()).count() {
                0 => {
                    out.push(p);
                    green.push(false);
                }
                1 => {
                    let i = (0..3).find(|&k| m[k].is_some()).expect("one edge");
                    let q = p.rotated(i);
                    let (mv, mb) = (m[i].expect("split"), bm(i));
                    let [a, b, c] = [0, 1, 2].map(|k| (q.v[k], q.bary[k]));
                    out.push(q.child([a, (mv, mb), c]));
                    out.push(q.child([(mv, mb), b, c]));
                    green.extend([true, true]);
                }
                2 => {
                    let j = (0..3).find(|&k| m[k].is_none()).expect("one edge unsplit");
                    let i = (j + 1) % 3;
                    let q = p.rotated(i);
                    let mab = (m[i].expect("split"), bm(i));
                    let mbc = (m[(i + 1) % 3].expect("split"), bm((i + 1) % 3));
                    let [a, b, c] = [0, 1, 2].map(|k| (q.v[k], q.bary[k]));
                    out.push(q.child([mab, b, mbc]));
                    // The shorter diagonal of the flat quad: the topology does not depend
                    // on the smoothing.
                    let flat = |b: [f64; 3]| self.flat(q.anc, b);
                    if (flat(a.1) - flat(mbc.1)).norm() <= (flat(mab.1) - flat(c.1)).norm() {
                        out.push(q.child([a, mab, mbc]));
                        out.push(q.child([a, mbc, c]));
                    } else {
                        out.push(q.child([a, mab, c]));
                        out.push(q.child([mab, mbc, c]));
                    }
                    green.extend([true, true, true]);
                }
                _ => {
                    let mv = m.map(|x| x.expect("split"));
                    out.extend(red_children(&p, mv, [bm(0), bm(1), bm(2)]));
                    green.extend([false; 4]);
                }
            }
        }
        (out, green)
    }
}

/// The four red children of `p` with edge vertices `m` (on ab, bc, ca) at barycentric `mb`.
fn red_children(p: &Piece, m: [usize; 3], mb: [[f64; 3]; 3]) -> [Piece; 4] {
    let [a, b, c] = [0, 1, 2].map(|k| (p.v[k], p.bary[k]));
    let [ab, bc, ca] = [0, 1, 2].map(|k| (m[k], mb[k]));
    [
        p.child([a, ab, ca]),
        p.child([ab, b, bc]),
        p.child([ca, bc, c]),
        p.child([ab, bc, ca]),
    ]
}

/// The row Σ c_j S_j for `terms` (current vertex j, coefficient c_j), merged by coarse vertex.
fn combine(terms: &[(usize, f64)], weights: &[Weights]) -> Weights {
    let mut w: Vec<(usize, f64)> = terms
        .iter()
        .flat_map(|&(v, c)| weights[v].iter().map(move |&(u, x)| (u, c * x)))
        .collect();
    w.sort_by_key(|p| p.0);
    let mut merged: Weights = Vec::with_capacity(w.len());
    for (v, x) in w {
        match merged.last_mut() {
            Some(last) if last.0 == v => last.1 += x,
            _ => merged.push((v, x)),
        }
    }
    merged.retain(|p| p.1 != 0.0);
    merged
}

/// Σ w p of a row over `positions` (m).
pub fn apply(row: &[(usize, f64)], positions: &[Vector3<f64>]) -> Vector3<f64> {
    row.iter().map(|&(v, w)| positions[v] * w).sum()
}

/// Red levels per triangle of `mesh` and the smoothing's fade per vertex for refining the
/// `region` triangles `levels` times: the region gets `levels`; a triangle whose nearest
/// vertex is j − 1 edges from the region (ring j) gets max(levels − j, 1) while j ≤ W =
/// max(levels − 1, 1), then 0; the fade is 1 on the region's vertices and 1 − d / W at d
/// edges from it (at least 0). Triangles sharing a vertex differ by at most one level, so the
/// one-ring of every edge being split is conforming when its butterfly stencil is taken.
pub fn graded_levels(mesh: &TriMesh, region: &[bool], levels: usize) -> (Vec<usize>, Vec<f64>) {
    let n = mesh.positions.len();
    let mut adj: Vec<Vec<usize>> = vec![Vec::new(); n];
    for t in &mesh.triangles {
        for k in 0..3 {
            adj[t[k]].push(t[(k + 1) % 3]);
            adj[t[(k + 1) % 3]].push(t[k]);
        }
    }
    let mut d = vec![usize::MAX; n];
    let mut queue = VecDeque::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if region[t] && levels > 0 {
            for &v in tri {
                if d[v] != 0 {
                    d[v] = 0;
                    queue.push_back(v);
                }
            }
        }
    }
    while let Some(v) = queue.pop_front() {
        for &w in &adj[v] {
            if d[w] == usize::MAX {
                d[w] = d[v] + 1;
                queue.push_back(w);
            }
        }
    }
    let width = levels.saturating_sub(1).max(1);
    let level = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| {
            let near = tri.iter().map(|&v| d[v]).min().unwrap_or(usize::MAX);
            if region[t] {
                levels
            } else if near < width {
                levels.saturating_sub(near + 1).max(1)
            } else {
                0
            }
        })
        .collect();
    let fade = d
        .iter()
        .map(|&x| match x {
            0 => 1.0,
            usize::MAX => 0.0,
            x => (1.0 - x as f64 / width as f64).max(0.0),
        })
        .collect();
    (level, fade)
}

/// [`graded_levels`] for a target level per triangle (0: not refined for itself): each
/// level's triangles graded as a region of their own, and per triangle the most levels and
/// per vertex the largest fade any of them asks for. Each grading changes by at most one
/// level between triangles sharing a vertex, so their maximum does too.
pub fn graded_levels_by_triangle(mesh: &TriMesh, target: &[usize]) -> (Vec<usize>, Vec<f64>) {
    let mut level = vec![0; mesh.triangles.len()];
    let mut fade = vec![0.0f64; mesh.positions.len()];
    let top = target.iter().copied().max().unwrap_or(0);
    for l in 1..=top {
        let region: Vec<bool> = target.iter().map(|&t| t == l).collect();
        if !region.contains(&true) {
            continue;
        }
        let (lv, fd) = graded_levels(mesh, &region, l);
        level.iter_mut().zip(lv).for_each(|(a, b)| *a = (*a).max(b));
        fade.iter_mut().zip(fd).for_each(|(a, b)| *a = a.max(b));
    }
    (level, fade)
}

/// Refine the `region` triangles of `mesh` (one flag per triangle) `levels` times with a
/// graded band and green closure around them, placing new vertices by `smoothing`.
pub fn refine(mesh: &TriMesh, region: &[bool], levels: usize, smoothing: Smoothing) -> RedGreen {
    let target: Vec<usize> = region.iter().map(|&r| if r { levels } else { 0 }).collect();
    refine_by_triangle(mesh, &target, smoothing)
}

/// Refine each triangle of `mesh` its own `target` number of levels (0: only as the grading
/// around its neighbours asks), with graded bands and green closure, placing new vertices by
/// `smoothing`: a thin patch of skin inside a thicker one is refined further than the rest.
pub fn refine_by_triangle(mesh: &TriMesh, target: &[usize], smoothing: Smoothing) -> RedGreen {
    let levels = target.iter().copied().max().unwrap_or(0);
    let (level, fade) = graded_levels_by_triangle(mesh, target);
    let n = mesh.positions.len();
    let mut work = Work {
        coarse: mesh,
        smoothing,
        fade,
        weights: (0..n).map(|v| vec![(v, 1.0)]).collect(),
        positions: mesh.positions.clone(),
        mids: HashMap::new(),
        edge: Vec::new(),
    };
    let eye = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    let mut pieces: Vec<Piece> = mesh
        .triangles
        .iter()
        .enumerate()
        .map(|(t, &v)| Piece {
            v,
            anc: t,
            bary: eye,
        })
        .collect();
    for done in 0..levels {
        pieces = work.red_step(pieces, &level, done);
    }
    let (pieces, green) = work.close(pieces);
    let ancestor = pieces
        .iter()
        .map(|p| Ancestor {
            triangle: p.anc,
            bary: p.bary,
        })
        .collect();
    let triangles = pieces.iter().map(|p| p.v).collect();
    RedGreen {
        mesh: TriMesh::new(work.positions, triangles),
        weights: work.weights,
        ancestor,
        green,
        level,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A flat n × n grid of unit squares split by diagonals, with vertex (n/2, n/2) moved
    /// along x by (1 − ε) of an edge: two triangles of area ε/2 beside it (m).
    fn sliver_grid(n: usize, eps: f64) -> TriMesh {
        let id = |i: usize, j: usize| j * (n + 1) + i;
        let mut p: Vec<Vector3<f64>> = (0..=n)
            .flat_map(|j| (0..=n).map(move |i| Vector3::new(i as f64, j as f64, 0.0)))
            .collect();
        p[id(n / 2, n / 2)].x += 1.0 - eps;
        let mut t = Vec::new();
        for j in 0..n {
            for i in 0..n {
                t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        TriMesh::new(p, t)
    }

    /// Around a sliver the butterfly stencils of a distorted mesh would turn children over;
    /// those new vertices fall back to midpoints, so no refined triangle faces down, and the
    /// flat sheet stays flat.
    #[test]
    fn smoothing_never_folds_a_sliver_over() {
        let m = sliver_grid(8, 1e-4);
        let all = vec![true; m.triangles.len()];
        let r = refine(&m, &all, 2, Smoothing::Butterfly);
        let flat = refine(&m, &all, 2, Smoothing::Midpoint);
        let moved = (0..r.mesh.positions.len())
            .filter(|&v| r.mesh.positions[v] != flat.mesh.positions[v])
            .count();
        assert!(moved > 0, "the butterfly rule moved nothing");
        for (f, t) in r.mesh.triangles.iter().enumerate() {
            let p = t.map(|v| r.mesh.positions[v]);
            assert!(p.iter().all(|x| x.z == 0.0));
            let (ra, ancestor) = (p, r.ancestor[f].triangle);
            let area = (ra[1] - ra[0]).cross(&(ra[2] - ra[0])).z;
            let q = m.triangles[ancestor].map(|v| m.positions[v]);
            let coarse = (q[1] - q[0]).cross(&(q[2] - q[0])).z;
            // Same orientation as its ancestor (slivers' children may be flat, not flipped).
            assert!(
                area * coarse.signum() >= 0.0,
                "triangle {f} folded over: {area}"
            );
        }
    }
}
