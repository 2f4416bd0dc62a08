//! The supernodal LDLᵀ factorisation on two cores, across its elimination tree.
//!
//! faer's supernodal LDLᵀ is left-looking: a supernode gathers the updates of its
//! descendants, factorises its dense diagonal block and scales the rows below. A subtree's
//! supernodes read and write only that subtree, so the two tasks of a [`TreeSplit`] factorise
//! their subtrees at once. The updates their supernodes owe the top (nested dissection's
//! separators, whose fronts are large and dense) are gathered by each task into its own
//! copy of the top's blocks, and the top adds the two copies in a fixed order: the same
//! bits on one thread or two. The top's large fronts are factorised by faer's dense LDLᵀ
//! with two tasks. The layout of the values is faer's, so faer's solves and inertia count
//! read the result.

use super::tree::{column_owners, factor_cost, Scalar, TreeSplit};
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::{
    cholesky_in_place, cholesky_in_place_scratch, LdltRegularization,
};
use faer::linalg::matmul::matmul;
use faer::linalg::triangular_solve::solve_unit_lower_triangular_in_place;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::SparseColMat;
use faer::{Accum, MatMut, MatRef, Par};

/// Task number of the top in [`FactorPlan::owner`].
const TOP: u8 = 2;

/// Fronts at least this wide are factorised by faer's dense LDLᵀ with two tasks.
const PARALLEL_FRONT: usize = 256;

/// What a factorisation across the tree needs beyond the symbolic analysis, built once per
/// analysis.
#[derive(Debug, Clone)]
pub struct FactorPlan {
    /// The split of the elimination tree, balanced by flops.
    split: TreeSplit,
    /// The task of each supernode: 0, 1, or [`TOP`].
    owner: Vec<u8>,
    /// For each supernode, the descendants that update it (pattern rows among its
    /// columns), increasing: `updaters[updater_ptr[s]..updater_ptr[s + 1]]`.
    updater_ptr: Vec<usize>,
    updaters: Vec<u32>,
    /// For each supernode, (index in the factor's values, slot in the assembled matrix's
    /// values) of the matrix's lower entries that land in its block:
    /// `entries[entry_ptr[s]..entry_ptr[s + 1]]`.
    entry_ptr: Vec<usize>,
    entries: Vec<(u32, u32)>,
    /// Whether the diagonal of each permuted column takes the shift (a free dof).
    shifted: Vec<bool>,
    /// Widest supernode (columns).
    widest: usize,
}

/// A supernode's block geometry: first column, columns, pattern rows below them.
struct Block<'a> {
    start: usize,
    ncols: usize,
    pattern: &'a [usize],
}

impl Block<'_> {
    fn nrows(&self) -> usize {
        self.ncols + self.pattern.len()
    }
}

fn block(sym: &SymbolicSupernodalCholesky<usize>, s: usize) -> Block<'_> {
    let sn = sym.supernode(s);
    Block {
        start: sn.start(),
        ncols: sym.supernode_end()[s] - sn.start(),
        pattern: sn.pattern(),
    }
}

/// Group `(key, item)` pairs by key into compressed rows of `n` keys, items in the given
/// order within a key.
fn compress<T: Copy + Default>(n: usize, pairs: &[(usize, T)]) -> (Vec<usize>, Vec<T>) {
    let mut ptr = vec![0usize; n + 1];
    for &(k, _) in pairs {
        ptr[k + 1] += 1;
    }
    for k in 0..n {
        ptr[k + 1] += ptr[k];
    }
    let mut next = ptr.clone();
    let mut items = vec![T::default(); pairs.len()];
    for &(k, v) in pairs {
        items[next[k]] = v;
        next[k] += 1;
    }
    (ptr, items)
}

