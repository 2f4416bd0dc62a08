//! The Hessian's layout and the assembly of the regularised KKT matrix from it: the first
//! Hessian of an energy gives the triplet layout (and γ), later ones are gathered or
//! scattered into the KKT matrix by that layout.

use super::model::Model;
use super::setup::{Setup, PINNED};
use super::{SolverError, StaticSolver};
use crate::math::hash::Fnv1a;
use crate::math::Energy;
use crate::solver::kkt::{HessianValues, KktBlocks};
use crate::solver::status::SolveReport;
use std::time::Instant;

/// Which energy a Hessian layout belongs to: its address and dof count.
pub(super) fn energy_identity(e: &dyn Energy) -> (usize, usize) {
    (e as *const dyn Energy as *const () as usize, e.dofs())
}

/// Where [`StaticSolver::assemble_at`] takes the Hessian's values from.
enum Source {
    /// The triplets just evaluated (a new or changed layout).
    Triplets,
    /// The energy's values for the held triplets' layout.
    Values,
    /// The energy's scatter into the matrix by the slot map.
    Scatter,
}

/// Regularisation δ of the constraint block, relative to γ. The factorisation sees the
/// penalty K + (γ²/δ) CᵀC on the free block; δ = 1e-6 γ keeps that penalty (1e6 γ) strong
/// enough for the inertia test yet small enough that its round-off (1e6 γ × 1e-16) stays far
/// below the soft bending eigenvalues of a thin skin (a much smaller δ loses a thin strip's
/// lowest buckling mode in round-off). GMRES preconditioned with the factor removes δ from
/// the solution.
const KKT_DELTA: f64 = 1e-6;

impl StaticSolver {
    /// Assemble the regularised KKT matrix of the model with the Hessian at `x`
    /// (element-projected when `project`): after the energy's first Hessian (its triplets
    /// give the layout) the energy scatters its values straight into the matrix (when it
    /// says how many triplets it has and that is still the layout's count; else its values
    /// are gathered). Returns the symbolic-analysis time (s), zero when the cached analysis
    /// was reused.
    pub(super) fn assemble_at(
        &mut self,
        m: &Model,
        x: &[f64],
        project: bool,
    ) -> Result<f64, SolverError> {
        let e = m.e;
        let mut values = Vec::new();
        let n = m.free() + m.rows();
        let key = |trip_key: u64| m.s.key ^ trip_key.rotate_left(29);
        let held = self.trip.len() == self.trip_len;
        let scatters = e.triplet_count() == Some(self.trip_len);
        let source = if !self.trip_current {
            self.evaluate_layout(e, x, project);
            Source::Triplets
        } else if scatters && (held || self.kkt.has_layout(n, key(self.trip_key))) {
            Source::Scatter
        } else if !held {
            self.evaluate_layout(e, x, project);
            Source::Triplets
        } else {
            e.hessian_values(x, &mut values, project);
            if values.len() == self.trip.len() {
                Source::Values
            } else {
                self.evaluate_layout(e, x, project);
                Source::Triplets
            }
        };
        let scatter = |slot: &[u32], out: &mut [f64]| e.hessian_scatter(x, slot, out, project);
        let pack = |slot: &[u32]| e.pack_slot_map(slot);
        let hessian_values = match source {
            Source::Triplets => HessianValues::Triplets,
            Source::Values => HessianValues::Values(&values),
            Source::Scatter => HessianValues::Scatter(&scatter, &pack),
        };
        let sym_s = self.kkt.assemble(&KktBlocks {
            free_of: &m.s.free_of,
            n_free: m.free(),
            n_cons: m.rows(),
            hessian: &self.trip,
            hessian_values,
            constraints: &m.s.cfree,
            gamma: m.gamma,
            delta: KKT_DELTA * m.gamma,
            layout_key: Some(key(self.trip_key)),
        })?;
        if e.triplet_count() == Some(self.trip_len) {
            // The analysed matrix keeps the layout and the energy scatters its values: the
            // triplets, the largest buffer of a refined skin's set-up, are not needed again.
            self.trip = Vec::new();
        }
        Ok(sym_s)
    }

    /// Evaluate the energy's Hessian triplets at `x` (their indices are the layout) and the
    /// hash of their indices.
    pub(super) fn evaluate_layout(&mut self, e: &dyn Energy, x: &[f64], project: bool) {
        self.trip.clear();
        e.eval(x, None, Some(&mut self.trip), project);
        self.trip_len = self.trip.len();
        self.trip_current = true;
        let mut h = Fnv1a::new();
        h.mix_usize(self.trip.len());
        for &(r, c, _) in &self.trip {
            h.mix_usize(r);
            h.mix_usize(c);
        }
        self.trip_key = h.finish();
    }

