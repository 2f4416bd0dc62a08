//! The embedding operator B: surface points carried by the lattice. Point p sits at
//! x_p = Σ_n B_pn q_n, a fixed combination of lattice node positions q with its element's
//! interpolation weights (a partition of unity), the same for the three coordinates.
//!
//! [`Embedding`] is the one place B is applied: B on node positions (m → m), Bᵀ on per-point
//! forces (N → N on the nodes), and Bᵀ K B on a stiffness over the points (N/m → N/m over
//! node pairs). Each method fixes its order of floating-point operations: points in their
//! order, each point's nodes in its row's order (node sums accumulate point by point), so a
//! result does not depend on which caller asks for it.
//!
//! Bᵀ K B of a sparse K ([`Embedding::project_stiffness`]) is formed column by column over
//! node dofs: for node m and axis a, the column K B e_{3m+a} = Σ_{p ∋ m} B_pm K e_{3p+a} is
//! accumulated from the compressed K, then multiplied by Bᵀ row by row; columns are
//! independent and run in parallel. The emitted triplet layout depends only on the patterns
//! of K and B, so a caller's sparse pattern and symbolic factorisation are reused from one
//! call to the next.

use crate::lattice::Lattice;
use anyhow::bail;
use faer::sparse::SparseColMatRef;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::collections::{BTreeMap, HashMap};
use std::sync::OnceLock;

/// Largest |Σ_n B_pn − 1| accepted for a row by [`Embedding::checked`] (dimensionless; the
/// rows of B are interpolation weights of a point in its element, which sum to one).
pub const ROW_SUM_TOLERANCE: f64 = 1e-6;

/// One entry of a matrix over node dofs (row dof, column dof, value).
pub type Triplet = (usize, usize, f64);

/// The embedding B of points in a lattice of `node_count` nodes: per point, its (node,
/// weight) row. Positions and forces are flat, three values (x, y, z) per point or node.
#[derive(Debug, Clone)]
pub struct Embedding {
    /// For each point, its (node, weight) pairs in the order they are summed.
    rows: Vec<Vec<(usize, f64)>>,
    /// Number of lattice nodes.
    nodes: usize,
    /// The transposed rows and point groups of [`Embedding::project_stiffness`], built on
    /// its first call.
    transpose: OnceLock<Transpose>,
}

/// What [`Embedding::project_stiffness`] needs besides the rows: the transposed embedding
/// and the points grouped by identical node lists (one group per lattice element in
/// practice).
#[derive(Debug, Clone)]
struct Transpose {
    /// For each node, its (point, weight) pairs in point order.
    cols: Vec<Vec<(usize, f64)>>,
    /// The node list of each group.
    group_nodes: Vec<Vec<usize>>,
    /// The group of each point.
    group_of: Vec<usize>,
    /// The start of each group's block in a flat per-group accumulator (3 × group nodes
    /// values), and the accumulator's length last.
    group_offset: Vec<usize>,
}

/// The position (m) of node `n` in flat node positions `q`.
fn node(q: &[f64], n: usize) -> Vector3<f64> {
    Vector3::new(q[3 * n], q[3 * n + 1], q[3 * n + 2])
}

impl Embedding {
    /// The embedding with `rows` (per point, its (node, weight) pairs, summed in this order)
    /// in a lattice of `nodes` nodes. Rows are taken as given: no check that the weights sum
    /// to one (see [`Embedding::checked`]).
    pub fn from_rows(rows: Vec<Vec<(usize, f64)>>, nodes: usize) -> Self {
        debug_assert!(rows.iter().flatten().all(|&(n, _)| n < nodes));
        Self {
            rows,
            nodes,
            transpose: OnceLock::new(),
        }
    }

