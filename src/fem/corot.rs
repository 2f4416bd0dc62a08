//! Rotations of deformation gradients that survive inversion, and the corotated energy
//! density.
//!
//! The rotation is the polar factor of F with the reflection removed (Irving, Teran and
//! Fedkiw 2004): F = U Σ̂ Vᵀ with U, V proper rotations and the smallest singular value
//! negated when det F < 0; R = U Vᵀ. For det F comfortably positive the polar factor comes
//! from a scaled Newton iteration (Higham 1986), which agrees with the SVD answer to round-off
//! and is several times cheaper.

use nalgebra::Matrix3;

type M3 = Matrix3<f64>;

/// Rotation R (det = +1) of the polar decomposition of `f`, with reflections removed as in
/// Irving et al. 2004 for inverted `f` (det f ≤ 0).
pub fn rotation(f: &M3) -> M3 {
    let det = f.determinant();
    let scale = f.norm_squared() / 3.0; // ~ σ² average
    if det > 1e-2 * scale.powf(1.5) {
        if let Some(r) = polar_newton(f) {
            return r;
        }
    }
    rotation_svd(f)
}

/// Scaled Newton iteration for the orthogonal polar factor (det > 0 assumed):
/// X ← ½ (γ X + X⁻ᵀ / γ), γ = |det X|^(−1/3), with X⁻ᵀ from the cofactors. Convergence is
/// quadratic, so stopping when a step is below 1e-12 leaves an error at round-off level.
fn polar_newton(f: &M3) -> Option<M3> {
    let mut x = *f;
    for _ in 0..30 {
        let (a, b, c) = (
            x.column(0).into_owned(),
            x.column(1).into_owned(),
            x.column(2).into_owned(),
        );
        let cof = M3::from_columns(&[b.cross(&c), c.cross(&a), a.cross(&b)]);
        let det = a.dot(&cof.column(0));
        if !(det > 0.0 && det.is_finite()) {
            return None;
        }
        let g = 1.0 / det.cbrt();
        let next = (x * g + cof * (1.0 / (det * g))) * 0.5;
        let d = (next - x).norm();
        x = next;
        if d < 1e-12 {
            return Some(x);
        }
    }
    None
}

/// Rotation from the SVD with the reflection moved into the smallest singular value.
pub fn rotation_svd(f: &M3) -> M3 {
    let svd = f.svd(true, true);
    let mut u = svd.u.expect("u requested");
    let mut v = svd.v_t.expect("v requested").transpose();
    let s = svd.singular_values;
    let m = if s[0] <= s[1] && s[0] <= s[2] {
        0
    } else if s[1] <= s[2] {
        1
    } else {
        2
    };
    if u.determinant() < 0.0 {
        u.column_mut(m).neg_mut();
    }
    if v.determinant() < 0.0 {
        v.column_mut(m).neg_mut();
    }
    u * v.transpose()
}

/// Corotated energy density (J/m³) ψ = μ‖S − I‖² + λ/2 tr(S − I)², S = sym(Rᵀ F), and its
/// first Piola–Kirchhoff stress P = R[2μ(S − I) + λ tr(S − I) I] (Pa). With R the polar
/// rotation of F (S then symmetric), P is the exact derivative of ψ(F); with R held fixed it
/// is the exact derivative of the frozen-rotation (rotated linear) energy.
pub fn corotated(f: &M3, r: &M3, mu: f64, lambda: f64) -> (f64, M3) {
    let a = r.transpose() * f;
    let s = (a + a.transpose()) * 0.5 - M3::identity();
    let tr = s.trace();
    let psi = mu * s.norm_squared() + 0.5 * lambda * tr * tr;
    let p = r * (s * (2.0 * mu) + M3::identity() * (lambda * tr));
    (psi, p)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Rotation3, Vector3};

    #[test]
    fn rotation_of_stretch_times_rotation_and_of_inversions() {
        let r0 = *Rotation3::from_axis_angle(&Vector3::y_axis(), 0.7).matrix();
        let s = M3::new(1.2, 0.1, 0.0, 0.1, 0.9, 0.05, 0.0, 0.05, 1.1);
        let f = r0 * s;
        assert!((rotation(&f) - r0).norm() < 1e-12);
        assert!((rotation_svd(&f) - r0).norm() < 1e-12);
        // Inverted: reflect z. The rotation stays proper and F = R S with S having one
        // negative eigenvalue.
        let fi = r0 * M3::from_diagonal(&Vector3::new(1.0, 0.8, -0.3));
        let ri = rotation(&fi);
        assert!((ri.determinant() - 1.0).abs() < 1e-12);
        assert!((ri - r0).norm() < 1e-12, "{ri}");
        let flat = M3::from_diagonal(&Vector3::new(1.0, 1.0, 0.0));
        assert!((rotation(&flat).determinant() - 1.0).abs() < 1e-12);
        // ψ = 0 and P = 0 for rigid motions.
        let (psi, p) = corotated(&r0, &r0, 3.0, 5.0);
        assert!(psi.abs() < 1e-24 && p.norm() < 1e-12);
    }
}
