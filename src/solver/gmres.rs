//! Right-preconditioned flexible GMRES for the KKT systems of the Newton solver.
//!
//! Why this method: the KKT matrix is symmetric *indefinite* and its preconditioner (an
//! LDLᵀ factor of a nearby KKT matrix: the δ-regularised one, or one of an earlier Newton
//! iterate) is indefinite too, so conjugate gradients and MINRES (which needs a definite
//! preconditioner) do not apply. GMRES minimises the true residual over the Krylov space,
//! and that space contains the iterates of stationary iterative refinement with the same
//! factor, so it never needs more factor solves than refinement does and converges where
//! refinement diverges (a lagged factor whose soft bending modes have moved). With a
//! constraint preconditioner the preconditioned spectrum is 1 (twice the constraint count)
//! and the generalised eigenvalues of the two Hessians on the constraint null space (Keller,
//! Gould and Wathen 2000), which cluster near 1 when the Hessian changed little. The flexible
//! form keeps the preconditioned vectors, so forming the solution costs no extra factor
//! solve: iteration j costs one factor solve and one product with the matrix. faer (0.24)
//! ships conjugate gradients, BiCGSTAB (two factor solves per iteration) and LSMR, not
//! GMRES, hence this small implementation.

use crate::math::vector::{dot, norm};

/// How a GMRES solve ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GmresReport {
    /// Iterations done, each one preconditioner application and one matrix product.
    pub iterations: usize,
    /// Final relative residual ‖b − A x‖ / ‖b‖ (the true one, recomputed at the end).
    pub relative_residual: f64,
    /// True when the relative residual reached the requested tolerance.
    pub converged: bool,
}

/// Solve A x = b from x = 0 by flexible GMRES without restarts: `apply_a(v, out)` writes
/// A v into `out`, `precondition(v)` replaces v by M⁻¹ v. Stops once the residual estimate
/// is below `rel_tol` ‖b‖, after `max_iterations`, or at a lucky breakdown. With
/// `give_up`, it also stops (not converged) from the third iteration on when the mean
/// reduction per iteration so far, kept up to `max_iterations`, would leave the residual
/// above 100 × `rel_tol` (a preconditioner too far from A: the caller then makes a better
/// one instead of spending the remaining solves). `x` receives the solution.
pub fn fgmres(
    mut apply_a: impl FnMut(&[f64], &mut [f64]),
    mut precondition: impl FnMut(&mut [f64]),
    b: &[f64],
    x: &mut [f64],
    rel_tol: f64,
    max_iterations: usize,
    give_up: bool,
) -> GmresReport {
    let n = b.len();
    assert_eq!(x.len(), n, "fgmres: x and b differ in length");
    x.fill(0.0);
    let b_norm = norm(b);
    if b_norm == 0.0 || !b_norm.is_finite() || max_iterations == 0 {
        return GmresReport {
            iterations: 0,
            relative_residual: if b_norm == 0.0 { 0.0 } else { f64::NAN },
            converged: b_norm == 0.0,
        };
    }
    let m = max_iterations;
    // Arnoldi basis V (m + 1 vectors), preconditioned vectors Z, Hessenberg H (column-major,
    // (m + 1) × m) reduced to triangular by Givens rotations (c, s); g = ‖b‖ e₁ rotated.
    let mut v: Vec<Vec<f64>> = vec![b.iter().map(|bi| bi / b_norm).collect()];
    let mut z: Vec<Vec<f64>> = Vec::with_capacity(m);
    let mut h = vec![0.0; (m + 1) * m];
    let (mut cs, mut sn) = (vec![0.0; m], vec![0.0; m]);
    let mut g = vec![0.0; m + 1];
    g[0] = b_norm;
    let mut w = vec![0.0; n];
    let mut k = 0;
    while k < m {
        let mut zk = v[k].clone();
        precondition(&mut zk);
        apply_a(&zk, &mut w);
        z.push(zk);
        // Modified Gram–Schmidt, with one re-orthogonalisation pass (the basis is short).
        let col = &mut h[k * (m + 1)..(k + 1) * (m + 1)];
        for _ in 0..2 {
            for (i, vi) in v.iter().enumerate() {
                let d = dot(&w, vi);
                col[i] += d;
                axpy(-d, vi, &mut w);
            }
        }
        let wn = norm(&w);
        col[k + 1] = wn;
        // Apply the earlier rotations, then make one that zeroes the subdiagonal.
        for i in 0..k {
            let (a, bb) = (col[i], col[i + 1]);
            col[i] = cs[i] * a + sn[i] * bb;
            col[i + 1] = -sn[i] * a + cs[i] * bb;
        }
        let r = col[k].hypot(col[k + 1]);
        if r == 0.0 || !r.is_finite() {
            break;
        }
        cs[k] = col[k] / r;
        sn[k] = col[k + 1] / r;
        col[k] = r;
        col[k + 1] = 0.0;
        g[k + 1] = -sn[k] * g[k];
        g[k] *= cs[k];
        let rel = g[k + 1].abs() / b_norm;
        k += 1;
        let hopeless =
            give_up && k >= 3 && rel * rel.powf((m - k) as f64 / k as f64) > 100.0 * rel_tol;
        if rel <= rel_tol || wn <= 1e-14 * b_norm || hopeless {
            break;
        }
        v.push(w.iter().map(|wi| wi / wn).collect());
    }
    // Back substitution H y = g on the k × k triangle, x = Z y.
    let mut y = vec![0.0; k];
    for i in (0..k).rev() {
        let mut s = g[i];
        for j in i + 1..k {
            s -= h[j * (m + 1) + i] * y[j];
        }
        y[i] = s / h[i * (m + 1) + i];
    }
    for (zj, &yj) in z.iter().zip(&y) {
        axpy(yj, zj, x);
    }
    apply_a(x, &mut w);
    let res = b
        .iter()
        .zip(&w)
        .map(|(bi, wi)| (bi - wi).powi(2))
        .sum::<f64>()
        .sqrt()
        / b_norm;
    GmresReport {
        iterations: k,
        relative_residual: res,
        converged: res <= rel_tol,
    }
}

