//! Sparse symmetric KKT solve for equality-constrained Newton steps.
//!
//! The system (free dofs only, pinned dofs removed) is
//!
//! ```text
//! [ K + τI   γCᵀ ] [Δx]   [a]
//! [ γC      −δI  ] [μ ] = [b]
//! ```
//!
//! with γ balancing the rows (N/m), τ an optional shift of the free diagonal (τ ≥ 0 from the
//! Newton solver's inertia correction) and δ (1e-6 γ from the Newton solver) a small
//! negative regularisation of the constraint block.
//!
//! Why this method: the KKT matrix is symmetric indefinite. With δ > 0 and K + τI positive
//! definite it is *quasi-definite*, so an LDLᵀ factorisation without pivoting exists for any
//! symmetric ordering (Vanderbei 1995). The ordering can therefore be chosen for fill alone:
//! each new layout is analysed with METIS's nested dissection ([`crate::solver::ordering`])
//! and with AMD, and the symbolic factorisation that needs fewer flops is kept and reused
//! across Newton iterations and frames while the layout stays. The numeric LDLᵀ (no pivoting,
//! no dynamic regularisation) runs across the elimination tree on two cores
//! ([`crate::solver::tree_factor`]) when the analysis is supernodal and has a two-core plan,
//! else as faer's sequential factorisation, in double or single precision
//! ([`FactorPrecision`]). It costs the same as a Cholesky of the same pattern, about half of
//! a sparse LU with partial pivoting, and unlike a null-space method it keeps the sparsity of
//! the cluster constraints. The error δ introduces (and a single-precision factor's
//! round-off) is removed by GMRES on the unregularised double-precision matrix preconditioned
//! with the factor ([`crate::solver::gmres`]); the same GMRES lets a factor of an earlier
//! Newton iterate serve later ones (a lagged factor). A bonus: by Sylvester's law of inertia
//! the signs of D tell whether K is positive definite on the null space of C (exactly m
//! negative pivots), i.e. whether the equilibrium is stable; Newton uses that to choose
//! between the exact Hessian, a shifted one and a projected one.
//!
//! This file holds the solver object; the parts live in:
//!
//! - `pattern`: the blocks of a system, the KKT pattern, the layout's fingerprint and the
//!   slots the Hessian's values are summed into;
//! - `analysis`: the ordering and symbolic factorisation of a new layout;
//! - `factor`: the numeric factorisation in double or single precision, and its inertia;
//! - `krylov`: the GMRES solves with the factor and the products with the assembled matrix.

mod analysis;
mod factor;
mod krylov;
mod pattern;
#[cfg(test)]
mod test_systems;

pub use factor::{FactorPrecision, KktFactorInfo};
pub use pattern::{HessianValues, KktBlocks, SlotPacker};

use super::tree::TreeSplit;
use super::tree_factor::FactorPlan;
use crate::math::sparse::SparseError;
use faer::dyn_stack::MemBuffer;
use faer::sparse::linalg::cholesky::SymbolicCholesky;
use faer::sparse::SparseColMat;

