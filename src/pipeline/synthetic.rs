//! Synthetic scenes (`furrow scene FILE`): slabs, cushions and cubes of interior material with
//! a skin on their top face, under a prescribed compression or a weight, solved frame by frame
//! with the two-step embedded-shell scheme.
//!
//! Geometry: each copy is a box [0, L] × [0, W] × [0, D] (the scene's `size`, z up inside this
//! module; exported with y up), a regular block lattice of cubic cells (`interior.cell_size`,
//! default D/2), and a flat sheet of equilateral triangles of edge `geometry.skin_edge` on the
//! top face, embedded in the lattice. The two bottom node layers are glued to the ground.
//! Loads ramp linearly over `load.frames` frames:
//! - `compression` ε: the lattice is compressed affinely along x about its centre and the two
//!   node layers at each x end are held there (the paper's validation slab);
//! - `weight` m (kg): the force m g pushes down on the skin vertices of the middle third of
//!   the top face (through Bᵀ), spread evenly.
//!
//! Copies sit side by side along x (1.5 L apart) and may each have their own skin
//! (`geometry.skins`): the same foam with different covers, or the same interior with
//! different skins. For each copy the report gives the predicted λ and the wavelength measured
//! on the last frame along the middle row (height above the embedded surface).

use crate::coupling::cluster_width::sigma_for_wavelength;
use crate::coupling::embedded::EmbeddedShell;
use crate::coupling::embedding::Embedding;
use crate::coupling::two_step::{two_step_with, InteriorMode};
use crate::coupling::wavelength::Bilayer;
use crate::fem::{BackwardEuler, Interior, LinearSolver, StepSettings, GRAVITY};
use crate::lattice::{shape, Lattice};
use crate::mesh::TriMesh;
use crate::scene::{Load, Scene, SkinSection};
use crate::shell::sheet::equilateral_sheet;
use crate::solver::{HessianMode, StaticSettings};
use crate::validate::measure;
use crate::validate::slab::{block_lattice, locate_in_block};
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::Serialize;
use std::time::Instant;

/// The skin's Newton tolerance of a synthetic scene by default (RMS residual force per
/// vertex relative to E_x h/(1−ν_x²) × edge, as `solver.shell_tolerance`): tighter than a
/// rig's, since these scenes measure the wavelength and sag (on a skin of 10⁴ vertices it
/// is about 10⁻⁶ of the residual's L2 norm).
const SYNTHETIC_SHELL_TOLERANCE: f64 = 1e-8;

/// What one copy did.
#[derive(Debug, Clone, Serialize)]
pub struct CopyReport {
    /// Copy index.
    pub copy: usize,
    /// Skin used (SI).
    pub skin: crate::shell::ShellMaterial,
    /// Predicted critical wavelength (m).
    pub predicted_wavelength_m: f64,
    /// Wavelength measured on the last frame (m), when wrinkles formed.
    pub measured_wavelength_m: Option<f64>,
    /// Wrinkle amplitude on the last frame (m).
    pub amplitude_m: Option<f64>,
    /// Sag of the top centre below its rest height on the last frame (m).
    pub sag_m: f64,
    /// Frames whose shell statics did not converge.
    pub frames_not_converged: usize,
    /// Skin vertices, lattice nodes, clusters.
    pub skin_vertices: usize,
    /// Lattice nodes.
    pub lattice_nodes: usize,
    /// Wall time (s).
    pub seconds: f64,
}

/// The result of a synthetic scene: one mesh of all copies, its frames, and the report.
#[derive(Debug, Clone)]
pub struct SceneOutput {
    /// All copies' skins in one mesh (exported frame (y up), m).
    pub mesh: TriMesh,
    /// Positions per frame (y up, m).
    pub frames: Vec<Vec<Vector3<f64>>>,
    /// One report per copy.
    pub copies: Vec<CopyReport>,
}

