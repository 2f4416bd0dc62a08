//! The frame step, one stage per module in the order they run: [`blend`] the frame's target,
//! [`drive`] the interior towards it (tracking force, or fitted muscle activations),
//! advance the [`interior`], solve the [`skin`], and [`compose`] the exported surface.
//! The step holds scratch only ([`Scratch`]); the state it advances is the set-up's
//! [`State`].

pub mod blend;
pub mod compose;
pub mod coupling;
pub mod drive;
pub mod interior;
pub mod skin;

use super::plan::SkinHold;
use super::record::{FrameRecord, NotSimulated};
use super::setup::{outside, Model, State};
use crate::io::load::Rig;
use compose::{Composed, SurfaceMaps};
use coupling::advance_driven;
use interior::InteriorSchedule;

/// Scratch kept between frames: the coupling stiffness (rebuilt when stale) and a zero force.
#[derive(Debug, Default)]
pub struct Scratch {
    /// Bᵀ K_x B of the skin (N/m, triplets over node dofs), once computed.
    pub skin_stiffness: Option<Vec<(usize, usize, f64)>>,
    /// Tracking and skin stiffness summed into one compact triplet list (N/m).
    pub combined: Option<Vec<(usize, usize, f64)>>,
    /// The layout key of `combined` ([`crate::fem::triplet_layout_key`]), taken when it is
    /// built, so that the interior's steps need not hash it again.
    pub combined_layout: u64,
    /// The frame's first coupling pass, when later passes may follow
    /// ([`interior::linear_pass`]).
    pub first_pass: Option<interior::FirstPass>,
    /// A zero external force over the node dofs (N).
    pub zero_force: Vec<f64>,
    /// Node positions at the end of each sub-step of the frame's last coupling pass (flat,
    /// m; empty when a sub-step was halved): where the next pass's sub-steps start Newton.
    pub substep_ends: Vec<Vec<f64>>,
    /// `combined` holds the tracking's stiffness alone, the skin's being held by the muscles
    /// ([`interior::skin_is_held`]).
    pub combined_is_held: bool,
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
    /// The stepping `scene` asks for under `plan` (its interior sub-steps per frame and its
    /// frames per second) with `driver`, the driver the model was set up with.
    pub fn of(
        scene: &crate::scene::Scene,
        plan: &super::plan::Plan,
        driver: &super::plan::Driver,
    ) -> Self {
        let (substeps, fps) = (plan.substeps, plan.fps);
        Self {
            schedule: InteriorSchedule {
                substeps,
                every_frame_stiffness: scene.solver.skin_stiffness
                    == Some(crate::scene::SkinStiffness::EveryFrame),
                coupling_iterations: scene.solver.coupling_iterations.unwrap_or(
                    if driver.skin_in_fit(scene) {
                        SKIN_IN_FIT_PASSES
                    } else {
                        1
                    },
                ),
                frame_interval: 1.0 / fps,
                skin_held: driver.skin_hold(scene) == Some(SkinHold::Reached),
                skin_from_embedded: !plan.animated,
            },
            simulated_surface: scene.export.surface == Some(crate::scene::ExportSurface::Simulated),
            fps,
        }
    }
}

impl StepOptions {
    /// The options for a pre-rolled run's first frame: the interior solved quasi-statically
    /// (at rest in the frame's pose, no velocity) and the skin started on the embedded
    /// surface B q, as a still rig's shapes are.
    pub fn settled(self) -> Self {
        Self {
            schedule: InteriorSchedule {
                substeps: 0,
                skin_from_embedded: true,
                ..self.schedule
            },
            ..self
        }
    }
}

/// Coupling passes per frame by default when generated muscles are fitted with the skin in
/// the loop: the skin then stands pre-tensioned against them, and one pass per frame swings
/// about the shape or lags it, so the frame takes two relaxed passes
/// ([`coupling::advance_coupled`]), which miss the shape as three do, in less time.
const SKIN_IN_FIT_PASSES: usize = 2;

