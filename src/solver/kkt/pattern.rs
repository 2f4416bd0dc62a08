//! The KKT matrix's pattern and the slots its values are summed into: the blocks a system
//! is assembled from, the pattern built from their index pairs, the fingerprint that says
//! whether a layout is new, and the gather lists and slot map that sum the Hessian, the
//! constraints and −δ into the analysed matrix's values.

use super::KktSolver;
use crate::math::energy::NO_SLOT;
use crate::math::hash::Fnv1a;
use crate::math::sparse::SparseError;
use faer::sparse::{SparseColMat, SymbolicSparseColMat};
use rayon::prelude::*;

/// The blocks of a KKT system (free dofs only) for [`KktSolver::assemble`].
#[derive(Debug, Clone, Copy)]
pub struct KktBlocks<'a> {
    /// Free index of each dof, or `usize::MAX` when it is pinned.
    pub free_of: &'a [usize],
    /// Free dofs (rows of K).
    pub n_free: usize,
    /// Constraint rows (rows of C).
    pub n_cons: usize,
    /// Hessian triplets over all dofs, both triangles, as an
    /// [`Energy`](crate::math::Energy) emits them (N/m).
    pub hessian: &'a [(usize, usize, f64)],
    /// Where the Hessian's values come from.
    pub hessian_values: HessianValues<'a>,
    /// Constraint triplets `(row, free dof, value)`, unscaled.
    pub constraints: &'a [(usize, usize, f64)],
    /// Row scale γ of the constraint rows (N/m).
    pub gamma: f64,
    /// Regularisation δ subtracted on the constraint diagonal (N/m).
    pub delta: f64,
    /// A key the caller gives the layout (sizes, pinned set, constraint pattern and Hessian
    /// triplet indices): equal keys promise equal layouts, so the solver skips fingerprinting
    /// them (it must cover the Hessian's triplet count). `None`: the solver fingerprints the
    /// layout itself. With a known key and scattered values, `hessian` may be empty.
    pub layout_key: Option<u64>,
}

/// Where [`KktSolver::assemble`] takes the Hessian's values from.
#[derive(Clone, Copy)]
pub enum HessianValues<'a> {
    /// The values of the [`KktBlocks::hessian`] triplets themselves.
    Triplets,
    /// Values replacing those of the triplets (same order and length: the values of
    /// [`Energy::hessian_values`](crate::math::Energy::hessian_values) for its layout).
    Values(&'a [f64]),
    /// A function that adds the Hessian into matrix values by a slot map, as
    /// [`Energy::hessian_scatter`](crate::math::Energy::hessian_scatter) does (the
    /// triplets then give only the layout), and the function that packs the slot map for
    /// it once per layout, as [`Energy::pack_slot_map`](crate::math::Energy::pack_slot_map)
    /// does.
    Scatter(&'a (dyn Fn(&[u32], &mut [f64]) + Sync), &'a SlotPacker<'a>),
}

/// Packs a slot map once per layout (see [`HessianValues::Scatter`]).
pub type SlotPacker<'a> = dyn Fn(&[u32]) -> Option<Vec<u32>> + Sync + 'a;

impl std::fmt::Debug for HessianValues<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Triplets => write!(f, "Triplets"),
            Self::Values(v) => write!(f, "Values({} values)", v.len()),
            Self::Scatter(..) => write!(f, "Scatter"),
        }
    }
}

