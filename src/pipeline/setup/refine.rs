//! The `refine` stage: the welded skin subdivided where it is simulated until it holds enough
//! vertices per critical wavelength, smoothly (modified butterfly) and with a conforming
//! transition to the coarse skin left out (see [`crate::coupling::refine`]), embedded in the
//! lattice, with the maps the export needs: each refined vertex's blend-shape target as a
//! combination of welded vertices (the subdivision operator S), and its place in the loaded
//! face (barycentric in its ancestor's loaded triangle).

use super::weld::Welded;
use crate::coupling::embedding::Embedding;
use crate::coupling::refine::{self, Ancestor, RefineReport, RefineSettings};
use crate::io::mesh::MeshInstance;
use crate::io::origin::VertexOrigin;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::pipeline::plan::SkinScale;
use crate::pipeline::record::{Stage, StagePlan};
use crate::scene::SkinSection;
use anyhow::Context;
use std::time::Instant;

/// The refined skin: the exported mesh and how it maps to the welded and loaded faces.
#[derive(Debug, Clone)]
pub struct RefinedSkin {
    /// The refined skin mesh (m); the welded vertices keep their indices and come first.
    pub mesh: TriMesh,
    /// For each refined vertex, (welded vertex, weight) pairs whose blend is its target: the
    /// subdivision operator S (rest shape and every blend shape's deltas go through it).
    pub target_of: Vec<Vec<(usize, f64)>>,
    /// For each refined vertex, its barycentric place in a loaded triangle (for the export).
    pub origin: Vec<VertexOrigin>,
    /// The embedding B of the refined vertices in the lattice (x = B q).
    pub embedding: Embedding,
    /// Skin thickness per refined triangle (m), when the scene varies it.
    pub thickness: Option<Vec<f64>>,
    /// For each refined triangle, the welded triangle it lies in and its corners'
    /// barycentric coordinates there (UVs, thickness and other surface data follow these;
    /// `Welded::loaded_triangle` leads on to the loaded triangle).
    pub ancestor: Vec<Ancestor>,
}

/// What the refinement works from: the loaded face, its weld, the lattice, the skin's scale
/// and the welded triangles to refine.
pub struct RefineInput<'a> {
    /// The loaded face (its triangles carry the per-triangle thickness).
    pub face: &'a MeshInstance,
    /// The welded face.
    pub welded: &'a Welded,
    /// The lattice the refined skin is embedded in.
    pub lattice: &'a Lattice,
    /// Thickness and critical wavelengths of the skin.
    pub scale: &'a SkinScale,
    /// The scale the rig is simulated at (named when the skin is too coarse).
    pub rig_scale: &'a crate::io::units::RigScale,
    /// Per welded triangle: simulated (the `select` stage); `None`: all of it.
    pub region: Option<&'a [bool]>,
}

/// The `refine` stage: subdivide each simulated triangle for its skin's wavelength
/// (`skin.vertices_per_wavelength`, at most `skin.refine_limit` levels; thin skin further than
/// thick), embed, and record;
/// `path` names the rig in errors.
pub fn refine_skin(
    input: &RefineInput,
    skin: &SkinSection,
    path: &str,
) -> anyhow::Result<(RefinedSkin, StagePlan)> {
    let t = Instant::now();
    let lambda: Vec<f64> = match input.scale.face_thickness.as_deref() {
        Some(h) => (input.welded.loaded_triangle.iter())
            .map(|&t| input.scale.wavelength_of(h[t]))
            .collect(),
        None => vec![input.scale.lambda; input.welded.mesh.triangles.len()],
    };
    let refined = refine::refine_for_wavelengths(
        &input.welded.mesh,
        input.region,
        &lambda,
        &RefineSettings {
            vertices_per_wavelength: skin
                .vertices_per_wavelength
                .unwrap_or(refine::DEFAULT_VERTICES_PER_WAVELENGTH),
            max_levels: skin.refine_limit.unwrap_or(refine::DEFAULT_MAX_LEVELS),
            ..RefineSettings::default()
        },
    )
    .with_context(|| {
        let size = crate::io::units::moved_extent(input.face);
        format!(
            "{path}: the skin is too coarse for its wrinkles (the face is {:.3} m tall, what its \
             blend shapes move, simulated at {} m per file unit; a human face is {:.2}–{:.2} m: \
             see `--scale`)",
            size,
            input.rig_scale.metres_per_unit,
            crate::io::units::HUMAN_FACE_M.0,
            crate::io::units::HUMAN_FACE_M.1,
        )
    })?;
    let record = refine_record(&refined.report, t);
    let thickness = match input.scale.face_thickness.as_deref() {
        Some(h) => Some(refined_thickness(
            input.welded,
            &refined.subdivision.ancestor,
            h,
        )),
        None => None,
    };
    let points = refine::embed_refined(input.lattice, &input.welded.mesh, &refined.subdivision)?;
    let triplets = refine::embedding_triplets(input.lattice, &points);
    let embedding = Embedding::from_triplets(&triplets, points.len(), input.lattice.node_count());
    let origin = export_origins(
        &refined.subdivision.mesh,
        &refined.subdivision.ancestor,
        input.face,
        input.welded,
    );
    let skin = RefinedSkin {
        ancestor: refined.subdivision.ancestor,
        mesh: refined.subdivision.mesh,
        target_of: refined.subdivision.weights,
        origin,
        embedding,
        thickness,
    };
    Ok((skin, record))
}

