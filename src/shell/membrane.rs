//! Membrane (stretch and shear) energy per triangle with plane-stress Lamé parameters times
//! thickness, μ = E_x / (2(1+ν)), λ = E_x ν / (1 − ν²), in one of two laws
//! ([`MembraneLaw`]) with the same small-strain behaviour (uniaxial stress gives Young's
//! modulus, biaxial strain E_x h / (1 − ν²)):
//!
//! - Saint Venant–Kirchhoff: with Green strain E = ½ (FᵀF − I) (F: 3 × 2, from the rest
//!   triangle's own 2D frame), W = A [ μh E:E + ½ λh (tr E)² ]. Its uniaxial force
//!   μ-part ∝ s (s² − 1) peaks at stretch s = 1/√3 and then falls: past 42 % compression the
//!   sheet softens towards collapse.
//! - Biot (corotated linear): with principal stretches s₁, s₂ of F,
//!   W = A [ μh ((s₁ − 1)² + (s₂ − 1)²) + ½ λh (s₁ + s₂ − 2)² ], whose force grows linearly
//!   in compression all the way to s = 0. Written through C = FᵀF: ‖U − I‖² = tr C − 2τ + 2
//!   with τ = s₁ + s₂ = √(tr C + 2 √det C).
//!
//! The thickness may vary per triangle ([`MembraneEnergy::with_thickness`]): each element
//! then uses μ h_t and λ h_t of its own thickness h_t (the stiffness of a plane-stress sheet
//! is linear in h). A uniform thickness gives bit-identical values to [`MembraneEnergy::new`].

use super::material::ShellMaterial;
use super::psd::{element_hessians, project_psd};
use super::scatter::{scatter_element_hessians, Colouring};
use crate::math::Energy;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;

/// Rest data of one membrane triangle.
#[derive(Debug, Clone, Copy)]
pub struct MembraneElement {
    /// Vertex indices.
    pub v: [usize; 3],
    /// Shape-function gradients in the rest 2D frame (1/m): F = Σ_i x_i b_iᵀ.
    pub b: [[f64; 2]; 3],
    /// Rest area (m²).
    pub area: f64,
}

/// The membrane energy of a triangle mesh (J), over flat positions (m).
#[derive(Debug, Clone)]
pub struct MembraneEnergy {
    /// Elements with their rest data.
    pub elements: Vec<MembraneElement>,
    /// μ h at the material's reference thickness (N/m).
    pub mu_h: f64,
    /// λ h at the material's reference thickness (N/m), plane stress.
    pub lambda_h: f64,
    /// Per element (μ h_t, λ h_t) at its own thickness h_t (N/m); all equal to
    /// (`mu_h`, `lambda_h`) for a uniform skin.
    pub element_lame: Vec<(f64, f64)>,
    /// The constitutive law.
    pub law: MembraneLaw,
    n_dofs: usize,
    /// Elements grouped by shared vertices, for [`Self::hessian_scatter_into`] (made at the
    /// first call; the elements' vertices do not change after construction).
    colouring: std::sync::OnceLock<Colouring>,
}

/// Rest data for the triangle `p`, or `None` if it has (numerically) zero area.
pub fn membrane_rest(v: [usize; 3], p: [Vector3<f64>; 3]) -> Option<MembraneElement> {
    let e1 = p[1] - p[0];
    let e2 = p[2] - p[0];
    let n = e1.cross(&e2);
    let area = 0.5 * n.norm();
    let scale = e1.norm_squared().max(e2.norm_squared());
    if area.is_nan() || area <= 1e-14 * scale || !area.is_finite() {
        return None;
    }
    let t1 = e1.normalize();
    let t2 = n.normalize().cross(&t1);
    // Dm columns are the rest edges in 2D.
    let (a, b, c, d) = (e1.dot(&t1), e2.dot(&t1), e1.dot(&t2), e2.dot(&t2));
    let det = a * d - b * c;
    let inv = [[d / det, -b / det], [-c / det, a / det]];
    let b1 = inv[0];
    let b2 = inv[1];
    let b0 = [-b1[0] - b2[0], -b1[1] - b2[1]];
    Some(MembraneElement {
        v,
        b: [b0, b1, b2],
        area,
    })
}

