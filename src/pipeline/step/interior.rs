//! The `interior` step: the lattice advanced over one frame interval (backward Euler sub-steps,
//! or one quasi-static solve) under the drive and the skin's pull. Every term beyond the
//! interior's own elasticity is exactly quadratic or linearised, so it enters the solve as
//! `ExtraTerms`: the tracking stiffness Bᵀ k B with the skin's Bᵀ K_x B (the paper's two-step
//! coupling), the drive's force and the skin's force Bᵀ F_x.

use super::drive;
use super::Scratch;
use crate::coupling::embedded::EmbeddedShell;
use crate::coupling::embedding::Embedding;
use crate::fem::{ExtraTerms, SolveReport, SolveStatus};
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
    /// Time between frames (s): frame k is at time k · `frame_interval`.
    pub frame_interval: f64,
    /// Most interior–skin passes per frame (≥ 1; `solver.coupling_iterations`).
    pub coupling_iterations: usize,
    /// The muscles hold the skin's pull at the state the interior reaches
    /// ([`crate::scene::SkinHold::Reached`]): while they drive, the skin does not
    /// load the interior.
    pub skin_held: bool,
    /// Each frame's skin starts its solve on the embedded surface B q rather than where the
    /// last frame left it: a still rig's shapes, each solved alone from rest, where the skin
    /// at rest is far from the shape but B q is near it.
    pub skin_from_embedded: bool,
}

/// Whether the skin's pull on the interior is held by the muscles this frame: under
/// [`InteriorSchedule::skin_held`] while the muscles drive (a frame redone by tracking feels
/// the skin again). Held, the pull cancels against the muscles' hold at every state, so
/// neither its force nor its stiffness enters the interior's solves.
pub fn skin_is_held(schedule: InteriorSchedule, state: &State) -> bool {
    schedule.skin_held && state.muscles.as_ref().is_some_and(|m| !m.fallback)
}

/// Halvings of one sub-step at most: a backward Euler step whose Newton solve does not
/// converge is retried from its start as two steps of half the length, down to 1/16 of the
/// sub-step; the record counts the halvings.
pub const MAX_HALVINGS: usize = 4;

/// Advance the interior over frame `k` towards the welded `target` (m) and record it, with
/// the skin's force linearised about node positions `about` (flat, m: where the skin's
/// current state was solved; default the interior's current positions). A later coupling
/// pass of the frame (`about` given) starts each sub-step's Newton where the last pass's
/// ended ([`Scratch::substep_ends`]).
pub fn advance(
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
    target: &[Vector3<f64>],
    k: usize,
    about: Option<&[f64]>,
) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let mut record = StageRecord {
        status: SolveStatus::Converged,
        iterations: 0,
        residual: 0.0,
        ms: 0.0,
        halvings: 0,
        load_steps: 0,
        ..Default::default()
    };
    let q = about.unwrap_or(&state.interior.q);
    // A later coupling pass of the frame (`about` given) keeps the frame's first tangent.
    let refresh = about.is_none();
    let held = skin_is_held(schedule, state);
    let skin = state.skin.as_ref().filter(|_| !held);
    let skin_force = coupling_terms(model, skin, q, scratch, schedule, (refresh, held));
    let mut starts = match about {
        Some(_) => std::mem::take(&mut scratch.substep_ends),
        None => Vec::new(),
    };
    scratch.substep_ends.clear();
    // Only a frame that may take another pass keeps where its sub-steps ended.
    let keep_ends = schedule.coupling_iterations > 1;
    let from = state.last_target.take().unwrap_or_else(|| target.to_vec());
    let simulated = scratch.skin_stiffness.as_deref();
    let skin_parts = if held {
        [None, None]
    } else {
        skin_parts(model, simulated.filter(|_| state.skin.is_some()))
    };
    let mut load = StepLoad {
        frame_q: q.to_vec(),
        skin_parts,
        stiffness: scratch.combined.take().unwrap_or_default(),
        base_len: 0,
        layout: scratch.combined_layout,
        skin_force,
        from: &from,
        target,
        zero_force: &scratch.zero_force,
        start: None,
        interval: (
            (k as f64 - 1.0) * schedule.frame_interval,
            schedule.frame_interval,
        ),
    };
    load.base_len = load.stiffness.len();
    if schedule.substeps == 0 {
        let rep = solve_once(model, state, &mut load, false, 1.0)?;
        record.iterations += rep.iterations;
        note(&mut record, &rep);
    } else {
        let n = schedule.substeps as f64;
        for i in 0..schedule.substeps {
            let span = (i as f64 / n, (i + 1) as f64 / n);
            load.start =
                (starts.len() == schedule.substeps).then(|| std::mem::take(&mut starts[i]));
            let halvings = record.halvings;
            step_adaptive(model, state, &mut load, (span, 0), &mut record)?;
            if keep_ends && record.halvings == halvings {
                scratch.substep_ends.push(state.interior.q.clone());
            }
        }
    }
    load.stiffness.truncate(load.base_len);
    scratch.combined = Some(load.stiffness);
    if about.is_none() {
        // Kept for the later passes' linear response only by a frame that may take them
        // and whose sub-steps all took the frame's time step.
        let keep = keep_ends && record.halvings == 0;
        scratch.first_pass = load.skin_force.filter(|_| keep).map(|force| FirstPass {
            q0: load.frame_q,
            force,
            q: state.interior.q.clone(),
            v: state.interior.v.clone(),
        });
    }
    state.last_target = Some(target.to_vec());
    if state.interior.q.iter().any(|v| !v.is_finite()) {
        bail!(
            "frame {k}: the interior became non-finite; lower dynamics.dt or stiffen the interior"
        );
    }
    record.ms = t.elapsed().as_secs_f64() * 1e3;
    Ok(record)
}

