//! The interior energy: corotational linear elasticity on lattice elements, one rotation per
//! element (standard corotational FEM, Müller–Gross warped stiffness).
//!
//! Energy (J) E(q) = Σ_e ½ u_eᵀ K₀ u_e with u_e = R_eᵀ x_e − X_e (element-local, 3K), K₀ the
//! linear-elastic stiffness of the undeformed element (27-point Gauss quadrature, computed
//! once), X_e the rest positions of the element's nodes and R_e the rotation of the
//! deformation gradient at the element centre: its polar rotation, with the reflection moved
//! into the smallest singular value when the centre is inverted (Irving et al. 2004, see
//! [`super::corot::rotation`]). The energy is invariant under rigid motions and equals
//! Σ w ψ(F) of [`super::corot::corotated`] with R frozen at R_e.
//!
//! The gradient is exact, including the derivative of R_e: with f = K₀ u (rotated frame),
//! τ = Σ_a (R_eᵀ x_a) × f_a and S = R_eᵀ F_c, ∂E/∂x_a = R_e f_a − R_e (c × ∇N_a(centre)),
//! c = (tr S · I − S)⁻¹ τ (δR = R \[ω\]×, skew(Rᵀ δF) = \[½ (tr S · I − S) ω\]×). τ is second
//! order in u (K₀ annihilates infinitesimal rotations), so the term is small but kept.
//!
//! Hessian ([`Energy::eval`]): the consistent tangent, R_e K₀ R_eᵀ plus the derivative of
//! the rotation ([`super::tangent`], a correction of rank ≤ 18 per element), exact when
//! `project_psd` is false and with its stress term projected to positive semi-definite when
//! true. [`FrozenInterior`] keeps each rotation fixed; its Hessian is R_e K₀ R_eᵀ alone (the
//! warped stiffness, symmetric positive semi-definite), which converges only linearly under
//! large rotation.

use super::corot::rotation;
use super::tangent::{ElementState, RotationCorrection};
use super::{FemError, Material};
use crate::lattice::basis::gauss27;
use crate::lattice::{shape, ElementOrder, Lattice};
use crate::math::Energy;
use nalgebra::{Matrix3, Vector3};
use rayon::prelude::*;

/// Elements per matrix product K₀ U in the energy evaluation.
const CHUNK: usize = 32;
/// Fixed number of groups of chunks reduced in order (determinism across thread counts).
const GROUPS: usize = 16;

type M3 = Matrix3<f64>;

/// One Gauss point of the reference element.
#[derive(Debug, Clone)]
pub(crate) struct QuadPoint {
    /// Quadrature weight times cell volume (m³).
    pub w: f64,
    /// Shape function values.
    pub n: Vec<f64>,
    /// ∇_X N_a (1/m).
    pub g: Vec<[f64; 3]>,
}

/// Corotated elasticity over the elements of a lattice, as an [`Energy`] over flat node
/// positions (3 × nodes, m).
#[derive(Debug, Clone)]
pub struct Interior {
    /// Shear modulus μ (Pa).
    pub mu: f64,
    /// Lamé's first parameter λ (Pa).
    pub lambda: f64,
    /// Mass density (kg/m³).
    pub density: f64,
    /// Element order.
    pub order: ElementOrder,
    /// Cell edge (m).
    pub cell_size: f64,
    /// Node indices of each element (local order of [`crate::lattice::Element::nodes`]).
    pub elements: Vec<Vec<usize>>,
    /// Number of nodes.
    pub nodes: usize,
    pub(crate) qp: Vec<QuadPoint>,
    center_g: Vec<[f64; 3]>,
    /// Linear-elastic stiffness of one undeformed element, (3K × 3K) row-major, N/m.
    pub(crate) k0: Vec<f64>,
    /// Actuated rest state: per element, the offset d_e of its rest node positions in its own
    /// rotated frame (3K per element, m; empty when the rest state is the lattice's own). See
    /// [`Interior::set_actuation`].
    actuation: Vec<f64>,
    /// Consistent mass of one element, (K × K) row-major, kg.
    pub(crate) m0: Vec<f64>,
    /// Rest positions of the element's nodes relative to its first node (local, 3K, m).
    x_ref: Vec<f64>,
    /// K₀ as 3 × 3 node blocks, block (a, b) at index a·K + b (N/m).
    pub(crate) k0_blocks: Vec<M3>,
}

