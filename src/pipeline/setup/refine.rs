//! The `refine` stage: the welded skin subdivided until it holds enough vertices per critical
//! wavelength, embedded in the lattice, with the maps the export needs (each refined vertex's
//! blend-shape target as a combination of welded vertices, and its loaded origin).

use super::weld::Welded;
use crate::coupling::refine::{self, RefineSettings};
use crate::io::export::VertexOrigin;
use crate::io::mesh::MeshInstance;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::pipeline::plan::SkinScale;
use crate::pipeline::record::StagePlan;
use crate::scene::SkinSection;
use anyhow::Context;
use std::time::Instant;

/// The refined skin: the exported mesh and how it maps to the welded and loaded faces.
#[derive(Debug, Clone)]
pub struct RefinedSkin {
    /// The refined skin mesh (m); the welded vertices keep their indices and come first.
    pub mesh: TriMesh,
    /// For each refined vertex, (welded vertex, weight) pairs whose blend is its target.
    pub target_of: Vec<Vec<(usize, f64)>>,
    /// For each refined vertex, up to three loaded vertices and weights (for the export).
    pub origin: Vec<VertexOrigin>,
    /// Embedding rows of each refined vertex in the lattice: (node, weight), x = Σ w q_node.
    pub rows: Vec<Vec<(usize, f64)>>,
    /// Skin thickness per refined triangle (m), when the scene varies it.
    pub thickness: Option<Vec<f64>>,
    /// Subdivision levels: refined triangle t lies in welded triangle t / 4^levels.
    pub levels: usize,
    /// For each refined triangle, the welded triangle it lies in and its corners'
    /// barycentric coordinates there (UVs, thickness and other surface data follow these;
    /// `Welded::loaded_triangle` leads on to the loaded triangle).
    pub ancestor: Vec<refine::Ancestor>,
}

/// What the refinement works from: the loaded face, its weld, the lattice and the skin's scale.
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
}

/// The `refine` stage: subdivide for the thinnest skin's wavelength (`skin.vertices_per_wavelength`,
/// at most `skin.refine_limit` levels), embed, and record; `path` names the rig in errors.
pub fn refine_skin(
    input: &RefineInput,
    skin: &SkinSection,
    path: &str,
) -> anyhow::Result<(RefinedSkin, StagePlan)> {
    let t = Instant::now();
    let lambda = input.scale.lambda;
    let refined = refine::refine_for_wavelength(
        &input.welded.mesh,
        lambda,
        &RefineSettings {
            vertices_per_wavelength: skin
                .vertices_per_wavelength
                .unwrap_or(refine::DEFAULT_VERTICES_PER_WAVELENGTH),
            max_levels: skin.refine_limit.unwrap_or(refine::DEFAULT_MAX_LEVELS),
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
    let r = &refined.report;
    let record = if r.levels > 0 {
        StagePlan::ran(
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
        )
    } else {
        StagePlan::skipped(
            "refine",
            format!(
                "the skin already holds {:.1} vertices per wavelength (λ = {:.2} mm)",
                r.vertices_per_wavelength,
                lambda * 1e3
            ),
        )
    };
    let thickness = match input.scale.face_thickness.as_deref() {
        Some(h) => Some(refined_thickness(input.face, input.welded, &refined, h)?),
        None => None,
    };
    let points = refine::embed_refined(input.lattice, &refined)?;
    let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); points.len()];
    for (v, n, w) in refine::embedding_triplets(input.lattice, &points) {
        rows[v].push((n, w));
    }
    let origin = export_origins(&refined.origin, &input.welded.loaded_of);
    let levels = refined.report.levels;
    let skin = RefinedSkin {
        levels,
        ancestor: refined.ancestor,
        mesh: refined.mesh,
        target_of: refined.origin,
        origin,
        rows,
        thickness,
    };
    Ok((skin, record))
}

/// Thickness per refined triangle (m): loaded triangles → welded ones (the weld keeps the
/// loaded order and drops collapsed triangles) → their refined children.
fn refined_thickness(
    face: &MeshInstance,
    welded: &Welded,
    refined: &refine::Refined,
    per_loaded: &[f64],
) -> anyhow::Result<Vec<f64>> {
    let w = &welded.of_loaded;
    let per_welded: Vec<f64> = face
        .triangles
        .iter()
        .zip(per_loaded)
        .filter(|(t, _)| {
            let [a, b, c] = t.map(|v| w[v]);
            a != b && b != c && a != c
        })
        .map(|(_, &x)| x)
        .collect();
    refine::carry_face_values(refined, &per_welded)
}

/// Each refined vertex's origin in the loaded face for the export: its three heaviest welded
/// vertices (ties by index), renormalised, as loaded vertices.
fn export_origins(target_of: &[Vec<(usize, f64)>], loaded_of: &[usize]) -> Vec<VertexOrigin> {
    target_of
        .iter()
        .map(|o| {
            let mut o = o.clone();
            o.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            o.truncate(3);
            let s: f64 = o.iter().map(|p| p.1).sum();
            let mut vo = VertexOrigin::same(loaded_of[o[0].0]);
            for (j, &(w, a)) in o.iter().enumerate() {
                vo.vertices[j] = loaded_of[w];
                vo.weights[j] = a / s;
            }
            vo
        })
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
        let welded = weld(&face.positions, &face.triangles, 1e-9);
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
        };
        let input = RefineInput {
            face: &face,
            welded: &welded,
            lattice: &lattice,
            scale: &scale,
            rig_scale: &Default::default(),
        };
        let (skin, record) = refine_skin(&input, &SkinSection::default(), "sheet.glb").unwrap();
        assert!(record.is_ran(), "{}", record.why);
        assert!(skin.mesh.positions.len() > welded.mesh.positions.len());
        assert_eq!(skin.rows.len(), skin.mesh.positions.len());
        for (v, row) in skin.rows.iter().enumerate() {
            let w: f64 = row.iter().map(|r| r.1).sum();
            assert!((w - 1.0).abs() < 1e-9, "vertex {v}: weights sum to {w}");
        }
        // Welded vertices are their own targets; every origin's weights sum to one.
        assert_eq!(skin.target_of[3], vec![(3, 1.0)]);
        for o in &skin.origin {
            assert!((o.weights.iter().sum::<f64>() - 1.0).abs() < 1e-12);
        }
    }

    #[test]
    fn export_origin_keeps_the_three_heaviest_and_renormalises() {
        let o = export_origins(
            &[vec![(0, 0.1), (1, 0.4), (2, 0.2), (3, 0.3)]],
            &[10, 11, 12, 13],
        );
        assert_eq!(o[0].vertices, [11, 13, 12]);
        let w = o[0].weights;
        assert!((w[0] - 0.4 / 0.9).abs() < 1e-15 && (w[2] - 0.2 / 0.9).abs() < 1e-15);
    }
}
