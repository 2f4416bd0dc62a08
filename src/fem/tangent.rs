//! The derivative of the polar rotation, dR/dF, and the consistent tangent of the
//! corotational interior (the part of its Hessian that the frozen-rotation stiffness
//! R K₀ Rᵀ leaves out).
//!
//! **dR/dF.** With F = R S (S = Rᵀ F symmetric), a change dF turns R by dR = R \[ω\]×, where
//! (tr S · I − S) ω = vee(Rᵀ dF − dFᵀ R) (vee: the axial vector of a skew matrix). Its own
//! derivative along a second change dF₂ (rotation ω₂) follows from differentiating that
//! formula: dR₂ = R \[ω₂\]×, dS₂ = Rᵀ dF₂ − \[ω₂\]× S, d(tr S I − S)⁻¹ = −M (tr dS₂ I − dS₂) M.
//! [`RotationDerivative`] gives both; the muscle actuation energy reuses them.
//!
//! **Consistent tangent.** One element stores E = ½ uᵀ K₀ u with u_a = Rᵀ x_a − X_a and R the
//! polar rotation at the element centre, F_c = D x (D: 9 × 3K). With y_a = Rᵀ x_a, f = K₀ u,
//! du = (R̂ᵀ + Ŷ W) δx where Ŷ stacks \[y_a\]× and W = Ω D maps δx to ω. The exact Hessian is
//!
//!   H = (R̂ᵀ + Ŷ W)ᵀ K₀ (R̂ᵀ + Ŷ W) + Wᵀ P + Pᵀ W + Wᵀ Q W + Dᵀ C_F D,
//!
//! P = \[ \[f_a\]× Rᵀ \]_a, Q = sym(Σ f_a y_aᵀ) − (Σ f_a·y_a) I and C_F(i, j) = −τ · dω(E_i; E_j)
//! (τ = Σ y_a × f_a). The first term is positive semi-definite; it expands to R̂ K₀ R̂ᵀ plus a
//! correction of rank ≤ 6. The rest (the stress term, rank ≤ 12) is what makes H indefinite
//! under compression; the projected tangent clamps its negative eigenvalues to zero, so the
//! element matrix stays positive semi-definite and equals H wherever the stress term is.
//! Everything beyond R̂ K₀ R̂ᵀ is stored as Z C Zᵀ (Z: 3K × 18), so the matrix-free product
//! and the assembly keep the shared K₀.

use nalgebra::{DMatrix, Matrix3, SMatrix, Vector3};

type M3 = Matrix3<f64>;
type V3 = Vector3<f64>;

/// Relative size below which the smallest eigenvalue of tr S · I − S counts as singular
/// (an element whose centre is flattened to a line): its rotation derivative is left out.
const SINGULAR: f64 = 1e-9;