/// z-up (simulation) to y-up (glTF).
fn to_y_up(p: &Vector3<f64>) -> Vector3<f64> {
    Vector3::new(p.x, p.z, -p.y)
}

/// Run a synthetic scene, calling `progress(done, total)` per frame.
pub fn run_scene(scene: &Scene, progress: &dyn Fn(usize, usize)) -> anyhow::Result<SceneOutput> {
    scene.validate()?;
    let g = scene
        .geometry
        .as_ref()
        .context("the scene has no [geometry]: give a rig with `furrow animate` instead")?;
    let load = scene.load.as_ref().context("the scene has no [load]")?;
    if load.compression.is_none() && load.weight.is_none() {
        bail!("`[load]` needs `compression` or `weight`");
    }
    let copies = g.copies.unwrap_or(g.skins.len().max(1));
    let skins: Vec<SkinSection> = (0..copies)
        .map(|c| {
            g.skins
                .get(c)
                .cloned()
                .unwrap_or_else(|| scene.skin.clone())
        })
        .collect();
    let mut mesh = TriMesh::new(Vec::new(), Vec::new());
    let mut per_copy_frames: Vec<Vec<Vec<Vector3<f64>>>> = Vec::new();
    let mut reports = Vec::new();
    let total = copies * load.frames;
    for (c, skin_section) in skins.iter().enumerate() {
        let offset = Vector3::new(1.5 * g.size[0] * c as f64, 0.0, 0.0);
        let (m, frames, rep) = run_copy(scene, skin_section, c, &|k| {
            progress(c * load.frames + k, total)
        })?;
        let base = mesh.positions.len();
        mesh.positions
            .extend(m.positions.iter().map(|p| to_y_up(&(p + offset))));
        mesh.triangles
            .extend(m.triangles.iter().map(|t| t.map(|v| v + base)));
        per_copy_frames.push(
            frames
                .into_iter()
                .map(|f| f.iter().map(|p| to_y_up(&(p + offset))).collect())
                .collect(),
        );
        reports.push(rep);
    }
    progress(total, total);
    let frames = (0..load.frames)
        .map(|k| per_copy_frames.iter().flat_map(|f| f[k].clone()).collect())
        .collect();
    Ok(SceneOutput {
        mesh,
        frames,
        copies: reports,
    })
}

type CopyResult = (TriMesh, Vec<Vec<Vector3<f64>>>, CopyReport);

/// Embedding triplets (skin vertex, node, weight).
type Triplets = Vec<(usize, usize, f64)>;

/// One copy's box: the interior's lattice, pins and stepper, and the skin on its top face.
struct CopyModel {
    /// The skin sheet on the top face (z up, m).
    skin_mesh: TriMesh,
    /// Skin vertices of the sheet's middle row (for the wavelength measurement).
    middle_row: Vec<usize>,
    /// Lattice nodes.
    nodes: usize,
    /// Lattice extent (m).
    extent: [f64; 3],
    /// Rest node positions (flat, m).
    rest: Vec<f64>,
    /// Pinned nodes (glued to the ground, or held at the compressed ends).
    pinned: Vec<bool>,
    /// The embedding B of the skin vertices in the lattice.
    embedding: Embedding,
    /// Skin vertices under the weight.
    loaded: Vec<usize>,
}

/// One copy's materials and predicted wavelength.
struct CopyMaterials {
    skin: crate::shell::ShellMaterial,
    interior: crate::fem::Material,
    /// Predicted critical wavelength (m).
    lambda: f64,
}