    /// The embedding of `points` points in `nodes` nodes from the triplets (point, node,
    /// weight) of B, each point's row in the triplets' order.
    pub fn from_triplets(triplets: &[(usize, usize, f64)], points: usize, nodes: usize) -> Self {
        let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); points];
        for &(p, n, w) in triplets {
            rows[p].push((n, w));
        }
        Self::from_rows(rows, nodes)
    }

    /// The lattice's embedding of its surface vertices ([`Lattice::embedding_triplets`]).
    pub fn of_lattice(lattice: &Lattice) -> Self {
        let points = lattice.vertex_points.len();
        Self::from_triplets(&lattice.embedding_triplets(), points, lattice.node_count())
    }

    /// As [`Embedding::from_triplets`] for the vertices of a skin, checked: each row sorted
    /// by node with repeated nodes merged. Fails, naming the problem, on a point or node out
    /// of range, a weight that is not finite, a vertex without weights (the lattice must
    /// cover the whole skin), or a row whose weights do not sum to one within
    /// [`ROW_SUM_TOLERANCE`].
    pub fn checked(
        triplets: &[(usize, usize, f64)],
        points: usize,
        nodes: usize,
    ) -> anyhow::Result<Self> {
        let (n, mut rows) = (points, vec![Vec::new(); points]);
        for &(v, node, w) in triplets {
            if v >= n {
                bail!("embedding entry names skin vertex {v}, but the skin has {n} vertices");
            }
            if node >= nodes {
                bail!(
                    "embedding entry names lattice node {node}, but the lattice has {nodes} nodes"
                );
            }
            if !w.is_finite() {
                bail!("embedding weight of vertex {v} on node {node} is not finite ({w})");
            }
            rows[v].push((node, w));
        }
        for (v, r) in rows.iter_mut().enumerate() {
            if r.is_empty() {
                bail!(
                    "skin vertex {v} is not embedded in the lattice (no embedding weights); \
                     the lattice must cover the whole skin"
                );
            }
            *r = merged(std::mem::take(r));
            let s: f64 = r.iter().map(|p| p.1).sum();
            if (s - 1.0).abs() > ROW_SUM_TOLERANCE {
                bail!(
                    "embedding weights of skin vertex {v} sum to {s}, not 1 (interpolation \
                     weights must be a partition of unity)"
                );
            }
        }
        Ok(Self::from_rows(rows, nodes))
    }

    /// Number of embedded points.
    pub fn point_count(&self) -> usize {
        self.rows.len()
    }

    /// Number of lattice nodes.
    pub fn node_count(&self) -> usize {
        self.nodes
    }

    /// Point `p`'s row of B: its (node, weight) pairs (weights dimensionless).
    pub fn row(&self, p: usize) -> &[(usize, f64)] {
        &self.rows[p]
    }

    /// B q at point `p`: its position (m) when the nodes are at `q` (flat, m). Also carries
    /// node displacements (m) to the point's displacement.
    pub fn point(&self, p: usize, q: &[f64]) -> Vector3<f64> {
        self.rows[p]
            .iter()
            .fold(Vector3::zeros(), |acc, &(n, w)| acc + w * node(q, n))
    }

    /// B q: every point's position (m) when the nodes are at `q` (flat, m); node
    /// displacements (m) give the points' displacements.
    pub fn positions(&self, q: &[f64]) -> Vec<Vector3<f64>> {
        (0..self.rows.len()).map(|p| self.point(p, q)).collect()
    }

    /// [`Embedding::positions`] flat (three values per point, m).
    pub fn positions_flat(&self, q: &[f64]) -> Vec<f64> {
        self.positions(q)
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect()
    }

    /// Bᵀ f at one point: the force `f` (N) acting at point `p` spread onto its nodes,
    /// added to the node forces `out` (flat, N).
    pub fn spread_point(&self, p: usize, f: &Vector3<f64>, out: &mut [f64]) {
        for &(n, w) in &self.rows[p] {
            for a in 0..3 {
                out[3 * n + a] += w * f[a];
            }
        }
    }

    /// Bᵀ f: per-point forces `f` (flat, three per point, N) spread onto the nodes, added to
    /// `out` (flat over node dofs, N).
    pub fn spread(&self, f: &[f64], out: &mut [f64]) {
        for (p, row) in self.rows.iter().enumerate() {
            for &(n, w) in row {
                for a in 0..3 {
                    out[3 * n + a] += w * f[3 * p + a];
                }
            }
        }
    }

    /// −Bᵀ g: the node forces (N) of an energy whose gradient at the points is `g` (flat,
    /// three per point, N = J/m), added to `out` (flat over node dofs, N). The force is
    /// minus the gradient, so this subtracts Bᵀ g.
    pub fn spread_gradient(&self, g: &[f64], out: &mut [f64]) {
        for (p, row) in self.rows.iter().enumerate() {
            for &(n, w) in row {
                for a in 0..3 {
                    out[3 * n + a] -= w * g[3 * p + a];
                }
            }
        }
    }

    /// [`Embedding::spread_gradient`] for a gradient over some of the points: `g` holds three
    /// values (N) per entry of `points`, entry i being point `points[i]`, in that order.
    pub fn spread_gradient_at(&self, points: &[usize], g: &[f64], out: &mut [f64]) {
        for (i, &p) in points.iter().enumerate() {
            for &(n, w) in &self.rows[p] {
                for a in 0..3 {
                    out[3 * n + a] -= w * g[3 * i + a];
                }
            }
        }
    }

    /// Bᵀ diag(k) d: the node forces (N) of springs of stiffness `k` (N/m, one per point)
    /// stretched by point displacements `d` (flat, three per point, m), added to `out` (flat
    /// over node dofs, N). Each term is formed as (B_pn k_p) d_p.
    pub fn spread_scaled(&self, k: &[f64], d: &[f64], out: &mut [f64]) {
        for (p, row) in self.rows.iter().enumerate() {
            for &(n, w) in row {
                for a in 0..3 {
                    out[3 * n + a] += w * k[p] * d[3 * p + a];
                }
            }
        }
    }

    /// Bᵀ K B for an isotropic stiffness per point: k_p (N/m, for the first `k.len()`
    /// points; the others carry none) the same on x, y and z. Returns triplets over node dofs
    /// (N/m), one per node pair the rows share and per axis, node pairs in ascending order,
    /// each pair's value summed over the points in order as k_p B_pa B_pb.
    pub fn scalar_stiffness(&self, k: &[f64]) -> Vec<Triplet> {
        let mut pairs: BTreeMap<(usize, usize), f64> = BTreeMap::new();
        for (p, &kp) in k.iter().enumerate() {
            let row = &self.rows[p];
            for &(a, wa) in row {
                for &(b, wb) in row {
                    *pairs.entry((a, b)).or_insert(0.0) += kp * wa * wb;
                }
            }
        }
        pairs
            .into_iter()
            .flat_map(|((a, b), k)| (0..3).map(move |d| (3 * a + d, 3 * b + d, k)))
            .collect()
    }

    /// Bᵀ K B of a stiffness `k` over the points' dofs (3 × points square, compressed by
    /// columns, N/m): triplets over node dofs (N/m), both triangles, column by column (node
    /// dof order), rows ascending within a column. The layout depends only on the patterns
    /// of K and B: entries that happen to vanish are kept.
    pub fn project_stiffness(&self, k: SparseColMatRef<'_, usize, f64>) -> Vec<Triplet> {
        let t = self.transpose.get_or_init(|| self.transposed());
        let (np, nd) = (self.rows.len(), 3 * self.nodes);
        let ng = t.group_nodes.len();
        let gsize = *t.group_offset.last().expect("offsets");
        let columns: Vec<Vec<Triplet>> = (0..self.nodes)
            .into_par_iter()
            .map_init(
                || Columns {
                    acc: vec![0.0; 3 * np],
                    seen: vec![false; 3 * np],
                    gacc: vec![0.0; gsize],
                    gseen: vec![false; ng],
                    out: vec![0.0; nd],
                    oseen: vec![false; nd],
                },
                |s, m| {
                    let mut col = Vec::new();
                    for a in 0..3 {
                        self.stiffness_column(t, k, s, (m, a), &mut col);
                    }
                    col
                },
            )
            .collect();
        columns.into_iter().flatten().collect()
    }

    /// Column 3m + a of Bᵀ K B appended to `col`: acc = K (B e_{3m+a}) over point dofs, then
    /// Bᵀ acc gathered per point group (dense loops over the group's nodes) and scattered
    /// once per group. The scratch `s` is left cleared.
    fn stiffness_column(
        &self,
        t: &Transpose,
        k: SparseColMatRef<'_, usize, f64>,
        s: &mut Columns,
        (m, a): (usize, usize),
        col: &mut Vec<Triplet>,
    ) {
        let mut touched = Vec::new();
        for &(v, w) in &t.cols[m] {
            let j = 3 * v + a;
            for (i, kv) in k.row_idx_of_col(j).zip(k.val_of_col(j)) {
                if !s.seen[i] {
                    s.seen[i] = true;
                    touched.push(i);
                }
                s.acc[i] += w * kv;
            }
        }
        let mut gtouched = Vec::new();
        for &i in &touched {
            let (u, b) = (i / 3, i % 3);
            let g = t.group_of[u];
            if !s.gseen[g] {
                s.gseen[g] = true;
                gtouched.push(g);
            }
            let row = &self.rows[u];
            let base = t.group_offset[g] + b * row.len();
            let val = s.acc[i];
            for (slot, &(_, w)) in s.gacc[base..base + row.len()].iter_mut().zip(row) {
                *slot += w * val;
            }
            s.acc[i] = 0.0;
            s.seen[i] = false;
        }
        let mut otouched = Vec::new();
        for &g in &gtouched {
            let gn = &t.group_nodes[g];
            let base = t.group_offset[g];
            for b in 0..3 {
                for (kk, &node) in gn.iter().enumerate() {
                    let r = 3 * node + b;
                    if !s.oseen[r] {
                        s.oseen[r] = true;
                        otouched.push(r);
                    }
                    let slot = &mut s.gacc[base + b * gn.len() + kk];
                    s.out[r] += *slot;
                    *slot = 0.0;
                }
            }
            s.gseen[g] = false;
        }
        otouched.sort_unstable();
        for &r in &otouched {
            col.push((r, 3 * m + a, s.out[r]));
            s.out[r] = 0.0;
            s.oseen[r] = false;
        }
    }

    /// The transposed rows and the point groups ([`Transpose`]).
    fn transposed(&self) -> Transpose {
        let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); self.nodes];
        for (v, r) in self.rows.iter().enumerate() {
            for &(node, w) in r {
                cols[node].push((v, w));
            }
        }
        let mut group_nodes: Vec<Vec<usize>> = Vec::new();
        let mut group_id: HashMap<Vec<usize>, usize> = HashMap::new();
        let group_of: Vec<usize> = self
            .rows
            .iter()
            .map(|r| {
                let key: Vec<usize> = r.iter().map(|p| p.0).collect();
                *group_id.entry(key.clone()).or_insert_with(|| {
                    group_nodes.push(key);
                    group_nodes.len() - 1
                })
            })
            .collect();
        let mut group_offset = Vec::with_capacity(group_nodes.len() + 1);
        let mut off = 0;
        for g in &group_nodes {
            group_offset.push(off);
            off += 3 * g.len();
        }
        group_offset.push(off);
        Transpose {
            cols,
            group_nodes,
            group_of,
            group_offset,
        }
    }
}

