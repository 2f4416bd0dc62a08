//! Preconditioned conjugate gradients on symmetric node-block (3 × 3) sparse matrices: the
//! iterative solver of the lattice's Newton systems [M + h²K] Δy = r.
//!
//! The matrix is held with both triangles in block compressed rows ([`BlockCsr`]), so each
//! output node of a product is computed on its own (no scatter, no per-thread accumulators).
//! Every parallel loop works on a fixed split of the nodes and dot products add the
//! per-chunk partial sums in chunk order: results have the same bits for any thread count.
//!
//! Preconditioners: 3 × 3 block Jacobi, optionally plus a coarse correction
//! ([`Coarse`]): z = D⁻¹ r + P A_c⁻¹ Pᵀ r (additive two-level), P the rigid-body modes
//! (3 translations, 3 infinitesimal rotations, orthonormalised) of aggregates of nearby
//! nodes that are connected in the matrix graph (so superimposed, mechanically separate
//! parts never share an aggregate), A_c = Pᵀ A P factorised by sparse Cholesky.

use crate::math::sparse::{assemble, SparseError, SpdSolver};
use rayon::prelude::*;
use std::collections::HashMap;

/// Nodes per chunk of every parallel loop (fixed: determinism across thread counts).
const CHUNK_NODES: usize = 48;

/// A symmetric positive definite linear map over node DOFs (3 per node).
pub trait SymOperator: Sync {
    /// y = A x; returns xᵀ A x.
    fn apply(&self, x: &[f64], y: &mut [f64]) -> f64;
}

impl SymOperator for BlockCsr {
    fn apply(&self, x: &[f64], y: &mut [f64]) -> f64 {
        self.mul(x, y)
    }
}

impl SymOperator for super::matfree::ElementOperator {
    fn apply(&self, x: &[f64], y: &mut [f64]) -> f64 {
        self.mul(x, y)
    }
}

/// A symmetric matrix over nodes with 3 × 3 blocks, both triangles stored, block compressed
/// rows. Units are those of the system (here N/m · s² scaled: kg).
#[derive(Debug, Clone, Default)]
pub struct BlockCsr {
    /// Row pointers into `col` (length nodes + 1).
    pub ptr: Vec<usize>,
    /// Block column (node) of each stored block, ascending within a row.
    pub col: Vec<u32>,
    /// Block values, 9 per block, row-major within the block.
    pub val: Vec<f64>,
    /// Index (into `col`) of each row's diagonal block.
    pub diag: Vec<usize>,
}

impl BlockCsr {
    /// Block rows (nodes).
    pub fn nodes(&self) -> usize {
        self.diag.len()
    }

    /// A matrix with the given block pattern (rows of sorted node columns, each row holding
    /// its diagonal) and zero values.
    pub fn from_pattern(rows: &[Vec<u32>]) -> Self {
        let mut ptr = Vec::with_capacity(rows.len() + 1);
        let mut col = Vec::new();
        let mut diag = Vec::with_capacity(rows.len());
        ptr.push(0);
        for (a, r) in rows.iter().enumerate() {
            let d = r
                .iter()
                .position(|&c| c as usize == a)
                .expect("every row holds its diagonal block");
            diag.push(col.len() + d);
            col.extend_from_slice(r);
            ptr.push(col.len());
        }
        let val = vec![0.0; 9 * col.len()];
        Self {
            ptr,
            col,
            val,
            diag,
        }
    }

