//! Patches of a KKT system, for Newton directions that refactorise only where the Hessian
//! changed (the skin's locality in space and time).
//!
//! The free dofs are split into patches by a grid of cubic cells (side [`PatchSettings::size`],
//! from the dofs' positions); each patch also holds the dofs within
//! [`PatchSettings::overlap`] of its cell, and the constraint rows with at least half their
//! weight on its dofs. A Newton direction solves the whole KKT system by GMRES,
//! preconditioned in two stages:
//!
//! 1. the *lagged global factor*, an LDLᵀ factor of the KKT matrix of an earlier Hessian
//!    (of an earlier iterate, or frames old), z = F⁻¹ r;
//! 2. a *fresh correction on the changed patches*: the residual s = r − A z is solved on each
//!    patch whose Hessian moved since the global factor (a column of A differs from the
//!    factored one by more than [`PatchSettings::change`] of its diagonal), with that patch's
//!    own factor of the current Hessian (Dirichlet on the rest), and written back on the dofs
//!    the patch owns (its cell; restricted additive Schwarz).
//!
//! Where the Hessian did not change, stage 1 is exact; where it did, stage 2 is, up to what
//! reaches past the patch's overlap, which the skin's cluster constraints make decay within
//! about a wavelength. So GMRES converges in a few iterations while only the changed patches
//! are factorised: a patch's factor is kept while its own block stays within the change
//! tolerance of the block it was made from, and dropped when its patch is unchanged again.
//! The direction is the exact Newton direction to GMRES's tolerance (the patches change the
//! cost, not the answer), so the result passes the global solver's own residual test.
//!
//! A patch whose block is not positive definite on its constraints' null space (the local
//! inertia test; buckling is local) is shifted by τ I on its dofs, grown ×10 from 1e-8 of its
//! mean diagonal, and the operator GMRES solves carries the same shift on the dofs the patch
//! owns: a locally regularised Newton step, at the cost of the patch's factorisations only.
//! Patches are factorised and solved in parallel; each writes only its own dofs, in a fixed
//! order, so the result does not depend on the thread count.

use super::kkt::{FactorPrecision, HessianValues, KktBlocks, KktSolver};
use faer::sparse::SparseColMat;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::time::Instant;

/// How a KKT system is split into patches, and when a patch gets a fresh factor.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PatchSettings {
    /// Side of a patch's cell (m); the skin uses a few wavelengths.
    pub size: f64,
    /// A patch also holds the dofs within this distance of its cell (m; at most `size`).
    pub overlap: f64,
    /// Relative change of a dof's Hessian column since the factor it is preconditioned with
    /// (Σ|ΔA| over the column / |diagonal|) beyond which its patch is refactorised.
    pub change: f64,
    /// Largest share of the free dofs the changed patches may own; beyond it a fresh global
    /// factor is cheaper.
    pub max_share: f64,
    /// Most GMRES iterations of a patched direction before a fresh global factor is made.
    pub max_solves: usize,
}

impl PatchSettings {
    /// Check the settings; the error names the bad field.
    pub fn validate(&self) -> Result<(), String> {
        if !(self.size.is_finite() && self.size > 0.0) {
            return Err(format!("patch size = {} must be > 0 (m)", self.size));
        }
        if !(self.overlap >= 0.0 && self.overlap <= self.size) {
            return Err(format!(
                "patch overlap = {} must lie in [0, size = {}] (m)",
                self.overlap, self.size
            ));
        }
        if !(self.change.is_finite() && self.change > 0.0) {
            return Err(format!("patch change = {} must be > 0", self.change));
        }
        if !(self.max_share > 0.0 && self.max_share <= 1.0) {
            return Err(format!(
                "patch max_share = {} must lie in (0, 1]",
                self.max_share
            ));
        }
        if self.max_solves == 0 {
            return Err("patch max_solves must be at least 1".into());
        }
        Ok(())
    }
}

