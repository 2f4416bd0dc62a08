//! Backward Euler and quasi-static solves of the lattice interior.
//!
//! One time step (h = 0.02 s by default) minimises the incremental potential over the free
//! node positions y (pinned nodes stay where they are):
//!
//!   Φ(y) = 1/(2h²) dᵀ M d + E(y) − (f_ext + f_g)ᵀ y + E_x(y),   d = y − q − h v,
//!
//! whose stationarity is backward Euler: M (v⁺ − v)/h = f(q⁺) + f_ext + f_g, q⁺ = q + h v⁺.
//! E_x is the optional extra term of the skin coupling, a quadratic model about the positions
//! at the start of the step, E_x(y) = −F_xᵀ (y − q) + ½ (y − q)ᵀ K_x (y − q) (K_x symmetric,
//! e.g. Bᵀ K_shell B, and F_x e.g. Bᵀ F_shell); its first Newton iteration from y = q + h v is
//! exactly the paper's [M + h²(K_q + K_x)] Δv = h (F_q + F_x − h K_x v).
//!
//! Each Newton iteration solves [M + h² (K + K_x)] Δy = −h² ∇Φ with a sparse Cholesky
//! factorisation (faer, symbolic analysis cached across iterations and steps), then
//! backtracks on Φ (Armijo, c = 1e-4). K is the corotational stiffness of [`Interior`].
//! The matrix is assembled straight into a compressed lower-triangle pattern built once
//! (node blocks of 3 × 3), in parallel over node columns, through a precomputed map from
//! (element, node pair) to block position; each block is R_e K₀_ab R_eᵀ with K₀ precomputed.
//! Conjugate gradients (block-Jacobi preconditioned, [`super::cg::pcg`]) skip the assembly
//! when there is no K_x: they multiply element by element ([`ElementOperator`]: rotate,
//! one shared K₀ + M₀ product per chunk of elements, rotate back), which costs about what a
//! product with the assembled matrix costs and saves its assembly. With K_x they multiply the
//! assembled matrix, mirrored into full node-block rows. CG starts each time step from the
//! previous step's first Newton direction, scaled to minimise the quadratic along it. The
//! element rotations of the gradient evaluation at the Newton point are reused for its
//! matrix.

use super::cg::{pcg, BlockCsr};
use super::interior::Interior;
use super::matfree::ElementOperator;
use super::tangent::RotationCorrection;
use super::FemError;
use crate::math::sparse::SpdSolver;
use crate::math::Energy;
use crate::solver::newton::{self, Check, NewtonLimits, NewtonProblem, Rejection, Verdict};
pub use crate::solver::SolveStatus;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

type M3 = Matrix3<f64>;

/// Free DOFs above which [`LinearSolver::Auto`] uses conjugate gradients for time steps.
pub const AUTO_CG_DOFS: usize = 2000;

/// Settings of the time stepper and the Newton solves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Time step h (s).
    pub dt: f64,
    /// Newton iterations per step at most (1 gives the paper's single linearised solve).
    pub max_newton: usize,
    /// Convergence: ‖∇Φ‖ on free DOFs ≤ `tolerance` × (initial ‖∇Φ‖ or the applied force
    /// norm, whichever is larger).
    pub tolerance: f64,
    /// Lumped (diagonal) mass instead of consistent mass.
    pub lumped_mass: bool,
    /// Gravity acceleration (m/s²), +Y up.
    pub gravity: [f64; 3],
    /// How each Newton system is solved.
    pub linear_solver: LinearSolver,
    /// Which stiffness the Newton matrix carries.
    #[serde(default)]
    pub tangent: Tangent,
}

/// The stiffness of the interior's Newton matrix.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
pub enum Tangent {
    /// The consistent tangent (the default): R K₀ Rᵀ plus the derivative of each element's
    /// rotation, its stress term projected to positive semi-definite
    /// ([`super::tangent`]). Newton converges quadratically where the projection is
    /// inactive. The matrix-free CG product (no coupling terms) uses it too.
    #[default]
    Consistent,
    /// The warped stiffness R K₀ Rᵀ with each rotation frozen: cheaper per iteration,
    /// linear convergence under large rotation (kept as the reference).
    Frozen,
}

/// Relative residual at which [`LinearSolver::Auto`]'s conjugate gradients stop. Measured
/// (tests/lattice_cg.rs: 50 single linearised steps of a sagging 6³ cube against CG at 1e-8):
/// 1e-3 moves the trajectory by 4.8e-5 m, 3 % of backward Euler's own time-step error
/// (1.5e-3 m between dt = 0.02 and 0.01 s); 1e-4 moves it 0.6 % for 35 instead of 26 CG
/// iterations. Steps solved to convergence meet the Newton tolerance either way.
pub const AUTO_CG_REL_TOL: f64 = 1e-3;

/// Linear solver for the Newton systems [M + h²K] Δy = r.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum LinearSolver {
    /// Measured choice (the default): Cholesky for quasi-static solves (no mass term, badly
    /// conditioned for CG) and for time steps with at most [`AUTO_CG_DOFS`] free DOFs;
    /// block-Jacobi CG (rel_tol [`AUTO_CG_REL_TOL`], ≤ 1000 iterations) for larger time
    /// steps, where it measured about 10× faster than Cholesky per Newton iteration (1,000
    /// quadratic elements, 4,320 DOFs, release, 2 loaded cores: matrix-free CG 17–35 ms with
    /// 35 iterations at rel_tol 1e-4, no assembly, vs Cholesky 230–330 ms per solve).
    Auto,
    /// Sparse Cholesky (faer, symbolic analysis cached): exact, cost grows fast in 3D.
    Cholesky,
    /// Conjugate gradients with a 3 × 3 block-Jacobi preconditioner, stopped at
    /// ‖r‖ ≤ `rel_tol` ‖b‖ or `max_iter` iterations (inexact Newton).
    ConjugateGradient {
        /// Relative residual at which CG stops.
        rel_tol: f64,
        /// Iteration cap.
        max_iter: usize,
    },
}

impl Default for StepSettings {
    fn default() -> Self {
        Self {
            dt: 0.02,
            max_newton: 20,
            tolerance: 1e-8,
            lumped_mass: false,
            gravity: [0.0, -super::GRAVITY, 0.0],
            linear_solver: LinearSolver::Auto,
            tangent: Tangent::Consistent,
        }
    }
}

impl StepSettings {
    /// Check the fields; the error names the one that is wrong.
    pub fn validate(&self) -> Result<(), FemError> {
        let bad = |field: &'static str, msg: String| Err(FemError::Settings { field, msg });
        if !(self.dt.is_finite() && self.dt > 0.0) {
            return bad(
                "dt",
                format!("time step must be positive (s), got {}", self.dt),
            );
        }
        if self.max_newton == 0 {
            return bad(
                "max_newton",
                "at least one Newton iteration is needed".into(),
            );
        }
        if !(self.tolerance.is_finite() && self.tolerance > 0.0) {
            return bad(
                "tolerance",
                format!("must be positive, got {}", self.tolerance),
            );
        }
        if !self.gravity.iter().all(|g| g.is_finite()) {
            return bad("gravity", "must be finite (m/s²)".into());
        }
        if let LinearSolver::ConjugateGradient { rel_tol, max_iter } = self.linear_solver {
            if !(rel_tol.is_finite() && rel_tol > 0.0 && rel_tol < 1.0) || max_iter == 0 {
                return bad(
                    "linear_solver",
                    "CG needs 0 < rel_tol < 1 and max_iter ≥ 1".into(),
                );
            }
        }
        Ok(())
    }
}

