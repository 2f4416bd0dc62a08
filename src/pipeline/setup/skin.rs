//! The skin stages of the set-up: which refined triangles the thin shell simulates (the scene's
//! mask minus degenerate triangles; the rest follows the interior), and the embedded shell over
//! them with its constraint clusters of width σ (the `clusters` stage).

use super::refine::RefinedSkin;
use crate::coupling::cluster_width::sigma_for_wavelength;
use crate::coupling::clusters::Clusters;
use crate::coupling::embedded::EmbeddedShell;
use crate::coupling::refine;
use crate::mesh::grid::PointGrid;
use crate::mesh::TriMesh;
use crate::pipeline::record::{Stage, StagePlan};
use crate::scene::{Scene, SkinSolver};
use crate::solver::patch::PatchSettings;
use crate::solver::statics::{HessianMode, LinearAlgebra, StaticSettings};
use anyhow::{anyhow, Context};
use std::collections::HashSet;
use std::time::Instant;

/// Quality (2 r_in / r_circ) below which a skin triangle is left out of the shell (it still
/// follows the interior): such triangles have no usable rest shape.
pub const DEGENERATE_QUALITY: f64 = 1e-3;

/// What the shell stages work from.
#[derive(Clone, Copy)]
pub struct ShellInput<'a> {
    /// The refined skin.
    pub refined: &'a RefinedSkin,
    /// Lattice nodes the skin is embedded in.
    pub nodes: usize,
    /// The scene (skin material, statics settings).
    pub scene: &'a Scene,
    /// Critical wavelength the clusters place wrinkles at (m).
    pub lambda: f64,
    /// The rig, in errors.
    pub path: &'a str,
}

/// The simulated skin: the embedded shell and which refined vertices it moves.
pub struct SimulatedSkin {
    /// The thin shell tied to the lattice by its clusters.
    pub shell: EmbeddedShell,
    /// Refined (export) vertex of each shell vertex.
    pub vertices: Vec<usize>,
    /// Cluster width σ (m).
    pub sigma: f64,
}

/// Refined triangles the shell may simulate: inside every box of `scene.skin.mask` (all when
/// it is empty) and not degenerate; degenerate ones are reported in `warnings`. Also, per
/// refined vertex, whether it is a corner of a degenerate triangle: such a triangle follows
/// the interior with its corners ([`pin_degenerate`]), so the skin on either side of it stays
/// joined rather than torn along it.
pub fn select_triangles(
    mesh: &TriMesh,
    scene: &Scene,
    path: &str,
    warnings: &mut Vec<String>,
) -> (Vec<usize>, Vec<bool>) {
    let mask = &scene.skin.mask;
    let quality = crate::mesh::quality::check(mesh, DEGENERATE_QUALITY);
    let degenerate: HashSet<usize> = quality.slivers.iter().map(|s| s.triangle).collect();
    if !degenerate.is_empty() {
        warnings.push(format!(
            "{path}: {} degenerate skin triangles are left out of the shell and follow the interior. {}",
            degenerate.len(),
            quality.message()
        ));
    }
    let mut on_degenerate = vec![false; mesh.positions.len()];
    for &t in &degenerate {
        mesh.triangles[t]
            .iter()
            .for_each(|&v| on_degenerate[v] = true);
    }
    let triangles = (0..mesh.triangles.len())
        .filter(|t| !degenerate.contains(t))
        .filter(|&t| {
            mask.is_empty()
                || mesh.triangles[t]
                    .iter()
                    .all(|&v| mask.iter().any(|b| b.contains(&mesh.positions[v])))
        })
        .collect();
    (triangles, on_degenerate)
}

