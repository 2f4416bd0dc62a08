//! The whole job on one rig: load, weld the face into a skin, refine it for the wavelength,
//! build the lattice, drive the interior, solve the skin, and hand back the wrinkled frames,
//! running only the stages the scene needs (the report says which ran and why the others did
//! not).
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
//! an unsplit run, which is what `furrow merge` relies on.

pub mod chunk;
pub mod frames;
pub mod preview;
pub mod record;
pub mod synthetic;
pub mod weld;

use crate::coupling::embedded::{sigma_for_wavelength, EmbeddedShell};
use crate::coupling::refine::{self, RefineSettings};
use crate::coupling::wavelength::Bilayer;
use crate::fem::{BackwardEuler, ExtraTerms, Interior, LinearSolver, StepSettings};
use crate::io::export::VertexOrigin;
use crate::io::load::Rig;
use crate::lattice::{ElementOrder, Lattice, LatticeSettings};
use crate::mesh::TriMesh;
use crate::scene::Scene;
use crate::solver::statics::{HessianMode, StaticSettings};
use anyhow::{bail, Context};
use frames::FrameRange;
use nalgebra::Vector3;
use record::{FrameRecord, RunReport, StagePlan, StageRecord, Totals};
use std::time::Instant;

/// Tracking stiffness factor κ (dimensionless): each skin vertex is pulled towards its
/// blend-shape position with stiffness κ E_q A_v / ℓ, ten times what the interior's own cell
/// offers, so the lattice follows the artist's shape to about 10 % of its own error.
pub const TRACKING_STIFFNESS: f64 = 10.0;

/// Tracking stiffness factor κ when muscles drive the interior: a tenth of
/// [`TRACKING_STIFFNESS`], enough to carry motion muscles cannot make (a jaw's rotation about
/// bone) without overriding their shape.
pub const MUSCLE_TRACKING: f64 = 1.0;

/// Muscles of a run and their current activations.
struct MuscleDrive {
    fitter: crate::muscle::Fitter,
    activations: Vec<f64>,
    origin: String,
}

/// Muscles from `source` (`auto`: generated from the rig's blend shapes on the welded skin;
/// otherwise a muscle TOML file), with their fitter.
fn build_muscles(rig: &Rig, scene: &Scene, s: &Setup, source: &str) -> anyhow::Result<MuscleDrive> {
    use crate::io::model::MorphTarget;
    use crate::muscle::{generate_muscles, FitSettings, Fitter, GenerateSettings};
    let material = scene.interior.material()?;
    let welded_mesh = TriMesh::new(
        s.welded_loaded
            .iter()
            .map(|&i| rig.face().positions[i])
            .collect(),
        Vec::new(),
    );
    let (muscles, origin) = if source == "auto" {
        let targets: Vec<MorphTarget> = rig
            .face()
            .targets
            .iter()
            .map(|t| MorphTarget {
                name: t.name.clone(),
                positions: s.welded_loaded.iter().map(|&i| t.positions[i]).collect(),
                normals: None,
            })
            .collect();
        let interior = Interior::new(&s.lattice, &material)?;
        let g = generate_muscles(
            &s.lattice,
            &interior,
            &targets,
            &GenerateSettings::default(),
        )?;
        (g.muscles, "generated from the blend shapes".to_string())
    } else {
        let path = std::path::Path::new(source);
        (
            crate::muscle::rigfile::load(path, &s.lattice, &welded_mesh)?,
            format!("from {source}"),
        )
    };
    if muscles.is_empty() {
        bail!(
            "{}: no muscles ({source}): every blend shape is empty; give a muscle file or use muscles.source = \"none\"",
            rig.path.display()
        );
    }
    let n = muscles.len();
    let fitter = Fitter::new(&s.lattice, &material, muscles, FitSettings::default())?;
    Ok(MuscleDrive {
        fitter,
        activations: vec![0.0; n],
        origin,
    })
}

/// Interior Newton tolerance: ‖∇Φ‖ relative to the larger of the initial gradient and the
/// applied force (the tracking and skin forces). 1e-4 leaves position errors far below the
/// lattice's own discretisation error; the linearised corotational Hessian converges only
/// linearly, so tighter tolerances cost many iterations for no visible change.
pub const INTERIOR_TOLERANCE: f64 = 1e-4;

