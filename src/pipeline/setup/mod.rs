//! The set-up: everything built once before the frame loop, one stage per module, in the order
//! they run: [`weld`] the loaded face into one skin, build the [`lattice`] over it, [`select`]
//! the welded triangles that can wrinkle, [`refine`] them for the critical wavelength and
//! embed the skin, build the simulated [`skin`]'s shell and clusters, the [`interior`] stepper
//! and tracking energy, and the [`muscles`].
//! Each stage returns its result and its record for the report.
//!
//! What the set-up builds splits in two: the [`Model`], fixed for the run (meshes, maps,
//! lattice, embedding, tracking energy), and the [`State`] that each frame step advances (the
//! interior's positions and velocities, the skin, the muscle activations).

pub mod cell;
pub mod interior;
pub mod lattice;
pub mod muscles;
pub mod outside;
pub mod refine;
pub mod select;
pub mod skin;
pub mod weld;

use super::plan::{Driver, Plan};
use super::record::StagePlan;
use super::Progress;
use crate::coupling::embedded::EmbeddedShell;
use crate::coupling::embedding::Embedding;
use crate::fem::BackwardEuler;
use crate::io::load::Rig;
use crate::io::origin::VertexOrigin;
use crate::io::split::{FaceMap, LoadedCorners};
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::scene::Scene;
use crate::scene::SkinHold;
use interior::Tracking;
use muscles::MuscleDrive;

/// What a run keeps fixed: the exported skin and its maps, the lattice and the embedding.
pub struct Model {
    /// The exported skin (the welded face refined; m).
    pub skin_mesh: TriMesh,
    /// For each export vertex, (welded vertex, weight) pairs whose blend is its target.
    pub target_of: Vec<Vec<(usize, f64)>>,
    /// For each export vertex, its origin in the loaded face.
    pub origin: Vec<VertexOrigin>,
    /// Loaded vertex → welded vertex.
    pub welded_of_loaded: Vec<usize>,
    /// Welded vertex → one loaded vertex at the same place.
    pub welded_loaded: Vec<usize>,
    /// Number of welded vertices (they come first among the export vertices).
    pub welded_count: usize,
    /// The interior's lattice.
    pub lattice: Lattice,
    /// The embedding B of every export vertex in the lattice (x = B q).
    pub embedding: Embedding,
    /// Export vertex of each shell vertex (empty when no skin is simulated).
    pub sim_vertices: Vec<usize>,
    /// Cluster width σ (m); NaN when no skin is simulated.
    pub sigma: f64,
    /// The tracking energy towards the blend-shape target.
    pub tracking: Tracking,
    /// For each skin triangle, the loaded triangle it lies in and its corners' barycentric
    /// coordinates there (the export's seams and primitives follow these).
    pub corners: Vec<LoadedCorners>,
    /// The skin the `select` stage left out, riding on the interior (x = B q), and its
    /// stiffness Bᵀ K_x B at rest (N/m): the interior keeps that skin's elasticity.
    pub left_out: Option<(skin::SimulatedSkin, skin::Stiffness)>,
    /// The simulated skin's stiffness Bᵀ K_x B at rest (N/m, triplets over node dofs; empty
    /// when no skin is simulated): the interior's coupling to it, and what the muscles' fit sees.
    pub skin_stiffness: skin::Stiffness,
    /// The head's motion the interior feels as inertial forces, when the rig's face node moves.
    pub head_motion: Option<crate::pipeline::plan::HeadMotion>,
    /// What drives the interior: the plan's driver, or tracking when default muscles cannot
    /// drive the rig.
    pub driver: Driver,
    /// Where each pose leaves the skin's model (that skin follows the blend shape there).
    pub outside: outside::OutOfModel,
    /// How a pose's region reaches the simulated skin's pins.
    pub pose_maps: outside::PoseMaps,
}

impl Model {
    /// How the skin maps onto the loaded face, for the export.
    pub fn face_map(&self) -> FaceMap {
        FaceMap {
            triangles: self.skin_mesh.triangles.clone(),
            subdivision: self.target_of.clone(),
            welded_of_loaded: self.welded_of_loaded.clone(),
            welded_count: self.welded_count,
            corners: self.corners.clone(),
        }
    }
}

