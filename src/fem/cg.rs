//! Preconditioned conjugate gradients on symmetric node-block (3 × 3) sparse matrices: the
//! iterative solver of the lattice's Newton systems [M + h²K] Δy = r.
//!
//! The matrix is held with both triangles in block compressed rows ([`BlockCsr`]), so each
//! output node of a product is computed on its own (no scatter, no per-thread accumulators).
//! Every parallel loop works on a fixed split of the nodes and dot products add the
//! per-chunk partial sums in chunk order: results have the same bits for any thread count.
//! The preconditioner is 3 × 3 block Jacobi: on the interior's systems a two-level correction
//! saves few iterations for more than it costs to build.

use rayon::prelude::*;

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

/// Sum of products over fixed chunks, added in chunk order (the bits of a parallel
/// chunked sum, computed serially: vectors here are short).
fn dot(u: &[f64], v: &[f64]) -> f64 {
    u.chunks(3 * CHUNK_NODES)
        .zip(v.chunks(3 * CHUNK_NODES))
        .map(|(p, q)| p.iter().zip(q).map(|(x, y)| x * y).sum::<f64>())
        .sum()
}

/// Preconditioned conjugate gradients for A x = b (A symmetric positive definite, node
/// blocks) with the 3 × 3 block-Jacobi preconditioner `inv` (inverse diagonal blocks,
/// row-major, e.g. from [`BlockCsr::diag_inverses`]). Stops at ‖r‖ ≤ `rel_tol` ‖b‖ or after `max_iter`
/// iterations; returns the solution and the iterations used. `guess` (length `b.len()`)
/// is scaled to minimise the quadratic along it and used as the start when its residual is
/// below ‖b‖. Only the products with A run in parallel; the vector updates (a few
/// thousand entries) are serial, fused into two passes per iteration.
pub fn pcg(
    a: &impl SymOperator,
    inv: &[[f64; 9]],
    b: &[f64],
    guess: Option<&[f64]>,
    rel_tol: f64,
    max_iter: usize,
) -> (Vec<f64>, usize) {
    let n = b.len();
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
    // x += α p, r −= α Ap, z = M⁻¹ r; returns (rᵀ z, rᵀ r), chunk sums in order.
    let step = |alpha: f64,
                x: &mut [f64],
                r: &mut [f64],
                z: &mut [f64],
                p: &[f64],
                ap: &[f64]|
     -> (f64, f64) {
        let (mut rz, mut rr) = (0.0, 0.0);
        for c in 0..n.div_ceil(3 * CHUNK_NODES) {
            let (lo, hi) = (3 * c * CHUNK_NODES, (3 * (c + 1) * CHUNK_NODES).min(n));
            let (mut crz, mut crr) = (0.0, 0.0);
            if alpha != 0.0 {
                for k in lo..hi {
                    x[k] += alpha * p[k];
                    r[k] -= alpha * ap[k];
                }
            }
            for nd in lo / 3..hi / 3 {
                let m = &inv[nd];
                let ra = [r[3 * nd], r[3 * nd + 1], r[3 * nd + 2]];
                for i in 0..3 {
                    let zi = m[3 * i] * ra[0] + m[3 * i + 1] * ra[1] + m[3 * i + 2] * ra[2];
                    z[3 * nd + i] = zi;
                    crz += ra[i] * zi;
                    crr += ra[i] * ra[i];
                }
            }
            rz += crz;
            rr += crr;
        }
        (rz, rr)
    };
    let mut z = vec![0.0; n];
    let mut p = vec![0.0; n];
    let (mut rz, _) = step(0.0, &mut x, &mut r, &mut z, &p, &ap);
    p.copy_from_slice(&z);
    for it in 1..=max_iter {
        let pap = a.apply(&p, &mut ap);
        if pap <= 0.0 {
            return (x, it);
        }
        let alpha = rz / pap;
        let (rz2, rr) = step(alpha, &mut x, &mut r, &mut z, &p, &ap);
        if rr.sqrt() <= rel_tol * bn {
            return (x, it);
        }
        let beta = rz2 / rz;
        rz = rz2;
        for (pi, zi) in p.iter_mut().zip(&z) {
            *pi = zi + beta * *pi;
        }
    }
    (x, max_iter)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Lcg;
    use nalgebra::{DMatrix, DVector};

    /// A random SPD node-block system: Σ over coupled node pairs of GᵀG (G random 6 × 6 on
    /// the pair's DOFs) plus 1e-2 I, pairs (a, a+1) and (a, a+5); as a BlockCsr and densely.
    fn random_spd(nodes: usize, seed: u64) -> (BlockCsr, DMatrix<f64>) {
        let mut rng = Lcg::from_state(seed);
        let n = 3 * nodes;
        let mut d = DMatrix::<f64>::identity(n, n) * 1e-2;
        let mut rows: Vec<Vec<u32>> = (0..nodes).map(|a| vec![a as u32]).collect();
        for a in 0..nodes {
            for off in [1, 5] {
                let b = a + off;
                if b >= nodes {
                    continue;
                }
                rows[a].push(b as u32);
                rows[b].push(a as u32);
                let g = DMatrix::<f64>::from_fn(6, 6, |_, _| rng.next_signed());
                let gg = g.transpose() * g;
                let idx = [3 * a, 3 * a + 1, 3 * a + 2, 3 * b, 3 * b + 1, 3 * b + 2];
                for i in 0..6 {
                    for j in 0..6 {
                        d[(idx[i], idx[j])] += gg[(i, j)];
                    }
                }
            }
        }
        for r in &mut rows {
            r.sort_unstable();
        }
        let mut m = BlockCsr::from_pattern(&rows);
        for a in 0..nodes {
            for k in m.ptr[a]..m.ptr[a + 1] {
                let b = m.col[k] as usize;
                for i in 0..3 {
                    for j in 0..3 {
                        m.val[9 * k + 3 * i + j] = d[(3 * a + i, 3 * b + j)];
                    }
                }
            }
        }
        (m, d)
    }

    fn rhs(n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Lcg::from_state(seed);
        (0..n).map(|_| rng.next_signed()).collect()
    }

    #[test]
    fn block_product_matches_the_dense_matrix() {
        let (m, d) = random_spd(150, 7);
        let x = rhs(450, 3);
        let mut y = vec![0.0; 450];
        let xax = m.mul(&x, &mut y);
        let yd = &d * DVector::from_column_slice(&x);
        for i in 0..450 {
            assert!((y[i] - yd[i]).abs() < 1e-12 * yd.amax(), "{i}");
        }
        let xd = DVector::from_column_slice(&x);
        assert!((xax - xd.dot(&yd)).abs() < 1e-12 * xax.abs());
    }

    /// PCG meets its tolerance on the true residual and matches a dense solve.
    #[test]
    fn pcg_solves_a_random_spd_block_system_to_its_tolerance() {
        let (m, d) = random_spd(200, 11);
        let b = rhs(600, 5);
        let bd = DVector::from_column_slice(&b);
        let exact = d.clone().cholesky().expect("SPD").solve(&bd);
        let inv = m.diag_inverses();
        for tol in [1e-3, 1e-6, 1e-10] {
            let (x, it) = pcg(&m, &inv, &b, None, tol, 10_000);
            assert!(it < 10_000, "did not converge at {tol}");
            let xd = DVector::from_column_slice(&x);
            let res = (&bd - &d * &xd).norm() / bd.norm();
            assert!(res <= tol, "tol {tol}: residual {res}");
            if tol == 1e-10 {
                let err = (&xd - &exact).norm() / exact.norm();
                assert!(err < 1e-6, "error {err}");
            }
        }
        // Started from the solution, it stops at once.
        let (_, it) = pcg(&m, &inv, &b, Some(exact.as_slice()), 1e-6, 100);
        assert!(it <= 1, "{it} iterations from the exact start");
    }

    /// Same bits for one thread and for three (fixed chunks, in-order sums).
    #[test]
    fn pcg_is_independent_of_the_thread_count() {
        let (m, _) = random_spd(300, 13);
        let b = rhs(900, 17);
        let inv = m.diag_inverses();
        let run = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
                .install(|| pcg(&m, &inv, &b, None, 1e-8, 5000))
        };
        let (x1, i1) = run(1);
        let (x3, i3) = run(3);
        assert_eq!(i1, i3);
        assert!(x1.iter().zip(&x3).all(|(a, b)| a.to_bits() == b.to_bits()));
    }
}