/// Extra coupling terms for one step (the skin): a symmetric stiffness K_x (triplets over
/// node DOFs, both triangles, N/m) and a force F_x (flat over node DOFs, N), held fixed
/// within the step.
#[derive(Debug, Clone, Copy)]
pub struct ExtraTerms<'a> {
    /// K_x as (row, col, value) triplets over DOFs 3·node + axis.
    pub stiffness: &'a [(usize, usize, f64)],
    /// F_x, flat over node DOFs.
    pub force: &'a [f64],
    /// A key of the triplets' (row, column) sequence that the caller changes whenever that
    /// sequence changes, so that a step need not pass over a large coupling stiffness to
    /// know its matrix layout still holds: a step checks the triplets (indices in range,
    /// values finite) only when their key is new, so a caller that changes the values under
    /// the same key vouches that they are finite. `None`: every step hashes and checks them.
    pub layout: Option<u64>,
}

impl<'a> ExtraTerms<'a> {
    /// Terms whose layout each step hashes.
    pub fn new(stiffness: &'a [(usize, usize, f64)], force: &'a [f64]) -> Self {
        Self {
            stiffness,
            force,
            layout: None,
        }
    }
}

/// The interior's outcome from the Newton core's: a failed line search, a step too short to
/// make progress and (never produced here) a non-finite residual are all `Stalled`, since the
/// stepper keeps its last good state.
fn interior_status(s: SolveStatus) -> SolveStatus {
    match s {
        SolveStatus::LineSearchFailed | SolveStatus::NotFinite => SolveStatus::Stalled,
        other => other,
    }
}

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Outcome.
    pub status: SolveStatus,
    /// Newton iterations (factorisations) performed.
    pub iterations: usize,
    /// Final ‖∇Φ‖ on free DOFs (N).
    pub residual: f64,
    /// `residual` divided by the reference force norm the tolerance applies to.
    pub relative_residual: f64,
    /// Time spent assembling matrices (s).
    pub assembly_s: f64,
    /// Time spent factorising and solving (s).
    pub solve_s: f64,
    /// Conjugate-gradient iterations summed over the Newton iterations (0 for Cholesky).
    pub cg_iterations: usize,
    /// Time spent evaluating the potential and its gradient (s).
    pub energy_s: f64,
    /// Potential evaluations (with or without gradient).
    pub evaluations: usize,
}

/// The terms of a Newton matrix mass_coef·M + stiff_coef·(K + K_x).
#[derive(Clone, Copy)]
struct MatrixTerms<'a> {
    /// Coefficient of the mass matrix (1 for a time step, 0 quasi-static).
    mass_coef: f64,
    /// Coefficient of the stiffness (h² for a time step, s²; 1 quasi-static).
    stiff_coef: f64,
    /// Lumped node masses (kg) instead of the consistent mass matrix.
    lumped: Option<&'a [f64]>,
    /// K_x triplets over DOFs (N/m).
    extra: Option<&'a [(usize, usize, f64)]>,
    /// Rotation-derivative part of each element's stiffness (empty: frozen rotations).
    corrections: &'a [Option<RotationCorrection>],
}

/// Compressed lower-triangle pattern over free DOFs with 3 × 3 node blocks.
struct System {
    free: Vec<usize>,
    nfree: usize,
    /// For each free node b: free nodes a ≥ b coupled to it (sorted, b first).
    nbrs: Vec<Vec<usize>>,
    colptr: Vec<usize>,
    /// For each free node b: (element, local index of b) of the elements containing it.
    node_elems: Vec<Vec<(u32, u16)>>,
    /// Assembly map, aligned with `node_elems[b]` × local node a: where block (a, b) goes in
    /// column b (`SLOT_DIAG`, `SLOT_SKIP` for pinned or upper-triangle nodes, else the rank
    /// of a in `nbrs[b][1..]`); `slot_ptr[b]` is the start of node b's run.
    slots: Vec<u32>,
    slot_ptr: Vec<usize>,
    /// Signature of the extra stiffness pattern this system was built for.
    extra_sig: Vec<(usize, usize)>,
    /// FNV hash (or the caller's key) of the extra triplets' (row, column) layout last seen
    /// with this system.
    extra_hash: u64,
    /// For each extra triplet of that layout: its index in `mat`'s values, or `usize::MAX`
    /// for a pinned node or the upper triangle.
    extra_slots: Vec<usize>,
    mat: SparseColMat<usize, f64>,
    /// The same matrix with both triangles in node-block rows (for CG), filled from `mat`.
    bsr: BlockCsr,
    /// For each block of `bsr` off the diagonal: the rank of the lower-triangle partner in
    /// its column's `nbrs` list (block (a, b), a > b: rank of a in `nbrs[b]`; a < b: rank of
    /// b in `nbrs[a]`).
    bsr_rank: Vec<u32>,
    /// Free node → node.
    free_nodes: Vec<usize>,
}

const NONE: usize = usize::MAX;
const SLOT_SKIP: u32 = u32::MAX;
const SLOT_DIAG: u32 = u32::MAX - 1;

impl System {
    fn new(
        interior: &Interior,
        pinned: &[bool],
        extra: &[(usize, usize)],
    ) -> Result<Self, FemError> {
        let mut free = vec![NONE; interior.nodes];
        let mut nfree = 0;
        for (n, f) in free.iter_mut().enumerate() {
            if !pinned[n] {
                *f = nfree;
                nfree += 1;
            }
        }
        let mut nbrs: Vec<Vec<usize>> = (0..nfree).map(|b| vec![b]).collect();
        let mut node_elems: Vec<Vec<(u32, u16)>> = vec![Vec::new(); nfree];
        for (e, nodes) in interior.elements.iter().enumerate() {
            for (lb, &nb) in nodes.iter().enumerate() {
                let fb = free[nb];
                if fb == NONE {
                    continue;
                }
                node_elems[fb].push((e as u32, lb as u16));
                for &na in nodes {
                    let fa = free[na];
                    if fa != NONE && fa > fb {
                        nbrs[fb].push(fa);
                    }
                }
            }
        }
        for &(a, b) in extra {
            let (fa, fb) = (free[a], free[b]);
            if fa != NONE && fb != NONE && fa > fb {
                nbrs[fb].push(fa);
            }
        }
        for l in &mut nbrs {
            l[1..].sort_unstable();
            l.dedup();
        }
        let n = 3 * nfree;
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        colptr.push(0);
        for (b, l) in nbrs.iter().enumerate() {
            for j in 0..3 {
                for i in j..3 {
                    rows.push(3 * b + i);
                }
                for &a in &l[1..] {
                    rows.extend([3 * a, 3 * a + 1, 3 * a + 2]);
                }
                colptr.push(rows.len());
            }
        }
        let mut slots = Vec::new();
        let mut slot_ptr = Vec::with_capacity(nfree + 1);
        for fb in 0..nfree {
            slot_ptr.push(slots.len());
            for &(e, _) in &node_elems[fb] {
                for &na in &interior.elements[e as usize] {
                    let fa = free[na];
                    slots.push(if fa == NONE || fa < fb {
                        SLOT_SKIP
                    } else if fa == fb {
                        SLOT_DIAG
                    } else {
                        nbrs[fb][1..].binary_search(&fa).expect("pattern") as u32
                    });
                }
            }
        }
        slot_ptr.push(slots.len());
        let nnz = rows.len();
        let sym = SymbolicSparseColMat::new_checked(n, n, colptr.clone(), None, rows);
        let mat = SparseColMat::new(sym, vec![0.0; nnz]);
        // Full block rows: lower partners (ascending b < a), the diagonal, then nbrs[a].
        let mut lower: Vec<Vec<(u32, u32)>> = vec![Vec::new(); nfree];
        for (b, l) in nbrs.iter().enumerate() {
            for (r, &a) in l[1..].iter().enumerate() {
                lower[a].push((b as u32, r as u32));
            }
        }
        let mut rows_b: Vec<Vec<u32>> = Vec::with_capacity(nfree);
        let mut bsr_rank = Vec::new();
        for a in 0..nfree {
            let mut row: Vec<u32> = Vec::new();
            for &(b, r) in &lower[a] {
                row.push(b);
                bsr_rank.push(r);
            }
            row.push(a as u32);
            bsr_rank.push(0);
            for (r, &b) in nbrs[a][1..].iter().enumerate() {
                row.push(b as u32);
                bsr_rank.push(r as u32);
            }
            rows_b.push(row);
        }
        let bsr = BlockCsr::from_pattern(&rows_b);
        let free_nodes = (0..interior.nodes).filter(|&n| free[n] != NONE).collect();
        Ok(Self {
            free,
            nfree,
            nbrs,
            colptr,
            node_elems,
            slots,
            slot_ptr,
            extra_sig: extra.to_vec(),
            extra_hash: 0,
            extra_slots: Vec::new(),
            mat,
            bsr,
            bsr_rank,
            free_nodes,
        })
    }

