//! Projection of small symmetric element matrices to positive semi-definite.

use nalgebra::{DMatrix, SymmetricEigen};
use rayon::prelude::*;

/// Fill `values` with one dense `dim × dim` element Hessian (J/m²) per element, in element
/// order and in parallel: `block(i, h)` writes element i's block into `h` (row-major),
/// which is then projected to PSD when `project` is set.
pub fn element_hessians(
    values: &mut [f64],
    dim: usize,
    project: bool,
    block: impl Fn(usize, &mut [f64]) + Sync + Send,
) {
    values
        .par_chunks_mut(dim * dim)
        .enumerate()
        .for_each(|(i, h)| {
            block(i, h);
            if project {
                project_psd(h, dim);
            }
        });
}

/// Replace the `n × n` symmetric row-major matrix `h` by its projection onto the positive
/// semi-definite cone (negative eigenvalues set to zero).
///
/// The matrix is scaled to unit max-norm and entries below 1e-100 of it are flushed to zero
/// first: without this, columns of tiny entries (e.g. the x–y rows of a flat hinge) underflow
/// in the Householder reduction and produce NaN.
pub fn project_psd(h: &mut [f64], n: usize) {
    let scale = h.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    if scale.is_nan() || scale <= 0.0 || !scale.is_finite() {
        return;
    }
    let m = DMatrix::from_row_slice(n, n, h).map(|v| {
        let w = v / scale;
        if w.abs() < 1e-100 {
            0.0
        } else {
            w
        }
    });
    let eig = SymmetricEigen::new(m.clone());
    let eig = if eig
        .eigenvalues
        .iter()
        .chain(eig.eigenvectors.iter())
        .all(|v| v.is_finite())
    {
        eig
    } else {
        jacobi_eigen(m)
    };
    if eig.eigenvalues.iter().all(|&l| l >= 0.0) {
        return;
    }
    let mut d = eig.eigenvalues.clone();
    for l in d.iter_mut() {
        *l = l.max(0.0);
    }
    let q = &eig.eigenvectors;
    let r = q * DMatrix::from_diagonal(&d) * q.transpose();
    for i in 0..n {
        for j in 0..n {
            h[i * n + j] = 0.5 * scale * (r[(i, j)] + r[(j, i)]);
        }
    }
}

/// Cyclic Jacobi eigen-decomposition of a small symmetric matrix: slower than nalgebra's
/// QR-based solver but free of the underflow that can make it return NaN.
fn jacobi_eigen(mut a: DMatrix<f64>) -> SymmetricEigen<f64, nalgebra::Dyn> {
    let n = a.nrows();
    let mut v = DMatrix::<f64>::identity(n, n);
    for _sweep in 0..60 {
        let off: f64 = (0..n)
            .flat_map(|i| (0..n).filter(move |&j| j != i).map(move |j| (i, j)))
            .map(|(i, j)| a[(i, j)].powi(2))
            .sum();
        let diag: f64 = (0..n).map(|i| a[(i, i)].powi(2)).sum();
        if off <= 1e-30 * diag || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[(p, q)];
                if apq == 0.0 {
                    continue;
                }
                let theta = (a[(q, q)] - a[(p, p)]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let t = if theta == 0.0 { 1.0 } else { t };
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[(k, p)], a[(k, q)]);
                    a[(k, p)] = c * akp - s * akq;
                    a[(k, q)] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[(p, k)], a[(q, k)]);
                    a[(p, k)] = c * apk - s * aqk;
                    a[(q, k)] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[(k, p)], v[(k, q)]);
                    v[(k, p)] = c * vkp - s * vkq;
                    v[(k, q)] = s * vkp + c * vkq;
                }
            }
        }
    }
    SymmetricEigen {
        eigenvalues: a.diagonal(),
        eigenvectors: v,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn projection_clamps_negative_eigenvalue() {
        // [[1, 2], [2, 1]] has eigenvalues 3 and −1 (vectors (1,1)/√2, (1,−1)/√2):
        // projection is 3/2 [[1,1],[1,1]].
        let mut h = [1.0, 2.0, 2.0, 1.0];
        project_psd(&mut h, 2);
        for v in h {
            assert!((v - 1.5).abs() < 1e-12);
        }
        let mut p = [2.0, 0.0, 0.0, 1.0];
        project_psd(&mut p, 2);
        assert_eq!(p, [2.0, 0.0, 0.0, 1.0]);
        // Tiny entries next to normal ones must not produce NaN.
        let mut t = [1.0, 1e-170, 0.0, 1e-170, -1e-170, 0.0, 0.0, 0.0, 1e-200];
        project_psd(&mut t, 3);
        assert!(t.iter().all(|v| v.is_finite()) && (t[0] - 1.0).abs() < 1e-15);
        // The Jacobi fallback reproduces a known decomposition.
        let m = DMatrix::from_row_slice(3, 3, &[2.0, 1.0, 0.0, 1.0, 2.0, 0.0, 0.0, 0.0, -1.0]);
        let e = jacobi_eigen(m.clone());
        let r =
            &e.eigenvectors * DMatrix::from_diagonal(&e.eigenvalues) * e.eigenvectors.transpose();
        assert!((r - m).norm() < 1e-12);
        let mut ev: Vec<f64> = e.eigenvalues.iter().copied().collect();
        ev.sort_by(f64::total_cmp);
        assert!(
            (ev[0] + 1.0).abs() < 1e-12
                && (ev[1] - 1.0).abs() < 1e-12
                && (ev[2] - 3.0).abs() < 1e-12
        );
    }
}
