//! The plane-strain St. Venant–Kirchhoff elastic energy of a Q2 mesh (3 × 3 Gauss points per
//! element), with its gradient and Hessian, and the Lamé constants it uses.

use super::mesh::QuadMesh;
use crate::math::Energy;
use anyhow::bail;

/// Gauss points and weights of the 3-point rule on [−1, 1].
const GAUSS3: [(f64, f64); 3] = [
    (-0.774_596_669_241_483_4, 5.0 / 9.0),
    (0.0, 8.0 / 9.0),
    (0.774_596_669_241_483_4, 5.0 / 9.0),
];

/// Quadratic Lagrange shape functions on [−1, 1] at nodes −1, 0, 1 and their derivatives.
fn lagrange2(t: f64) -> ([f64; 3], [f64; 3]) {
    (
        [0.5 * t * (t - 1.0), 1.0 - t * t, 0.5 * t * (t + 1.0)],
        [t - 0.5, -2.0 * t, t + 0.5],
    )
}

/// Lamé constants (λ_L, μ) in Pa of Young's modulus `e` (Pa) and Poisson ratio `nu`.
pub fn lame(e: f64, nu: f64) -> (f64, f64) {
    (
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        e / (2.0 * (1.0 + nu)),
    )
}

/// St. Venant–Kirchhoff plane-strain elastic energy (J per metre of depth) of a Q2 mesh;
/// dofs are the current positions (x, y) of every node, m (2 per node).
pub struct PlaneStrainSvk {
    n_nodes: usize,
    elements: Vec<[usize; 9]>,
    /// (λ_L, μ) per element, Pa.
    lame: Vec<(f64, f64)>,
    /// Per element, per Gauss point: reference shape-function gradients (1/m) and
    /// weight × det J (m²).
    pub(super) quad: Vec<[([[f64; 2]; 9], f64); 9]>,
}

