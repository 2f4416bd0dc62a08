//! The symbolic analysis of a new KKT layout: the fill-reducing ordering (METIS's nested
//! dissection or, on small systems, AMD where its factorisation needs fewer flops), the symbolic
//! factorisation and its workspace, and the elimination tree's two-core split and plan.

use super::pattern::{kkt_pattern, slot_of};
use super::{KktBlocks, KktSolver};
use crate::math::sparse::SparseError;
use crate::solver::ordering::nd_permutation;
use crate::solver::tree::{solve_cost, TreeSplit};
use crate::solver::tree_factor::FactorPlan;
use faer::dyn_stack::MemBuffer;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
    SymmetricOrdering,
};
use faer::sparse::SparseColMat;
use faer::Side;

impl KktSolver {
    /// A new analysis for the layout of `blocks`: pattern, ordering and symbolic
    /// factorisation, factorisation memory, and the gather lists of the value sums.
    pub(super) fn analyse(&mut self, blocks: &KktBlocks) -> Result<(), SparseError> {
        let a = kkt_pattern(blocks)?;
        let sym = self.choose_ordering(&a, blocks)?;
        let par = self.par();
        let req = sym
            .factorize_numeric_ldlt_scratch::<f64>(par, Default::default())
            .or(sym.solve_in_place_scratch::<f64>(1, par));
        self.mem = Some(MemBuffer::new(req));
        self.values = Vec::new();
        self.values32 = Vec::new();
        self.matrix32 = None;
        self.single_inertia = None;
        self.shifted = None;
        self.base_is_factored = false;
        let n = blocks.n_free + blocks.n_cons;
        self.diag_pos = (0..n)
            .map(|j| slot_of(&a, j, j))
            .collect::<Result<_, _>>()?;
        self.build_gather(&a, blocks)?;
        self.split = match sym.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => TreeSplit::new(s, solve_cost),
            SymbolicCholeskyRaw::Simplicial(_) => None,
        };
        self.plan = match (sym.raw(), sym.perm()) {
            (SymbolicCholeskyRaw::Supernodal(s), Some(perm)) => {
                FactorPlan::new(s, perm.arrays(), &a, blocks.n_free)
            }
            _ => None,
        };
        self.symbolic = Some(sym);
        self.base = Some(a);
        self.matrix = None;
        self.symbolic_count += 1;
        // A new analysis invalidates the factor.
        self.factored = false;
        Ok(())
    }

    /// Symbolic LDLᵀ of the pattern `a` with METIS's nested-dissection ordering or, below
    /// [`ND_ONLY_FROM`] rows, AMD when it needs no more flops ([`crate::solver::ordering`]:
    /// METIS on the skins, AMD on small or chain-like systems where its local choices are
    /// as good).
    fn choose_ordering(
        &mut self,
        a: &SparseColMat<usize, f64>,
        blocks: &KktBlocks,
    ) -> Result<SymbolicCholesky<usize>, SparseError> {
        let analyse = |ordering: SymmetricOrdering<'_, usize>| {
            factorize_symbolic_cholesky(
                a.symbolic(),
                Side::Lower,
                ordering,
                CholeskySymbolicParams::default(),
            )
            .map_err(|e| SparseError::Build(format!("{e:?}")))
        };
        let n = blocks.n_free + blocks.n_cons;
        let (fwd, inv) = nd_permutation(a, blocks.free_of, blocks.n_free);
        let mut sym = analyse(SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(
            &fwd, &inv, n,
        )))?;
        self.flops = factor_flops(&sym);
        self.nested_dissection = true;
        if n < ND_ONLY_FROM {
            let amd = analyse(SymmetricOrdering::Amd)?;
            let amd_flops = factor_flops(&amd);
            if amd_flops <= self.flops {
                sym = amd;
                self.flops = amd_flops;
                self.nested_dissection = false;
            }
        }
        Ok(sym)
    }

    /// Flops of one numeric factorisation with the current analysis, and whether its ordering
    /// is nested dissection (true) or AMD (false).
    pub fn analysis(&self) -> (f64, bool) {
        (self.flops, self.nested_dissection)
    }
}

