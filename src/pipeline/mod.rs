//! The whole job on one rig: load, weld the face into a skin, build the lattice, select the
//! skin that can wrinkle and refine it for the wavelength, drive the interior, solve the skin,
//! and hand back the wrinkled frames,
//! running only the stages the scene needs (the report says which ran and why the others did
//! not).
//!
//! [`run`] reads as its stages: the [`plan`] checks the rig and the options, the [`setup`]
//! builds the model and the initial state (weld, lattice, select, refine, clusters,
//! interior, muscles), and the [`step`] advances every frame (blend → drive → interior → skin →
//! compose), each stage in its own module with its own record for the report ([`record`]).
//!
//! Per frame k (time k / fps):
//! 1. the blend shapes give the target surface t_k (the artist's shape);
//! 2. the interior (lattice) is driven towards it: with `muscles.source = "none"` by a stiff
//!    quadratic tracking energy ½ Σ_v k_v ‖t_v − (B q)_v‖², k_v = κ E_q A_v / ℓ (A_v the vertex
//!    area, ℓ the cell size, κ = [`TRACKING_STIFFNESS`]); it is exactly quadratic, so it enters
//!    the backward Euler step as `ExtraTerms` (force Bᵀ k (t − B q), stiffness Bᵀ k B) together
//!    with the skin's force Bᵀ F_x and stiffness Bᵀ K_x B (the paper's two-step coupling);
//!    sub-steps of at most `dynamics.dt` cover the frame interval;
//! 3. the skin is solved quasi-statically with H x = H B q from the last frame's state;
//! 4. the exported surface is the blend-shape target plus the skin's high-frequency part:
//!    t + (x − B q). H (x − B q) = 0, so this adds exactly the wrinkles (what the constraints
//!    leave free) to the artist's shape; `export.surface = "simulated"` writes x itself.
//!
//! A clip is history-dependent (velocities, the wrinkle pattern), so a run limited to frames
//! A:B simulates frames 0..B and writes A..B: its frames are identical to the same frames of
//! an unsplit run, which is what `furrow merge` relies on. With a pre-roll P it simulates
//! max(0, A − P)..B instead, starting at rest in the pose of its first frame: the history
//! fades within the pre-roll, and chunks of a clip run in parallel.

pub mod chunk;
pub mod farm;
pub mod frames;
pub mod layer;
pub mod plan;
pub mod preview;
pub mod record;
pub mod report;
pub mod setup;
pub mod shapes;
pub mod step;
pub mod synthetic;

pub use setup::interior::{INTERIOR_TOLERANCE, MUSCLE_TRACKING, TRACKING_STIFFNESS};
pub use setup::skin::DEGENERATE_QUALITY;

use crate::io::load::Rig;
use crate::io::origin::VertexOrigin;
use crate::io::split::FaceMap;
use crate::scene::Scene;
use frames::FrameRange;
use nalgebra::Vector3;
use plan::Plan;
use record::{FrameRecord, Stage, StagePlan, Totals};
use report::RunReport;
use setup::{Log, Model, State};
use std::time::Instant;
use step::{Scratch, StepOptions};

/// What to run.
#[derive(Debug, Clone)]
pub struct RunOptions {
    /// The scene (materials, lattice, solver, export settings).
    pub scene: Scene,
    /// Where it came from (for the report).
    pub scene_path: Option<String>,
    /// Frames per second at which the clip is sampled.
    pub fps: f64,
    /// Frames to write (`None`: all).
    pub frames: Option<FrameRange>,
    /// Frames simulated before the first written one, from rest (`None`: the clip's whole
    /// history, from frame 0). The first of them is solved quasi-statically (the interior at
    /// rest in that pose, the skin from the embedded surface), so a chunk of a farm starts
    /// near the clip's state without simulating its whole past.
    pub preroll: Option<usize>,
}

impl RunOptions {
    /// Every frame of the clip at 30 frames per second under `scene`, the whole history
    /// simulated, no scene file named.
    pub fn new(scene: Scene) -> Self {
        Self {
            scene,
            scene_path: None,
            fps: 30.0,
            frames: None,
            preroll: None,
        }
    }