/// The KKT pattern of `blocks` (both triangles, zero diagonal slots included), its values
/// zero ([`KktSolver::assemble`] sums them in). Built from the distinct (column, row) pairs,
/// 8 bytes per triplet while sorting, so the set-up's peak memory stays below a copy of a
/// refined skin's Hessian triplets with their values.
pub(super) fn kkt_pattern(blocks: &KktBlocks) -> Result<SparseColMat<usize, f64>, SparseError> {
    let (free_of, n_free) = (blocks.free_of, blocks.n_free);
    let n = n_free + blocks.n_cons;
    if u32::try_from(n).is_err() {
        return Err(SparseError::Build(format!("{n} KKT rows: more than 2³²")));
    }
    let key = |r: usize, col: usize| ((col as u64) << 32) | r as u64;
    let c = blocks.constraints;
    let mut keys = Vec::with_capacity(blocks.hessian.len() + 2 * c.len() + n);
    for &(r, cc, _) in blocks.hessian {
        let (fr, fc) = (free_of[r], free_of[cc]);
        if fr != usize::MAX && fc != usize::MAX {
            keys.push(key(fr, fc));
        }
    }
    keys.extend((0..n).map(|i| key(i, i)));
    for &(r, j, _) in c {
        keys.push(key(n_free + r, j));
        keys.push(key(j, n_free + r));
    }
    keys.par_sort_unstable();
    keys.dedup();
    keys.shrink_to_fit();
    let mut col_ptr = vec![0usize; n + 1];
    for &k in &keys {
        col_ptr[(k >> 32) as usize + 1] += 1;
    }
    for j in 0..n {
        col_ptr[j + 1] += col_ptr[j];
    }
    let row_idx: Vec<usize> = keys.iter().map(|&k| (k & 0xffff_ffff) as usize).collect();
    drop(keys);
    let nnz = row_idx.len();
    let symbolic = SymbolicSparseColMat::new_checked(n, n, col_ptr, None, row_idx);
    Ok(SparseColMat::new(symbolic, vec![0.0; nnz]))
}

/// Value index of entry (r, col) of the compressed matrix `a`.
pub(super) fn slot_of(
    a: &SparseColMat<usize, f64>,
    r: usize,
    col: usize,
) -> Result<usize, SparseError> {
    let cp = a.col_ptr();
    let rows = &a.row_idx()[cp[col]..cp[col + 1]];
    rows.binary_search(&r)
        .map(|q| cp[col] + q)
        .map_err(|_| SparseError::Build(format!("entry ({r}, {col}) missing from pattern")))
}

/// The fingerprint of a layout of `n` rows the caller keyed (see [`KktBlocks::layout_key`]):
/// its triplet count is the key's to cover, so the count's place holds a marker no
/// fingerprinted layout has.
fn keyed_fingerprint(n: usize, key: u64) -> (usize, usize, u64) {
    (n, usize::MAX, key)
}

/// The fingerprint of the layout of `n` rows with dof map `free_of`, Hessian triplets `k`
/// and constraint triplets `c`: the row and triplet counts and a hash of the free set, the
/// constraint pattern and every 31st Hessian triplet index (and the last).
fn layout_fingerprint(
    n: usize,
    free_of: &[usize],
    k: &[(usize, usize, f64)],
    c: &[(usize, usize, f64)],
) -> (usize, usize, u64) {
    let mut h = Fnv1a::new();
    h.mix_usize(free_of.len());
    for &f in free_of {
        h.mix_usize(f);
    }
    for &(r, j, _) in c {
        h.mix_usize(r);
        h.mix_usize(j);
    }
    h.mix_usize(c.len());
    for &(r, cc, _) in k.iter().step_by(31).chain(k.last()) {
        h.mix_usize(r);
        h.mix_usize(cc);
    }
    (n, k.len(), h.finish())
}