    /// y = A x (flat, 3 per node); returns xᵀ A x (sum of per-chunk partial sums in order).
    pub fn mul(&self, x: &[f64], y: &mut [f64]) -> f64 {
        let partial: Vec<f64> = y
            .par_chunks_mut(3 * CHUNK_NODES)
            .enumerate()
            .map(|(c, yc)| {
                let a0 = c * CHUNK_NODES;
                let mut xy = 0.0;
                for (k, ya) in yc.chunks_exact_mut(3).enumerate() {
                    let a = a0 + k;
                    let (s, e) = (self.ptr[a], self.ptr[a + 1]);
                    let vals = &self.val[9 * s..9 * e];
                    let mut acc = [0.0; 3];
                    for (blk, &b) in vals.chunks_exact(9).zip(&self.col[s..e]) {
                        let b = 3 * b as usize;
                        let xb = &x[b..b + 3];
                        acc[0] += blk[0] * xb[0] + blk[1] * xb[1] + blk[2] * xb[2];
                        acc[1] += blk[3] * xb[0] + blk[4] * xb[1] + blk[5] * xb[2];
                        acc[2] += blk[6] * xb[0] + blk[7] * xb[1] + blk[8] * xb[2];
                    }
                    ya.copy_from_slice(&acc);
                    xy += acc[0] * x[3 * a] + acc[1] * x[3 * a + 1] + acc[2] * x[3 * a + 2];
                }
                xy
            })
            .collect();
        partial.iter().sum()
    }

    /// Inverses of the diagonal blocks (row-major 3 × 3), a non-invertible block replaced
    /// by the inverse of its diagonal's magnitudes.
    pub fn diag_inverses(&self) -> Vec<[f64; 9]> {
        self.diag
            .par_iter()
            .map(|&d| {
                let m = nalgebra::Matrix3::from_row_slice(&self.val[9 * d..9 * d + 9]);
                let inv = m.try_inverse().unwrap_or_else(|| {
                    nalgebra::Matrix3::from_diagonal(
                        &m.diagonal().map(|v| 1.0 / v.abs().max(1e-300)),
                    )
                });
                let mut o = [0.0; 9];
                for i in 0..3 {
                    for j in 0..3 {
                        o[3 * i + j] = inv[(i, j)];
                    }
                }
                o
            })
            .collect()
    }
}

/// Two-level coarse space: orthonormal rigid-body modes of node aggregates, and the
/// factorised Galerkin matrix A_c = Pᵀ A P.
pub struct Coarse {
    /// Aggregate of each node.
    agg: Vec<u32>,
    /// Nodes of each aggregate.
    members: Vec<Vec<u32>>,
    /// First coarse unknown of each aggregate (length aggregates + 1).
    offset: Vec<usize>,
    /// Per node: its 3 × k rows of P, stored as 6 modes × 3 components (mode-major).
    basis: Vec<[f64; 18]>,
    solver: SpdSolver,
    factorised: bool,
}

