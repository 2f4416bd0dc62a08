//! Sparse symmetric KKT solve for equality-constrained Newton steps.
//!
//! The system (free dofs only, pinned dofs removed) is
//!
//! ```text
//! [ K + τI   γCᵀ ] [Δx]   [a]
//! [ γC      −δI  ] [μ ] = [b]
//! ```
//!
//! with γ balancing the rows, τ ≥ 0 an optional shift and δ (1e-6 γ from the Newton solver)
//! a small negative regularisation of the constraint block.
//!
//! Why this method: the KKT matrix is symmetric indefinite. With δ > 0 and K + τI positive
//! definite it is *quasi-definite*, so an LDLᵀ factorisation without pivoting exists for any
//! symmetric ordering (Vanderbei 1995). That lets us use faer's supernodal sparse LDLᵀ with
//! a fill-reducing ordering computed once, METIS's nested dissection or AMD, whichever needs
//! fewer flops ([`super::ordering`]; the symbolic analysis is cached here and reused across
//! Newton iterations and frames). It costs the same as a Cholesky of the same
//! pattern, about half of a sparse LU with partial pivoting, and unlike a null-space method
//! it keeps the sparsity of the cluster constraints. The error δ introduces is removed by
//! GMRES on the unregularised matrix preconditioned with the factor ([`super::gmres`]); the
//! same GMRES lets a factor of an earlier Newton iterate serve later ones (a lagged factor).
//! A bonus: by
//! Sylvester's law of inertia the signs of D tell whether K is positive definite on the null
//! space of C (exactly m negative pivots), i.e. whether the equilibrium is stable; Newton
//! uses that to decide between the exact and a projected Hessian.

/// Columns per parallel chunk of [`KktSolver::curvature`].
const CURVATURE_CHUNK: usize = 4096;

/// LDLᵀ without dynamic regularisation (faer's default: no signs, δ = ε = 0), in either
/// precision: a zero pivot is reported, not perturbed.
fn no_regularization<T: faer::traits::RealField>() -> LdltRegularization<'static, T> {
    LdltRegularization::default()
}

use super::gmres::{fgmres, GmresReport};
use super::tree::{solve_cost, Scalar, TreeSplit};
use super::tree_factor::{self, FactorPlan};
use crate::math::energy::NO_SLOT;
use crate::math::hash::Fnv1a;
use crate::math::sparse::{mul_sym_lower_into, SparseError};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{
    factorize_symbolic_cholesky, CholeskySymbolicParams, LdltRef, SymbolicCholesky,
    SymbolicCholeskyRaw, SymmetricOrdering,
};
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use faer::{Conj, MatMut, Side};
use rayon::prelude::*;

/// Outcome of one numeric KKT factorisation.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KktFactorInfo {
    /// Negative pivots found in D.
    pub negative_pivots: usize,
    /// True when the inertia is (free dofs positive, constraint rows negative): the
    /// (shifted) Hessian is positive definite on the null space of the constraints.
    pub inertia_ok: bool,
    /// Seconds spent in the symbolic analysis (0 when reused).
    pub symbolic_s: f64,
    /// Seconds spent in the numeric factorisation.
    pub numeric_s: f64,
    /// A single-precision factor's inertia was not the expected one, so the factor was made
    /// again in double precision (its inertia is the one reported).
    pub double_retry: bool,
}

/// The floating-point precision of a KKT factor. The factor only preconditions GMRES, which
/// works on the double-precision matrix, so a single-precision factor changes the cost of a
/// Newton direction, not its accuracy: it factorises and solves faster than a double factor,
/// GMRES needs about one iteration more with it, and its negative pivots count the same
/// inertia as the double factor's on buckling skins (a factor whose inertia differs is made
/// again in double precision).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum FactorPrecision {
    /// f64 factor and solves.
    #[default]
    Double,
    /// f32 factor and solves (half the memory traffic, twice the SIMD lanes).
    Single,
}

/// A KKT factorisation with cached pattern and symbolic analysis. Hold one per problem
/// (per skin) and reuse it: only the numeric factorisation is redone while the triplet
/// layout is unchanged.
pub struct KktSolver {
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
    diag_pos: Vec<usize>,
    n_free: usize,
    n_cons: usize,
    shift: f64,
    /// δ of the assembled matrix `base`.
    delta: f64,
    /// δ of the factored matrix `matrix`.
    factor_delta: f64,
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
    /// The plan of a factorisation across that split ([`tree_factor`]).
    plan: Option<FactorPlan>,
}

/// The blocks of a KKT system (free dofs only) for [`KktSolver::assemble`].
#[derive(Debug, Clone, Copy)]
pub struct KktBlocks<'a> {
    /// Free index of each dof, or `usize::MAX` when it is pinned.
    pub free_of: &'a [usize],
    /// Free dofs (rows of K).
    pub n_free: usize,
    /// Constraint rows (rows of C).
    pub n_cons: usize,
    /// Hessian triplets over all dofs, both triangles, as an
    /// [`Energy`](crate::math::Energy) emits them (N/m).
    pub hessian: &'a [(usize, usize, f64)],
    /// Where the Hessian's values come from.
    pub hessian_values: HessianValues<'a>,
    /// Constraint triplets `(row, free dof, value)`, unscaled.
    pub constraints: &'a [(usize, usize, f64)],
    /// Row scale γ of the constraint rows (N/m).
    pub gamma: f64,
    /// Regularisation δ subtracted on the constraint diagonal (N/m).
    pub delta: f64,
    /// A key the caller gives the layout (sizes, pinned set, constraint pattern and Hessian
    /// triplet indices): equal keys promise equal layouts, so the solver skips fingerprinting
    /// them (it must cover the Hessian's triplet count). `None`: the solver fingerprints the
    /// layout itself. With a known key and scattered values, `hessian` may be empty.
    pub layout_key: Option<u64>,
}