    /// Only the frames `range` written.
    pub fn frames(mut self, range: FrameRange) -> Self {
        self.frames = Some(range);
        self
    }

    /// The clip sampled at `fps` frames per second (Hz).
    pub fn fps(mut self, fps: f64) -> Self {
        self.fps = fps;
        self
    }

    /// `frames` frames simulated from rest before the first written one.
    pub fn preroll(mut self, frames: usize) -> Self {
        self.preroll = Some(frames);
        self
    }
}

/// The result of a run: the exported face frames and the report.
#[derive(Debug, Clone)]
pub struct RunOutput {
    /// How the refined skin maps onto the loaded face (the wrinkle layer's seams,
    /// primitives and subdivision S).
    pub face_map: FaceMap,
    /// The rig's weights of each written frame (for a still rig: shape k alone at 1).
    pub weights: Vec<Vec<f64>>,
    /// Whether the rig is animated (else each frame is one shape solved alone from rest).
    pub animated: bool,
    /// Triangles of the exported face.
    pub triangles: Vec<[usize; 3]>,
    /// Origin of each exported vertex in the loaded face.
    pub origin: Vec<VertexOrigin>,
    /// Wrinkled positions per written frame (world, m).
    pub frames: Vec<Vec<Vector3<f64>>>,
    /// Blend-shape-only positions per written frame (world, m), same vertices.
    pub smooth: Vec<Vec<Vector3<f64>>>,
    /// The report.
    pub report: RunReport,
}

/// The part of a run a progress report counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// The set-up: its steps done of all.
    Setup,
    /// The frames: simulated of all.
    Frames,
}

/// Progress callback: (phase, done, total).
pub type Progress<'a> = &'a dyn Fn(Phase, usize, usize);

/// Run the pipeline on a loaded rig: plan, set up, step every frame, report.
pub fn run(rig: &Rig, opts: &RunOptions, progress: Progress) -> anyhow::Result<RunOutput> {
    let wall = Instant::now();
    let scene = &opts.scene;
    let plan = Plan::new(rig, opts)?;
    let mut log = Log::default();
    log.stages.push(plan.load_stage(rig));
    let (mut model, mut state) = setup::set_up(rig, scene, &plan, &mut log, progress)?;
    if state.skin.is_some() {
        log.stages.push(shell_stage(&plan, &model));
    }
    let options = StepOptions::of(scene, &plan, &model.driver);
    let mut scratch = Scratch::new(model.lattice.node_count());
    let mut per_frame = Vec::new();
    let mut out = Frames::default();
    let mut totals = Totals::default();
    let end = plan.range.end;
    if plan.animated {
        // A clip's history leads to its first written frame.
        for k in plan.first_simulated()..end {
            progress(Phase::Frames, k, end);
            let frame_options = if k == plan.first_simulated() && k > 0 {
                options.settled()
            } else {
                options
            };
            let w = &plan.weights[k];
            let (record, composed) =
                step::step_frame(rig, w, k, &model, &mut state, &mut scratch, frame_options)?;
            totals.add(&record);
            per_frame.push(record);
            if k >= plan.range.start {
                out.wrinkled.push(composed.wrinkled);
                out.smooth.push(composed.target);
            }
        }
    } else {
        // A still rig's shapes are each solved alone, from rest, and only those that
        // compress some skin; side by side when the state can be copied.
        let to_solve = (plan.range.start..end)
            .filter(|&k| model.pose_maps.solves(k))
            .count();
        let mut extra = Vec::new();
        for _ in 1..shapes::worker_count(to_solve) {
            match state.at_rest_copy(&model, scene, &plan)? {
                Some(copy) => extra.push(copy),
                None => break,
            }
        }
        let solved = shapes::solve_shapes(
            rig,
            (&model, &plan.weights, plan.fps),
            plan.range.start..plan.range.end,
            (&mut state, extra),
            options,
            progress,
        )?;
        for (record, composed) in solved {
            if record.not_simulated.is_none() {
                totals.add(&record);
            }
            per_frame.push(record);
            out.wrinkled.push(composed.wrinkled);
            out.smooth.push(composed.target);
        }
    }
    progress(Phase::Frames, end, end);
    if plan.animated {
        model.outside.jolt = setup::outside::jolt(
            &model.outside,
            &model.target_of,
            (&out.wrinkled, &out.smooth),
            plan.range.start,
        );
    }
    totals.frames_written = out.wrinkled.len();
    totals.wall_s = wall.elapsed().as_secs_f64();
    let written = plan.range.start - plan.first_simulated();
    let outcome = Outcome {
        log,
        per_frame: per_frame.split_off(written),
        totals,
    };
    let report = finish_report(rig, opts, &plan, &model, &state, outcome);
    Ok(RunOutput {
        face_map: model.face_map(),
        weights: plan.weights[plan.range.start..plan.range.end].to_vec(),
        animated: plan.animated,
        triangles: model.skin_mesh.triangles.clone(),
        origin: model.origin.clone(),
        frames: out.wrinkled,
        smooth: out.smooth,
        report,
    })
}