impl Interior {
    /// The interior of `lattice` made of `material`.
    pub fn new(lattice: &Lattice, material: &Material) -> Result<Self, FemError> {
        material.validate()?;
        let (mu, lambda) = material.lame();
        let order = lattice.order;
        let h = lattice.cell_size;
        let k = order.nodes_per_element();
        let qp: Vec<QuadPoint> = gauss27()
            .into_iter()
            .map(|(xi, w)| {
                let s = shape(order, xi);
                QuadPoint {
                    w: w * h * h * h,
                    n: s.val[..k].to_vec(),
                    g: s.grad[..k].iter().map(|g| g.map(|c| c / h)).collect(),
                }
            })
            .collect();
        let sc = shape(order, [0.5; 3]);
        let center_g = sc.grad[..k].iter().map(|g| g.map(|c| c / h)).collect();
        // K₀_ab = Σ w [μ (g_a·g_b) I + μ g_b g_aᵀ + λ g_a g_bᵀ]; M₀_ab = ρ Σ w N_a N_b.
        let n3 = 3 * k;
        let mut k0 = vec![0.0; n3 * n3];
        let mut m0 = vec![0.0; k * k];
        for q in &qp {
            for a in 0..k {
                for b in 0..k {
                    let (ga, gb) = (q.g[a], q.g[b]);
                    let dot = ga[0] * gb[0] + ga[1] * gb[1] + ga[2] * gb[2];
                    for i in 0..3 {
                        for j in 0..3 {
                            let mut v = mu * gb[i] * ga[j] + lambda * ga[i] * gb[j];
                            if i == j {
                                v += mu * dot;
                            }
                            k0[(3 * a + i) * n3 + 3 * b + j] += q.w * v;
                        }
                    }
                    m0[a * k + b] += material.density * q.w * q.n[a] * q.n[b];
                }
            }
        }
        // Local node (a, b, c) (index a + k·b + k²·c) sits at h·((a, b, c) + offset) in its
        // cell; only differences matter (K₀ annihilates translations).
        let side = if k == 27 { 3 } else { 2 };
        let mut x_ref = vec![0.0; 3 * k];
        for c in 0..side {
            for b in 0..side {
                for a in 0..side {
                    let l = a + side * b + side * side * c;
                    x_ref[3 * l] = h * a as f64;
                    x_ref[3 * l + 1] = h * b as f64;
                    x_ref[3 * l + 2] = h * c as f64;
                }
            }
        }
        let k0_blocks = (0..k * k)
            .map(|ab| {
                let (a, b) = (ab / k, ab % k);
                M3::from_fn(|i, j| k0[(3 * a + i) * n3 + 3 * b + j])
            })
            .collect();
        Ok(Self {
            mu,
            lambda,
            density: material.density,
            order,
            cell_size: h,
            elements: lattice.elements.iter().map(|e| e.nodes.clone()).collect(),
            nodes: lattice.node_count(),
            qp,
            center_g,
            k0,
            m0,
            actuation: Vec::new(),
            x_ref,
            k0_blocks,
        })
    }

    /// Nodes per element.
    pub fn nodes_per_element(&self) -> usize {
        self.order.nodes_per_element()
    }