/// Quality (2 r_in / r_circ) below which a skin triangle is left out of the shell (it still
/// follows the interior): such triangles have no usable rest shape.
pub const DEGENERATE_QUALITY: f64 = 1e-3;

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
}

/// The result of a run: the exported face frames and the report.
#[derive(Debug, Clone)]
pub struct RunOutput {
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

/// Progress callback: (stage, done, total).
pub type Progress<'a> = &'a dyn Fn(&str, usize, usize);

/// Everything built once before the frame loop.
struct Setup {
    /// Export vertices: welded/refined skin vertices; `origin` maps them to loaded vertices.
    skin_mesh: TriMesh,
    /// For each export vertex: (welded vertex, weight) combination giving its target.
    target_of: Vec<Vec<(usize, f64)>>,
    origin: Vec<VertexOrigin>,
    /// Loaded vertex → welded vertex.
    welded_of_loaded: Vec<usize>,
    /// Welded vertex → one loaded vertex.
    welded_loaded: Vec<usize>,
    welded_count: usize,
    lattice: Lattice,
    /// Embedding rows of every export vertex (node, weight).
    rows: Vec<Vec<(usize, f64)>>,
    /// Shell over the simulated part: its vertices are `sim_vertices` (export indices).
    shell: Option<(EmbeddedShell, Vec<usize>)>,
    stepper: BackwardEuler,
    /// Tracking stiffness per welded vertex (N/m) and its embedding rows.
    track_k: Vec<f64>,
    track_stiffness: Vec<(usize, usize, f64)>,
    /// Bᵀ K_x B of the skin, once computed (N/m, triplets over node dofs).
    skin_stiffness: Option<Vec<(usize, usize, f64)>>,
    /// Cluster width σ (m); NaN when no skin is simulated.
    sigma: f64,
    /// Tracking and skin stiffness summed into one compact triplet list (N/m).
    combined: Option<Vec<(usize, usize, f64)>>,
}

/// Run the pipeline on a loaded rig.
pub fn run(rig: &Rig, opts: &RunOptions, progress: Progress) -> anyhow::Result<RunOutput> {
    let wall = Instant::now();
    let scene = &opts.scene;
    scene.validate()?;
    if !(opts.fps.is_finite() && opts.fps > 0.0 && opts.fps <= 1000.0) {
        bail!("fps must lie in (0, 1000], got {}", opts.fps);
    }
    if scene.geometry.is_some() {
        bail!("this scene describes synthetic geometry; run it with `furrow scene`, not on a rig");
    }
    let mut stages = Vec::new();
    let mut warnings = Vec::new();
    let weights = rig.frame_weights(opts.fps);
    let range = opts.frames.unwrap_or(FrameRange::all(weights.len()));
    if range.end > weights.len() || range.is_empty() {
        bail!(
            "{}: frames {}:{} are outside the clip's {} frames",
            rig.path.display(),
            range.start,
            range.end,
            weights.len()
        );
    }
    let animated = rig.track.is_some() && weights.len() > 1;
    let materials = scene.materials()?;
    // Skin thickness per loaded face triangle when the scene varies it (regions, attribute,
    // texture); the refinement and the clusters use the thinnest skin's λ (the shortest
    // wrinkles, the most demanding), λ ∝ h.
    let face_thickness = if crate::scene::thickness::varies(&scene.skin) {
        Some(crate::scene::thickness::rig_face_thickness(
            rig,
            &scene.skin,
            materials.skin.thickness,
            None,
        )?)
    } else {
        None
    };
    let (h_min, h_max) = face_thickness.as_deref().map_or(
        (materials.skin.thickness, materials.skin.thickness),
        |h| {
            h.iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                    (lo.min(x), hi.max(x))
                })
        },
    );
    let wavelength_of = |h: f64| {
        Bilayer {
            thickness: h,
            skin_modulus: materials.skin.young,
            skin_poisson: materials.skin.poisson,
            interior_modulus: materials.interior.young,
            interior_poisson: materials.interior.poisson,
        }
        .critical_wavelength()
    };
    let lambda = wavelength_of(h_min);
    let lambda_max = wavelength_of(h_max);
    let face = rig.face();
    if !scene.skin.meshes.is_empty() && !scene.skin.meshes.contains(&face.name) {
        bail!(
            "{}: the scene names skin meshes {:?} but the face furrow simulates is '{}' (pick it with --mesh)",
            rig.path.display(),
            scene.skin.meshes,
            face.name
        );
    }
    stages.push(StagePlan::ran(
        "load",
        format!(
            "{}; {} frames at {} fps",
            rig.face_reason,
            weights.len(),
            opts.fps
        ),
        0.0,
    ));
    let mut setup = build(
        rig,
        scene,
        lambda,
        face_thickness.as_deref(),
        &mut stages,
        &mut warnings,
        progress,
    )?;
    let sigma = setup.sigma;
    if h_max > h_min && setup.shell.is_some() {
        warnings.push(format!(
            "skin thickness varies from {:.3} to {:.3} mm (λ {:.2} to {:.2} mm); the skin is refined for the thinnest skin and the constraint clusters widen with the thickness (σ = {:.2} mm where thinnest)",
            h_min * 1e3,
            h_max * 1e3,
            lambda * 1e3,
            lambda_max * 1e3,
            sigma * 1e3
        ));
    }

    // The frame loop.
    let dynamics = scene.dynamics.enabled.unwrap_or(animated);
    let frame_dt = 1.0 / opts.fps;
    let substeps = if dynamics {
        (frame_dt / setup.stepper.settings.dt - 1e-9)
            .ceil()
            .max(1.0) as usize
    } else {
        0
    };
    if dynamics {
        setup.stepper.settings.dt = frame_dt / substeps as f64;
        stages.push(StagePlan::ran(
            "interior",
            format!(
                "backward Euler, {substeps} step(s) of {:.4} s per frame, driven by {}",
                setup.stepper.settings.dt,
                driver_name(scene)
            ),
            0.0,
        ));
    } else {
        stages.push(StagePlan::ran(
            "interior",
            format!(
                "quasi-static ({}), driven by {}",
                if animated {
                    "dynamics disabled by the scene"
                } else {
                    "the rig has no animation: no dynamics"
                },
                driver_name(scene)
            ),
            0.0,
        ));
    }
    // Muscles: generated from the blend shapes (`auto`) or read from a file; their
    // activations are fitted to every frame and drive the interior.
    let mut muscles = match scene.muscles.source.as_deref().unwrap_or("none") {
        "none" => {
            stages.push(StagePlan::skipped(
                "muscles",
                "muscles.source = none: the interior tracks the blended surface directly",
            ));
            stages.push(StagePlan::skipped("fit", "no muscles: no activation QP"));
            None
        }
        source => {
            let t = Instant::now();
            let m = build_muscles(rig, scene, &setup, source)?;
            stages.push(StagePlan::ran(
                "muscles",
                format!(
                    "{} muscles {}; a weak tracking (κ = {MUSCLE_TRACKING}) carries what they cannot make (bone motion)",
                    m.fitter.muscles().len(),
                    m.origin
                ),
                t.elapsed().as_secs_f64() * 1e3,
            ));
            stages.push(StagePlan::ran(
                "fit",
                "activations per frame: clarabel QP on the linearised response (warm-started)",
                0.0,
            ));
            Some(m)
        }
    };
    if setup.shell.is_some() {
        stages.push(StagePlan::ran(
            "shell",
            format!(
                "quasi-static skin with H x = H B q, λ = {:.2} mm, σ = {:.2} mm",
                lambda * 1e3,
                sigma * 1e3
            ),
            0.0,
        ));
    }

    let mut per_frame = Vec::new();
    let mut out_frames = Vec::new();
    let mut smooth_frames = Vec::new();
    let mut totals = Totals::default();
    let n_nodes = setup.lattice.node_count();
    let zero_force = vec![0.0; 3 * n_nodes];
    let simulated_surface = scene.export.surface.as_deref() == Some("simulated");
    let every_frame_stiffness = scene.solver.skin_stiffness.as_deref() == Some("every_frame");
    for k in 0..range.end {
        progress("frames", k, range.end);
        let loaded = rig.blend(&weights[k]);
        if loaded.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
            bail!(
                "{}: frame {k}: the blended face has a non-finite position (check the morph weights)",
                rig.path.display()
            );
        }
        let mut welded_target = vec![Vector3::zeros(); setup.welded_count];
        for (i, p) in loaded.iter().enumerate() {
            welded_target[setup.welded_of_loaded[i]] = *p;
        }
        // Interior.
        let t = Instant::now();
        let mut interior_rec = StageRecord {
            status: "converged".into(),
            iterations: 0,
            residual: 0.0,
            ms: 0.0,
        };
        // The skin's pull on the interior: the force Bᵀ F_x every frame; the stiffness
        // Bᵀ K_x B (element-projected, the expensive part) at the rest state once, or every
        // frame with `solver.skin_stiffness = "every_frame"`.
        let skin_terms = match setup.shell.as_ref() {
            Some((skin, verts)) => {
                if setup.skin_stiffness.is_none() || every_frame_stiffness {
                    setup.skin_stiffness = Some(skin.coupling_terms().0);
                }
                Some((
                    setup.skin_stiffness.clone().unwrap_or_default(),
                    skin_force(skin, verts, &setup.rows, 3 * n_nodes),
                ))
            }
            None => None,
        };
        let steps = if dynamics { substeps } else { 1 };
        if setup.combined.is_none() || every_frame_stiffness {
            let mut all = setup.track_stiffness.clone();
            if let Some((ks, _)) = &skin_terms {
                all.extend_from_slice(ks);
            }
            setup.combined = Some(aggregate(all));
        }
        let mut stiffness = setup.combined.clone().unwrap_or_default();
        let base_len = stiffness.len();
        // Fit the activations to this frame's target.
        let mut fit_rec = None;
        if let Some(m) = muscles.as_mut() {
            let t = Instant::now();
            let f = m.fitter.fit_frame(&welded_target)?;
            m.activations = f.activations.clone();
            fit_rec = Some(StageRecord {
                status: if f.status == crate::muscle::FrameStatus::Fitted {
                    "converged".into()
                } else {
                    format!("{:?} ({})", f.status, f.clarabel_status).to_lowercase()
                },
                iterations: f.gauss_newton + 1,
                residual: f.rms_residual,
                ms: t.elapsed().as_secs_f64() * 1e3,
            });
            totals.fit_ms += fit_rec.as_ref().map_or(0.0, |r| r.ms);
        }
        for _ in 0..steps {
            let mut force = tracking_force(&setup, &welded_target);
            if let Some(m) = muscles.as_ref() {
                // The active energy linearised at the step's start (PSD stiffness), like the
                // skin's terms; its triplet layout is the same every step.
                let act = crate::muscle::ActiveEnergy::new(
                    &setup.stepper.interior,
                    m.fitter.muscles(),
                    &m.activations,
                );
                let (k, f) = crate::muscle::linearised_terms(&act, &setup.stepper.q);
                stiffness.truncate(base_len);
                stiffness.extend_from_slice(&k);
                for (a, b) in force.iter_mut().zip(&f) {
                    *a += b;
                }
            }
            if let Some((_, fs)) = &skin_terms {
                for (f, g) in force.iter_mut().zip(fs) {
                    *f += g;
                }
            }
            let extra = ExtraTerms {
                stiffness: &stiffness,
                force: &force,
            };
            let rep = if dynamics {
                setup.stepper.step(&zero_force, Some(&extra))?
            } else {
                setup.stepper.quasi_static(&zero_force, Some(&extra))?
            };
            interior_rec.iterations += rep.iterations;
            interior_rec.residual = rep.residual;
            match rep.status {
                crate::fem::SolveStatus::Converged => {}
                crate::fem::SolveStatus::IterationLimit => {
                    interior_rec.status = "iteration_limit".into()
                }
                crate::fem::SolveStatus::Stalled => interior_rec.status = "stalled".into(),
            }
        }
        if setup.stepper.q.iter().any(|v| !v.is_finite()) {
            bail!("frame {k}: the interior became non-finite; lower dynamics.dt or stiffen the interior");
        }
        interior_rec.ms = t.elapsed().as_secs_f64() * 1e3;
        totals.interior_ms += interior_rec.ms;
        // Skin.
        let q = setup.stepper.q.clone();
        let mut shell_rec = None;
        if let Some((skin, _)) = setup.shell.as_mut() {
            let t = Instant::now();
            let rep = skin.solve(&q)?;
            let ms = t.elapsed().as_secs_f64() * 1e3;
            totals.shell_ms += ms;
            shell_rec = Some(StageRecord {
                status: rep.status.as_str().into(),
                iterations: rep.iterations,
                residual: rep.residual,
                ms,
            });
        }
        let not_converged = interior_rec.status != "converged"
            || shell_rec.as_ref().is_some_and(|s| s.status != "converged");
        if not_converged {
            totals.frames_not_converged += 1;
        }
        totals.frames_simulated += 1;
        // Compose the frame.
        let embedded = embed_rows(&setup.rows, &q);
        let target: Vec<Vector3<f64>> = setup
            .target_of
            .iter()
            .map(|o| o.iter().map(|&(w, a)| welded_target[w] * a).sum())
            .collect();
        let mut out = if simulated_surface {
            embedded.clone()
        } else {
            target.clone()
        };
        let mut depth_max = 0.0f64;
        if let Some((skin, verts)) = &setup.shell {
            let x = skin.x();
            for (i, &v) in verts.iter().enumerate() {
                let xv = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
                let detail = xv - embedded[v];
                depth_max = depth_max.max(detail.norm());
                out[v] = if simulated_surface {
                    xv
                } else {
                    target[v] + detail
                };
            }
        }
        if out.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
            bail!("frame {k}: a non-finite position reached the output; nothing was written");
        }
        per_frame.push(FrameRecord {
            frame: k,
            time_s: k as f64 / opts.fps,
            fit: fit_rec,
            interior: Some(interior_rec),
            shell: shell_rec,
            wrinkle_depth_max_m: depth_max,
        });
        if k >= range.start {
            out_frames.push(out);
            smooth_frames.push(target);
        }
    }
    progress("frames", range.end, range.end);
    if totals.frames_not_converged > 0 {
        warnings.push(format!(
            "{} of {} frames did not converge in every stage (see per_frame)",
            totals.frames_not_converged, totals.frames_simulated
        ));
    }
    if range.start > 0 {
        warnings.push(format!(
            "frames 0..{} were simulated but not written (the clip's history leads to frame {})",
            range.start, range.start
        ));
    }
    totals.frames_written = out_frames.len();
    totals.wall_s = wall.elapsed().as_secs_f64();
    let sizes = serde_json::json!({
        "loaded_vertices": face.positions.len(),
        "skin_vertices": setup.skin_mesh.positions.len(),
        "skin_triangles": setup.skin_mesh.triangles.len(),
        "simulated_vertices": setup.shell.as_ref().map_or(0, |(_, v)| v.len()),
        "lattice_elements": setup.lattice.elements.len(),
        "lattice_nodes": n_nodes,
        "bone_nodes": setup.lattice.pinned_count(),
        "clusters": setup.shell.as_ref().map_or(0, |(s, _)| s.cluster_stats().clusters),
        "muscles": muscles.as_ref().map_or(0, |m| m.fitter.muscles().len()),
    });
    let report = RunReport {
        furrow: env!("CARGO_PKG_VERSION").into(),
        rig: rig.path.display().to_string(),
        scene: opts.scene_path.clone(),
        face: face.name.clone(),
        fps: opts.fps,
        frames: [range.start, range.end],
        materials: serde_json::json!({
            "skin": materials.skin,
            "interior": materials.interior,
            "skin_thickness_m": { "min": h_min, "max": h_max },
            "wavelength_m": { "min": lambda, "max": lambda_max },
        }),
        wavelength_m: lambda,
        sigma_m: sigma,
        sizes,
        stages,
        per_frame: per_frame.split_off(range.start),
        totals,
        warnings,
    };
    Ok(RunOutput {
        triangles: setup.skin_mesh.triangles.clone(),
        origin: setup.origin.clone(),
        frames: out_frames,
        smooth: smooth_frames,
        report,
    })
}