/// What the frame step advances.
pub struct State {
    /// The interior: lattice node positions q (m) and velocities (m/s), with its stepper.
    pub interior: BackwardEuler,
    /// The simulated skin (its positions x, m), when any.
    pub skin: Option<EmbeddedShell>,
    /// The muscles and their activations, when muscles drive the interior.
    pub muscles: Option<MuscleDrive>,
    /// The welded target of the last frame stepped (m): sub-steps of the next frame move
    /// the target from it to that frame's, so a shorter step is also a smaller load step.
    pub last_target: Option<Vec<nalgebra::Vector3<f64>>>,
}

impl State {
    /// Put the state back at rest for `model` (a still rig's next shape is solved alone from
    /// rest): the interior at its rest positions, the skin at its rest shape with a fresh
    /// solver history, the muscles at rest, no last target. What only speeds up solves (the
    /// sparsity patterns and their analyses) is kept.
    pub fn reset_to_rest(&mut self, model: &Model) {
        self.interior.reset_to_rest(&model.lattice.rest_flat());
        if let Some(skin) = self.skin.as_mut() {
            skin.reset_to_rest();
        }
        if let Some(m) = self.muscles.as_mut() {
            m.reset();
        }
        self.last_target = None;
    }
}

impl State {
    /// Another state at rest for a still rig's shapes, solved beside this one: its own
    /// interior stepper and a copy of the skin ([`EmbeddedShell::duplicate`]). `None` when
    /// muscles drive (their fitter is not copied; the shapes are then solved one by one).
    pub fn at_rest_copy(
        &self,
        model: &Model,
        scene: &Scene,
        plan: &Plan,
    ) -> anyhow::Result<Option<State>> {
        if self.muscles.is_some() {
            return Ok(None);
        }
        let skin = self.skin.as_ref().map(|s| s.duplicate()).transpose()?;
        let mut copy = State {
            interior: interior::stepper(&model.lattice, scene, plan)?,
            skin,
            muscles: None,
            last_target: None,
        };
        copy.reset_to_rest(model);
        Ok(Some(copy))
    }
}

/// The run's log: each stage's record in the order they were planned, and the warnings.
#[derive(Debug, Default)]
pub struct Log {
    /// Stage records, in order.
    pub stages: Vec<StagePlan>,
    /// Warnings for the user.
    pub warnings: Vec<String>,
}