    /// Actuate the rest state (a muscle's active shape change, Phace-style): element e's
    /// energy becomes ½ (u_e − d_e)ᵀ K₀ (u_e − d_e), u_e = R_eᵀ x_e − X_e, with `offsets`
    /// holding d_e (3K per element, m, in the element's rotated frame, node order of
    /// [`Self::elements`]); empty restores the lattice's own rest state. Positions whose
    /// local displacements are the offsets ([`Self::local_displacements`]) have zero energy
    /// whatever the stiffness: a compatible actuation makes its shape exactly, and the energy
    /// stays invariant under rigid motions.
    pub fn set_actuation(&mut self, offsets: Vec<f64>) -> Result<(), FemError> {
        let want = 3 * self.nodes_per_element() * self.elements.len();
        if !offsets.is_empty() && offsets.len() != want {
            return Err(FemError::Input(format!(
                "actuation has {} offsets, the interior needs {want} (3 per node of each element)",
                offsets.len()
            )));
        }
        if offsets.iter().any(|v| !v.is_finite()) {
            return Err(FemError::Input("an actuation offset is not finite".into()));
        }
        self.actuation = offsets;
        Ok(())
    }

    /// The actuation offsets (m, 3K per element; empty when not actuated).
    pub fn actuation(&self) -> &[f64] {
        &self.actuation
    }

    /// Local displacements u_e = R_e(x)ᵀ (x_a − x_0) − (X_a − X_0) of every element at
    /// positions `x` (flat, m), 3K per element: the actuation whose rest state `x` is.
    pub fn local_displacements(&self, x: &[f64]) -> Vec<f64> {
        let n3 = 3 * self.nodes_per_element();
        let mut out = vec![0.0; n3 * self.elements.len()];
        out.par_chunks_mut(n3).enumerate().for_each(|(e, u)| {
            let mut y = [0.0; 81];
            self.element_frame(x, e, None, &mut y[..n3], u);
        });
        out
    }

    /// Element `e`'s local displacements at positions `x` (flat, m) as a rest state, whatever
    /// the interior's own actuation: u = R(x)ᵀ (x_a − x_0) − (X_a − X_0) (3K, m, into `u`),
    /// and, when `rate` is given, their derivative along node velocities `dx` (flat, m per
    /// unit; into `rate`): R(x)ᵀ (δx_a − δx_0) − \[ω\]× y_a with δR = R \[ω\]×,
    /// ω = 2 (tr S · I − S)⁻¹ axial(skew(Rᵀ δF_c)), S = sym(Rᵀ F_c).
    pub fn element_local_displacements(
        &self,
        x: &[f64],
        e: usize,
        u: &mut [f64],
        rate: Option<(&[f64], &mut [f64])>,
    ) {
        let mut y = [0.0; 81];
        let y = &mut y[..u.len()];
        let (r, fc) = self.element_frame(x, e, None, y, u);
        let (Some((dx, out)), Some(fc)) = (rate, fc) else {
            return;
        };
        let rt = r.transpose();
        let m = rt * self.center_def_grad(dx, e);
        let axial = Vector3::new(
            m[(2, 1)] - m[(1, 2)],
            m[(0, 2)] - m[(2, 0)],
            m[(1, 0)] - m[(0, 1)],
        );
        let s = rt * fc;
        let s = (s + s.transpose()) * 0.5;
        let omega = (M3::identity() * s.trace() - s)
            .try_inverse()
            .map_or_else(Vector3::zeros, |gi| gi * axial);
        let nodes = &self.elements[e];
        let at = |n: usize| Vector3::new(dx[3 * n], dx[3 * n + 1], dx[3 * n + 2]);
        let dx0 = at(nodes[0]);
        for (a, &n) in nodes.iter().enumerate() {
            let ya = Vector3::new(y[3 * a], y[3 * a + 1], y[3 * a + 2]);
            let d = rt * (at(n) - dx0) - omega.cross(&ya);
            out[3 * a..3 * a + 3].copy_from_slice(d.as_slice());
        }
    }