/// The copy's skin and interior materials and λ; refuses a skin too coarse for λ.
fn copy_materials(
    scene: &Scene,
    skin_section: &SkinSection,
    copy: usize,
) -> anyhow::Result<CopyMaterials> {
    let g = scene.geometry.as_ref().expect("checked");
    let skin = skin_section
        .material()
        .with_context(|| format!("copy {copy}: skin"))?;
    let interior = scene.interior.material()?;
    let lambda = Bilayer {
        thickness: skin.thickness,
        skin_modulus: skin.young,
        skin_poisson: skin.poisson,
        interior_modulus: interior.young,
        interior_poisson: interior.poisson,
    }
    .critical_wavelength();
    let edge = g.skin_edge;
    if lambda < 3.0 * edge {
        bail!(
            "copy {copy}: λ = {:.2} mm holds fewer than 3 skin edges of {:.2} mm: wrinkles cannot \
             form; make `geometry.skin_edge` at most {:.2} mm",
            lambda * 1e3,
            edge * 1e3,
            lambda / 6.0 * 1e3
        );
    }
    Ok(CopyMaterials {
        skin,
        interior,
        lambda,
    })
}

/// The block lattice of the copy's box (cubic cells of `interior.cell_size`, default D/2) and
/// its cell counts per axis.
fn copy_lattice(scene: &Scene) -> anyhow::Result<(Lattice, [usize; 3], f64)> {
    let g = scene.geometry.as_ref().expect("checked");
    let [l, w, d] = g.size;
    let cell = scene.interior.cell_size.unwrap_or(d / 2.0);
    let dims = [
        (l / cell).round().max(1.0) as usize,
        (w / cell).round().max(1.0) as usize,
        (d / cell).round().max(1.0) as usize,
    ];
    let order = scene.interior.lattice_settings().order;
    let cells = dims[0] * dims[1] * dims[2];
    if cells > 20_000 {
        bail!("the lattice would have {cells} cells; increase `interior.cell_size`");
    }
    Ok((
        block_lattice(Vector3::zeros(), cell, dims, order),
        dims,
        cell,
    ))
}

/// The copy's geometry: lattice, pins, and the equilateral skin sheet on its top face
/// embedded in it. Returns the model, the lattice and the embedding triplets.
fn copy_model(scene: &Scene, copy: usize) -> anyhow::Result<(CopyModel, Triplets, Lattice)> {
    let g = scene.geometry.as_ref().expect("checked");
    let load = scene.load.as_ref().expect("checked");
    let (lattice, dims, cell) = copy_lattice(scene)?;
    let edge = g.skin_edge;
    let (lx, ly, lz) = (
        dims[0] as f64 * cell,
        dims[1] as f64 * cell,
        dims[2] as f64 * cell,
    );
    let nx = (lx / edge).round().max(2.0) as usize;
    let ny = (ly / (edge * 3f64.sqrt() / 2.0)).round().max(2.0) as usize;
    let sheet = equilateral_sheet(nx, ny, lx / nx as f64);
    let sy = ly / (ny as f64 * sheet.edge * 3f64.sqrt() / 2.0);
    let mut skin_mesh = sheet.mesh.clone();
    for p in &mut skin_mesh.positions {
        *p = Vector3::new(p.x, p.y * sy, lz);
    }
    let mut embedding = Vec::new();
    for (v, p) in skin_mesh.positions.iter().enumerate() {
        let mp = locate_in_block(&lattice, p);
        let sh = shape(lattice.order, mp.xi);
        for a in 0..sh.n {
            if sh.val[a] != 0.0 {
                embedding.push((v, lattice.elements[mp.element].nodes[a], sh.val[a]));
            }
        }
    }
    let k = lattice.order.per_axis();
    let nn = [dims[0] + k - 1, dims[1] + k - 1, dims[2] + k - 1];
    let layers = k - 1;
    let compression = load.compression.unwrap_or(0.0);
    let pinned: Vec<bool> = lattice
        .grid
        .iter()
        .map(|gp| {
            gp[2] < layers || (compression > 0.0 && (gp[0] < layers || gp[0] >= nn[0] - layers))
        })
        .collect();
    // Weight: spread over the skin vertices of the middle third of the top face.
    let loaded: Vec<usize> = skin_mesh
        .positions
        .iter()
        .enumerate()
        .filter(|(_, p)| (p.x - lx / 2.0).abs() <= lx / 6.0 && (p.y - ly / 2.0).abs() <= ly / 6.0)
        .map(|(v, _)| v)
        .collect();
    if load.weight.is_some() && loaded.is_empty() {
        bail!("copy {copy}: no skin vertex under the weight; refine `geometry.skin_edge`");
    }
    let points = skin_mesh.positions.len();
    let rows = Embedding::from_triplets(&embedding, points, lattice.node_count());
    let model = CopyModel {
        skin_mesh,
        middle_row: sheet.rows[ny / 2].clone(),
        nodes: lattice.node_count(),
        extent: [lx, ly, lz],
        rest: lattice.rest_flat(),
        pinned,
        embedding: rows,
        loaded,
    };
    Ok((model, embedding, lattice))
}