/// The membrane's constitutive law (see the module notes).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum MembraneLaw {
    /// Saint Venant–Kirchhoff (Green strain): softens beyond 42 % compression.
    StVenantKirchhoff,
    /// Biot strain (corotated linear): stable in compression (the default).
    #[default]
    Biot,
}

type S2 = [[f64; 2]; 2];

/// √det C is floored at this fraction of tr C (a triangle flattened to a segment), where
/// the Biot law's derivatives in C are singular.
const FLAT: f64 = 1e-12;

impl MembraneLaw {
    /// Energy per rest area W(C) (J/m²) for the right Cauchy–Green tensor `c` and Lamé
    /// parameters times thickness (N/m).
    fn density(self, c: &S2, mu_h: f64, lambda_h: f64) -> f64 {
        match self {
            Self::StVenantKirchhoff => {
                let e = green(c);
                let tr = e[0][0] + e[1][1];
                let ee = e[0][0] * e[0][0] + 2.0 * e[0][1] * e[0][1] + e[1][1] * e[1][1];
                mu_h * ee + 0.5 * lambda_h * tr * tr
            }
            Self::Biot => {
                let b = Biot::at(c);
                mu_h * (c[0][0] + c[1][1] - 2.0 * b.tau + 2.0)
                    + 0.5 * lambda_h * (b.tau - 2.0).powi(2)
            }
        }
    }

    /// Second Piola–Kirchhoff stress S = 2 ∂W/∂C (N/m).
    fn stress(self, c: &S2, mu_h: f64, lambda_h: f64) -> S2 {
        match self {
            Self::StVenantKirchhoff => {
                let e = green(c);
                let tr = e[0][0] + e[1][1];
                [
                    [2.0 * mu_h * e[0][0] + lambda_h * tr, 2.0 * mu_h * e[0][1]],
                    [2.0 * mu_h * e[1][0], 2.0 * mu_h * e[1][1] + lambda_h * tr],
                ]
            }
            Self::Biot => {
                let b = Biot::at(c);
                let k = 2.0 * lambda_h * (b.tau - 2.0) - 4.0 * mu_h;
                std::array::from_fn(|i| {
                    std::array::from_fn(|j| k * b.t[i][j] + if i == j { 2.0 * mu_h } else { 0.0 })
                })
            }
        }
    }

    /// The change dS of the stress for a change `dc` of C (N/m).
    fn stress_change(self, c: &S2, dc: &S2, mu_h: f64, lambda_h: f64) -> S2 {
        match self {
            Self::StVenantKirchhoff => {
                let de = dc.map(|r| r.map(|v| 0.5 * v));
                let dtr = de[0][0] + de[1][1];
                [
                    [
                        2.0 * mu_h * de[0][0] + lambda_h * dtr,
                        2.0 * mu_h * de[0][1],
                    ],
                    [
                        2.0 * mu_h * de[1][0],
                        2.0 * mu_h * de[1][1] + lambda_h * dtr,
                    ],
                ]
            }
            Self::Biot => {
                let b = Biot::at(c);
                let ddot = |a: &S2, m: &S2| {
                    (0..2)
                        .flat_map(|i| (0..2).map(move |j| a[i][j] * m[i][j]))
                        .sum::<f64>()
                };
                let dtau = ddot(&b.t, dc);
                let dr = 0.5 * b.r * ddot(&b.inv, dc);
                // d(C⁻¹) = −C⁻¹ dC C⁻¹.
                let cdc: S2 = std::array::from_fn(|i| {
                    std::array::from_fn(|j| (0..2).map(|k| b.inv[i][k] * dc[k][j]).sum())
                });
                let dinv: S2 = std::array::from_fn(|i| {
                    std::array::from_fn(|j| -(0..2).map(|k| cdc[i][k] * b.inv[k][j]).sum::<f64>())
                });
                let k = 2.0 * lambda_h * (b.tau - 2.0) - 4.0 * mu_h;
                std::array::from_fn(|i| {
                    std::array::from_fn(|j| {
                        let dt = -dtau / b.tau * b.t[i][j]
                            + (dr * b.inv[i][j] + b.r * dinv[i][j]) / (2.0 * b.tau);
                        k * dt + 2.0 * lambda_h * dtau * b.t[i][j]
                    })
                })
            }
        }
    }
}

