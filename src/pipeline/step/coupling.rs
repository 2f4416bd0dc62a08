//! The coupling within a frame: the interior stepped with the skin's force linearised, then
//! the skin solved on it, repeated from the frame's start (relaxed by Aitken's Δ²) until the
//! interior settles; and a muscle-driven frame that does not converge redone by tracking.

use super::interior::InteriorSchedule;
use super::{interior, skin, Scratch, StepOptions};
use crate::math::vector::{dot, norm};
use crate::pipeline::record::{StageRecord, Tracked, TrackedBecause};
use crate::pipeline::setup::{Model, State};

/// The state a frame starts from: the interior's positions (m), velocities (m/s) and time
/// (s), the last frame's target (m) and, for a frame that may be redone, the skin's
/// positions (flat, m). Copied once per frame, for the coupling's later passes and the
/// muscle-driven frame's redo alike.
pub(super) struct FrameStart {
    q: Vec<f64>,
    v: Vec<f64>,
    time: f64,
    last_target: Option<Vec<nalgebra::Vector3<f64>>>,
    x: Option<Vec<f64>>,
    /// The skin's pinned vertices at the frame's start (a try that met the skin passing
    /// through itself pins more; a redo starts from the frame's own pins).
    pinned: Option<Vec<usize>>,
}

impl FrameStart {
    /// The start of the frame `state` is at; the skin's positions too `with_skin`.
    fn of(state: &State, with_skin: bool) -> Self {
        let be = &state.interior;
        Self {
            q: be.q.clone(),
            v: be.v.clone(),
            time: be.time,
            last_target: state.last_target.clone(),
            x: state
                .skin
                .as_ref()
                .filter(|_| with_skin)
                .map(|s| s.x().to_vec()),
            pinned: state
                .skin
                .as_ref()
                .filter(|_| with_skin)
                .map(|s| s.pinned().to_vec()),
        }
    }

    /// Put the interior (and the last target) back to the frame's start.
    fn rewind_interior(&self, state: &mut State) {
        let be = &mut state.interior;
        be.q.clone_from(&self.q);
        be.v.clone_from(&self.v);
        be.time = self.time;
        state.last_target.clone_from(&self.last_target);
    }

    /// Put the interior and the skin back to the frame's start.
    fn restore(&self, state: &mut State) -> anyhow::Result<()> {
        self.rewind_interior(state);
        if let (Some(skin), Some(pinned)) = (state.skin.as_mut(), &self.pinned) {
            if skin.pinned() != pinned.as_slice() {
                skin.set_pinned(pinned)?;
            }
        }
        if let (Some(skin), Some(x)) = (state.skin.as_mut(), &self.x) {
            skin.set_x(x)?;
        }
        Ok(())
    }
}

/// [`advance_coupled`] under the frame's driver. A muscle-driven frame whose interior or
/// skin does not converge (or goes non-finite) is redone from its start driven by tracking
/// at its full stiffness while the muscles relax over the frame (activations from the last
/// frame's to rest across the sub-steps); the `fit` record says so, and the records sum
/// both tries. Holding the last activations instead left the stability sweep's sheet
/// compressed by 70 % in 0.1 s with a self-intersecting skin in its last frame; relaxing
/// them converges.
pub(super) fn advance_driven(
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    options: StepOptions,
    target: &[nalgebra::Vector3<f64>],
    k: usize,
    fit: &mut Option<StageRecord>,
) -> anyhow::Result<(StageRecord, Option<StageRecord>)> {
    let schedule = options.schedule;
    let muscled = state.muscles.as_ref().is_some_and(|m| !m.fallback);
    let passes = schedule.coupling_iterations.max(1);
    let start = (muscled || passes > 1).then(|| FrameStart::of(state, muscled));
    let result = advance_coupled(model, state, scratch, schedule, target, k, start.as_ref());
    let Some(start) = start.filter(|_| muscled) else {
        return result;
    };
    let converged = |r: &StageRecord| r.status.is_converged();
    let tracked = match &result {
        Ok((i, s)) if converged(i) && s.as_ref().is_none_or(converged) => return result,
        Ok((i, _)) if !converged(i) => Tracked {
            because: TrackedBecause::InteriorNotConverged,
            detail: i.status.to_string(),
        },
        Ok((_, s)) => Tracked {
            because: TrackedBecause::SkinNotConverged,
            detail: s.as_ref().map_or(String::new(), |s| s.status.to_string()),
        },
        Err(e) => Tracked {
            because: TrackedBecause::FrameFailed,
            detail: format!("{e:#}"),
        },
    };
    start.restore(state)?;
    let m = state
        .muscles
        .as_mut()
        .expect("a muscle-driven frame has muscles");
    m.fallback = true;
    m.relax();
    if let Some(f) = fit.as_mut() {
        f.tracked = Some(tracked);
    }
    let (interior, shell) =
        advance_coupled(model, state, scratch, schedule, target, k, Some(&start))?;
    Ok(match result {
        Ok((mut i, s)) => {
            i.then(interior);
            let shell = match (s, shell) {
                (Some(mut a), Some(b)) => {
                    a.then(b);
                    Some(a)
                }
                (_, b) => b,
            };
            (i, shell)
        }
        Err(_) => (interior, shell),
    })
}