/// The `refine` stage's record: what was refined, how, and into how much.
fn refine_record(r: &RefineReport, t: Instant) -> StagePlan {
    let lambda_mm = r.wavelength * 1e3;
    if r.region_triangles == 0 {
        return StagePlan::skipped(
            Stage::Refine,
            "no skin is simulated (see select): the skin stays as it is",
        );
    }
    if r.levels == 0 {
        return StagePlan::skipped(
            Stage::Refine,
            format!(
                "the simulated skin already holds {:.1} vertices per wavelength (λ = {lambda_mm:.2} mm)",
                r.vertices_per_wavelength
            ),
        );
    }
    let whole = r.region_triangles == r.triangles_before;
    let graded = match r.fewer_levels {
        0 => String::new(),
        n => format!(" ({n} of them, of thicker skin, fewer levels for its longer wavelength)"),
    };
    let region = if whole {
        format!("the whole skin{graded}")
    } else {
        format!(
            "the {} simulated of {} triangles{graded}, with a transition band of {} triangles \
             ({} green closures) fading the smoothing to plain midpoints; the skin left out \
             stays coarse",
            r.region_triangles, r.triangles_before, r.band_triangles, r.transition_triangles
        )
    };
    StagePlan::ran(
        Stage::Refine,
        format!(
            "{} level(s) of {} subdivision on {region}: {} → {} triangles, {} → {} vertices; mean \
             edge {:.2} → {:.2} mm ({:.1} vertices per λ = {lambda_mm:.2} mm)",
            r.levels,
            r.smoothing.name(),
            r.triangles_before,
            r.triangles_after,
            r.vertices_before,
            r.vertices_after,
            r.mean_edge_before * 1e3,
            r.mean_edge_after * 1e3,
            r.vertices_per_wavelength,
        ),
        t.elapsed().as_secs_f64() * 1e3,
    )
}

/// Thickness per refined triangle (m): its ancestor's welded triangle's loaded triangle's.
fn refined_thickness(welded: &Welded, ancestor: &[Ancestor], per_loaded: &[f64]) -> Vec<f64> {
    ancestor
        .iter()
        .map(|a| per_loaded[welded.loaded_triangle[a.triangle]])
        .collect()
}

