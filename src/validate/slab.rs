//! The paper's validation scene: a slab of soft interior with a stiff skin on its top face,
//! compressed along x until the skin wrinkles.
//!
//! Geometry (m): the slab spans [0, L] × [0, W_lattice] × [0, D], with z up; the skin is a
//! flat sheet of (nearly) equilateral triangles on the top face z = D covering [0, L] ×
//! [0, W]. The interior is a regular block lattice of cubic cells (quadratic B-spline or
//! trilinear hexahedra, a few cells along the depth) built directly (no surface cutting is
//! needed for a box). The sheet is embedded in it by the lattice's shape functions.
//!
//! Loading (prescribed strain, quasi-static): the two node layers at each x end and the two
//! bottom layers are pinned (a slab glued to a base, ends held) and all nodes are moved by the
//! affine compression x ↦ x_c + (1 − ε)(x − x_c), ε growing geometrically over `steps` load
//! steps from `onset` × ε_b (ε_b = (2πh/λ)²/12, the strain at which a free sheet buckles
//! into waves of length λ) to `compression`. Ramping matters: compressed at once far beyond
//! onset, the flat skin falls into the fastest-growing (much shorter) mode and stays there
//! (measured 0.64 λ at 6 % strain in one step); ramped, the first mode to buckle is the
//! longest one the constraints allow, and later steps only grow its amplitude, as in a
//! physical film on a substrate. The skin starts on B q with a tiny deterministic
//! pseudo-random height noise (`noise` × edge) that breaks the symmetry. Each step is one
//! two-step solve: shell statics under H x = H B q, then the quasi-static interior with the
//! skin's Bᵀ F_x and Bᵀ K_x B. The result is the skin's height above the embedded surface,
//! w = z − (B q)_z, along the middle row of the sheet (the compression axis).
//!
//! All lengths scale with the predicted wavelength λ (slab length, sheet width, edge length,
//! cell size, σ), so every (E_x/E_q, h) point costs the same and holds the same number of
//! wavelengths: λ stays well below the slab size by construction.

use crate::coupling::cluster_width::sigma_for_wavelength;
use crate::coupling::clusters::ClusterStats;
use crate::coupling::embedded::EmbeddedShell;
use crate::coupling::two_step::{two_step_with, InteriorMode, TwoStepReport};
use crate::coupling::wavelength::Bilayer;
use crate::fem::{BackwardEuler, Interior, LinearSolver, Material, StepSettings};
use crate::lattice::{shape, Element, ElementKind, ElementOrder, Lattice, MaterialPoint};
use crate::mesh::TriMesh;
use crate::shell::sheet::equilateral_sheet;
use crate::shell::ShellMaterial;
use crate::solver::{HessianMode, SolveStatus, StaticSettings};
use anyhow::{bail, Context};
use nalgebra::Vector3;
use std::time::Instant;

/// Settings of the compressed-slab scene. Lengths are in wavelengths λ (the predicted
/// critical wavelength of `bilayer`) unless stated.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SlabSettings {
    /// Skin and interior materials and skin thickness (SI).
    pub bilayer: Bilayer,
    /// Interior mass density (kg/m³); irrelevant for the quasi-static solve, kept physical.
    pub density: f64,
    /// Slab length L along the compression axis, in λ.
    pub length: f64,
    /// Sheet width W across the compression axis, in λ.
    pub width: f64,
    /// Lattice cells along the length (the cell size is L / cells_along).
    pub cells_along: usize,
    /// Lattice cells along the depth (D = depth_cells × cell size).
    pub depth_cells: usize,
    /// Element order of the lattice.
    pub order: ElementOrder,
    /// Skin edge length as vertices per λ (λ / edge).
    pub vertices_per_wavelength: f64,
    /// Prescribed compressive strain ε along x (dimensionless, > 0).
    pub compression: f64,
    /// Cluster width σ as a multiple of the derived width
    /// [`crate::coupling::cluster_width::sigma_for_wavelength`] (≈ λ/2; 1 is the default).
    pub sigma_factor: f64,
    /// Loading steps: the strain grows geometrically from `onset` × ε_b to `compression`
    /// over this many steps, one two-step solve (shell statics, interior quasi-statics) each.
    pub steps: usize,
    /// First strain of the ramp as a multiple of ε_b = (2π h / λ)² / 12, the strain at which
    /// a free sheet buckles into waves of length λ (bending against membrane compression).
    pub onset: f64,
    /// Amplitude of the symmetry-breaking height noise, in skin edge lengths.
    pub noise: f64,
    /// Seed of the symmetry-breaking noise.
    pub seed: u64,
    /// Amplitude, in λ, of a prescribed smooth transverse bend of the interior, z ↦ z +
    /// bend · λ · sin(2π x / (bend_period · λ)) applied to every lattice node by its rest x.
    /// When positive the whole interior is held (every node prescribed: a kinematic base),
    /// so the embedded surface is the element interpolation of a smooth curve: C⁰ with
    /// kinks at the cell faces for trilinear elements, C¹ for quadratic B-splines. 0 = flat.
    #[serde(default)]
    pub bend: f64,
    /// Period of the bend, in λ (used when `bend` > 0).
    #[serde(default)]
    pub bend_period: f64,
    /// Phase of the bend, in periods: the bend is bend · λ · sin(2π (x / (bend_period · λ) +
    /// bend_phase)). Shifting it moves the bend's peaks against the element grid by
    /// bend_phase · bend_period · λ (m) without moving the grid. 0 = a sine starting at x = 0.
    #[serde(default)]
    pub bend_phase: f64,
}