impl PlaneStrainSvk {
    /// The energy of `mesh` with element materials `(E (Pa), ν)` per element. Fails when an
    /// element is inverted or degenerate in the reference configuration.
    pub fn new(mesh: &QuadMesh, materials: &[(f64, f64)]) -> anyhow::Result<Self> {
        if materials.len() != mesh.elements.len() {
            bail!(
                "{} materials given for {} elements",
                materials.len(),
                mesh.elements.len()
            );
        }
        let mut quad = Vec::with_capacity(mesh.elements.len());
        for (k, el) in mesh.elements.iter().enumerate() {
            let mut q = [([[0.0; 2]; 9], 0.0); 9];
            for (gj, &(eta, wj)) in GAUSS3.iter().enumerate() {
                for (gi, &(xi, wi)) in GAUSS3.iter().enumerate() {
                    let (nx, dx) = lagrange2(xi);
                    let (ny, dy) = lagrange2(eta);
                    // dN/dξ, dN/dη
                    let mut dn = [[0.0; 2]; 9];
                    for j in 0..3 {
                        for i in 0..3 {
                            dn[i + 3 * j] = [dx[i] * ny[j], nx[i] * dy[j]];
                        }
                    }
                    let mut jac = [[0.0; 2]; 2]; // J[a][b] = dX_a / dξ_b
                    for (a, &n) in el.iter().enumerate() {
                        let p = mesh.nodes[n];
                        for r in 0..2 {
                            for c in 0..2 {
                                jac[r][c] += p[r] * dn[a][c];
                            }
                        }
                    }
                    let det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0];
                    if !(det.is_finite() && det > 0.0) {
                        bail!("element {k} is inverted or degenerate (det J = {det:e})");
                    }
                    let inv = [
                        [jac[1][1] / det, -jac[0][1] / det],
                        [-jac[1][0] / det, jac[0][0] / det],
                    ];
                    let mut g = [[0.0; 2]; 9];
                    for a in 0..9 {
                        // dN/dX_c = Σ_b dN/dξ_b dξ_b/dX_c
                        for c in 0..2 {
                            g[a][c] = dn[a][0] * inv[0][c] + dn[a][1] * inv[1][c];
                        }
                    }
                    q[gi + 3 * gj] = (g, wi * wj * det);
                }
            }
            quad.push(q);
        }
        Ok(Self {
            n_nodes: mesh.nodes.len(),
            elements: mesh.elements.clone(),
            lame: materials.iter().map(|&(e, nu)| lame(e, nu)).collect(),
            quad,
        })
    }

    /// Energy of one element (J/m); adds its gradient (18) and Hessian (18 × 18 row-major).
    fn element(
        &self,
        k: usize,
        x: &[f64],
        mut grad: Option<&mut [f64; 18]>,
        mut hess: Option<&mut [f64; 324]>,
    ) -> f64 {
        let el = &self.elements[k];
        let (lam, mu) = self.lame[k];
        let mut e_total = 0.0;
        for (g, wj) in self.quad[k].iter() {
            let mut f = [[0.0; 2]; 2];
            for a in 0..9 {
                let p = [x[2 * el[a]], x[2 * el[a] + 1]];
                for r in 0..2 {
                    for c in 0..2 {
                        f[r][c] += p[r] * g[a][c];
                    }
                }
            }
            // Green strain and second Piola–Kirchhoff stress.
            let mut e = [[0.0; 2]; 2];
            for r in 0..2 {
                for c in 0..2 {
                    e[r][c] = 0.5 * (f[0][r] * f[0][c] + f[1][r] * f[1][c]);
                }
                e[r][r] -= 0.5;
            }
            let tr = e[0][0] + e[1][1];
            let ee = e[0][0] * e[0][0] + 2.0 * e[0][1] * e[0][1] + e[1][1] * e[1][1];
            e_total += wj * (0.5 * lam * tr * tr + mu * ee);
            if grad.is_none() && hess.is_none() {
                continue;
            }
            let mut s = [
                [2.0 * mu * e[0][0], 2.0 * mu * e[0][1]],
                [2.0 * mu * e[1][0], 2.0 * mu * e[1][1]],
            ];
            s[0][0] += lam * tr;
            s[1][1] += lam * tr;
            if let Some(gr) = grad.as_deref_mut() {
                // P = F S; ∂W/∂x_a = P g_a
                let mut p = [[0.0; 2]; 2];
                for r in 0..2 {
                    for c in 0..2 {
                        p[r][c] = f[r][0] * s[0][c] + f[r][1] * s[1][c];
                    }
                }
                for a in 0..9 {
                    for r in 0..2 {
                        gr[2 * a + r] += wj * (p[r][0] * g[a][0] + p[r][1] * g[a][1]);
                    }
                }
            }
            if let Some(h) = hess.as_deref_mut() {
                // K[(a,i),(b,k)] = w [ δ_ik g_a·S g_b + λ (F g_a)_i (F g_b)_k
                //                     + μ ((F Fᵀ)_ik g_a·g_b + (F g_b)_i (F g_a)_k) ]
                let mut fg = [[0.0; 2]; 9];
                let mut sg = [[0.0; 2]; 9];
                for a in 0..9 {
                    for r in 0..2 {
                        fg[a][r] = f[r][0] * g[a][0] + f[r][1] * g[a][1];
                        sg[a][r] = s[r][0] * g[a][0] + s[r][1] * g[a][1];
                    }
                }
                let mut fft = [[0.0; 2]; 2];
                for r in 0..2 {
                    for c in 0..2 {
                        fft[r][c] = f[r][0] * f[c][0] + f[r][1] * f[c][1];
                    }
                }
                for a in 0..9 {
                    for b in 0..9 {
                        let gsg = g[a][0] * sg[b][0] + g[a][1] * sg[b][1];
                        let gg = g[a][0] * g[b][0] + g[a][1] * g[b][1];
                        for i in 0..2 {
                            for kk in 0..2 {
                                let mut v = lam * fg[a][i] * fg[b][kk]
                                    + mu * (fft[i][kk] * gg + fg[b][i] * fg[a][kk]);
                                if i == kk {
                                    v += gsg;
                                }
                                h[(2 * a + i) * 18 + 2 * b + kk] += wj * v;
                            }
                        }
                    }
                }
            }
        }
        e_total
    }
}

impl Energy for PlaneStrainSvk {
    fn dofs(&self) -> usize {
        2 * self.n_nodes
    }

