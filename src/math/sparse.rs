//! Sparse assembly with a reusable pattern, and sparse direct solves (faer).
//!
//! Physical layers emit element contributions as `(row, col, value)` triplets. The first
//! assembly computes the compressed column pattern and the permutation that sums duplicates;
//! later assemblies with the same triplet order only refill values ([`Pattern::assemble`]),
//! and the symbolic Cholesky factorisation is reused across iterations and frames.

use faer::linalg::solvers::Solve;
use faer::sparse::linalg::solvers::{Llt, SymbolicLlt};
use faer::sparse::{Argsort, Pair, SparseColMat, SymbolicSparseColMat};
use faer::{MatMut, Side};

/// Errors from sparse assembly and factorisation.
#[derive(Debug, thiserror::Error)]
pub enum SparseError {
    /// The triplet list does not match the pattern it is assembled into.
    #[error("triplet count {got} does not match the assembled pattern ({expected})")]
    PatternMismatch {
        /// Triplets in the stored pattern.
        expected: usize,
        /// Triplets given now.
        got: usize,
    },
    /// An index is out of range or the pattern could not be built.
    #[error("could not build sparse pattern: {0}")]
    Build(String),
    /// The matrix is not (numerically) symmetric positive definite.
    #[error("matrix is not positive definite (Cholesky failed)")]
    NotPositiveDefinite,
}

/// A compressed sparse column pattern built from one triplet layout, reusable for refills.
pub struct Pattern {
    n: usize,
    triplet_count: usize,
    symbolic: SymbolicSparseColMat<usize>,
    argsort: Argsort<usize>,
}

impl Pattern {
    /// Build the pattern of an `n × n` matrix from the indices of `triplets` (values ignored).
    pub fn new(n: usize, triplets: &[(usize, usize, f64)]) -> Result<Self, SparseError> {
        let idx: Vec<Pair<usize, usize>> = triplets
            .iter()
            .map(|&(r, c, _)| Pair { row: r, col: c })
            .collect();
        let (symbolic, argsort) = SymbolicSparseColMat::try_new_from_indices(n, n, &idx)
            .map_err(|e| SparseError::Build(format!("{e:?}")))?;
        Ok(Self {
            n,
            triplet_count: triplets.len(),
            symbolic,
            argsort,
        })
    }

    /// Matrix size.
    pub fn n(&self) -> usize {
        self.n
    }

    /// Sum `triplets` (same layout as at construction) into a compressed matrix.
    pub fn assemble(
        &self,
        triplets: &[(usize, usize, f64)],
    ) -> Result<SparseColMat<usize, f64>, SparseError> {
        if triplets.len() != self.triplet_count {
            return Err(SparseError::PatternMismatch {
                expected: self.triplet_count,
                got: triplets.len(),
            });
        }
        let vals: Vec<f64> = triplets.iter().map(|t| t.2).collect();
        SparseColMat::new_from_argsort(self.symbolic.clone(), &self.argsort, &vals)
            .map_err(|e| SparseError::Build(format!("{e:?}")))
    }
}

/// Assemble triplets into a compressed `nrows × ncols` matrix (duplicates summed), one-off.
pub fn assemble(
    nrows: usize,
    ncols: usize,
    triplets: &[(usize, usize, f64)],
) -> Result<SparseColMat<usize, f64>, SparseError> {
    let t: Vec<faer::sparse::Triplet<usize, usize, f64>> = triplets
        .iter()
        .map(|&(r, c, v)| faer::sparse::Triplet::new(r, c, v))
        .collect();
    SparseColMat::try_new_from_triplets(nrows, ncols, &t)
        .map_err(|e| SparseError::Build(format!("{e:?}")))
}

/// Sparse Cholesky (LLᵀ) solver for symmetric positive definite systems, caching the
/// symbolic analysis (fill-reducing ordering and elimination tree) for its pattern.
#[derive(Default)]
pub struct SpdSolver {
    symbolic: Option<SymbolicLlt<usize>>,
    factor: Option<Llt<usize, f64>>,
}

impl SpdSolver {
    /// A solver with no cached analysis.
    pub fn new() -> Self {
        Self::default()
    }

