//! Hinge bending energy (discrete shells, Grinspun et al. 2003).
//!
//! Per interior edge e with dihedral angle θ (signed, from atan2) and rest angle θ̄:
//! W_e = (D/2) ‖ē‖² / Ā_e · (θ − θ̄)², with ‖ē‖ the rest edge length, Ā_e the rest area of
//! the two triangles and D = E h³ / (12 (1 − ν²)) the bending rigidity (N·m). With the hinge
//! area A_e = Ā_e / 3 this is (D/6) ‖ē‖² θ² / A_e.
//!
//! Calibration of the constant 1/2: a flat regular equilateral mesh bent isometrically onto a
//! cylinder of radius R stores D/(2R²) per unit hinge area for every orientation of the
//! cylinder axis; `tests/shell_energy.rs` measures 0.9964 D/(2R²) at a/R = 1/80, the error
//! halving with each refinement. (A naive estimate with triangle normals at the centroids
//! gives a constant twice as large; it ignores the transverse tilt of the linear interpolant.)
//! Hinge energies depend on the mesh: on meshes far from equilateral the calibration is only
//! approximate, so the skin should be meshed with near-equilateral triangles.
//!
//! Varying thickness ([`BendingEnergy::with_thickness`]): each hinge takes the rigidity
//! D_e = (A₁ D(h₁) + A₂ D(h₂)) / (A₁ + A₂), the area-weighted mean of D over its two
//! triangles, i.e. a mean of h³ (not of h, then cubed). Why: the hinge energy stands for
//! ∫ ½ D κ² dA over its share of the two triangles (a third of each), with the curvature κ
//! taken constant over that region (the discrete-shells assumption); an integral of an
//! energy density is additive over the two halves, so the rigidities add weighted by area.
//! Cubing the mean thickness would understate the thicker side ((h₁+h₂)/2)³ <
//! (h₁³+h₂³)/2. (Only hinges that straddle a thickness step are affected; when a moment,
//! not a curvature, is what crosses the step, the halves act in series and the harmonic mean
//! would be exact; that difference is confined to that one row of hinges.) When both faces
//! have the same thickness, D_e is that face's D exactly, so a uniform skin gives
//! bit-identical values to [`BendingEnergy::new`].
//!
//! The gradient of θ is the classical closed form (Bridson et al. 2003, Grinspun et al.);
//! the Hessian of θ is its exact derivative computed by forward-mode dual numbers on that
//! closed form (12 directional passes), which the finite-difference tests check.

use super::material::ShellMaterial;
use super::psd::{element_hessians, project_psd};
use super::scatter::{scatter_element_hessians, Colouring};
use crate::math::Energy;
use crate::mesh::topology::Topology;
use crate::mesh::TriMesh;
use rayon::prelude::*;
use std::ops::{Add, Div, Mul, Neg, Sub};

/// Scalar for the hinge kernel: f64, or a forward-mode dual number for second derivatives.
pub trait Scalar:
    Copy
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// A constant.
    fn cst(v: f64) -> Self;
    /// Square root.
    fn sqrt(self) -> Self;
    /// Two-argument arctangent atan2(self, x).
    fn atan2(self, x: Self) -> Self;
}

impl Scalar for f64 {
    fn cst(v: f64) -> Self {
        v
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
}

/// Forward-mode dual number v + d ε (ε² = 0): carries one directional derivative.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Dual {
    /// Value.
    pub v: f64,
    /// Directional derivative.
    pub d: f64,
}