/// Rows from which the KKT analysis orders by nested dissection without trying AMD: on the
/// skins' systems of that size nested dissection needs fewer flops (0.64–0.70 of AMD's on
/// the avatar's shapes, 17,000–37,000 rows), and AMD's analysis costs as much as its own.
pub const ND_ONLY_FROM: usize = 10_000;

/// Flops of a numeric factorisation with this symbolic structure (supernodal: Σ over
/// supernodes of the dense front work; simplicial: Σ column counts squared).
fn factor_flops(sym: &SymbolicCholesky<usize>) -> f64 {
    match sym.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            let cp = s.col_ptr();
            (0..sym.nrows())
                .map(|k| ((cp[k + 1] - cp[k]) as f64).powi(2))
                .sum()
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            let (b, e, cpv) = (s.supernode_begin(), s.supernode_end(), s.col_ptr_for_val());
            (0..s.n_supernodes())
                .map(|sn| {
                    let nc = (e[sn] - b[sn]) as f64;
                    let below = (cpv[sn + 1] - cpv[sn]) as f64 / nc - nc;
                    nc * nc * nc / 3.0 + nc * nc * below + nc * below * below
                })
                .sum()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::krylov::kkt_mul;
    use super::super::test_systems::one_row_blocks;
    use super::*;

    /// A 3-dof-per-node grid "membrane" (graph Laplacian ⊗ I₃ plus a small mass) with one
    /// averaging constraint: the analysis keeps the ordering with fewer flops (never more
    /// than AMD's) and the solution solves the system to round-off.
    #[test]
    fn a_grid_is_ordered_by_the_cheaper_ordering_and_solved() {
        let k = 24usize;
        let id = |i: usize, j: usize| i * k + j;
        let mut t = Vec::new();
        for i in 0..k {
            for j in 0..k {
                for a in 0..3 {
                    t.push((3 * id(i, j) + a, 3 * id(i, j) + a, 0.01));
                }
                let mut link = |p: usize, q: usize| {
                    for a in 0..3 {
                        let (r, c) = (3 * p + a, 3 * q + a);
                        t.extend([(r, r, 1.0), (c, c, 1.0), (r, c, -1.0), (c, r, -1.0)]);
                    }
                };
                if i + 1 < k {
                    link(id(i, j), id(i + 1, j));
                }
                if j + 1 < k {
                    link(id(i, j), id(i, j + 1));
                }
            }
        }
        let n = 3 * k * k;
        let c: Vec<(usize, usize, f64)> = (0..k)
            .map(|j| (0, 3 * id(k / 2, j), 1.0 / k as f64))
            .collect();
        let free_of: Vec<usize> = (0..n).collect();
        let rhs: Vec<f64> = (0..n + 1).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
        let mut s = KktSolver::new();
        let blocks = one_row_blocks(&free_of, &t, &c);
        s.assemble(&blocks).unwrap();
        assert!(s.factor(0.0).inertia_ok);
        let (flops, _) = s.analysis();
        let amd = factorize_symbolic_cholesky(
            s.assembled().unwrap().symbolic(),
            Side::Lower,
            SymmetricOrdering::Amd,
            CholeskySymbolicParams::default(),
        )
        .unwrap();
        assert!(flops <= factor_flops(&amd), "{flops} > AMD's");
        let mut x = rhs.clone();
        s.solve(&mut x, 3, 1e-15);
        let mut ax = vec![0.0; n + 1];
        kkt_mul(
            (s.assembled().unwrap(), &s.diag_pos),
            (n, 1),
            (1e-8, 0.0),
            &[],
            &x,
            &mut ax,
        );
        let scale = rhs.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (a, b) in ax.iter().zip(&rhs) {
            assert!((a - b).abs() <= 1e-9 * scale, "{a} vs {b}");
        }
    }
}