/// A run's set-up up to its muscles, without stepping a frame: what fitting activations
/// alone (`furrow fit`) needs to fit in the interior the pipeline runs.
pub struct MuscleSetUp {
    /// The run's plan (its frames' weights, materials, driver).
    pub plan: Plan,
    /// The model (welded skin, lattice, tracking).
    pub model: Model,
    /// The muscles, their fitter (the QP's J in this interior) and the jaw's hinge.
    pub muscles: setup::muscles::MuscleDrive,
    /// The set-up's stage records and warnings.
    pub log: Log,
}

impl MuscleSetUp {
    /// The blended face of frame `k` as the welded skin's positions (m): the fit's target.
    pub fn target(&self, rig: &Rig, k: usize) -> anyhow::Result<Vec<Vector3<f64>>> {
        let m = &self.model;
        step::blend::blend_frame(
            rig,
            &self.plan.weights[k],
            &m.welded_of_loaded,
            m.welded_count,
            k,
        )
    }
}

/// Set up a run of `rig` under `opts` as [`run`] does (weld, lattice, selection, skin,
/// muscles) and stop before the first frame. An error names the rig when its driver is not
/// muscles or they cannot be made (a scene that leaves `muscles.source` out gets the
/// muscles' error, not the run's fallback to tracking).
pub fn set_up_muscles(
    rig: &Rig,
    opts: &RunOptions,
    progress: Progress,
) -> anyhow::Result<MuscleSetUp> {
    let mut opts = opts.clone();
    opts.scene
        .muscles
        .source
        .get_or_insert(crate::scene::MuscleSource::Auto);
    let plan = Plan::new(rig, &opts)?;
    if plan.driver == plan::Driver::Tracking {
        anyhow::bail!(
            "{}: no muscles to fit (`muscles.source = \"none\"`, or no blend shape moves the face)",
            rig.path.display()
        );
    }
    let mut log = Log::default();
    log.stages.push(plan.load_stage(rig));
    let (model, state) = setup::set_up(rig, &opts.scene, &plan, &mut log, progress)?;
    let muscles = state
        .muscles
        .ok_or_else(|| anyhow::anyhow!("{}: the set-up made no muscles", rig.path.display()))?;
    Ok(MuscleSetUp {
        plan,
        model,
        muscles,
        log,
    })
}

/// The written frames' surfaces (m).
#[derive(Default)]
struct Frames {
    wrinkled: Vec<Vec<Vector3<f64>>>,
    smooth: Vec<Vec<Vector3<f64>>>,
}

/// The `shell` stage's record: the skin statics and its scales; where the thickness varies,
/// its range (each triangle refined for its own wavelength, the clusters widening with it).
fn shell_stage(plan: &Plan, model: &Model) -> StagePlan {
    let [h_min, h_max] = plan.skin.thickness;
    let varies = if h_max > h_min {
        format!(
            " where thinnest; the thickness varies from {:.3} to {:.3} mm (λ to {:.2} mm), each triangle refined for its own λ and the constraint clusters widening with it",
            h_min * 1e3,
            h_max * 1e3,
            plan.skin.lambda_max * 1e3,
        )
    } else {
        String::new()
    };
    let lids = match plan.skin.lids {
        Some((n, h)) => format!(
            "; the lids ({n} face triangles the blink shapes move) are {:.2} mm thick (`skin.lids`)",
            h * 1e3
        ),
        None => String::new(),
    };
    StagePlan::ran(
        Stage::Shell,
        format!(
            "quasi-static skin with H x = H B q, λ = {:.2} mm, σ = {:.2} mm{varies}{lids}",
            plan.skin.lambda * 1e3,
            model.sigma * 1e3
        ),
        0.0,
    )
}

