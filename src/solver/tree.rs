//! Solves with a supernodal LDLᵀ factor on two cores, across its elimination tree.
//!
//! A supernode's forward substitution writes only to its own rows and to rows of its
//! ancestors, and its backward substitution reads only those: disjoint subtrees of the
//! elimination tree are independent. [`TreeSplit`] takes subtrees below the top of the tree
//! (nested dissection's separators), deals them to two tasks with about equal factor
//! entries, and leaves the rest (the top) to run alone. faer's own parallelism works
//! inside each dense front instead, and on a skin's many small fronts its synchronisation
//! cost more than it saved (see [`super::kkt`]).
//!
//! Each task works on its own copy of the vector, and the top rows add the two tasks'
//! updates in a fixed order: the result is the same bits on one thread or two (it differs
//! from the sequential solve's by rounding).

use faer::linalg::matmul::matmul_with_conj;
use faer::linalg::triangular_solve::{
    solve_unit_lower_triangular_in_place_with_conj, solve_unit_upper_triangular_in_place_with_conj,
};
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::{Accum, Conj, MatMut, MatRef, Par};
use std::ops::Range;

/// Subtrees [`TreeSplit::new`] splits, one per step, looking for its best split.
const SPLIT_STEPS: usize = 64;

/// The heaviest subtrees [`TreeSplit::new`] tries splitting at each step.
const SPLIT_CANDIDATES: usize = 8;

/// A split of a supernodal factor's elimination tree for two tasks.
#[derive(Debug, Clone)]
pub struct TreeSplit {
    /// The supernodes of the subtrees each task runs, in increasing order.
    tasks: [Vec<usize>; 2],
    /// Their columns.
    task_cols: [Vec<Range<usize>>; 2],
    /// Supernodes in no subtree, in increasing order (each after its descendants).
    top: Vec<usize>,
    /// Columns of the top supernodes.
    top_cols: Vec<usize>,
}

/// The cost of a supernode in a solve: its factor entries.
pub fn solve_cost(sym: &SymbolicSupernodalCholesky<usize>, s: usize) -> f64 {
    let cp = sym.col_ptr_for_val();
    (cp[s + 1] - cp[s]) as f64
}

/// The cost of a supernode in a factorisation: the flops of its dense front and of the
/// updates it sends its ancestors.
pub fn factor_cost(sym: &SymbolicSupernodalCholesky<usize>, s: usize) -> f64 {
    let cols = (sym.supernode_end()[s] - sym.supernode_begin()[s]) as f64;
    let below = sym.supernode(s).pattern().len() as f64;
    cols * cols * cols / 3.0 + cols * cols * below + cols * below * below
}

/// The parent of each supernode in the elimination tree (`usize::MAX` at a root), or
/// `None` when a parent comes before its child (the solves' order would break).
fn supernode_parents(sym: &SymbolicSupernodalCholesky<usize>) -> Option<Vec<usize>> {
    let ns = sym.n_supernodes();
    let owner = column_owners(sym);
    let mut parent = vec![usize::MAX; ns];
    for s in 0..ns {
        if let Some(&row) = sym.supernode(s).pattern().first() {
            if owner[row] <= s {
                return None;
            }
            parent[s] = owner[row];
        }
    }
    Some(parent)
}

/// The supernode of each column of the factor.
pub fn column_owners(sym: &SymbolicSupernodalCholesky<usize>) -> Vec<usize> {
    let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
    let mut owner = vec![0usize; sym.nrows()];
    for s in 0..sym.n_supernodes() {
        owner[begin[s]..end[s]].fill(s);
    }
    owner
}

/// The supernodes of the subtrees rooted at `roots`, in increasing order (each after its
/// descendants).
fn members(roots: &[usize], children: &[Vec<usize>]) -> Vec<usize> {
    let mut out = Vec::new();
    let mut stack = roots.to_vec();
    while let Some(s) = stack.pop() {
        out.push(s);
        stack.extend(&children[s]);
    }
    out.sort_unstable();
    out
}

/// The columns of supernodes `list` (increasing) as ranges, adjacent ones merged.
fn column_ranges(sym: &SymbolicSupernodalCholesky<usize>, list: &[usize]) -> Vec<Range<usize>> {
    let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
    let mut out: Vec<Range<usize>> = Vec::new();
    for &s in list {
        match out.last_mut() {
            Some(r) if r.end == begin[s] => r.end = end[s],
            _ => out.push(begin[s]..end[s]),
        }
    }
    out
}