/// A frame's first coupling pass, for its later passes' linear response
/// ([`linear_pass`]): where the frame started (flat, m), the skin's force there that the
/// pass's linear model took (flat, N), and where the pass ended (m, m/s).
#[derive(Debug, Clone)]
pub struct FirstPass {
    q0: Vec<f64>,
    force: Vec<f64>,
    q: Vec<f64>,
    v: Vec<f64>,
}

/// A later coupling pass of the frame about node positions `about` (flat, m; where the skin
/// was just solved) as the linear response of the first pass's sub-steps, instead of taking
/// them again: the pass's skin force model F(about) − K_x (y − about) differs from the first
/// pass's F(q₀) − K_x (y − q₀) by the constant c = F(about) − F(q₀) + K_x (about − q₀) (the
/// tracking, muscles and targets are the same), so the pass ends at the first pass's end
/// plus the steps' response to c ([`crate::fem::BackwardEuler::linear_response`], two
/// triangular solves per sub-step with the last Newton factor). Sets the interior's q and v
/// and returns true; false (nothing changed) when there is no first pass to respond from (a
/// sub-step of it was halved) or no factor to respond with (conjugate gradients,
/// quasi-static frames), and the caller takes the pass's steps again.
pub fn linear_pass(
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
    about: &[f64],
) -> bool {
    let Some(first) = scratch.first_pass.take() else {
        return false;
    };
    let force = coupling_terms(
        model,
        state.skin.as_ref(),
        about,
        scratch,
        schedule,
        (false, false),
    );
    let Some(mut c) = force else {
        return false;
    };
    for (ci, f0) in c.iter_mut().zip(&first.force) {
        *ci -= f0;
    }
    let moved: Vec<f64> = about.iter().zip(&first.q0).map(|(a, b)| a - b).collect();
    let simulated = scratch.skin_stiffness.as_deref();
    let skin_parts = skin_parts(model, simulated.filter(|_| state.skin.is_some()));
    for part in skin_parts.into_iter().flatten() {
        crate::math::sparse::triplets_mul_add(part, &moved, &mut c);
    }
    let Some((dy, dv)) = state.interior.linear_response(&c, schedule.substeps) else {
        scratch.first_pass = Some(first);
        return false;
    };
    let be = &mut state.interior;
    be.q = first.q.iter().zip(&dy).map(|(a, b)| a + b).collect();
    be.v = first.v.iter().zip(&dv).map(|(a, b)| a + b).collect();
    scratch.first_pass = Some(first);
    true
}

/// The skin's stiffness on the lattice (N/m, triplets over node dofs), in its parts: the
/// simulated skin's Bᵀ K_x B (`simulated`, when a skin is simulated) and the left-out skin's.
fn skin_parts<'a>(
    model: &'a Model,
    simulated: Option<&'a [Triplet]>,
) -> [Option<&'a [Triplet]>; 2] {
    [
        simulated,
        model.left_out.as_ref().map(|(_, k)| k.as_slice()),
    ]
}

/// One stiffness entry (row dof, column dof, N/m).
type Triplet = (usize, usize, f64);