    /// The node force (N, flat over node dofs, added into `force`) of a unit rate of
    /// actuation: −∂/∂s ∇E at `x` when the offsets of elements `elements` grow by s times
    /// `offsets` (3K per listed element, m). Exact, with the derivative of the rotations;
    /// at rest it is Σ_e K₀ d_e.
    pub fn actuation_force(
        &self,
        x: &[f64],
        elements: &[usize],
        offsets: &[f64],
        force: &mut [f64],
    ) {
        let n3 = 3 * self.nodes_per_element();
        for (j, &e) in elements.iter().enumerate() {
            let mut y = [0.0; 81];
            let mut u = [0.0; 81];
            let (r, fc) = self.element_prepare(x, e, None, &mut y[..n3], &mut u[..n3]);
            let mut f = [0.0; 81];
            self.k0_times(&offsets[j * n3..(j + 1) * n3], &mut f[..n3]);
            let mut g = [0.0; 81];
            self.element_finish(
                &r,
                fc.as_ref(),
                &y[..n3],
                &u[..n3],
                &f[..n3],
                Some(&mut g[..n3]),
            );
            for (a, &n) in self.elements[e].iter().enumerate() {
                for i in 0..3 {
                    force[3 * n + i] += g[3 * a + i];
                }
            }
        }
    }

    /// Deformation gradient at the element centre, F_c = Σ_a x_a ∇N_a(centre)ᵀ (no
    /// allocation).
    fn center_def_grad(&self, x: &[f64], e: usize) -> M3 {
        let mut f = M3::zeros();
        for (&n, ga) in self.elements[e].iter().zip(&self.center_g) {
            for i in 0..3 {
                let xi = x[3 * n + i];
                for j in 0..3 {
                    f[(i, j)] += xi * ga[j];
                }
            }
        }
        f
    }

    fn gather(&self, x: &[f64], e: usize) -> Vec<Vector3<f64>> {
        self.elements[e]
            .iter()
            .map(|&n| Vector3::new(x[3 * n], x[3 * n + 1], x[3 * n + 2]))
            .collect()
    }

    fn def_grad(xe: &[Vector3<f64>], g: &[[f64; 3]]) -> M3 {
        let mut f = M3::zeros();
        for (xa, ga) in xe.iter().zip(g) {
            for j in 0..3 {
                f.column_mut(j).axpy(ga[j], xa, 1.0);
            }
        }
        f
    }

    /// Deformation gradients F at the 27 Gauss points of element `e` for positions `x`.
    pub fn deformation_gradients(&self, x: &[f64], e: usize) -> Vec<M3> {
        let xe = self.gather(x, e);
        self.qp.iter().map(|q| Self::def_grad(&xe, &q.g)).collect()
    }

    /// The element rotation R_e (polar rotation of F at the cell centre, reflection removed).
    pub fn element_rotation(&self, x: &[f64], e: usize) -> M3 {
        rotation(&self.center_def_grad(x, e))
    }

    /// Energy (J) of element `e`, adding its gradient (N) into `grad` (local, 3K) when
    /// given. `frozen` replaces the element rotation R_e(x) by a fixed rotation (and drops
    /// the rotation-derivative term of the gradient).
    pub(crate) fn element_energy(
        &self,
        x: &[f64],
        e: usize,
        frozen: Option<&M3>,
        grad: Option<&mut [f64]>,
    ) -> f64 {
        let n3 = 3 * self.elements[e].len();
        let mut y = [0.0; 81];
        let mut u = [0.0; 81];
        let (r, fc) = self.element_prepare(x, e, frozen, &mut y[..n3], &mut u[..n3]);
        let mut f = [0.0; 81];
        self.k0_times(&u[..n3], &mut f[..n3]);
        self.element_finish(&r, fc.as_ref(), &y[..n3], &u[..n3], &f[..n3], grad)
    }

    /// f += K₀ u for one element (N; u in m, 3K each) as a sum of columns (K₀ is
    /// symmetric: column c = row c), which vectorises, unlike row dot products.
    fn k0_times(&self, u: &[f64], f: &mut [f64]) {
        let n3 = u.len();
        for (c, &uc) in u.iter().enumerate() {
            let kc = &self.k0[c * n3..(c + 1) * n3];
            for (fr, kv) in f.iter_mut().zip(kc) {
                *fr += kv * uc;
            }
        }
    }