/// Per triangle of the welded skin `mesh`: whether its bounding box meets a box of
/// `scene.skin.mask` (m), so that some of its refined skin may lie inside; `None` without a
/// mask. The skin outside the mask follows the interior and is not refined.
pub fn within_mask(mesh: &TriMesh, scene: &Scene) -> Option<Vec<bool>> {
    let mask = &scene.skin.mask;
    if mask.is_empty() {
        return None;
    }
    let meets = |t: &[usize; 3]| {
        let p = t.map(|v| mesh.positions[v]);
        let lo = p[0].inf(&p[1]).inf(&p[2]);
        let hi = p[0].sup(&p[1]).sup(&p[2]);
        mask.iter()
            .any(|b| (0..3).all(|k| lo[k] <= b.max[k] && hi[k] >= b.min[k]))
    };
    Some(mesh.triangles.iter().map(meets).collect())
}

/// Pin the shell's vertices that are corners of degenerate triangles (`on_degenerate`, per
/// refined vertex) to the interior, beside those already pinned: the degenerate triangle is
/// not simulated, and with its corners free the shell on its two sides would move apart (on
/// the stability sweep's slivers, corners 0.25 µm apart at rest ended 0.2 mm apart, the skin
/// through itself).
pub fn pin_degenerate(sim: &mut SimulatedSkin, on_degenerate: &[bool]) -> anyhow::Result<()> {
    let corners: Vec<usize> = (0..sim.vertices.len())
        .filter(|&i| on_degenerate[sim.vertices[i]])
        .collect();
    pin_also(sim, corners)
}

/// Pin the shell's `vertices` to the interior beside those already pinned.
fn pin_also(
    sim: &mut SimulatedSkin,
    vertices: impl IntoIterator<Item = usize>,
) -> anyhow::Result<()> {
    let mut pinned = sim.shell.pinned().to_vec();
    let before = pinned.len();
    pinned.extend(vertices);
    if pinned.len() > before {
        sim.shell.set_pinned(&pinned)?;
    }
    Ok(())
}

/// Pin the skin's slits to the interior: the sides of a slit modelled closed (lips that
/// touch at rest, kept apart by the weld because the blend shapes part them, or nearly
/// touch: closer than half the boundary's edges there) have no contact between them, so
/// their edge vertices and the ring of triangles on each side follow B q, as the lattice,
/// cut along the slit, parts them. Where the lips press together the interior holds them
/// edge to edge, and with the edge alone pinned the first ring's wrinkles (0.01–0.4 mm)
/// pushed each lip through the other in 35 of the demo's 262 frames under the 21.6 mm
/// lattice's muscles (redone by tracking, 222 s); contact, which the skin does not model,
/// would hold that ring flat against the other lip. The capture head's lips are 0.4 mm apart
/// at rest: left free, its smiles' wrinkles at the mouth's corners passed one lip through
/// the other in 38 of its 331 frames.
pub fn pin_slits(sim: &mut SimulatedSkin) -> anyhow::Result<()> {
    let rest = &sim.shell.shell.rest;
    let on_slit = slit_vertices(rest);
    let ring: Vec<usize> = rest
        .triangles
        .iter()
        .filter(|t| t.iter().any(|&v| on_slit[v]))
        .flatten()
        .copied()
        .collect();
    pin_also(sim, ring)
}

/// The vertices of `mesh` on a slit modelled closed: boundary vertices with another boundary
/// vertex, not joined to it by an edge, within half the shortest boundary edge at either.
fn slit_vertices(mesh: &TriMesh) -> Vec<bool> {
    let n = mesh.positions.len();
    let mut slit = vec![false; n];
    let Ok(topo) = crate::mesh::topology::Topology::new(mesh) else {
        return slit;
    };
    let mut reach = vec![f64::INFINITY; n];
    let mut joined: HashSet<(usize, usize)> = HashSet::new();
    for &e in &topo.boundary_edges {
        let [a, b] = topo.edges[e];
        let half = 0.5 * (mesh.positions[a] - mesh.positions[b]).norm();
        reach[a] = reach[a].min(half);
        reach[b] = reach[b].min(half);
        joined.insert((a.min(b), a.max(b)));
    }
    let edge: Vec<usize> = (0..n).filter(|&v| reach[v].is_finite()).collect();
    // A pair within reach lies within the largest reach, the grid's cell.
    let cell = edge.iter().map(|&v| reach[v]).fold(0.0f64, f64::max);
    let grid = PointGrid::new(cell, edge.iter().map(|&v| (v, mesh.positions[v])));
    for &v in &edge {
        slit[v] = grid.near(&mesh.positions[v]).any(|u| {
            let close = (mesh.positions[u] - mesh.positions[v]).norm() < reach[u].min(reach[v]);
            u != v && close && !joined.contains(&(u.min(v), u.max(v)))
        });
    }
    slit
}