    /// Whether this system was built for exactly the nodes `pinned`.
    fn pins(&self, pinned: &[bool]) -> bool {
        self.free.len() == pinned.len()
            && self
                .free
                .iter()
                .zip(pinned)
                .all(|(&f, &p)| (f == NONE) == p)
    }

    /// Copy the assembled lower-triangle matrix into the full node-block rows of `bsr`.
    fn fill_bsr(&mut self) {
        let cp = &self.colptr;
        let cv = self.mat.val();
        let rank = &self.bsr_rank;
        let bsr = &mut self.bsr;
        let (ptr, col) = (&bsr.ptr, &bsr.col);
        let mut rows: Vec<&mut [f64]> = Vec::with_capacity(ptr.len() - 1);
        let mut rest: &mut [f64] = &mut bsr.val;
        for a in 0..ptr.len() - 1 {
            let (head, tail) = rest.split_at_mut(9 * (ptr[a + 1] - ptr[a]));
            rows.push(head);
            rest = tail;
        }
        rows.into_par_iter().enumerate().for_each(|(a, out)| {
            for k in ptr[a]..ptr[a + 1] {
                let b = col[k] as usize;
                let r = rank[k] as usize;
                let o = &mut out[9 * (k - ptr[a])..9 * (k - ptr[a]) + 9];
                for i in 0..3 {
                    for j in 0..3 {
                        o[3 * i + j] = if b < a {
                            cv[cp[3 * b + j] + (3 - j) + 3 * r + i]
                        } else if b > a {
                            cv[cp[3 * a + i] + (3 - i) + 3 * r + j]
                        } else if i >= j {
                            cv[cp[3 * a + j] + i - j]
                        } else {
                            cv[cp[3 * a + i] + j - i]
                        };
                    }
                }
            }
        });
    }

    /// Value index of entry (3·fa + i, 3·fb + j), fa ≥ fb, (i ≥ j when fa = fb).
    fn offset(&self, fa: usize, fb: usize, i: usize, j: usize) -> usize {
        let base = self.colptr[3 * fb + j];
        if fa == fb {
            base + i - j
        } else {
            let r = self.nbrs[fb][1..]
                .binary_search(&fa)
                .expect("pair in pattern");
            base + (3 - j) + 3 * r + i
        }
    }

    /// A = mass_coef·M + stiff_coef·(Σ_e R_e K₀ R_eᵀ + K_x) with the element `rotations`.
    fn assemble(&mut self, interior: &Interior, rotations: &[M3], terms: &MatrixTerms) {
        let MatrixTerms {
            mass_coef,
            stiff_coef,
            lumped,
            extra,
            corrections,
        } = *terms;
        let k = interior.nodes_per_element();
        let colptr = &self.colptr;
        let free = &self.free;
        let node_elems = &self.node_elems;
        // Split the value array into the three columns of each free node.
        let vals = self.mat.val_mut();
        let mut slices: Vec<&mut [f64]> = Vec::with_capacity(self.nfree);
        let mut rest: &mut [f64] = vals;
        for b in 0..self.nfree {
            let len = colptr[3 * b + 3] - colptr[3 * b];
            let (head, tail) = rest.split_at_mut(len);
            slices.push(head);
            rest = tail;
        }
        let slots = &self.slots;
        let slot_ptr = &self.slot_ptr;
        slices.into_par_iter().enumerate().for_each(|(fb, col)| {
            col.fill(0.0);
            let c0 = colptr[3 * fb];
            let cj = [0, colptr[3 * fb + 1] - c0, colptr[3 * fb + 2] - c0];
            let mut s = slot_ptr[fb];
            for &(e, lb) in &node_elems[fb] {
                let (e, lb) = (e as usize, lb as usize);
                let r = &rotations[e];
                let rt = r.transpose();
                for la in 0..k {
                    let slot = slots[s + la];
                    if slot == SLOT_SKIP {
                        continue;
                    }
                    let mut rb = r * interior.k0_blocks[la * k + lb] * rt;
                    if let Some(Some(c)) = corrections.get(e) {
                        rb += c.block(la, lb);
                    }
                    rb *= stiff_coef;
                    if lumped.is_none() {
                        let m = mass_coef * interior.m0[la * k + lb];
                        for i in 0..3 {
                            rb[(i, i)] += m;
                        }
                    }
                    if slot == SLOT_DIAG {
                        for j in 0..3 {
                            for i in j..3 {
                                col[cj[j] + i - j] += rb[(i, j)];
                            }
                        }
                    } else {
                        let rk = 3 * slot as usize;
                        for j in 0..3 {
                            let base = cj[j] + (3 - j) + rk;
                            for i in 0..3 {
                                col[base + i] += rb[(i, j)];
                            }
                        }
                    }
                }
                s += k;
            }
        });
        if let Some(m) = lumped {
            for (n, &fb) in free.iter().enumerate() {
                if fb != NONE {
                    for j in 0..3 {
                        let o = self.colptr[3 * fb + j];
                        self.mat.val_mut()[o] += mass_coef * m[n];
                    }
                }
            }
        }
        if let Some(ex) = extra {
            debug_assert_eq!(ex.len(), self.extra_slots.len(), "slots of this layout");
            let vals = self.mat.val_mut();
            for (&(_, _, v), &o) in ex.iter().zip(&self.extra_slots) {
                if o != usize::MAX {
                    vals[o] += stiff_coef * v;
                }
            }
        }
    }

    /// Where each extra triplet goes in `mat`'s values ([`Self::extra_slots`]).
    fn place_extra(&mut self, extra: &[(usize, usize, f64)]) {
        let free = &self.free;
        let slots = extra
            .iter()
            .map(|&(r, c, _)| {
                let (fa, fb) = (free[r / 3], free[c / 3]);
                let (i, j) = (r % 3, c % 3);
                // Pinned, or the upper triangle (the lower one carries it).
                if fa == NONE || fb == NONE || 3 * fa + i < 3 * fb + j {
                    usize::MAX
                } else {
                    self.offset(fa, fb, i, j)
                }
            })
            .collect();
        self.extra_slots = slots;
    }
}

/// Node triplets (a, b, value) summed into CSR form (row pointers, columns, values).
fn node_csr(n: usize, mut t: Vec<(usize, usize, f64)>) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    t.sort_unstable_by_key(|&(a, b, _)| (a, b));
    let mut ptr = vec![0usize; n + 1];
    let mut col: Vec<usize> = Vec::new();
    let mut val: Vec<f64> = Vec::new();
    let mut last = (usize::MAX, usize::MAX);
    for (a, b, v) in t {
        if (a, b) == last {
            *val.last_mut().expect("entry") += v;
        } else {
            col.push(b);
            val.push(v);
            ptr[a + 1] += 1;
            last = (a, b);
        }
    }
    for i in 0..n {
        ptr[i + 1] += ptr[i];
    }
    (ptr, col, val)
}