impl SlabSettings {
    /// The default scene for a bilayer: 8 λ long, 1.2 λ wide, 4 cells along, 2 deep,
    /// quadratic elements, 10 vertices per λ, 6 % compression reached in 8 geometric
    /// loading steps from 1.5 ε_b, σ from [`sigma_for_wavelength`].
    pub fn new(bilayer: Bilayer) -> Self {
        Self {
            bilayer,
            density: 1000.0,
            length: 8.0,
            width: 1.2,
            cells_along: 4,
            depth_cells: 2,
            order: ElementOrder::Quadratic,
            vertices_per_wavelength: 10.0,
            compression: 0.06,
            sigma_factor: 1.0,
            steps: 8,
            onset: 1.5,
            noise: 1e-3,
            seed: 1,
            bend: 0.0,
            bend_period: 4.0,
            bend_phase: 0.0,
        }
    }

    /// The prescribed bend height (m) at rest position `x` (m) for predicted wavelength
    /// `lambda` (m): bend · λ · sin(2π (x / (bend_period · λ) + bend_phase)); 0 when `bend`
    /// is 0.
    pub fn bend_height(&self, lambda: f64, x: f64) -> f64 {
        if self.bend <= 0.0 {
            return 0.0;
        }
        let period = self.bend_period * lambda;
        self.bend * lambda * (2.0 * std::f64::consts::PI * (x / period + self.bend_phase)).sin()
    }

    /// Check the settings; the error names the field.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.bilayer.validate().map_err(anyhow::Error::msg)?;
        let pos = |v: f64, name: &str| -> anyhow::Result<()> {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                bail!("slab setting `{name}` must be positive, got {v}")
            }
        };
        pos(self.density, "density")?;
        pos(self.length, "length")?;
        pos(self.width, "width")?;
        pos(self.vertices_per_wavelength, "vertices_per_wavelength")?;
        pos(self.compression, "compression")?;
        pos(self.sigma_factor, "sigma_factor")?;
        if !(self.noise.is_finite() && self.noise >= 0.0) {
            bail!(
                "slab setting `noise` must be ≥ 0 (edge lengths), got {}",
                self.noise
            );
        }
        if self.compression >= 0.5 {
            bail!(
                "slab setting `compression` = {} is a strain; use less than 0.5",
                self.compression
            );
        }
        pos(self.onset, "onset")?;
        if !(self.bend.is_finite() && self.bend >= 0.0) {
            bail!(
                "slab setting `bend` must be ≥ 0 (wavelengths), got {}",
                self.bend
            );
        }
        if self.bend > 0.0 {
            pos(self.bend_period, "bend_period")?;
        }
        if !self.bend_phase.is_finite() {
            bail!(
                "slab setting `bend_phase` must be finite (periods), got {}",
                self.bend_phase
            );
        }
        if self.cells_along == 0 || self.depth_cells == 0 || self.steps == 0 {
            bail!("slab settings `cells_along`, `depth_cells` and `steps` must be at least 1");
        }
        if self.vertices_per_wavelength < 4.0 {
            bail!(
                "slab setting `vertices_per_wavelength` = {} cannot resolve a wrinkle; use ≥ 4",
                self.vertices_per_wavelength
            );
        }
        Ok(())
    }
}