/// A block of the correction: one connected set of changed cells, its KKT indices (free dofs
/// first, then constraint rows), which of them it writes, its Hessian and constraint blocks in
/// local numbering, and its factor.
struct Patch {
    /// KKT indices of the block, free dofs first (sorted), then constraint rows (sorted).
    index: Vec<usize>,
    /// Local positions (into `index`) of the indices this block writes: its cells' own dofs
    /// and its constraint rows.
    owned: Vec<usize>,
    /// Free dofs among `index`.
    n_dofs: usize,
    /// Hessian block triplets (local row, local column, value) in a fixed layout.
    hess: Vec<(usize, usize, f64)>,
    /// Value slot, in the assembled matrix, of each `hess` triplet.
    slots: Vec<usize>,
    /// Constraint triplets (local row, local dof, γ c) of the block's rows.
    cons: Vec<(usize, usize, f64)>,
    /// The block's KKT solver (analysis kept; factor of `factored` when present).
    solver: KktSolver,
    /// Hessian block values of the current factor, when there is one.
    factored: Option<Vec<f64>>,
    /// Shift τ (N/m) of the current factor.
    shift: f64,
    /// Whether the block is usable in the current direction.
    active: bool,
}

/// What preparing the patches for one direction did.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct PatchWork {
    /// Patches (cells) corrected: changed since the global factor.
    pub active: usize,
    /// Share of the free dofs those patches own.
    pub share: f64,
    /// Factorisations of correction blocks made (a kept factor costs none).
    pub factorizations: usize,
    /// Blocks that needed a shift to pass their inertia test.
    pub shifted: usize,
    /// Seconds spent preparing and factorising blocks.
    pub factor_s: f64,
}

/// One grid cell of free dofs: its key, the dofs within the overlap of it, and its own.
struct Cell {
    key: [i64; 3],
    members: Vec<usize>,
    core: Vec<usize>,
}

/// The patches of one KKT layout: the cells, and the correction blocks (connected sets of
/// changed cells) of the last direction, keyed by their cells.
pub struct PatchSet {
    cells: Vec<Cell>,
    blocks: BTreeMap<Vec<usize>, Patch>,
    n_free: usize,
    n_cons: usize,
    /// The settings the set was built with.
    pub settings: PatchSettings,
    /// Precision of the blocks' factors.
    precision: FactorPrecision,
}

/// Share of a constraint row's weight that must lie on a block's dofs for the block to hold
/// the row (rows less inside would ask their few inside members for the whole cluster's
/// correction; rows left out leave the block's border unconstrained, and compressed skin
/// without its constraints buckles).
const ROW_INSIDE: f64 = 0.5;

/// Grid cell of a point for cells of side `size`.
fn cell_of(p: &[f64; 3], size: f64) -> [i64; 3] {
    p.map(|c| (c / size).floor() as i64)
}

impl PatchSet {
    /// Patches of a KKT system of `n_free` free dofs at `positions` (m) and `n_cons`
    /// constraint rows, their blocks factorised in `precision`.
    pub fn build(
        n_free: usize,
        n_cons: usize,
        positions: &[[f64; 3]],
        settings: PatchSettings,
        precision: FactorPrecision,
    ) -> Self {
        let (keys, members, core) = cell_members(positions, &settings);
        let mut own = vec![Vec::new(); keys.len()];
        for (j, &c) in core.iter().enumerate() {
            own[c].push(j);
        }
        let cells = keys
            .into_iter()
            .zip(members)
            .zip(own)
            .map(|((key, members), core)| Cell { key, members, core })
            .collect();
        Self {
            cells,
            blocks: BTreeMap::new(),
            n_free,
            n_cons,
            settings,
            precision,
        }
    }

    /// Number of patches (cells).
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// Whether there are no patches.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Whether the set was built for a system of these sizes.
    pub fn fits(&self, n_free: usize, n_cons: usize) -> bool {
        self.n_free == n_free && self.n_cons == n_cons
    }