/// A KKT factorisation with cached pattern and symbolic analysis. Hold one per problem
/// (per skin) and reuse it: only the numeric factorisation is redone while the triplet
/// layout is unchanged.
pub struct KktSolver {
    /// The fingerprint of the analysed layout (rows, triplet count or key marker, hash).
    fingerprint: Option<(usize, usize, u64)>,
    /// For each compressed slot, the range in `gather_src` of the Hessian triplets summed
    /// into it (lower-triangle slots only; upper slots are mirrored).
    gather_ptr: Vec<usize>,
    /// Hessian triplet indices, grouped by the lower-triangle slot they sum into.
    gather_src: Vec<u32>,
    /// (upper slot, its lower mirror) for every strictly upper slot.
    mirror: Vec<(usize, usize)>,
    /// Lower slot of each constraint triplet.
    cmap: Vec<usize>,
    /// Slot map of the Hessian triplets ([`crate::math::Energy::hessian_scatter`]): a
    /// lower-triangle free–free triplet's value slot in the matrix, a (free row, pinned
    /// column) triplet's slot `nnz + k` (its pair is `coupling[k]`), the rest `NO_SLOT`.
    slot: Vec<u32>,
    /// The energy's packed form of `slot` ([`crate::math::Energy::pack_slot_map`]): `None`
    /// until the first scatter of the layout asks for it, then what the energy made.
    packed_slot: Option<Option<Vec<u32>>>,
    /// (free row, pinned dof) of each coupling slot.
    coupling: Vec<(usize, usize)>,
    /// The Hessian's coupling values K_fp (N/m) of the last assembly, one per `coupling` pair.
    coupling_values: Vec<f64>,
    /// The symbolic factorisation of the analysed layout.
    symbolic: Option<SymbolicCholesky<usize>>,
    /// The factor's values in double precision (current when `factor_precision` is double).
    values: Vec<f64>,
    /// The factor's values in single precision (current when `factor_precision` is single).
    values32: Vec<f32>,
    /// The precision the next factorisations are made in.
    precision: FactorPrecision,
    /// The precision of the current factor (`values` or `values32`).
    factor_precision: FactorPrecision,
    /// Whether single-precision inertia is trusted for the current analysis: `None` until a
    /// double-precision check of a failed single-precision test, then whether the check agreed
    /// (a disagreement is kept: every later single-precision failure is checked).
    single_inertia: Option<bool>,
    /// The lower triangle of the shifted matrix rounded to single precision (a
    /// single-precision factorisation's input).
    matrix32: Option<SparseColMat<usize, f32>>,
    /// Workspace of faer's factorisation and solves.
    mem: Option<MemBuffer>,
    /// The matrix of the current factor (unshifted), once `base` has been assembled anew
    /// after the factorisation (the buffers are swapped, not copied).
    matrix: Option<SparseColMat<usize, f64>>,
    /// The assembled matrix (unshifted).
    base: Option<SparseColMat<usize, f64>>,
    /// `base` is the matrix of the current factor (no assembly since the factorisation).
    base_is_factored: bool,
    /// Whether the upper triangle of `base` is filled (mirrored from the lower one): the
    /// factorisation, products and curvature read only the lower triangle; the patches read
    /// whole columns.
    full_storage: bool,
    /// The shifted copy a double-precision factorisation with a shift reads.
    shifted: Option<SparseColMat<usize, f64>>,
    /// Value slot of each diagonal entry of the analysed pattern.
    diag_pos: Vec<usize>,
    /// Free dofs (rows of K).
    n_free: usize,
    /// Constraint rows (rows of C).
    n_cons: usize,
    /// The shift τ of the current factor on the free diagonal (N/m).
    shift: f64,
    /// δ of the assembled matrix `base`.
    delta: f64,
    /// δ of the factored matrix `matrix`.
    factor_delta: f64,
    /// The last factorisation succeeded (no zero pivot).
    factored: bool,
    /// Factorisation flops of the current symbolic analysis (decides sequential or parallel).
    flops: f64,
    /// Whether the current analysis uses the nested-dissection ordering (else AMD).
    nested_dissection: bool,
    /// Number of symbolic analyses performed so far (to check reuse).
    pub symbolic_count: usize,
    /// The elimination tree's split for solves on two cores, when the analysis is
    /// supernodal and one pays ([`TreeSplit`]).
    split: Option<TreeSplit>,
    /// The plan of a factorisation across that split ([`crate::solver::tree_factor`]).
    plan: Option<FactorPlan>,
}

impl Default for KktSolver {
    fn default() -> Self {
        Self {
            fingerprint: None,
            gather_ptr: Vec::new(),
            gather_src: Vec::new(),
            mirror: Vec::new(),
            cmap: Vec::new(),
            slot: Vec::new(),
            packed_slot: None,
            coupling: Vec::new(),
            coupling_values: Vec::new(),
            symbolic: None,
            values: Vec::new(),
            values32: Vec::new(),
            precision: FactorPrecision::Double,
            factor_precision: FactorPrecision::Double,
            single_inertia: None,
            matrix32: None,
            mem: None,
            matrix: None,
            base: None,
            base_is_factored: false,
            full_storage: true,
            shifted: None,
            diag_pos: Vec::new(),
            n_free: 0,
            n_cons: 0,
            shift: 0.0,
            delta: 0.0,
            factor_delta: 0.0,
            factored: false,
            flops: 0.0,
            nested_dissection: false,
            symbolic_count: 0,
            split: None,
            plan: None,
        }
    }
}

impl KktSolver {
    /// An empty solver (no cached analysis).
    pub fn new() -> Self {
        Self::default()
    }

