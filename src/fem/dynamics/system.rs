//! The Newton matrix's compressed lower-triangle pattern over the free DOFs, in 3 × 3 node
//! blocks, and its assembly from the element rotations, the mass and the coupling stiffness;
//! mirrored into full node-block rows for conjugate gradients.

use super::M3;
use crate::fem::cg::BlockCsr;
use crate::fem::interior::Interior;
use crate::fem::tangent::RotationCorrection;
use crate::fem::FemError;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

/// The terms of a Newton matrix mass_coef·M + stiff_coef·(K + K_x).
#[derive(Clone, Copy)]
pub(super) struct MatrixTerms<'a> {
    /// Coefficient of the mass matrix (1 for a time step, 0 quasi-static).
    pub(super) mass_coef: f64,
    /// Coefficient of the stiffness (h² for a time step, s²; 1 quasi-static).
    pub(super) stiff_coef: f64,
    /// Lumped node masses (kg) instead of the consistent mass matrix.
    pub(super) lumped: Option<&'a [f64]>,
    /// K_x triplets over DOFs (N/m).
    pub(super) extra: Option<&'a [(usize, usize, f64)]>,
    /// Rotation-derivative part of each element's stiffness (empty: frozen rotations).
    pub(super) corrections: &'a [Option<RotationCorrection>],
}

/// Compressed lower-triangle pattern over free DOFs with 3 × 3 node blocks.
pub(super) struct System {
    /// Free index of each node (`NONE` for a pinned node).
    pub(super) free: Vec<usize>,
    /// Number of free nodes.
    pub(super) nfree: usize,
    /// For each free node b: free nodes a ≥ b coupled to it (sorted, b first).
    nbrs: Vec<Vec<usize>>,
    /// Column pointers of `mat` (3 columns per free node).
    pub(super) colptr: Vec<usize>,
    /// For each free node b: (element, local index of b) of the elements containing it.
    node_elems: Vec<Vec<(u32, u16)>>,
    /// Assembly map, aligned with `node_elems[b]` × local node a: where block (a, b) goes in
    /// column b (`SLOT_DIAG`, `SLOT_SKIP` for pinned or upper-triangle nodes, else the rank
    /// of a in `nbrs[b][1..]`); `slot_ptr[b]` is the start of node b's run.
    slots: Vec<u32>,
    slot_ptr: Vec<usize>,
    /// Signature of the extra stiffness pattern this system was built for.
    pub(super) extra_sig: Vec<(usize, usize)>,
    /// FNV hash (or the caller's key) of the extra triplets' (row, column) layout last seen
    /// with this system.
    pub(super) extra_hash: u64,
    /// For each extra triplet of that layout: its index in `mat`'s values, or `usize::MAX`
    /// for a pinned node or the upper triangle.
    extra_slots: Vec<usize>,
    /// The assembled lower triangle over the free DOFs.
    pub(super) mat: SparseColMat<usize, f64>,
    /// The same matrix with both triangles in node-block rows (for CG), filled from `mat`.
    pub(super) bsr: BlockCsr,
    /// For each block of `bsr` off the diagonal: the rank of the lower-triangle partner in
    /// its column's `nbrs` list (block (a, b), a > b: rank of a in `nbrs[b]`; a < b: rank of
    /// b in `nbrs[a]`).
    bsr_rank: Vec<u32>,
    /// Free node → node.
    pub(super) free_nodes: Vec<usize>,
}

/// The free index of a pinned node.
pub(super) const NONE: usize = usize::MAX;
const SLOT_SKIP: u32 = u32::MAX;
const SLOT_DIAG: u32 = u32::MAX - 1;