impl Coarse {
    /// Aggregate the nodes of `a` that lie in the same box of side `width` (m) at
    /// `positions` (flat, m) and are connected through the blocks of `a` inside the box,
    /// and build each aggregate's orthonormal rigid-body basis about its centroid.
    pub fn new(a: &BlockCsr, positions: &[f64], width: f64) -> Self {
        let n = a.nodes();
        let key = |i: usize| {
            [0, 1, 2].map(|d| (positions[3 * i + d] / width).floor() as i64)
        };
        // Connected components of the graph restricted to same-box edges (breadth first).
        let mut agg = vec![u32::MAX; n];
        let mut members: Vec<Vec<u32>> = Vec::new();
        let keys: Vec<[i64; 3]> = (0..n).map(key).collect();
        for s in 0..n {
            if agg[s] != u32::MAX {
                continue;
            }
            let id = members.len() as u32;
            let mut list = vec![s as u32];
            agg[s] = id;
            let mut head = 0;
            while head < list.len() {
                let i = list[head] as usize;
                head += 1;
                for &j in &a.col[a.ptr[i]..a.ptr[i + 1]] {
                    let j = j as usize;
                    if agg[j] == u32::MAX && keys[j] == keys[i] {
                        agg[j] = id;
                        list.push(j as u32);
                    }
                }
            }
            list.sort_unstable();
            members.push(list);
        }
        let mut basis = vec![[0.0; 18]; n];
        let mut offset = Vec::with_capacity(members.len() + 1);
        offset.push(0);
        for m in &members {
            let cnt = m.len() as f64;
            let mut c = [0.0; 3];
            for &i in m {
                for d in 0..3 {
                    c[d] += positions[3 * i as usize + d] / cnt;
                }
            }
            // Candidate modes over the aggregate's 3m DOFs.
            let dofs = 3 * m.len();
            let mut modes: Vec<Vec<f64>> = Vec::with_capacity(6);
            for t in 0..3 {
                let mut v = vec![0.0; dofs];
                for k in 0..m.len() {
                    v[3 * k + t] = 1.0;
                }
                modes.push(v);
            }
            for axis in 0..3 {
                let mut v = vec![0.0; dofs];
                for (k, &i) in m.iter().enumerate() {
                    let r = [0, 1, 2].map(|d| positions[3 * i as usize + d] - c[d]);
                    // e_axis × r
                    let w = match axis {
                        0 => [0.0, -r[2], r[1]],
                        1 => [r[2], 0.0, -r[0]],
                        _ => [-r[1], r[0], 0.0],
                    };
                    v[3 * k..3 * k + 3].copy_from_slice(&w);
                }
                modes.push(v);
            }
            // Modified Gram–Schmidt (twice), dropping dependent modes (a single node has no
            // rotations, collinear nodes one fewer).
            let scale = width * width * cnt;
            let mut kept: Vec<Vec<f64>> = Vec::new();
            for mut v in modes {
                let n0: f64 = v.iter().map(|x| x * x).sum::<f64>();
                for _ in 0..2 {
                    for q in &kept {
                        let d: f64 = v.iter().zip(q).map(|(a, b)| a * b).sum();
                        v.iter_mut().zip(q).for_each(|(a, b)| *a -= d * b);
                    }
                }
                let nn: f64 = v.iter().map(|x| x * x).sum::<f64>();
                if nn > 1e-16 * n0.max(1e-30) && nn > 1e-20 * scale {
                    let s = 1.0 / nn.sqrt();
                    v.iter_mut().for_each(|x| *x *= s);
                    kept.push(v);
                }
            }
            for (mi, q) in kept.iter().enumerate() {
                for (k, &i) in m.iter().enumerate() {
                    for d in 0..3 {
                        basis[i as usize][3 * mi + d] = q[3 * k + d];
                    }
                }
            }
            offset.push(offset.last().expect("nonempty") + kept.len());
        }
        Self {
            agg,
            members,
            offset,
            basis,
            solver: SpdSolver::new(),
            factorised: false,
        }
    }

    /// Coarse unknowns (modes over all aggregates).
    pub fn size(&self) -> usize {
        *self.offset.last().expect("offset has a first entry")
    }

    /// Number of aggregates.
    pub fn aggregates(&self) -> usize {
        self.members.len()
    }

    fn dim(&self, g: usize) -> usize {
        self.offset[g + 1] - self.offset[g]
    }