/// The Green strain E = ½ (C − I).
fn green(c: &S2) -> S2 {
    [
        [0.5 * (c[0][0] - 1.0), 0.5 * c[0][1]],
        [0.5 * c[1][0], 0.5 * (c[1][1] - 1.0)],
    ]
}

/// The Biot law's quantities at C: r = √det C (floored), C⁻¹, τ = √(tr C + 2r) and
/// T = ∂τ/∂C = (I + r C⁻¹) / (2τ).
struct Biot {
    r: f64,
    inv: S2,
    tau: f64,
    t: S2,
}

impl Biot {
    fn at(c: &S2) -> Self {
        let tr = c[0][0] + c[1][1];
        let det = (c[0][0] * c[1][1] - c[0][1] * c[1][0]).max((FLAT * tr).powi(2));
        let r = det.sqrt();
        let inv = [
            [c[1][1] / det, -c[0][1] / det],
            [-c[1][0] / det, c[0][0] / det],
        ];
        let tau = (tr + 2.0 * r).sqrt();
        let t = std::array::from_fn(|i| {
            std::array::from_fn(|j| (if i == j { 1.0 } else { 0.0 } + r * inv[i][j]) / (2.0 * tau))
        });
        Self { r, inv, tau, t }
    }
}

/// Energy (J) of one element at positions `x` under `law`; adds the 9-vector gradient and
/// fills the row-major 9 × 9 Hessian when asked.
pub fn membrane_element(
    el: &MembraneElement,
    x: [[f64; 3]; 3],
    (law, mu_h, lambda_h): (MembraneLaw, f64, f64),
    grad: Option<&mut [f64; 9]>,
    hess: Option<&mut [f64; 81]>,
) -> f64 {
    let b = &el.b;
    // F[c][a]
    let mut f = [[0.0; 2]; 3];
    for i in 0..3 {
        for c in 0..3 {
            for a in 0..2 {
                f[c][a] += x[i][c] * b[i][a];
            }
        }
    }
    // C = FᵀF
    let mut cg = [[0.0; 2]; 2];
    for a in 0..2 {
        for bb in 0..2 {
            cg[a][bb] = (0..3).map(|c| f[c][a] * f[c][bb]).sum();
        }
    }
    let energy = el.area * law.density(&cg, mu_h, lambda_h);
    if grad.is_none() && hess.is_none() {
        return energy;
    }
    let s = law.stress(&cg, mu_h, lambda_h);
    if let Some(g) = grad {
        // P = F S; grad_i = A P b_i
        let mut p = [[0.0; 2]; 3];
        for c in 0..3 {
            for a in 0..2 {
                p[c][a] = f[c][0] * s[0][a] + f[c][1] * s[1][a];
            }
        }
        for i in 0..3 {
            for c in 0..3 {
                g[3 * i + c] += el.area * (p[c][0] * b[i][0] + p[c][1] * b[i][1]);
            }
        }
    }
    if let Some(h) = hess {
        // S b_i
        let sb: [[f64; 2]; 3] = std::array::from_fn(|i| {
            [
                s[0][0] * b[i][0] + s[0][1] * b[i][1],
                s[1][0] * b[i][0] + s[1][1] * b[i][1],
            ]
        });
        for j in 0..3 {
            for d in 0..3 {
                let fd = f[d];
                // δC = b_j f_dᵀ + f_d b_jᵀ
                let dc = [
                    [2.0 * b[j][0] * fd[0], b[j][0] * fd[1] + fd[0] * b[j][1]],
                    [b[j][1] * fd[0] + fd[1] * b[j][0], 2.0 * b[j][1] * fd[1]],
                ];
                let ds = law.stress_change(&cg, &dc, mu_h, lambda_h);
                let col = 3 * j + d;
                for i in 0..3 {
                    let dsb = [
                        ds[0][0] * b[i][0] + ds[0][1] * b[i][1],
                        ds[1][0] * b[i][0] + ds[1][1] * b[i][1],
                    ];
                    let geo = b[j][0] * sb[i][0] + b[j][1] * sb[i][1];
                    for c in 0..3 {
                        let mut v = f[c][0] * dsb[0] + f[c][1] * dsb[1];
                        if c == d {
                            v += geo;
                        }
                        h[(3 * i + c) * 9 + col] = el.area * v;
                    }
                }
            }
        }
    }
    energy
}