impl System {
    pub(super) fn new(
        interior: &Interior,
        pinned: &[bool],
        extra: &[(usize, usize)],
    ) -> Result<Self, FemError> {
        let mut free = vec![NONE; interior.nodes];
        let mut nfree = 0;
        for (n, f) in free.iter_mut().enumerate() {
            if !pinned[n] {
                *f = nfree;
                nfree += 1;
            }
        }
        let mut nbrs: Vec<Vec<usize>> = (0..nfree).map(|b| vec![b]).collect();
        let mut node_elems: Vec<Vec<(u32, u16)>> = vec![Vec::new(); nfree];
        for (e, nodes) in interior.elements.iter().enumerate() {
            for (lb, &nb) in nodes.iter().enumerate() {
                let fb = free[nb];
                if fb == NONE {
                    continue;
                }
                node_elems[fb].push((e as u32, lb as u16));
                for &na in nodes {
                    let fa = free[na];
                    if fa != NONE && fa > fb {
                        nbrs[fb].push(fa);
                    }
                }
            }
        }
        for &(a, b) in extra {
            let (fa, fb) = (free[a], free[b]);
            if fa != NONE && fb != NONE && fa > fb {
                nbrs[fb].push(fa);
            }
        }
        for l in &mut nbrs {
            l[1..].sort_unstable();
            l.dedup();
        }
        let n = 3 * nfree;
        let mut colptr = Vec::with_capacity(n + 1);
        let mut rows = Vec::new();
        colptr.push(0);
        for (b, l) in nbrs.iter().enumerate() {
            for j in 0..3 {
                for i in j..3 {
                    rows.push(3 * b + i);
                }
                for &a in &l[1..] {
                    rows.extend([3 * a, 3 * a + 1, 3 * a + 2]);
                }
                colptr.push(rows.len());
            }
        }
        let mut slots = Vec::new();
        let mut slot_ptr = Vec::with_capacity(nfree + 1);
        for fb in 0..nfree {
            slot_ptr.push(slots.len());
            for &(e, _) in &node_elems[fb] {
                for &na in &interior.elements[e as usize] {
                    let fa = free[na];
                    slots.push(if fa == NONE || fa < fb {
                        SLOT_SKIP
                    } else if fa == fb {
                        SLOT_DIAG
                    } else {
                        nbrs[fb][1..].binary_search(&fa).expect("pattern") as u32
                    });
                }
            }
        }
        slot_ptr.push(slots.len());
        let nnz = rows.len();
        let sym = SymbolicSparseColMat::new_checked(n, n, colptr.clone(), None, rows);
        let mat = SparseColMat::new(sym, vec![0.0; nnz]);
        let (bsr, bsr_rank) = block_rows(&nbrs, nfree);
        let free_nodes = (0..interior.nodes).filter(|&n| free[n] != NONE).collect();
        Ok(Self {
            free,
            nfree,
            nbrs,
            colptr,
            node_elems,
            slots,
            slot_ptr,
            extra_sig: extra.to_vec(),
            extra_hash: 0,
            extra_slots: Vec::new(),
            mat,
            bsr,
            bsr_rank,
            free_nodes,
        })
    }

    /// Whether this system was built for exactly the nodes `pinned`.
    pub(super) fn pins(&self, pinned: &[bool]) -> bool {
        self.free.len() == pinned.len()
            && self
                .free
                .iter()
                .zip(pinned)
                .all(|(&f, &p)| (f == NONE) == p)
    }

    /// Copy the assembled lower-triangle matrix into the full node-block rows of `bsr`.
    pub(super) fn fill_bsr(&mut self) {
        let cp = &self.colptr;
        let cv = self.mat.val();
        let rank = &self.bsr_rank;
        let bsr = &mut self.bsr;
        let (ptr, col) = (&bsr.ptr, &bsr.col);
        let mut rows: Vec<&mut [f64]> = Vec::with_capacity(ptr.len() - 1);
        let mut rest: &mut [f64] = &mut bsr.val;
        for a in 0..ptr.len() - 1 {
            let (head, tail) = rest.split_at_mut(9 * (ptr[a + 1] - ptr[a]));
            rows.push(head);
            rest = tail;
        }
        rows.into_par_iter().enumerate().for_each(|(a, out)| {
            for k in ptr[a]..ptr[a + 1] {
                let b = col[k] as usize;
                let r = rank[k] as usize;
                let o = &mut out[9 * (k - ptr[a])..9 * (k - ptr[a]) + 9];
                for i in 0..3 {
                    for j in 0..3 {
                        o[3 * i + j] = if b < a {
                            cv[cp[3 * b + j] + (3 - j) + 3 * r + i]
                        } else if b > a {
                            cv[cp[3 * a + i] + (3 - i) + 3 * r + j]
                        } else if i >= j {
                            cv[cp[3 * a + j] + i - j]
                        } else {
                            cv[cp[3 * a + i] + j - i]
                        };
                    }
                }
            }
        });
    }