/// FNV-1a hash of the (row, column) sequence of stiffness triplets: the key a step compares
/// to know its matrix layout still holds (an [`ExtraTerms::layout`] for a caller that keeps
/// one stiffness over many steps).
pub fn triplet_layout_key(stiffness: &[(usize, usize, f64)]) -> u64 {
    let mut h = crate::math::hash::Fnv1a::new();
    for &(r, c, _) in stiffness {
        h.mix_usize(r);
        h.mix_usize(c);
    }
    h.mix_usize(stiffness.len());
    h.finish()
}

fn extra_signature(extra: Option<&ExtraTerms>) -> Vec<(usize, usize)> {
    node_pairs(extra.map_or(&[], |x| x.stiffness))
}

/// The node pairs (larger, smaller) that `stiffness` triplets over DOFs couple, sorted.
fn node_pairs(stiffness: &[(usize, usize, f64)]) -> Vec<(usize, usize)> {
    let mut s: Vec<(usize, usize)> = stiffness
        .iter()
        .map(|&(r, c, _)| ((r / 3).max(c / 3), (r / 3).min(c / 3)))
        .collect();
    s.sort_unstable();
    s.dedup();
    s
}

/// The stiffness of an interior over its free DOFs, K(x) = Σ_e (R_e K₀ R_eᵀ + C_e) + K_x
/// (N/m: the element rotations R_e of x, their rotation-derivative corrections C_e, and
/// constant extra triplets K_x), assembled straight into the compressed lower triangle of
/// 3 × 3 node blocks that [`BackwardEuler`]'s quasi-static Newton factorises: for other
/// Newton loops over the same interior (the muscles' equilibria), which would otherwise sort
/// 27² × 9 triplets per element into a matrix at every factorisation.
pub struct StiffnessMatrix {
    system: System,
}

impl StiffnessMatrix {
    /// The pattern of `interior`'s elements over the nodes not `pinned`, plus the node pairs
    /// of the `extra` triplets (over DOFs) to be added at each assembly.
    pub fn new(
        interior: &Interior,
        pinned: &[bool],
        extra: &[(usize, usize, f64)],
    ) -> Result<Self, FemError> {
        if pinned.len() != interior.nodes {
            return Err(FemError::Input(format!(
                "{} pin flags for {} nodes",
                pinned.len(),
                interior.nodes
            )));
        }
        let mut system = System::new(interior, pinned, &node_pairs(extra))?;
        system.extra_hash = triplet_layout_key(extra);
        system.place_extra(extra);
        Ok(Self { system })
    }

    /// Whether `extra` triplets fit the layout this matrix was built for (else build anew).
    pub fn fits(&self, pinned: &[bool], extra: &[(usize, usize, f64)]) -> bool {
        self.system.pins(pinned) && self.system.extra_hash == triplet_layout_key(extra)
    }

    /// K(x) at node positions `x` (flat, m) of `interior` with its current actuation, the
    /// stress term of C_e projected to positive semi-definite when `project`, plus `extra`
    /// (the layout given at construction) and `diagonal` (N/m) on every free DOF: the lower
    /// triangle, column-compressed over the free DOFs (3 per free node, in node order).
    pub fn assemble(
        &mut self,
        interior: &Interior,
        x: &[f64],
        project: bool,
        extra: &[(usize, usize, f64)],
        diagonal: f64,
    ) -> &SparseColMat<usize, f64> {
        let rotations: Vec<M3> = (0..interior.elements.len())
            .into_par_iter()
            .map(|e| interior.element_rotation(x, e))
            .collect();
        let corrections: Vec<Option<RotationCorrection>> = (0..interior.elements.len())
            .into_par_iter()
            .map(|e| interior.rotation_correction(x, e, project))
            .collect();
        let terms = MatrixTerms {
            mass_coef: 0.0,
            stiff_coef: 1.0,
            lumped: None,
            extra: Some(extra),
            corrections: &corrections,
        };
        let sys = &mut self.system;
        sys.assemble(interior, &rotations, &terms);
        let vals = sys.mat.val_mut();
        for &c in &sys.colptr[..3 * sys.nfree] {
            vals[c] += diagonal;
        }
        &sys.mat
    }
}

/// Backward Euler time stepping of the lattice interior (state q, v; see the module notes).
pub struct BackwardEuler {
    /// The elastic energy and element data.
    pub interior: Interior,
    /// Node positions (flat, m).
    pub q: Vec<f64>,
    /// Node velocities (flat, m/s).
    pub v: Vec<f64>,
    /// Pinned nodes: they keep their position in `q` through a step (velocity zero). To drive
    /// bone (e.g. a jaw), write the pinned nodes' new positions into `q` before `step`.
    /// Changing which nodes are pinned rebuilds the sparse pattern on the next solve.
    pub pinned: Vec<bool>,
    /// Time step, Newton and mass settings.
    pub settings: StepSettings,
    /// Simulated time (s).
    pub time: f64,
    /// Consistent node mass matrix, CSR over nodes (row pointers, columns, kg).
    node_mass: (Vec<usize>, Vec<usize>, Vec<f64>),
    lumped: Vec<f64>,
    system: Option<System>,
    solver: SpdSolver,
    /// The (mass, stiffness) coefficients of the Newton matrix `solver` last factorised
    /// (time steps only; `None` when it holds no factor of one).
    factor_coefs: Option<(f64, f64)>,
    eval_clock: std::cell::Cell<(f64, usize)>,
    /// First Newton direction of the last time step (free DOFs, m), CG's warm start.
    last_direction: Option<Vec<f64>>,
    /// CG's matrix-free Newton operator (built on the first CG solve without K_x).
    operator: Option<ElementOperator>,
    /// Positions of the last potential evaluation with gradient and its element rotations.
    rot_cache: std::cell::RefCell<(Vec<f64>, Vec<M3>)>,
}

impl BackwardEuler {
    /// Put the interior back at rest at positions `q0` (flat, m), with zero velocity at time
    /// zero and no warm start or factor from earlier steps.
    pub fn reset_to_rest(&mut self, q0: &[f64]) {
        self.q.copy_from_slice(q0);
        self.v.iter_mut().for_each(|v| *v = 0.0);
        self.time = 0.0;
        self.last_direction = None;
        self.factor_coefs = None;
    }

    /// A stepper starting at rest at positions `q0` (flat, m) with `pinned` nodes.
    pub fn new(
        interior: Interior,
        q0: Vec<f64>,
        pinned: Vec<bool>,
        settings: StepSettings,
    ) -> Result<Self, FemError> {
        settings.validate()?;
        let n = interior.nodes;
        if q0.len() != 3 * n || pinned.len() != n {
            return Err(FemError::Input(format!(
                "expected {} positions and {n} pin flags, got {} and {}",
                3 * n,
                q0.len(),
                pinned.len()
            )));
        }
        if q0.iter().any(|x| !x.is_finite()) {
            return Err(FemError::Input(
                "initial positions contain a non-finite value".into(),
            ));
        }
        let node_mass = node_csr(n, interior.node_mass(false));
        let lumped = interior.node_masses();
        Ok(Self {
            interior,
            v: vec![0.0; q0.len()],
            q: q0,
            pinned,
            settings,
            time: 0.0,
            node_mass,
            lumped,
            system: None,
            solver: SpdSolver::new(),
            factor_coefs: None,
            eval_clock: std::cell::Cell::new((0.0, 0)),
            last_direction: None,
            operator: None,
            rot_cache: Default::default(),
        })
    }