/// Where [`KktSolver::assemble`] takes the Hessian's values from.
#[derive(Clone, Copy)]
pub enum HessianValues<'a> {
    /// The values of the [`KktBlocks::hessian`] triplets themselves.
    Triplets,
    /// Values replacing those of the triplets (same order and length: the values of
    /// [`Energy::hessian_values`](crate::math::Energy::hessian_values) for its layout).
    Values(&'a [f64]),
    /// A function that adds the Hessian into matrix values by a slot map, as
    /// [`Energy::hessian_scatter`](crate::math::Energy::hessian_scatter) does (the
    /// triplets then give only the layout), and the function that packs the slot map for
    /// it once per layout, as [`Energy::pack_slot_map`](crate::math::Energy::pack_slot_map)
    /// does.
    Scatter(&'a (dyn Fn(&[u32], &mut [f64]) + Sync), &'a SlotPacker<'a>),
}

/// Packs a slot map once per layout (see [`HessianValues::Scatter`]).
pub type SlotPacker<'a> = dyn Fn(&[u32]) -> Option<Vec<u32>> + Sync + 'a;

impl std::fmt::Debug for HessianValues<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Triplets => write!(f, "Triplets"),
            Self::Values(v) => write!(f, "Values({} values)", v.len()),
            Self::Scatter(..) => write!(f, "Scatter"),
        }
    }
}

/// The KKT pattern of `blocks` (both triangles, zero diagonal slots included), its values
/// zero ([`KktSolver::assemble`] sums them in). Built from the distinct (column, row) pairs,
/// 8 bytes per triplet while sorting: the Hessian triplets of a refined head (16 million)
/// made the set-up's peak memory when they were copied with their values to build it.
fn kkt_pattern(blocks: &KktBlocks) -> Result<SparseColMat<usize, f64>, SparseError> {
    let (free_of, n_free) = (blocks.free_of, blocks.n_free);
    let n = n_free + blocks.n_cons;
    if u32::try_from(n).is_err() {
        return Err(SparseError::Build(format!("{n} KKT rows: more than 2³²")));
    }
    let key = |r: usize, col: usize| ((col as u64) << 32) | r as u64;
    let c = blocks.constraints;
    let mut keys = Vec::with_capacity(blocks.hessian.len() + 2 * c.len() + n);
    for &(r, cc, _) in blocks.hessian {
        let (fr, fc) = (free_of[r], free_of[cc]);
        if fr != usize::MAX && fc != usize::MAX {
            keys.push(key(fr, fc));
        }
    }
    keys.extend((0..n).map(|i| key(i, i)));
    for &(r, j, _) in c {
        keys.push(key(n_free + r, j));
        keys.push(key(j, n_free + r));
    }
    keys.par_sort_unstable();
    keys.dedup();
    keys.shrink_to_fit();
    let mut col_ptr = vec![0usize; n + 1];
    for &k in &keys {
        col_ptr[(k >> 32) as usize + 1] += 1;
    }
    for j in 0..n {
        col_ptr[j + 1] += col_ptr[j];
    }
    let row_idx: Vec<usize> = keys.iter().map(|&k| (k & 0xffff_ffff) as usize).collect();
    drop(keys);
    let nnz = row_idx.len();
    let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
    Ok(SparseColMat::new(symbolic, vec![0.0; nnz]))
}

/// Value index of entry (r, col) of the compressed matrix `a`.
fn slot_of(a: &SparseColMat<usize, f64>, r: usize, col: usize) -> Result<usize, SparseError> {
    let cp = a.col_ptr();
    let rows = &a.row_idx()[cp[col]..cp[col + 1]];
    rows.binary_search(&r)
        .map(|q| cp[col] + q)
        .map_err(|_| SparseError::Build(format!("entry ({r}, {col}) missing from pattern")))
}

/// The fingerprint of a layout of `n` rows the caller keyed (see [`KktBlocks::layout_key`]):
/// its triplet count is the key's to cover, so the count's place holds a marker no
/// fingerprinted layout has.
fn keyed_fingerprint(n: usize, key: u64) -> (usize, usize, u64) {
    (n, usize::MAX, key)
}