    /// Value index of entry (3·fa + i, 3·fb + j), fa ≥ fb, (i ≥ j when fa = fb).
    fn offset(&self, fa: usize, fb: usize, i: usize, j: usize) -> usize {
        let base = self.colptr[3 * fb + j];
        if fa == fb {
            base + i - j
        } else {
            let r = self.nbrs[fb][1..]
                .binary_search(&fa)
                .expect("pair in pattern");
            base + (3 - j) + 3 * r + i
        }
    }

    /// A = mass_coef·M + stiff_coef·(Σ_e R_e K₀ R_eᵀ + K_x) with the element `rotations`.
    pub(super) fn assemble(&mut self, interior: &Interior, rotations: &[M3], terms: &MatrixTerms) {
        let MatrixTerms {
            mass_coef,
            stiff_coef,
            lumped,
            extra,
            corrections,
        } = *terms;
        let k = interior.nodes_per_element();
        let colptr = &self.colptr;
        let free = &self.free;
        let node_elems = &self.node_elems;
        // Split the value array into the three columns of each free node.
        let vals = self.mat.val_mut();
        let mut slices: Vec<&mut [f64]> = Vec::with_capacity(self.nfree);
        let mut rest: &mut [f64] = vals;
        for b in 0..self.nfree {
            let len = colptr[3 * b + 3] - colptr[3 * b];
            let (head, tail) = rest.split_at_mut(len);
            slices.push(head);
            rest = tail;
        }
        let slots = &self.slots;
        let slot_ptr = &self.slot_ptr;
        slices.into_par_iter().enumerate().for_each(|(fb, col)| {
            col.fill(0.0);
            let c0 = colptr[3 * fb];
            let cj = [0, colptr[3 * fb + 1] - c0, colptr[3 * fb + 2] - c0];
            let mut s = slot_ptr[fb];
            for &(e, lb) in &node_elems[fb] {
                let (e, lb) = (e as usize, lb as usize);
                let r = &rotations[e];
                let rt = r.transpose();
                for la in 0..k {
                    let slot = slots[s + la];
                    if slot == SLOT_SKIP {
                        continue;
                    }
                    let mut rb = r * interior.k0_blocks[la * k + lb] * rt;
                    if let Some(Some(c)) = corrections.get(e) {
                        rb += c.block(la, lb);
                    }
                    rb *= stiff_coef;
                    if lumped.is_none() {
                        let m = mass_coef * interior.m0[la * k + lb];
                        for i in 0..3 {
                            rb[(i, i)] += m;
                        }
                    }
                    if slot == SLOT_DIAG {
                        for j in 0..3 {
                            for i in j..3 {
                                col[cj[j] + i - j] += rb[(i, j)];
                            }
                        }
                    } else {
                        let rk = 3 * slot as usize;
                        for j in 0..3 {
                            let base = cj[j] + (3 - j) + rk;
                            for i in 0..3 {
                                col[base + i] += rb[(i, j)];
                            }
                        }
                    }
                }
                s += k;
            }
        });
        if let Some(m) = lumped {
            for (n, &fb) in free.iter().enumerate() {
                if fb != NONE {
                    for j in 0..3 {
                        let o = self.colptr[3 * fb + j];
                        self.mat.val_mut()[o] += mass_coef * m[n];
                    }
                }
            }
        }
        if let Some(ex) = extra {
            debug_assert_eq!(ex.len(), self.extra_slots.len(), "slots of this layout");
            let vals = self.mat.val_mut();
            for (&(_, _, v), &o) in ex.iter().zip(&self.extra_slots) {
                if o != usize::MAX {
                    vals[o] += stiff_coef * v;
                }
            }
        }
    }

    /// Where each extra triplet goes in `mat`'s values ([`Self::extra_slots`]).
    pub(super) fn place_extra(&mut self, extra: &[(usize, usize, f64)]) {
        let free = &self.free;
        let slots = extra
            .iter()
            .map(|&(r, c, _)| {
                let (fa, fb) = (free[r / 3], free[c / 3]);
                let (i, j) = (r % 3, c % 3);
                // Pinned, or the upper triangle (the lower one carries it).
                if fa == NONE || fb == NONE || 3 * fa + i < 3 * fb + j {
                    usize::MAX
                } else {
                    self.offset(fa, fb, i, j)
                }
            })
            .collect();
        self.extra_slots = slots;
    }
}