/// The record of a run whose shell simulates nothing; `compressed` says whether any triangle
/// was compressed enough to wrinkle (the `select` stage).
pub fn skipped_shell(scene: &Scene, compressed: bool) -> StagePlan {
    StagePlan::skipped(
        Stage::Shell,
        if !compressed {
            "no frame compresses the skin past the wrinkling threshold: the whole skin follows the blend shapes".to_string()
        } else if scene.skin.mask.is_empty() {
            "every skin triangle is degenerate".to_string()
        } else {
            "the skin mask selects no triangle: the whole skin follows the interior".to_string()
        },
    )
}

/// Triplets (row, column, value) of a stiffness over node dofs (N/m).
pub type Stiffness = Vec<(usize, usize, f64)>;

/// The skin left out of the simulation, riding on the interior (x = B q): a shell over
/// `triangles` and its stiffness Bᵀ K_x B at rest (N/m, triplets over node dofs), so the
/// interior keeps that skin's elasticity; `None` when nothing is left out.
pub fn left_out_skin(
    input: &ShellInput,
    triangles: &[usize],
) -> anyhow::Result<Option<(SimulatedSkin, Stiffness)>> {
    if triangles.is_empty() {
        return Ok(None);
    }
    // Never solved: it needs no constraints, only its elasticity (σ = λ/π is nominal; a
    // varying thickness rebuilds clusters from it).
    let part = sub_mesh(&input.refined.mesh, triangles);
    let none = Clusters {
        sigma: input.lambda / std::f64::consts::PI,
        centres: Vec::new(),
        entries: Vec::new(),
        vertices: part.1.len(),
    };
    let rest = shell_over(input, triangles, part, ClusterSource::Given(none))?;
    let stiffness = rest.shell.coupling_terms().0;
    Ok(Some((rest, stiffness)))
}

/// The candidate triangles outside `selected` that share a vertex with it: the ring the
/// selected shell is clamped to (its vertices outside the selection follow B q).
pub fn border_ring(mesh: &TriMesh, candidates: &[usize], selected: &[usize]) -> Vec<usize> {
    let mut in_selection = vec![false; mesh.positions.len()];
    let mut chosen = vec![false; mesh.triangles.len()];
    for &t in selected {
        chosen[t] = true;
        for &v in &mesh.triangles[t] {
            in_selection[v] = true;
        }
    }
    candidates
        .iter()
        .copied()
        .filter(|&t| !chosen[t] && mesh.triangles[t].iter().any(|&v| in_selection[v]))
        .collect()
}