fn driver_name(scene: &Scene) -> &'static str {
    match scene.muscles.source.as_deref().unwrap_or("none") {
        "none" => "tracking of the blended surface",
        _ => "muscle activations",
    }
}

/// x = B q per export vertex.
fn embed_rows(rows: &[Vec<(usize, f64)>], q: &[f64]) -> Vec<Vector3<f64>> {
    rows.iter()
        .map(|r| {
            r.iter()
                .map(|&(n, w)| Vector3::new(q[3 * n], q[3 * n + 1], q[3 * n + 2]) * w)
                .sum()
        })
        .collect()
}

/// Bᵀ F_x: the skin's elastic force F_x = −∇E_x at its current state, carried to the nodes
/// (flat over node dofs, N).
fn skin_force(
    skin: &EmbeddedShell,
    verts: &[usize],
    rows: &[Vec<(usize, f64)>],
    nd: usize,
) -> Vec<f64> {
    use crate::math::Energy;
    let x = skin.x();
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
fn aggregate(mut t: Vec<(usize, usize, f64)>) -> Vec<(usize, usize, f64)> {
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

/// The tracking energy's force Bᵀ k (t − B q) (flat over node dofs, N); its stiffness Bᵀ k B
/// is constant (`Setup::track_stiffness`).
fn tracking_force(s: &Setup, target: &[Vector3<f64>]) -> Vec<f64> {
    let q = &s.stepper.q;
    let mut force = vec![0.0; q.len()];
    for (v, &k) in s.track_k.iter().enumerate() {
        let row = &s.rows[v];
        let mut bq = Vector3::zeros();
        for &(n, w) in row {
            bq += Vector3::new(q[3 * n], q[3 * n + 1], q[3 * n + 2]) * w;
        }
        let f = (target[v] - bq) * k;
        for &(n, w) in row {
            for a in 0..3 {
                force[3 * n + a] += w * f[a];
            }
        }
    }
    force
}

/// Build everything the frame loop needs, recording each stage.
fn build(
    rig: &Rig,
    scene: &Scene,
    lambda: f64,
    face_thickness: Option<&[f64]>,
    stages: &mut Vec<StagePlan>,
    warnings: &mut Vec<String>,
    progress: Progress,
) -> anyhow::Result<Setup> {
    let face = rig.face();
    let path = rig.path.display().to_string();
    progress("setup", 0, 4);
    // Weld.
    let t = Instant::now();
    let raw = TriMesh::new(face.positions.clone(), face.triangles.clone());
    let (lo, hi) = raw
        .bounding_box()
        .with_context(|| format!("{path}: the face '{}' has no vertices", face.name))?;
    let diag = (hi - lo).norm();
    if !(diag.is_finite() && diag > 0.0) {
        bail!("{path}: the face '{}' has no extent", face.name);
    }
    let welded = weld::weld(&face.positions, &face.triangles, 1e-7 * diag);
    if welded.mesh.triangles.is_empty() {
        bail!("{path}: the face '{}' has no triangles", face.name);
    }
    stages.push(StagePlan::ran(
        "weld",
        format!(
            "{} loaded vertices → {} skin vertices ({} triangles dropped as collapsed)",
            face.positions.len(),
            welded.mesh.positions.len(),
            welded.dropped_triangles
        ),
        t.elapsed().as_secs_f64() * 1e3,
    ));
    // Lattice over the welded (unrefined) skin.
    let t = Instant::now();
    let i = &scene.interior;
    let order = match i.elements.as_deref() {
        Some("trilinear") => ElementOrder::Trilinear,
        _ => ElementOrder::Quadratic,
    };
    let lattice = Lattice::build(
        &welded.mesh,
        &LatticeSettings {
            cell_size: i.cell_size,
            target_cells: i.target_cells,
            order,
            depth: i.depth,
        },
    )
    .with_context(|| format!("{path}: building the lattice"))?;
    stages.push(StagePlan::ran(
        "lattice",
        format!(
            "{} elements, {} nodes ({} bone), cell {:.1} mm",
            lattice.elements.len(),
            lattice.node_count(),
            lattice.pinned_count(),
            lattice.cell_size * 1e3
        ),
        t.elapsed().as_secs_f64() * 1e3,
    ));
    progress("setup", 1, 4);
    // Refine.
    let t = Instant::now();
    let refined = refine::refine_for_wavelength(
        &welded.mesh,
        lambda,
        &RefineSettings {
            vertices_per_wavelength: scene
                .skin
                .vertices_per_wavelength
                .unwrap_or(refine::DEFAULT_VERTICES_PER_WAVELENGTH),
            max_levels: scene
                .skin
                .refine_limit
                .unwrap_or(refine::DEFAULT_MAX_LEVELS),
        },
    )
    .with_context(|| format!("{path}: the skin is too coarse for its wrinkles"))?;
    let r = &refined.report;
    if r.levels > 0 {
        stages.push(StagePlan::ran(
            "refine",
            format!(
                "{} level(s): {} → {} vertices, mean edge {:.2} → {:.2} mm for λ = {:.2} mm",
                r.levels,
                r.vertices_before,
                r.vertices_after,
                r.mean_edge_before * 1e3,
                r.mean_edge_after * 1e3,
                lambda * 1e3
            ),
            t.elapsed().as_secs_f64() * 1e3,
        ));
    } else {
        stages.push(StagePlan::skipped(
            "refine",
            format!(
                "the skin already holds {:.1} vertices per wavelength (λ = {:.2} mm)",
                r.vertices_per_wavelength,
                lambda * 1e3
            ),
        ));
    }
    // Thickness per refined triangle: loaded triangles → welded ones (the weld keeps the
    // loaded order and drops collapsed triangles) → their refined children.
    let refined_thickness = match face_thickness {
        Some(h) => {
            let w = &welded.of_loaded;
            let per_welded: Vec<f64> = face
                .triangles
                .iter()
                .zip(h)
                .filter(|(t, _)| {
                    let [a, b, c] = t.map(|v| w[v]);
                    a != b && b != c && a != c
                })
                .map(|(_, &x)| x)
                .collect();
            Some(refine::carry_face_values(&refined, &per_welded)?)
        }
        None => None,
    };
    let points = refine::embed_refined(&lattice, &refined)?;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); points.len()];
    for (v, n, w) in refine::embedding_triplets(&lattice, &points) {
        rows[v].push((n, w));
    }
    let target_of = refined.origin.clone();
    let origin: Vec<VertexOrigin> = refined
        .origin
        .iter()
        .map(|o| {
            let mut o = o.clone();
            o.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            o.truncate(3);
            let s: f64 = o.iter().map(|p| p.1).sum();
            let mut vo = VertexOrigin::same(welded.loaded_of[o[0].0]);
            for (j, &(w, a)) in o.iter().enumerate() {
                vo.vertices[j] = welded.loaded_of[w];
                vo.weights[j] = a / s;
            }
            vo
        })
        .collect();
    let skin_mesh = refined.mesh.clone();
    progress("setup", 2, 4);
    // The simulated part of the skin: the mask, minus degenerate triangles.
    let t = Instant::now();
    let mask = &scene.skin.mask;
    let quality = crate::mesh::quality::check(&skin_mesh, DEGENERATE_QUALITY);
    let degenerate: std::collections::HashSet<usize> =
        quality.slivers.iter().map(|s| s.triangle).collect();
    if !degenerate.is_empty() {
        warnings.push(format!(
            "{path}: {} degenerate skin triangles are left out of the shell and follow the interior. {}",
            degenerate.len(),
            quality.message()
        ));
    }
    let sim_tris: Vec<usize> = (0..skin_mesh.triangles.len())
        .filter(|t| !degenerate.contains(t))
        .filter(|&t| {
            mask.is_empty()
                || skin_mesh.triangles[t]
                    .iter()
                    .all(|&v| mask.iter().any(|b| b.contains(&skin_mesh.positions[v])))
        })
        .collect();
    let mut sigma = f64::NAN;
    let shell = if sim_tris.is_empty() {
        stages.push(StagePlan::skipped(
            "shell",
            if mask.is_empty() {
                "every skin triangle is degenerate".to_string()
            } else {
                "the skin mask selects no triangle: the whole skin follows the interior".to_string()
            },
        ));
        None
    } else {
        let mut local = vec![usize::MAX; skin_mesh.positions.len()];
        let mut verts = Vec::new();
        let mut tris = Vec::with_capacity(sim_tris.len());
        for &t in &sim_tris {
            let tri = skin_mesh.triangles[t].map(|v| {
                if local[v] == usize::MAX {
                    local[v] = verts.len();
                    verts.push(v);
                }
                local[v]
            });
            tris.push(tri);
        }
        let sub = TriMesh::new(
            verts.iter().map(|&v| skin_mesh.positions[v]).collect(),
            tris,
        );
        let emb: Vec<(usize, usize, f64)> = verts
            .iter()
            .enumerate()
            .flat_map(|(i, &v)| rows[v].iter().map(move |&(n, w)| (i, n, w)))
            .collect();
        // σ that puts the wrinkles at λ on this mesh (the truncated kernel's first zero,
        // corrected for edge-path distances; see `coupling::embedded`).
        sigma = sigma_for_wavelength(&sub, lambda);
        let edge = refine::mean_edge(&sub);
        let stretch = scene.skin.material()?.stretch_stiffness();
        let settings = StaticSettings {
            tolerance: scene.solver.shell_tolerance.unwrap_or(1e-6) * stretch * edge,
            max_iterations: scene.solver.shell_iterations.unwrap_or(60),
            hessian: HessianMode::Auto,
            energy_merit: true,
            ..StaticSettings::default()
        };
        let mut skin = EmbeddedShell::new(
            sub,
            scene.skin.material()?,
            emb,
            lattice.node_count(),
            sigma,
            settings,
        )
        .with_context(|| format!("{path}: setting up the skin"))?;
        if let Some(h) = &refined_thickness {
            // The skin's own thickness per simulated triangle; the clusters widen with it
            // (σ ∝ λ ∝ h, from σ of the thinnest skin above).
            let sub_h: Vec<f64> = sim_tris.iter().map(|&t| h[t]).collect();
            skin.set_thickness(sub_h)
                .with_context(|| format!("{path}: setting up the skin thickness"))?;
        }
        let st = skin.cluster_stats();
        stages.push(StagePlan::ran(
            "clusters",
            format!(
                "{} clusters of σ = {:.2} mm, {:.0} vertices each on average, {:.1} per vertex",
                st.clusters,
                sigma * 1e3,
                st.vertices_per_cluster[1],
                st.clusters_per_vertex[1]
            ),
            t.elapsed().as_secs_f64() * 1e3,
        ));
        Some((skin, verts))
    };
    progress("setup", 3, 4);
    // Interior.
    let material = scene.interior.material()?;
    let interior = Interior::new(&lattice, &material)?;
    let gravity = if scene.dynamics.gravity.unwrap_or(false) {
        [0.0, -crate::fem::GRAVITY, 0.0]
    } else {
        [0.0; 3]
    };
    let stepper = BackwardEuler::new(
        interior,
        lattice.rest_flat(),
        lattice.pinned.clone(),
        StepSettings {
            dt: scene.dynamics.dt.unwrap_or(0.02),
            max_newton: scene.solver.interior_iterations.unwrap_or(4),
            tolerance: INTERIOR_TOLERANCE,
            lumped_mass: false,
            gravity,
            linear_solver: LinearSolver::Auto,
        },
    )?;
    // Tracking stiffness per welded vertex: κ E_q A_v / ℓ.
    let areas = vertex_areas(&welded.mesh);
    let kappa = match scene.muscles.source.as_deref().unwrap_or("none") {
        "none" => TRACKING_STIFFNESS,
        _ => MUSCLE_TRACKING,
    };
    let track_k: Vec<f64> = areas
        .iter()
        .map(|a| kappa * material.young * a / lattice.cell_size)
        .collect();
    // Bᵀ k B summed per node pair once (the same on every step): 27² pairs per vertex would
    // otherwise be re-assembled every step.
    let mut pairs: std::collections::BTreeMap<(usize, usize), f64> = Default::default();
    for (v, &k) in track_k.iter().enumerate() {
        let row = &rows[v];
        for &(a, wa) in row {
            for &(b, wb) in row {
                *pairs.entry((a, b)).or_insert(0.0) += k * wa * wb;
            }
        }
    }
    let track_stiffness: Vec<(usize, usize, f64)> = pairs
        .into_iter()
        .flat_map(|((a, b), k)| (0..3).map(move |d| (3 * a + d, 3 * b + d, k)))
        .collect();
    progress("setup", 4, 4);
    Ok(Setup {
        skin_mesh,
        target_of,
        origin,
        welded_of_loaded: welded.of_loaded.clone(),
        welded_loaded: welded.loaded_of.clone(),
        welded_count: welded.mesh.positions.len(),
        lattice,
        rows,
        shell,
        stepper,
        track_k,
        track_stiffness,
        skin_stiffness: None,
        sigma,
        combined: None,
    })
}

/// Lumped vertex areas (one third of each adjacent triangle), m².
fn vertex_areas(mesh: &TriMesh) -> Vec<f64> {
    let mut a = vec![0.0; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let at = mesh.triangle_area(t) / 3.0;
        for &v in tri {
            a[v] += at;
        }
    }
    a
}