    /// Compute A_c = Pᵀ A P and factorise it (sparse Cholesky, symbolic analysis reused).
    pub fn factorize(&mut self, a: &BlockCsr) -> Result<(), SparseError> {
        let nc = self.size();
        let trip: Vec<Vec<(usize, usize, f64)>> = (0..self.members.len())
            .into_par_iter()
            .map(|g| {
                let kg = self.dim(g);
                let mut blocks: HashMap<u32, [f64; 36]> = HashMap::new();
                for &i in &self.members[g] {
                    let i = i as usize;
                    let pi = &self.basis[i];
                    for k in a.ptr[i]..a.ptr[i + 1] {
                        let j = a.col[k] as usize;
                        let h = self.agg[j];
                        let kh = self.dim(h as usize);
                        let blk = &a.val[9 * k..9 * k + 9];
                        let pj = &self.basis[j];
                        // T = A_ij P_j (3 × kh), then P_iᵀ T (kg × kh).
                        let mut t = [[0.0; 3]; 6];
                        for m in 0..kh {
                            for r in 0..3 {
                                t[m][r] = blk[3 * r] * pj[3 * m]
                                    + blk[3 * r + 1] * pj[3 * m + 1]
                                    + blk[3 * r + 2] * pj[3 * m + 2];
                            }
                        }
                        let out = blocks.entry(h).or_insert([0.0; 36]);
                        for l in 0..kg {
                            for m in 0..kh {
                                out[6 * l + m] += pi[3 * l] * t[m][0]
                                    + pi[3 * l + 1] * t[m][1]
                                    + pi[3 * l + 2] * t[m][2];
                            }
                        }
                    }
                }
                let mut keys: Vec<u32> = blocks.keys().copied().collect();
                keys.sort_unstable();
                let mut out = Vec::new();
                for h in keys {
                    let b = &blocks[&h];
                    let (o0, o1) = (self.offset[g], self.offset[h as usize]);
                    for l in 0..kg {
                        for m in 0..self.dim(h as usize) {
                            out.push((o0 + l, o1 + m, b[6 * l + m]));
                        }
                    }
                }
                out
            })
            .collect();
        let t: Vec<(usize, usize, f64)> = trip.into_iter().flatten().collect();
        let ac = assemble(nc, nc, &t)?;
        self.factorised = false;
        self.solver.factorize(&ac)?;
        self.factorised = true;
        Ok(())
    }

    /// Whether a factorisation is available for [`Self::apply_add`].
    pub fn is_factorised(&self) -> bool {
        self.factorised
    }

    /// z += P A_c⁻¹ Pᵀ r; returns rᵀ P A_c⁻¹ Pᵀ r.
    pub fn apply_add(&self, r: &[f64], z: &mut [f64]) -> f64 {
        let rc: Vec<Vec<f64>> = (0..self.members.len())
            .into_par_iter()
            .map(|g| {
                let kg = self.dim(g);
                let mut s = vec![0.0; kg];
                for &i in &self.members[g] {
                    let i = i as usize;
                    let p = &self.basis[i];
                    for (m, sm) in s.iter_mut().enumerate() {
                        *sm += p[3 * m] * r[3 * i]
                            + p[3 * m + 1] * r[3 * i + 1]
                            + p[3 * m + 2] * r[3 * i + 2];
                    }
                }
                s
            })
            .collect();
        let mut rc: Vec<f64> = rc.into_iter().flatten().collect();
        let rhs = rc.clone();
        self.solver.solve_in_place(&mut rc);
        let dot: f64 = rhs.iter().zip(&rc).map(|(a, b)| a * b).sum();
        z.par_chunks_mut(3 * CHUNK_NODES)
            .enumerate()
            .for_each(|(c, zc)| {
                for (k, za) in zc.chunks_exact_mut(3).enumerate() {
                    let i = c * CHUNK_NODES + k;
                    let g = self.agg[i] as usize;
                    let p = &self.basis[i];
                    for m in 0..self.dim(g) {
                        let e = rc[self.offset[g] + m];
                        for d in 0..3 {
                            za[d] += p[3 * m + d] * e;
                        }
                    }
                }
            });
        dot
    }
}