    /// Factorise `a` (both triangles stored, only the lower one read). The symbolic analysis
    /// is computed on the first call and reused while the pattern is unchanged.
    pub fn factorize(&mut self, a: &SparseColMat<usize, f64>) -> Result<(), SparseError> {
        let same = match &self.symbolic {
            Some(_) => self.factor.is_some(),
            None => false,
        };
        if !same {
            let s = SymbolicLlt::try_new(a.symbolic(), Side::Lower)
                .map_err(|e| SparseError::Build(format!("{e:?}")))?;
            self.symbolic = Some(s);
        }
        let sym = self.symbolic.clone().expect("symbolic set above");
        match Llt::try_new_with_symbolic(sym, a.as_ref(), Side::Lower) {
            Ok(f) => {
                self.factor = Some(f);
                Ok(())
            }
            Err(_) => {
                self.factor = None;
                Err(SparseError::NotPositiveDefinite)
            }
        }
    }

    /// Forget the cached analysis (call when the pattern changes).
    pub fn reset(&mut self) {
        self.symbolic = None;
        self.factor = None;
    }

    /// Solve A x = b in place (b overwritten by x). Panics if not factorised.
    pub fn solve_in_place(&self, b: &mut [f64]) {
        let f = self
            .factor
            .as_ref()
            .expect("SpdSolver::solve before factorize");
        let n = b.len();
        let m = MatMut::from_column_major_slice_mut(b, n, 1);
        f.solve_in_place(m);
    }
}

/// y += A x for A given by triplets `(row, column, value)` (duplicates summed).
pub fn triplets_mul_add(a: &[(usize, usize, f64)], x: &[f64], y: &mut [f64]) {
    for &(r, c, v) in a {
        y[r] += v * x[c];
    }
}

/// Dense row-major copy of an `n × n` matrix given by triplets (for tests and small checks).
pub fn dense_from_triplets(n: usize, triplets: &[(usize, usize, f64)]) -> Vec<f64> {
    let mut d = vec![0.0; n * n];
    for &(r, c, v) in triplets {
        d[r * n + c] += v;
    }
    d
}

/// y = A x for a compressed matrix.
pub fn mul_vec(a: &SparseColMat<usize, f64>, x: &[f64]) -> Vec<f64> {
    let mut y = vec![0.0; a.nrows()];
    mul_vec_into(a, x, &mut y);
    y
}

/// y = A x into `y` (overwritten; length `a.nrows()`).
pub fn mul_vec_into(a: &SparseColMat<usize, f64>, x: &[f64], y: &mut [f64]) {
    y.fill(0.0);
    let ar = a.as_ref();
    for j in 0..a.ncols() {
        let xj = x[j];
        if xj == 0.0 {
            continue;
        }
        for (i, v) in ar.row_idx_of_col(j).zip(ar.val_of_col(j)) {
            y[i] += v * xj;
        }
    }
}

/// Column ranges of the fixed chunks [`mul_sym_lower_into`] splits a product into.
const PRODUCT_CHUNKS: usize = 4;

/// y = A x for a symmetric `a` read from its lower triangle only: column j's entries from
/// its diagonal slot `diag[j]` down (rows ≥ j, as a sorted compressed column stores them),
/// half the memory traffic of [`mul_sym_vec_into`] (every column must hold its diagonal). Column j adds a_jj x_j + Σ a_ij x_i to y_j
/// and a_ij x_j to each y_i below; the columns are split into a fixed number of chunks of
/// about equal entries, each summed into its own vector in parallel, then added in order, so
/// the result does not depend on the thread count.
pub fn mul_sym_lower_into(a: &SparseColMat<usize, f64>, diag: &[usize], x: &[f64], y: &mut [f64]) {
    use rayon::prelude::*;
    let (cp, ri, val) = (a.col_ptr(), a.row_idx(), a.val());
    let n = a.ncols();
    let lower = |j: usize| diag[j]..cp[j + 1];
    let total: usize = (0..n).map(|j| lower(j).len()).sum();
    let mut bounds = vec![0];
    let mut acc = 0;
    for j in 0..n {
        acc += lower(j).len();
        if acc * PRODUCT_CHUNKS >= total * bounds.len() && bounds.len() < PRODUCT_CHUNKS {
            bounds.push(j + 1);
        }
    }
    bounds.push(n);
    bounds.dedup();
    let parts: Vec<(usize, Vec<f64>)> = bounds
        .par_windows(2)
        .map(|w| {
            let (start, end) = (w[0], w[1]);
            let mut z = vec![0.0; n - start];
            for j in start..end {
                let (xj, range) = (x[j], lower(j));
                let mut yj = 0.0;
                for q in range.clone().skip(1) {
                    let i = ri[q];
                    yj += val[q] * x[i];
                    z[i - start] += val[q] * xj;
                }
                debug_assert_eq!(ri[range.start], j, "diag[{j}] is the diagonal slot");
                z[j - start] += yj + val[range.start] * xj;
            }
            (start, z)
        })
        .collect();
    y.iter_mut().for_each(|v| *v = 0.0);
    for (start, z) in parts {
        for (yi, zi) in y[start..].iter_mut().zip(z) {
            *yi += zi;
        }
    }
}