/// Build the model and the initial state, recording each stage in `log`. Muscles by default
/// (`muscles.source` not given) that cannot be made for the rig (no bone behind the face, no
/// shape a muscle can make) or that cannot make its shapes
/// ([`muscles::MUSCLE_SHAPE_LIMIT`]) leave the interior to tracking: the model's driver is
/// [`Driver::Tracking`] and a warning says why. The plan is not changed.
pub fn set_up(
    rig: &Rig,
    scene: &Scene,
    plan: &Plan,
    log: &mut Log,
    progress: Progress,
) -> anyhow::Result<(Model, State)> {
    let face = rig.face();
    let path = rig.path.display().to_string();
    progress(super::Phase::Setup, 0, 4);
    let (welded, record) = weld::weld_face(face, &path)?;
    log.stages.push(record);
    let (outside, record) = outside::find(rig, plan, &welded);
    log.stages.push(record);
    let (lattice, record) = lattice::lattice_for_run(face, &welded, &scene.interior, plan, &path)?;
    log.stages.push(record);
    progress(super::Phase::Setup, 1, 4);
    let (selection, record) = select::select_skin(rig, scene, plan, &welded, &outside);
    log.stages.push(record);
    let region = simulated_region(selection.as_ref(), skin::within_mask(&welded.mesh, scene));
    let input = refine::RefineInput {
        face,
        welded: &welded,
        lattice: &lattice,
        scale: &plan.skin,
        rig_scale: &rig.scale,
        region: region.as_deref(),
    };
    let (refined, record) = refine::refine_skin(&input, &scene.skin, &path)?;
    log.stages.push(record);
    progress(super::Phase::Setup, 2, 4);
    let nodes = lattice.node_count();
    let input = skin::ShellInput {
        refined: &refined,
        nodes,
        scene,
        lambda: plan.skin.lambda,
        path: &path,
    };
    let compressed = selection
        .as_ref()
        .is_none_or(|sel| sel.simulated.contains(&true));
    let (mut simulated, left_out) = simulated_skin(&input, region.as_deref(), compressed, log)?;
    progress(super::Phase::Setup, 3, 4);
    let stepper = interior::stepper(&lattice, scene, plan)?;
    let young = scene.interior.material()?.young;
    let track = |driver: &Driver| {
        let kappa = interior::tracking_factor(scene, driver);
        let cell = lattice.cell_size;
        interior::tracking(&welded.mesh, &refined.embedding, kappa, young, cell)
    };
    let mut tracking = track(&plan.driver);
    progress(super::Phase::Setup, 4, 4);
    let skin_stiffness = simulated
        .as_ref()
        .map(|s| s.shell.coupling_terms().0)
        .unwrap_or_default();
    let mut driver = plan.driver.clone();
    let driven = match &plan.driver {
        Driver::Tracking => Ok(None),
        Driver::Muscles { source } => muscles::build_muscles(
            face,
            &path,
            scene,
            &lattice,
            &welded,
            source,
            muscles::Beside {
                coupling: muscle_coupling(&tracking),
                // The skin's force at each shape joins the actuation fit when the driver
                // fits generated muscles with the skin in the loop.
                skin: simulated
                    .as_mut()
                    .filter(|_| plan.driver.skin_in_fit(scene))
                    .map(|s| &mut s.shell),
                wavelength: plan.skin.lambda,
                hold: plan.driver.skin_hold(scene).unwrap_or(SkinHold::Reached),
            },
        )
        .map(Some),
    };
    let (muscles, records) = match driven {
        Ok(Some((m, records))) => (Some(m), records),
        Ok(None) => (None, muscles::skipped(scene)),
        // Muscles by default, not asked for: a rig they cannot drive is tracked instead.
        Err(e) if scene.muscles.source.is_none() => {
            driver = Driver::Tracking;
            tracking = track(&driver);
            log.warnings.push(format!(
                "{path}: muscles cannot drive this rig ({e:#}); the interior tracks the blended \
                 surface instead (`[muscles] source = \"none\"` says so and skips the attempt)"
            ));
            (None, muscles::fell_back(&e))
        }
        Err(e) => return Err(e),
    };
    log.stages.push(interior::record(plan, &driver, &stepper));
    log.stages.extend(records);
    let pose_maps = pose_maps(simulated.as_ref(), &refined, selection);
    let (skin, sim_vertices, sigma) = match simulated {
        Some(s) => (Some(s.shell), s.vertices, s.sigma),
        None => (None, Vec::new(), f64::NAN),
    };
    let model = Model {
        corners: loaded_corners(&refined, &welded),
        skin_mesh: refined.mesh,
        target_of: refined.target_of,
        origin: refined.origin,
        welded_of_loaded: welded.of_loaded,
        welded_loaded: welded.loaded_of,
        welded_count: welded.mesh.positions.len(),
        lattice,
        embedding: refined.embedding,
        sim_vertices,
        sigma,
        tracking,
        left_out,
        skin_stiffness,
        head_motion: plan.head_motion.clone(),
        driver,
        outside,
        pose_maps,
    };
    let state = State {
        interior: stepper,
        skin,
        muscles,
        last_target: None,
    };
    Ok((model, state))
}

/// The maps from refined skin to shell, welded face and per-pose activity that place the
/// out-of-model regions' pins.
fn pose_maps(
    simulated: Option<&skin::SimulatedSkin>,
    refined: &refine::RefinedSkin,
    selection: Option<select::Selection>,
) -> outside::PoseMaps {
    outside::PoseMaps {
        static_pins: simulated.map_or_else(Vec::new, |s| s.shell.pinned().to_vec()),
        shell_of_refined: shell_of_refined(simulated, refined.mesh.positions.len()),
        welded_of_refined: refined.ancestor.iter().map(|a| a.triangle as u32).collect(),
        active: selection.map_or_else(Vec::new, |s| s.per_pose),
    }
}

/// Each refined skin vertex as a point of a loaded triangle (barycentric coordinates).
fn loaded_corners(refined: &refine::RefinedSkin, welded: &weld::Welded) -> Vec<LoadedCorners> {
    refined
        .ancestor
        .iter()
        .map(|a| LoadedCorners {
            triangle: welded.loaded_triangle[a.triangle],
            bary: a.bary,
        })
        .collect()
}

/// The shell vertex of each of `count` refined vertices (`u32::MAX` where not simulated).
fn shell_of_refined(simulated: Option<&skin::SimulatedSkin>, count: usize) -> Vec<u32> {
    let mut of = vec![u32::MAX; count];
    if let Some(s) = simulated {
        for (i, &v) in s.vertices.iter().enumerate() {
            of[v] = i as u32;
        }
    }
    of
}