/// The cross-product matrix \[w\]× (\[w\]× v = w × v).
pub fn skew(w: &V3) -> M3 {
    M3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// The axial vector of the skew part's double, vee(A − Aᵀ): for A = \[w\]×/2 + symmetric, w.
fn vee_skew(a: &M3) -> V3 {
    V3::new(
        a[(2, 1)] - a[(1, 2)],
        a[(0, 2)] - a[(2, 0)],
        a[(1, 0)] - a[(0, 1)],
    )
}

/// The unit matrix E_k of F's entry k = 3 i + j (row i, column j).
fn unit(k: usize) -> M3 {
    let mut e = M3::zeros();
    e[(k / 3, k % 3)] = 1.0;
    e
}

/// The derivative of the polar rotation R(F) (dimensionless per unit of F) at one F.
#[derive(Debug, Clone, Copy)]
pub struct RotationDerivative {
    /// The rotation R.
    pub r: M3,
    /// The symmetric factor S = Rᵀ F.
    pub s: M3,
    /// M = (tr S · I − S)⁻¹.
    pub m: M3,
}

impl RotationDerivative {
    /// The derivative at deformation gradient `f` whose rotation is `r`; `None` when
    /// tr S · I − S is singular (two singular values of F sum to about zero).
    pub fn new(f: &M3, r: &M3) -> Option<Self> {
        let s = r.transpose() * f;
        let s = (s + s.transpose()) * 0.5;
        let g = M3::identity() * s.trace() - s;
        let eig = g.symmetric_eigenvalues();
        let big = eig.amax();
        if !(big.is_finite() && big > 0.0) || eig.iter().any(|v| v.abs() <= SINGULAR * big) {
            return None;
        }
        let m = g.try_inverse()?;
        Some(Self { r: *r, s, m })
    }

    /// The rotation ω of a change `df` of F: dR = R \[ω\]× (rad per unit of F).
    pub fn omega(&self, df: &M3) -> V3 {
        self.m * vee_skew(&(self.r.transpose() * df))
    }

    /// Ω (3 × 9): ω = Ω vec(dF), vec index 3 i + j for entry (i, j).
    pub fn omega_matrix(&self) -> SMatrix<f64, 3, 9> {
        let mut o = SMatrix::<f64, 3, 9>::zeros();
        for k in 0..9 {
            o.set_column(k, &self.omega(&unit(k)));
        }
        o
    }

    /// The derivative of ω(dF₁) along a second change dF₂ of F (second derivative of R).
    pub fn second(&self, df1: &M3, df2: &M3) -> V3 {
        let rt = self.r.transpose();
        let w2 = self.omega(df2);
        let v1 = vee_skew(&(rt * df1));
        let g = -skew(&w2) * rt * df1;
        let dv = vee_skew(&g);
        let ds = rt * df2 - skew(&w2) * self.s;
        let ds = (ds + ds.transpose()) * 0.5;
        let dm = -self.m * (M3::identity() * ds.trace() - ds) * self.m;
        dm * v1 + self.m * dv
    }
}

/// The rotation-derivative part of one element's Hessian: H_e − R̂ K₀ R̂ᵀ = Z C Zᵀ (N/m),
/// stored as Z and Z C (3K × 18 each, column-major).
#[derive(Debug, Clone)]
pub struct RotationCorrection {
    z: DMatrix<f64>,
    zc: DMatrix<f64>,
}

impl RotationCorrection {
    /// The 3 × 3 block (a, b) of Z C Zᵀ (N/m).
    pub fn block(&self, a: usize, b: usize) -> M3 {
        let r = self.z.ncols();
        let mut out = M3::zeros();
        for p in 0..r {
            for i in 0..3 {
                let zc = self.zc[(3 * a + i, p)];
                for j in 0..3 {
                    out[(i, j)] += zc * self.z[(3 * b + j, p)];
                }
            }
        }
        out
    }

    /// out += scale · Z C Zᵀ x over one element's values (3K each; N/m × m = N when scale
    /// is 1).
    pub fn apply(&self, x: &[f64], out: &mut [f64], scale: f64) {
        let r = self.z.ncols();
        let n3 = self.z.nrows();
        for p in 0..r {
            let zp = &self.z.as_slice()[p * n3..(p + 1) * n3];
            let t: f64 = zp.iter().zip(x).map(|(a, b)| a * b).sum::<f64>() * scale;
            let zcp = &self.zc.as_slice()[p * n3..(p + 1) * n3];
            for (o, c) in out.iter_mut().zip(zcp) {
                *o += c * t;
            }
        }
    }

    /// Add Z C Zᵀ into the row-major 3K × 3K matrix `out`.
    pub fn add_to(&self, out: &mut [f64]) {
        let full = &self.zc * self.z.transpose();
        let n = full.nrows();
        for i in 0..n {
            for j in 0..n {
                out[i * n + j] += full[(i, j)];
            }
        }
    }
}

/// One element's state, as [`RotationCorrection::new`] needs it.
pub struct ElementState<'a> {
    /// Rotation R at the centre.
    pub r: &'a M3,
    /// Centre deformation gradient F_c.
    pub fc: &'a M3,
    /// Rotated node positions y_a = Rᵀ (x_a − x_0) (m, 3K).
    pub y: &'a [f64],
    /// Element-frame forces f = K₀ u (N, 3K).
    pub f: &'a [f64],
    /// K₀ (3K × 3K, symmetric, N/m).
    pub k0: &'a [f64],
    /// Shape function gradients at the centre (1/m).
    pub center_g: &'a [[f64; 3]],
}