    /// y ↦ M y (flat node vectors; the consistent mass matrix, or the lumped one when the
    /// settings ask; kg · the unit of y).
    pub fn mass_times(&self, y: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; y.len()];
        if self.settings.lumped_mass {
            for (n, m) in self.lumped.iter().enumerate() {
                for i in 0..3 {
                    out[3 * n + i] = m * y[3 * n + i];
                }
            }
        } else {
            let (ptr, col, val) = &self.node_mass;
            out.par_chunks_mut(3).enumerate().for_each(|(a, o)| {
                for k in ptr[a]..ptr[a + 1] {
                    let (b, m) = (col[k], val[k]);
                    for i in 0..3 {
                        o[i] += m * y[3 * b + i];
                    }
                }
            });
        }
        out
    }

    /// The linear response of `steps` backward Euler steps of the current dt, taken from
    /// the current state, to a constant extra force `df` (flat over node dofs, N) held over
    /// them: the change of the end positions and velocities (flat, m and m/s; zero at pinned
    /// nodes), with the last factorised Newton matrix M + h²(K + K_x) as every step's
    /// tangent: δy_k = A⁻¹ (M (δy_{k−1} + h δv_{k−1}) + h² δf), δv_k = (δy_k − δy_{k−1}) / h.
    /// Exact for a quadratic energy whose matrix the steps share; to first order in `df`
    /// otherwise. K_x is taken about fixed positions: a caller whose [`ExtraTerms`] force
    /// carries the stiffness from each step's start to its anchor (as the pipeline's
    /// coupling does) gets its steps' response. `None` when no Cholesky factor of a time step of this dt is at hand
    /// (conjugate gradients, a quasi-static solve, or no step yet).
    pub fn linear_response(&self, df: &[f64], steps: usize) -> Option<(Vec<f64>, Vec<f64>)> {
        let h = self.settings.dt;
        let (mass_coef, stiff_coef) = self.factor_coefs?;
        let same_dt = mass_coef == 1.0 && (stiff_coef - h * h).abs() <= 1e-12 * h * h;
        let sys = self.system.as_ref()?;
        if !same_dt || df.len() != self.q.len() {
            return None;
        }
        let n = df.len();
        let (mut y, mut v) = (vec![0.0; n], vec![0.0; n]);
        for _ in 0..steps {
            let predicted: Vec<f64> = (0..n).map(|i| y[i] + h * v[i]).collect();
            let m = self.mass_times(&predicted);
            let mut rhs = vec![0.0; 3 * sys.nfree];
            for (node, &f) in sys.free.iter().enumerate() {
                if f != NONE {
                    for i in 0..3 {
                        let d = 3 * node + i;
                        rhs[3 * f + i] = m[d] + h * h * df[d];
                    }
                }
            }
            self.solver.solve_in_place(&mut rhs);
            let mut next = vec![0.0; n];
            for (node, &f) in sys.free.iter().enumerate() {
                if f != NONE {
                    next[3 * node..3 * node + 3].copy_from_slice(&rhs[3 * f..3 * f + 3]);
                }
            }
            for i in 0..n {
                v[i] = (next[i] - y[i]) / h;
            }
            y = next;
        }
        Some((y, v))
    }

    fn ensure_system(&mut self, extra: Option<&ExtraTerms>) -> Result<(), FemError> {
        // The sorted pattern signature costs a sort of every extra triplet; the caller's
        // layout key, or a hash of the triplet layout (O(n), no allocation), tells first
        // whether anything could differ.
        let hash = match extra {
            Some(x) => x.layout.unwrap_or_else(|| triplet_layout_key(x.stiffness)),
            None => triplet_layout_key(&[]),
        };
        if let Some(s) = &self.system {
            if s.extra_hash == hash && s.pins(&self.pinned) {
                return Ok(());
            }
        }
        let sig = extra_signature(extra);
        let rebuild = match &self.system {
            Some(s) => s.extra_sig != sig || !s.pins(&self.pinned),
            None => true,
        };
        if rebuild {
            self.system = Some(System::new(&self.interior, &self.pinned, &sig)?);
            self.solver.reset();
            self.factor_coefs = None;
            self.last_direction = None;
            self.operator = None;
        }
        if let Some(s) = self.system.as_mut() {
            s.extra_hash = hash;
            s.place_extra(extra.map_or(&[], |x| x.stiffness));
        }
        Ok(())
    }

    fn check_inputs(&self, f_ext: &[f64], extra: Option<&ExtraTerms>) -> Result<(), FemError> {
        let n = self.q.len();
        if f_ext.len() != n {
            return Err(FemError::Input(format!(
                "external force has {} entries, expected {n}",
                f_ext.len()
            )));
        }
        if let Some(x) = extra {
            if x.force.len() != n {
                return Err(FemError::Input(format!(
                    "extra force has {} entries, expected {n}",
                    x.force.len()
                )));
            }
            // A caller's layout key vouches for the triplets it has shown before.
            let known =
                x.layout.is_some() && x.layout == self.system.as_ref().map(|s| s.extra_hash);
            if !known
                && x.stiffness
                    .iter()
                    .any(|&(r, c, v)| r >= n || c >= n || !v.is_finite())
            {
                return Err(FemError::Input(
                    "extra stiffness has an index out of range or a non-finite value".into(),
                ));
            }
        }
        if f_ext.iter().any(|f| !f.is_finite()) {
            return Err(FemError::Input(
                "external force contains a non-finite value".into(),
            ));
        }
        Ok(())
    }

    /// One backward Euler step with external node forces `f_ext` (flat, N; surface forces
    /// enter as Bᵀ f) and optional coupling terms. Advances q, v and time even when the
    /// Newton solve did not converge (the report says so).
    pub fn step(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.step_from(f_ext, extra, None)
    }

    /// [`Self::step`] with Newton started at `start` (node positions, flat, m; pinned nodes
    /// keep theirs) instead of the inertial predictor q + h v: a step taken again under a
    /// slightly changed load (a later interior–skin coupling pass) starts where the last
    /// attempt ended. The step's answer is the same; only the iterations to it change.
    pub fn step_from(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
        start: Option<&[f64]>,
    ) -> Result<SolveReport, FemError> {
        self.check_inputs(f_ext, extra)?;
        if let Some(s) = start {
            if s.len() != self.q.len() || s.iter().any(|v| !v.is_finite()) {
                return Err(FemError::Input(
                    "a step's start has the wrong length or a non-finite value".into(),
                ));
            }
        }
        self.ensure_system(extra)?;
        let h = self.settings.dt;
        let x0 = self.q.clone();
        let mut y: Vec<f64> = x0.clone();
        for n in 0..self.interior.nodes {
            if !self.pinned[n] {
                for i in 0..3 {
                    y[3 * n + i] += h * self.v[3 * n + i];
                }
            }
        }
        let target: Vec<f64> = y.clone();
        if let Some(s) = start {
            for n in (0..self.interior.nodes).filter(|&n| !self.pinned[n]) {
                y[3 * n..3 * n + 3].copy_from_slice(&s[3 * n..3 * n + 3]);
            }
        }
        let report = self.minimise(&mut y, &x0, Some((&target, h)), f_ext, extra)?;
        for i in 0..y.len() {
            self.v[i] = (y[i] - x0[i]) / h;
        }
        for n in 0..self.interior.nodes {
            if self.pinned[n] {
                for i in 0..3 {
                    self.v[3 * n + i] = 0.0;
                }
            }
        }
        self.q = y;
        self.time += h;
        Ok(report)
    }

    /// Quasi-static equilibrium from the current q: minimise E(y) − (f_ext + f_g)ᵀ y (+ E_x)
    /// over the free nodes; sets q to the result and v to zero. Needs pinned nodes (or a
    /// positive definite K_x) to remove rigid motions.
    pub fn quasi_static(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.check_inputs(f_ext, extra)?;
        self.ensure_system(extra)?;
        let x0 = self.q.clone();
        let mut y = x0.clone();
        let report = self.minimise(&mut y, &x0, None, f_ext, extra)?;
        self.q = y;
        self.v.iter_mut().for_each(|v| *v = 0.0);
        Ok(report)
    }

    /// Φ and ∇Φ at y (timed into `self.eval_clock`); the gradient is empty unless
    /// `want_grad`.
    fn potential(&self, terms: &Terms, y: &[f64], want_grad: bool) -> (f64, Vec<f64>) {
        let t = Instant::now();
        let out = self.potential_raw(terms, y, want_grad);
        let (s, n) = self.eval_clock.get();
        self.eval_clock.set((s + t.elapsed().as_secs_f64(), n + 1));
        out
    }

    fn potential_raw(&self, terms: &Terms, y: &[f64], want_grad: bool) -> (f64, Vec<f64>) {
        let (x0, force) = (terms.x0, terms.force);
        let n = y.len();
        let mut g = if want_grad { vec![0.0; n] } else { Vec::new() };
        let mut phi = if want_grad {
            let mut cache = self.rot_cache.borrow_mut();
            let (at, rot) = &mut *cache;
            let e = self.interior.eval_with_rotations(y, &mut g, rot);
            at.clear();
            at.extend_from_slice(y);
            e
        } else {
            self.interior.eval(y, None, None, false)
        };
        if let Some((target, h)) = terms.inertia {
            let d: Vec<f64> = y.iter().zip(target).map(|(a, b)| a - b).collect();
            let md = self.mass_times(&d);
            let inv = 1.0 / (h * h);
            phi += 0.5 * inv * d.iter().zip(&md).map(|(a, b)| a * b).sum::<f64>();
            if want_grad {
                for i in 0..n {
                    g[i] += inv * md[i];
                }
            }
        }
        for i in 0..n {
            phi -= force[i] * y[i];
            if want_grad {
                g[i] -= force[i];
            }
        }
        if let Some(x) = terms.extra {
            let dy: Vec<f64> = y.iter().zip(x0).map(|(a, b)| a - b).collect();
            let mut kd = vec![0.0; n];
            for &(r, c, v) in x.stiffness {
                kd[r] += v * dy[c];
            }
            for i in 0..n {
                phi += -x.force[i] * dy[i] + 0.5 * dy[i] * kd[i];
                if want_grad {
                    g[i] += -x.force[i] + kd[i];
                }
            }
        }
        (phi, g)
    }

    fn free_norm(&self, g: &[f64]) -> f64 {
        let mut s = 0.0;
        for n in 0..self.interior.nodes {
            if !self.pinned[n] {
                for i in 0..3 {
                    s += g[3 * n + i] * g[3 * n + i];
                }
            }
        }
        s.sqrt()
    }

    /// Force scale (N) the tolerance applies to, given the first residual `res`: the larger
    /// of it, the applied forces, and (floor) the force that strains one cell face by 1e-3 —
    /// so a state already at rest counts as converged instead of chasing round-off.
    fn reference_force(&self, res: f64, terms: &Terms) -> f64 {
        let mut applied = self.free_norm(terms.force);
        if let Some(x) = terms.extra {
            applied += self.free_norm(x.force);
        }
        let cell_force = 1e-3 * self.interior.mu * self.interior.cell_size.powi(2);
        res.max(applied).max(cell_force)
    }

    /// Element rotations at `y`: those of the last gradient evaluation when it was at `y`
    /// (it usually is), else computed.
    fn rotations_at(&self, y: &[f64]) -> Vec<M3> {
        let cache = self.rot_cache.borrow();
        if cache.0.as_slice() == y && cache.1.len() == self.interior.elements.len() {
            cache.1.clone()
        } else {
            drop(cache);
            let interior = &self.interior;
            (0..interior.elements.len())
                .into_par_iter()
                .map(|e| interior.element_rotation(y, e))
                .collect()
        }
    }

    /// The rotation-derivative part of each element's stiffness at `y` (exact, or with its
    /// stress term projected to positive semi-definite when `project`), or none when the
    /// settings ask for the frozen-rotation stiffness.
    fn corrections_at(&self, y: &[f64], project: bool) -> Vec<Option<RotationCorrection>> {
        match self.settings.tangent {
            Tangent::Frozen => Vec::new(),
            Tangent::Consistent => {
                let interior = &self.interior;
                (0..interior.elements.len())
                    .into_par_iter()
                    .map(|e| interior.rotation_correction(y, e, project))
                    .collect()
            }
        }
    }

    /// The linear solver of the settings with [`LinearSolver::Auto`] resolved for a system
    /// of `free_dofs` (a `time_step` or a quasi-static solve).
    fn resolved_solver(&self, free_dofs: usize, time_step: bool) -> LinearSolver {
        match self.settings.linear_solver {
            LinearSolver::Auto if time_step && free_dofs > AUTO_CG_DOFS => {
                LinearSolver::ConjugateGradient {
                    rel_tol: AUTO_CG_REL_TOL,
                    max_iter: 1000,
                }
            }
            LinearSolver::Auto => LinearSolver::Cholesky,
            other => other,
        }
    }

    /// Bring the Newton matrix M_coef·M + K_coef·(K(rotations) + K_x) up to date: the
    /// element operator when `matrix_free`, else the assembled matrix.
    fn prepare_matrix(
        &mut self,
        terms: &Terms,
        rotations: Vec<M3>,
        corrections: Vec<Option<RotationCorrection>>,
        matrix_free: bool,
    ) {
        let (mass_coef, stiff_coef) = terms.coefficients();
        let lumped = if self.settings.lumped_mass {
            Some(self.lumped.as_slice())
        } else {
            None
        };
        let sys = self.system.as_mut().expect("system built");
        if matrix_free {
            let op = self
                .operator
                .get_or_insert_with(|| ElementOperator::new(&self.interior, &sys.free));
            let lumped_free = lumped.map(|m| sys.free_nodes.iter().map(|&nd| m[nd]).collect());
            op.update(
                &self.interior,
                rotations,
                corrections,
                mass_coef,
                stiff_coef,
                lumped_free,
            );
        } else {
            let coefs = MatrixTerms {
                mass_coef,
                stiff_coef,
                lumped,
                extra: terms.extra.map(|x| x.stiffness),
                corrections: &corrections,
            };
            sys.assemble(&self.interior, &rotations, &coefs);
        }
    }

    /// Solve the prepared Newton system for `rhs` (free DOFs) with `solver` (resolved);
    /// returns the solution and the CG iterations, or `None` when the matrix is not
    /// positive definite and `may_fail` (the caller then tries a projected one). `warm`: the
    /// first Newton iteration of a time step, whose CG starts from and records the last
    /// step's first direction.
    fn solve_newton_system(
        &mut self,
        solver: LinearSolver,
        matrix_free: bool,
        mut rhs: Vec<f64>,
        (warm, time_step, may_fail): (bool, bool, bool),
    ) -> Result<Option<(Vec<f64>, usize)>, FemError> {
        let sys = self.system.as_mut().expect("system built");
        match solver {
            LinearSolver::Auto => unreachable!("resolved by the caller"),
            LinearSolver::Cholesky => {
                if let Err(e) = self.solver.factorize(&sys.mat) {
                    if may_fail {
                        return Ok(None);
                    }
                    return Err(if time_step {
                        FemError::Sparse(e)
                    } else {
                        FemError::Input(format!(
                            "quasi-static solve: the stiffness is singular ({e}); pin nodes to remove rigid motions"
                        ))
                    });
                }
                self.solver.solve_in_place(&mut rhs);
                Ok(Some((rhs, 0)))
            }
            LinearSolver::ConjugateGradient { rel_tol, max_iter } => {
                // Warm start: the first Newton direction of the last time step (the
                // velocity change varies slowly between steps).
                let guess = if warm {
                    self.last_direction.as_deref()
                } else {
                    None
                };
                let (x, it) = if matrix_free {
                    let op = self.operator.as_ref().expect("updated before");
                    let inv = op.diag_inverses();
                    pcg(op, &inv, &rhs, guess, rel_tol, max_iter)
                } else {
                    sys.fill_bsr();
                    let inv = sys.bsr.diag_inverses();
                    pcg(&sys.bsr, &inv, &rhs, guess, rel_tol, max_iter)
                };
                if warm {
                    self.last_direction = Some(x.clone());
                }
                Ok(Some((x, it)))
            }
        }
    }

    /// Minimise Φ over the free nodes from `y` (updated in place) by the Newton core
    /// ([`crate::solver::newton`]); `inertia` is the target y₀ + h v and the time step h
    /// (s) of a backward Euler step, `None` for a quasi-static solve.
    fn minimise(
        &mut self,
        y: &mut [f64],
        x0: &[f64],
        inertia: Option<(&[f64], f64)>,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.eval_clock.set((0.0, 0));
        let gvec = Vector3::from(self.settings.gravity);
        let fg = self.interior.gravity_force(gvec);
        let force: Vec<f64> = fg.iter().zip(f_ext).map(|(a, b)| a + b).collect();
        let terms = Terms {
            x0,
            inertia,
            force: &force,
            extra,
        };
        let (phi, g) = self.potential(&terms, y, true);
        let res = self.free_norm(&g);
        let reference = self.reference_force(res, &terms);
        let limits = NewtonLimits {
            max_iterations: self.settings.max_newton,
            max_trials: 30,
        };
        let mut problem = EulerNewton {
            report: SolveReport {
                status: SolveStatus::IterationLimit,
                iterations: 0,
                residual: res,
                relative_residual: res / reference,
                assembly_s: 0.0,
                solve_s: 0.0,
                cg_iterations: 0,
                energy_s: 0.0,
                evaluations: 0,
            },
            be: self,
            terms,
            y,
            phi,
            g,
            res,
            reference,
            line: EulerLine::default(),
        };
        let record = newton::solve(&mut problem, &limits)?;
        let mut report = problem.report;
        report.status = interior_status(record.status);
        report.iterations = record.iterations;
        let (es, en) = self.eval_clock.get();
        report.energy_s = es;
        report.evaluations = en;
        Ok(report)
    }
}