    /// First half of [`Self::element_energy`]: [`Self::element_frame`], with the actuation's
    /// offsets taken from the displacements (u = y − (X − X_0) − d_e).
    fn element_prepare(
        &self,
        x: &[f64],
        e: usize,
        frozen: Option<&M3>,
        y: &mut [f64],
        u: &mut [f64],
    ) -> (M3, Option<M3>) {
        let frame = self.element_frame(x, e, frozen, y, u);
        if !self.actuation.is_empty() {
            let d = &self.actuation[e * u.len()..(e + 1) * u.len()];
            u.iter_mut().zip(d).for_each(|(ui, di)| *ui -= di);
        }
        frame
    }

    /// The rotation R_e (and the centre deformation gradient F_c unless `frozen`), the
    /// rotated node positions y_a = Rᵀ(x_a − x_0) (m) and the lattice's own local
    /// displacements u = y − (X − X_0) (m), both written into slices of length 3K.
    fn element_frame(
        &self,
        x: &[f64],
        e: usize,
        frozen: Option<&M3>,
        y: &mut [f64],
        u: &mut [f64],
    ) -> (M3, Option<M3>) {
        let nodes = &self.elements[e];
        let (r, fc) = match frozen {
            Some(r) => (*r, None),
            None => {
                let f = self.center_def_grad(x, e);
                (rotation(&f), Some(f))
            }
        };
        let rt = r.transpose();
        let n0 = nodes[0];
        let x0 = Vector3::new(x[3 * n0], x[3 * n0 + 1], x[3 * n0 + 2]);
        for (a, &n) in nodes.iter().enumerate() {
            let ya = rt * (Vector3::new(x[3 * n], x[3 * n + 1], x[3 * n + 2]) - x0);
            for i in 0..3 {
                y[3 * a + i] = ya[i];
                u[3 * a + i] = ya[i] - self.x_ref[3 * a + i];
            }
        }
        (r, fc)
    }

    /// Second half of [`Self::element_energy`]: given f = K₀ u (N), the energy ½ uᵀf (J),
    /// and the gradient (N, local 3K) added into `grad` when given.
    fn element_finish(
        &self,
        r: &M3,
        fc: Option<&M3>,
        y: &[f64],
        u: &[f64],
        f: &[f64],
        grad: Option<&mut [f64]>,
    ) -> f64 {
        let k = y.len() / 3;
        let energy = 0.5 * u.iter().zip(f).map(|(a, b)| a * b).sum::<f64>();
        if let Some(gr) = grad {
            for a in 0..k {
                let fa = r * Vector3::new(f[3 * a], f[3 * a + 1], f[3 * a + 2]);
                for i in 0..3 {
                    gr[3 * a + i] += fa[i];
                }
            }
            if let Some(fc) = fc {
                // Derivative of R_e: −R (c × ∇N_a(centre)), c = (tr S I − S)⁻¹ τ.
                let rt = r.transpose();
                let mut tau = Vector3::zeros();
                for a in 0..k {
                    let ya = Vector3::new(y[3 * a], y[3 * a + 1], y[3 * a + 2]);
                    let fa = Vector3::new(f[3 * a], f[3 * a + 1], f[3 * a + 2]);
                    tau += ya.cross(&fa);
                }
                let s = rt * fc;
                let s = (s + s.transpose()) * 0.5;
                let gm = M3::identity() * s.trace() - s;
                if let Some(c) = gm.try_inverse().map(|gi| gi * tau) {
                    if c.iter().all(|v| v.is_finite()) {
                        for (a, ga) in self.center_g.iter().enumerate() {
                            let d = r * c.cross(&Vector3::new(ga[0], ga[1], ga[2]));
                            for i in 0..3 {
                                gr[3 * a + i] -= d[i];
                            }
                        }
                    }
                }
            }
        }
        energy
    }