/// What every solve of one frame shares: the combined stiffness (tracking and skin, taken
/// from the scratch for the frame; muscle terms are appended after `base_len` per solve) and
/// its layout key ([`Scratch::combined_layout`]), the skin's force at the frame's start
/// positions `frame_q` (m) and the skin's stiffness (its parts: simulated and left out), the
/// last frame's and this frame's targets (m), a zero external force, where the next step's
/// Newton starts when not at the inertial predictor (m; taken by that step) and the frame
/// interval (its start and length, s).
struct StepLoad<'a> {
    frame_q: Vec<f64>,
    skin_parts: [Option<&'a [Triplet]>; 2],
    stiffness: Vec<(usize, usize, f64)>,
    base_len: usize,
    layout: u64,
    skin_force: Option<Vec<f64>>,
    from: &'a [Vector3<f64>],
    target: &'a [Vector3<f64>],
    zero_force: &'a [f64],
    start: Option<Vec<f64>>,
    interval: (f64, f64),
}

/// One backward Euler step of the stepper's current dt (`dynamics`) or one quasi-static solve,
/// under the drive at the current positions towards the target at fraction `at` of the frame
/// interval (linear between the last frame's and this frame's), and the frame's skin force.
fn solve_once(
    model: &Model,
    state: &mut State,
    load: &mut StepLoad,
    dynamics: bool,
    at: f64,
) -> anyhow::Result<SolveReport> {
    // The muscles at this step's end, as the target below.
    let activations = state.muscles.as_ref().map(|m| m.at(at));
    if let (Some(m), Some(a)) = (state.muscles.as_ref(), &activations) {
        drive::actuate(m, a, &mut state.interior)?;
    }
    let be = &state.interior;
    let target: Vec<Vector3<f64>> = if at >= 1.0 {
        load.target.to_vec()
    } else {
        load.from
            .iter()
            .zip(load.target)
            .map(|(a, b)| a + (b - a) * at)
            .collect()
    };
    let mut force = drive::tracking_force(&model.tracking, &model.embedding, &be.q, &target);
    if let Some(m) = state.muscles.as_ref() {
        let a = activations.as_deref().unwrap_or_default();
        drive::add_muscle_terms(m, a, be, &mut load.stiffness, load.base_len, &mut force);
        if m.fallback {
            drive::fallback_tracking(&model.tracking, &mut load.stiffness, &mut force);
        }
    }
    if let Some(fs) = &load.skin_force {
        // The skin's force at this step's start, from its linear model about the frame's
        // start: F_x(q) = F_x(q_frame) − K_x (q − q_frame). The step's quadratic model is
        // about its own start, so a sub-step must not re-apply the frame's force.
        let dq: Vec<f64> = be.q.iter().zip(&load.frame_q).map(|(a, b)| b - a).collect();
        if dq.iter().any(|&d| d != 0.0) {
            for part in load.skin_parts.into_iter().flatten() {
                crate::math::sparse::triplets_mul_add(part, &dq, &mut force);
            }
        }
        for (f, g) in force.iter_mut().zip(fs) {
            *f += g;
        }
    }
    let extra = ExtraTerms {
        stiffness: &load.stiffness,
        force: &force,
        // Muscle terms appended to the combined stiffness may change its layout.
        layout: (load.stiffness.len() == load.base_len).then_some(load.layout),
    };
    Ok(if dynamics {
        let inertial = model.head_motion.as_ref().and_then(|m| {
            let end = load.interval.0 + at * load.interval.1;
            let acc = m.acceleration(end, state.interior.settings.dt);
            (!acc.is_zero()).then(|| state.interior.frame_force(&acc))
        });
        let f_ext = inertial.as_deref().unwrap_or(load.zero_force);
        let start = load.start.take();
        state
            .interior
            .step_from(f_ext, Some(&extra), start.as_deref())?
    } else {
        state.interior.quasi_static(load.zero_force, Some(&extra))?
    })
}

/// One sub-step over the fraction `span` of the frame interval, retried as two half steps
/// (recursively, [`MAX_HALVINGS`] deep, each moving the target half as far) when its Newton
/// solve does not converge; the halved steps' outcome is what the record keeps.
fn step_adaptive(
    model: &Model,
    state: &mut State,
    load: &mut StepLoad,
    (span, depth): ((f64, f64), usize),
    record: &mut StageRecord,
) -> anyhow::Result<()> {
    let start = (
        state.interior.q.clone(),
        state.interior.v.clone(),
        state.interior.time,
    );
    let rep = solve_once(model, state, load, true, span.1)?;
    record.iterations += rep.iterations;
    let ok = rep.status == SolveStatus::Converged && rep_finite(state);
    if ok || depth >= MAX_HALVINGS {
        note(record, &rep);
        return Ok(());
    }
    let be = &mut state.interior;
    (be.q, be.v, be.time) = start;
    let dt = be.settings.dt;
    be.settings.dt = 0.5 * dt;
    record.halvings += 1;
    let mid = 0.5 * (span.0 + span.1);
    let result = [(span.0, mid), (mid, span.1)]
        .into_iter()
        .try_for_each(|half| step_adaptive(model, state, load, (half, depth + 1), record));
    state.interior.settings.dt = dt;
    result
}