/// The outcome of one slab run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SlabResult {
    /// Predicted critical wavelength λ (m).
    pub predicted: f64,
    /// Cluster width σ used (m).
    pub sigma: f64,
    /// Height profile along the compression axis: (x position, height w above the embedded
    /// surface), both in m, ordered by x.
    pub profile: Vec<(f64, f64)>,
    /// Slab length L at rest (m).
    pub length: f64,
    /// Skin vertices.
    pub skin_vertices: usize,
    /// Lattice nodes.
    pub nodes: usize,
    /// Cluster statistics.
    pub clusters: ClusterStats,
    /// Compressive strain of each loading step.
    pub strains: Vec<f64>,
    /// Reports of each loading step's two-step solve.
    pub rounds: Vec<TwoStepReport>,
    /// True when every shell statics converged.
    pub converged: bool,
    /// Wall-clock seconds of the whole run.
    pub seconds: f64,
    /// Lattice cell size (m) at rest.
    pub cell: f64,
    /// Deformed x positions (m) of the lattice's cell faces x = i · cell (i = 0 ..=
    /// cells_along) on the slab's top surface along the sheet's middle row, i.e. the
    /// element boundaries in the frame of `profile`, ordered by x.
    pub faces: Vec<f64>,
    /// The middle row of the sheet, ordered by deformed x: the same samples as `profile`
    /// with the rest position and the embedded surface's height.
    pub row: Vec<RowSample>,
    /// Final skin positions (m), for export and inspection.
    #[serde(skip)]
    pub skin: Vec<Vector3<f64>>,
    /// The skin's rest mesh.
    #[serde(skip)]
    pub mesh: TriMesh,
}

/// One skin vertex of the sheet's middle row after the last load step.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct RowSample {
    /// Rest x position (m) of the vertex.
    pub rest_x: f64,
    /// Deformed x position (m) of the vertex.
    pub x: f64,
    /// Skin height z (m) of the vertex.
    pub z: f64,
    /// Height (m) of the embedded surface B q at the vertex; `z − surface_z` is the
    /// `profile` height w.
    pub surface_z: f64,
}

/// A regular block lattice of `dims` cubic cells of edge `cell` (m) from `origin`, one volume
/// element per cell, neighbouring elements sharing their overlapping nodes; `vertex_points`
/// is left empty.
pub fn block_lattice(
    origin: Vector3<f64>,
    cell: f64,
    dims: [usize; 3],
    order: ElementOrder,
) -> Lattice {
    let k = order.per_axis();
    let nn = [dims[0] + k - 1, dims[1] + k - 1, dims[2] + k - 1];
    let id = |g: [usize; 3]| g[0] + nn[0] * (g[1] + nn[1] * g[2]);
    let off = order.node_offset();
    let mut rest = Vec::with_capacity(nn[0] * nn[1] * nn[2]);
    let mut grid = Vec::with_capacity(rest.capacity());
    for kz in 0..nn[2] {
        for jy in 0..nn[1] {
            for ix in 0..nn[0] {
                grid.push([ix, jy, kz]);
                rest.push(
                    origin + Vector3::new(ix as f64 + off, jy as f64 + off, kz as f64 + off) * cell,
                );
            }
        }
    }
    let mut elements = Vec::new();
    for cz in 0..dims[2] {
        for cy in 0..dims[1] {
            for cx in 0..dims[0] {
                let nodes = (0..k * k * k)
                    .map(|a| {
                        let o = crate::lattice::basis::local_offset(order, a);
                        id([cx + o[0], cy + o[1], cz + o[2]])
                    })
                    .collect();
                elements.push(Element {
                    cell: [cx, cy, cz],
                    nodes,
                    kind: ElementKind::Volume,
                });
            }
        }
    }
    let pinned = vec![false; rest.len()];
    Lattice {
        order,
        origin,
        cell_size: cell,
        dims,
        elements,
        rest,
        grid,
        pinned,
        vertex_points: Vec::new(),
        closed: true,
        depth: dims[2] as f64 * cell,
        graph: Vec::new(),
    }
}