impl FactorPlan {
    /// The plan for `sym`, whose ordering is `(fwd, inv)`, factorising the lower triangle of
    /// the assembled matrix `a` (its first `n_free` columns take the shift). `None` when
    /// the tree does not split ([`TreeSplit::new`]), a task's supernode would be updated from
    /// outside its task, or the factor is too large for 32-bit indices.
    pub fn new(
        sym: &SymbolicSupernodalCholesky<usize>,
        (fwd, inv): (&[usize], &[usize]),
        a: &SparseColMat<usize, f64>,
        n_free: usize,
    ) -> Option<Self> {
        let split = TreeSplit::new(sym, factor_cost)?;
        let ns = sym.n_supernodes();
        let cpv = sym.col_ptr_for_val();
        if cpv[ns] > u32::MAX as usize || a.val().len() > u32::MAX as usize {
            return None;
        }
        let mut owner = vec![TOP; ns];
        for (t, list) in split.tasks().iter().enumerate() {
            for &s in list {
                owner[s] = t as u8;
            }
        }
        let col_owner = column_owners(sym);
        let mut pairs = Vec::new();
        for d in 0..ns {
            let mut last = usize::MAX;
            for &r in block(sym, d).pattern {
                let s = col_owner[r];
                if s != last {
                    pairs.push((s, d as u32));
                    last = s;
                }
            }
        }
        let (updater_ptr, updaters) = compress(ns, &pairs);
        // A task's supernode must have every descendant in its task (the tasks hold whole
        // subtrees): it gathers only those.
        let closed = (0..ns).all(|s| {
            owner[s] == TOP
                || updaters[updater_ptr[s]..updater_ptr[s + 1]]
                    .iter()
                    .all(|&d| owner[d as usize] == owner[s])
        });
        if !closed {
            return None;
        }
        let (cp, ri) = (a.col_ptr(), a.row_idx());
        let mut pairs = Vec::with_capacity(a.val().len() / 2 + a.ncols());
        for c in 0..a.ncols() {
            for q in cp[c]..cp[c + 1] {
                let r = ri[q];
                if r < c {
                    continue;
                }
                let (i, j) = (inv[r].max(inv[c]), inv[r].min(inv[c]));
                let s = col_owner[j];
                let b = block(sym, s);
                let row = if i < b.start + b.ncols {
                    i - b.start
                } else {
                    b.ncols + b.pattern.binary_search(&i).ok()?
                };
                let at = cpv[s] + (j - b.start) * b.nrows() + row;
                pairs.push((s, (at as u32, q as u32)));
            }
        }
        let (entry_ptr, entries) = compress(ns, &pairs);
        let shifted = fwd.iter().map(|&o| o < n_free).collect();
        let widest = (0..ns).map(|s| block(sym, s).ncols).max().unwrap_or(0);
        Some(Self {
            split,
            owner,
            updater_ptr,
            updaters,
            entry_ptr,
            entries,
            shifted,
            widest,
        })
    }

    fn updaters_of(&self, s: usize) -> impl Iterator<Item = usize> + '_ {
        self.updaters[self.updater_ptr[s]..self.updater_ptr[s + 1]]
            .iter()
            .map(|&d| d as usize)
    }
}

/// Scratch of one task: a row map and work matrices.
struct Scratch<T> {
    /// Local row in the current target block of each pattern row.
    local: Vec<usize>,
    scaled: Vec<T>,
    product: Vec<T>,
    dense: MemBuffer,
}

impl<T: Scalar> Scratch<T> {
    fn new(n: usize, widest: usize) -> Self {
        let req = cholesky_in_place_scratch::<T>(widest, Par::rayon(2), Default::default());
        Self {
            local: vec![0; n],
            scaled: Vec::new(),
            product: Vec::new(),
            dense: MemBuffer::new(req),
        }
    }

    /// Point `local` at block `b`'s pattern rows.
    fn target(&mut self, b: &Block) {
        for (k, &r) in b.pattern.iter().enumerate() {
            self.local[r] = b.ncols + k;
        }
    }

    /// Subtract from block `c` of supernode `s` (geometry `b`) the updates of its
    /// descendants in task `from` (0, 1 or [`TOP`]), whose finished blocks are in `blocks`.
    fn gather(
        &mut self,
        (sym, plan): (&SymbolicSupernodalCholesky<usize>, &FactorPlan),
        (s, b): (usize, &Block),
        from: u8,
        blocks: &[Option<&mut [T]>],
        c: &mut [T],
    ) {
        self.target(b);
        for d in plan.updaters_of(s).filter(|&d| plan.owner[d] == from) {
            let ld = blocks[d].as_deref().expect("a finished descendant");
            self.update(&block(sym, d), ld, b, c);
        }
    }