/// The interior moves by less than this fraction of the frame's motion (RMS over the node
/// dofs) in a coupling pass when the coupling has settled.
const COUPLING_SETTLED: f64 = 1e-3;

/// Bounds of the Aitken relaxation factor of a coupling pass.
const RELAXATION: (f64, f64) = (0.1, 2.0);

/// The skin's tolerance in a coupling pass that is not the frame's last, over its own: its
/// force only feeds the next pass (muscle-driven demo frames 0–39 with the skin in the fit:
/// the wrinkles moved by 0.06 % per 2λ region at 100×, in 13 % less time; at 1000× they are
/// 14.93 % from tracking at κ = 1000 against 14.91 % at 100×, and the whole clip takes 1,100
/// skin iterations against 1,187).
pub(super) const PASS_LOOSENING: f64 = 1000.0;

/// Advance the interior, then solve the skin on it; repeated from the frame's start (up to
/// `schedule.coupling_iterations` passes) with the skin's force linearised about the last
/// pass's interior, until the interior moves by less than [`COUPLING_SETTLED`] of the frame's
/// motion. The passes are a fixed-point iteration x ← G(x) on the interior's state, relaxed by
/// Aitken's Δ² factor (Küttler and Wall 2008, as partitioned fluid–structure coupling does):
/// ω_k = −ω_{k−1} r_{k−1}ᵀ (r_k − r_{k−1}) / ‖r_k − r_{k−1}‖², r_k = G(x_{k−1}) − x_{k−1}, so a
/// coupling that swings about its answer (a pre-tensioned skin seen through its rest tangent)
/// settles and a slow one is sped up. The skin is solved at [`PASS_LOOSENING`] times its
/// tolerance except after the frame's last pass. A later pass differs from the first only by
/// a constant force (the skin's, solved, against the first pass's linear model of it), so
/// it is taken as the first pass's sub-steps' linear response to that force
/// ([`interior::linear_pass`]: two triangular solves per sub-step with the last Newton
/// factor, about half the cost of stepping again, with the same miss of the shape); where there is no such factor (conjugate gradients, a halved sub-step,
/// quasi-static frames) the sub-steps are taken again, starting Newton where the last
/// pass's ended. `start` is the frame's start (needed when a second pass may run). Returns
/// the interior's and the skin's records, summed over the passes.
pub(super) fn advance_coupled(
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    schedule: InteriorSchedule,
    target: &[nalgebra::Vector3<f64>],
    k: usize,
    start: Option<&FrameStart>,
) -> anyhow::Result<(StageRecord, Option<StageRecord>)> {
    // A held skin does not load the interior: a later pass would find the same interior.
    let passes = if interior::skin_is_held(schedule, state) {
        1
    } else {
        schedule.coupling_iterations.max(1)
    };
    let start = start.filter(|_| passes > 1);
    let mut interior = interior::advance(model, state, scratch, schedule, target, k, None)?;
    if let Some(skin) = state.skin.as_mut().filter(|_| schedule.skin_from_embedded) {
        let bq = skin.embedded_flat(&state.interior.q);
        skin.set_x(&bq)?;
    }
    let first_loosening = if start.is_some() { PASS_LOOSENING } else { 1.0 };
    let mut shell = solve_skin_on_interior(model, state, first_loosening, false)?;
    let Some(start) = start else {
        return Ok((interior, shell));
    };
    let q0 = &start.q;
    let mut residual = minus(&state.interior.q, q0);
    let mut omega = 1.0;
    for pass in 1..passes {
        let (x, xv) = (state.interior.q.clone(), state.interior.v.clone());
        let clock = std::time::Instant::now();
        if interior::linear_pass(model, state, scratch, schedule, &x) {
            interior.ms += clock.elapsed().as_secs_f64() * 1e3;
        } else {
            start.rewind_interior(state);
            let step = interior::advance(model, state, scratch, schedule, target, k, Some(&x))?;
            interior.then(step);
        }
        let r = minus(&state.interior.q, &x);
        omega = aitken(omega, &residual, &r);
        let be = &mut state.interior;
        for i in 0..x.len() {
            be.v[i] = xv[i] + omega * (be.v[i] - xv[i]);
            be.q[i] = x[i] + omega * r[i];
        }
        let settled = norm(&r) <= COUPLING_SETTLED * norm(&minus(&state.interior.q, q0));
        let loosening = if settled || pass + 1 == passes {
            1.0
        } else {
            PASS_LOOSENING
        };
        // Every earlier solve of the frame was loosened, and unchecked.
        let moved = shell.as_ref().is_some_and(|s| s.iterations > 0);
        if let (Some(s), Some(p)) = (
            shell.as_mut(),
            solve_skin_on_interior(model, state, loosening, moved)?,
        ) {
            s.then(p);
        }
        if settled {
            break;
        }
        residual = r;
    }
    Ok((interior, shell))
}