/// A row sorted by node, repeated nodes' weights summed.
fn merged(mut r: Vec<(usize, f64)>) -> Vec<(usize, f64)> {
    r.sort_by_key(|&(node, _)| node);
    let mut out: Vec<(usize, f64)> = Vec::with_capacity(r.len());
    for (node, w) in r {
        match out.last_mut() {
            Some(last) if last.0 == node => last.1 += w,
            _ => out.push((node, w)),
        }
    }
    out
}

/// One worker's scratch for [`Embedding::stiffness_column`], all zero (false) between
/// columns: K B e over point dofs, per-group Bᵀ sums and the node-dof column, each with the
/// flags of the entries touched.
struct Columns {
    acc: Vec<f64>,
    seen: Vec<bool>,
    gacc: Vec<f64>,
    gseen: Vec<bool>,
    out: Vec<f64>,
    oseen: Vec<bool>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::sparse::assemble;

    /// Two points on three nodes: point 0 halfway between nodes 0 and 1, point 1 a quarter
    /// of the way from node 1 to node 2.
    fn two_points() -> Embedding {
        Embedding::from_rows(
            vec![vec![(0, 0.5), (1, 0.5)], vec![(1, 0.75), (2, 0.25)]],
            3,
        )
    }

    #[test]
    fn b_interpolates_node_positions() {
        let e = two_points();
        let q = [0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 2.0, 4.0, 0.0];
        assert_eq!(
            e.positions(&q),
            vec![Vector3::new(1.0, 0.0, 0.0), Vector3::new(2.0, 1.0, 0.0)]
        );
        assert_eq!(e.positions_flat(&q), vec![1.0, 0.0, 0.0, 2.0, 1.0, 0.0]);
    }