/// The `clusters` stage for a selected part of the skin the shell could simulate
/// (`candidates`): a shell over the `selected` triangles and their border `ring`, whose
/// vertices outside the selection are pinned to the interior (x = B q, as the left-out skin
/// beyond them), with the whole candidate skin's clusters and σ restricted to the selection (a
/// cluster stays when its centre and half its weight lie in it), so that inside the selection
/// the constraints are the whole skin's whatever was left out. With a varying thickness the
/// clusters are built on the part itself.
pub fn build_selected_shell(
    input: &ShellInput,
    candidates: &[usize],
    selected: &[usize],
    ring: &[usize],
) -> anyhow::Result<(SimulatedSkin, StagePlan)> {
    if candidates.len() == selected.len() {
        return build_shell(input, selected);
    }
    let t = Instant::now();
    let mesh = &input.refined.mesh;
    let (whole, whole_vertices) = sub_mesh(mesh, candidates);
    let sigma = sigma_for_wavelength(&whole, input.lambda);
    let shell_triangles: Vec<usize> = selected.iter().chain(ring).copied().collect();
    let part = sub_mesh(mesh, &shell_triangles);
    let mut is_selected = vec![false; mesh.positions.len()];
    for &t in selected {
        for &v in &mesh.triangles[t] {
            is_selected[v] = true;
        }
    }
    let mut local_of_refined = vec![None; mesh.positions.len()];
    let mut pinned = Vec::new();
    for (i, &v) in part.1.iter().enumerate() {
        if is_selected[v] {
            local_of_refined[v] = Some(i);
        } else {
            pinned.push(i);
        }
    }
    let clusters = if input.refined.thickness.is_none() {
        let clusters = Clusters::build(&whole, sigma).map_err(|e| anyhow!("clusters: {e}"))?;
        let local: Vec<Option<usize>> = whole_vertices
            .iter()
            .map(|&v| local_of_refined[v])
            .collect();
        ClusterSource::Given(clusters.restrict(&local, part.1.len(), 0.5))
    } else {
        ClusterSource::Width(sigma)
    };
    let mut sim = shell_over(input, &shell_triangles, part, clusters)?;
    sim.shell.set_pinned(&pinned)?;
    let record = clusters_record(&sim, t);
    Ok((sim, record))
}

/// The sub-mesh of `triangles` with its own vertex numbering, and the refined vertex of each
/// of its vertices.
fn sub_mesh(mesh: &TriMesh, triangles: &[usize]) -> (TriMesh, Vec<usize>) {
    let mut local = vec![usize::MAX; mesh.positions.len()];
    let mut verts = Vec::new();
    let mut tris = Vec::with_capacity(triangles.len());
    for &t in triangles {
        let tri = mesh.triangles[t].map(|v| {
            if local[v] == usize::MAX {
                local[v] = verts.len();
                verts.push(v);
            }
            local[v]
        });
        tris.push(tri);
    }
    let sub = TriMesh::new(verts.iter().map(|&v| mesh.positions[v]).collect(), tris);
    (sub, verts)
}

/// The `clusters` stage: the embedded shell over `triangles` of the refined skin, its clusters
/// of the σ that puts wrinkles at λ (m), and the skin statics settings of the scene.
pub fn build_shell(
    input: &ShellInput,
    triangles: &[usize],
) -> anyhow::Result<(SimulatedSkin, StagePlan)> {
    let t = Instant::now();
    let part = sub_mesh(&input.refined.mesh, triangles);
    // σ that puts the wrinkles at λ on this mesh (the truncated kernel's first zero,
    // corrected for edge-path distances; see `coupling::embedded`).
    let sigma = sigma_for_wavelength(&part.0, input.lambda);
    let sim = shell_over(input, triangles, part, ClusterSource::Width(sigma))?;
    let record = clusters_record(&sim, t);
    Ok((sim, record))
}

/// The constraint clusters a shell is built with.
enum ClusterSource {
    /// Clusters of this width σ (m), built on the shell's own mesh.
    Width(f64),
    /// These clusters, over the shell's vertices.
    Given(Clusters),
}

/// Load-stepping levels of the skin by default: a skin solve that does not converge is
/// redone in 2, then 4 equal load steps. On the stability sweep's 50 % compression this
/// turns the one unconverged frame (72 iterations, residual 1e-2 N) into a converged one;
/// frames that converge directly never pay for it.
pub const DEFAULT_SKIN_CONTINUATION: usize = 2;

