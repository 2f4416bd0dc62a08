//! The Newton matrix A = c_m M + c_k Σ_e R_e K₀ R_eᵀ applied without assembling it: per
//! element, rotate the element's values into its rest frame, multiply by the shared element
//! matrix c_k K₀ + c_m (M₀ ⊗ I₃) (consistent mass is rotation invariant, so it joins K₀),
//! rotate back, and sum per node. The element products are one matrix product per chunk of
//! elements (one K₀ for all elements), which runs at dense-matrix speed.
//!
//! Works on free DOFs (3 per free node, in free-node order); pinned nodes are held at zero.
//! Sums are formed per node over a fixed list of (element, local node) pairs and dot products
//! over fixed chunks in order: the same bits for any thread count.

use super::interior::Interior;
use super::tangent::RotationCorrection;
use faer::linalg::matmul::matmul;
use faer::{Accum, MatMut, MatRef, Par};
use nalgebra::Matrix3;
use rayon::prelude::*;

type M3 = Matrix3<f64>;

/// Elements per matrix product.
const CHUNK_ELEMS: usize = 64;
/// Nodes per chunk of the per-node sums.
const CHUNK_NODES: usize = 48;
/// Marks a pinned node in an element's local-to-free map.
const PINNED: u32 = u32::MAX;

/// Matrix-free Newton operator over free DOFs (see the module notes). Units: kg (the
/// system [M + h²K] of a time step) or N/m (c_m = 0, statics).
pub struct ElementOperator {
    k: usize,
    /// Element matrix c_k K₀ + c_m (M₀ ⊗ I₃), column-major (3K × 3K).
    ke: Vec<f64>,
    coefs: (f64, f64),
    /// Free index of each element node (`PINNED` for pinned), K per element.
    elem_free: Vec<u32>,
    /// Per free node, its (element, local node) pairs, and where each run starts.
    node_elems: Vec<(u32, u16)>,
    node_ptr: Vec<usize>,
    /// Rotation of each element.
    rot: Vec<M3>,
    /// Rotation-derivative part of each element's stiffness (consistent tangent; empty for
    /// the frozen-rotation stiffness).
    corrections: Vec<Option<RotationCorrection>>,
    /// Lumped mass per free node times c_m (kg), when lumped.
    lumped: Option<Vec<f64>>,
    /// Scratch: element results (3K per element).
    buf: std::sync::Mutex<Vec<f64>>,
}

impl ElementOperator {
    /// The operator for `interior` with free-node map `free` (node → free index or
    /// `usize::MAX` when pinned). Coefficients and rotations are set by [`Self::update`].
    pub fn new(interior: &Interior, free: &[usize]) -> Self {
        let k = interior.nodes_per_element();
        let nfree = free.iter().filter(|&&f| f != usize::MAX).count();
        let mut elem_free = Vec::with_capacity(k * interior.elements.len());
        let mut lists: Vec<Vec<(u32, u16)>> = vec![Vec::new(); nfree];
        for (e, nodes) in interior.elements.iter().enumerate() {
            for (la, &n) in nodes.iter().enumerate() {
                let f = free[n];
                if f == usize::MAX {
                    elem_free.push(PINNED);
                } else {
                    elem_free.push(f as u32);
                    lists[f].push((e as u32, la as u16));
                }
            }
        }
        let mut node_ptr = Vec::with_capacity(nfree + 1);
        let mut node_elems = Vec::new();
        node_ptr.push(0);
        for l in lists {
            node_elems.extend(l);
            node_ptr.push(node_elems.len());
        }
        Self {
            k,
            ke: Vec::new(),
            coefs: (f64::NAN, f64::NAN),
            elem_free,
            node_elems,
            node_ptr,
            rot: Vec::new(),
            corrections: Vec::new(),
            lumped: None,
            buf: std::sync::Mutex::new(vec![0.0; 3 * k * interior.elements.len()]),
        }
    }

    /// Free nodes.
    pub fn nodes(&self) -> usize {
        self.node_ptr.len() - 1
    }

    /// Set A = c_m M + c_k Σ (R_e K₀ R_eᵀ + Z_e C_e Z_eᵀ) for element rotations `rot` and
    /// rotation corrections `corrections` (empty: none); `lumped` gives the lumped node
    /// masses of the free nodes (kg) instead of the consistent mass.
    pub fn update(
        &mut self,
        interior: &Interior,
        rot: Vec<M3>,
        corrections: Vec<Option<RotationCorrection>>,
        mass_coef: f64,
        stiff_coef: f64,
        lumped: Option<Vec<f64>>,
    ) {
        let k = self.k;
        let n3 = 3 * k;
        let cons = if lumped.is_some() { 0.0 } else { mass_coef };
        if self.coefs != (cons, stiff_coef) {
            let mut ke = vec![0.0; n3 * n3];
            for c in 0..n3 {
                for r in 0..n3 {
                    // K₀ is symmetric: row-major and column-major agree.
                    let mut v = stiff_coef * interior.k0[r * n3 + c];
                    if r % 3 == c % 3 {
                        v += cons * interior.m0[(r / 3) * k + c / 3];
                    }
                    ke[c * n3 + r] = v;
                }
            }
            self.ke = ke;
            self.coefs = (cons, stiff_coef);
        }
        self.rot = rot;
        self.corrections = corrections;
        self.lumped = lumped.map(|m| m.into_iter().map(|v| v * mass_coef).collect());
    }