    /// Mark the patches whose Hessian changed since `kkt`'s (lagged) factor, join touching
    /// ones into blocks and give each block a factor of the current assembled matrix (kept
    /// when the block recurs and is still within the change tolerance of the one it was made
    /// from); blocks no longer needed are dropped.
    pub fn prepare(&mut self, kkt: &KktSolver) -> PatchWork {
        let t = Instant::now();
        let change = column_change(kkt);
        let theta = self.settings.change;
        let nf = self.n_free;
        let active: Vec<usize> = (0..self.cells.len())
            .filter(|&c| self.cells[c].core.iter().any(|&j| change[j] > theta))
            .collect();
        let owned: usize = active.iter().map(|&c| self.cells[c].core.len()).sum();
        let mut work = PatchWork {
            active: active.len(),
            share: owned as f64 / nf.max(1) as f64,
            ..PatchWork::default()
        };
        let groups = self.components(&active);
        if work.share > self.settings.max_share {
            self.blocks.clear();
            return work;
        }
        let a = kkt.assembled().expect("assembled KKT matrix");
        let mut blocks = std::mem::take(&mut self.blocks);
        let mut next = BTreeMap::new();
        for g in groups {
            let b = blocks.remove(&g).unwrap_or_else(|| self.block(a, &g));
            next.insert(g, b);
        }
        let delta = kkt.delta();
        let done: Vec<(bool, bool)> = next
            .par_iter_mut()
            .map(|(_, p)| p.refresh(a, delta, theta))
            .collect();
        self.blocks = next;
        work.factorizations = done.iter().filter(|d| d.0).count();
        work.shifted = done.iter().filter(|d| d.1).count();
        work.factor_s = t.elapsed().as_secs_f64();
        work
    }

    /// The connected sets of the cells `active` (cells touch when their keys differ by at
    /// most one on every axis), each sorted, in the order of their first cell.
    fn components(&self, active: &[usize]) -> Vec<Vec<usize>> {
        let at: BTreeMap<[i64; 3], usize> =
            active.iter().map(|&c| (self.cells[c].key, c)).collect();
        let mut seen = std::collections::BTreeSet::new();
        let mut groups = Vec::new();
        for &c in active {
            if !seen.insert(c) {
                continue;
            }
            let (mut group, mut stack) = (vec![c], vec![c]);
            while let Some(u) = stack.pop() {
                let k = self.cells[u].key;
                for d in 0..27 {
                    let n = [k[0] + d % 3 - 1, k[1] + (d / 3) % 3 - 1, k[2] + d / 9 - 1];
                    if let Some(&v) = at.get(&n) {
                        if seen.insert(v) {
                            group.push(v);
                            stack.push(v);
                        }
                    }
                }
            }
            group.sort_unstable();
            groups.push(group);
        }
        groups
    }

    /// The correction block of the cells `group` in the assembled matrix `a`: their dofs
    /// (within the overlap), the constraint rows with at least half their weight on them.
    fn block(&self, a: &SparseColMat<usize, f64>, group: &[usize]) -> Patch {
        let mut dofs: Vec<usize> = group
            .iter()
            .flat_map(|&c| self.cells[c].members.iter().copied())
            .collect();
        dofs.sort_unstable();
        dofs.dedup();
        let mut core: Vec<usize> = group
            .iter()
            .flat_map(|&c| self.cells[c].core.iter().copied())
            .collect();
        core.sort_unstable();
        let rows = constraint_rows(a, self.n_free, &dofs);
        let mut patch = Patch::new(a, dofs, &core, rows);
        patch.solver.set_precision(self.precision);
        patch
    }

    /// Diagonal shifts (KKT index, N/m) of the blocks' own free dofs: the operator GMRES
    /// must solve when a block needed a shift.
    pub fn shifts(&self) -> Vec<(usize, f64)> {
        let nf = self.n_free;
        self.blocks
            .values()
            .filter(|p| p.active && p.shift > 0.0)
            .flat_map(|p| {
                p.owned
                    .iter()
                    .map(|&o| p.index[o])
                    .filter(move |&i| i < nf)
                    .map(move |i| (i, p.shift))
            })
            .collect()
    }

    /// Stage 2 of the preconditioner: z += Σ over the blocks of their own part of
    /// A_p⁻¹ (r − A_op z)_p, with A_op the assembled matrix `a` plus δ on the constraint
    /// rows (`delta`) and `shift` (per free dof, N/m).
    pub fn correct(
        &mut self,
        a: &SparseColMat<usize, f64>,
        delta: f64,
        shift: &[f64],
        r: &[f64],
        z: &mut [f64],
    ) {
        let nf = self.n_free;
        let ar = a.as_ref();
        let zr: &[f64] = z;
        let corrections: Vec<Vec<f64>> = self
            .blocks
            .par_iter_mut()
            .filter(|(_, p)| p.active)
            .map(|(_, p)| {
                let mut s: Vec<f64> = p
                    .index
                    .iter()
                    .map(|&i| {
                        // Row i of the symmetric A_op applied to z: column i.
                        let az: f64 = ar
                            .row_idx_of_col(i)
                            .zip(ar.val_of_col(i))
                            .map(|(j, v)| v * zr[j])
                            .sum();
                        let extra = if i >= nf { delta } else { shift[i] };
                        r[i] - az - extra * zr[i]
                    })
                    .collect();
                p.solver.apply_factor(&mut s);
                s
            })
            .collect();
        let active = self.blocks.values().filter(|p| p.active);
        for (p, s) in active.zip(corrections) {
            for &o in &p.owned {
                z[p.index[o]] += s[o];
            }
        }
    }