/// The material point of rest position `p` in a block lattice (the cell containing it,
/// points on the far faces going to the last cell).
pub fn locate_in_block(lattice: &Lattice, p: &Vector3<f64>) -> MaterialPoint {
    let r = (p - lattice.origin) / lattice.cell_size;
    let c: [usize; 3] =
        [0, 1, 2].map(|d| (r[d].floor().max(0.0) as usize).min(lattice.dims[d] - 1));
    let e = c[0] + lattice.dims[0] * (c[1] + lattice.dims[1] * c[2]);
    lattice.locate_in_element(e, p)
}

/// A small deterministic pseudo-random number in [−1, 1] (SplitMix64).
fn noise(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64 * 2.0 - 1.0
}

/// Run the compressed slab and return the skin's height profile along x.
pub fn run_slab(s: &SlabSettings) -> anyhow::Result<SlabResult> {
    s.validate()?;
    let t0 = Instant::now();
    let g = SlabGeometry::new(s);
    let sheet = equilateral_sheet(g.nx, g.ny, g.edge);
    let lattice = block_lattice(
        Vector3::zeros(),
        g.cell,
        [s.cells_along, g.cells_y, s.depth_cells],
        s.order,
    );
    let mesh = on_top_face(&sheet.mesh, &g);
    let sigma = s.sigma_factor * sigma_for_wavelength(&mesh, g.lambda);
    let mut skin = slab_skin(s, &g, &lattice, &mesh, sigma)?;
    let strains = loading_strains(s, g.lambda);
    let mut be = slab_interior(s, &g, &lattice, strains[0])?;
    start_with_noise(&mut skin, &be.q, s, g.edge)?;
    let rounds = load_ramp(&mut be, &mut skin, &strains, 0.5 * g.length)?;
    // Final shell statics at the final interior state.
    let last = skin.solve(&be.q)?;
    let converged = rounds
        .iter()
        .all(|r| r.shell.status == SolveStatus::Converged)
        && last.status == SolveStatus::Converged;
    let x = skin.x();
    let mid = &sheet.rows[g.ny / 2];
    let row = middle_row(mid, &mesh, x, &skin.embedded_positions(&be.q));
    let profile: Vec<(f64, f64)> = row.iter().map(|r| (r.x, r.z - r.surface_z)).collect();
    let y_mid = mesh.positions[mid[mid.len() / 2]].y;
    let faces = face_positions(&lattice, &be.q, s.cells_along, y_mid, g.depth);
    let skin_pos = (0..mesh.positions.len())
        .map(|v| Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]))
        .collect();
    Ok(SlabResult {
        predicted: g.lambda,
        sigma,
        profile,
        length: g.length,
        skin_vertices: mesh.positions.len(),
        nodes: lattice.node_count(),
        clusters: skin.cluster_stats(),
        strains,
        rounds,
        converged,
        seconds: t0.elapsed().as_secs_f64(),
        cell: g.cell,
        faces,
        row,
        skin: skin_pos,
        mesh,
    })
}

/// The sizes of a slab scene, derived from its settings and the predicted wavelength.
struct SlabGeometry {
    /// Predicted critical wavelength λ (m).
    lambda: f64,
    /// Skin edge length (m).
    edge: f64,
    /// Sheet triangles along x.
    nx: usize,
    /// Sheet rows across (along y).
    ny: usize,
    /// Slab length L along x (m), a whole number of edges.
    length: f64,
    /// Lattice cell size (m).
    cell: f64,
    /// Slab depth D (m): the skin lies at z = D.
    depth: f64,
    /// Sheet width W across x (m).
    width: f64,
    /// Lattice cells across (along y), enough to hold the sheet.
    cells_y: usize,
}

impl SlabGeometry {
    /// The sizes for settings `s`.
    fn new(s: &SlabSettings) -> Self {
        let lambda = s.bilayer.critical_wavelength();
        let edge = lambda / s.vertices_per_wavelength;
        let nx = (s.length * s.vertices_per_wavelength).round().max(2.0) as usize;
        let length = nx as f64 * edge;
        let ny = ((s.width * lambda) / (edge * 3f64.sqrt() / 2.0))
            .round()
            .max(2.0) as usize;
        let cell = length / s.cells_along as f64;
        let depth = s.depth_cells as f64 * cell;
        let width = ny as f64 * edge * 3f64.sqrt() / 2.0;
        let cells_y = ((width / cell).ceil() as usize).max(1);
        Self {
            lambda,
            edge,
            nx,
            ny,
            length,
            cell,
            depth,
            width,
            cells_y,
        }
    }
}