impl Model {
    /// How the export vertices follow the lattice, the target and the skin.
    pub fn surface_maps(&self) -> SurfaceMaps<'_> {
        SurfaceMaps {
            embedding: &self.embedding,
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
    if let Some(skin) = state.skin.as_mut() {
        let pins = model.pose_maps.pins(&model.outside, &model.skin_mesh, k);
        if pins != skin.pinned() {
            skin.set_pinned(&pins)?;
        }
    }
    let mut fit = match state.muscles.as_mut() {
        Some(m) => Some(drive::fit_activations(m, target)?),
        None => None,
    };
    let (interior, shell) = advance_driven(model, state, scratch, options, target, k, &mut fit)?;
    let q = &state.interior.q;
    let x = state.skin.as_ref().map(|s| s.x());
    let fade = outside::refined_fade(&model.outside, &model.target_of, k);
    let mut composed = compose::compose(
        model.surface_maps(),
        target,
        (q, x, fade.as_deref()),
        options.simulated_surface,
        k,
    )?;
    let cleared = if options.simulated_surface || x.is_none() {
        0
    } else {
        outside::clear_new_crossings(
            &model.skin_mesh,
            &composed.target,
            &mut composed.wrinkled,
            model.outside.margin_m,
        )
    };
    let record = FrameRecord {
        frame: k,
        time_s: k as f64 / options.fps,
        fit,
        interior: Some(interior),
        shell,
        wrinkle_depth_max_m: composed.depth_max,
        shape_miss_m: composed.shape_miss,
        shape_motion_m: compose::rms_distance(&composed.target, &model.skin_mesh.positions),
        jaw_deg: state
            .muscles
            .as_ref()
            .and_then(|m| m.fitter.forward.bone.as_ref())
            .map(|(_, bone)| bone.angle_of(q).to_degrees()),
        not_simulated: None,
        crossing_cleared: cleared,
    };
    Ok((record, composed))
}

/// Frame `k` with morph `weights` not simulated (`why`): its surface is the blend shape on
/// the refined skin, without wrinkles.
pub fn unsimulated_frame(
    rig: &Rig,
    weights: &[f64],
    k: usize,
    model: &Model,
    (fps, why): (f64, NotSimulated),
) -> anyhow::Result<(FrameRecord, Composed)> {
    let welded = blend::blend_frame(rig, weights, &model.welded_of_loaded, model.welded_count, k)?;
    let target = compose::carry(&model.target_of, &welded);
    let record = FrameRecord {
        frame: k,
        time_s: k as f64 / fps,
        fit: None,
        interior: None,
        shell: None,
        wrinkle_depth_max_m: 0.0,
        shape_miss_m: 0.0,
        shape_motion_m: compose::rms_distance(&target, &model.skin_mesh.positions),
        jaw_deg: None,
        not_simulated: Some(why),
        crossing_cleared: 0,
    };
    let composed = Composed {
        wrinkled: target.clone(),
        target,
        depth_max: 0.0,
        shape_miss: 0.0,
    };
    Ok((record, composed))
}

#[cfg(test)]
mod tests {
    use super::coupling::{minus, solve_skin_on_interior, PASS_LOOSENING};
    use super::*;
    use crate::math::vector::norm;
    use crate::pipeline::plan::Driver;
    use crate::pipeline::setup::test_support::{lifted_target, small_model, small_model_with};

    fn options(substeps: usize) -> StepOptions {
        StepOptions {
            schedule: InteriorSchedule {
                substeps,
                every_frame_stiffness: false,
                frame_interval: 1.0 / 30.0,
                coupling_iterations: 1,
                skin_held: false,
                skin_from_embedded: false,
            },
            simulated_surface: false,
            fps: 30.0,
        }
    }