/// Deal `subtrees` (root, cost) to two tasks, largest first to the lighter one: the tasks'
/// costs.
fn deal(subtrees: &[(usize, f64)]) -> ([Vec<usize>; 2], [f64; 2]) {
    let mut order: Vec<usize> = (0..subtrees.len()).collect();
    order.sort_by(|&a, &b| subtrees[b].1.total_cmp(&subtrees[a].1).then(a.cmp(&b)));
    let mut tasks = [Vec::new(), Vec::new()];
    let mut cost = [0.0; 2];
    for k in order {
        let t = usize::from(cost[1] < cost[0]);
        tasks[t].push(subtrees[k].0);
        cost[t] += subtrees[k].1;
    }
    (tasks, cost)
}

impl TreeSplit {
    /// The split of `sym` whose estimated time (the top's `cost` plus the heavier task's,
    /// [`solve_cost`] or [`factor_cost`] per supernode) is least among those met by
    /// splitting, [`SPLIT_STEPS`] times, the subtree among the heaviest whose split leaves
    /// the least estimate into its children; `None`
    /// when it would save under a fifth of a sequential solve, or a supernode's parent
    /// comes before it.
    pub fn new(
        sym: &SymbolicSupernodalCholesky<usize>,
        cost_of: fn(&SymbolicSupernodalCholesky<usize>, usize) -> f64,
    ) -> Option<Self> {
        let ns = sym.n_supernodes();
        let parent = supernode_parents(sym)?;
        let mut children = vec![Vec::new(); ns];
        let own: Vec<f64> = (0..ns).map(|s| cost_of(sym, s)).collect();
        let mut cost = own.clone();
        for s in 0..ns {
            if parent[s] != usize::MAX {
                children[parent[s]].push(s);
                cost[parent[s]] += cost[s];
            }
        }
        let total: f64 = own.iter().sum();
        let mut subtrees: Vec<(usize, f64)> = (0..ns)
            .filter(|&s| parent[s] == usize::MAX)
            .map(|s| (s, cost[s]))
            .collect();
        let mut top = Vec::new();
        let mut top_cost = 0.0;
        let estimate = |subtrees: &[(usize, f64)], top_cost: f64| {
            let (_, c) = deal(subtrees);
            top_cost + c[0].max(c[1])
        };
        let mut best = (estimate(&subtrees, top_cost), subtrees.clone(), top.len());
        for _ in 0..SPLIT_STEPS {
            let mut splittable: Vec<usize> = (0..subtrees.len())
                .filter(|&k| !children[subtrees[k].0].is_empty())
                .collect();
            splittable.sort_by(|&a, &b| subtrees[b].1.total_cmp(&subtrees[a].1));
            let split_at = |k: usize| {
                let mut next = subtrees.clone();
                let root = next.swap_remove(k).0;
                next.extend(children[root].iter().map(|&c| (c, cost[c])));
                (next, root)
            };
            let Some((e, k)) = splittable
                .iter()
                .take(SPLIT_CANDIDATES)
                .map(|&k| (estimate(&split_at(k).0, top_cost + own[subtrees[k].0]), k))
                .min_by(|a, b| a.0.total_cmp(&b.0))
            else {
                break;
            };
            let (next, root) = split_at(k);
            subtrees = next;
            top.push(root);
            top_cost += own[root];
            if e < best.0 || best.1.len() < 2 {
                best = (e, subtrees.clone(), top.len());
            }
        }
        let (time, subtrees, tops) = best;
        top.truncate(tops);
        if time > 0.8 * total {
            return None;
        }
        let (dealt, _) = deal(&subtrees);
        let tasks = [members(&dealt[0], &children), members(&dealt[1], &children)];
        let task_cols = [column_ranges(sym, &tasks[0]), column_ranges(sym, &tasks[1])];
        top.sort_unstable();
        let (begin, end) = (sym.supernode_begin(), sym.supernode_end());
        let top_cols = top.iter().flat_map(|&s| begin[s]..end[s]).collect();
        Some(Self {
            tasks,
            task_cols,
            top,
            top_cols,
        })
    }

    /// The supernodes each task runs, in increasing order.
    pub fn tasks(&self) -> &[Vec<usize>; 2] {
        &self.tasks
    }

    /// The supernodes in no task's subtrees, in increasing order.
    pub fn top(&self) -> &[usize] {
        &self.top
    }