/// The copy's skin: an embedded shell with clusters for λ and the scene's statics settings.
fn copy_skin(
    scene: &Scene,
    model: &CopyModel,
    materials: &CopyMaterials,
    embedding: Vec<(usize, usize, f64)>,
    copy: usize,
) -> anyhow::Result<EmbeddedShell> {
    let edge = scene.geometry.as_ref().expect("checked").skin_edge;
    let skin_mat = materials.skin;
    EmbeddedShell::new(
        model.skin_mesh.clone(),
        skin_mat,
        embedding,
        model.nodes,
        sigma_for_wavelength(&model.skin_mesh, materials.lambda),
        StaticSettings {
            tolerance: skin_mat.residual_tolerance(
                scene
                    .solver
                    .shell_tolerance
                    .unwrap_or(SYNTHETIC_SHELL_TOLERANCE),
                edge,
                model.skin_mesh.positions.len(),
            ),
            max_iterations: scene.solver.shell_iterations.unwrap_or(100),
            hessian: HessianMode::Auto,
            energy_merit: true,
            ..Default::default()
        },
    )
    .with_context(|| format!("copy {copy}: building the skin"))
}

/// The copy's interior: backward Euler on the lattice with its pins and the scene's gravity.
fn copy_interior(
    scene: &Scene,
    lattice: &Lattice,
    model: &CopyModel,
    materials: &CopyMaterials,
) -> anyhow::Result<BackwardEuler> {
    let interior = Interior::new(lattice, &materials.interior)?;
    let gravity = if scene.dynamics.gravity.unwrap_or(false) {
        [0.0, 0.0, -GRAVITY]
    } else {
        [0.0; 3]
    };
    Ok(BackwardEuler::new(
        interior,
        model.rest.clone(),
        model.pinned.clone(),
        StepSettings {
            dt: scene.dynamics.dt.unwrap_or(0.02),
            max_newton: scene.solver.interior_iterations.unwrap_or(20),
            gravity,
            linear_solver: LinearSolver::Auto,
            tangent: crate::fem::Tangent::Consistent,
            ..Default::default()
        },
    )?)
}

/// The load of frame `f` of `frames` (ramped linearly): the compressed ends placed (and on the
/// first frame the free nodes too, a good first guess), and the weight's force through Bᵀ
/// (flat over node dofs, N).
fn apply_load(load: &Load, model: &CopyModel, be: &mut BackwardEuler, f: usize) -> Vec<f64> {
    let s = (f + 1) as f64 / load.frames as f64;
    let compression = load.compression.unwrap_or(0.0);
    let xc = model.extent[0] / 2.0;
    let rest = &model.rest;
    if compression > 0.0 {
        let factor = 1.0 - compression * s;
        for (n, &p) in model.pinned.iter().enumerate() {
            if p {
                be.q[3 * n] = xc + factor * (rest[3 * n] - xc);
            }
        }
    }
    let mut f_ext = vec![0.0; be.q.len()];
    if let Some(m) = load.weight {
        let per = m * GRAVITY * s / model.loaded.len() as f64;
        let weight = Vector3::new(0.0, 0.0, -per);
        for &v in &model.loaded {
            model.embedding.spread_point(v, &weight, &mut f_ext);
        }
    }
    if f == 0 && compression > 0.0 {
        // Free nodes start on the affinely compressed state (a good first guess).
        let factor = 1.0 - compression * s;
        for (n, &p) in model.pinned.iter().enumerate() {
            if !p {
                be.q[3 * n] = xc + factor * (rest[3 * n] - xc);
            }
        }
    }
    f_ext
}

