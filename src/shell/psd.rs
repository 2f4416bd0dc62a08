//! Projection of small symmetric element matrices to positive semi-definite.

use nalgebra::{DMatrix, SymmetricEigen};

/// Replace the `n × n` symmetric row-major matrix `h` by its projection onto the positive
/// semi-definite cone (negative eigenvalues set to zero).
pub fn project_psd(h: &mut [f64], n: usize) {
    let m = DMatrix::from_row_slice(n, n, h);
    let eig = SymmetricEigen::new(m);
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
            h[i * n + j] = 0.5 * (r[(i, j)] + r[(j, i)]);
        }
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
    }
}