/// The skin's linear algebra for `solver.skin_solver` and wavelength `lambda` (m): the
/// patches (cells of side λ with an overlap of λ/2, a cluster's half-width, refactorised where
/// a Hessian column moved by more than [`PATCH_CHANGE`] of its diagonal) for `patches`, and
/// the lag cap and factor precision ([`LinearAlgebra`]): `global` is the reference, `lagged`
/// (the default) and `patches` the fast one.
fn linear_settings(scene: &Scene, lambda: f64) -> (Option<PatchSettings>, LinearAlgebra) {
    let patches = PatchSettings {
        size: lambda,
        overlap: 0.5 * lambda,
        change: PATCH_CHANGE,
        max_share: 0.5,
        max_solves: 20,
    };
    match scene.solver.skin_solver.unwrap_or_default() {
        SkinSolver::Global => (None, LinearAlgebra::REFERENCE),
        SkinSolver::Patches => (Some(patches), LinearAlgebra::FAST),
        SkinSolver::Lagged => (None, LinearAlgebra::FAST),
    }
}

/// The skin's Newton tolerance by default: the RMS residual force per vertex relative to
/// the skin's stretch stiffness E_x h/(1−ν_x²) × mean edge (so the test does not tighten as a
/// skin is refined). On the demo's frames 0–39 it moves the wrinkles by at most 1.9 µm (of
/// 1.98 mm) against a tolerance 100× tighter, and saves a fifth of the Newton iterations.
pub const SHELL_TOLERANCE: f64 = 1e-6;

/// Relative change of a Hessian column (Σ|ΔA| over the column / |diagonal|) beyond which the
/// local solver refactorises its patch. Measured on the demo's frames 0–39: 0.3 reproduces
/// the global solve to 22 nm (of 1.98 mm wrinkles); 3.0 was 8–10 % faster (40 whole and 5
/// patch factorisations against 24 and 47) but its lagged directions led the buckling
/// forehead onto another branch in some frames (1.76 mm apart, the same amplitude per 2λ
/// region within 1.9 %); 1.0 was no faster than 0.3.
pub const PATCH_CHANGE: f64 = 0.3;

/// The embedded shell over `triangles`, whose sub-mesh and refined vertices are `part`
/// ([`sub_mesh`]), with the scene's skin, thickness and statics settings.
fn shell_over(
    input: &ShellInput,
    triangles: &[usize],
    part: (TriMesh, Vec<usize>),
    clusters: ClusterSource,
) -> anyhow::Result<SimulatedSkin> {
    let (skin, scene, path) = (input.refined, input.scene, input.path);
    let (sub, vertices) = part;
    let emb: Vec<(usize, usize, f64)> = vertices
        .iter()
        .enumerate()
        .flat_map(|(i, &v)| skin.embedding.row(v).iter().map(move |&(n, w)| (i, n, w)))
        .collect();
    let edge = refine::mean_edge(&sub);
    let relative = scene.solver.shell_tolerance.unwrap_or(SHELL_TOLERANCE);
    let (patches, linear) = linear_settings(scene, input.lambda);
    let settings = linear.apply(StaticSettings {
        tolerance: scene
            .skin
            .material()?
            .residual_tolerance(relative, edge, sub.positions.len()),
        max_iterations: scene.solver.shell_iterations.unwrap_or(60),
        hessian: HessianMode::Auto,
        energy_merit: true,
        patches,
        ..StaticSettings::default()
    });
    let material = scene.skin.material()?;
    let nodes = input.nodes;
    let (shell, sigma) = match clusters {
        ClusterSource::Width(sigma) => (
            EmbeddedShell::new(sub, material, emb, nodes, sigma, settings),
            sigma,
        ),
        ClusterSource::Given(c) => {
            let sigma = c.sigma;
            let shell = EmbeddedShell::with_clusters(sub, material, emb, nodes, c, settings);
            (shell, sigma)
        }
    };
    let mut shell = shell.with_context(|| format!("{path}: setting up the skin"))?;
    if scene.skin.membrane == Some(crate::scene::MembraneLaw::Stvk) {
        shell.shell.membrane.law = crate::shell::membrane::MembraneLaw::StVenantKirchhoff;
    }
    shell.set_continuation_levels(
        scene
            .solver
            .skin_continuation
            .unwrap_or(DEFAULT_SKIN_CONTINUATION),
    );
    if let Some(h) = &skin.thickness {
        // The skin's own thickness per simulated triangle; the clusters widen with it
        // (σ ∝ λ ∝ h, from σ of the thinnest skin above).
        let sub_h: Vec<f64> = triangles.iter().map(|&t| h[t]).collect();
        shell
            .set_thickness(sub_h)
            .with_context(|| format!("{path}: setting up the skin thickness"))?;
    }
    Ok(SimulatedSkin {
        shell,
        vertices,
        sigma,
    })
}