/// Wavelength and amplitude along the middle row and the centre's sag, on the last frame.
fn measure_copy(
    model: &CopyModel,
    skin: &EmbeddedShell,
    q: &[f64],
    last: &[Vector3<f64>],
) -> (Option<measure::Measured>, f64) {
    let [lx, ly, lz] = model.extent;
    let bq = skin.embedded_positions(q);
    let profile: Vec<(f64, f64)> = model
        .middle_row
        .iter()
        .map(|&v| (last[v].x, last[v].z - bq[v].z))
        .collect();
    let measured = measure::wavelength(&profile);
    let centre = model
        .skin_mesh
        .positions
        .iter()
        .enumerate()
        .min_by(|a, b| {
            let da = (a.1.x - lx / 2.0).powi(2) + (a.1.y - ly / 2.0).powi(2);
            let db = (b.1.x - lx / 2.0).powi(2) + (b.1.y - ly / 2.0).powi(2);
            da.total_cmp(&db)
        })
        .map_or(0, |(v, _)| v);
    (measured, lz - last[centre].z)
}

/// Simulate one copy frame by frame (two-step: interior, then skin) and measure it.
fn run_copy(
    scene: &Scene,
    skin_section: &SkinSection,
    copy: usize,
    progress: &dyn Fn(usize),
) -> anyhow::Result<CopyResult> {
    let t0 = Instant::now();
    let load = scene.load.as_ref().expect("checked");
    let materials = copy_materials(scene, skin_section, copy)?;
    let (model, embedding, lattice) = copy_model(scene, copy)?;
    let mut skin = copy_skin(scene, &model, &materials, embedding, copy)?;
    let mut be = copy_interior(scene, &lattice, &model, &materials)?;
    let mode = if scene.dynamics.enabled.unwrap_or(false) {
        InteriorMode::Dynamic
    } else {
        InteriorMode::QuasiStatic
    };
    let mut frames = Vec::with_capacity(load.frames);
    let mut not_converged = 0;
    for f in 0..load.frames {
        progress(f);
        let f_ext = apply_load(load, &model, &mut be, f);
        let rep = two_step_with(&mut be, &mut skin, &f_ext, mode)?;
        // The interior moved after the shell solve: re-solve the skin on the final state.
        let last = skin.solve(&be.q)?;
        if rep.shell.status != crate::solver::SolveStatus::Converged
            || last.status != crate::solver::SolveStatus::Converged
        {
            not_converged += 1;
        }
        let x = skin.x();
        if x.iter().any(|v| !v.is_finite()) {
            bail!("copy {copy}, frame {f}: the skin became non-finite");
        }
        frames.push(
            (0..model.skin_mesh.positions.len())
                .map(|v| Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]))
                .collect::<Vec<_>>(),
        );
    }
    let last = frames.last().expect("at least one frame");
    let (measured, sag) = measure_copy(&model, &skin, &be.q, last);
    let report = CopyReport {
        copy,
        skin: materials.skin,
        predicted_wavelength_m: materials.lambda,
        measured_wavelength_m: measured.as_ref().map(|m| m.wavelength),
        amplitude_m: measured.as_ref().map(|m| m.amplitude),
        sag_m: sag,
        frames_not_converged: not_converged,
        skin_vertices: model.skin_mesh.positions.len(),
        lattice_nodes: model.nodes,
        seconds: t0.elapsed().as_secs_f64(),
    };
    Ok((model.skin_mesh, frames, report))
}