    /// Drop every block factor (after a fresh global factor every patch is unchanged).
    pub fn clear(&mut self) {
        self.blocks.clear();
    }
}

/// Per free dof, the change of its Hessian column in the assembled matrix against the
/// factored one: Σ|ΔA_ij| over the free rows i, over |A_jj| (floored at 1e-3 of the mean
/// diagonal). Infinite when there is no factor to compare with.
fn column_change(kkt: &KktSolver) -> Vec<f64> {
    let (nf, _) = kkt.sizes();
    let (Some(a), Some(f)) = (kkt.assembled(), kkt.factored_matrix()) else {
        return vec![f64::INFINITY; nf];
    };
    let (ar, fr) = (a.as_ref(), f.as_ref());
    let diag = |j: usize| a.val()[kkt.diagonal_slot(j)].abs();
    let floor = 1e-3 * (0..nf).map(diag).sum::<f64>() / nf.max(1) as f64;
    (0..nf)
        .into_par_iter()
        .map(|j| {
            let d: f64 = ar
                .row_idx_of_col(j)
                .zip(ar.val_of_col(j).iter().zip(fr.val_of_col(j)))
                .filter(|(i, _)| *i < nf)
                .map(|(_, (x, y))| (x - y).abs())
                .sum();
            d / diag(j).max(floor)
        })
        .collect()
}

/// Free dofs of each patch (its cell's and those within the overlap of it), patches in the
/// order of their cells, and the patch whose cell holds each free dof.
fn cell_members(
    positions: &[[f64; 3]],
    s: &PatchSettings,
) -> (Vec<[i64; 3]>, Vec<Vec<usize>>, Vec<usize>) {
    let mut cells: BTreeMap<[i64; 3], usize> = BTreeMap::new();
    for p in positions {
        cells.insert(cell_of(p, s.size), 0);
    }
    for (k, v) in cells.values_mut().enumerate() {
        *v = k;
    }
    let mut members = vec![Vec::new(); cells.len()];
    let mut core = vec![0usize; positions.len()];
    for (j, p) in positions.iter().enumerate() {
        let c = cell_of(p, s.size);
        core[j] = cells[&c];
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let n = [c[0] + dx, c[1] + dy, c[2] + dz];
                    let Some(&k) = cells.get(&n) else { continue };
                    // Distance from p to cell n's box, per axis.
                    let near = (0..3).all(|a| {
                        let lo = n[a] as f64 * s.size;
                        let d = (lo - p[a]).max(p[a] - (lo + s.size)).max(0.0);
                        d <= s.overlap
                    });
                    if near {
                        members[k].push(j);
                    }
                }
            }
        }
    }
    (cells.into_keys().collect(), members, core)
}

/// The constraint rows of the assembled matrix `a` with at least half their weight on the
/// free dofs `dofs` (sorted).
fn constraint_rows(a: &SparseColMat<usize, f64>, n_free: usize, dofs: &[usize]) -> Vec<usize> {
    let ar = a.as_ref();
    (n_free..a.nrows())
        .filter(|&r| {
            let (mut inside, mut total) = (0.0, 0.0);
            for (j, v) in ar.row_idx_of_col(r).zip(ar.val_of_col(r)) {
                if j < n_free {
                    total += v.abs();
                    if dofs.binary_search(&j).is_ok() {
                        inside += v.abs();
                    }
                }
            }
            total > 0.0 && inside >= ROW_INSIDE * total
        })
        .collect()
}