    /// Bᵀ is the adjoint of B: f · B q = Bᵀ f · q; the gradient form is its negative, and
    /// the scaled form is Bᵀ of the scaled displacements.
    #[test]
    fn spreading_is_the_adjoint() {
        let e = two_points();
        let q = [0.1, -0.2, 0.3, 0.7, 0.5, -0.4, 1.1, 0.9, 0.6];
        let f = [1.0, 2.0, -3.0, -0.5, 0.25, 4.0];
        let bq = e.positions_flat(&q);
        let mut btf = vec![0.0; 9];
        e.spread(&f, &mut btf);
        let lhs: f64 = f.iter().zip(&bq).map(|(a, b)| a * b).sum();
        let rhs: f64 = btf.iter().zip(&q).map(|(a, b)| a * b).sum();
        assert!((lhs - rhs).abs() < 1e-12, "{lhs} vs {rhs}");
        let mut minus = vec![0.0; 9];
        e.spread_gradient(&f, &mut minus);
        assert!(minus.iter().zip(&btf).all(|(a, b)| *a == -b));
        let mut one = vec![0.0; 9];
        e.spread_gradient_at(&[1], &f[3..], &mut one);
        let mut each = vec![0.0; 9];
        e.spread_point(1, &Vector3::new(-0.5, 0.25, 4.0), &mut each);
        assert!(one.iter().zip(&each).all(|(a, b)| *a == -b));
        let mut scaled = vec![0.0; 9];
        e.spread_scaled(&[2.0, 3.0], &f, &mut scaled);
        let kf: Vec<f64> = f
            .iter()
            .enumerate()
            .map(|(i, x)| x * [2.0, 3.0][i / 3])
            .collect();
        let mut direct = vec![0.0; 9];
        e.spread(&kf, &mut direct);
        assert!(scaled
            .iter()
            .zip(&direct)
            .all(|(a, b)| (a - b).abs() < 1e-15));
    }