    /// The rotation-derivative part of element `e`'s Hessian at `x` (see
    /// [`super::tangent`]): exact, or with its stress term projected to positive
    /// semi-definite when `project`; `None` where the rotation has no derivative.
    pub(crate) fn rotation_correction(
        &self,
        x: &[f64],
        e: usize,
        project: bool,
    ) -> Option<RotationCorrection> {
        let n3 = 3 * self.elements[e].len();
        let mut y = [0.0; 81];
        let mut u = [0.0; 81];
        let (r, fc) = self.element_prepare(x, e, None, &mut y[..n3], &mut u[..n3]);
        let mut f = [0.0; 81];
        self.k0_times(&u[..n3], &mut f[..n3]);
        let state = ElementState {
            r: &r,
            fc: fc.as_ref().expect("not frozen"),
            y: &y[..n3],
            f: &f[..n3],
            k0: &self.k0,
            center_g: &self.center_g,
        };
        RotationCorrection::new(&state, project)
    }

    /// The rotated element stiffness R K₀ Rᵀ (3K × 3K, row-major, N/m).
    pub(crate) fn rotated_stiffness(&self, r: &M3) -> Vec<f64> {
        let k = self.nodes_per_element();
        let n3 = 3 * k;
        let mut out = vec![0.0; n3 * n3];
        for a in 0..k {
            for b in 0..k {
                let blk = M3::from_fn(|i, j| self.k0[(3 * a + i) * n3 + 3 * b + j]);
                let rb = r * blk * r.transpose();
                for i in 0..3 {
                    for j in 0..3 {
                        out[(3 * a + i) * n3 + 3 * b + j] = rb[(i, j)];
                    }
                }
            }
        }
        out
    }

    /// Energy (J) at `x` (flat node positions, m), adding the gradient (N) into `grad`,
    /// and writing each element's rotation R_e(x) into `rotations` (which Newton reuses
    /// for its matrix at the same positions).
    pub(crate) fn eval_with_rotations(
        &self,
        x: &[f64],
        grad: &mut [f64],
        rotations: &mut Vec<M3>,
    ) -> f64 {
        self.eval_chunked(x, None, Some(grad), Some(rotations))
    }

    fn eval_impl(
        &self,
        x: &[f64],
        frozen: Option<&[M3]>,
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        project: bool,
    ) -> f64 {
        match hess {
            None => self.eval_chunked(x, frozen, grad, None),
            Some(h) => self.eval_with_hessian(x, frozen, grad, h, project),
        }
    }

    /// Energy (J) and optionally gradient (N, added into `grad`) and element rotations
    /// (into `rot_out`), element chunk by chunk: per-thread accumulation, no per-element
    /// buffers. Chunks are grouped into at most GROUPS fixed groups whose partial sums are
    /// added in group order: the result does not depend on the thread count.
    fn eval_chunked(
        &self,
        x: &[f64],
        frozen: Option<&[M3]>,
        grad: Option<&mut [f64]>,
        rot_out: Option<&mut Vec<M3>>,
    ) -> f64 {
        let want_g = grad.is_some();
        let len = if want_g { 3 * self.nodes } else { 0 };
        let chunks = self.elements.len().div_ceil(CHUNK);
        let want_rot = rot_out.is_some();
        let per_group = chunks.div_ceil(GROUPS).max(1);
        let partial: Vec<(f64, Vec<f64>, Vec<M3>)> = (0..chunks.div_ceil(per_group))
            .into_par_iter()
            .map(|grp| {
                let range = grp * per_group..((grp + 1) * per_group).min(chunks);
                self.eval_group(x, frozen, range, want_g, want_rot)
            })
            .collect();
        let mut energy = 0.0;
        let mut g = vec![0.0; len];
        if let Some(ro) = rot_out {
            ro.clear();
            for (_, _, r) in &partial {
                ro.extend_from_slice(r);
            }
        }
        for (e, gp, _) in partial {
            energy += e;
            g.iter_mut().zip(&gp).for_each(|(p, q)| *p += q);
        }
        if let Some(gr) = grad {
            gr.iter_mut().zip(&g).for_each(|(p, q)| *p += q);
        }
        energy
    }

