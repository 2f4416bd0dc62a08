//! Small KKT systems the unit tests of the KKT solver factorise and solve: a helper that
//! assembles and factorises triplets over all-free dofs, one-row constraint blocks, and a
//! 3D lattice whose factor is supernodal.

use super::{HessianValues, KktBlocks, KktFactorInfo, KktSolver};

/// Assemble and factorise K (triplets over free dofs 0..n, n the largest index + 1) with
/// `n_cons` constraint rows `c`, row scale γ, regularisation δ and `shift`.
pub(super) fn factorize_free(
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

/// The KKT blocks of Hessian triplets `t` over the dofs `free_of` (all free) with the
/// one constraint row `c`, γ = 1 and δ = 1e-8.
pub(super) fn one_row_blocks<'a>(
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
