//! The numeric LDLᵀ factorisation of the assembled KKT matrix in double or single
//! precision (across the elimination tree on two cores when the analysis has a plan, else
//! faer's sequential factorisation), its inertia, and the solves with the factor.

use super::KktSolver;
use crate::solver::tree::{Scalar, TreeSplit};
use crate::solver::tree_factor;
use faer::dyn_stack::{MemBuffer, MemStack};
use faer::linalg::cholesky::ldlt::factor::LdltRegularization;
use faer::sparse::linalg::cholesky::supernodal::SymbolicSupernodalCholesky;
use faer::sparse::linalg::cholesky::{LdltRef, SymbolicCholesky, SymbolicCholeskyRaw};
use faer::sparse::SparseColMat;
use faer::{Conj, MatMut, Side};

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

/// LDLᵀ without dynamic regularisation (faer's default: no signs, δ = ε = 0), in either
/// precision: a zero pivot is reported, not perturbed.
fn no_regularization<T: faer::traits::RealField>() -> LdltRegularization<'static, T> {
    LdltRegularization::default()
}

impl KktSolver {
    /// Numeric LDLᵀ of the assembled matrix with `shift` added to the free-dof diagonal.
    /// Call repeatedly with growing shifts for inertia correction (no re-assembly). A
    /// single-precision factor whose inertia is not the expected one is made again in double
    /// precision, and that one is kept: single-precision rounding of the large entries a
    /// constraint row eliminated early brings (γ²/δ) can miscount the skin's soft modes and
    /// make a positive definite Hessian look indefinite.
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

    /// Parallelism for faer's own sparse factorisation and solves: sequential. faer
    /// parallelises inside the dense fronts, and a shell's fronts are small and many, so
    /// there the synchronisation costs more than it saves; the two cores go across the
    /// elimination tree instead ([`crate::solver::tree`] and [`crate::solver::tree_factor`]),
    /// and faer's sequential path serves analyses that do not split.
    pub(super) fn par(&self) -> faer::Par {
        faer::Par::Seq
    }

    /// Apply the current factor's inverse to `rhs` in place (one forward and backward
    /// solve with the regularised, shifted matrix: a preconditioner, not a solution).
    pub(crate) fn apply_factor(&mut self, rhs: &mut [f64]) {
        self.raw_solve(rhs);
    }

    /// Apply the current factor's inverse to `rhs` in place, in the factor's precision:
    /// across the elimination tree when the analysis splits, else by faer's solve.
    pub(super) fn raw_solve(&mut self, rhs: &mut [f64]) {
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

#[cfg(test)]
mod tests {
    use super::super::test_systems::{factorize_free, lattice_kkt, one_row_blocks};
    use super::*;

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