/// The full node-block rows of the lower-triangle pattern `nbrs` (for each free node b: b,
/// then the free nodes a > b coupled to it): row a holds its lower partners (ascending
/// b < a), the diagonal, then `nbrs[a]`. Returns the pattern and, for each of its blocks, the
/// rank of the lower-triangle partner ([`System`]'s `bsr_rank`).
fn block_rows(nbrs: &[Vec<usize>], nfree: usize) -> (BlockCsr, Vec<u32>) {
    let mut lower: Vec<Vec<(u32, u32)>> = vec![Vec::new(); nfree];
    for (b, l) in nbrs.iter().enumerate() {
        for (r, &a) in l[1..].iter().enumerate() {
            lower[a].push((b as u32, r as u32));
        }
    }
    let mut rows_b: Vec<Vec<u32>> = Vec::with_capacity(nfree);
    let mut bsr_rank = Vec::new();
    for a in 0..nfree {
        let mut row: Vec<u32> = Vec::new();
        for &(b, r) in &lower[a] {
            row.push(b);
            bsr_rank.push(r);
        }
        row.push(a as u32);
        bsr_rank.push(0);
        for (r, &b) in nbrs[a][1..].iter().enumerate() {
            row.push(b as u32);
            bsr_rank.push(r as u32);
        }
        rows_b.push(row);
    }
    (BlockCsr::from_pattern(&rows_b), bsr_rank)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::bench::cube_lattice;
    use crate::fem::dynamics::twisted;
    use crate::fem::matfree::ElementOperator;
    use crate::fem::Material;
    use nalgebra::{Rotation3, Unit, Vector3};

    /// The matrix-free operator and the assembled matrix (lower triangle mirrored into
    /// node-block rows) give the same products and diagonal blocks, with consistent and
    /// with lumped mass, pinned nodes and arbitrary element rotations.
    #[test]
    fn matrix_free_operator_equals_the_assembled_matrix() {
        let h = 0.02;
        let lat = cube_lattice(3, h).unwrap();
        let int = Interior::new(&lat, &Material::default()).unwrap();
        let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.5 * h).collect();
        let mut sys = System::new(&int, &pinned, &[]).unwrap();
        let rot: Vec<M3> = (0..int.elements.len())
            .map(|e| {
                let ax = Unit::new_normalize(Vector3::new(1.0, e as f64, 2.0 - e as f64));
                *Rotation3::from_axis_angle(&ax, 0.3 * e as f64).matrix()
            })
            .collect();
        // The consistent tangent's rotation corrections at a twisted, stretched state.
        let q = twisted(&lat);
        let corrections: Vec<_> = (0..int.elements.len())
            .map(|e| int.rotation_correction(&q, e, true))
            .collect();
        assert!(corrections.iter().all(|c| c.is_some()));
        let lumped_all = int.node_masses();
        let lumped_free: Vec<f64> = sys.free_nodes.iter().map(|&n| lumped_all[n]).collect();
        let n = 3 * sys.nfree;
        let x: Vec<f64> = (0..n)
            .map(|i| ((i * 7919) % 1000) as f64 * 1e-3 - 0.5)
            .collect();
        for lumped in [false, true] {
            let coefs = (1.0, h * h);
            let terms = MatrixTerms {
                mass_coef: coefs.0,
                stiff_coef: coefs.1,
                lumped: lumped.then_some(lumped_all.as_slice()),
                extra: None,
                corrections: &corrections,
            };
            sys.assemble(&int, &rot, &terms);
            sys.fill_bsr();
            let mut op = ElementOperator::new(&int, &sys.free);
            op.update(
                &int,
                rot.clone(),
                corrections.clone(),
                coefs.0,
                coefs.1,
                lumped.then(|| lumped_free.clone()),
            );
            let (mut y1, mut y2) = (vec![0.0; n], vec![0.0; n]);
            let e1 = sys.bsr.mul(&x, &mut y1);
            let e2 = op.mul(&x, &mut y2);
            let scale = y1.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let diff = y1
                .iter()
                .zip(&y2)
                .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
            assert!(diff < 1e-12 * scale, "lumped {lumped}: {diff} of {scale}");
            assert!((e1 - e2).abs() < 1e-12 * e1.abs());
            for (a, b) in sys.bsr.diag_inverses().iter().zip(op.diag_inverses()) {
                for k in 0..9 {
                    assert!((a[k] - b[k]).abs() < 1e-9 * a[k].abs().max(1e-3 * a[0].abs()));
                }
            }
        }
    }
}