    /// Subtract descendant `d`'s update L_{≥s,d} D_d L_{s,d}ᵀ (lower part) from the block
    /// `c` of supernode `sb` (the target the row map points at).
    fn update(&mut self, d: &Block, ld: &[T], sb: &Block, c: &mut [T]) {
        let ld = MatRef::from_column_major_slice(ld, d.nrows(), d.ncols);
        let end = sb.start + sb.ncols;
        let p0 = d.pattern.partition_point(|&r| r < sb.start);
        let rows = &d.pattern[p0..];
        let mid = rows.partition_point(|&r| r < end);
        let m = rows.len();
        if mid == 0 {
            return;
        }
        let below = ld.subrows(d.ncols + p0, m);
        self.scaled.clear();
        for k in 0..d.ncols {
            let dk = ld[(k, k)];
            self.scaled.extend((0..mid).map(|i| below[(i, k)] * dk));
        }
        let scaled = MatRef::from_column_major_slice(&self.scaled, mid, d.ncols);
        self.product.clear();
        self.product.resize(m * mid, T::ZERO);
        let w = MatMut::from_column_major_slice_mut(&mut self.product, m, mid);
        matmul(
            w,
            Accum::Replace,
            below,
            scaled.transpose(),
            T::ONE,
            Par::Seq,
        );
        let nr = sb.nrows();
        for jj in 0..mid {
            let col = rows[jj] - sb.start;
            let out = &mut c[col * nr..(col + 1) * nr];
            let w = &self.product[jj * m..(jj + 1) * m];
            for ii in jj..m {
                let row = if ii < mid {
                    rows[ii] - sb.start
                } else {
                    self.local[rows[ii]]
                };
                out[row] -= w[ii];
            }
        }
    }

    /// Factorise block `c` of `b` once its updates are in: dense LDLᵀ of the diagonal
    /// block, then L_below = A_below L⁻ᵀ D⁻¹. False on a zero pivot.
    fn finish(&mut self, b: &Block, c: &mut [T]) -> bool {
        let par = if b.ncols >= PARALLEL_FRONT {
            Par::rayon(2)
        } else {
            Par::Seq
        };
        let mut ls = MatMut::from_column_major_slice_mut(c, b.nrows(), b.ncols);
        let (mut top, mut bot) = ls.as_mut().split_at_row_mut(b.ncols);
        let stack = MemStack::new(&mut self.dense);
        let ok = cholesky_in_place(
            top.as_mut(),
            LdltRegularization::default(),
            par,
            stack,
            Default::default(),
        )
        .is_ok();
        if !ok {
            return false;
        }
        for j in 1..b.ncols {
            for i in 0..j {
                top[(i, j)] = T::ZERO;
            }
        }
        solve_unit_lower_triangular_in_place(top.as_ref(), bot.as_mut().transpose_mut(), par);
        for j in 0..b.ncols {
            let dj = top[(j, j)];
            for i in 0..b.pattern.len() {
                bot[(i, j)] /= dj;
            }
        }
        true
    }
}

/// Zero block `c` of supernode `s` and add the matrix's entries (`a`, with `shift` on the
/// free diagonal); `offset` is the block's first index in the factor's values.
fn load<T: Scalar>(
    plan: &FactorPlan,
    s: usize,
    offset: usize,
    a: &[f64],
    shift: f64,
    c: &mut [T],
    b: &Block,
) {
    c.fill(T::ZERO);
    for &(at, q) in &plan.entries[plan.entry_ptr[s]..plan.entry_ptr[s + 1]] {
        c[at as usize - offset] += T::from_f64(a[q as usize]);
    }
    let nr = b.nrows();
    for j in 0..b.ncols {
        if plan.shifted[b.start + j] {
            c[j * nr + j] += T::from_f64(shift);
        }
    }
}