/// The fixed terms of one minimisation of Φ: the positions at the start of the step x0 (m),
/// the inertia target y₀ + h v (m) and time step h (s) (`None`: quasi-static), the applied
/// force f_ext + f_g (N, flat) and the coupling terms.
#[derive(Clone, Copy)]
struct Terms<'a> {
    x0: &'a [f64],
    inertia: Option<(&'a [f64], f64)>,
    force: &'a [f64],
    extra: Option<&'a ExtraTerms<'a>>,
}

impl Terms<'_> {
    /// Coefficients (of M, of K) of the Newton matrix: (1, h²) for a time step, (0, 1)
    /// quasi-static.
    fn coefficients(&self) -> (f64, f64) {
        match self.inertia {
            Some((_, h)) => (1.0, h * h),
            None => (0.0, 1.0),
        }
    }
}

/// The search line of the last Newton direction of Φ.
#[derive(Default)]
struct EulerLine {
    /// Direction over all DOFs (m; zero at pinned nodes).
    dir: Vec<f64>,
    /// ∇Φ · dir (J per unit step).
    slope: f64,
    /// Largest |dir| component (m).
    step_max: f64,
    /// Positions of the last trial (m).
    trial: Vec<f64>,
    /// Φ (J) and ∇Φ (N) of the last trial when it was accepted.
    accepted: Option<(f64, Vec<f64>)>,
}