/// Whether the interior's positions are all finite.
fn rep_finite(state: &State) -> bool {
    state.interior.q.iter().all(|v| v.is_finite())
}

/// Record a solve's residual and, when it did not converge, its status.
fn note(record: &mut StageRecord, rep: &SolveReport) {
    record.residual = rep.residual;
    if !rep.status.is_converged() {
        record.status = rep.status;
    }
}

/// The skin's pull on the interior: its force Bᵀ F_x now (returned; the left-out skin's at
/// x = B q), and the combined stiffness of tracking and skin in `scratch`. The skin's
/// stiffness Bᵀ K_x B (element projected, the expensive part) is the model's, taken at the
/// rest state, or re-taken at each frame's first coupling pass (`refresh`) when asked. When
/// the muscles hold the skin (`held`, [`skin_is_held`]; `skin` is then `None`) there is no
/// pull: the combined stiffness is the tracking's alone and no force is returned.
fn coupling_terms(
    model: &Model,
    skin: Option<&EmbeddedShell>,
    q: &[f64],
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
    (refresh, held): (bool, bool),
) -> Option<Vec<f64>> {
    let every = schedule.every_frame_stiffness && refresh && !held;
    if let Some(skin) = skin {
        if every {
            scratch.skin_stiffness = Some(skin.coupling_terms().0);
        } else if scratch.skin_stiffness.is_none() {
            scratch.skin_stiffness = Some(model.skin_stiffness.clone());
        }
    }
    // Rebuilt when stale, or when the last frame held the skin and this one does not (or
    // the other way round).
    if scratch.combined.is_none() || every || scratch.combined_is_held != held {
        let mut all = model.tracking.stiffness.clone();
        if let Some((_, ks)) = model.left_out.as_ref().filter(|_| !held) {
            all.extend_from_slice(ks);
        }
        if let (Some(_), Some(ks)) = (skin, &scratch.skin_stiffness) {
            all.extend_from_slice(ks);
        }
        let combined = aggregate(all);
        scratch.combined_layout = crate::fem::triplet_layout_key(&combined);
        scratch.combined = Some(combined);
        scratch.combined_is_held = held;
    }
    if held {
        return None;
    }
    let nd = scratch.zero_force.len();
    let force = skin.map(|s| skin_force(s, &model.sim_vertices, &model.embedding, nd));
    match (&model.left_out, force) {
        (Some((left, _)), force) => {
            let mut f = force.unwrap_or_else(|| vec![0.0; nd]);
            let x = left.shell.embedded_flat(q);
            let g = elastic_force(&left.shell, &x, &left.vertices, &model.embedding, nd);
            for (a, b) in f.iter_mut().zip(&g) {
                *a += b;
            }
            Some(f)
        }
        (None, force) => force,
    }
}

/// Bᵀ F_x: the skin's elastic force F_x = −∇E_x at its current state, carried to the nodes
/// (flat over `nd` node dofs, N); shell vertex i is export vertex `verts[i]` of `embedding`.
pub fn skin_force(
    skin: &EmbeddedShell,
    verts: &[usize],
    embedding: &Embedding,
    nd: usize,
) -> Vec<f64> {
    // The last skin solve's own gradient at x: no second pass over the skin.
    let mut force = vec![0.0; nd];
    embedding.spread_gradient_at(verts, &skin.elastic_gradient(), &mut force);
    force
}

/// Bᵀ F_x of the skin at positions `x` (flat, m), as [`skin_force`].
fn elastic_force(
    skin: &EmbeddedShell,
    x: &[f64],
    verts: &[usize],
    embedding: &Embedding,
    nd: usize,
) -> Vec<f64> {
    use crate::math::Energy;
    let mut grad = vec![0.0; x.len()];
    skin.shell.eval(x, Some(&mut grad), None, false);
    let mut force = vec![0.0; nd];
    embedding.spread_gradient_at(verts, &grad, &mut force);
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