/// a − b, entry by entry.
pub(super) fn minus(a: &[f64], b: &[f64]) -> Vec<f64> {
    a.iter().zip(b).map(|(x, y)| x - y).collect()
}

/// Aitken's relaxation factor after `omega` from the last two fixed-point residuals,
/// within [`RELAXATION`]; `omega` again when they do not differ.
fn aitken(omega: f64, last: &[f64], now: &[f64]) -> f64 {
    let change = minus(now, last);
    let (along, sq) = (dot(last, &change), dot(&change, &change));
    if sq > 0.0 {
        (-omega * along / sq).clamp(RELAXATION.0, RELAXATION.1)
    } else {
        omega
    }
}

/// The skin's statics on the interior's current positions, when a skin is simulated, at
/// `loosening` times its tolerance ([`skin::solve_skin`]).
pub(super) fn solve_skin_on_interior(
    model: &Model,
    state: &mut State,
    loosening: f64,
    moved_unchecked: bool,
) -> anyhow::Result<Option<StageRecord>> {
    match state.skin.as_mut() {
        Some(skin) => Ok(Some(skin::solve_skin(
            skin,
            &state.interior.q,
            (loosening, moved_unchecked),
            model.outside.margin_m,
        )?)),
        None => Ok(None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A relaxed coupling pass: Aitken's factor halves a residual that flips sign (a
    /// swinging iteration), keeps ω on a repeated residual, and stays within its bounds.
    #[test]
    fn aitken_relaxation_damps_a_swing_and_stays_bounded() {
        let w = aitken(1.0, &[1.0, -2.0], &[-1.0, 2.0]);
        assert!((w - 0.5).abs() < 1e-12, "{w}");
        assert_eq!(aitken(0.7, &[1.0, 2.0], &[1.0, 2.0]), 0.7);
        // A residual that shrinks by 0.9 per pass asks for over-relaxation, capped at 2.
        assert_eq!(aitken(1.0, &[1.0], &[0.9]), RELAXATION.1);
        assert_eq!(aitken(1.0, &[1.0], &[2.0]), RELAXATION.0);
    }
}
