//! The `interior` step: the lattice advanced over one frame interval (backward Euler sub-steps,
//! or one quasi-static solve) under the drive and the skin's pull. Every term beyond the
//! interior's own elasticity is exactly quadratic or linearised, so it enters the solve as
//! `ExtraTerms`: the tracking stiffness Bᵀ k B with the skin's Bᵀ K_x B (the paper's two-step
//! coupling), the drive's force and the skin's force Bᵀ F_x.

use super::drive;
use super::Scratch;
use crate::coupling::embedded::EmbeddedShell;
use crate::fem::{ExtraTerms, SolveStatus};
use crate::pipeline::record::StageRecord;
use crate::pipeline::setup::{Model, State};
use anyhow::bail;
use nalgebra::Vector3;
use std::time::Instant;

/// How the interior steps each frame.
#[derive(Debug, Clone, Copy)]
pub struct InteriorSchedule {
    /// Backward Euler sub-steps per frame; 0 for one quasi-static solve.
    pub substeps: usize,
    /// Re-linearise the skin's stiffness Bᵀ K_x B every frame (else once, at rest).
    pub every_frame_stiffness: bool,
}

/// Advance the interior over frame `k` towards the welded `target` (m) and record it.
pub fn advance(
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
    target: &[Vector3<f64>],
    k: usize,
) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let mut record = StageRecord {
        status: "converged".into(),
        iterations: 0,
        residual: 0.0,
        ms: 0.0,
    };
    let q = &state.interior.q;
    let skin_force = coupling_terms(model, state.skin.as_ref(), q, scratch, schedule);
    let mut stiffness = scratch.combined.clone().unwrap_or_default();
    let base_len = stiffness.len();
    let dynamics = schedule.substeps > 0;
    for _ in 0..schedule.substeps.max(1) {
        let be = &state.interior;
        let mut force = drive::tracking_force(&model.tracking, &model.rows, &be.q, target);
        if let Some(m) = state.muscles.as_ref() {
            drive::add_muscle_terms(m, be, &mut stiffness, base_len, &mut force);
        }
        if let Some(fs) = &skin_force {
            for (f, g) in force.iter_mut().zip(fs) {
                *f += g;
            }
        }
        let extra = ExtraTerms {
            stiffness: &stiffness,
            force: &force,
        };
        let rep = if dynamics {
            state.interior.step(&scratch.zero_force, Some(&extra))?
        } else {
            state
                .interior
                .quasi_static(&scratch.zero_force, Some(&extra))?
        };
        record.iterations += rep.iterations;
        record.residual = rep.residual;
        match rep.status {
            SolveStatus::Converged => {}
            SolveStatus::IterationLimit => record.status = "iteration_limit".into(),
            SolveStatus::Stalled => record.status = "stalled".into(),
        }
    }
    if state.interior.q.iter().any(|v| !v.is_finite()) {
        bail!(
            "frame {k}: the interior became non-finite; lower dynamics.dt or stiffen the interior"
        );
    }
    record.ms = t.elapsed().as_secs_f64() * 1e3;
    Ok(record)
}

/// The skin's pull on the interior: its force Bᵀ F_x now (returned; the left-out skin's at
/// x = B q), and the combined stiffness of tracking and skin in `scratch`. The skin's stiffness Bᵀ K_x B (element
/// projected, the expensive part) is taken at the rest state once, or every frame when asked.
fn coupling_terms(
    model: &Model,
    skin: Option<&EmbeddedShell>,
    q: &[f64],
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
) -> Option<Vec<f64>> {
    let every = schedule.every_frame_stiffness;
    if let Some(skin) = skin {
        if scratch.skin_stiffness.is_none() || every {
            scratch.skin_stiffness = Some(skin.coupling_terms().0);
        }
    }
    if scratch.combined.is_none() || every {
        let mut all = model.tracking.stiffness.clone();
        if let Some((_, ks)) = &model.left_out {
            all.extend_from_slice(ks);
        }
        if let (Some(_), Some(ks)) = (skin, &scratch.skin_stiffness) {
            all.extend_from_slice(ks);
        }
        scratch.combined = Some(aggregate(all));
    }
    let nd = scratch.zero_force.len();
    let force = skin.map(|s| skin_force(s, &model.sim_vertices, &model.rows, nd));
    match (&model.left_out, force) {
        (Some((left, _)), force) => {
            let mut f = force.unwrap_or_else(|| vec![0.0; nd]);
            let riding = left.shell.embedded_positions(q);
            let x: Vec<f64> = riding.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
            let g = elastic_force(&left.shell, &x, &left.vertices, &model.rows, nd);
            for (a, b) in f.iter_mut().zip(&g) {
                *a += b;
            }
            Some(f)
        }
        (None, force) => force,
    }
}

/// Bᵀ F_x: the skin's elastic force F_x = −∇E_x at its current state, carried to the nodes
/// (flat over `nd` node dofs, N); shell vertex i is export vertex `verts[i]`.
pub fn skin_force(
    skin: &EmbeddedShell,
    verts: &[usize],
    rows: &[Vec<(usize, f64)>],
    nd: usize,
) -> Vec<f64> {
    elastic_force(skin, skin.x(), verts, rows, nd)
}

/// Bᵀ F_x of the skin at positions `x` (flat, m), as [`skin_force`].
fn elastic_force(
    skin: &EmbeddedShell,
    x: &[f64],
    verts: &[usize],
    rows: &[Vec<(usize, f64)>],
    nd: usize,
) -> Vec<f64> {
    use crate::math::Energy;
    let mut grad = vec![0.0; x.len()];
    skin.shell.eval(x, Some(&mut grad), None, false);
    let mut force = vec![0.0; nd];
    for (i, &v) in verts.iter().enumerate() {
        for &(n, w) in &rows[v] {
            for a in 0..3 {
                force[3 * n + a] -= w * grad[3 * i + a];
            }
        }
    }
    force
}

/// Triplets with duplicates summed, in (column, row) order: a compact, fixed layout.
pub fn aggregate(mut t: Vec<(usize, usize, f64)>) -> Vec<(usize, usize, f64)> {
    t.sort_unstable_by_key(|&(r, c, _)| (c, r));
    let mut out: Vec<(usize, usize, f64)> = Vec::with_capacity(t.len() / 4);
    for (r, c, v) in t {
        match out.last_mut() {
            Some(l) if l.0 == r && l.1 == c => l.2 += v,
            _ => out.push((r, c, v)),
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aggregate_sums_duplicates_in_column_order() {
        let t = vec![(1, 0, 1.0), (0, 0, 2.0), (1, 0, 0.5), (0, 1, 4.0)];
        assert_eq!(aggregate(t), vec![(0, 0, 2.0), (1, 0, 1.5), (0, 1, 4.0)]);
    }
}