    /// Bᵀ K B of a diagonal K equals the scalar form, and both equal Bᵀ (K (B e)) column by
    /// column.
    #[test]
    fn projected_stiffness_matches_the_scalar_form() {
        let e = two_points();
        let k = [3.0, 5.0];
        let diag: Vec<Triplet> = (0..6).map(|i| (i, i, k[i / 3])).collect();
        let kx = assemble(6, 6, &diag).unwrap();
        let dense = |t: &[Triplet]| {
            let mut m = vec![0.0; 81];
            for &(r, c, v) in t {
                m[9 * r + c] += v;
            }
            m
        };
        let projected = dense(&e.project_stiffness(kx.as_ref()));
        let scalar = dense(&e.scalar_stiffness(&k));
        for (a, b) in projected.iter().zip(&scalar) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
        // Column 3 (node 1, x): K B e_3 = (0.5 · 3, 0.75 · 5) on the points' x.
        for c in 0..9 {
            let mut unit = vec![0.0; 9];
            unit[c] = 1.0;
            let kb: Vec<f64> = e
                .positions_flat(&unit)
                .iter()
                .enumerate()
                .map(|(i, x)| x * k[i / 3])
                .collect();
            let mut col = vec![0.0; 9];
            e.spread(&kb, &mut col);
            for r in 0..9 {
                assert!((projected[9 * r + c] - col[r]).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn checked_rows_are_sorted_merged_and_partitions_of_unity() {
        let t = [(0, 2, 0.25), (0, 1, 0.5), (0, 2, 0.25), (1, 0, 1.0)];
        let e = Embedding::checked(&t, 2, 3).unwrap();
        assert_eq!(e.row(0), &[(1, 0.5), (2, 0.5)]);
        let err = |t: &[(usize, usize, f64)]| Embedding::checked(t, 2, 3).unwrap_err().to_string();
        assert!(err(&t[..3]).contains("vertex 1"));
        assert!(err(&[(0, 1, 0.9), (1, 0, 1.0)]).contains("sum to"));
        assert!(err(&[(0, 3, 1.0), (1, 0, 1.0)]).contains("node 3"));
        assert!(err(&[(0, 1, f64::NAN), (1, 0, 1.0)]).contains("not finite"));
    }
}