/// One minimisation of Φ as a [`NewtonProblem`]: the interior's own linear solvers
/// (Cholesky or CG, matrix-free or assembled) and the iterate y with Φ(y), ∇Φ(y).
struct EulerNewton<'a, 't> {
    be: &'a mut BackwardEuler,
    terms: Terms<'t>,
    y: &'a mut [f64],
    /// Φ(y) (J).
    phi: f64,
    /// ∇Φ(y) (N, all DOFs).
    g: Vec<f64>,
    /// ‖∇Φ‖ over free DOFs (N).
    res: f64,
    /// Force scale of the tolerance (N).
    reference: f64,
    report: SolveReport,
    line: EulerLine,
}

impl EulerNewton<'_, '_> {
    fn converged(&self) -> bool {
        self.res <= self.be.settings.tolerance * self.reference
    }

    /// Right-hand side −K_coef ∇Φ over free DOFs.
    fn newton_rhs(&self) -> Vec<f64> {
        let sys = self.be.system.as_ref().expect("system built");
        let stiff_coef = self.terms.coefficients().1;
        let mut rhs = vec![0.0; 3 * sys.nfree];
        for (n, &f) in sys.free.iter().enumerate() {
            if f != NONE {
                for i in 0..3 {
                    rhs[3 * f + i] = -stiff_coef * self.g[3 * n + i];
                }
            }
        }
        rhs
    }

    /// The free-DOF solution `dy` scattered over all DOFs.
    fn scatter(&self, dy: &[f64]) -> Vec<f64> {
        let sys = self.be.system.as_ref().expect("system built");
        let mut dir = vec![0.0; self.y.len()];
        for (n, &f) in sys.free.iter().enumerate() {
            if f != NONE {
                for i in 0..3 {
                    dir[3 * n + i] = dy[3 * f + i];
                }
            }
        }
        dir
    }

    /// ∇Φ at the trial point, evaluated now unless `gt` already holds it.
    fn trial_gradient(&self, gt: Vec<f64>) -> Vec<f64> {
        if gt.is_empty() {
            self.be.potential(&self.terms, &self.line.trial, true).1
        } else {
            gt
        }
    }
}

impl NewtonProblem for EulerNewton<'_, '_> {
    type Error = FemError;

    fn check(&mut self) -> Check {
        if self.converged() {
            Check::Converged
        } else {
            Check::Continue
        }
    }

    /// Solve [M_coef M + K_coef (K + K_x)] Δy = −K_coef ∇Φ. With the consistent tangent the
    /// exact Hessian is tried first (quadratic convergence); when it is not positive
    /// definite or gives no descent direction, its stress term is projected and the system
    /// solved again.
    fn direction(&mut self, iteration: usize) -> Result<Option<SolveStatus>, FemError> {
        let time_step = self.terms.inertia.is_some();
        let nfree = self.be.system.as_ref().expect("system built").nfree;
        let solver = self.be.resolved_solver(3 * nfree, time_step);
        // CG without coupling terms multiplies element by element (no assembly); with
        // K_x it multiplies the assembled matrix.
        let matrix_free =
            matches!(solver, LinearSolver::ConjugateGradient { .. }) && self.terms.extra.is_none();
        let consistent = self.be.settings.tangent == Tangent::Consistent;
        let warm = time_step && iteration == 0;
        for project in [false, true] {
            let last = project || !consistent;
            let t0 = Instant::now();
            let rotations = self.be.rotations_at(self.y);
            let corrections = self.be.corrections_at(self.y, project);
            self.be
                .prepare_matrix(&self.terms, rotations, corrections, matrix_free);
            self.report.assembly_s += t0.elapsed().as_secs_f64();
            let t1 = Instant::now();
            let rhs = self.newton_rhs();
            let flags = (warm, time_step, !last);
            let solved = self
                .be
                .solve_newton_system(solver, matrix_free, rhs, flags)?;
            let factored = time_step && solved.is_some() && solver == LinearSolver::Cholesky;
            self.be.factor_coefs = factored.then(|| self.terms.coefficients());
            self.report.solve_s += t1.elapsed().as_secs_f64();
            let Some((dy, cg_iterations)) = solved else {
                continue;
            };
            self.report.cg_iterations += cg_iterations;
            let dir = self.scatter(&dy);
            let slope: f64 = dir.iter().zip(&self.g).map(|(d, gi)| d * gi).sum();
            if slope < 0.0 || last {
                self.line = EulerLine {
                    slope,
                    step_max: dir.iter().fold(0.0f64, |m, d| m.max(d.abs())),
                    dir,
                    trial: self.y.to_vec(),
                    accepted: None,
                };
                break;
            }
        }
        Ok(None)
    }