fn layout_fingerprint(
    n: usize,
    free_of: &[usize],
    k: &[(usize, usize, f64)],
    c: &[(usize, usize, f64)],
) -> (usize, usize, u64) {
    let mut h = Fnv1a::new();
    h.mix_usize(free_of.len());
    for &f in free_of {
        h.mix_usize(f);
    }
    for &(r, j, _) in c {
        h.mix_usize(r);
        h.mix_usize(j);
    }
    h.mix_usize(c.len());
    for &(r, cc, _) in k.iter().step_by(31).chain(k.last()) {
        h.mix_usize(r);
        h.mix_usize(cc);
    }
    (n, k.len(), h.finish())
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

    /// Assemble the unshifted KKT matrix of `blocks` (shift slots on the diagonal kept at
    /// zero).
    ///
    /// The first call (or a call whose layout differs) builds the pattern, the ordering
    /// (METIS or AMD, [`Self::analysis`]) and symbolic factorisation, and gather lists: for
    /// each lower-triangle slot
    /// the Hessian triplets that sum into it (the upper-triangle triplets are not read; the
    /// upper triangle is copied from the lower one). Later calls only sum the values into
    /// the slots, in parallel (no sorting or copying of triplets). The layout check compares
    /// the sizes, the pinned set, the constraints and every 31st Hessian triplet index.
    /// Returns the seconds spent building (0 when reused).
    pub fn assemble(&mut self, blocks: &KktBlocks) -> Result<f64, SparseError> {
        let k = blocks.hessian;
        if let HessianValues::Values(v) = blocks.hessian_values {
            if v.len() != k.len() {
                return Err(SparseError::PatternMismatch {
                    expected: k.len(),
                    got: v.len(),
                });
            }
        }
        let n = blocks.n_free + blocks.n_cons;
        let fp = match blocks.layout_key {
            Some(key) => keyed_fingerprint(n, key),
            None => layout_fingerprint(n, blocks.free_of, k, blocks.constraints),
        };
        let mut symbolic_s = 0.0;
        self.n_free = blocks.n_free;
        self.n_cons = blocks.n_cons;
        if self.fingerprint != Some(fp) || self.base.is_none() {
            if k.is_empty() && matches!(blocks.hessian_values, HessianValues::Scatter(..)) {
                return Err(SparseError::Build(
                    "a new KKT layout needs the Hessian's triplets".into(),
                ));
            }
            let t0 = std::time::Instant::now();
            self.analyse(blocks)?;
            self.fingerprint = Some(fp);
            symbolic_s = t0.elapsed().as_secs_f64();
        }
        self.sum_values(blocks);
        Ok(symbolic_s)
    }

    /// A new analysis for the layout of `blocks`: pattern, ordering and symbolic
    /// factorisation, factorisation memory, and the gather lists of the value sums.
    fn analyse(&mut self, blocks: &KktBlocks) -> Result<(), SparseError> {
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

    /// Symbolic LDLᵀ of the pattern `a` with METIS's nested-dissection ordering or AMD,
    /// whichever needs fewer flops ([`super::ordering`]: METIS on the skins, AMD on small
    /// or chain-like systems where its local choices are as good).
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
        let mut sym = analyse(SymmetricOrdering::Amd)?;
        self.flops = factor_flops(&sym);
        self.nested_dissection = false;
        let n = blocks.n_free + blocks.n_cons;
        let (fwd, inv) = nd_permutation(a, blocks.free_of, blocks.n_free);
        let nd = analyse(SymmetricOrdering::Custom(faer::perm::PermRef::new_checked(
            &fwd, &inv, n,
        )))?;
        let nd_flops = factor_flops(&nd);
        if nd_flops < self.flops {
            sym = nd;
            self.flops = nd_flops;
            self.nested_dissection = true;
        }
        Ok(sym)
    }

    /// Gather lists of the pattern `a`: each lower-triangle Hessian triplet goes to its
    /// slot; the upper ones are skipped (an energy emits both triangles of its symmetric
    /// Hessian) and the upper triangle is copied from the lower one (`mirror`), so the matrix
    /// is exactly symmetric; `cmap` holds the slot of each constraint triplet.
    fn build_gather(
        &mut self,
        a: &SparseColMat<usize, f64>,
        blocks: &KktBlocks,
    ) -> Result<(), SparseError> {
        let (free_of, k) = (blocks.free_of, blocks.hessian);
        let nnz = a.val().len();
        let mut count = vec![0usize; nnz + 1];
        let mut lower_slot = Vec::with_capacity(k.len());
        for &(r, cc, _) in k {
            let (fr, fc) = (free_of[r], free_of[cc]);
            if fr != usize::MAX && fc != usize::MAX && fr >= fc {
                let q = slot_of(a, fr, fc)?;
                count[q + 1] += 1;
                lower_slot.push(q);
            } else {
                lower_slot.push(usize::MAX);
            }
        }
        for q in 0..nnz {
            count[q + 1] += count[q];
        }
        let mut next = count.clone();
        let mut src = vec![0u32; count[nnz]];
        for (i, &q) in lower_slot.iter().enumerate() {
            if q != usize::MAX {
                src[next[q]] = u32::try_from(i)
                    .map_err(|_| SparseError::Build("more than 2³² Hessian triplets".into()))?;
                next[q] += 1;
            }
        }
        self.gather_ptr = count;
        self.gather_src = src;
        self.mirror = Vec::new();
        let (cp, ri) = (a.col_ptr(), a.row_idx());
        for col in 0..a.ncols() {
            for q in cp[col]..cp[col + 1] {
                let r = ri[q];
                if r < col {
                    self.mirror.push((q, slot_of(a, col, r)?));
                }
            }
        }
        self.cmap = blocks
            .constraints
            .iter()
            .map(|&(r, j, _)| slot_of(a, blocks.n_free + r, j))
            .collect::<Result<_, SparseError>>()?;
        self.build_slot_map(&lower_slot, blocks)
    }

    /// The slot map of the Hessian triplets (see `slot`) from the lower-triangle slots
    /// `lower_slot` (`usize::MAX` where none), and the coupling pairs.
    fn build_slot_map(
        &mut self,
        lower_slot: &[usize],
        blocks: &KktBlocks,
    ) -> Result<(), SparseError> {
        let nnz = self.gather_ptr.len() - 1;
        let too_many = || SparseError::Build("more than 2³² − 1 matrix slots".into());
        let mut pair_slot: std::collections::HashMap<(usize, usize), u32> = Default::default();
        self.coupling = Vec::new();
        self.slot = Vec::with_capacity(lower_slot.len());
        self.packed_slot = None;
        for (&(r, c, _), &q) in blocks.hessian.iter().zip(lower_slot) {
            let (fr, fc) = (blocks.free_of[r], blocks.free_of[c]);
            let s = if q != usize::MAX {
                u32::try_from(q).map_err(|_| too_many())?
            } else if fr != usize::MAX && fc == usize::MAX {
                let next = u32::try_from(nnz + self.coupling.len()).map_err(|_| too_many())?;
                *pair_slot.entry((fr, c)).or_insert_with(|| {
                    self.coupling.push((fr, c));
                    next
                })
            } else {
                NO_SLOT
            };
            if s == NO_SLOT && q != usize::MAX {
                return Err(too_many());
            }
            self.slot.push(s);
        }
        self.coupling_values = vec![0.0; self.coupling.len()];
        Ok(())
    }

    /// The Hessian's coupling of free rows to pinned dofs at the last assembly: (free row,
    /// pinned dof) pairs and their values K_fp (N/m).
    pub fn pinned_coupling(&self) -> (&[(usize, usize)], &[f64]) {
        (&self.coupling, &self.coupling_values)
    }

    /// Sum the values of `blocks` into the analysed matrix: the Hessian (its triplets
    /// gathered per slot in parallel, or scattered by its energy), γ C, −δ on the constraint
    /// diagonal, and the mirrored upper triangle.
    fn sum_values(&mut self, blocks: &KktBlocks) {
        self.keep_factored_matrix();
        match blocks.hessian_values {
            HessianValues::Scatter(scatter, pack) => self.scatter_hessian(scatter, pack),
            HessianValues::Values(v) => self.gather_hessian(blocks.hessian, Some(v)),
            HessianValues::Triplets => self.gather_hessian(blocks.hessian, None),
        }
        let base = self.base.as_mut().expect("base set");
        let vals = base.val_mut();
        for (&lo, t) in self.cmap.iter().zip(blocks.constraints) {
            vals[lo] += blocks.gamma * t.2;
        }
        for &q in &self.diag_pos[blocks.n_free..] {
            vals[q] -= blocks.delta;
        }
        if self.full_storage {
            for &(up, lo) in &self.mirror {
                vals[up] = vals[lo];
            }
        }
        self.delta = blocks.delta;
    }

    /// Before `base` is assembled anew: when it is the matrix of the current factor, it
    /// becomes `matrix` and `base` takes `matrix`'s buffer (a swap, no copy; the first time
    /// a clone).
    fn keep_factored_matrix(&mut self) {
        if !self.base_is_factored {
            return;
        }
        let base = self.base.as_mut().expect("base set");
        match &mut self.matrix {
            Some(m) if m.col_ptr() == base.col_ptr() => std::mem::swap(m, base),
            _ => self.matrix = Some(base.clone()),
        }
        self.base_is_factored = false;
    }

    /// The Hessian's values into the matrix's lower triangle (and the coupling values) by
    /// gathering each slot's triplets in parallel: values `v`, or the triplets' own.
    fn gather_hessian(&mut self, k: &[(usize, usize, f64)], v: Option<&[f64]>) {
        let value = |i: usize| v.map_or(k[i].2, |v| v[i]);
        let base = self.base.as_mut().expect("base set");
        let (ptr, src) = (&self.gather_ptr, &self.gather_src);
        base.val_mut()
            .par_iter_mut()
            .with_min_len(4096)
            .enumerate()
            .for_each(|(q, out)| {
                *out = src[ptr[q]..ptr[q + 1]]
                    .iter()
                    .map(|&i| value(i as usize))
                    .sum()
            });
        let nnz = ptr.len() - 1;
        self.coupling_values.iter_mut().for_each(|c| *c = 0.0);
        for (i, &s) in self.slot.iter().enumerate() {
            if s != NO_SLOT && s as usize >= nnz {
                self.coupling_values[s as usize - nnz] += value(i);
            }
        }
    }

    /// The Hessian's values into the matrix's lower triangle (and the coupling values) by
    /// the energy's own scatter through the slot map, packed by `pack` the first time.
    fn scatter_hessian(
        &mut self,
        scatter: &(dyn Fn(&[u32], &mut [f64]) + Sync),
        pack: &SlotPacker,
    ) {
        let (sym, mut vals) = self.base.take().expect("base set").into_parts();
        let nnz = vals.len();
        vals.par_iter_mut()
            .with_min_len(1 << 14)
            .for_each(|v| *v = 0.0);
        vals.resize(nnz + self.coupling.len(), 0.0);
        let packed = self.packed_slot.get_or_insert_with(|| pack(&self.slot));
        scatter(packed.as_deref().unwrap_or(&self.slot), &mut vals);
        self.coupling_values.clear();
        self.coupling_values.extend_from_slice(&vals[nnz..]);
        vals.truncate(nnz);
        self.base = Some(SparseColMat::new(sym, vals));
    }
    /// Numeric LDLᵀ of the assembled matrix with `shift` added to the free-dof diagonal.
    /// Call repeatedly with growing shifts for inertia correction (no re-assembly). A
    /// single-precision factor whose inertia is not the expected one is made again in double
    /// precision, and that one is kept: single-precision rounding of the large entries a
    /// constraint row eliminated early brings (γ²/δ) can miscount the skin's soft modes (a
    /// 500-face sheet: every exact Hessian looked indefinite in single precision, none in
    /// double).
    pub fn factor(&mut self, shift: f64) -> KktFactorInfo {
        let t1 = std::time::Instant::now();
        let mut info = self.factor_in(self.precision, shift);
        let single = self.precision == FactorPrecision::Single;
        if single && !info.inertia_ok && self.single_inertia != Some(true) {
            info = self.factor_in(FactorPrecision::Double, shift);
            info.double_retry = true;
            // Once double precision has confirmed a single-precision verdict, single
            // precision is trusted for this analysis; once it has contradicted one, every
            // single-precision failure is checked.
            if self.single_inertia.is_none() {
                self.single_inertia = Some(!info.inertia_ok);
            }
        }
        info.numeric_s = t1.elapsed().as_secs_f64();
        info
    }

    /// [`Self::factor`] in `precision`, without the retry.
    fn factor_in(&mut self, precision: FactorPrecision, shift: f64) -> KktFactorInfo {
        assert!(self.base.is_some(), "KktSolver::factor before assemble");
        // Across the elimination tree when the analysis has a plan, else faer's sequential
        // factorisation; a single-precision factor must also have stayed finite (f32
        // overflows where f64 would not).
        let res = match self.factor_across_tree(shift, precision) {
            Some(ok) => ok,
            None => match precision {
                FactorPrecision::Double => self.faer_factor_double(shift),
                FactorPrecision::Single => self.faer_factor_single(shift),
            },
        } && (precision == FactorPrecision::Double
            || self.values32.iter().all(|v| v.is_finite()));
        self.shift = shift;
        self.factor_delta = self.delta;
        self.base_is_factored = true;
        self.factor_precision = precision;
        let mut info = KktFactorInfo {
            negative_pivots: usize::MAX,
            inertia_ok: false,
            symbolic_s: 0.0,
            numeric_s: 0.0,
            double_retry: false,
        };
        self.factored = res;
        if res {
            let sym = self.symbolic.as_ref().expect("symbolic set");
            info.negative_pivots = match precision {
                FactorPrecision::Double => negative_pivots(sym, &self.values),
                FactorPrecision::Single => negative_pivots(sym, &self.values32),
            };
            info.inertia_ok = info.negative_pivots == self.n_cons;
        }
        info
    }

    /// faer's numeric LDLᵀ of the assembled matrix plus `shift` on the free diagonal, in
    /// double precision, into `values` (the matrix is read in place, or from a shifted
    /// copy); false on a zero pivot.
    fn faer_factor_double(&mut self, shift: f64) -> bool {
        let par = self.par();
        let base = self.base.as_ref().expect("base set");
        let a = if shift == 0.0 {
            base
        } else {
            let m = match &mut self.shifted {
                Some(m) if m.col_ptr() == base.col_ptr() => m,
                slot => slot.insert(base.clone()),
            };
            m.val_mut().copy_from_slice(base.val());
            let v = m.val_mut();
            for &q in &self.diag_pos[..self.n_free] {
                v[q] += shift;
            }
            &*m
        };
        let sym = self.symbolic.as_ref().expect("symbolic set");
        self.values.resize(sym.len_val(), 0.0);
        let mem = self.mem.as_mut().expect("memory set");
        faer_ldlt(sym, &mut self.values, a.as_ref(), par, mem)
    }

    /// faer's numeric LDLᵀ of the lower triangle of the assembled matrix plus `shift` on
    /// the free diagonal, rounded to single precision, into `values32`; false on a zero
    /// pivot.
    fn faer_factor_single(&mut self, shift: f64) -> bool {
        let par = self.par();
        let base = self.base.as_ref().expect("base set");
        let (cp, diag, nf) = (base.col_ptr(), &self.diag_pos, self.n_free);
        let m32 = self
            .matrix32
            .get_or_insert_with(|| lower_triangle_f32(base, diag));
        let dst = m32.val_mut();
        let mut k = 0;
        for j in 0..base.ncols() {
            let src = &base.val()[diag[j]..cp[j + 1]];
            for (d, &v) in dst[k..k + src.len()].iter_mut().zip(src) {
                *d = v as f32;
            }
            if j < nf {
                dst[k] = (src[0] + shift) as f32;
            }
            k += src.len();
        }
        let sym = self.symbolic.as_ref().expect("symbolic set");
        self.values32.resize(sym.len_val(), 0.0);
        let mem = self.mem.as_mut().expect("memory set");
        faer_ldlt(sym, &mut self.values32, m32.as_ref(), par, mem)
    }

    /// The factorisation of [`Self::faer_factor_double`] or [`Self::faer_factor_single`]
    /// across the elimination tree on two cores ([`tree_factor`]), when the analysis has a
    /// plan for it: whether it factorised.
    fn factor_across_tree(&mut self, shift: f64, precision: FactorPrecision) -> Option<bool> {
        let (Some(plan), Some(sym)) = (&self.plan, &self.symbolic) else {
            return None;
        };
        let SymbolicCholeskyRaw::Supernodal(s) = sym.raw() else {
            return None;
        };
        let a = self.base.as_ref().expect("base set").val();
        Some(match precision {
            FactorPrecision::Double => {
                self.values.resize(sym.len_val(), 0.0);
                tree_factor::factor(s, plan, (a, shift), &mut self.values)
            }
            FactorPrecision::Single => {
                self.values32.resize(sym.len_val(), 0.0);
                tree_factor::factor(s, plan, (a, shift), &mut self.values32)
            }
        })
    }

    /// The precision of the factorisations from now on (the default is double).
    pub fn set_precision(&mut self, precision: FactorPrecision) {
        self.precision = precision;
    }

    /// Whether the assembled matrix also holds its upper triangle (the patches read whole
    /// columns of it; the default). Without it, an assembly skips mirroring the lower
    /// triangle, and [`Self::assembled`] holds the lower triangle only.
    pub fn set_full_storage(&mut self, full: bool) {
        self.full_storage = full;
    }

    /// Parallelism for faer's own sparse factorisation and solves: sequential. faer
    /// parallelises inside the dense fronts; a shell's fronts are small and many, and there
    /// the synchronisation costs more than it saves (the capture head's skin KKT: 0.73 s
    /// per single-precision factorisation against 1.09 s with two faer tasks). The two
    /// cores go across the elimination tree instead ([`super::tree`] and
    /// [`super::tree_factor`], 1.43× on the head's factorisations and 1.48× on its
    /// solves); faer's sequential path serves analyses that do not split.
    fn par(&self) -> faer::Par {
        faer::Par::Seq
    }

    /// Flops of one numeric factorisation with the current analysis, and whether its ordering
    /// is nested dissection (true) or AMD (false).
    pub fn analysis(&self) -> (f64, bool) {
        (self.flops, self.nested_dissection)
    }

    /// True when the last factorisation succeeded (no zero pivot).
    pub fn is_factored(&self) -> bool {
        self.factored
    }

    /// Solve the *unregularised* KKT system (τ kept, δ removed) of the last factorised
    /// matrix for `rhs` in place by GMRES preconditioned with its factor (see
    /// [`super::gmres`]), with at most `refine` + 1 factor solves, stopping once the residual
    /// is below `rel_tol` of ‖rhs‖. Returns the linear solves with the factor that were used.
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

    /// Whether the matrix was last analysed for the layout `key` (see
    /// [`KktBlocks::layout_key`]) of `n` rows: an assembly with that key may then scatter
    /// its values without the Hessian's triplets.
    pub fn has_layout(&self, n: usize, key: u64) -> bool {
        self.base.is_some() && self.fingerprint == Some(keyed_fingerprint(n, key))
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

    /// Apply the current factor's inverse to `rhs` in place (one forward and backward
    /// solve with the regularised, shifted matrix: a preconditioner, not a solution).
    pub(crate) fn apply_factor(&mut self, rhs: &mut [f64]) {
        self.raw_solve(rhs);
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

    fn raw_solve(&mut self, rhs: &mut [f64]) {
        let sym = self.symbolic.as_ref().expect("symbolic");
        if let (Some(split), SymbolicCholeskyRaw::Supernodal(s)) = (&self.split, sym.raw()) {
            let perm = sym
                .perm()
                .expect("a supernodal analysis is ordered")
                .arrays();
            match self.factor_precision {
                FactorPrecision::Single => tree_solve(split, s, &self.values32, perm, rhs),
                FactorPrecision::Double => tree_solve(split, s, &self.values, perm, rhs),
            }
            return;
        }
        let n = rhs.len();
        let par = self.par();
        let stack = MemStack::new(self.mem.as_mut().expect("memory"));
        if self.factor_precision == FactorPrecision::Single {
            let mut r32: Vec<f32> = rhs.iter().map(|&v| v as f32).collect();
            let ldlt = LdltRef::<usize, f32>::new(sym, &self.values32);
            let m = MatMut::from_column_major_slice_mut(&mut r32, n, 1);
            ldlt.solve_in_place_with_conj(Conj::No, m, par, stack);
            for (a, b) in rhs.iter_mut().zip(&r32) {
                *a = f64::from(*b);
            }
        } else {
            let ldlt = LdltRef::<usize, f64>::new(sym, &self.values);
            let m = MatMut::from_column_major_slice_mut(rhs, n, 1);
            ldlt.solve_in_place_with_conj(Conj::No, m, par, stack);
        }
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

/// faer's numeric LDLᵀ (no regularisation) of the lower triangle of `a` into `values`
/// (sized for `sym`), with `mem` as its workspace; false on a zero pivot.
fn faer_ldlt<T: faer::traits::RealField>(
    sym: &SymbolicCholesky<usize>,
    values: &mut [T],
    a: faer::sparse::SparseColMatRef<'_, usize, T>,
    par: faer::Par,
    mem: &mut MemBuffer,
) -> bool {
    sym.factorize_numeric_ldlt(
        values,
        a,
        Side::Lower,
        no_regularization(),
        par,
        MemStack::new(mem),
        Default::default(),
    )
    .is_ok()
}

/// Solve with the supernodal factor `values` of `sym` (ordering `(fwd, inv)`) for `rhs` in
/// place, on two cores across the elimination tree by `split`, in the factor's precision.
fn tree_solve<T: Scalar + Into<f64>>(
    split: &TreeSplit,
    sym: &SymbolicSupernodalCholesky<usize>,
    values: &[T],
    (fwd, inv): (&[usize], &[usize]),
    rhs: &mut [f64],
) {
    let mut x: Vec<T> = fwd.iter().map(|&i| T::from_f64(rhs[i])).collect();
    split.solve(sym, values, &mut x);
    for (r, &k) in rhs.iter_mut().zip(inv) {
        *r = x[k].into();
    }
}

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

/// The lower triangle of `a` (its entries from the diagonal `diag[j]` down in each column)
/// in single precision, values zero: a single-precision factorisation's input.
fn lower_triangle_f32(a: &SparseColMat<usize, f64>, diag: &[usize]) -> SparseColMat<usize, f32> {
    let (cp, ri) = (a.col_ptr(), a.row_idx());
    let mut col_ptr = Vec::with_capacity(a.ncols() + 1);
    let mut rows = Vec::new();
    col_ptr.push(0);
    for j in 0..a.ncols() {
        rows.extend_from_slice(&ri[diag[j]..cp[j + 1]]);
        col_ptr.push(rows.len());
    }
    let nnz = rows.len();
    let sym =
        faer::sparse::SymbolicSparseColMat::new_checked(a.nrows(), a.ncols(), col_ptr, None, rows);
    SparseColMat::new(sym, vec![0.0f32; nnz])
}

/// Nested-dissection permutation (forward: new → old index, inverse) of the KKT matrix `a`
/// whose first `n_free` rows are free dofs (`free_of` maps dofs to them; dof `d` belongs to
/// vertex `d / 3`) and whose last rows are constraints. The graph METIS orders has one node
/// per vertex with a free dof and one per set of constraint rows that couple the same
/// vertices (a cluster's three coordinate rows), weighted by their index counts.
fn nd_permutation(
    a: &SparseColMat<usize, f64>,
    free_of: &[usize],
    n_free: usize,
) -> (Vec<usize>, Vec<usize>) {
    let n = a.nrows();
    let mut vertex_of_free = vec![0usize; n_free];
    for (d, &f) in free_of.iter().enumerate() {
        if f != usize::MAX {
            vertex_of_free[f] = d / 3;
        }
    }
    let (cp, ri) = (a.col_ptr(), a.row_idx());
    let mut node_of = vec![usize::MAX; n];
    let mut members: Vec<Vec<usize>> = Vec::new();
    let mut node_of_vertex = vec![usize::MAX; free_of.len().div_ceil(3)];
    for f in 0..n_free {
        let v = vertex_of_free[f];
        if node_of_vertex[v] == usize::MAX {
            node_of_vertex[v] = members.len();
            members.push(Vec::new());
        }
        node_of[f] = node_of_vertex[v];
        members[node_of_vertex[v]].push(f);
    }
    let mut node_of_rows: std::collections::HashMap<Vec<usize>, usize> = Default::default();
    for row in n_free..n {
        let mut verts: Vec<usize> = ri[cp[row]..cp[row + 1]]
            .iter()
            .filter(|&&i| i < n_free)
            .map(|&i| vertex_of_free[i])
            .collect();
        verts.sort_unstable();
        verts.dedup();
        let node = *node_of_rows.entry(verts).or_insert_with(|| {
            members.push(Vec::new());
            members.len() - 1
        });
        node_of[row] = node;
        members[node].push(row);
    }
    let mut neighbours = vec![Vec::new(); members.len()];
    for col in 0..n {
        let nc = node_of[col];
        neighbours[nc].extend(ri[cp[col]..cp[col + 1]].iter().map(|&r| node_of[r]));
    }
    let weight: Vec<usize> = members.iter().map(Vec::len).collect();
    let order = super::ordering::nested_dissection(&neighbours, &weight);
    let fwd: Vec<usize> = order
        .iter()
        .flat_map(|&nd| members[nd].iter().copied())
        .collect();
    let mut inv = vec![0usize; n];
    for (i, &o) in fwd.iter().enumerate() {
        inv[o] = i;
    }
    (fwd, inv)
}

/// Count negative entries of D in an LDLᵀ factor (D is stored on the factor's diagonal).
fn negative_pivots<T: Copy + PartialOrd + Default>(
    sym: &SymbolicCholesky<usize>,
    values: &[T],
) -> usize {
    match sym.raw() {
        SymbolicCholeskyRaw::Simplicial(s) => {
            let cp = s.col_ptr();
            (0..sym.nrows())
                .filter(|&k| values[cp[k]] < T::default())
                .count()
        }
        SymbolicCholeskyRaw::Supernodal(s) => {
            let begin = s.supernode_begin();
            let end = s.supernode_end();
            let cpv = s.col_ptr_for_val();
            let mut neg = 0;
            for sn in 0..s.n_supernodes() {
                let ncols = end[sn] - begin[sn];
                let len = cpv[sn + 1] - cpv[sn];
                let nrows = len / ncols;
                for k in 0..ncols {
                    if values[cpv[sn] + k * nrows + k] < T::default() {
                        neg += 1;
                    }
                }
            }
            neg
        }
    }
}

/// Assemble and factorise K (triplets over free dofs 0..n, n the largest index + 1) with
/// `n_cons` constraint rows `c`, row scale γ, regularisation δ and `shift`.
#[cfg(test)]
fn factorize_free(
    s: &mut KktSolver,
    k: &[(usize, usize, f64)],
    n_cons: usize,
    c: &[(usize, usize, f64)],
    gamma: f64,
    delta: f64,
    shift: f64,
) -> KktFactorInfo {
    let n = k.iter().map(|t| t.0.max(t.1) + 1).max().unwrap_or(0);
    let free_of: Vec<usize> = (0..n).collect();
    let blocks = KktBlocks {
        free_of: &free_of,
        n_free: n,
        n_cons,
        hessian: k,
        hessian_values: HessianValues::Triplets,
        constraints: c,
        gamma,
        delta,
        layout_key: None,
    };
    s.factorize(&blocks, shift).unwrap()
}

/// out = (A + τ I on the free block + δ I on the constraint block + `shifts` on the
/// diagonal) v: the KKT operator GMRES solves, from the assembled KKT matrix `a` (read by its
/// lower triangle, `diag` its diagonal slots) of `sizes`
/// = (free dofs, constraint rows), with δ (the regularisation the factor carries) removed
/// again and the uniform shift τ and the diagonal `shifts` (KKT index, N/m) added.
fn kkt_mul(
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

#[cfg(test)]
mod tests {
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

#[cfg(test)]
mod ordering_tests {
    use super::*;

    /// The pattern built from the distinct index pairs is the one a triplet assembly of
    /// the same blocks gives (pinned dofs left out, diagonal slots and both constraint
    /// triangles in), with duplicates and unsorted triplets.
    #[test]
    fn the_kkt_pattern_is_the_triplet_assemblys() {
        let free_of = vec![0, usize::MAX, 1, 2, 3];
        let hessian = vec![
            (4, 0, 1.0),
            (0, 4, 1.0),
            (0, 0, 2.0),
            (1, 0, 5.0),
            (0, 1, 5.0),
            (3, 2, -1.0),
            (2, 3, -1.0),
            (4, 0, 3.0),
            (3, 3, 1.0),
        ];
        let constraints = vec![(0, 1, 1.0), (1, 3, 2.0), (0, 2, 1.0)];
        let blocks = KktBlocks {
            free_of: &free_of,
            n_free: 4,
            n_cons: 2,
            hessian: &hessian,
            hessian_values: HessianValues::Triplets,
            constraints: &constraints,
            gamma: 1.0,
            delta: 0.0,
            layout_key: None,
        };
        let mut t: Vec<(usize, usize, f64)> = hessian
            .iter()
            .filter(|&&(r, c, _)| free_of[r] != usize::MAX && free_of[c] != usize::MAX)
            .map(|&(r, c, v)| (free_of[r], free_of[c], v))
            .collect();
        t.extend((0..6).map(|i| (i, i, 0.0)));
        for &(r, j, v) in &constraints {
            t.extend([(4 + r, j, v), (j, 4 + r, v)]);
        }
        let reference = crate::math::sparse::assemble(6, 6, &t).unwrap();
        let pattern = kkt_pattern(&blocks).unwrap();
        assert_eq!(pattern.col_ptr(), reference.col_ptr());
        assert_eq!(pattern.row_idx(), reference.row_idx());
        assert!(pattern.val().iter().all(|&v| v == 0.0));
    }

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

    /// The KKT blocks of Hessian triplets `t` over the dofs `free_of` (all free) with the
    /// one constraint row `c`, γ = 1 and δ = 1e-8.
    fn one_row_blocks<'a>(
        free_of: &'a [usize],
        t: &'a [(usize, usize, f64)],
        c: &'a [(usize, usize, f64)],
    ) -> KktBlocks<'a> {
        KktBlocks {
            free_of,
            n_free: free_of.len(),
            n_cons: 1,
            hessian: t,
            hessian_values: HessianValues::Triplets,
            constraints: c,
            gamma: 1.0,
            delta: 1e-8,
            layout_key: None,
        }
    }

    /// (row, column, value) entries.
    pub(super) type Triplets = Vec<(usize, usize, f64)>;

    /// A 3D lattice of n³ nodes, one dof each, each tied to its 6 neighbours with `diagonal`
    /// on the diagonal (a shifted graph Laplacian, supernodal when factorised), and one
    /// constraint row averaging a line
    /// of nodes: (Hessian triplets, constraint triplets, free dofs).
    pub(super) fn lattice_kkt(n: usize, diagonal: f64) -> (Triplets, Triplets, usize) {
        let id = |i: usize, j: usize, k: usize| (i * n + j) * n + k;
        let mut t = Vec::new();
        for i in 0..n {
            for j in 0..n {
                for k in 0..n {
                    t.push((id(i, j, k), id(i, j, k), diagonal));
                    let mut link = |a: usize, b: usize| t.extend([(a, b, -1.0), (b, a, -1.0)]);
                    if i + 1 < n {
                        link(id(i, j, k), id(i + 1, j, k));
                    }
                    if j + 1 < n {
                        link(id(i, j, k), id(i, j + 1, k));
                    }
                    if k + 1 < n {
                        link(id(i, j, k), id(i, j, k + 1));
                    }
                }
            }
        }
        let c = (0..n)
            .map(|k| (0, id(n / 2, n / 2, k), 1.0 / n as f64))
            .collect();
        (t, c, n * n * n)
    }

    /// The factorisation and solves across the elimination tree on two cores
    /// ([`TreeSplit`], [`tree_factor`]) equal faer's sequential ones to round-off in both
    /// precisions (values, inertia, solution), shifted or not, and give the same bits on
    /// one thread and on two.
    #[test]
    fn the_two_core_tree_factor_and_solve_are_faers_on_any_thread_count() {
        let (t, c, n) = lattice_kkt(16, 6.01);
        let free_of: Vec<usize> = (0..n).collect();
        let blocks = one_row_blocks(&free_of, &t, &c);
        let rhs: Vec<f64> = (0..n + 1).map(|i| ((i * 7919) % 13) as f64 - 6.0).collect();
        let pool = |threads: usize| {
            rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap()
        };
        let cases = [
            (FactorPrecision::Double, 0.0, 1e-12),
            (FactorPrecision::Double, -0.3, 1e-11),
            (FactorPrecision::Single, 0.0, 1e-5),
        ];
        for (precision, shift, tol) in cases {
            let mut s = KktSolver::new();
            s.set_precision(precision);
            s.assemble(&blocks).unwrap();
            assert!(
                s.split.is_some() && s.plan.is_some(),
                "a 16³ lattice splits"
            );
            let run = |s: &mut KktSolver, threads: usize| {
                pool(threads).install(|| {
                    let info = s.factor(shift);
                    let mut x = rhs.clone();
                    s.apply_factor(&mut x);
                    let v: Vec<f64> = match precision {
                        FactorPrecision::Double => s.values.clone(),
                        FactorPrecision::Single => s.values32.iter().map(|&v| v.into()).collect(),
                    };
                    (info.negative_pivots, v, x)
                })
            };
            let one = run(&mut s, 1);
            let two = run(&mut s, 2);
            assert_eq!(
                one, two,
                "{precision:?}, shift {shift}: 1 and 2 threads differ"
            );
            (s.split, s.plan) = (None, None);
            let faer = run(&mut s, 1);
            assert_eq!(one.0, faer.0, "{precision:?}, shift {shift}: inertia");
            assert!(
                shift == 0.0 || one.0 > 1,
                "the shift makes the lattice indefinite"
            );
            for (a, b) in [(&one.1, &faer.1), (&one.2, &faer.2)] {
                let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                for (x, y) in a.iter().zip(b) {
                    assert!(
                        (x - y).abs() <= tol * scale,
                        "{precision:?}, shift {shift}: {x} vs {y}"
                    );
                }
            }
        }
    }
}

#[cfg(test)]
mod inertia_tests {
    use super::ordering_tests::lattice_kkt;
    use super::*;

    /// 3D Dirichlet Laplacian on an N³ grid minus σ I: the number of negative pivots must
    /// equal the number of eigenvalues Σ 4 sin²(kπ/2(N+1)) below σ (supernodal factor).
    #[test]
    fn negative_pivots_count_eigenvalues_below_shift_on_a_large_supernodal_matrix() {
        let nn = 16usize;
        let (t, _, _) = lattice_kkt(nn, 6.0);
        let ev: Vec<f64> = (1..=nn)
            .map(|k| {
                let s = (k as f64 * std::f64::consts::PI / (2.0 * (nn as f64 + 1.0))).sin();
                4.0 * s * s
            })
            .collect();
        let mut s = KktSolver::new();
        for sigma in [0.01, 0.2, 0.5, 1.0] {
            let mut expected = 0;
            for a in &ev {
                for b in &ev {
                    for c in &ev {
                        if a + b + c < sigma {
                            expected += 1;
                        }
                    }
                }
            }
            let info = factorize_free(&mut s, &t, 0, &[], 1.0, 0.0, -sigma);
            assert_eq!(info.negative_pivots, expected, "sigma {sigma}");
        }
        assert!(matches!(
            s.symbolic.as_ref().unwrap().raw(),
            SymbolicCholeskyRaw::Supernodal(_)
        ));
    }
}
