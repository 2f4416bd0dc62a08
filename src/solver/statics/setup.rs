//! The free-dof set-up of a problem: which dofs are free, their indices, and the constraint
//! entries over them, with the hash of that structure that keys the KKT layout. The last
//! set-up is kept and reused while the dof count, pinned dofs and constraint entries stay
//! those of the last solve.

use super::problem::check_start;
use super::{SolverError, StaticProblem, StaticSolver};
use crate::math::hash::Fnv1a;
use crate::math::Energy;
use std::sync::Arc;

/// The free index of a pinned dof.
pub(super) const PINNED: usize = usize::MAX;

/// The free dofs of a problem and its constraint entries over them.
pub(super) struct Setup {
    /// Free index of each dof, or [`PINNED`].
    pub(super) free_of: Vec<usize>,
    /// The dof of each free index.
    pub(super) free: Vec<usize>,
    /// Constraint entries `(row, free index, coefficient)` of the free dofs.
    pub(super) cfree: Vec<(usize, usize, f64)>,
    /// Hash of the free set and the constraint pattern (with the Hessian's layout, the KKT
    /// matrix's layout key).
    pub(super) key: u64,
}

/// What a [`Setup`] was built from: the dof count, the pinned dofs and the constraint rows
/// and entries (values as bits).
pub(super) struct SetupInput {
    dofs: usize,
    rows: usize,
    pinned: Vec<usize>,
    entries: Vec<(usize, usize, u64)>,
}

impl SetupInput {
    /// What `p` for `dofs` dofs is.
    pub(super) fn of(dofs: usize, p: &StaticProblem) -> Self {
        let c = &p.constraints;
        Self {
            dofs,
            rows: c.rows,
            pinned: p.pinned.clone(),
            entries: c
                .entries
                .iter()
                .map(|&(r, d, v)| (r, d, v.to_bits()))
                .collect(),
        }
    }

    /// Whether `p` for `dofs` dofs is what this was made from.
    pub(super) fn is_of(&self, dofs: usize, p: &StaticProblem) -> bool {
        let c = &p.constraints;
        self.dofs == dofs
            && self.rows == c.rows
            && self.pinned == p.pinned
            && self.entries.len() == c.entries.len()
            && self
                .entries
                .iter()
                .zip(&c.entries)
                .all(|(a, b)| (a.0, a.1, a.2) == (b.0, b.1, b.2.to_bits()))
    }
}

/// FNV-1a hash of the free set `free_of` and the pattern of the constraint entries `cfree`.
fn setup_key(free_of: &[usize], cfree: &[(usize, usize, f64)]) -> u64 {
    let mut h = Fnv1a::new();
    h.mix_usize(free_of.len());
    free_of.iter().for_each(|&f| h.mix_usize(f));
    h.mix_usize(cfree.len());
    for &(r, j, _) in cfree {
        h.mix_usize(r);
        h.mix_usize(j);
    }
    h.finish()
}

impl StaticSolver {
    /// The free-dof set-up of `p` for energy `e`, after checking `p` and the start `x`: the
    /// last one when the dof count, pinned dofs and constraint entries are those of the last
    /// solve (the skin's cluster rows keep their entries from frame to frame, so a frame
    /// compares them instead of building and hashing them again), else built anew.
    pub(super) fn setup(
        &mut self,
        e: &dyn Energy,
        p: &StaticProblem,
        x: &[f64],
    ) -> Result<Arc<Setup>, SolverError> {
        let n = e.dofs();
        check_start(n, p, x)?;
        if let Some((input, s)) = &self.last_setup {
            if input.is_of(n, p) {
                return Ok(Arc::clone(s));
            }
        }
        let s = Arc::new(self.build_setup(n, p)?);
        self.last_setup = Some((SetupInput::of(n, p), Arc::clone(&s)));
        Ok(s)
    }

    /// [`Self::setup`] built anew for `n` dofs (the start already checked).
    fn build_setup(&self, n: usize, p: &StaticProblem) -> Result<Setup, SolverError> {
        let c = &p.constraints;
        let mut free_of = vec![0usize; n];
        for &d in &p.pinned {
            if d >= n {
                return Err(SolverError::Problem(format!(
                    "pinned dof {d} out of range ({n} dofs)"
                )));
            }
            free_of[d] = PINNED;
        }
        let mut free = Vec::with_capacity(n);
        for (d, f) in free_of.iter_mut().enumerate() {
            if *f != PINNED {
                *f = free.len();
                free.push(d);
            }
        }
        let mut cfree = Vec::with_capacity(c.entries.len());
        for &(r, d, v) in &c.entries {
            if r >= c.rows || d >= n || !v.is_finite() {
                return Err(SolverError::Problem(format!(
                    "constraint entry ({r}, {d}, {v}) out of range ({} rows, {n} dofs) or not finite",
                    c.rows
                )));
            }
            if free_of[d] != PINNED {
                cfree.push((r, free_of[d], v));
            }
        }
        let key = setup_key(&free_of, &cfree);
        Ok(Setup {
            free_of,
            free,
            cfree,
            key,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::{quartic_problem, QUARTIC};
    use super::*;

    /// The set-up is reused while the dofs, pinned dofs and constraint entries are the last
    /// solve's (a frame's new right-hand side keeps it), built anew when any changes, and
    /// the start is checked either way.
    #[test]
    fn the_set_up_is_reused_while_the_problem_keeps_its_entries() {
        let mut solver = StaticSolver::default();
        let mut p = quartic_problem();
        let x = vec![0.5, 1.0, 1.0, 0.0, 0.0, 0.0];
        let first = solver.setup(&QUARTIC, &p, &x).unwrap();
        p.constraints.rhs[0] = 3.0;
        assert!(Arc::ptr_eq(
            &first,
            &solver.setup(&QUARTIC, &p, &x).unwrap()
        ));
        p.constraints.entries[1].2 = 2.0;
        let scaled = solver.setup(&QUARTIC, &p, &x).unwrap();
        assert!(!Arc::ptr_eq(&first, &scaled));
        assert_eq!(scaled.cfree[1].2, 2.0);
        p.pinned = vec![0, 5];
        let pinned = solver.setup(&QUARTIC, &p, &x).unwrap();
        assert_eq!(pinned.free, vec![1, 2, 3, 4]);
        let nan = vec![f64::NAN; 6];
        assert!(solver.setup(&QUARTIC, &p, &nan).is_err());
    }
}