impl Patch {
    /// The block of free dofs `dofs` (sorted; it writes those in `core`, sorted) and
    /// constraint `rows` (all its own) of the assembled matrix `a`.
    fn new(
        a: &SparseColMat<usize, f64>,
        dofs: Vec<usize>,
        core: &[usize],
        rows: Vec<usize>,
    ) -> Self {
        let n_dofs = dofs.len();
        let index: Vec<usize> = dofs.into_iter().chain(rows).collect();
        let mut local: BTreeMap<usize, usize> = BTreeMap::new();
        for (l, &i) in index.iter().enumerate() {
            local.insert(i, l);
        }
        let owned = index
            .iter()
            .enumerate()
            .filter(|&(l, i)| l >= n_dofs || core.binary_search(i).is_ok())
            .map(|(l, _)| l)
            .collect();
        let (cp, ri) = (a.col_ptr(), a.row_idx());
        let (mut hess, mut slots, mut cons) = (Vec::new(), Vec::new(), Vec::new());
        for (lj, &j) in index[..n_dofs].iter().enumerate() {
            for q in cp[j]..cp[j + 1] {
                let Some(&li) = local.get(&ri[q]) else {
                    continue;
                };
                if li < n_dofs {
                    hess.push((li, lj, 0.0));
                    slots.push(q);
                } else {
                    cons.push((li - n_dofs, lj, a.val()[q]));
                }
            }
        }
        Self {
            index,
            owned,
            n_dofs,
            hess,
            slots,
            cons,
            solver: KktSolver::new(),
            factored: None,
            shift: 0.0,
            active: true,
        }
    }

    /// Give the patch a factor of the current assembled matrix `a` (δ of the constraint
    /// block), unless its kept factor's block is within `theta` of the current one; shifts
    /// the patch until its inertia test passes. Returns (factorised, shifted).
    fn refresh(&mut self, a: &SparseColMat<usize, f64>, delta: f64, theta: f64) -> (bool, bool) {
        let vals: Vec<f64> = self.slots.iter().map(|&q| a.val()[q]).collect();
        if let Some(old) = &self.factored {
            let scale = vals.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let moved = vals
                .iter()
                .zip(old)
                .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
            if moved <= theta * scale {
                return (false, self.shift > 0.0);
            }
        }
        let free_of: Vec<usize> = (0..self.n_dofs).collect();
        let blocks = KktBlocks {
            free_of: &free_of,
            n_free: self.n_dofs,
            n_cons: self.index.len() - self.n_dofs,
            hessian: &self.hess,
            hessian_values: HessianValues::Values(&vals),
            constraints: &self.cons,
            gamma: 1.0,
            delta,
            layout_key: None,
        };
        self.shift = 0.0;
        let mut info = match self.solver.factorize(&blocks, 0.0) {
            Ok(i) => i,
            Err(_) => {
                self.active = false;
                return (false, false);
            }
        };
        let mean_diag = vals
            .iter()
            .zip(&self.hess)
            .filter(|(_, t)| t.0 == t.1)
            .map(|(v, _)| v.abs())
            .sum::<f64>()
            / self.n_dofs.max(1) as f64;
        let mut tau = 1e-8 * mean_diag;
        while !info.inertia_ok && tau <= mean_diag {
            info = self.solver.factor(tau);
            self.shift = tau;
            tau *= 10.0;
        }
        if !self.solver.is_factored() || !info.inertia_ok {
            // Nothing usable: leave the patch to the global factor.
            self.active = false;
            self.shift = 0.0;
            self.factored = None;
            return (true, false);
        }
        self.factored = Some(vals);
        (true, self.shift > 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cells_cover_every_dof_once_as_core_and_overlap_reaches_neighbours() {
        let positions: Vec<[f64; 3]> = (0..40).map(|i| [i as f64 * 0.1, 0.0, 0.0]).collect();
        let s = PatchSettings {
            size: 1.0,
            overlap: 0.25,
            change: 0.1,
            max_share: 0.5,
            max_solves: 10,
        };
        let (_, members, core) = cell_members(&positions, &s);
        assert_eq!(members.len(), 4);
        for (j, &c) in core.iter().enumerate() {
            assert!(members[c].contains(&j), "dof {j} not in its own cell");
        }
        // Cell 1 spans [1, 2): with the overlap it holds x in [0.75, 2.25].
        let xs: Vec<f64> = members[1].iter().map(|&j| positions[j][0]).collect();
        assert!(xs.iter().all(|&x| (0.75 - 1e-9..=2.25 + 1e-9).contains(&x)));
        assert_eq!(xs.len(), 15);
        assert!(s.validate().is_ok());
        let bad = PatchSettings { overlap: 2.0, ..s };
        assert!(bad.validate().unwrap_err().contains("overlap"));
    }
}