impl KktSolver {
    /// Assemble the unshifted KKT matrix of `blocks` (shift slots on the diagonal kept at
    /// zero).
    ///
    /// The first call (or a call whose layout differs) builds the pattern, the ordering
    /// (METIS or AMD, [`Self::analysis`]) and symbolic factorisation, and gather lists: for
    /// each lower-triangle slot
    /// the Hessian triplets that sum into it (the upper-triangle triplets are not read; the
    /// upper triangle is copied from the lower one). Later calls only sum the values into
    /// the slots, in parallel (no sorting or copying of triplets). The layout check compares
    /// the caller's [`KktBlocks::layout_key`] when there is one, else the sizes, the pinned
    /// set, the constraint pattern, the Hessian's triplet count and every 31st Hessian triplet
    /// index.
    /// Returns the seconds spent building (0 when reused).
    pub fn assemble(&mut self, blocks: &KktBlocks) -> Result<f64, SparseError> {
        let k = blocks.hessian;
        if let HessianValues::Values(v) = blocks.hessian_values {
            if v.len() != k.len() {
                return Err(SparseError::PatternMismatch {
                    expected: k.len(),
                    got: v.len(),
                });
            }
        }
        let n = blocks.n_free + blocks.n_cons;
        let fp = match blocks.layout_key {
            Some(key) => keyed_fingerprint(n, key),
            None => layout_fingerprint(n, blocks.free_of, k, blocks.constraints),
        };
        let mut symbolic_s = 0.0;
        self.n_free = blocks.n_free;
        self.n_cons = blocks.n_cons;
        if self.fingerprint != Some(fp) || self.base.is_none() {
            if k.is_empty() && matches!(blocks.hessian_values, HessianValues::Scatter(..)) {
                return Err(SparseError::Build(
                    "a new KKT layout needs the Hessian's triplets".into(),
                ));
            }
            let t0 = std::time::Instant::now();
            self.analyse(blocks)?;
            self.fingerprint = Some(fp);
            symbolic_s = t0.elapsed().as_secs_f64();
        }
        self.sum_values(blocks);
        Ok(symbolic_s)
    }

    /// Whether the matrix was last analysed for the layout `key` (see
    /// [`KktBlocks::layout_key`]) of `n` rows: an assembly with that key may then scatter
    /// its values without the Hessian's triplets.
    pub fn has_layout(&self, n: usize, key: u64) -> bool {
        self.base.is_some() && self.fingerprint == Some(keyed_fingerprint(n, key))
    }

    /// Whether the assembled matrix also holds its upper triangle (the patches read whole
    /// columns of it; the default). Without it, an assembly skips mirroring the lower
    /// triangle, and [`Self::assembled`] holds the lower triangle only.
    pub fn set_full_storage(&mut self, full: bool) {
        self.full_storage = full;
    }

    /// Gather lists of the pattern `a`: each lower-triangle Hessian triplet goes to its
    /// slot; the upper ones are skipped (an energy emits both triangles of its symmetric
    /// Hessian) and the upper triangle is copied from the lower one (`mirror`), so the matrix
    /// is exactly symmetric; `cmap` holds the slot of each constraint triplet.
    pub(super) fn build_gather(
        &mut self,
        a: &SparseColMat<usize, f64>,
        blocks: &KktBlocks,
    ) -> Result<(), SparseError> {
        let (free_of, k) = (blocks.free_of, blocks.hessian);
        let nnz = a.val().len();
        let mut count = vec![0usize; nnz + 1];
        let mut lower_slot = Vec::with_capacity(k.len());
        for &(r, cc, _) in k {
            let (fr, fc) = (free_of[r], free_of[cc]);
            if fr != usize::MAX && fc != usize::MAX && fr >= fc {
                let q = slot_of(a, fr, fc)?;
                count[q + 1] += 1;
                lower_slot.push(q);
            } else {
                lower_slot.push(usize::MAX);
            }
        }
        for q in 0..nnz {
            count[q + 1] += count[q];
        }
        let mut next = count.clone();
        let mut src = vec![0u32; count[nnz]];
        for (i, &q) in lower_slot.iter().enumerate() {
            if q != usize::MAX {
                src[next[q]] = u32::try_from(i)
                    .map_err(|_| SparseError::Build("more than 2³² Hessian triplets".into()))?;
                next[q] += 1;
            }
        }
        self.gather_ptr = count;
        self.gather_src = src;
        self.mirror = Vec::new();
        let (cp, ri) = (a.col_ptr(), a.row_idx());
        for col in 0..a.ncols() {
            for q in cp[col]..cp[col + 1] {
                let r = ri[q];
                if r < col {
                    self.mirror.push((q, slot_of(a, col, r)?));
                }
            }
        }
        self.cmap = blocks
            .constraints
            .iter()
            .map(|&(r, j, _)| slot_of(a, blocks.n_free + r, j))
            .collect::<Result<_, SparseError>>()?;
        self.build_slot_map(&lower_slot, blocks)
    }