/// The flat sheet moved onto the top face z = D, centred across the lattice's width.
fn on_top_face(sheet: &TriMesh, g: &SlabGeometry) -> TriMesh {
    let y0 = 0.5 * (g.cells_y as f64 * g.cell - g.width);
    let mut mesh = sheet.clone();
    for p in &mut mesh.positions {
        *p = Vector3::new(p.x, p.y + y0, g.depth);
    }
    mesh
}

/// The embedding of each vertex of `mesh` in the block lattice: (vertex, node, weight) for
/// every non-zero shape function of the element holding it.
fn block_embedding(lattice: &Lattice, mesh: &TriMesh) -> Vec<(usize, usize, f64)> {
    let points: Vec<MaterialPoint> = mesh
        .positions
        .iter()
        .map(|p| locate_in_block(lattice, p))
        .collect();
    let mut embedding = Vec::new();
    for (v, mp) in points.iter().enumerate() {
        let sh = shape(lattice.order, mp.xi);
        for a in 0..sh.n {
            if sh.val[a] != 0.0 {
                embedding.push((v, lattice.elements[mp.element].nodes[a], sh.val[a]));
            }
        }
    }
    embedding
}

/// The slab's skin: `mesh` embedded in `lattice` with cluster width `sigma` (m), shell
/// statics to a tolerance relative to the skin's membrane force, failed load steps redone in
/// increments.
fn slab_skin(
    s: &SlabSettings,
    g: &SlabGeometry,
    lattice: &Lattice,
    mesh: &TriMesh,
    sigma: f64,
) -> anyhow::Result<EmbeddedShell> {
    let b = s.bilayer;
    let material = ShellMaterial {
        young: b.skin_modulus,
        poisson: b.skin_poisson,
        thickness: b.thickness,
    };
    let settings = StaticSettings {
        tolerance: 1e-9 * b.skin_modulus * b.thickness * g.edge,
        max_iterations: 200,
        hessian: HessianMode::Auto,
        energy_merit: true,
        ..Default::default()
    };
    let mut skin = EmbeddedShell::new(
        mesh.clone(),
        material,
        block_embedding(lattice, mesh),
        lattice.node_count(),
        sigma,
        settings,
    )
    .context("building the slab's skin")?;
    // A failed load step is redone in up to 4 increments (held, bent quadratic interiors
    // otherwise stall from the first step; see `EmbeddedShell::set_continuation_levels`).
    skin.set_continuation_levels(2);
    Ok(skin)
}

/// The compressive strain of each load step: geometric from `onset` × ε_b (the buckling
/// strain at λ = `lambda`, m) to `compression`, or `compression` alone for one step.
fn loading_strains(s: &SlabSettings, lambda: f64) -> Vec<f64> {
    let eps_b = (2.0 * std::f64::consts::PI * s.bilayer.thickness / lambda).powi(2) / 12.0;
    let start = (s.onset * eps_b).min(s.compression);
    if s.steps == 1 {
        vec![s.compression]
    } else {
        (0..s.steps)
            .map(|i| start * (s.compression / start).powf(i as f64 / (s.steps - 1) as f64))
            .collect()
    }
}

/// Scale the x coordinates of the flat positions `q` (m) about `xc` (m) by `factor`.
fn compress(q: &mut [f64], xc: f64, factor: f64) {
    for n in 0..q.len() / 3 {
        q[3 * n] = xc + factor * (q[3 * n] - xc);
    }
}

/// The pinned lattice nodes: the node layers shaping the two x-end faces and the bottom
/// face, or every node when the interior is held on a bend.
fn slab_pins(lattice: &Lattice, bend: bool) -> Vec<bool> {
    let k = lattice.order.per_axis();
    let nn = [
        lattice.dims[0] + k - 1,
        lattice.dims[1] + k - 1,
        lattice.dims[2] + k - 1,
    ];
    let layers = k - 1; // nodes that shape the boundary face
    lattice
        .grid
        .iter()
        .map(|g| g[0] < layers || g[0] >= nn[0] - layers || g[2] < layers || bend)
        .collect()
}