    /// Energy, gradient over all node DOFs (empty unless `want_g`) and element rotations
    /// (empty unless `want_rot`) of the element chunks `chunks`. The displacements of a chunk
    /// form the columns of U and F = K₀ U is one matrix product (K₀ is shared by all
    /// elements), much faster than one K₀ u product per element.
    fn eval_group(
        &self,
        x: &[f64],
        frozen: Option<&[M3]>,
        chunks: std::ops::Range<usize>,
        want_g: bool,
        want_rot: bool,
    ) -> (f64, Vec<f64>, Vec<M3>) {
        let n3 = 3 * self.nodes_per_element();
        let ne = self.elements.len();
        let k0 = nalgebra::DMatrixView::from_slice(&self.k0, n3, n3);
        let (mut en, mut g) = (0.0, vec![0.0; if want_g { 3 * self.nodes } else { 0 }]);
        let mut rots = Vec::new();
        for c in chunks {
            let e0 = c * CHUNK;
            let m = CHUNK.min(ne - e0);
            let mut ys = vec![0.0; n3 * m];
            let mut us = vec![0.0; n3 * m];
            let mut rot = Vec::with_capacity(m);
            for j in 0..m {
                let fr = frozen.map(|f| &f[e0 + j]);
                rot.push(self.element_prepare(
                    x,
                    e0 + j,
                    fr,
                    &mut ys[j * n3..(j + 1) * n3],
                    &mut us[j * n3..(j + 1) * n3],
                ));
            }
            if want_rot {
                rots.extend(rot.iter().map(|(r, _)| *r));
            }
            // (nalgebra's product measured faster than faer's for this shape.)
            let um = nalgebra::DMatrixView::from_slice(&us, n3, m);
            let fm = k0 * um;
            let fs = fm.as_slice();
            let mut loc = [0.0; 81];
            for (j, (r, fc)) in rot.iter().enumerate() {
                let sl = j * n3..(j + 1) * n3;
                loc[..n3].fill(0.0);
                en += self.element_finish(
                    r,
                    fc.as_ref(),
                    &ys[sl.clone()],
                    &us[sl.clone()],
                    &fs[sl],
                    if want_g { Some(&mut loc[..n3]) } else { None },
                );
                if want_g {
                    for (a, &n) in self.elements[e0 + j].iter().enumerate() {
                        for i in 0..3 {
                            g[3 * n + i] += loc[3 * a + i];
                        }
                    }
                }
            }
        }
        (en, g, rots)
    }

    /// Energy (J), optionally gradient (N, added into `grad`), and the Hessian triplets of
    /// every element (pushed onto `hess`), element by element: R_e K₀ R_eᵀ when the
    /// rotations are `frozen`, else the consistent tangent (its stress term projected to
    /// positive semi-definite when `project`).
    fn eval_with_hessian(
        &self,
        x: &[f64],
        frozen: Option<&[M3]>,
        mut grad: Option<&mut [f64]>,
        hess: &mut Vec<(usize, usize, f64)>,
        project: bool,
    ) -> f64 {
        let want_g = grad.is_some();
        let k = self.nodes_per_element();
        let per: Vec<(f64, Vec<f64>, Vec<f64>)> = (0..self.elements.len())
            .into_par_iter()
            .map(|e| {
                let mut g = if want_g { vec![0.0; 3 * k] } else { Vec::new() };
                let fr = frozen.map(|f| &f[e]);
                let en = self.element_energy(x, e, fr, if want_g { Some(&mut g) } else { None });
                let r = match fr {
                    Some(r) => *r,
                    None => self.element_rotation(x, e),
                };
                let mut hm = self.rotated_stiffness(&r);
                if fr.is_none() {
                    if let Some(c) = self.rotation_correction(x, e, project) {
                        c.add_to(&mut hm);
                    }
                }
                (en, g, hm)
            })
            .collect();
        let mut energy = 0.0;
        let n3 = 3 * k;
        for (e, (en, g, hm)) in per.into_iter().enumerate() {
            energy += en;
            let nodes = &self.elements[e];
            if let Some(gr) = grad.as_deref_mut() {
                for (a, &n) in nodes.iter().enumerate() {
                    for i in 0..3 {
                        gr[3 * n + i] += g[3 * a + i];
                    }
                }
            }
            for (a, &na) in nodes.iter().enumerate() {
                for (b, &nb) in nodes.iter().enumerate() {
                    for i in 0..3 {
                        for j in 0..3 {
                            hess.push((3 * na + i, 3 * nb + j, hm[(3 * a + i) * n3 + 3 * b + j]));
                        }
                    }
                }
            }
        }
        energy
    }