    /// Copy each task's own columns from its copy of the vector into `x`.
    fn take_task_columns<T: Copy>(&self, x: &mut [T], copies: [&[T]; 2]) {
        for (cols, y) in self.task_cols.iter().zip(copies) {
            for r in cols {
                x[r.clone()].copy_from_slice(&y[r.clone()]);
            }
        }
    }

    /// Solve L D Lᵀ x = b in place (`x` holds b, in the factor's permuted order) with the
    /// supernodal LDLᵀ `values` of `sym`, the two tasks on two cores when rayon has them.
    pub fn solve<T: Scalar>(
        &self,
        sym: &SymbolicSupernodalCholesky<usize>,
        values: &[T],
        x: &mut [T],
    ) {
        let f = Factor { sym, values };
        let (mut a, mut b) = (x.to_vec(), x.to_vec());
        rayon::join(
            || f.forward(&self.tasks[0], &mut a),
            || f.forward(&self.tasks[1], &mut b),
        );
        self.take_task_columns(x, [&a, &b]);
        for &c in &self.top_cols {
            x[c] = x[c] + (a[c] - x[c]) + (b[c] - x[c]);
        }
        f.forward(&self.top, x);
        f.scale(x);
        f.backward(&self.top, x);
        a.copy_from_slice(x);
        b.copy_from_slice(x);
        rayon::join(
            || f.backward(&self.tasks[0], &mut a),
            || f.backward(&self.tasks[1], &mut b),
        );
        self.take_task_columns(x, [&a, &b]);
    }
}

/// A real scalar of a factor: f32 or f64.
pub trait Scalar:
    faer::traits::RealField
    + Copy
    + Send
    + Sync
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Div<Output = Self>
    + std::ops::Neg<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::AddAssign
    + std::ops::SubAssign
    + std::ops::DivAssign
{
    /// Zero.
    const ZERO: Self;
    /// One.
    const ONE: Self;
    /// `v` rounded to this precision.
    fn from_f64(v: f64) -> Self;
}

impl Scalar for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_f64(v: f64) -> Self {
        v as f32
    }
}

impl Scalar for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_f64(v: f64) -> Self {
        v
    }
}

/// A supernodal LDLᵀ factor (unit L, D on its diagonal).
struct Factor<'a, T> {
    sym: &'a SymbolicSupernodalCholesky<usize>,
    values: &'a [T],
}