/// What the interior carries besides its elasticity, as the muscles' fit sees it: the
/// tracking (the skin's force at each shape joins it with `muscles.skin_hold = "shapes"`, see
/// [`crate::muscle::actuation`]).
fn muscle_coupling(tracking: &Tracking) -> crate::muscle::Coupling {
    crate::muscle::Coupling {
        stiffness: tracking.stiffness.clone(),
        tracking: tracking.k.clone(),
    }
}

/// The left-out skin and its rest stiffness, when the selection leaves some out.
type LeftOut = Option<(skin::SimulatedSkin, skin::Stiffness)>;

/// The welded triangles whose skin may be simulated, refined and solved: those the selection
/// keeps that meet the mask; `None` when that is all of them.
fn simulated_region(
    selection: Option<&select::Selection>,
    mask: Option<Vec<bool>>,
) -> Option<Vec<bool>> {
    match (selection, mask) {
        (None, mask) => mask,
        (Some(s), None) => Some(s.simulated.clone()),
        (Some(s), Some(m)) => Some(s.simulated.iter().zip(m).map(|(&a, b)| a && b).collect()),
    }
}

/// The simulated skin (the non-degenerate triangles inside the mask whose welded ancestor is
/// in `region`, with its shell and clusters) and the rest stiffness of the skin the selection
/// left out; records the `clusters` stage, or the `shell` stage as skipped (`compressed`: some
/// skin was compressed enough to be selected).
fn simulated_skin(
    s: &skin::ShellInput,
    region: Option<&[bool]>,
    compressed: bool,
    log: &mut Log,
) -> anyhow::Result<(Option<skin::SimulatedSkin>, LeftOut)> {
    let mesh = &s.refined.mesh;
    let (candidates, on_degenerate) =
        skin::select_triangles(mesh, s.scene, s.path, &mut log.warnings);
    // The region's welded triangles were refined whole: their refined triangles are all
    // red, at the full level; the transition band lies outside them.
    let ancestor = &s.refined.ancestor;
    let (triangles, beyond): (Vec<usize>, Vec<usize>) = candidates
        .iter()
        .partition(|&&t| region.is_none_or(|r| r[ancestor[t].triangle]));
    let ring = skin::border_ring(mesh, &candidates, &triangles);
    let mut in_ring = vec![false; mesh.triangles.len()];
    ring.iter().for_each(|&t| in_ring[t] = true);
    let left_out: Vec<usize> = beyond.into_iter().filter(|&t| !in_ring[t]).collect();
    let shell = if triangles.is_empty() {
        log.stages.push(skin::skipped_shell(s.scene, compressed));
        None
    } else {
        let (mut sim, record) = skin::build_selected_shell(s, &candidates, &triangles, &ring)?;
        skin::pin_degenerate(&mut sim, &on_degenerate)?;
        skin::pin_slits(&mut sim)?;
        log.stages.push(record);
        Some(sim)
    };
    let rest = skin::left_out_skin(s, &left_out)?;
    Ok((shell, rest))
}

/// Small inputs for the stages' unit tests.
#[cfg(test)]
pub(crate) mod test_support {
    use crate::io::mesh::{MeshInstance, VertexTransform};
    use crate::mesh::TriMesh;
    use crate::pipeline::plan::Driver;
    use nalgebra::{Matrix4, Vector3};