    /// The slot map of the Hessian triplets (see `slot`) from the lower-triangle slots
    /// `lower_slot` (`usize::MAX` where none), and the coupling pairs.
    fn build_slot_map(
        &mut self,
        lower_slot: &[usize],
        blocks: &KktBlocks,
    ) -> Result<(), SparseError> {
        let nnz = self.gather_ptr.len() - 1;
        let too_many = || SparseError::Build("more than 2³² − 1 matrix slots".into());
        let mut pair_slot: std::collections::HashMap<(usize, usize), u32> = Default::default();
        self.coupling = Vec::new();
        self.slot = Vec::with_capacity(lower_slot.len());
        self.packed_slot = None;
        for (&(r, c, _), &q) in blocks.hessian.iter().zip(lower_slot) {
            let (fr, fc) = (blocks.free_of[r], blocks.free_of[c]);
            let s = if q != usize::MAX {
                u32::try_from(q).map_err(|_| too_many())?
            } else if fr != usize::MAX && fc == usize::MAX {
                let next = u32::try_from(nnz + self.coupling.len()).map_err(|_| too_many())?;
                *pair_slot.entry((fr, c)).or_insert_with(|| {
                    self.coupling.push((fr, c));
                    next
                })
            } else {
                NO_SLOT
            };
            if s == NO_SLOT && q != usize::MAX {
                return Err(too_many());
            }
            self.slot.push(s);
        }
        self.coupling_values = vec![0.0; self.coupling.len()];
        Ok(())
    }

    /// The Hessian's coupling of free rows to pinned dofs at the last assembly: (free row,
    /// pinned dof) pairs and their values K_fp (N/m).
    pub fn pinned_coupling(&self) -> (&[(usize, usize)], &[f64]) {
        (&self.coupling, &self.coupling_values)
    }

    /// Sum the values of `blocks` into the analysed matrix: the Hessian (its triplets
    /// gathered per slot in parallel, or scattered by its energy), γ C, −δ on the constraint
    /// diagonal, and the mirrored upper triangle.
    fn sum_values(&mut self, blocks: &KktBlocks) {
        self.keep_factored_matrix();
        match blocks.hessian_values {
            HessianValues::Scatter(scatter, pack) => self.scatter_hessian(scatter, pack),
            HessianValues::Values(v) => self.gather_hessian(blocks.hessian, Some(v)),
            HessianValues::Triplets => self.gather_hessian(blocks.hessian, None),
        }
        let base = self.base.as_mut().expect("base set");
        let vals = base.val_mut();
        for (&lo, t) in self.cmap.iter().zip(blocks.constraints) {
            vals[lo] += blocks.gamma * t.2;
        }
        for &q in &self.diag_pos[blocks.n_free..] {
            vals[q] -= blocks.delta;
        }
        if self.full_storage {
            for &(up, lo) in &self.mirror {
                vals[up] = vals[lo];
            }
        }
        self.delta = blocks.delta;
    }

    /// Before `base` is assembled anew: when it is the matrix of the current factor, it
    /// becomes `matrix` and `base` takes `matrix`'s buffer (a swap, no copy; the first time
    /// a clone).
    fn keep_factored_matrix(&mut self) {
        if !self.base_is_factored {
            return;
        }
        let base = self.base.as_mut().expect("base set");
        match &mut self.matrix {
            Some(m) if m.col_ptr() == base.col_ptr() => std::mem::swap(m, base),
            _ => self.matrix = Some(base.clone()),
        }
        self.base_is_factored = false;
    }