/// Each refined vertex's place in the loaded face for the export: its barycentric
/// coordinates in the loaded triangle of its ancestor (exactly three loaded vertices). Of
/// the refined triangles at the vertex, the one whose loaded corners (those with weight) are
/// most often their welded vertex's first loaded copy is taken (the first such), so a seam
/// the weld joined reads one side's attributes consistently; a vertex at a corner is that
/// loaded vertex alone.
fn export_origins(
    mesh: &TriMesh,
    ancestor: &[Ancestor],
    face: &MeshInstance,
    welded: &Welded,
) -> Vec<VertexOrigin> {
    let mut best: Vec<Option<(usize, VertexOrigin)>> = vec![None; mesh.positions.len()];
    for (tri, a) in mesh.triangles.iter().zip(ancestor) {
        let wt = welded.mesh.triangles[a.triangle];
        let lt = face.triangles[welded.loaded_triangle[a.triangle]];
        for (k, &v) in tri.iter().enumerate() {
            let bary = a.bary[k];
            let score = (0..3)
                .filter(|&i| bary[i] != 0.0 && lt[i] == welded.loaded_of[wt[i]])
                .count();
            if best[v].as_ref().is_none_or(|b| score > b.0) {
                let corner = (0..3).filter(|&i| bary[i] != 0.0).collect::<Vec<_>>();
                let o = match corner.as_slice() {
                    [i] => VertexOrigin::same(lt[*i]),
                    _ => VertexOrigin {
                        vertices: lt,
                        weights: bary,
                    },
                };
                best[v] = Some((score, o));
            }
        }
    }
    best.into_iter()
        .enumerate()
        .map(|(v, b)| b.map_or_else(|| VertexOrigin::same(welded.loaded_of[v]), |b| b.1))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::setup::test_support::{bump_sheet, face_of};
    use crate::pipeline::setup::weld::weld;

    #[test]
    fn refines_a_coarse_sheet_for_a_short_wavelength_and_embeds_every_vertex() {
        let face = face_of(bump_sheet(6));
        let welded = weld(&face.positions, &face.targets, &face.triangles, 1e-9);
        let (lattice, _) = crate::pipeline::setup::lattice::build_lattice(
            &welded.mesh,
            &Default::default(),
            "sheet.glb",
        )
        .unwrap();
        let scale = SkinScale {
            face_thickness: None,
            thickness: [2e-4; 2],
            lambda: 0.01,
            lambda_max: 0.01,
            lids: None,
        };
        let input = RefineInput {
            face: &face,
            welded: &welded,
            lattice: &lattice,
            scale: &scale,
            rig_scale: &Default::default(),
            region: None,
        };
        let (skin, record) = refine_skin(&input, &SkinSection::default(), "sheet.glb").unwrap();
        assert!(record.is_ran(), "{}", record.why);
        assert!(skin.mesh.positions.len() > welded.mesh.positions.len());
        assert_eq!(skin.embedding.point_count(), skin.mesh.positions.len());
        for v in 0..skin.embedding.point_count() {
            let w: f64 = skin.embedding.row(v).iter().map(|r| r.1).sum();
            assert!((w - 1.0).abs() < 1e-9, "vertex {v}: weights sum to {w}");
        }
        // Welded vertices are their own targets; every origin's weights sum to one.
        assert_eq!(skin.target_of[3], vec![(3, 1.0)]);
        for o in &skin.origin {
            assert!((o.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    /// Two triangles joined along a seam (vertices 1, 2 and their copies 3, 5): every new
    /// vertex is barycentric in one loaded triangle; on the seam it reads the side whose
    /// corners are the first copies, and welded vertices are their first copy.
    #[test]
    fn export_origins_are_barycentric_in_the_ancestors_loaded_triangle() {
        use nalgebra::Vector3;
        let p = [
            [0.0, 0.0],
            [1.0, 0.0],
            [0.0, 1.0],
            [1.0, 0.0],
            [1.0, 1.0],
            [0.0, 1.0],
        ]
        .map(|[x, y]| Vector3::new(x, y, 0.0));
        let mesh = TriMesh::new(p.to_vec(), vec![[0, 1, 2], [3, 4, 5]]);
        let face = face_of(mesh);
        let welded = weld(&face.positions, &face.targets, &face.triangles, 1e-9);
        assert_eq!(welded.loaded_of, vec![0, 1, 2, 4]);
        let flat = RefineSettings {
            smoothing: refine::Smoothing::Midpoint,
            ..RefineSettings::default()
        };
        let r = refine::refine_for_wavelength(&welded.mesh, 1.0, &flat).unwrap();
        assert_eq!(r.report.levels, 3);
        let origin = export_origins(&r.subdivision.mesh, &r.subdivision.ancestor, &face, &welded);
        for (v, o) in origin.iter().enumerate() {
            assert!((o.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            assert!(o.weights.iter().all(|&w| w >= 0.0));
            let at: Vector3<f64> = (0..3)
                .map(|j| face.positions[o.vertices[j]] * o.weights[j])
                .sum();
            if v < 4 {
                assert_eq!(*o, VertexOrigin::same(welded.loaded_of[v]));
            } else if at.x + at.y == 1.0 {
                // On the seam: the first triangle's corners.
                assert!(o.vertices == [0, 1, 2], "vertex {v}: {o:?}");
            } else if at.x + at.y > 1.0 {
                assert!(o.vertices == [3, 4, 5], "vertex {v}: {o:?}");
            }
            // Refined by midpoints, the mesh is where the origin says.
            assert!(
                (at - r.subdivision.mesh.positions[v]).norm() < 1e-12,
                "vertex {v}"
            );
        }
    }
}