/// The `clusters` stage's record of a built shell, timed from `t`.
fn clusters_record(sim: &SimulatedSkin, t: Instant) -> StagePlan {
    let st = sim.shell.cluster_stats();
    StagePlan::ran(
        Stage::Clusters,
        format!(
            "{} clusters of σ = {:.2} mm, {:.0} vertices each on average, {:.1} per vertex",
            st.clusters,
            sim.sigma * 1e3,
            st.vertices_per_cluster[1],
            st.clusters_per_vertex[1]
        ),
        t.elapsed().as_secs_f64() * 1e3,
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Aabb;

    fn two_triangles() -> TriMesh {
        use nalgebra::Vector3;
        TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(1.0, 2.0, 0.0),
            ],
            // The second triangle is collinear (degenerate).
            vec![[0, 1, 2], [1, 3, 4], [1, 3, 2]],
        )
    }

    #[test]
    fn selection_drops_degenerate_triangles_and_respects_the_mask() {
        let mesh = two_triangles();
        let mut scene = Scene::default();
        let mut warnings = Vec::new();
        let (triangles, on_degenerate) = select_triangles(&mesh, &scene, "f.glb", &mut warnings);
        assert_eq!(triangles, vec![0, 2]);
        // The collinear triangle's corners are the ones pinned to the interior.
        assert_eq!(on_degenerate, vec![false, true, false, true, true]);
        assert_eq!(warnings.len(), 1);
        assert!(warnings[0].starts_with("f.glb: 1 degenerate"));
        scene.skin.mask = vec![Aabb {
            min: [-0.1, -0.1, -0.1],
            max: [0.5, 1.1, 0.1],
        }];
        assert!(select_triangles(&mesh, &scene, "f.glb", &mut warnings)
            .0
            .is_empty());
        assert!(skipped_shell(&scene, true)
            .why
            .contains("mask selects no triangle"));
        assert!(skipped_shell(&scene, false)
            .why
            .starts_with("no frame compresses"));
    }

    #[test]
    fn only_triangles_meeting_the_mask_may_be_refined() {
        let mesh = two_triangles();
        let mut scene = Scene::default();
        assert!(within_mask(&mesh, &scene).is_none());
        // A box inside the first triangle, touching no vertex, meets it and no other.
        scene.skin.mask = vec![Aabb {
            min: [0.1, 0.1, -0.1],
            max: [0.2, 0.2, 0.1],
        }];
        assert_eq!(within_mask(&mesh, &scene), Some(vec![true, false, true]));
    }

    #[test]
    fn sub_mesh_renumbers_in_order_of_first_use() {
        let (sub, verts) = sub_mesh(&two_triangles(), &[2]);
        assert_eq!(verts, vec![1, 3, 2]);
        assert_eq!(sub.triangles, vec![[0, 1, 2]]);
        assert_eq!(sub.positions[1], two_triangles().positions[3]);
    }

    /// Two strips of triangles (unit spacing, 5 columns) facing each other across a gap:
    /// their facing edges are a slit modelled closed when the gap is under half their
    /// edges (0 and 0.4 here, as the face's lips and the capture head's), not when wider
    /// (0.6); the strips' outer edges never are.
    #[test]
    fn a_slit_is_a_boundary_closer_to_another_than_half_its_edges() {
        use nalgebra::Vector3;
        let strips = |gap: f64| {
            let mut positions = Vec::new();
            for (y0, y1) in [(-1.0 - 0.5 * gap, -0.5 * gap), (0.5 * gap, 1.0 + 0.5 * gap)] {
                for y in [y0, y1] {
                    for i in 0..5 {
                        positions.push(Vector3::new(f64::from(i), y, 0.0));
                    }
                }
            }
            let mut triangles = Vec::new();
            for s in 0..2 {
                let (a, b) = (10 * s, 10 * s + 5);
                for i in 0..4 {
                    triangles.push([a + i, a + i + 1, b + i + 1]);
                    triangles.push([a + i, b + i + 1, b + i]);
                }
            }
            TriMesh::new(positions, triangles)
        };
        for (gap, closed) in [(0.0, true), (0.4, true), (0.6, false)] {
            let slit = slit_vertices(&strips(gap));
            // The facing rows: the lower strip's upper row (5..10), the upper's lower (10..15).
            let facing: Vec<bool> = (0..20).map(|v| (5..15).contains(&v)).collect();
            for v in 0..20 {
                assert_eq!(slit[v], closed && facing[v], "gap {gap}, vertex {v}");
            }
        }
    }

    /// A 7 × 7 sheet with a slit modelled closed (lips that touch at rest: the middle three
    /// vertices of row 3 have a copy used by the triangles below it) and a shape that opens
    /// it (the rows below move down 1 mm, the copies with them): the weld keeps the copies
    /// apart, and the skin pins both sides of the slit to the interior.
    #[test]
    fn a_slit_modelled_closed_stays_open_and_its_sides_follow_the_interior() {
        use crate::pipeline::plan::Driver;
        use crate::pipeline::setup::test_support::{bump_sheet, face_of, set_up_sheet, sheet_rig};
        use nalgebra::Vector3;
        let n = 7;
        let mut mesh = bump_sheet(n);
        let copies: Vec<usize> = (2..5).map(|i| 3 * n + i).collect();
        let copy_of = |v: usize| copies.iter().position(|&c| c == v).map(|k| n * n + k);
        for (t, tri) in mesh.triangles.iter_mut().enumerate() {
            // Triangles of the row of cells below row 3 (j = 2) use the copies.
            if t / (2 * (n - 1)) == 2 {
                tri.iter_mut().for_each(|v| *v = copy_of(*v).unwrap_or(*v));
            }
        }
        let line: Vec<_> = copies.iter().map(|&c| mesh.positions[c]).collect();
        mesh.positions.extend(line);
        let mut face = face_of(mesh);
        let open = &mut face.targets[0];
        open.name = "open".into();
        for (v, d) in open.positions.iter_mut().enumerate() {
            let below = v >= n * n || v / n < 3;
            *d = if below {
                Vector3::new(0.0, -0.001, 0.0)
            } else {
                Vector3::zeros()
            };
        }
        let (rig, _) = sheet_rig(face);
        let (_, state, log) = set_up_sheet(&rig, Driver::Tracking, 0, |_| {});
        let weld = &log.stages[0];
        assert_eq!(weld.stage, Stage::Weld);
        assert!(
            weld.why
                .contains("3 vertices at a welded vertex kept apart"),
            "{}",
            weld.why
        );
        let skin = state.skin.expect("the whole skin is simulated");
        let rest = &skin.shell.rest.positions;
        let pinned_at = |p: &Vector3<f64>| {
            skin.pinned()
                .iter()
                .filter(|&&v| (rest[v] - p).norm() < 1e-12)
                .count()
        };
        // Refined, the slit holds more coincident pairs than the three loaded ones: each is
        // pinned on both sides.
        let pairs: Vec<usize> = (0..rest.len())
            .filter(|&v| (0..rest.len()).any(|w| w != v && (rest[w] - rest[v]).norm() < 1e-12))
            .collect();
        assert!(pairs.len() >= 6, "{} slit vertices", pairs.len());
        for v in pairs {
            assert_eq!(
                pinned_at(&rest[v]),
                2,
                "both sides of the slit at vertex {v}"
            );
        }
    }
}