    /// Assemble and factorise the KKT matrix ([`KktSolver::assemble`] then
    /// [`KktSolver::factor`] with `shift`, N/m).
    pub fn factorize(
        &mut self,
        blocks: &KktBlocks,
        shift: f64,
    ) -> Result<KktFactorInfo, SparseError> {
        let symbolic_s = self.assemble(blocks)?;
        let mut info = self.factor(shift);
        info.symbolic_s = symbolic_s;
        Ok(info)
    }

    /// True when the last factorisation succeeded (no zero pivot).
    pub fn is_factored(&self) -> bool {
        self.factored
    }

    /// The assembled KKT matrix (free dofs, then constraint rows; both triangles; −δ on the
    /// constraint diagonal), when one is.
    pub(crate) fn assembled(&self) -> Option<&SparseColMat<usize, f64>> {
        self.base.as_ref()
    }

    /// The matrix of the current factor (the assembled one of its time, without its shift),
    /// when the last factorisation succeeded.
    pub(crate) fn factored_matrix(&self) -> Option<&SparseColMat<usize, f64>> {
        let m = if self.base_is_factored {
            self.base.as_ref()
        } else {
            self.matrix.as_ref()
        };
        m.filter(|_| self.factored)
    }

    /// (free dofs, constraint rows) of the assembled system.
    pub(crate) fn sizes(&self) -> (usize, usize) {
        (self.n_free, self.n_cons)
    }

    /// δ of the assembled matrix (N/m).
    pub(crate) fn delta(&self) -> f64 {
        self.delta
    }

    /// Value slot of the diagonal entry of KKT index `j` in the assembled matrix.
    pub(crate) fn diagonal_slot(&self, j: usize) -> usize {
        self.diag_pos[j]
    }

    /// Forget the cached analysis (the precision and storage are kept).
    pub fn reset(&mut self) {
        *self = Self {
            symbolic_count: self.symbolic_count,
            precision: self.precision,
            full_storage: self.full_storage,
            ..Self::default()
        };
    }
}

#[cfg(test)]
mod tests {
    use super::test_systems::factorize_free;
    use super::*;

    /// min ½ xᵀ K x − fᵀx s.t. x0 + x1 + x2 = 1 with K = diag(1, 2, 4), f = 0: the solution is
    /// x = K⁻¹Cᵀλ' with λ' = 1 / (C K⁻¹ Cᵀ) = 1 / 1.75: x = (4/7, 2/7, 1/7).
    #[test]
    fn kkt_solves_constrained_quadratic_and_reports_inertia() {
        let k = vec![(0, 0, 1.0), (1, 1, 2.0), (2, 2, 4.0)];
        let c = vec![(0, 0, 1.0), (0, 1, 1.0), (0, 2, 1.0)];
        let mut s = KktSolver::new();
        for gamma in [1.0, 10.0] {
            let info = factorize_free(&mut s, &k, 1, &c, gamma, 1e-8 * gamma, 0.0);
            assert!(info.inertia_ok, "{info:?}");
            let mut rhs = vec![0.0, 0.0, 0.0, gamma * 1.0];
            s.solve(&mut rhs, 3, 1e-15);
            for (xi, ex) in rhs.iter().zip([4.0 / 7.0, 2.0 / 7.0, 1.0 / 7.0]) {
                assert!((xi - ex).abs() < 1e-12, "{xi} vs {ex}");
            }
        }
        assert_eq!(s.symbolic_count, 1, "same pattern: the analysis is reused");
        // K = diag(1, 2, −4): indefinite on the null space of C → inertia flagged.
        let kneg = vec![(0, 0, 1.0), (1, 1, 2.0), (2, 2, -4.0)];
        let info = factorize_free(&mut s, &kneg, 1, &c, 1.0, 1e-8, 0.0);
        assert!(!info.inertia_ok);
        // ...but K = diag(1, 2, −0.1) with the constraint x2 = 0 is PD on the null space.
        let c2 = vec![(0, 2, 1.0)];
        let kn2 = vec![(0, 0, 1.0), (1, 1, 2.0), (2, 2, -0.1)];
        let info = factorize_free(&mut s, &kn2, 1, &c2, 1.0, 1e-8, 0.0);
        assert!(info.inertia_ok, "{info:?}");
    }
}
