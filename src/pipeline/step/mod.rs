//! The frame step, one stage per module in the order they run: [`blend`] the frame's target,
//! [`drive`] the interior towards it (tracking force, or fitted muscle activations),
//! advance the [`interior`], solve the [`skin`], and [`compose`] the exported surface.
//! The step holds scratch only ([`Scratch`]); the state it advances is the set-up's
//! [`State`].

pub mod blend;
pub mod compose;
pub mod drive;
pub mod interior;
pub mod skin;

use super::record::FrameRecord;
use super::setup::{Model, State};
use crate::io::load::Rig;
use compose::{Composed, SurfaceMaps};
use interior::InteriorSchedule;

/// Scratch kept between frames: the coupling stiffness (rebuilt when stale) and a zero force.
#[derive(Debug, Default)]
pub struct Scratch {
    /// Bᵀ K_x B of the skin (N/m, triplets over node dofs), once computed.
    pub skin_stiffness: Option<Vec<(usize, usize, f64)>>,
    /// Tracking and skin stiffness summed into one compact triplet list (N/m).
    pub combined: Option<Vec<(usize, usize, f64)>>,
    /// A zero external force over the node dofs (N).
    pub zero_force: Vec<f64>,
}

impl Scratch {
    /// Scratch for a lattice of `nodes` nodes.
    pub fn new(nodes: usize) -> Self {
        Self {
            zero_force: vec![0.0; 3 * nodes],
            ..Self::default()
        }
    }
}

/// How every frame is stepped.
#[derive(Debug, Clone, Copy)]
pub struct StepOptions {
    /// How the interior steps.
    pub schedule: InteriorSchedule,
    /// Export the simulated skin x itself instead of target + wrinkles.
    pub simulated_surface: bool,
    /// Frames per second (Hz), for the frame's time.
    pub fps: f64,
}

impl StepOptions {
    /// The stepping `scene` asks for, with `substeps` interior sub-steps per frame at `fps`
    /// frames per second (Hz).
    pub fn of(scene: &crate::scene::Scene, substeps: usize, fps: f64) -> Self {
        Self {
            schedule: InteriorSchedule {
                substeps,
                every_frame_stiffness: match scene.solver.skin_stiffness.as_deref() {
                    Some(when) => when == "every_frame",
                    // Muscles fitted against the skin's force at their shapes pre-tension it:
                    // the interior must see its current tangent, or the staggered coupling
                    // swings (a lifted sheet's interior alternated 2.93 / 0.56 mm about its
                    // 2 mm lift frame after frame with the rest tangent).
                    None => {
                        scene.muscles.skin_in_fit == Some(true)
                            && scene.muscles.source.as_deref() == Some("auto")
                    }
                },
                frame_interval: 1.0 / fps,
            },
            simulated_surface: scene.export.surface.as_deref() == Some("simulated"),
            fps,
        }
    }
}

impl Model {
    /// How the export vertices follow the lattice, the target and the skin.
    pub fn surface_maps(&self) -> SurfaceMaps<'_> {
        SurfaceMaps {
            rows: &self.rows,
            target_of: &self.target_of,
            sim_vertices: &self.sim_vertices,
        }
    }
}

/// Step frame `k` with morph `weights`: blend → drive → interior → skin → compose. Returns the
/// frame's record and surfaces.
pub fn step_frame(
    rig: &Rig,
    weights: &[f64],
    k: usize,
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    options: StepOptions,
) -> anyhow::Result<(FrameRecord, Composed)> {
    let welded_of_loaded = &model.welded_of_loaded;
    let target = blend::blend_frame(rig, weights, welded_of_loaded, model.welded_count, k)?;
    step_to_target(&target, k, model, state, scratch, options)
}