impl<T: Scalar> Factor<'_, T> {
    /// Supernode `s`'s block of L: its columns over its own rows, then its pattern's rows.
    fn block(&self, s: usize) -> (MatRef<'_, T>, &[usize], usize) {
        let cp = self.sym.col_ptr_for_val();
        let sn = self.sym.supernode(s);
        let (start, ncols) = (sn.start(), self.sym.supernode_end()[s] - sn.start());
        let pattern = sn.pattern();
        let l = MatRef::from_column_major_slice(
            &self.values[cp[s]..cp[s + 1]],
            ncols + pattern.len(),
            ncols,
        );
        (l, pattern, start)
    }

    /// Forward substitution L y = b over the supernodes `list`, in order.
    fn forward(&self, list: &[usize], x: &mut [T]) {
        let mut tmp: Vec<T> = Vec::new();
        for &s in list {
            let (l, pattern, start) = self.block(s);
            let n = l.ncols();
            let (top, bottom) = l.split_at_row(n);
            let mut xs = MatMut::from_column_major_slice_mut(&mut x[start..start + n], n, 1);
            solve_unit_lower_triangular_in_place_with_conj(top, Conj::No, xs.as_mut(), Par::Seq);
            tmp.clear();
            tmp.resize(pattern.len(), T::ZERO);
            let t = MatMut::from_column_major_slice_mut(&mut tmp, pattern.len(), 1);
            matmul_with_conj(
                t,
                Accum::Replace,
                bottom,
                Conj::No,
                xs.as_ref(),
                Conj::No,
                T::ONE,
                Par::Seq,
            );
            for (&i, &v) in pattern.iter().zip(&tmp) {
                x[i] -= v;
            }
        }
    }

    /// y ← D⁻¹ y over every supernode.
    fn scale(&self, x: &mut [T]) {
        for s in 0..self.sym.n_supernodes() {
            let (l, _, start) = self.block(s);
            for j in 0..l.ncols() {
                x[start + j] /= l[(j, j)];
            }
        }
    }

    /// Backward substitution Lᵀ x = y over the supernodes `list`, in reverse order.
    fn backward(&self, list: &[usize], x: &mut [T]) {
        let mut tmp: Vec<T> = Vec::new();
        for &s in list.iter().rev() {
            let (l, pattern, start) = self.block(s);
            let n = l.ncols();
            let (top, bottom) = l.split_at_row(n);
            tmp.clear();
            tmp.extend(pattern.iter().map(|&i| x[i]));
            let t = MatRef::from_column_major_slice(&tmp, pattern.len(), 1);
            let mut xs = MatMut::from_column_major_slice_mut(&mut x[start..start + n], n, 1);
            matmul_with_conj(
                xs.as_mut(),
                Accum::Add,
                bottom.transpose(),
                Conj::No,
                t,
                Conj::No,
                -T::ONE,
                Par::Seq,
            );
            solve_unit_upper_triangular_in_place_with_conj(
                top.transpose(),
                Conj::No,
                xs.as_mut(),
                Par::Seq,
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use faer::sparse::linalg::cholesky::{
        factorize_symbolic_cholesky, CholeskySymbolicParams, SymbolicCholesky, SymbolicCholeskyRaw,
        SymmetricOrdering,
    };
    use faer::sparse::linalg::SupernodalThreshold;
    use faer::sparse::{SparseColMat, Triplet};
    use faer::Side;

    /// The supernodal analysis (forced) of the graph on `n` nodes with edges `edges`, AMD
    /// ordered.
    fn analysis(n: usize, edges: &[(usize, usize)]) -> SymbolicCholesky<usize> {
        let mut t: Vec<Triplet<usize, usize, f64>> =
            (0..n).map(|i| Triplet::new(i, i, 4.0)).collect();
        for &(a, b) in edges {
            t.extend([Triplet::new(a, b, -1.0), Triplet::new(b, a, -1.0)]);
        }
        let a = SparseColMat::try_new_from_triplets(n, n, &t).unwrap();
        let params = CholeskySymbolicParams {
            supernodal_flop_ratio_threshold: SupernodalThreshold::FORCE_SUPERNODAL,
            ..Default::default()
        };
        factorize_symbolic_cholesky(a.symbolic(), Side::Lower, SymmetricOrdering::Amd, params)
            .unwrap()
    }

    /// The supernodal structure of `sym`.
    fn supernodal(sym: &SymbolicCholesky<usize>) -> &SymbolicSupernodalCholesky<usize> {
        match sym.raw() {
            SymbolicCholeskyRaw::Supernodal(s) => s,
            SymbolicCholeskyRaw::Simplicial(_) => panic!("supernodal was forced"),
        }
    }

    /// A grid's tree splits into two tasks that share no supernode, hold every supernode's
    /// descendants with it, and leave the rest to the top; a chain (one path, nothing to run
    /// at once) does not split.
    #[test]
    fn a_grid_splits_into_closed_disjoint_tasks_and_a_chain_does_not() {
        let k = 40;
        let mut edges = Vec::new();
        for i in 0..k {
            for j in 0..k {
                if i + 1 < k {
                    edges.push((i * k + j, (i + 1) * k + j));
                }
                if j + 1 < k {
                    edges.push((i * k + j, i * k + j + 1));
                }
            }
        }
        let analysed = analysis(k * k, &edges);
        let sym = supernodal(&analysed);
        let split = TreeSplit::new(sym, factor_cost).expect("a grid splits");
        let parent = supernode_parents(sym).unwrap();
        let mut task = vec![usize::MAX; sym.n_supernodes()];
        for (t, list) in split.tasks().iter().enumerate() {
            assert!(!list.is_empty(), "task {t} has work");
            for &s in list {
                assert_eq!(task[s], usize::MAX, "supernode {s} in two tasks");
                task[s] = t;
            }
        }
        for &s in split.top() {
            assert_eq!(task[s], usize::MAX, "top supernode {s} in a task");
            task[s] = 2;
        }
        for s in 0..sym.n_supernodes() {
            assert_ne!(task[s], usize::MAX, "supernode {s} nowhere");
            let p = parent[s];
            if p != usize::MAX && task[p] < 2 {
                assert_eq!(task[p], task[s], "supernode {s}'s parent in another task");
            }
        }
        let chain: Vec<(usize, usize)> = (0..199).map(|i| (i, i + 1)).collect();
        let analysed = analysis(200, &chain);
        assert!(TreeSplit::new(supernodal(&analysed), factor_cost).is_none());
    }
}