    /// y = A x over free DOFs; returns xᵀ A x.
    pub fn mul(&self, x: &[f64], y: &mut [f64]) -> f64 {
        let k = self.k;
        let n3 = 3 * k;
        let mut guard = self.buf.lock().expect("scratch lock");
        let buf: &mut [f64] = &mut guard;
        let ke = MatRef::from_column_major_slice(&self.ke, n3, n3);
        buf.par_chunks_mut(n3 * CHUNK_ELEMS)
            .enumerate()
            .for_each(|(c, out)| {
                let e0 = c * CHUNK_ELEMS;
                let m = out.len() / n3;
                let mut u = vec![0.0; n3 * m];
                for j in 0..m {
                    let e = e0 + j;
                    let r = &self.rot[e];
                    for a in 0..k {
                        let f = self.elem_free[e * k + a];
                        if f != PINNED {
                            let f = 3 * f as usize;
                            let (x0, x1, x2) = (x[f], x[f + 1], x[f + 2]);
                            for i in 0..3 {
                                u[j * n3 + 3 * a + i] =
                                    r[(0, i)] * x0 + r[(1, i)] * x1 + r[(2, i)] * x2;
                            }
                        }
                    }
                }
                let um = MatRef::from_column_major_slice(&u, n3, m);
                let om = MatMut::from_column_major_slice_mut(out, n3, m);
                matmul(om, Accum::Replace, ke, um, 1.0, Par::Seq);
                for j in 0..m {
                    let r = &self.rot[e0 + j];
                    for a in 0..k {
                        let o = &mut out[j * n3 + 3 * a..j * n3 + 3 * a + 3];
                        let (v0, v1, v2) = (o[0], o[1], o[2]);
                        for i in 0..3 {
                            o[i] = r[(i, 0)] * v0 + r[(i, 1)] * v1 + r[(i, 2)] * v2;
                        }
                    }
                    self.add_correction(e0 + j, x, &mut out[j * n3..(j + 1) * n3]);
                }
            });
        let buf: &[f64] = buf;
        let parts: Vec<f64> = y
            .par_chunks_mut(3 * CHUNK_NODES)
            .enumerate()
            .map(|(c, yc)| {
                let mut xy = 0.0;
                for (kk, ya) in yc.chunks_exact_mut(3).enumerate() {
                    let a = c * CHUNK_NODES + kk;
                    let mut acc = [0.0; 3];
                    for &(e, la) in &self.node_elems[self.node_ptr[a]..self.node_ptr[a + 1]] {
                        let o = e as usize * n3 + 3 * la as usize;
                        acc[0] += buf[o];
                        acc[1] += buf[o + 1];
                        acc[2] += buf[o + 2];
                    }
                    if let Some(l) = &self.lumped {
                        for i in 0..3 {
                            acc[i] += l[a] * x[3 * a + i];
                        }
                    }
                    ya.copy_from_slice(&acc);
                    xy += acc[0] * x[3 * a] + acc[1] * x[3 * a + 1] + acc[2] * x[3 * a + 2];
                }
                xy
            })
            .collect();
        parts.iter().sum()
    }

    /// out += c_k Z_e C_e Z_eᵀ x_e for element `e` (x over free DOFs; pinned nodes zero).
    fn add_correction(&self, e: usize, x: &[f64], out: &mut [f64]) {
        let Some(Some(c)) = self.corrections.get(e) else {
            return;
        };
        let k = self.k;
        let mut xe = [0.0; 81];
        for a in 0..k {
            let f = self.elem_free[e * k + a];
            if f != PINNED {
                let f = 3 * f as usize;
                xe[3 * a..3 * a + 3].copy_from_slice(&x[f..f + 3]);
            }
        }
        c.apply(&xe[..3 * k], out, self.coefs.1);
    }

    /// Inverses of the 3 × 3 diagonal blocks (row-major), for block Jacobi.
    pub fn diag_inverses(&self) -> Vec<[f64; 9]> {
        let n3 = 3 * self.k;
        (0..self.nodes())
            .into_par_iter()
            .map(|a| {
                let mut d = M3::zeros();
                for &(e, la) in &self.node_elems[self.node_ptr[a]..self.node_ptr[a + 1]] {
                    let la = la as usize;
                    let blk = M3::from_fn(|i, j| self.ke[(3 * la + j) * n3 + 3 * la + i]);
                    let r = &self.rot[e as usize];
                    d += r * blk * r.transpose();
                    if let Some(Some(c)) = self.corrections.get(e as usize) {
                        d += c.block(la, la) * self.coefs.1;
                    }
                }
                if let Some(l) = &self.lumped {
                    for i in 0..3 {
                        d[(i, i)] += l[a];
                    }
                }
                let inv = d.try_inverse().unwrap_or_else(|| {
                    M3::from_diagonal(&d.diagonal().map(|v| 1.0 / v.abs().max(1e-300)))
                });
                let mut o = [0.0; 9];
                for i in 0..3 {
                    for j in 0..3 {
                        o[3 * i + j] = inv[(i, j)];
                    }
                }
                o
            })
            .collect()
    }
}