impl MembraneEnergy {
    /// Membrane of `rest` with `material` (uniform thickness). Fails on a degenerate triangle
    /// (names it).
    pub fn new(rest: &TriMesh, material: &ShellMaterial) -> anyhow::Result<Self> {
        let h = vec![material.thickness; rest.triangles.len()];
        Self::with_thickness(rest, material, &h)
    }

    /// Membrane of `rest` with `material`, triangle t of thickness `thickness[t]` (m; the
    /// material's own thickness is then only the reference for `mu_h`, `lambda_h`). Fails on
    /// a degenerate triangle, a thickness list of the wrong length, or a thickness that is not
    /// a positive finite number of metres (names the triangle).
    pub fn with_thickness(
        rest: &TriMesh,
        material: &ShellMaterial,
        thickness: &[f64],
    ) -> anyhow::Result<Self> {
        material.validate()?;
        check_thickness(thickness, rest.triangles.len())?;
        let (mu_h, lambda_h) = material.lame_times_thickness();
        let element_lame = thickness
            .iter()
            .map(|&h| {
                ShellMaterial {
                    thickness: h,
                    ..*material
                }
                .lame_times_thickness()
            })
            .collect();
        let mut elements = Vec::with_capacity(rest.triangles.len());
        for (t, &v) in rest.triangles.iter().enumerate() {
            let p = v.map(|i| rest.positions[i]);
            let el = membrane_rest(v, p).ok_or_else(|| {
                anyhow::anyhow!(
                    "triangle {t} (vertices {v:?}) has zero rest area; remove or remesh it \
                     (see mesh::quality::check)"
                )
            })?;
            elements.push(el);
        }
        Ok(Self {
            elements,
            mu_h,
            lambda_h,
            element_lame,
            law: MembraneLaw::default(),
            n_dofs: 3 * rest.positions.len(),
            colouring: std::sync::OnceLock::new(),
        })
    }

    /// The elements of which `keep` (given an element's vertices) says yes, with their
    /// stiffness and law: the membrane of that part of the skin, over the same dofs.
    pub fn part(&self, keep: impl Fn(&[usize]) -> bool) -> Self {
        let (elements, element_lame) = self
            .elements
            .iter()
            .zip(&self.element_lame)
            .filter(|(el, _)| keep(&el.v))
            .map(|(el, lame)| (*el, *lame))
            .unzip();
        Self {
            elements,
            element_lame,
            colouring: std::sync::OnceLock::new(),
            ..*self
        }
    }

    /// Number of Hessian triplets emitted per evaluation.
    pub fn triplet_count(&self) -> usize {
        81 * self.elements.len()
    }

    /// [`Energy::hessian_scatter`] of the membrane: element Hessians at `x` (J/m², projected
    /// to PSD when `project` is set) added into `out` by the slot map `slot` (one slot per
    /// triplet, [`Self::triplet_count`] of them), in parallel by colours ([`super::scatter`]).
    pub fn hessian_scatter_into(&self, x: &[f64], slot: &[u32], out: &mut [f64], project: bool) {
        let colouring = self
            .colouring
            .get_or_init(|| Colouring::greedy(self.elements.iter().map(|el| el.v)));
        let law = self.law;
        scatter_element_hessians(out, slot, 9, project, colouring, |i, h| {
            let (el, (mu_h, lambda_h)) = (&self.elements[i], self.element_lame[i]);
            let h: &mut [f64; 81] = h.try_into().expect("81 values per element");
            membrane_element(el, gather3(x, el.v), (law, mu_h, lambda_h), None, Some(h));
        });
    }

    /// The Hessian values of [`Energy::eval`]'s triplets at `x` (J/m²), in their order,
    /// written into `values` (exactly [`Self::triplet_count`] long); element Hessians are
    /// projected to PSD when `project` is set.
    pub fn hessian_values_into(&self, x: &[f64], values: &mut [f64], project: bool) {
        assert_eq!(
            values.len(),
            self.triplet_count(),
            "Hessian value buffer size"
        );
        let law = self.law;
        element_hessians(values, 9, project, |i, h| {
            let (el, (mu_h, lambda_h)) = (&self.elements[i], self.element_lame[i]);
            let h: &mut [f64; 81] = h.try_into().expect("81 values per element");
            membrane_element(el, gather3(x, el.v), (law, mu_h, lambda_h), None, Some(h));
        });
    }
}