impl RotationCorrection {
    /// The correction of one element (exact, or with its stress term projected to positive
    /// semi-definite when `project`); `None` where R has no derivative (see
    /// [`RotationDerivative::new`]).
    pub fn new(el: &ElementState, project: bool) -> Option<Self> {
        let rd = RotationDerivative::new(el.fc, el.r)?;
        let n3 = el.y.len();
        let k = n3 / 3;
        let vec3 = |v: &[f64], a: usize| V3::new(v[3 * a], v[3 * a + 1], v[3 * a + 2]);
        let mut yhat = DMatrix::zeros(n3, 3);
        let mut pt = DMatrix::zeros(n3, 3);
        let mut dt = DMatrix::zeros(n3, 9);
        let (mut fy, mut fdoty, mut tau) = (M3::zeros(), 0.0, V3::zeros());
        for a in 0..k {
            let (ya, fa) = (vec3(el.y, a), vec3(el.f, a));
            yhat.fixed_view_mut::<3, 3>(3 * a, 0).copy_from(&skew(&ya));
            pt.fixed_view_mut::<3, 3>(3 * a, 0)
                .copy_from(&(-el.r * skew(&fa)));
            fy += fa * ya.transpose();
            fdoty += fa.dot(&ya);
            tau += ya.cross(&fa);
            for i in 0..3 {
                for j in 0..3 {
                    dt[(3 * a + i, 3 * i + j)] = el.center_g[a][j];
                }
            }
        }
        let k0 = nalgebra::DMatrixView::from_slice(el.k0, n3, n3);
        let k0y = k0 * &yhat;
        let mut a1 = k0y.clone();
        for a in 0..k {
            let blk = el.r * a1.fixed_view::<3, 3>(3 * a, 0);
            a1.fixed_view_mut::<3, 3>(3 * a, 0).copy_from(&blk);
        }
        let b1 = yhat.transpose() * &k0y;
        let omega = rd.omega_matrix();
        let omega_d = DMatrix::from_column_slice(3, 9, omega.as_slice());
        let wt = &dt * omega_d.transpose();
        let q = (fy + fy.transpose()) * 0.5 - M3::identity() * fdoty;
        let mut cf = DMatrix::zeros(9, 9);
        for i in 0..9 {
            for j in 0..9 {
                cf[(i, j)] = -tau.dot(&rd.second(&unit(i), &unit(j)));
            }
        }
        let cf = (&cf + cf.transpose()) * 0.5;
        let q_d = DMatrix::from_column_slice(3, 3, q.as_slice());
        // Stress term Z₂ C₂ Z₂ᵀ, Z₂ = [Pᵀ, Dᵀ], C₂ = [[0, Ω], [Ωᵀ, Ωᵀ Q Ω + C_F]].
        let mut c2 = DMatrix::zeros(12, 12);
        c2.view_mut((0, 3), (3, 9)).copy_from(&omega_d);
        c2.view_mut((3, 0), (9, 3)).copy_from(&omega_d.transpose());
        c2.view_mut((3, 3), (9, 9))
            .copy_from(&(omega_d.transpose() * q_d * &omega_d + cf));
        let mut z2 = DMatrix::zeros(n3, 12);
        z2.view_mut((0, 0), (n3, 3)).copy_from(&pt);
        z2.view_mut((0, 3), (n3, 9)).copy_from(&dt);
        let (z2, c2) = if project {
            project_low_rank(z2, &c2)
        } else {
            (z2, c2)
        };
        // Gauss–Newton part: Z₁ = [A₁, Wᵀ], C₁ = [[0, I], [I, B₁]], A₁ = R̂ K₀ Ŷ.
        let r2 = z2.ncols();
        let mut z = DMatrix::zeros(n3, 6 + r2);
        z.view_mut((0, 0), (n3, 3)).copy_from(&a1);
        z.view_mut((0, 3), (n3, 3)).copy_from(&wt);
        z.view_mut((0, 6), (n3, r2)).copy_from(&z2);
        let mut c = DMatrix::zeros(6 + r2, 6 + r2);
        c.view_mut((0, 3), (3, 3)).fill_with_identity();
        c.view_mut((3, 0), (3, 3)).fill_with_identity();
        c.view_mut((3, 3), (3, 3)).copy_from(&b1);
        c.view_mut((6, 6), (r2, r2)).copy_from(&c2);
        let zc = &z * c;
        if zc.iter().chain(z.iter()).all(|v| v.is_finite()) {
            Some(Self { z, zc })
        } else {
            None
        }
    }
}