/// Preconditioned conjugate gradients for A x = b (A symmetric positive definite, node
/// blocks): block Jacobi `inv` (from [`BlockCsr::diag_inverses`]) plus the coarse
/// correction when given and factorised. Stops at ‖r‖ ≤ `rel_tol` ‖b‖ or after `max_iter`
/// iterations; returns the solution and the iterations used. `guess` (length `b.len()`)
/// is scaled to minimise the quadratic along it and used as the start when its residual is
/// below ‖b‖.
pub fn pcg(
    a: &impl SymOperator,
    inv: &[[f64; 9]],
    coarse: Option<&Coarse>,
    b: &[f64],
    guess: Option<&[f64]>,
    rel_tol: f64,
    max_iter: usize,
) -> (Vec<f64>, usize) {
    let n = b.len();
    let coarse = coarse.filter(|c| c.is_factorised());
    let dot = |u: &[f64], v: &[f64]| -> f64 {
        let part: Vec<f64> = u
            .par_chunks(3 * CHUNK_NODES)
            .zip(v.par_chunks(3 * CHUNK_NODES))
            .map(|(p, q)| p.iter().zip(q).map(|(x, y)| x * y).sum::<f64>())
            .collect();
        part.iter().sum()
    };
    let mut x = vec![0.0; n];
    let mut r = b.to_vec();
    let bn = dot(b, b).sqrt();
    if bn == 0.0 {
        return (x, 0);
    }
    let mut ap = vec![0.0; n];
    if let Some(g) = guess.filter(|g| g.len() == n) {
        let gag = a.apply(g, &mut ap);
        if gag > 0.0 {
            let alpha = dot(g, b) / gag;
            let r0: Vec<f64> = b.iter().zip(&ap).map(|(bi, ai)| bi - alpha * ai).collect();
            if dot(&r0, &r0).sqrt() < bn {
                x.iter_mut().zip(g).for_each(|(xi, gi)| *xi = alpha * gi);
                r = r0;
            }
        }
    }
    // z = M⁻¹ r; returns (rᵀ z, rᵀ r). `step` first applies x += α p, r −= α Ap.
    let precondition = |alpha: f64,
                        x: &mut [f64],
                        r: &mut [f64],
                        z: &mut [f64],
                        p: &[f64],
                        ap: &[f64]|
     -> (f64, f64) {
        let parts: Vec<(f64, f64)> = x
            .par_chunks_mut(3 * CHUNK_NODES)
            .zip(r.par_chunks_mut(3 * CHUNK_NODES))
            .zip(z.par_chunks_mut(3 * CHUNK_NODES))
            .enumerate()
            .map(|(c, ((xc, rc), zc))| {
                let o = 3 * c * CHUNK_NODES;
                let (mut rz, mut rr) = (0.0, 0.0);
                if alpha != 0.0 {
                    for k in 0..xc.len() {
                        xc[k] += alpha * p[o + k];
                        rc[k] -= alpha * ap[o + k];
                    }
                }
                for (k, (ra, za)) in rc.chunks_exact(3).zip(zc.chunks_exact_mut(3)).enumerate() {
                    let m = &inv[c * CHUNK_NODES + k];
                    for i in 0..3 {
                        za[i] = m[3 * i] * ra[0] + m[3 * i + 1] * ra[1] + m[3 * i + 2] * ra[2];
                        rz += ra[i] * za[i];
                        rr += ra[i] * ra[i];
                    }
                }
                (rz, rr)
            })
            .collect();
        let (mut rz, mut rr) = (0.0, 0.0);
        for (a, b) in parts {
            rz += a;
            rr += b;
        }
        if let Some(cs) = coarse {
            rz += cs.apply_add(r, z);
        }
        (rz, rr)
    };
    let mut z = vec![0.0; n];
    let mut p = vec![0.0; n];
    let (mut rz, _) = precondition(0.0, &mut x, &mut r, &mut z, &p, &ap);
    p.copy_from_slice(&z);
    for it in 1..=max_iter {
        let pap = a.apply(&p, &mut ap);
        if pap <= 0.0 {
            return (x, it);
        }
        let alpha = rz / pap;
        let (rz2, rr) = precondition(alpha, &mut x, &mut r, &mut z, &p, &ap);
        if rr.sqrt() <= rel_tol * bn {
            return (x, it);
        }
        let beta = rz2 / rz;
        rz = rz2;
        p.par_chunks_mut(3 * CHUNK_NODES)
            .zip(z.par_chunks(3 * CHUNK_NODES))
            .for_each(|(pc, zc)| {
                for (pi, zi) in pc.iter_mut().zip(zc) {
                    *pi = zi + beta * *pi;
                }
            });
    }
    (x, max_iter)
}