impl Add for Dual {
    type Output = Dual;
    fn add(self, o: Dual) -> Dual {
        Dual {
            v: self.v + o.v,
            d: self.d + o.d,
        }
    }
}
impl Sub for Dual {
    type Output = Dual;
    fn sub(self, o: Dual) -> Dual {
        Dual {
            v: self.v - o.v,
            d: self.d - o.d,
        }
    }
}
impl Mul for Dual {
    type Output = Dual;
    fn mul(self, o: Dual) -> Dual {
        Dual {
            v: self.v * o.v,
            d: self.d * o.v + self.v * o.d,
        }
    }
}
impl Div for Dual {
    type Output = Dual;
    fn div(self, o: Dual) -> Dual {
        let q = self.v / o.v;
        Dual {
            v: q,
            d: (self.d - q * o.d) / o.v,
        }
    }
}
impl Neg for Dual {
    type Output = Dual;
    fn neg(self) -> Dual {
        Dual {
            v: -self.v,
            d: -self.d,
        }
    }
}
impl Scalar for Dual {
    fn cst(v: f64) -> Self {
        Dual { v, d: 0.0 }
    }
    fn sqrt(self) -> Self {
        let s = self.v.sqrt();
        Dual {
            v: s,
            d: self.d / (2.0 * s),
        }
    }
    fn atan2(self, x: Self) -> Self {
        let r2 = x.v * x.v + self.v * self.v;
        Dual {
            v: self.v.atan2(x.v),
            d: (x.v * self.d - self.v * x.d) / r2,
        }
    }
}

type V<T> = [T; 3];