/// What the frame loop leaves for the report.
struct Outcome {
    log: Log,
    per_frame: Vec<FrameRecord>,
    totals: Totals,
}

/// The run's report: the plan, the sizes of what was built, each stage's record, every
/// written frame's record, the totals and the warnings.
fn finish_report(
    rig: &Rig,
    opts: &RunOptions,
    plan: &Plan,
    model: &Model,
    state: &State,
    outcome: Outcome,
) -> RunReport {
    let Outcome {
        mut log,
        per_frame,
        totals,
    } = outcome;
    if totals.frames_not_converged > 0 {
        log.warnings.push(format!(
            "{} of {} frames did not converge in every stage (see per_frame)",
            totals.frames_not_converged, totals.frames_simulated
        ));
    }
    let first = plan.first_simulated();
    if plan.range.start > first && plan.animated {
        let from = match plan.preroll {
            Some(_) => "a pre-roll from rest",
            None => "the clip's history",
        };
        log.warnings.push(format!(
            "frames {first}..{} were simulated but not written ({from} leads to frame {})",
            plan.range.start, plan.range.start
        ));
    }
    let face = rig.face();
    let sizes = serde_json::json!({
        "loaded_vertices": face.positions.len(),
        "skin_vertices": model.skin_mesh.positions.len(),
        "skin_triangles": model.skin_mesh.triangles.len(),
        "simulated_vertices": model.sim_vertices.len(),
        "lattice_elements": model.lattice.elements.len(),
        "lattice_cell_m": model.lattice.cell_size,
        "lattice_nodes": model.lattice.node_count(),
        "bone_nodes": model.lattice.pinned_count(),
        "clusters": state.skin.as_ref().map_or(0, |s| s.cluster_stats().clusters),
        "muscles": state.muscles.as_ref().map_or(0, |m| m.fitter.muscles().len()),
    });
    let m = &plan.materials;
    let [h_min, h_max] = plan.skin.thickness;
    RunReport {
        furrow: env!("CARGO_PKG_VERSION").into(),
        rig: rig.path.display().to_string(),
        scene: opts.scene_path.clone(),
        face: face.name.clone(),
        rig_scale: rig.scale.clone(),
        fps: opts.fps,
        frames: [plan.range.start, plan.range.end],
        preroll: plan.preroll,
        materials: serde_json::json!({
            "skin": m.skin,
            "interior": m.interior,
            "skin_thickness_m": { "min": h_min, "max": h_max },
            "wavelength_m": { "min": plan.skin.lambda, "max": plan.skin.lambda_max },
        }),
        wavelength_m: plan.skin.lambda,
        sigma_m: model.sigma,
        sizes,
        stages: log.stages,
        per_frame,
        totals,
        warnings: log.warnings,
        muscles: state
            .muscles
            .as_ref()
            .map(|m| m.made.clone())
            .unwrap_or_default(),
        jaw: state
            .muscles
            .as_ref()
            .and_then(|m| m.jaw.clone())
            .or_else(|| jaw_hinge(face)),
        export: None,
        face_parts: (rig.parts.parts.len() > 1).then(|| rig.parts.clone()),
        out_of_model: (!model.outside.regions.is_empty()).then(|| model.outside.clone()),
    }
}

/// The jaw's hinge, fitted from the face's first jaw-opening shape (world space, m).
fn jaw_hinge(face: &crate::io::mesh::MeshInstance) -> Option<crate::muscle::jaw::Hinge> {
    use crate::muscle::jaw;
    let t = face.targets.iter().find(|t| jaw::is_jaw_shape(&t.name))?;
    jaw::fit_hinge(&t.name, &face.positions, &t.positions)
}
