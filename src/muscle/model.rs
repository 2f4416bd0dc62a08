//! The muscle model: named sets of lattice elements that either change the interior's rest
//! state (an *actuation*, the default for muscles generated from blend shapes) or pull along
//! a fibre direction per element (muscle files), and the active energy an activation adds.
//!
//! # Actuation muscles
//!
//! An actuation muscle holds, for each of its elements, an offset d_m,e of the element's rest
//! node positions in its own rotated frame (3K numbers, m), and (generated muscles) the
//! lattice rest change s_m those offsets are of. At activations a the interior's rest state
//! is actuated by d(a) ([`ActuationBlend::field`], [`crate::fem::Interior::set_actuation`]): the
//! offsets of the summed change X + Σ_m a_m s_m ([`super::blend`]: muscles combine as the
//! blend shapes they make, linearly in position), or Σ_m a_m d_m for muscles given as offsets
//! alone; element e stores ½ (u_e − d_e(a))ᵀ K₀ (u_e − d_e(a)). This is Phace's rest-state actuation (Ichim et al. 2017, ψ = min_R ‖F − R A(a)‖²
//! with A(a) = I + Σ a_m (A_m − I)) written per element of the corotational interior: the
//! offsets carry a symmetric stretch that varies across the 27-node element. A compatible
//! actuation makes its shape at zero energy whatever the stiffness, so a muscle does not have
//! to out-pull passive flesh; where the tracking resists, its offsets are fitted
//! with it in the loop ([`super::actuation`]). Its unit force is −∂∇E/∂a_m through
//! ∂d/∂a_m ([`ActuationBlend::tangents`]).
//!
//! # Fibre muscles
//!
//! Active energy of muscle m at activation a (J), summed over its elements e and the 27 Gauss
//! points of each (weight w, m³):
//!
//!   E_m(q, a) = a σ_m Σ_e Σ_g w [ (‖F f_e‖ − 1) − (det F − 1) / 3 ],   σ_m = 3 μ c_m,
//!
//! with F the deformation gradient at the Gauss point, f_e the unit fibre direction (rest
//! frame), μ the interior's shear modulus (Pa) and c_m the muscle's maximum contraction
//! (dimensionless). The first term is a contractile fibre tension of a σ_m (Pa, a Hill-type
//! active stress); the second makes the active stress deviatoric: at small strain the
//! first Piola–Kirchhoff stress is a σ (f fᵀ − I/3), which has zero trace, so the tissue
//! shortens along the fibre and widens across it with its volume kept (to first order, for
//! any isotropic interior). A free block of muscle of the corotational interior (shear
//! modulus μ) in equilibrium shortens along the fibre by the strain a c (linearised; see
//! the tests): c is the free contraction at full activation.
//!
//! E_m is linear in a (zero at rest activation, no passive stiffness added), and invariant
//! under rigid motions (‖R F f‖ = ‖F f‖, det R F = det F). Its derivatives with respect to
//! node positions are exact: P = ∂ψ/∂F = n fᵀ − cof(F)/3 (n = F f/‖F f‖), and the Hessian
//! of ‖F f‖ is (f·g_a)(f·g_b)(I − n nᵀ)/‖F f‖ per node pair (a, b), that of det F is
//! −[F (g_a × g_b)]× (g the shape-function gradients).

use super::blend::ActuationBlend;
pub use super::definition::{Muscle, DEFAULT_MAX_CONTRACTION};
use crate::fem::Interior;
use crate::math::Energy;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;

type M3 = Matrix3<f64>;
type V3 = Vector3<f64>;

/// Fibre stretch below which the fibre direction is undefined (the element has collapsed
/// along its fibre); the tension term is skipped there.
const MIN_STRETCH: f64 = 1e-9;

/// The active energy of a set of muscles at given activations, as an [`Energy`] over the
/// interior's node positions (flat, m). Add it to the interior energy for the muscle-driven
/// equilibrium.
pub struct ActiveEnergy<'a> {
    interior: &'a Interior,
    /// Per element: (fibre, a σ in Pa) of each muscle acting on it.
    terms: Vec<(usize, Vec<(V3, f64)>)>,
    /// [`triple_tensor`] of the interior, computed on the first Hessian request.
    triple: std::sync::OnceLock<Vec<f64>>,
}

impl<'a> ActiveEnergy<'a> {
    /// The active energy of `muscles` at `activations` (one per muscle, dimensionless) on
    /// `interior`. Muscles are assumed validated against the interior's lattice.
    pub fn new(interior: &'a Interior, muscles: &[Muscle], activations: &[f64]) -> Self {
        assert_eq!(
            muscles.len(),
            activations.len(),
            "one activation per muscle"
        );
        let mut per: Vec<Vec<(V3, f64)>> = vec![Vec::new(); interior.elements.len()];
        for (m, &a) in muscles.iter().zip(activations) {
            let s = a * m.stress(interior.mu);
            for (&e, f) in m.elements.iter().zip(&m.fibres) {
                per[e].push((V3::new(f[0], f[1], f[2]), s));
            }
        }
        let terms = per
            .into_iter()
            .enumerate()
            .filter(|(_, t)| !t.is_empty())
            .collect();
        Self {
            interior,
            terms,
            triple: std::sync::OnceLock::new(),
        }
    }