/// The factor's values cut into one block per supernode.
fn blocks<'v, T>(
    sym: &SymbolicSupernodalCholesky<usize>,
    mut values: &'v mut [T],
) -> Vec<Option<&'v mut [T]>> {
    let cpv = sym.col_ptr_for_val();
    let mut out = Vec::with_capacity(sym.n_supernodes());
    for s in 0..sym.n_supernodes() {
        let (head, tail) = std::mem::take(&mut values).split_at_mut(cpv[s + 1] - cpv[s]);
        out.push(Some(head));
        values = tail;
    }
    out
}

/// One task's subtrees: each supernode loaded, updated by its descendants and finished;
/// then the updates its supernodes owe the top, into zeroed copies of the top's blocks.
/// Returns the copies (in `split.top()` order), or `None` on a zero pivot.
fn run_task<T: Scalar>(
    t: usize,
    (sym, plan): (&SymbolicSupernodalCholesky<usize>, &FactorPlan),
    (a, shift): (&[f64], f64),
    own: &mut [Option<&mut [T]>],
) -> Option<Vec<Vec<T>>> {
    let (cpv, split) = (sym.col_ptr_for_val(), &plan.split);
    let mut scratch = Scratch::<T>::new(sym.nrows(), plan.widest);
    for &s in &split.tasks()[t] {
        let b = block(sym, s);
        let c = own[s].take().expect("a task's block");
        load(plan, s, cpv[s], a, shift, c, &b);
        // A task's supernode has all its descendants in the task.
        scratch.gather((sym, plan), (s, &b), t as u8, own, c);
        let ok = scratch.finish(&b, c);
        own[s] = Some(c);
        if !ok {
            return None;
        }
    }
    let mut copies = Vec::with_capacity(split.top().len());
    for &s in split.top() {
        let b = block(sym, s);
        let mut c = vec![T::ZERO; cpv[s + 1] - cpv[s]];
        scratch.gather((sym, plan), (s, &b), t as u8, own, &mut c);
        copies.push(c);
    }
    Some(copies)
}

/// Numeric LDLᵀ of the assembled matrix `a` (values of the pattern the plan was built for)
/// plus `shift` on the free diagonal, into `values` in faer's supernodal layout, the plan's
/// two tasks on two cores. False on a zero pivot.
pub fn factor<T: Scalar>(
    sym: &SymbolicSupernodalCholesky<usize>,
    plan: &FactorPlan,
    (a, shift): (&[f64], f64),
    values: &mut [T],
) -> bool {
    let (cpv, split) = (sym.col_ptr_for_val(), &plan.split);
    let ns = sym.n_supernodes();
    let mut all = blocks(sym, values);
    let mut own: [Vec<Option<&mut [T]>>; 2] = [
        (0..ns).map(|_| None).collect(),
        (0..ns).map(|_| None).collect(),
    ];
    for s in 0..ns {
        if plan.owner[s] != TOP {
            own[plan.owner[s] as usize][s] = all[s].take();
        }
    }
    let ctx = (sym, plan);
    let [own0, own1] = &mut own;
    let (c0, c1) = rayon::join(
        || run_task(0, ctx, (a, shift), own0),
        || run_task(1, ctx, (a, shift), own1),
    );
    let (Some(c0), Some(c1)) = (c0, c1) else {
        return false;
    };
    for s in 0..ns {
        if plan.owner[s] != TOP {
            all[s] = own[plan.owner[s] as usize][s].take();
        }
    }
    let mut scratch = Scratch::<T>::new(sym.nrows(), plan.widest);
    for (k, &s) in split.top().iter().enumerate() {
        let b = block(sym, s);
        let c = all[s].take().expect("a top block");
        load(plan, s, cpv[s], a, shift, c, &b);
        for ((x, &u0), &u1) in c.iter_mut().zip(&c0[k]).zip(&c1[k]) {
            *x = *x + u0 + u1;
        }
        scratch.gather((sym, plan), (s, &b), TOP, &all, c);
        let ok = scratch.finish(&b, c);
        all[s] = Some(c);
        if !ok {
            return false;
        }
    }
    true
}