fn axpy(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi += alpha * xi;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Lcg;
    use nalgebra::{DMatrix, DVector};

    /// A random symmetric indefinite saddle-point matrix [K Cᵀ; C 0] with a known solution.
    fn saddle(n: usize, m: usize, seed: u64) -> DMatrix<f64> {
        let mut rng = Lcg::new(seed);
        let mut k = DMatrix::from_fn(n, n, |_, _| rng.next_signed());
        k = &k * k.transpose() + DMatrix::identity(n, n) * 0.5;
        let c = DMatrix::from_fn(m, n, |_, _| rng.next_signed());
        let mut a = DMatrix::zeros(n + m, n + m);
        a.view_mut((0, 0), (n, n)).copy_from(&k);
        a.view_mut((n, 0), (m, n)).copy_from(&c);
        a.view_mut((0, n), (n, m)).copy_from(&c.transpose());
        a
    }

    /// Unpreconditioned GMRES on an n × n system converges within n iterations (exact
    /// arithmetic: the Krylov space is then the whole space) to the known solution.
    #[test]
    fn solves_an_indefinite_saddle_point_system_within_its_dimension() {
        let a = saddle(12, 3, 7);
        let x_true = DVector::from_fn(15, |i, _| (i as f64 * 0.37).sin());
        let b = &a * &x_true;
        let mut x = vec![0.0; 15];
        let rep = fgmres(
            |v, out| out.copy_from_slice((&a * DVector::from_column_slice(v)).as_slice()),
            |_| {},
            b.as_slice(),
            &mut x,
            1e-12,
            15,
            false,
        );
        assert!(rep.converged, "{rep:?}");
        assert!(rep.iterations <= 15);
        for i in 0..15 {
            assert!(
                (x[i] - x_true[i]).abs() < 1e-8,
                "x[{i}] = {} vs {}",
                x[i],
                x_true[i]
            );
        }
    }

    /// With the exact inverse as preconditioner one iteration solves the system; with the
    /// inverse of a matrix that differs by a rank-r change, GMRES needs at most r + 1
    /// iterations (the preconditioned matrix is the identity plus rank r).
    #[test]
    fn a_preconditioner_off_by_rank_r_needs_at_most_r_plus_one_iterations() {
        let a = saddle(20, 4, 11);
        let b = DVector::from_fn(24, |i, _| 1.0 + (i as f64).cos());
        let mut rng = Lcg::new(3);
        for r in [0usize, 1, 3] {
            let mut m = a.clone();
            for _ in 0..r {
                let u = DVector::from_fn(24, |_, _| rng.next_signed());
                m += &u * u.transpose();
            }
            let minv = m.clone().try_inverse().expect("invertible");
            let mut x = vec![0.0; 24];
            let rep = fgmres(
                |v, out| out.copy_from_slice((&a * DVector::from_column_slice(v)).as_slice()),
                |v| {
                    let y = &minv * DVector::from_column_slice(v);
                    v.copy_from_slice(y.as_slice());
                },
                b.as_slice(),
                &mut x,
                1e-10,
                24,
                false,
            );
            assert!(rep.converged, "rank {r}: {rep:?}");
            assert!(
                rep.iterations <= r + 1,
                "rank {r}: {} iterations",
                rep.iterations
            );
            let res = (&a * DVector::from_column_slice(&x) - &b).norm() / b.norm();
            assert!(res < 1e-9, "rank {r}: residual {res}");
        }
    }

    /// A zero right-hand side gives x = 0 without iterating; an iteration cap is respected
    /// and reported as not converged.
    #[test]
    fn zero_rhs_and_iteration_cap() {
        let a = saddle(10, 2, 5);
        let mut x = vec![1.0; 12];
        let rep = fgmres(
            |v, out| out.copy_from_slice((&a * DVector::from_column_slice(v)).as_slice()),
            |_| {},
            &[0.0; 12],
            &mut x,
            1e-12,
            5,
            false,
        );
        assert_eq!((rep.iterations, rep.converged), (0, true));
        assert!(x.iter().all(|&v| v == 0.0));
        let b = vec![1.0; 12];
        let rep = fgmres(
            |v, out| out.copy_from_slice((&a * DVector::from_column_slice(v)).as_slice()),
            |_| {},
            &b,
            &mut x,
            1e-14,
            2,
            false,
        );
        assert_eq!(rep.iterations, 2);
        assert!(!rep.converged);
    }
}