    fn eval(
        &self,
        x: &[f64],
        mut grad: Option<&mut [f64]>,
        mut hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64 {
        let mut total = 0.0;
        let want_g = grad.is_some();
        let want_h = hess.is_some();
        if let Some(h) = hess.as_deref_mut() {
            h.reserve(324 * self.elements.len());
        }
        for k in 0..self.elements.len() {
            let mut ge = [0.0; 18];
            let mut he = [0.0; 324];
            total += self.element(k, x, want_g.then_some(&mut ge), want_h.then_some(&mut he));
            let el = &self.elements[k];
            let dof = |l: usize| 2 * el[l / 2] + l % 2;
            if let Some(g) = grad.as_deref_mut() {
                for (l, v) in ge.iter().enumerate() {
                    g[dof(l)] += v;
                }
            }
            if let Some(h) = hess.as_deref_mut() {
                if project_psd {
                    crate::shell::psd::project_psd(&mut he, 18);
                }
                for r in 0..18 {
                    for c in 0..18 {
                        h.push((dof(r), dof(c), he[r * 18 + c]));
                    }
                }
            }
        }
        total
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd::{check_gradient, check_hessian};
    use crate::math::rng::Lcg;
    use crate::solver::statics::{StaticProblem, StaticSettings, StaticSolver};
    use crate::solver::status::SolveStatus;

    fn small_mesh() -> QuadMesh {
        QuadMesh::rectangle(2e-3, 2, &[0.0, 0.4e-3, 1e-3])
    }

    fn perturbed(mesh: &QuadMesh, amp: f64, seed: u64) -> Vec<f64> {
        let mut rng = Lcg::from_state(seed);
        mesh.nodes
            .iter()
            .flat_map(|p| [p[0], p[1]])
            .map(|v| v + amp * rng.next_signed())
            .collect()
    }

    /// Gradient and Hessian of the SVK energy against central differences, at a strongly
    /// deformed state (random displacements of 10% of the element size, plus a rotation).
    #[test]
    fn svk_energy_matches_finite_differences() {
        let mesh = small_mesh();
        let mats: Vec<(f64, f64)> = (0..mesh.elements.len())
            .map(|k| if k < 2 { (1e4, 0.45) } else { (1e6, 0.3) })
            .collect();
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let mut x = perturbed(&mesh, 1e-4, 5);
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        for p in x.chunks_mut(2) {
            let (a, b) = (p[0], p[1]);
            p[0] = c * a - s * b;
            p[1] = s * a + c * b;
        }
        let g = check_gradient(&e, &x, 1e-3);
        assert!(g.rel_error < 1e-7, "gradient {g:?}");
        let h = check_hessian(&e, &x, 1e-3);
        assert!(h.rel_error < 1e-7, "hessian {h:?}");
    }

    /// Rigid motions cost nothing; a uniform stretch costs the plane-strain SVK energy.
    #[test]
    fn rigid_motion_is_free_and_stretch_matches_formula() {
        let mesh = small_mesh();
        let (young, nu) = (2e5, 0.3);
        let mats = vec![(young, nu); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let (c, s) = (1.1f64.cos(), 1.1f64.sin());
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [c * p[0] - s * p[1] + 0.3, s * p[0] + c * p[1] - 0.2])
            .collect();
        let mut g = vec![0.0; x.len()];
        let w = e.eval(&x, Some(&mut g), None, false);
        assert!(w.abs() < 1e-12, "{w}");
        assert!(g.iter().all(|v| v.abs() < 1e-9), "{g:?}");
        // Uniaxial stretch 1 + a along x with y held: E_xx = a + a²/2, energy density
        // (λ_L/2 + μ) E_xx² over area 2e-3 × 1e-3.
        let a = 0.02;
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [(1.0 + a) * p[0], p[1]])
            .collect();
        let (lam, mu) = lame(young, nu);
        let exx = a + 0.5 * a * a;
        let expected = (0.5 * lam + mu) * exx * exx * 2e-6;
        let w = e.eval(&x, None, None, false);
        assert!(
            (w - expected).abs() < 1e-12 * expected.max(1.0),
            "{w} {expected}"
        );
    }

    /// Projected element Hessians are positive semi-definite: xᵀ K x ≥ 0 for random x.
    #[test]
    fn projected_hessian_is_psd() {
        let mesh = small_mesh();
        let mats = vec![(1e5, 0.3); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        // A strongly compressed state has an indefinite exact Hessian.
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [0.6 * p[0], 0.7 * p[1]])
            .collect();
        let n = x.len();
        let mut t = Vec::new();
        e.eval(&x, None, Some(&mut t), true);
        let k = crate::math::sparse::dense_from_triplets(n, &t);
        let mut exact = Vec::new();
        e.eval(&x, None, Some(&mut exact), false);
        let ke = crate::math::sparse::dense_from_triplets(n, &exact);
        let mut rng = Lcg::from_state(9);
        let mut min_proj = f64::INFINITY;
        let mut min_exact = f64::INFINITY;
        for _ in 0..200 {
            let v: Vec<f64> = (0..n).map(|_| rng.next_signed()).collect();
            let q = |m: &[f64]| -> f64 {
                (0..n)
                    .map(|i| v[i] * (0..n).map(|j| m[i * n + j] * v[j]).sum::<f64>())
                    .sum()
            };
            min_proj = min_proj.min(q(&k));
            min_exact = min_exact.min(q(&ke));
        }
        assert!(min_proj >= -1e-9 * k.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        assert!(min_exact < 0.0, "the test state should be indefinite");
    }

    /// Bending without shear locking: a clamped cantilever of thickness t and length 20 t,
    /// 2 Q2 layers through the thickness, under a small tip load P (per metre of depth).
    /// Timoshenko beam theory in plane strain: δ = P ℓ³ / (3 Ē I) + P ℓ / (κ G t),
    /// Ē = E/(1 − ν²), I = t³/12, κ = 5/6. The tolerances, 3 % for elements of aspect ratio
    /// 10 and 1 % for aspect 2, sit just above the stiffness those elements and the continuum
    /// clamp (which also stops the Poisson contraction at the root) add to beam theory.
    #[test]
    fn cantilever_tip_deflection_matches_beam_theory() {
        for (nx, tol) in [(4usize, 0.03), (20, 0.01)] {
            cantilever(nx, tol);
        }
    }

    fn cantilever(nx: usize, tol: f64) {
        let (t, ell) = (1e-3, 20e-3);
        let (young, nu) = (1e6, 0.3);
        let mesh = QuadMesh::rectangle(ell, nx, &[0.0, 0.5 * t, t]);
        let mats = vec![(young, nu); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let mut pinned = Vec::new();
        for r in 0..mesh.rows {
            let n = mesh.node(0, r);
            pinned.extend([2 * n, 2 * n + 1]);
        }
        // Tip load P distributed consistently over the 3 end nodes (1/6, 4/6, 1/6).
        let p_total = -1e-4; // N/m, tiny: linear regime
        let mut forces = vec![0.0; e.dofs()];
        for (r, w) in [(0, 1.0 / 6.0), (1, 4.0 / 6.0), (2, 1.0 / 6.0)] {
            forces[2 * mesh.node(mesh.columns - 1, r) + 1] = w * p_total;
        }
        let problem = StaticProblem {
            pinned,
            forces,
            ..Default::default()
        };
        let mut solver = StaticSolver::new(StaticSettings {
            tolerance: 1e-6 * p_total.abs(),
            ..Default::default()
        })
        .unwrap();
        let mut x: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p[0], p[1]]).collect();
        let rep = solver.solve(&e, &problem, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        let tip = mesh.node(mesh.columns - 1, 1);
        let delta = x[2 * tip + 1] - mesh.nodes[tip][1];
        let ebar = young / (1.0 - nu * nu);
        let g = young / (2.0 * (1.0 + nu));
        let i = t.powi(3) / 12.0;
        let expected =
            p_total * ell.powi(3) / (3.0 * ebar * i) + p_total * ell / (5.0 / 6.0 * g * t);
        let rel = (delta - expected).abs() / expected.abs();
        assert!(
            rel < tol,
            "nx {nx}: tip {delta:e} beam theory {expected:e} rel {rel:.4}"
        );
    }
}