    /// Elements touched by at least one muscle.
    pub fn element_count(&self) -> usize {
        self.terms.len()
    }
}

/// Energy density ψ/(a σ) (dimensionless) and P = ∂ψ/∂F / (a σ) at one point.
fn density(f: &M3, fib: &V3) -> (f64, M3, f64, V3) {
    let v = f * fib;
    let l = v.norm();
    let (c0, c1, c2) = (
        f.column(0).into_owned(),
        f.column(1).into_owned(),
        f.column(2).into_owned(),
    );
    let cof = M3::from_columns(&[c1.cross(&c2), c2.cross(&c0), c0.cross(&c1)]);
    let det = c0.dot(&cof.column(0));
    let mut p = -cof / 3.0;
    let mut psi = -(det - 1.0) / 3.0;
    let n = if l > MIN_STRETCH { v / l } else { V3::zeros() };
    if l > MIN_STRETCH {
        psi += l - 1.0;
        p += n * fib.transpose();
    }
    (psi, p, l, n)
}

fn skew(w: &V3) -> M3 {
    M3::new(0.0, -w.z, w.y, w.z, 0.0, -w.x, -w.y, w.x, 0.0)
}

/// The 9 × 9 Hessian d²ψ/dF² / (a σ) at one point, index 3·j + i for F_ij (column-major).
fn density_hessian(f: &M3, fib: &V3, l: f64, n: &V3) -> [[f64; 9]; 9] {
    let mut h = [[0.0; 9]; 9];
    if l > MIN_STRETCH {
        let a = (M3::identity() - n * n.transpose()) / l;
        for j in 0..3 {
            for k in 0..3 {
                let c = fib[j] * fib[k];
                for i in 0..3 {
                    for m in 0..3 {
                        h[3 * j + i][3 * k + m] += c * a[(i, m)];
                    }
                }
            }
        }
    }
    // −(1/3) ∂²det/∂F_j∂F_l: block (j, l) = −(1/3)·(−[F (e_j × e_l)]×).
    for j in 0..3 {
        for k in 0..3 {
            if j == k {
                continue;
            }
            let e = V3::ith(j, 1.0).cross(&V3::ith(k, 1.0));
            let b = skew(&(f * e)) / 3.0;
            for i in 0..3 {
                for m in 0..3 {
                    h[3 * j + i][3 * k + m] += b[(i, m)];
                }
            }
        }
    }
    h
}