    /// Mean |diagonal| of the free dofs of the Hessian in `trip` (N/m), 1 when it is zero.
    fn mean_diag(&self, s: &Setup) -> f64 {
        let nfree = s.free.len();
        let mut d = vec![0.0; nfree];
        for &(r, c, v) in &self.trip {
            if r == c && s.free_of[r] != PINNED {
                d[s.free_of[r]] += v;
            }
        }
        let m = d.iter().map(|v| v.abs()).sum::<f64>() / nfree.max(1) as f64;
        if m > 0.0 && m.is_finite() {
            m
        } else {
            1.0
        }
    }

    /// Assemble the KKT matrix of the Hessian at `x` (element-projected when `project`),
    /// unless `have` (which Hessian the KKT matrix holds at `x`) says it is there; the times
    /// go to `rep`.
    pub(super) fn assemble_hessian(
        &mut self,
        m: &Model,
        x: &[f64],
        project: bool,
        have: &mut Option<bool>,
        rep: &mut SolveReport,
    ) -> Result<(), SolverError> {
        if *have == Some(project) {
            return Ok(());
        }
        let t = Instant::now();
        let sym_s = self.assemble_at(m, x, project)?;
        *have = Some(project);
        rep.symbolic_s += sym_s;
        rep.factor_s += sym_s;
        rep.assembly_s += t.elapsed().as_secs_f64() - sym_s;
        Ok(())
    }

    /// Row balance γ of the KKT system (N/m): the settings' value, else the one of an
    /// earlier solve, else the mean diagonal of the Hessian in `trip` ([`Self::mean_diag`]).
    pub(super) fn gamma_for(&mut self, s: &Setup) -> f64 {
        if let Some(g) = self.settings.gamma {
            self.gamma = Some(g);
        }
        match self.gamma {
            Some(g) => g,
            None => {
                let g = self.mean_diag(s);
                self.gamma = Some(g);
                g
            }
        }
    }

    /// Evaluate the Hessian's triplets at `x` for γ when neither the settings nor an
    /// earlier solve gave γ (its mean diagonal, [`Self::gamma_for`]).
    pub(super) fn hessian_for_gamma(&mut self, e: &dyn Energy, x: &[f64], rep: &mut SolveReport) {
        if self.gamma.is_some() || self.settings.gamma.is_some() {
            return;
        }
        let t = Instant::now();
        self.evaluate_layout(e, x, false);
        rep.assembly_s += t.elapsed().as_secs_f64();
    }
}

#[cfg(test)]
mod tests {
    use super::super::test_energies::SpringChain;
    use super::super::test_energies::LINEAR_CHAIN;
    use super::super::{StaticProblem, StaticSettings};
    use super::*;
    use crate::solver::SolveStatus;

    /// An energy that scatters its Hessian: once the KKT matrix holds the layout the solver
    /// lets its triplets go, and a solve with other pins (a new layout) evaluates them again;
    /// every answer is the exact one, as a fresh solver's.
    #[test]
    fn a_scattering_energy_drops_its_triplets_and_lays_out_again_for_new_pins() {
        let settings = StaticSettings {
            tolerance: 1e-12,
            gamma: Some(1.0),
            ..Default::default()
        };
        let ends = StaticProblem {
            pinned: vec![0, 4],
            ..Default::default()
        };
        let middle = StaticProblem {
            pinned: vec![0, 2, 4],
            ..Default::default()
        };
        let chain = SpringChain {
            scatters: true,
            ..LINEAR_CHAIN
        };
        let mut solver = StaticSolver::new(settings).unwrap();
        let cases: [(&StaticProblem, [f64; 5], [f64; 5]); 3] = [
            (
                &ends,
                [0.0, 0.3, -0.2, 0.1, 1.0],
                [0.0, 0.25, 0.5, 0.75, 1.0],
            ),
            (
                &middle,
                [0.0, 0.3, 1.0, 0.1, 0.0],
                [0.0, 0.5, 1.0, 0.5, 0.0],
            ),
            (&ends, [0.0, 0.3, -0.2, 0.1, 2.0], [0.0, 0.5, 1.0, 1.5, 2.0]),
        ];
        for (p, start, exact) in cases {
            let mut x = start.to_vec();
            let rep = solver.solve(&chain, p, &mut x).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
            assert!(solver.trip.is_empty() && solver.trip_len == 16);
            let mut fresh_x = start.to_vec();
            let mut fresh = StaticSolver::new(settings).unwrap();
            fresh.solve(&chain, p, &mut fresh_x).unwrap();
            for ((a, b), e) in x.iter().zip(&fresh_x).zip(exact) {
                assert!(
                    (a - e).abs() < 1e-12 && (a - b).abs() < 1e-12,
                    "{x:?} {fresh_x:?}"
                );
            }
        }
        assert_eq!(solver.symbolic_analyses(), 3);
    }
}