    /// Armijo on Φ (c = 1e-4), or, near the solution where Φ changes by less than its
    /// round-off, a step that does not raise Φ beyond round-off and lowers the residual.
    /// The full step is evaluated with its gradient (it is usually accepted); shorter steps
    /// first by value only. Steps are halved.
    fn trial(&mut self, t: f64) -> Verdict {
        for i in 0..self.y.len() {
            self.line.trial[i] = self.y[i] + t * self.line.dir[i];
        }
        let (p, gt) = self.be.potential(&self.terms, &self.line.trial, t == 1.0);
        let phi = self.phi;
        let mut accepted = None;
        if p.is_finite() && p <= phi + 1e-4 * t * self.line.slope.min(0.0) {
            accepted = Some((p, self.trial_gradient(gt)));
        } else if p.is_finite() && p - phi <= 1e-12 * phi.abs().max(1e-300) {
            let gt = self.trial_gradient(gt);
            if self.be.free_norm(&gt) < self.res {
                accepted = Some((p, gt));
            }
        }
        self.line.accepted = accepted;
        Verdict {
            accepted: self.line.accepted.is_some(),
            fit: None,
        }
    }

    /// Move to the trial; a step shorter than 1e-14 cells ends the solve (converged when
    /// the residual meets the tolerance, else stalled).
    fn accept(&mut self, t: f64) -> Option<SolveStatus> {
        let (p, g) = self.line.accepted.take().expect("accepted trial");
        self.y.copy_from_slice(&self.line.trial);
        self.phi = p;
        self.res = self.be.free_norm(&g);
        self.g = g;
        self.report.residual = self.res;
        self.report.relative_residual = self.res / self.reference;
        if t * self.line.step_max < 1e-14 * self.be.interior.cell_size {
            return Some(if self.converged() {
                SolveStatus::Converged
            } else {
                SolveStatus::LineSearchFailed
            });
        }
        None
    }

    fn rejected(&mut self) -> Rejection {
        Rejection::Stop(SolveStatus::LineSearchFailed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::bench::cube_lattice;
    use crate::fem::Material;
    use nalgebra::{Rotation3, Unit};

    /// Node positions (flat, m) of `lat` twisted about z (2 rad/m), stretched along x by 20 %
    /// and squashed along z by 10 %: a state with rotations and stress in every element.
    fn twisted(lat: &crate::lattice::Lattice) -> Vec<f64> {
        lat.rest
            .iter()
            .flat_map(|p| {
                let t = 2.0 * p.z;
                let (c, s) = (t.cos(), t.sin());
                [1.2 * (c * p.x - s * p.y), c * p.y + s * p.x, 0.9 * p.z]
            })
            .collect()
    }

    /// The stiffness assembled straight into its pattern is the interior's Hessian from
    /// triplets (exact and projected rotation corrections) restricted to the free DOFs, with
    /// the extra triplets and the diagonal added, at a twisted, stretched, actuated state.
    #[test]
    fn stiffness_matrix_equals_the_triplet_hessian() {
        let h = 0.02;
        let lat = cube_lattice(3, h).unwrap();
        let mut int = Interior::new(&lat, &Material::default()).unwrap();
        let n3 = 3 * int.nodes_per_element();
        let offsets: Vec<f64> = (0..n3 * int.elements.len())
            .map(|i| 1e-3 * (((i * 31) % 17) as f64 / 17.0 - 0.5))
            .collect();
        int.set_actuation(offsets).unwrap();
        let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.5 * h).collect();
        let q = twisted(&lat);
        // Extra triplets coupling two far nodes (outside the element pattern) and a diagonal.
        let last = int.nodes - 1;
        let extra = vec![
            (3 * last, 3 * last, 5.0),
            (3 * last + 1, 3 * (last - 40), -2.0),
            (3 * (last - 40), 3 * last + 1, -2.0),
        ];
        let diagonal = 0.25;
        let mut free = vec![usize::MAX; 3 * int.nodes];
        let mut nfree = 0;
        for (n, _) in pinned.iter().enumerate().filter(|(_, p)| !**p) {
            for i in 0..3 {
                free[3 * n + i] = nfree;
                nfree += 1;
            }
        }
        let mut k = StiffnessMatrix::new(&int, &pinned, &extra).unwrap();
        assert!(k.fits(&pinned, &extra));
        for project in [false, true] {
            let mut trip = Vec::new();
            int.eval(&q, None, Some(&mut trip), project);
            trip.extend_from_slice(&extra);
            let mut want = vec![0.0; nfree * nfree];
            for &(r, c, v) in &trip {
                if free[r] != usize::MAX && free[c] != usize::MAX {
                    want[free[r] * nfree + free[c]] += v;
                }
            }
            (0..nfree).for_each(|i| want[i * nfree + i] += diagonal);
            let mat = k.assemble(&int, &q, project, &extra, diagonal);
            let mut got = vec![0.0; nfree * nfree];
            let (cp, ri, val) = (mat.col_ptr(), mat.row_idx(), mat.val());
            for c in 0..nfree {
                for p in cp[c]..cp[c + 1] {
                    assert!(ri[p] >= c, "lower triangle only");
                    got[ri[p] * nfree + c] += val[p];
                }
            }
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for r in 0..nfree {
                for c in 0..=r {
                    let (g, w) = (got[r * nfree + c], want[r * nfree + c]);
                    assert!(
                        (g - w).abs() <= 1e-12 * scale,
                        "({r}, {c}): {g} against {w}"
                    );
                }
            }
        }
    }

    /// The matrix-free operator and the assembled matrix (lower triangle mirrored into
    /// node-block rows) give the same products and diagonal blocks, with consistent and
    /// with lumped mass, pinned nodes and arbitrary element rotations.
    #[test]
    fn matrix_free_operator_equals_the_assembled_matrix() {
        let h = 0.02;
        let lat = cube_lattice(3, h).unwrap();
        let int = Interior::new(&lat, &Material::default()).unwrap();
        let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.5 * h).collect();
        let mut sys = System::new(&int, &pinned, &[]).unwrap();
        let rot: Vec<M3> = (0..int.elements.len())
            .map(|e| {
                let ax = Unit::new_normalize(Vector3::new(1.0, e as f64, 2.0 - e as f64));
                *Rotation3::from_axis_angle(&ax, 0.3 * e as f64).matrix()
            })
            .collect();
        // The consistent tangent's rotation corrections at a twisted, stretched state.
        let q = twisted(&lat);
        let corrections: Vec<_> = (0..int.elements.len())
            .map(|e| int.rotation_correction(&q, e, true))
            .collect();
        assert!(corrections.iter().all(|c| c.is_some()));
        let lumped_all = int.node_masses();
        let lumped_free: Vec<f64> = sys.free_nodes.iter().map(|&n| lumped_all[n]).collect();
        let n = 3 * sys.nfree;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f64 * 1e-3 - 0.5)
            .collect();
        for lumped in [false, true] {
            let coefs = (1.0, h * h);
            let terms = MatrixTerms {
                mass_coef: coefs.0,
                stiff_coef: coefs.1,
                lumped: lumped.then_some(lumped_all.as_slice()),
                extra: None,
                corrections: &corrections,
            };
            sys.assemble(&int, &rot, &terms);
            sys.fill_bsr();
            let mut op = ElementOperator::new(&int, &sys.free);
            op.update(
                &int,
                rot.clone(),
                corrections.clone(),
                coefs.0,
                coefs.1,
                lumped.then(|| lumped_free.clone()),
            );
            let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
            let e1 = sys.bsr.mul(&x, &mut y1);
            let e2 = op.mul(&x, &mut y2);
            let scale = y1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = y1
                .iter()
                .zip(&y2)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(diff < 1e-12 * scale, "lumped {lumped}: {diff} of {scale}");
            assert!((e1 - e2).abs() < 1e-12 * e1.abs());
            for (a, b) in sys.bsr.diag_inverses().iter().zip(op.diag_inverses()) {
                for k in 0..9 {
                    assert!((a[k] - b[k]).abs() < 1e-9 * a[k].abs().max(1e-3 * a[0].abs()));
                }
            }
        }
    }
}