/// Z C Zᵀ with its negative eigenvalues clamped to zero, returned as (Q, E) with Q
/// orthonormal (columns of Z's span) and E positive semi-definite: Z = Q R, then the
/// eigen-decomposition of R C Rᵀ.
fn project_low_rank(z: DMatrix<f64>, c: &DMatrix<f64>) -> (DMatrix<f64>, DMatrix<f64>) {
    let qr = z.qr();
    let (q, r) = (qr.q(), qr.r());
    let inner = &r * c * r.transpose();
    let inner = (&inner + inner.transpose()) * 0.5;
    let eig = inner.symmetric_eigen();
    let lam = eig.eigenvalues.map(|v| v.max(0.0));
    let e = &eig.eigenvectors * DMatrix::from_diagonal(&lam) * eig.eigenvectors.transpose();
    (q, e)
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    fn polar(f: &M3) -> M3 {
        crate::fem::corot::rotation(f)
    }

    /// ω and its derivative against central differences of the polar rotation itself.
    #[test]
    fn rotation_derivatives_match_finite_differences() {
        let rot = *Rotation3::from_euler_angles(0.7, -1.1, 2.0).matrix();
        let f = rot * M3::new(1.3, 0.2, -0.1, 0.1, 0.8, 0.3, 0.0, -0.2, 1.1);
        let r = polar(&f);
        let rd = RotationDerivative::new(&f, &r).unwrap();
        let df1 = M3::new(0.3, -0.2, 0.5, 0.1, 0.4, -0.6, 0.2, 0.7, -0.1);
        let df2 = M3::new(-0.4, 0.1, 0.2, 0.6, -0.3, 0.1, 0.5, -0.2, 0.3);
        let h = 1e-6;
        // dR ≈ (R(F + h dF) − R(F − h dF)) / 2h = R [ω]×.
        let dr = (polar(&(f + df1 * h)) - polar(&(f - df1 * h))) / (2.0 * h);
        let fd_w = vee_skew(&(r.transpose() * dr)) * 0.5;
        let w = rd.omega(&df1);
        assert!((fd_w - w).norm() < 1e-7 * w.norm(), "{fd_w} vs {w}");
        // dω(dF₁; dF₂) ≈ (ω at F + h dF₂ − ω at F − h dF₂) / 2h.
        let at = |g: M3| RotationDerivative::new(&g, &polar(&g)).unwrap().omega(&df1);
        let fd2 = (at(f + df2 * h) - at(f - df2 * h)) / (2.0 * h);
        let d2 = rd.second(&df1, &df2);
        assert!((fd2 - d2).norm() < 1e-6 * d2.norm(), "{fd2} vs {d2}");
    }

    /// A flattened centre (two singular values summing to zero) has no rotation derivative.
    #[test]
    fn a_singular_centre_has_no_derivative() {
        let f = M3::from_diagonal(&V3::new(1.0, 1e-14, -1e-14));
        let r = polar(&f);
        assert!(RotationDerivative::new(&f, &r).is_none());
    }
}