impl ActiveEnergy<'_> {
    /// Energy (J) of element term `t`, adding the local gradient (N, 3K) and, when asked,
    /// the local Hessian (N/m, 3K × 3K row-major).
    fn element(
        &self,
        x: &[f64],
        t: usize,
        grad: &mut [f64],
        hess: Option<&mut [f64]>,
        project_psd: bool,
    ) -> f64 {
        let (e, terms) = &self.terms[t];
        if terms.iter().all(|(_, s)| *s == 0.0) {
            // Inactive element: zero energy, gradient and Hessian (the Hessian buffer keeps
            // its zeros so the triplet layout does not depend on the activations).
            return 0.0;
        }
        let fs = self.interior.deformation_gradients(x, *e);
        let k = self.interior.nodes_per_element();
        let n3 = 3 * k;
        let mut energy = 0.0;
        let mut hess = hess;
        let cheap = hess.is_some() && !project_psd;
        // Upper node-pair blocks (b ≥ a) of the Hessian on the cheap path.
        let mut hb = if cheap {
            vec![M3::zeros(); k * k]
        } else {
            Vec::new()
        };
        let mut c = [0.0; 27];
        for (q, f) in self.interior.qp.iter().zip(&fs) {
            let mut p_tot = M3::zeros();
            let mut h9 = [[0.0; 9]; 9];
            for (fib, s) in terms {
                let (psi, p, l, n) = density(f, fib);
                energy += q.w * s * psi;
                p_tot += p * *s;
                if project_psd && hess.is_some() {
                    let hd = density_hessian(f, fib, l, &n);
                    for i in 0..9 {
                        for j in 0..9 {
                            h9[i][j] += s * hd[i][j];
                        }
                    }
                } else if cheap && l > MIN_STRETCH && *s != 0.0 {
                    // Fibre term: (f·g_a)(f·g_b) w s (I − nnᵀ)/l.
                    let wsa = (M3::identity() - n * n.transpose()) * (q.w * s / l);
                    for a in 0..k {
                        c[a] = fib.x * q.g[a][0] + fib.y * q.g[a][1] + fib.z * q.g[a][2];
                    }
                    for a in 0..k {
                        if c[a] == 0.0 {
                            continue;
                        }
                        for b in a..k {
                            hb[a * k + b] += wsa * (c[a] * c[b]);
                        }
                    }
                }
            }
            for a in 0..k {
                let ga = V3::new(q.g[a][0], q.g[a][1], q.g[a][2]);
                let fa = p_tot * ga * q.w;
                for i in 0..3 {
                    grad[3 * a + i] += fa[i];
                }
            }
            if !project_psd {
                continue;
            }
            let Some(hm) = hess.as_deref_mut() else {
                continue;
            };
            let m = nalgebra::SMatrix::<f64, 9, 9>::from_fn(|i, j| h9[i][j]);
            let mut eig = SymmetricEigen::new(m);
            eig.eigenvalues.iter_mut().for_each(|v| *v = v.max(0.0));
            let mp = eig.recompose();
            for a in 0..k {
                for b in 0..k {
                    let (ga, gb) = (q.g[a], q.g[b]);
                    for i in 0..3 {
                        for m2 in 0..3 {
                            let mut v = 0.0;
                            for j in 0..3 {
                                for l in 0..3 {
                                    v += ga[j] * mp[(3 * j + i, 3 * l + m2)] * gb[l];
                                }
                            }
                            hm[(3 * a + i) * n3 + 3 * b + m2] += q.w * v;
                        }
                    }
                }
            }
        }
        if let (true, Some(hm)) = (cheap, hess) {
            // Volume term: Σ_q w (s_sum/3) [F_q (g_a × g_b)]× = (s_sum/3) [Σ_c T_abc x_c]×,
            // with T_abc = Σ_q w g_c · (g_a × g_b) (the same for every element).
            let s3: f64 = terms.iter().map(|(_, s)| s).sum::<f64>() / 3.0;
            let t = self.triple.get_or_init(|| triple_tensor(self.interior));
            let nodes = &self.interior.elements[*e];
            let xs: Vec<V3> = nodes
                .iter()
                .map(|&n| V3::new(x[3 * n], x[3 * n + 1], x[3 * n + 2]))
                .collect();
            for a in 0..k {
                for b in a..k {
                    let mut blk = hb[a * k + b];
                    if a != b && s3 != 0.0 {
                        let row = &t[(a * k + b) * k..(a * k + b + 1) * k];
                        let v: V3 = row.iter().zip(&xs).map(|(tc, xc)| xc * *tc).sum();
                        blk += skew(&(v * s3));
                    }
                    for i in 0..3 {
                        for m2 in 0..3 {
                            hm[(3 * a + i) * n3 + 3 * b + m2] = blk[(i, m2)];
                            hm[(3 * b + m2) * n3 + 3 * a + i] = blk[(i, m2)];
                        }
                    }
                }
            }
        }
        energy
    }
}

/// T_abc = Σ_q w_q g_c · (g_a × g_b) over the interior's Gauss points (m³/m³ = 1),
/// index (a·K + b)·K + c.
fn triple_tensor(interior: &Interior) -> Vec<f64> {
    let k = interior.nodes_per_element();
    let mut t = vec![0.0; k * k * k];
    for q in &interior.qp {
        let g: Vec<V3> = q.g.iter().map(|g| V3::new(g[0], g[1], g[2])).collect();
        for a in 0..k {
            for b in 0..k {
                if a == b {
                    continue;
                }
                let ab = g[a].cross(&g[b]) * q.w;
                for (cc, gc) in g.iter().enumerate() {
                    t[(a * k + b) * k + cc] += gc.dot(&ab);
                }
            }
        }
    }
    t
}

impl Energy for ActiveEnergy<'_> {
    fn dofs(&self) -> usize {
        3 * self.interior.nodes
    }

    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64 {
        let k = self.interior.nodes_per_element();
        let n3 = 3 * k;
        let want_h = hess.is_some();
        let per: Vec<(f64, Vec<f64>, Vec<f64>)> = (0..self.terms.len())
            .into_par_iter()
            .map(|t| {
                let mut g = vec![0.0; n3];
                let mut h = if want_h {
                    vec![0.0; n3 * n3]
                } else {
                    Vec::new()
                };
                let en = self.element(
                    x,
                    t,
                    &mut g,
                    if want_h { Some(&mut h) } else { None },
                    project_psd,
                );
                (en, g, h)
            })
            .collect();
        let mut energy = 0.0;
        let mut grad = grad;
        let mut hess = hess;
        for ((e, _), (en, g, h)) in self.terms.iter().zip(per) {
            energy += en;
            let nodes = &self.interior.elements[*e];
            if let Some(gr) = grad.as_deref_mut() {
                for (a, &n) in nodes.iter().enumerate() {
                    for i in 0..3 {
                        gr[3 * n + i] += g[3 * a + i];
                    }
                }
            }
            if let Some(hs) = hess.as_deref_mut() {
                for (a, &na) in nodes.iter().enumerate() {
                    for (b, &nb) in nodes.iter().enumerate() {
                        for i in 0..3 {
                            for j in 0..3 {
                                hs.push((3 * na + i, 3 * nb + j, h[(3 * a + i) * n3 + 3 * b + j]));
                            }
                        }
                    }
                }
            }
        }
        energy
    }
}