/// Step frame `k` towards the welded `target` (m): drive → interior → skin → compose.
pub fn step_to_target(
    target: &[nalgebra::Vector3<f64>],
    k: usize,
    model: &Model,
    state: &mut State,
    scratch: &mut Scratch,
    options: StepOptions,
) -> anyhow::Result<(FrameRecord, Composed)> {
    let fit = match state.muscles.as_mut() {
        Some(m) => {
            let record = drive::fit_activations(m, target)?;
            drive::actuate(m, &mut state.interior)?;
            Some(record)
        }
        None => None,
    };
    let interior = interior::advance(model, state, scratch, options.schedule, target, k)?;
    let q = &state.interior.q;
    let shell = match state.skin.as_mut() {
        Some(skin) => Some(skin::solve_skin(skin, q)?),
        None => None,
    };
    let x = state.skin.as_ref().map(|s| s.x());
    let composed = compose::compose(
        model.surface_maps(),
        target,
        q,
        x,
        options.simulated_surface,
        k,
    )?;
    let record = FrameRecord {
        frame: k,
        time_s: k as f64 / options.fps,
        fit,
        interior: Some(interior),
        shell,
        wrinkle_depth_max_m: composed.depth_max,
        shape_miss_m: composed.shape_miss,
        shape_motion_m: compose::rms_distance(&composed.target, &model.skin_mesh.positions),
    };
    Ok((record, composed))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::plan::Driver;
    use crate::pipeline::setup::test_support::{lifted_target, small_model, small_model_with};

    fn options(substeps: usize) -> StepOptions {
        StepOptions {
            schedule: InteriorSchedule {
                substeps,
                every_frame_stiffness: false,
                frame_interval: 1.0 / 30.0,
            },
            simulated_surface: false,
            fps: 30.0,
        }
    }

    /// The embedded surface's rise at the sheet's middle vertex (m).
    fn middle_rise(model: &Model, state: &State) -> f64 {
        let mid = model.welded_count / 2;
        let rest = compose::embed_rows(&model.rows, &model.lattice.rest_flat());
        let now = compose::embed_rows(&model.rows, &state.interior.q);
        now[mid].z - rest[mid].z
    }

    #[test]
    fn tracking_frames_follow_the_lift_and_the_skin_converges() {
        let (model, mut state, face) = small_model(Driver::Tracking, 0);
        let mut scratch = Scratch::new(model.lattice.node_count());
        let target = lifted_target(&face, &model, 1.0);
        let (rec, composed) =
            step_to_target(&target, 0, &model, &mut state, &mut scratch, options(0)).unwrap();
        let interior = rec.interior.as_ref().unwrap();
        assert_eq!(interior.status, "converged", "{interior:?}");
        assert_eq!(rec.shell.as_ref().unwrap().status, "converged");
        assert!(rec.fit.is_none());
        // The tracking pulls the middle up most of the 2 mm lift (κ = 10: ~90 %).
        let rise = middle_rise(&model, &state);
        assert!(rise > 1.2e-3 && rise < 2.1e-3, "rise {rise}");
        // A smooth lift at this scale does not wrinkle: the detail is far below the lift.
        assert!(composed.depth_max < 2e-4, "depth {}", composed.depth_max);
        assert_eq!(composed.wrinkled.len(), model.skin_mesh.positions.len());
        // The combined coupling stiffness was built once and is kept.
        assert!(scratch.combined.is_some() && scratch.skin_stiffness.is_some());
    }

    #[test]
    fn backward_euler_substeps_carry_inertia_past_the_quasi_static_answer() {
        let (model, mut state, face) = small_model(Driver::Tracking, 2);
        let mut scratch = Scratch::new(model.lattice.node_count());
        let target = lifted_target(&face, &model, 1.0);
        let (rec, _) =
            step_to_target(&target, 0, &model, &mut state, &mut scratch, options(2)).unwrap();
        let interior = rec.interior.as_ref().unwrap();
        assert_eq!(interior.status, "converged");
        assert!(
            interior.iterations >= 2,
            "one solve per sub-step: {interior:?}"
        );
        assert!(
            state.interior.v.iter().any(|v| v.abs() > 1e-3),
            "the lattice moves"
        );
        let dynamic_rise = middle_rise(&model, &state);
        let (model_qs, mut state_qs, _) = small_model(Driver::Tracking, 0);
        let mut scratch_qs = Scratch::new(model_qs.lattice.node_count());
        step_to_target(
            &target,
            0,
            &model_qs,
            &mut state_qs,
            &mut scratch_qs,
            options(0),
        )
        .unwrap();
        let static_rise = middle_rise(&model_qs, &state_qs);
        // Backward Euler on the stiff tracking spring reaches the target within the first
        // sub-step and its velocity carries it a little past (by m v / (k h) ≪ the lift).
        let (d, s) = (dynamic_rise, static_rise);
        assert!(d > s + 1e-6 && d < 1.2 * s, "{d} vs {s}");
    }

    #[test]
    fn muscles_generated_from_the_lift_are_fitted_and_drive_the_interior() {
        let (model, mut state, face) = small_model(
            Driver::Muscles {
                source: "auto".into(),
            },
            0,
        );
        assert!(!state.muscles.as_ref().unwrap().activations.is_empty());
        let mut scratch = Scratch::new(model.lattice.node_count());
        let target = lifted_target(&face, &model, 1.0);
        let (rec, _) =
            step_to_target(&target, 0, &model, &mut state, &mut scratch, options(0)).unwrap();
        let fit = rec.fit.as_ref().expect("a fit record");
        assert!(fit.iterations >= 1 && fit.residual.is_finite());
        let a = &state.muscles.as_ref().unwrap().activations;
        assert!(a.iter().any(|&x| x > 0.05), "activations {a:?}");
        assert!(middle_rise(&model, &state) > 0.5e-3);
    }

    /// Muscles fitted with the skin in the loop (`muscles.skin_in_fit`) make the lift against
    /// the skin's resistance: held for 8 quasi-static frames, the interior misses the lifted
    /// surface by much less than with muscles fitted without the skin, whose actuations only
    /// balance the flesh and tracking. The interior must see the skin's current tangent (the
    /// default with the skin in the fit): with its rest tangent the staggered coupling swings
    /// about the lift from frame to frame and ends further off than without the skin.
    #[test]
    fn muscles_fitted_with_the_skin_make_the_shape_against_it() {
        let miss = |skin_in_fit: bool, every_frame: bool| {
            let driver = Driver::Muscles {
                source: "auto".into(),
            };
            let (model, mut state, face) =
                small_model_with(driver, 0, |s| s.muscles.skin_in_fit = Some(skin_in_fit));
            let mut scratch = Scratch::new(model.lattice.node_count());
            let target = lifted_target(&face, &model, 1.0);
            let mut o = options(0);
            o.schedule.every_frame_stiffness = every_frame;
            let mut misses = Vec::new();
            let mut motion = 0.0;
            for k in 0..8 {
                let (r, _) =
                    step_to_target(&target, k, &model, &mut state, &mut scratch, o).unwrap();
                assert_eq!(r.shell.as_ref().unwrap().status, "converged");
                misses.push(r.shape_miss_m);
                motion = r.shape_motion_m;
            }
            println!("skin in the fit {skin_in_fit}, current tangent {every_frame}: miss per frame {:?} m of {motion:.2e} m", misses.iter().map(|m| format!("{:.3e}", m)).collect::<Vec<_>>());
            (misses, motion)
        };
        let (without, motion) = miss(false, true);
        let (with, _) = miss(true, true);
        let (swinging, _) = miss(true, false);
        let last = |m: &[f64]| m[m.len() - 1];
        assert!(last(&without) > 0.2 * motion, "the skin resists");
        assert!(last(&with) < 0.3 * last(&without));
        // Settled: the last frames agree.
        assert!((with[6] - with[7]).abs() < 0.01 * with[7]);
        // With the rest tangent the interior swings by more than the settled miss.
        assert!((swinging[6] - swinging[7]).abs() > last(&with));
    }

    /// A frame whose activation fit failed is driven by the tracking at the tracking driver's
    /// full stiffness: with the muscles relaxed, the interior then rises as a tracking-driven
    /// run does, and clearly more than under the muscles' weak tracking alone.
    #[test]
    fn a_frame_whose_fit_failed_is_driven_by_full_tracking() {
        let muscles = || Driver::Muscles {
            source: "auto".into(),
        };
        let rise_after = |driver: Driver, fallback: bool| {
            let (model, mut state, face) = small_model(driver, 0);
            if let Some(m) = state.muscles.as_mut() {
                m.fallback = fallback;
            }
            let mut scratch = Scratch::new(model.lattice.node_count());
            let target = lifted_target(&face, &model, 1.0);
            let rec = interior::advance(
                &model,
                &mut state,
                &mut scratch,
                options(0).schedule,
                &target,
                0,
            )
            .unwrap();
            assert_eq!(rec.status, "converged");
            middle_rise(&model, &state)
        };
        let tracking = rise_after(Driver::Tracking, false);
        let fallback = rise_after(muscles(), true);
        let weak = rise_after(muscles(), false);
        println!("rise: tracking {tracking:.3e}, fallback {fallback:.3e}, weak {weak:.3e} m");
        assert!((fallback - tracking).abs() < 1e-3 * tracking);
        assert!(weak < 0.7 * tracking);
    }
}