/// Check a per-triangle thickness list (m): one positive finite value per triangle.
pub fn check_thickness(thickness: &[f64], triangles: usize) -> anyhow::Result<()> {
    if thickness.len() != triangles {
        anyhow::bail!(
            "skin thickness: {} per-triangle values for {triangles} triangles",
            thickness.len()
        );
    }
    if let Some((t, h)) = thickness
        .iter()
        .enumerate()
        .find(|(_, h)| !(h.is_finite() && **h > 0.0))
    {
        anyhow::bail!(
            "skin thickness of triangle {t} is {h}; it must be a positive number of metres"
        );
    }
    Ok(())
}

fn gather3(x: &[f64], v: [usize; 3]) -> [[f64; 3]; 3] {
    v.map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
}

impl Energy for MembraneEnergy {
    fn dofs(&self) -> usize {
        self.n_dofs
    }

    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        project: bool,
    ) -> f64 {
        let want_g = grad.is_some();
        let ne = self.elements.len();
        let law = self.law;
        let mut hbuf: Option<&mut [(usize, usize, f64)]> = None;
        if let Some(h) = hess {
            let start = h.len();
            h.resize(start + 81 * ne, (0, 0, 0.0));
            hbuf = Some(&mut h[start..]);
        }
        let mut gbuf = if want_g {
            vec![[0.0; 9]; ne]
        } else {
            Vec::new()
        };
        let energy: f64 = match (hbuf, want_g) {
            (Some(hb), _) => {
                let gchunks: Vec<Option<&mut [f64; 9]>> = if want_g {
                    gbuf.iter_mut().map(Some).collect()
                } else {
                    (0..ne).map(|_| None).collect()
                };
                hb.par_chunks_mut(81)
                    .zip(gchunks.into_par_iter())
                    .zip(self.elements.par_iter().zip(self.element_lame.par_iter()))
                    .map(|((tr, g), (el, &(mu_h, lambda_h)))| {
                        let mut he = [0.0; 81];
                        let e = membrane_element(
                            el,
                            gather3(x, el.v),
                            (law, mu_h, lambda_h),
                            g,
                            Some(&mut he),
                        );
                        if project {
                            project_psd(&mut he, 9);
                        }
                        for r in 0..9 {
                            for c in 0..9 {
                                tr[r * 9 + c] = (
                                    3 * el.v[r / 3] + r % 3,
                                    3 * el.v[c / 3] + c % 3,
                                    he[r * 9 + c],
                                );
                            }
                        }
                        e
                    })
                    .collect::<Vec<f64>>()
                    .iter()
                    .sum::<f64>()
            }
            (None, true) => gbuf
                .par_iter_mut()
                .zip(self.elements.par_iter().zip(self.element_lame.par_iter()))
                .map(|(g, (el, &(mu_h, lambda_h)))| {
                    membrane_element(el, gather3(x, el.v), (law, mu_h, lambda_h), Some(g), None)
                })
                .collect::<Vec<f64>>()
                .iter()
                .sum::<f64>(),
            (None, false) => self
                .elements
                .par_iter()
                .zip(self.element_lame.par_iter())
                .map(|(el, &(mu_h, lambda_h))| {
                    membrane_element(el, gather3(x, el.v), (law, mu_h, lambda_h), None, None)
                })
                .collect::<Vec<f64>>()
                .iter()
                .sum::<f64>(),
        };
        if let Some(g) = grad {
            for (el, ge) in self.elements.iter().zip(&gbuf) {
                for (k, &vi) in el.v.iter().enumerate() {
                    for c in 0..3 {
                        g[3 * vi + c] += ge[3 * k + c];
                    }
                }
            }
        }
        energy
    }

    fn hessian_values(&self, x: &[f64], values: &mut Vec<f64>, project: bool) {
        values.resize(self.triplet_count(), 0.0);
        self.hessian_values_into(x, values, project);
    }
}