/// The generalised force of each muscle at unit activation at `x` (flat over node DOFs, N),
/// at activations `a`: −∂E_m/∂q for a fibre muscle (E_m is linear in a, so its force at
/// activation a is a times this), −∂∇E/∂a_m of the actuated interior for an actuation
/// muscle (the rest change's derivative [`ActuationBlend::tangents`] at `a`, through the
/// interior's current actuation).
pub fn unit_forces(
    interior: &Interior,
    muscles: &[Muscle],
    blend: &ActuationBlend,
    a: &[f64],
    x: &[f64],
) -> Vec<Vec<f64>> {
    let tangents = blend.tangents(interior, muscles, a);
    muscles
        .par_iter()
        .zip(&tangents)
        .map(|(m, (elements, rates))| {
            if m.is_actuation() {
                let mut f = vec![0.0; x.len()];
                interior.actuation_force(x, elements, rates, &mut f);
                return f;
            }
            fibre_force(interior, m, x)
        })
        .collect()
}

/// The force each muscle's whole change makes at `x` (flat, N): a fibre muscle's unit force,
/// an actuation muscle's −∂∇E/∂s for its rest change d_m scaled by s (at rest: Σ_e K₀ d_m,e).
/// The scale of the forces an equilibrium balances.
pub fn full_forces(interior: &Interior, muscles: &[Muscle], x: &[f64]) -> Vec<Vec<f64>> {
    muscles
        .par_iter()
        .map(|m| {
            if m.is_actuation() {
                let mut f = vec![0.0; x.len()];
                interior.actuation_force(x, &m.elements, &m.actuation, &mut f);
                return f;
            }
            fibre_force(interior, m, x)
        })
        .collect()
}

/// −∂E_m/∂q of fibre muscle `m` at activation 1 (flat, N).
fn fibre_force(interior: &Interior, m: &Muscle, x: &[f64]) -> Vec<f64> {
    let e = ActiveEnergy::new(interior, std::slice::from_ref(m), &[1.0]);
    let mut g = vec![0.0; x.len()];
    e.eval(x, Some(&mut g), None, false);
    g.iter_mut().for_each(|v| *v = -*v);
    g
}

/// The active energy linearised at node positions `q` (flat, m), in the form of
/// [`crate::fem::ExtraTerms`] for one backward Euler step or quasi-static solve of the
/// interior: the force F = −∇E_a(q) (flat, N) and the stiffness K = ∇²E_a(q) projected to
/// positive semi-definite (triplets, N/m), so that E_a(y) ≈ E_a(q) − Fᵀ(y − q) +
/// ½ (y − q)ᵀ K (y − q) within the step. (Add the skin's terms to these when both act.)
pub fn linearised_terms(energy: &ActiveEnergy, q: &[f64]) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
    let mut g = vec![0.0; q.len()];
    let mut k = Vec::new();
    energy.eval(q, Some(&mut g), Some(&mut k), true);
    g.iter_mut().for_each(|v| *v = -*v);
    (k, g)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn density_gradient_and_hessian_match_finite_differences() {
        let f = M3::new(1.1, 0.2, -0.1, 0.05, 0.9, 0.3, -0.2, 0.1, 1.2);
        let fib = V3::new(0.3, -0.5, 0.8).normalize();
        let (_, p, l, n) = density(&f, &fib);
        let h = density_hessian(&f, &fib, l, &n);
        let eps = 1e-6;
        for c in 0..9 {
            let (i, j) = (c % 3, c / 3);
            let mut fp = f;
            fp[(i, j)] += eps;
            let mut fm = f;
            fm[(i, j)] -= eps;
            let (psp, pp, _, _) = density(&fp, &fib);
            let (psm, pm, _, _) = density(&fm, &fib);
            assert!(((psp - psm) / (2.0 * eps) - p[(i, j)]).abs() < 1e-8);
            for r in 0..9 {
                let (ri, rj) = (r % 3, r / 3);
                let num = (pp[(ri, rj)] - pm[(ri, rj)]) / (2.0 * eps);
                assert!(
                    (num - h[r][c]).abs() < 1e-7,
                    "{r} {c}: {num} vs {}",
                    h[r][c]
                );
            }
        }
    }
}