    /// The Hessian's values into the matrix's lower triangle (and the coupling values) by
    /// gathering each slot's triplets in parallel: values `v`, or the triplets' own.
    fn gather_hessian(&mut self, k: &[(usize, usize, f64)], v: Option<&[f64]>) {
        let value = |i: usize| v.map_or(k[i].2, |v| v[i]);
        let base = self.base.as_mut().expect("base set");
        let (ptr, src) = (&self.gather_ptr, &self.gather_src);
        base.val_mut()
            .par_iter_mut()
            .with_min_len(4096)
            .enumerate()
            .for_each(|(q, out)| {
                *out = src[ptr[q]..ptr[q + 1]]
                    .iter()
                    .map(|&i| value(i as usize))
                    .sum()
            });
        let nnz = ptr.len() - 1;
        self.coupling_values.iter_mut().for_each(|c| *c = 0.0);
        for (i, &s) in self.slot.iter().enumerate() {
            if s != NO_SLOT && s as usize >= nnz {
                self.coupling_values[s as usize - nnz] += value(i);
            }
        }
    }

    /// The Hessian's values into the matrix's lower triangle (and the coupling values) by
    /// the energy's own scatter through the slot map, packed by `pack` the first time.
    fn scatter_hessian(
        &mut self,
        scatter: &(dyn Fn(&[u32], &mut [f64]) + Sync),
        pack: &SlotPacker,
    ) {
        let (sym, mut vals) = self.base.take().expect("base set").into_parts();
        let nnz = vals.len();
        vals.par_iter_mut()
            .with_min_len(1 << 14)
            .for_each(|v| *v = 0.0);
        vals.resize(nnz + self.coupling.len(), 0.0);
        let packed = self.packed_slot.get_or_insert_with(|| pack(&self.slot));
        scatter(packed.as_deref().unwrap_or(&self.slot), &mut vals);
        self.coupling_values.clear();
        self.coupling_values.extend_from_slice(&vals[nnz..]);
        vals.truncate(nnz);
        self.base = Some(SparseColMat::new(sym, vals));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The pattern built from the distinct index pairs is the one a triplet assembly of
    /// the same blocks gives (pinned dofs left out, diagonal slots and both constraint
    /// triangles in), with duplicates and unsorted triplets.
    #[test]
    fn the_kkt_pattern_is_the_triplet_assemblys() {
        let free_of = vec![0, usize::MAX, 1, 2, 3];
        let hessian = vec![
            (4, 0, 1.0),
            (0, 4, 1.0),
            (0, 0, 2.0),
            (1, 0, 5.0),
            (0, 1, 5.0),
            (3, 2, -1.0),
            (2, 3, -1.0),
            (4, 0, 3.0),
            (3, 3, 1.0),
        ];
        let constraints = vec![(0, 1, 1.0), (1, 3, 2.0), (0, 2, 1.0)];
        let blocks = KktBlocks {
            free_of: &free_of,
            n_free: 4,
            n_cons: 2,
            hessian: &hessian,
            hessian_values: HessianValues::Triplets,
            constraints: &constraints,
            gamma: 1.0,
            delta: 0.0,
            layout_key: None,
        };
        let mut t: Vec<(usize, usize, f64)> = hessian
            .iter()
            .filter(|&&(r, c, _)| free_of[r] != usize::MAX && free_of[c] != usize::MAX)
            .map(|&(r, c, v)| (free_of[r], free_of[c], v))
            .collect();
        t.extend((0..6).map(|i| (i, i, 0.0)));
        for &(r, j, v) in &constraints {
            t.extend([(4 + r, j, v), (j, 4 + r, v)]);
        }
        let reference = crate::math::sparse::assemble(6, 6, &t).unwrap();
        let pattern = kkt_pattern(&blocks).unwrap();
        assert_eq!(pattern.col_ptr(), reference.col_ptr());
        assert_eq!(pattern.row_idx(), reference.row_idx());
        assert!(pattern.val().iter().all(|&v| v == 0.0));
    }
}
