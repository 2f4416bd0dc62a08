//! Solves of the KKT system by GMRES on the unregularised double-precision matrix,
//! preconditioned with the factor (fresh, or lagged behind the assembled matrix), and the
//! products with the assembled matrix they need: the KKT operator and the curvature dᵀK d.

use super::KktSolver;
use crate::math::sparse::mul_sym_lower_into;
use crate::solver::gmres::{fgmres, GmresReport};
use faer::sparse::SparseColMat;
use rayon::prelude::*;

/// Columns per parallel chunk of [`KktSolver::curvature`].
const CURVATURE_CHUNK: usize = 4096;

impl KktSolver {
    /// Solve the *unregularised* KKT system (τ kept, δ removed) of the last factorised
    /// matrix for `rhs` in place by GMRES preconditioned with its factor (see
    /// [`crate::solver::gmres`]), with at most `refine` + 1 factor solves, stopping once the
    /// residual is below `rel_tol` of ‖rhs‖. Returns the linear solves with the factor that
    /// were used.
    pub fn solve(&mut self, rhs: &mut [f64], refine: usize, rel_tol: f64) -> usize {
        assert!(
            self.factored,
            "KktSolver::solve before a successful factorize"
        );
        self.krylov(rhs, false, refine + 1, rel_tol)
            .iterations
            .max(1)
    }

    /// Solve the unregularised, unshifted KKT system of the matrix last *assembled* (which
    /// may be newer than the last factorisation: a later Newton iterate's Hessian) for `rhs`
    /// in place by GMRES preconditioned with the last factor (a lagged factor), with at most
    /// `max_solves` factor solves and relative tolerance `rel_tol`.
    pub fn solve_lagged(
        &mut self,
        rhs: &mut [f64],
        max_solves: usize,
        rel_tol: f64,
    ) -> GmresReport {
        assert!(
            self.factored,
            "KktSolver::solve_lagged before a successful factorize"
        );
        self.krylov(rhs, true, max_solves, rel_tol)
    }

    /// GMRES on the factored (`assembled = false`) or the last assembled matrix with δ
    /// removed, preconditioned by the current factor. Only the lagged solve (on the
    /// assembled matrix) may give up early: a fresh factor is as good as it gets.
    fn krylov(
        &mut self,
        rhs: &mut [f64],
        assembled: bool,
        max_solves: usize,
        rel_tol: f64,
    ) -> GmresReport {
        let b = rhs.to_vec();
        let (nf, nc) = (self.n_free, self.n_cons);
        let (delta, shift) = if assembled {
            (self.delta, 0.0)
        } else {
            (self.factor_delta, self.shift)
        };
        let from_base = assembled || self.base_is_factored;
        let a = if from_base {
            self.base.take().expect("assembled matrix")
        } else {
            self.matrix.take().expect("factored matrix")
        };
        let diag = std::mem::take(&mut self.diag_pos);
        let rep = {
            let this = &mut *self;
            fgmres(
                |v, out| kkt_mul((&a, &diag), (nf, nc), (delta, shift), &[], v, out),
                |v| this.raw_solve(v),
                &b,
                rhs,
                rel_tol.max(1e-15),
                max_solves.max(1),
                assembled,
            )
        };
        self.diag_pos = diag;
        if from_base {
            self.base = Some(a);
        } else {
            self.matrix = Some(a);
        }
        rep
    }

    /// Curvature dᵀ K d (J/m² times the units of d²) of the last assembled Hessian along
    /// `d`, a vector over the free dofs: from the lower triangle, Σ_j d_j (K_jj d_j + 2 Σ_{i>j}
    /// K_ij d_i), in fixed chunks of columns summed in order (the same bits on any number of
    /// threads).
    pub fn curvature(&self, d: &[f64]) -> f64 {
        let a = self
            .base
            .as_ref()
            .expect("KktSolver::curvature before assemble");
        let (cp, ri, val) = (a.col_ptr(), a.row_idx(), a.val());
        let nf = self.n_free.min(d.len());
        let column = |j: usize| {
            let range = self.diag_pos[j]..cp[j + 1];
            let off: f64 = range
                .clone()
                .skip(1)
                .take_while(|&q| ri[q] < nf)
                .map(|q| val[q] * d[ri[q]])
                .sum();
            d[j] * (val[range.start] * d[j] + 2.0 * off)
        };
        let chunks: Vec<f64> = (0..nf.div_ceil(CURVATURE_CHUNK))
            .into_par_iter()
            .map(|c| {
                (c * CURVATURE_CHUNK..((c + 1) * CURVATURE_CHUNK).min(nf))
                    .map(column)
                    .sum()
            })
            .collect();
        chunks.iter().sum()
    }

    /// GMRES on the last assembled matrix with δ removed and `shifts` (KKT index, N/m) added
    /// to its diagonal, preconditioned by the current (lagged) factor followed by
    /// `correct(a, r, z)`, which may improve z ≈ A⁻¹ r given the assembled matrix `a` and the
    /// preconditioned vector's input `r`; at most `max_solves` iterations, relative tolerance
    /// `rel_tol`, giving up early when hopeless.
    pub(crate) fn solve_lagged_with(
        &mut self,
        rhs: &mut [f64],
        max_solves: usize,
        rel_tol: f64,
        shifts: &[(usize, f64)],
        mut correct: impl FnMut(&SparseColMat<usize, f64>, &[f64], &mut [f64]),
    ) -> GmresReport {
        assert!(
            self.factored,
            "solve_lagged_with before a successful factorize"
        );
        let b = rhs.to_vec();
        let (nf, nc, delta) = (self.n_free, self.n_cons, self.delta);
        let a = self.base.take().expect("assembled matrix");
        let diag = std::mem::take(&mut self.diag_pos);
        let mut r = vec![0.0; nf + nc];
        let rep = {
            let this = &mut *self;
            fgmres(
                |v, out| kkt_mul((&a, &diag), (nf, nc), (delta, 0.0), shifts, v, out),
                |v| {
                    r.copy_from_slice(v);
                    this.raw_solve(v);
                    correct(&a, &r, v);
                },
                &b,
                rhs,
                rel_tol.max(1e-15),
                max_solves.max(1),
                true,
            )
        };
        self.diag_pos = diag;
        self.base = Some(a);
        rep
    }
}

/// out = (A + τ I on the free block + δ I on the constraint block + `shifts` on the
/// diagonal) v: the KKT operator GMRES solves, from the assembled KKT matrix `a` (read by its
/// lower triangle, `diag` its diagonal slots) of `sizes`
/// = (free dofs, constraint rows), with δ (the regularisation the factor carries) removed
/// again and the uniform shift τ and the diagonal `shifts` (KKT index, N/m) added.
pub(super) fn kkt_mul(
    (a, diag): (&SparseColMat<usize, f64>, &[usize]),
    (nf, nc): (usize, usize),
    (delta, tau): (f64, f64),
    shifts: &[(usize, f64)],
    v: &[f64],
    out: &mut [f64],
) {
    mul_sym_lower_into(a, diag, v, out);
    if tau != 0.0 {
        for i in 0..nf {
            out[i] += tau * v[i];
        }
    }
    for i in nf..nf + nc {
        out[i] += delta * v[i];
    }
    for &(i, t) in shifts {
        out[i] += t * v[i];
    }
}