    /// An n × n vertex grid over 4 cm × 4 cm with a gentle 4 mm bump (m), like a patch of cheek.
    pub fn bump_sheet(n: usize) -> TriMesh {
        let h = 0.04 / (n - 1) as f64;
        let mut p = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let (x, y) = (i as f64 * h - 0.02, j as f64 * h - 0.02);
                p.push(Vector3::new(x, y, 0.004 * (-(x * x + y * y) / 2e-4).exp()));
            }
        }
        TriMesh::new(p, crate::mesh::grid_triangles(n, n))
    }

    /// A loaded face of `mesh` with one morph target that lifts the middle by up to 2 mm.
    pub fn face_of(mesh: TriMesh) -> MeshInstance {
        let lift = mesh
            .positions
            .iter()
            .map(|p| Vector3::new(0.0, 0.0, 0.002 * (-(p.x * p.x + p.y * p.y) / 1e-4).exp()))
            .collect();
        MeshInstance {
            node: 0,
            mesh: 0,
            name: "sheet".into(),
            normals: None,
            targets: vec![crate::io::model::MorphTarget {
                name: "lift".into(),
                positions: lift,
                normals: None,
            }],
            default_weights: vec![0.0],
            to_world: VertexTransform::Node(Matrix4::identity()),
            primitives: vec![crate::io::mesh::PrimitiveSpan {
                json: 0,
                first: 0,
                count: mesh.positions.len(),
            }],
            skipped_primitives: 0,
            positions: mesh.positions,
            triangles: mesh.triangles,
        }
    }

    /// The welded target of `face` with its lift at weight `w` (m).
    pub fn lifted_target(face: &MeshInstance, model: &super::Model, w: f64) -> Vec<Vector3<f64>> {
        let loaded: Vec<Vector3<f64>> = face
            .positions
            .iter()
            .zip(&face.targets[0].positions)
            .map(|(p, d)| p + d * w)
            .collect();
        crate::pipeline::step::blend::weld_positions(
            &loaded,
            &model.welded_of_loaded,
            model.welded_count,
        )
    }

    /// A small model and state from [`set_up`](super::set_up): the lifted 7 × 7 bump sheet as
    /// a rig (its lift ramping from 0 to 1 over one frame), 1 cm cells, refined for λ = 1 cm,
    /// the whole default skin simulated, driven by `driver`, with `substeps` backward Euler
    /// steps per frame at 30 fps (0: quasi-static). Returns the loaded face too.
    pub fn small_model(
        driver: Driver,
        substeps: usize,
    ) -> (super::Model, super::State, MeshInstance) {
        small_model_with(driver, substeps, |_| {})
    }

    /// The rig of `face`'s mesh and blend shapes, animated over two frames at 30 fps from
    /// rest to its first shape at weight 1, loaded as a file would be. Returns the face too.
    pub fn sheet_rig(face: MeshInstance) -> (crate::io::load::Rig, MeshInstance) {
        let mesh = TriMesh::new(face.positions.clone(), face.triangles.clone());
        let keys = crate::io::model::WeightKeys {
            times: vec![0.0, 1.0 / 30.0],
            weights: vec![vec![0.0], vec![1.0]],
        };
        let bytes = crate::io::export::rig_glb("sheet", &mesh, &face.targets, &keys).unwrap();
        let path = std::path::Path::new("sheet.glb");
        let rig = crate::io::load::load_bytes(path, &bytes, &Default::default()).unwrap();
        (rig, face)
    }

    /// [`small_model`] with its scene changed by `tweak` first.
    pub fn small_model_with(
        driver: Driver,
        substeps: usize,
        tweak: impl Fn(&mut crate::scene::Scene),
    ) -> (super::Model, super::State, MeshInstance) {
        let (rig, _) = sheet_rig(face_of(bump_sheet(7)));
        let (model, state, _) = set_up_sheet(&rig, driver, substeps, tweak);
        (model, state, rig.face().clone())
    }

    /// [`set_up`](super::set_up) on a sheet `rig` as [`small_model`] sets it up (1 cm cells,
    /// λ = 1 cm, the whole skin simulated, driven by `driver`, `substeps` backward Euler steps
    /// per frame), its scene changed by `tweak` first; with the set-up's log.
    pub fn set_up_sheet(
        rig: &crate::io::load::Rig,
        driver: Driver,
        substeps: usize,
        tweak: impl Fn(&mut crate::scene::Scene),
    ) -> (super::Model, super::State, super::Log) {
        use super::*;
        let mut scene = Scene::default();
        scene.interior.cell_size = Some(0.01);
        scene.skin.simulate = Some(crate::scene::SkinSelection::All);
        scene.muscles.source = Some(match &driver {
            Driver::Muscles { source } => source.clone(),
            Driver::Tracking => crate::scene::MuscleSource::None,
        });
        tweak(&mut scene);
        let opts = crate::pipeline::RunOptions::new(scene.clone());
        let mut plan = Plan::new(rig, &opts).unwrap();
        plan.skin.lambda = 0.01;
        plan.skin.lambda_max = 0.01;
        plan.substeps = substeps;
        let mut log = Log::default();
        let (model, state) = set_up(rig, &scene, &plan, &mut log, &|_, _, _| {}).unwrap();
        (model, state, log)
    }
}