    /// The frozen-rotation (rotated linear) energy at the element rotations of `x`.
    pub fn frozen_at(&self, x: &[f64]) -> FrozenInterior<'_> {
        let rotations = (0..self.elements.len())
            .map(|e| self.element_rotation(x, e))
            .collect();
        FrozenInterior {
            interior: self,
            rotations,
        }
    }

    /// Node-level mass entries (node_a, node_b, kg): consistent (ρ∫N_a N_b) or lumped (row
    /// sums on the diagonal). Multiply by the 3×3 identity for the DOF mass matrix.
    pub fn node_mass(&self, lumped: bool) -> Vec<(usize, usize, f64)> {
        let k = self.nodes_per_element();
        let mut t = Vec::new();
        for nodes in &self.elements {
            for a in 0..k {
                if lumped {
                    let s: f64 = (0..k).map(|b| self.m0[a * k + b]).sum();
                    t.push((nodes[a], nodes[a], s));
                } else {
                    for b in 0..k {
                        t.push((nodes[a], nodes[b], self.m0[a * k + b]));
                    }
                }
            }
        }
        t
    }

    /// Mass of each node (kg): the lumped (row-sum) mass, ρ ∫ N_a over its elements.
    pub fn node_masses(&self) -> Vec<f64> {
        let mut m = vec![0.0; self.nodes];
        for (a, _, v) in self.node_mass(true) {
            m[a] += v;
        }
        m
    }

    /// Total mass (kg): density × cell volume × element count (superimposed elements each
    /// carry a full cell of material).
    pub fn total_mass(&self) -> f64 {
        self.node_masses().iter().sum()
    }

    /// Gravity force on the nodes (flat, N) for acceleration `g` (m/s²): f_a = ρ g ∫ N_a.
    /// Exact for both mass matrices: M 1 g = f, so free fall accelerates uniformly at g.
    pub fn gravity_force(&self, g: Vector3<f64>) -> Vec<f64> {
        self.node_masses()
            .iter()
            .flat_map(|m| [m * g.x, m * g.y, m * g.z])
            .collect()
    }
}

impl Energy for Interior {
    fn dofs(&self) -> usize {
        3 * self.nodes
    }

    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64 {
        self.eval_impl(x, None, grad, hess, project_psd)
    }
}

/// The rotated linear energy Σ w ψ(F) with each element's rotation frozen (Müller–Gross
/// warped stiffness): E = ½ (Rᵀq − X)ᵀ K₀ (Rᵀq − X) per element. Its Hessian is exactly what
/// [`Interior`] emits, which lets finite differences check that Hessian.
pub struct FrozenInterior<'a> {
    interior: &'a Interior,
    /// Frozen rotation of each element.
    pub rotations: Vec<M3>,
}

impl Energy for FrozenInterior<'_> {
    fn dofs(&self) -> usize {
        3 * self.interior.nodes
    }

    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        _project_psd: bool,
    ) -> f64 {
        self.interior
            .eval_impl(x, Some(&self.rotations), grad, hess, false)
    }
}