/// The quasi-static interior: rest lattice (bent when `s.bend` > 0) compressed by
/// `first_strain` about the slab's middle, ends and bottom pinned.
fn slab_interior(
    s: &SlabSettings,
    g: &SlabGeometry,
    lattice: &Lattice,
    first_strain: f64,
) -> anyhow::Result<BackwardEuler> {
    let b = s.bilayer;
    let interior = Interior::new(
        lattice,
        &Material {
            young: b.interior_modulus,
            poisson: b.interior_poisson.min(0.49),
            density: s.density,
        },
    )?;
    let mut q = lattice.rest_flat();
    let pinned = slab_pins(lattice, s.bend > 0.0);
    if s.bend > 0.0 {
        for n in 0..lattice.node_count() {
            q[3 * n + 2] += s.bend_height(g.lambda, lattice.rest[n].x);
        }
    }
    let step = StepSettings {
        gravity: [0.0; 3],
        linear_solver: LinearSolver::Cholesky,
        tangent: crate::fem::Tangent::Consistent,
        max_newton: 30,
        ..Default::default()
    };
    compress(&mut q, 0.5 * g.length, 1.0 - first_strain);
    Ok(BackwardEuler::new(interior, q, pinned, step)?)
}

/// Start the skin on the embedded surface of interior positions `q` plus the settings'
/// tiny deterministic height noise (`s.noise` × `edge`, m).
fn start_with_noise(
    skin: &mut EmbeddedShell,
    q: &[f64],
    s: &SlabSettings,
    edge: f64,
) -> anyhow::Result<()> {
    let mut seed = s.seed;
    let x0: Vec<f64> = skin
        .embedded_positions(q)
        .iter()
        .flat_map(|p| [p.x, p.y, p.z + s.noise * edge * noise(&mut seed)])
        .collect();
    skin.set_x(&x0)
}

/// One two-step solve per load strain, compressing the interior about `xc` (m) from each
/// strain to the next (the first is already applied).
fn load_ramp(
    be: &mut BackwardEuler,
    skin: &mut EmbeddedShell,
    strains: &[f64],
    xc: f64,
) -> anyhow::Result<Vec<TwoStepReport>> {
    let f_ext = vec![0.0; be.q.len()];
    let mut rounds = Vec::with_capacity(strains.len());
    for (i, &eps) in strains.iter().enumerate() {
        if i > 0 {
            compress(&mut be.q, xc, (1.0 - eps) / (1.0 - strains[i - 1]));
        }
        rounds.push(two_step_with(be, skin, &f_ext, InteriorMode::QuasiStatic)?);
    }
    Ok(rounds)
}

/// The samples of sheet row `mid` from skin positions `x` (flat, m) and embedded surface
/// `bq` (m), ordered by deformed x.
fn middle_row(mid: &[usize], mesh: &TriMesh, x: &[f64], bq: &[Vector3<f64>]) -> Vec<RowSample> {
    let mut row: Vec<RowSample> = mid
        .iter()
        .map(|&v| RowSample {
            rest_x: mesh.positions[v].x,
            x: x[3 * v],
            z: x[3 * v + 2],
            surface_z: bq[v].z,
        })
        .collect();
    row.sort_by(|a, b| a.x.total_cmp(&b.x));
    row
}

/// Deformed x (m) of the element boundaries x = i · cell on the top surface z = `depth` at
/// y = `y_mid` (m), mapped by the interior positions `q`.
fn face_positions(
    lattice: &Lattice,
    q: &[f64],
    cells_along: usize,
    y_mid: f64,
    depth: f64,
) -> Vec<f64> {
    let cell = lattice.cell_size;
    (0..=cells_along)
        .map(|i| {
            let p = Vector3::new(i as f64 * cell, y_mid, depth);
            let mp = locate_in_block(lattice, &p);
            let sh = shape(lattice.order, mp.xi);
            (0..sh.n)
                .map(|a| sh.val[a] * q[3 * lattice.elements[mp.element].nodes[a]])
                .sum()
        })
        .collect()
}