    /// The embedded surface's rise at the sheet's middle vertex (m).
    fn middle_rise(model: &Model, state: &State) -> f64 {
        let mid = model.welded_count / 2;
        let rest = model.embedding.positions(&model.lattice.rest_flat());
        let now = model.embedding.positions(&state.interior.q);
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
        assert!(interior.status.is_converged(), "{interior:?}");
        assert!(rec.shell.as_ref().unwrap().status.is_converged());
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
        assert!(interior.status.is_converged());
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
                source: crate::scene::MuscleSource::Auto,
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

    /// Gauss–Newton re-linearisations of the fit (`muscles.gauss_newton`) reach the pipeline's
    /// fitter: each frame's fit record counts them, and the fit's residual (then the nonlinear
    /// equilibrium's, not the linear model's) and the interior's miss of the lifted sheet
    /// stay as small as the linear fit's.
    #[test]
    fn gauss_newton_re_linearises_each_frames_fit() {
        let run = |gauss_newton: usize| {
            let driver = Driver::Muscles {
                source: crate::scene::MuscleSource::Auto,
            };
            let (model, mut state, face) =
                small_model_with(driver, 0, |s| s.muscles.gauss_newton = Some(gauss_newton));
            let mut scratch = Scratch::new(model.lattice.node_count());
            let target = lifted_target(&face, &model, 1.0);
            let mut o = options(0);
            o.schedule.skin_held = true;
            let (r, _) = step_to_target(&target, 0, &model, &mut state, &mut scratch, o).unwrap();
            let fit = r.fit.expect("a fit record");
            println!(
                "gauss_newton {gauss_newton}: {} fits, residual {:.3e} m, miss {:.3e} m",
                fit.iterations, fit.residual, r.shape_miss_m
            );
            (fit.iterations, fit.residual, r.shape_miss_m)
        };
        let (linear, nonlinear) = (run(0), run(2));
        assert_eq!((linear.0, nonlinear.0), (1, 3));
        assert!(nonlinear.1 <= 1.5 * linear.1, "{nonlinear:?} vs {linear:?}");
        assert!(
            nonlinear.2 <= 1.05 * linear.2,
            "{nonlinear:?} vs {linear:?}"
        );
    }

    /// The lifted sheet held for 8 quasi-static frames under muscles holding the skin as
    /// `hold` says (`muscles.skin_hold`) with `passes` coupling passes: the interior's miss of
    /// the lifted surface per frame (m) and the lift's motion (m).
    fn held_lift(hold: SkinHold, passes: usize) -> (Vec<f64>, f64) {
        let driver = Driver::Muscles {
            source: crate::scene::MuscleSource::Auto,
        };
        let (model, mut state, face) =
            small_model_with(driver, 0, |s| s.muscles.skin_hold = Some(hold));
        let mut scratch = Scratch::new(model.lattice.node_count());
        let target = lifted_target(&face, &model, 1.0);
        let mut o = options(0);
        o.schedule.coupling_iterations = passes;
        o.schedule.skin_held = hold == SkinHold::Reached;
        let mut misses = Vec::new();
        let mut motion = 0.0;
        for k in 0..8 {
            let (r, _) = step_to_target(&target, k, &model, &mut state, &mut scratch, o).unwrap();
            assert!(r.shell.as_ref().unwrap().status.is_converged());
            misses.push(r.shape_miss_m);
            motion = r.shape_motion_m;
        }
        let shown: Vec<String> = misses.iter().map(|m| format!("{m:.3e}")).collect();
        println!("skin held {hold}, {passes} passes: miss per frame {shown:?} m of {motion:.2e} m");
        (misses, motion)
    }

    /// Muscles that hold the skin make the lift against its resistance: held for 8
    /// quasi-static frames, the interior misses the lifted surface by much less than under
    /// muscles that leave the skin's pull on it (`none`), whose actuations only balance the
    /// flesh and tracking. Held at each shape (`shapes`), one coupling pass per frame swings
    /// about the answer (the skin pre-tensioned, seen through its rest tangent); three
    /// relaxed passes settle it within 3 % of the motion in the first frame, two in the
    /// second. Held at the state reached (`reached`, the default), one pass makes the shape
    /// more closely (measured 1.6e-5 against 2.3e-5 m of 6.0e-4 m; the lattice fit held on
    /// the subdivided surface), the same in every frame.
    #[test]
    fn muscles_that_hold_the_skin_make_the_shape_against_it() {
        let (without, motion) = held_lift(SkinHold::None, 3);
        let (swinging, _) = held_lift(SkinHold::Shapes, 1);
        let (with, _) = held_lift(SkinHold::Shapes, 3);
        let (two, _) = held_lift(SkinHold::Shapes, 2);
        let (reached, _) = held_lift(SkinHold::Reached, 1);
        assert!(without[7] > 0.2 * motion, "the skin resists");
        assert!(with[7] < 0.3 * without[7], "{} vs {}", with[7], without[7]);
        // Settled from the first frame on.
        let settled = |m: &f64| (m - with[7]).abs() < 0.03 * motion;
        assert!(with.iter().all(settled), "{with:?}");
        // Two passes (the default with the skin at the shapes) settle from the second frame on.
        assert!(two[1..].iter().all(settled) && !settled(&two[0]), "{two:?}");
        // One pass swings between frames by more than the settled miss.
        assert!((swinging[6] - swinging[7]).abs() > with[7], "{swinging:?}");
        // Held where it is, in one pass, from the first frame on.
        assert!(
            reached
                .iter()
                .all(|&m| m < 1.25 * with[7] && (m - reached[7]).abs() < 0.01 * m),
            "{reached:?} vs {with:?}"
        );
    }

    /// Muscles holding the skin at the state reached cancel its pull on the interior
    /// exactly: the muscle-driven frame lands on the same interior whatever the skin's state
    /// (here its start stretched by 1 %), and the skin is still solved on it.
    /// Not held, or once the frame is redone by tracking, the interior feels the skin again.
    #[test]
    fn a_held_skin_does_not_load_the_interior() {
        let run = |stretch: f64, held: bool| {
            let driver = Driver::Muscles {
                source: crate::scene::MuscleSource::Auto,
            };
            let (model, mut state, face) = small_model(driver, 0);
            if let Some(skin) = state.skin.as_mut() {
                let x: Vec<f64> = skin.x().iter().map(|v| v * (1.0 + stretch)).collect();
                skin.set_x(&x).unwrap();
            }
            let mut scratch = Scratch::new(model.lattice.node_count());
            let target = lifted_target(&face, &model, 1.0);
            let mut o = options(2);
            o.schedule.skin_held = held;
            let (r, _) = step_to_target(&target, 0, &model, &mut state, &mut scratch, o).unwrap();
            assert!(r.shell.as_ref().unwrap().status.is_converged());
            assert_eq!(interior::skin_is_held(o.schedule, &state), held);
            state.muscles.as_mut().unwrap().fallback = true;
            assert!(!interior::skin_is_held(o.schedule, &state), "tracked");
            state.interior.q
        };
        let apart = |a: &[f64], b: &[f64]| norm(&minus(a, b));
        let (q, moved) = (run(0.0, true), run(0.01, true));
        assert!(
            apart(&q, &moved) <= 1e-12 * norm(&q),
            "{}",
            apart(&q, &moved)
        );
        let (free, free_moved) = (run(0.0, false), run(0.01, false));
        assert!(apart(&free, &free_moved) > 1e-9, "the skin loads it");
        assert!(apart(&q, &free) > 1e-9, "the hold changes the frame");
    }

    /// A later coupling pass taken as the linear response of the first pass's sub-steps
    /// ([`interior::linear_pass`]) lands where taking the sub-steps again does: on the
    /// lifted sheet driven by muscles fitted with the skin (two backward Euler sub-steps),
    /// within 0.1 % of the pass's own move over three frames (measured 0.002–0.02 %).
    #[test]
    fn a_linear_coupling_pass_lands_where_the_stepped_pass_does() {
        let driver = Driver::Muscles {
            source: crate::scene::MuscleSource::Auto,
        };
        let mut o = options(2);
        o.schedule.coupling_iterations = 2;
        let run = |linear: bool| {
            let (model, mut state, face) = small_model_with(driver.clone(), 2, |_| {});
            let mut scratch = Scratch::new(model.lattice.node_count());
            let mut out = Vec::new();
            for k in 0..3 {
                let target = lifted_target(&face, &model, 0.3 * (k + 1) as f64);
                let (q0, v0, t0) = (
                    state.interior.q.clone(),
                    state.interior.v.clone(),
                    state.interior.time,
                );
                let last = state.last_target.clone();
                let pass = |state: &mut State, scratch: &mut Scratch, about: Option<&[f64]>| {
                    interior::advance(&model, state, scratch, o.schedule, &target, k, about)
                        .unwrap();
                };
                pass(&mut state, &mut scratch, None);
                solve_skin_on_interior(&model, &mut state, PASS_LOOSENING, false).unwrap();
                let x = state.interior.q.clone();
                if linear {
                    assert!(interior::linear_pass(
                        &model,
                        &mut state,
                        &mut scratch,
                        o.schedule,
                        &x
                    ));
                } else {
                    let be = &mut state.interior;
                    (be.q, be.v, be.time) = (q0, v0, t0);
                    state.last_target = last;
                    pass(&mut state, &mut scratch, Some(&x));
                }
                out.push((x, state.interior.q.clone()));
                solve_skin_on_interior(&model, &mut state, 1.0, true).unwrap();
            }
            out
        };
        let (linear, stepped) = (run(true), run(false));
        for (k, ((_, ql), (xs, qs))) in linear.iter().zip(&stepped).enumerate() {
            let moved = norm(&minus(qs, xs));
            let apart = norm(&minus(ql, qs));
            println!("frame {k}: the stepped pass moves {moved:.3e} m, the linear one lands {apart:.3e} m from it");
            assert!(
                moved > 0.0 && apart < 1e-3 * moved,
                "frame {k}: {apart} of {moved}"
            );
        }
    }

    /// A frame whose activation fit failed is driven by the tracking at the tracking driver's
    /// full stiffness: with the muscles relaxed, the interior then rises as a tracking-driven
    /// run does, and clearly more than under the muscles' weak tracking alone.
    #[test]
    fn a_frame_whose_fit_failed_is_driven_by_full_tracking() {
        let muscles = || Driver::Muscles {
            source: crate::scene::MuscleSource::Auto,
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
                None,
            )
            .unwrap();
            assert!(rec.status.is_converged());
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