/// y = A x for a structurally and numerically symmetric `a` stored with both triangles: each
/// yᵢ is the dot product of column i with x (= row i), so rows are computed in parallel
/// without write conflicts; the sum over a column runs in its stored order, so the result does
/// not depend on the thread count.
pub fn mul_sym_vec_into(a: &SparseColMat<usize, f64>, x: &[f64], y: &mut [f64]) {
    use rayon::prelude::*;
    let ar = a.as_ref();
    y.par_iter_mut()
        .with_min_len(2048)
        .enumerate()
        .for_each(|(i, yi)| {
            *yi = ar
                .row_idx_of_col(i)
                .zip(ar.val_of_col(i))
                .map(|(j, v)| v * x[j])
                .sum();
        });
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The lower-triangle product equals the full one on a random symmetric matrix with a
    /// stored diagonal in every column (to round-off: the sums run in another order).
    #[test]
    fn lower_triangle_product_equals_the_full_one() {
        let n = 300;
        let mut rng = crate::math::rng::Lcg::new(7);
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, rng.next_f64() + 1.0));
            for _ in 0..5 {
                let j = (rng.next_f64() * n as f64) as usize % n;
                if j != i {
                    let v = rng.next_f64() - 0.5;
                    t.push((i, j, v));
                    t.push((j, i, v));
                }
            }
        }
        let a = Pattern::new(n, &t).unwrap().assemble(&t).unwrap();
        let diag: Vec<usize> = (0..n)
            .map(|j| {
                let (cp, ri) = (a.col_ptr(), a.row_idx());
                cp[j] + ri[cp[j]..cp[j + 1]].binary_search(&j).unwrap()
            })
            .collect();
        let x: Vec<f64> = (0..n).map(|_| rng.next_f64() - 0.5).collect();
        let (mut y_full, mut y_lower) = (vec![0.0; n], vec![1.0; n]);
        mul_sym_vec_into(&a, &x, &mut y_full);
        mul_sym_lower_into(&a, &diag, &x, &mut y_lower);
        for (a, b) in y_full.iter().zip(&y_lower) {
            assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        }
    }

    /// 1D Laplacian with Dirichlet ends: the solution of A x = 1 is x_i = (i+1)(n-i)/2.
    #[test]
    fn spd_solver_solves_laplacian_and_reuses_pattern() {
        let n = 50;
        let mut t = Vec::new();
        for i in 0..n {
            t.push((i, i, 2.0));
            if i + 1 < n {
                t.push((i, i + 1, -1.0));
                t.push((i + 1, i, -1.0));
            }
        }
        let pat = Pattern::new(n, &t).unwrap();
        let a = pat.assemble(&t).unwrap();
        let mut s = SpdSolver::new();
        for scale in [1.0, 3.0] {
            let ts: Vec<_> = t.iter().map(|&(r, c, v)| (r, c, v * scale)).collect();
            let a2 = pat.assemble(&ts).unwrap();
            s.factorize(&a2).unwrap();
            let mut b = vec![1.0; n];
            s.solve_in_place(&mut b);
            for (i, bi) in b.iter().enumerate() {
                let exact = ((i + 1) * (n - i)) as f64 / 2.0 / scale;
                assert!(
                    (bi - exact).abs() < 1e-9 * exact.max(1.0),
                    "{i}: {bi} vs {exact}"
                );
            }
        }
        let y = mul_vec(&a, &vec![1.0; n]);
        assert_eq!(y[0], 1.0);
        assert_eq!(y[n / 2], 0.0);
        assert!(pat.assemble(&t[1..]).is_err());
        let mut neg = t.clone();
        neg[0].2 = -5.0;
        assert!(s.factorize(&pat.assemble(&neg).unwrap()).is_err());
    }
}