fn sub<T: Scalar>(a: V<T>, b: V<T>) -> V<T> {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}
fn dot<T: Scalar>(a: V<T>, b: V<T>) -> T {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}
fn cross<T: Scalar>(a: V<T>, b: V<T>) -> V<T> {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
fn scale<T: Scalar>(s: T, a: V<T>) -> V<T> {
    [s * a[0], s * a[1], s * a[2]]
}

/// Signed dihedral angle θ (rad) of the hinge `x = [edge start, edge end, opposite A,
/// opposite B]` (0 when flat, positive when the hinge folds towards triangle A's normal...
/// any consistent sign works for (θ − θ̄)²) and its gradient with respect to the 12
/// coordinates.
pub fn hinge_angle<T: Scalar>(x: [V<T>; 4]) -> (T, [V<T>; 4]) {
    let e = sub(x[1], x[0]);
    let a = sub(x[2], x[0]);
    let b = sub(x[3], x[0]);
    let na = cross(e, a);
    let nb = cross(b, e);
    let e2 = dot(e, e);
    let el = e2.sqrt();
    let y = dot(cross(na, nb), e) / el;
    let xx = dot(na, nb);
    let theta = y.atan2(xx);
    let na2 = dot(na, na);
    let nb2 = dot(nb, nb);
    let g2 = scale(-el / na2, na);
    let g3 = scale(-el / nb2, nb);
    let aa = dot(a, e) / e2;
    let ab = dot(b, e) / e2;
    let one = T::cst(1.0);
    let g0: V<T> = std::array::from_fn(|c| -(one - aa) * g2[c] - (one - ab) * g3[c]);
    let g1: V<T> = std::array::from_fn(|c| -aa * g2[c] - ab * g3[c]);
    (theta, [g0, g1, g2, g3])
}

/// Hessian (row-major 12 × 12) of the hinge angle, exact, by 12 dual-number passes.
pub fn hinge_angle_hessian(x: [[f64; 3]; 4]) -> [f64; 144] {
    let mut h = [0.0; 144];
    for k in 0..12 {
        let xd: [V<Dual>; 4] = std::array::from_fn(|i| {
            std::array::from_fn(|c| Dual {
                v: x[i][c],
                d: if 3 * i + c == k { 1.0 } else { 0.0 },
            })
        });
        let (_, g) = hinge_angle(xd);
        for i in 0..4 {
            for c in 0..3 {
                h[(3 * i + c) * 12 + k] = g[i][c].d;
            }
        }
    }
    for r in 0..12 {
        for c in 0..r {
            let s = 0.5 * (h[r * 12 + c] + h[c * 12 + r]);
            h[r * 12 + c] = s;
            h[c * 12 + r] = s;
        }
    }
    h
}

/// Rest data of one hinge.
#[derive(Debug, Clone, Copy)]
pub struct HingeElement {
    /// `[edge start, edge end, opposite A, opposite B]`.
    pub v: [usize; 4],
    /// Stiffness k = D ‖ē‖² / Ā_e (J/rad²).
    pub k: f64,
    /// Rest dihedral angle θ̄ (rad).
    pub rest_angle: f64,
}

/// The fold θ − θ̄ (rad) taken into (−π, π]: θ from `atan2` jumps by 2π where a hinge
/// passes through the fully folded state θ = ±π, and measured from the rest angle the jump
/// moves to a fold of π away from rest, so the energy stays continuous (and smooth) through
/// θ = ±π for any rest angle.
pub fn angle_change(theta: f64, rest: f64) -> f64 {
    let d = theta - rest;
    if d > std::f64::consts::PI {
        d - 2.0 * std::f64::consts::PI
    } else if d <= -std::f64::consts::PI {
        d + 2.0 * std::f64::consts::PI
    } else {
        d
    }
}

/// Energy (J) of one hinge; adds the 12-gradient and fills the 12 × 12 Hessian when asked.
pub fn hinge_element(
    el: &HingeElement,
    x: [[f64; 3]; 4],
    grad: Option<&mut [f64; 12]>,
    hess: Option<&mut [f64; 144]>,
) -> f64 {
    let (theta, g) = hinge_angle(x);
    let dth = angle_change(theta, el.rest_angle);
    let energy = el.k * dth * dth;
    if let Some(gr) = grad {
        for i in 0..4 {
            for c in 0..3 {
                gr[3 * i + c] += 2.0 * el.k * dth * g[i][c];
            }
        }
    }
    if let Some(h) = hess {
        let hth = hinge_angle_hessian(x);
        let gf: [f64; 12] = std::array::from_fn(|k| g[k / 3][k % 3]);
        for r in 0..12 {
            for c in 0..12 {
                h[r * 12 + c] = 2.0 * el.k * (gf[r] * gf[c] + dth * hth[r * 12 + c]);
            }
        }
    }
    energy
}

/// The hinge bending energy of a triangle mesh (J), over flat positions (m).
#[derive(Debug, Clone)]
pub struct BendingEnergy {
    /// Hinges with their rest data.
    pub hinges: Vec<HingeElement>,
    /// Bending rigidity D (N·m) at the material's reference thickness.
    pub rigidity: f64,
    n_dofs: usize,
    /// Hinges grouped by shared vertices, for [`Self::hessian_scatter_into`] (made at the
    /// first call; the hinges' vertices do not change after construction).
    colouring: std::sync::OnceLock<Colouring>,
}

impl BendingEnergy {
    /// Bending of `rest` (rest angles from its shape) with `material` (uniform thickness).
    pub fn new(rest: &TriMesh, topo: &Topology, material: &ShellMaterial) -> anyhow::Result<Self> {
        let h = vec![material.thickness; rest.triangles.len()];
        Self::with_thickness(rest, topo, material, &h)
    }

    /// Bending of `rest` with `material`, triangle t of thickness `thickness[t]` (m); each
    /// hinge uses the area-weighted mean of D = E h³ / (12 (1 − ν²)) of its two triangles
    /// (module notes). Fails on a thickness list of the wrong length or a non-positive value.
    pub fn with_thickness(
        rest: &TriMesh,
        topo: &Topology,
        material: &ShellMaterial,
        thickness: &[f64],
    ) -> anyhow::Result<Self> {
        material.validate()?;
        super::membrane::check_thickness(thickness, rest.triangles.len())?;
        let d = material.bending_rigidity();
        let face_d: Vec<f64> = thickness
            .iter()
            .map(|&h| {
                ShellMaterial {
                    thickness: h,
                    ..*material
                }
                .bending_rigidity()
            })
            .collect();
        let p = &rest.positions;
        let mut hinges = Vec::with_capacity(topo.hinges.len());
        for h in &topo.hinges {
            let (a0, a1) = (rest.triangle_area(h.tris[0]), rest.triangle_area(h.tris[1]));
            let area = a0 + a1;
            let el2 = (p[h.v[1]] - p[h.v[0]]).norm_squared();
            if area.is_nan() || area <= 0.0 {
                anyhow::bail!(
                    "hinge on edge {:?} has zero rest area; remesh it",
                    [h.v[0], h.v[1]]
                );
            }
            let xs = h.v.map(|i| [p[i].x, p[i].y, p[i].z]);
            let (theta, _) = hinge_angle(xs);
            let (d0, d1) = (face_d[h.tris[0]], face_d[h.tris[1]]);
            let de = if d0 == d1 {
                d0
            } else {
                (a0 * d0 + a1 * d1) / area
            };
            hinges.push(HingeElement {
                v: h.v,
                k: 0.5 * de * el2 / area,
                rest_angle: theta,
            });
        }
        Ok(Self {
            hinges,
            rigidity: d,
            n_dofs: 3 * p.len(),
            colouring: std::sync::OnceLock::new(),
        })
    }

    /// The hinges of which `keep` (given a hinge's four vertices) says yes: the bending of
    /// that part of the skin, over the same dofs.
    pub fn part(&self, keep: impl Fn(&[usize]) -> bool) -> Self {
        Self {
            hinges: self.hinges.iter().filter(|h| keep(&h.v)).copied().collect(),
            colouring: std::sync::OnceLock::new(),
            ..*self
        }
    }

    /// Number of Hessian triplets emitted per evaluation.
    pub fn triplet_count(&self) -> usize {
        144 * self.hinges.len()
    }

    /// [`Energy::hessian_scatter`] of the hinges: hinge Hessians at `x` (J/m², projected
    /// to PSD when `project` is set) added into `out` by the slot map `slot` (one slot per
    /// triplet, [`Self::triplet_count`] of them), in parallel by colours ([`super::scatter`]).
    pub fn hessian_scatter_into(&self, x: &[f64], slot: &[u32], out: &mut [f64], project: bool) {
        let colouring = self
            .colouring
            .get_or_init(|| Colouring::greedy(self.hinges.iter().map(|el| el.v)));
        scatter_element_hessians(out, slot, 12, project, colouring, |i, h| {
            let el = &self.hinges[i];
            let h: &mut [f64; 144] = h.try_into().expect("144 values per hinge");
            hinge_element(el, gather4(x, el.v), None, Some(h));
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
        element_hessians(values, 12, project, |i, h| {
            let el = &self.hinges[i];
            let h: &mut [f64; 144] = h.try_into().expect("144 values per hinge");
            hinge_element(el, gather4(x, el.v), None, Some(h));
        });
    }
}

fn gather4(x: &[f64], v: [usize; 4]) -> [[f64; 3]; 4] {
    v.map(|i| [x[3 * i], x[3 * i + 1], x[3 * i + 2]])
}

impl Energy for BendingEnergy {
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
        let ne = self.hinges.len();
        let mut gbuf = if want_g {
            vec![[0.0; 12]; ne]
        } else {
            Vec::new()
        };
        let energy: f64 = if let Some(h) = hess {
            let start = h.len();
            h.resize(start + 144 * ne, (0, 0, 0.0));
            let gchunks: Vec<Option<&mut [f64; 12]>> = if want_g {
                gbuf.iter_mut().map(Some).collect()
            } else {
                (0..ne).map(|_| None).collect()
            };
            h[start..]
                .par_chunks_mut(144)
                .zip(gchunks.into_par_iter())
                .zip(self.hinges.par_iter())
                .map(|((tr, g), el)| {
                    let mut he = [0.0; 144];
                    let e = hinge_element(el, gather4(x, el.v), g, Some(&mut he));
                    if project {
                        project_psd(&mut he, 12);
                    }
                    for r in 0..12 {
                        for c in 0..12 {
                            tr[r * 12 + c] = (
                                3 * el.v[r / 3] + r % 3,
                                3 * el.v[c / 3] + c % 3,
                                he[r * 12 + c],
                            );
                        }
                    }
                    e
                })
                .collect::<Vec<f64>>()
                .iter()
                .sum::<f64>()
        } else if want_g {
            gbuf.par_iter_mut()
                .zip(self.hinges.par_iter())
                .map(|(g, el)| hinge_element(el, gather4(x, el.v), Some(g), None))
                .collect::<Vec<f64>>()
                .iter()
                .sum::<f64>()
        } else {
            self.hinges
                .par_iter()
                .map(|el| hinge_element(el, gather4(x, el.v), None, None))
                .collect::<Vec<f64>>()
                .iter()
                .sum::<f64>()
        };
        if let Some(g) = grad {
            for (el, ge) in self.hinges.iter().zip(&gbuf) {
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A hinge with a sharp rest fold (θ̄ = 3 rad) bent through θ = ±π, where atan2 jumps
    /// by 2π: the energy is continuous there (k (π − 3)² from both sides) and its gradient
    /// matches finite differences across the jump.
    #[test]
    fn hinge_energy_is_continuous_through_the_folded_state() {
        let el = HingeElement {
            v: [0, 1, 2, 3],
            k: 2.0,
            rest_angle: 3.0,
        };
        // Edge along x; wing A in the xy half-plane y > 0; wing B at angle φ from −y.
        let hinge = |phi: f64| {
            [
                [0.0, 0.0, 0.0],
                [1.0, 0.0, 0.0],
                [0.4, 1.0, 0.0],
                [0.6, -phi.cos(), phi.sin()],
            ]
        };
        let angle = |phi: f64| hinge_angle(hinge(phi)).0;
        // φ = π puts wing B onto wing A: fully folded. Find the sides of the atan2 jump.
        let (a, b) = (std::f64::consts::PI - 1e-3, std::f64::consts::PI + 1e-3);
        assert!(
            (angle(a) - angle(b)).abs() > 6.0,
            "the test must cross the atan2 jump: {} {}",
            angle(a),
            angle(b)
        );
        let (ea, eb) = (
            hinge_element(&el, hinge(a), None, None),
            hinge_element(&el, hinge(b), None, None),
        );
        let want = 2.0 * (std::f64::consts::PI - 3.0).powi(2);
        assert!(
            (ea - want).abs() < 1e-2 && (eb - want).abs() < 1e-2,
            "{ea} {eb} {want}"
        );
        // dE/dφ by finite differences across the jump against the chain rule.
        let h = 1e-6;
        let phi = std::f64::consts::PI + 2e-7;
        let num = (hinge_element(&el, hinge(phi + h), None, None)
            - hinge_element(&el, hinge(phi - h), None, None))
            / (2.0 * h);
        let mut g = [0.0; 12];
        hinge_element(&el, hinge(phi), Some(&mut g), None);
        let dx3 = [0.0, phi.sin(), phi.cos()];
        let ana: f64 = (0..3).map(|c| g[9 + c] * dx3[c]).sum();
        assert!(
            (num - ana).abs() < 1e-5 * ana.abs().max(1.0),
            "{num} vs {ana}"
        );
    }

    #[test]
    fn hinge_angle_gradient_matches_finite_differences() {
        let x = [
            [0.0, 0.0, 0.0],
            [1.0, 0.1, 0.0],
            [0.3, 0.9, 0.2],
            [0.6, -0.8, 0.4],
        ];
        let (_, g) = hinge_angle(x);
        let h = 1e-6;
        for i in 0..4 {
            for c in 0..3 {
                let mut xp = x;
                xp[i][c] += h;
                let mut xm = x;
                xm[i][c] -= h;
                let num = (hinge_angle(xp).0 - hinge_angle(xm).0) / (2.0 * h);
                assert!(
                    (num - g[i][c]).abs() < 1e-7,
                    "{i} {c}: {num} vs {}",
                    g[i][c]
                );
            }
        }
    }
}
