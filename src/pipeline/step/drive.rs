//! The `drive` step: what pulls the interior towards the frame's target. With tracking, the
//! force of the tracking energy Bᵀ k (t − B q) (its stiffness Bᵀ k B is constant, in the
//! model); with muscles, first the activations fitted to the target (the `fit` stage, a QP),
//! then their active energy linearised at the interior's state.

use crate::coupling::embedding::Embedding;
use crate::fem::BackwardEuler;
use crate::pipeline::record::{StageRecord, Tracked, TrackedBecause};
use crate::pipeline::setup::interior::Tracking;
use crate::pipeline::setup::muscles::MuscleDrive;
use nalgebra::Vector3;
use std::time::Instant;

/// Fit the muscle activations to the welded `target` (m) and record the QP's outcome.
pub fn fit_activations(
    muscles: &mut MuscleDrive,
    target: &[Vector3<f64>],
) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let f = muscles.fitter.fit_frame(target)?;
    muscles.previous = std::mem::replace(&mut muscles.activations, f.activations.clone());
    muscles.fallback = f.status != crate::muscle::FrameStatus::Fitted;
    let tracked = muscles.fallback.then(|| Tracked {
        because: TrackedBecause::FitFailed,
        detail: format!("{:?} (clarabel: {})", f.status, f.clarabel_status),
    });
    Ok(StageRecord {
        status: f.qp_status,
        tracked,
        iterations: f.gauss_newton + 1,
        residual: f.rms_residual,
        ms: t.elapsed().as_secs_f64() * 1e3,
        halvings: 0,
        load_steps: 0,
        ..Default::default()
    })
}

/// Tracking at full stiffness for a frame whose fit failed: the tracking `force` (N) scaled
/// from the muscles' weak κ to the tracking driver's, and the stiffness that makes up the
/// difference appended to `stiffness` (N/m).
pub fn fallback_tracking(
    tracking: &Tracking,
    stiffness: &mut Vec<(usize, usize, f64)>,
    force: &mut [f64],
) {
    use crate::pipeline::setup::interior::{MUSCLE_TRACKING, TRACKING_STIFFNESS};
    let ratio = TRACKING_STIFFNESS / MUSCLE_TRACKING;
    force.iter_mut().for_each(|f| *f *= ratio);
    stiffness.extend(
        tracking
            .stiffness
            .iter()
            .map(|&(r, c, k)| (r, c, k * (ratio - 1.0))),
    );
}

/// Actuate the interior's rest state for `activations` (the muscles' at a step's end,
/// [`MuscleDrive::at`]: the actuation muscles' combined rest change, [`crate::muscle::blend`];
/// fibre muscles act through
/// [`add_muscle_terms`]) and turn the jaw's bone nodes by its muscle's activation (pinned,
/// they hold that through the step).
pub fn actuate(
    muscles: &MuscleDrive,
    activations: &[f64],
    stepper: &mut BackwardEuler,
) -> anyhow::Result<()> {
    let forward = &muscles.fitter.forward;
    let d = forward
        .blend()
        .field(&stepper.interior, forward.muscles(), activations);
    stepper.interior.set_actuation(d)?;
    if let Some((m, bone)) = &muscles.fitter.forward.bone {
        bone.place(activations[*m], &mut stepper.q);
    }
    Ok(())
}

/// The tracking energy's force Bᵀ k (t − B q) at node positions `q` (m) as node forces (flat
/// over node dofs, N); welded vertex v is point v of `embedding` and has target `target[v]`
/// (m).
pub fn tracking_force(
    tracking: &Tracking,
    embedding: &Embedding,
    q: &[f64],
    target: &[Vector3<f64>],
) -> Vec<f64> {
    let mut force = vec![0.0; q.len()];
    for (v, &k) in tracking.k.iter().enumerate() {
        let f = (target[v] - embedding.point(v, q)) * k;
        embedding.spread_point(v, &f, &mut force);
    }
    force
}

/// Add the fibre muscles' active energy at `activations` (dimensionless), linearised at the
/// stepper's state (PSD stiffness, like the skin's terms), to `force` (N) and to `stiffness`
/// after its first `base_len` triplets (N/m; the triplet layout is the same every step).
pub fn add_muscle_terms(
    muscles: &MuscleDrive,
    activations: &[f64],
    stepper: &BackwardEuler,
    stiffness: &mut Vec<(usize, usize, f64)>,
    base_len: usize,
    force: &mut [f64],
) {
    let act =
        crate::muscle::ActiveEnergy::new(&stepper.interior, muscles.fitter.muscles(), activations);
    let (k, f) = crate::muscle::linearised_terms(&act, &stepper.q);
    stiffness.truncate(base_len);
    stiffness.extend_from_slice(&k);
    for (a, b) in force.iter_mut().zip(&f) {
        *a += b;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tracking_force_pulls_the_embedded_point_to_its_target() {
        // One vertex halfway between nodes 0 and 1, both at the origin; target 2 m up x.
        let tracking = Tracking {
            k: vec![3.0],
            stiffness: Vec::new(),
        };
        let rows = Embedding::from_rows(vec![vec![(0, 0.5), (1, 0.5)]], 2);
        let q = vec![0.0; 6];
        let f = tracking_force(&tracking, &rows, &q, &[Vector3::new(2.0, 0.0, 0.0)]);
        // k (t − Bq) = 6 N, split by the weights.
        assert_eq!(f, vec![3.0, 0.0, 0.0, 3.0, 0.0, 0.0]);
        let at_target = tracking_force(
            &tracking,
            &rows,
            &[2.0, 0.0, 0.0, 2.0, 0.0, 0.0],
            &[Vector3::new(2.0, 0.0, 0.0)],
        );
        assert_eq!(at_target, vec![0.0; 6]);
    }
}
