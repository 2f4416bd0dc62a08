//! The `select` stage: the part of the skin that can wrinkle. Skin wrinkles only where it is
//! compressed past the onset strain of the bilayer, so before anything is simulated each welded
//! triangle's largest compression over the whole clip (or, for a still rig, over every shape
//! at weight 1) is measured as 1 − s_min, with s_min the smaller principal stretch of the
//! blended triangle against its rest shape. Triangles compressed beyond the threshold (default
//! half the onset strain ε_c = ¼ (3 Ē_q / Ē_x)^(2/3), Ē = E / (1 − ν²)), grown by a margin of
//! one critical wavelength, are simulated; the rest follows the blend shapes exactly, as
//! outside a `mask`, riding on the interior (x = B q) with its elasticity kept there; the
//! simulated part keeps the whole skin's constraint clusters (restricted to it), so inside it
//! the constraints do not depend on the selection. `skin.simulate = "all"` turns it off. The measure uses every frame whatever `--frames` says, so chunks, `merge`
//! and reruns share one topology.

use super::outside::{grow, OutOfModel};
use super::weld::Welded;
use crate::io::load::Rig;
use crate::mesh::TriMesh;
use crate::pipeline::plan::Plan;
use crate::pipeline::record::{Stage, StagePlan};
use crate::pipeline::step::blend::weld_positions;
use crate::scene::{Materials, Scene};
use nalgebra::{Matrix2, Vector3};
use std::time::Instant;

/// Onset strain ε_c of wrinkling for a skin on an interior (dimensionless): the compressive
/// strain at which a stiff film on a soft half-space buckles, ¼ (3 Ē_q / Ē_x)^(2/3) with
/// plane-strain moduli Ē = E / (1 − ν²).
pub fn onset_strain(materials: &Materials) -> f64 {
    let plane = |e: f64, nu: f64| e / (1.0 - nu * nu);
    let skin = plane(materials.skin.young, materials.skin.poisson);
    let interior = plane(materials.interior.young, materials.interior.poisson);
    0.25 * (3.0 * interior / skin).powf(2.0 / 3.0)
}

/// The compression (1 − the smaller principal stretch) past which skin counts as compressed
/// when the scene gives no `skin.compression_threshold`: half the onset strain
/// ([`onset_strain`]), so skin is simulated before it can wrinkle.
pub fn default_threshold(materials: &Materials) -> f64 {
    0.5 * onset_strain(materials)
}

/// The smaller principal stretch of triangle `now` against its rest shape `rest` (both in m):
/// √ of the smaller eigenvalue of C = Fᵀ F, F the deformation gradient in the rest plane.
/// 1 for a rigid motion, below 1 under compression; 1 for a degenerate rest triangle.
pub fn smaller_stretch(rest: [Vector3<f64>; 3], now: [Vector3<f64>; 3]) -> f64 {
    let (e1, e2) = (rest[1] - rest[0], rest[2] - rest[0]);
    let l1 = e1.norm();
    if l1 == 0.0 {
        return 1.0;
    }
    let u = e1 / l1;
    let w = e2 - u * e2.dot(&u);
    let h = w.norm();
    if h <= 1e-12 * l1 {
        return 1.0;
    }
    // Rest edges in the plane basis (u, w/h): Dm = [[l1, e2·u], [0, h]].
    let dm = Matrix2::new(l1, e2.dot(&u), 0.0, h);
    let Some(dm_inv) = dm.try_inverse() else {
        return 1.0;
    };
    let (d1, d2) = (now[1] - now[0], now[2] - now[0]);
    // F = Ds Dm⁻¹ (3 × 2); C = Fᵀ F = Dm⁻ᵀ (Dsᵀ Ds) Dm⁻¹.
    let g = Matrix2::new(d1.dot(&d1), d1.dot(&d2), d1.dot(&d2), d2.dot(&d2));
    let c = dm_inv.transpose() * g * dm_inv;
    let (tr, det) = (c[(0, 0)] + c[(1, 1)], c.determinant());
    let disc = (tr * tr - 4.0 * det).max(0.0).sqrt();
    (0.5 * (tr - disc)).max(0.0).sqrt()
}

/// Largest compression 1 − s_min of each triangle of `rest` over `poses` (positions of the
/// same vertices, m), leaving out in each pose the triangles `outside` it (per pose, per
/// triangle; `None`: none); 0 where no pose compresses it. Also, per pose, the triangles it
/// compresses beyond `threshold`.
pub fn largest_compression<P: AsRef<[Vector3<f64>]>>(
    rest: &TriMesh,
    poses: impl IntoIterator<Item = (P, Option<Vec<bool>>)>,
    threshold: f64,
) -> (Vec<f64>, Vec<Vec<usize>>) {
    let mut worst = vec![0.0f64; rest.triangles.len()];
    let mut per_pose = Vec::new();
    for (pose, outside) in poses {
        let pose = pose.as_ref();
        let mut beyond = Vec::new();
        for (t, tri) in rest.triangles.iter().enumerate() {
            if outside.as_ref().is_some_and(|o| o[t]) {
                continue;
            }
            let s = smaller_stretch(tri.map(|v| rest.positions[v]), tri.map(|v| pose[v]));
            worst[t] = worst[t].max(1.0 - s);
            if 1.0 - s > threshold {
                beyond.push(t);
            }
        }
        per_pose.push(beyond);
    }
    (worst, per_pose)
}

/// Which welded triangles the skin simulates, and why.
#[derive(Debug, Clone)]
pub struct Selection {
    /// Per welded triangle: simulated.
    pub simulated: Vec<bool>,
    /// Per welded triangle: the largest compression 1 − s_min over the poses.
    pub compression: Vec<f64>,
    /// The compression beyond which a triangle wrinkles (dimensionless).
    pub threshold: f64,
    /// Fraction of the skin's rest area simulated (0–1).
    pub area_fraction: f64,
    /// Per pose: the triangles it compresses beyond the threshold (in the model), grown by
    /// the margin: where that pose alone can wrinkle (a still rig's shape is solved there
    /// only, and not at all when it is empty).
    pub per_pose: Vec<Vec<bool>>,
}

/// Select the triangles of `rest` compressed beyond `threshold` in some pose (leaving out
/// each pose's triangles outside the model, as [`largest_compression`]), grown by `margin`
/// (m); with `each_pose`, also each pose's own ([`Selection::per_pose`], else empty).
pub fn select_compressed<P: AsRef<[Vector3<f64>]>>(
    rest: &TriMesh,
    poses: impl IntoIterator<Item = (P, Option<Vec<bool>>)>,
    (threshold, margin): (f64, f64),
    each_pose: bool,
) -> Selection {
    let (compression, beyond) = largest_compression(rest, poses, threshold);
    let seed: Vec<bool> = compression.iter().map(|&c| c > threshold).collect();
    let simulated = grow(rest, &seed, margin);
    let area = |t: usize| rest.triangle_area(t);
    let total: f64 = (0..rest.triangles.len()).map(area).sum();
    let kept: f64 = (0..rest.triangles.len())
        .filter(|&t| simulated[t])
        .map(area)
        .sum();
    Selection {
        simulated,
        compression,
        threshold,
        area_fraction: if total > 0.0 { kept / total } else { 0.0 },
        per_pose: beyond
            .iter()
            .filter(|_| each_pose)
            .map(|b| {
                let mut seed = vec![false; rest.triangles.len()];
                b.iter().for_each(|&t| seed[t] = true);
                if b.is_empty() {
                    seed
                } else {
                    grow(rest, &seed, margin)
                }
            })
            .collect(),
    }
}

/// The `select` stage: with `skin.simulate = "compressed"` (the default), the welded triangles
/// some pose of the rig compresses past the threshold, grown by one λ (of the thickest skin);
/// `None` with `"all"`. The poses are every frame of the clip at the run's fps (whatever
/// frames are written), or for a still rig each shape at weight 1; in each, the skin
/// `outside` the model is left out.
pub fn select_skin(
    rig: &Rig,
    scene: &Scene,
    plan: &Plan,
    welded: &Welded,
    outside: &OutOfModel,
) -> (Option<Selection>, StagePlan) {
    if scene.skin.simulate == Some(crate::scene::SkinSelection::All) {
        let why = "skin.simulate = all: the whole skin is simulated";
        return (None, StagePlan::skipped(Stage::Select, why));
    }
    let t = Instant::now();
    let onset = onset_strain(&plan.materials);
    let threshold = scene
        .skin
        .compression_threshold
        .unwrap_or_else(|| default_threshold(&plan.materials));
    let weights = &plan.weights;
    let count = welded.mesh.positions.len();
    let triangles = welded.mesh.triangles.len();
    let poses = weights.iter().enumerate().map(|(k, w)| {
        let region = outside.region(k).map(|r| {
            let mut on = vec![false; triangles];
            r.triangles.iter().for_each(|&t| on[t] = true);
            on
        });
        (
            weld_positions(&rig.blend(w), &welded.of_loaded, count),
            region,
        )
    });
    let margin = plan.skin.lambda_max;
    let s = select_compressed(&welded.mesh, poses, (threshold, margin), !plan.animated);
    let why = format!(
        "{:.1} % of the skin's area simulated: compressed beyond {:.2} % (ε_c = {:.2} %) in some of {} {}, plus a margin of λ = {:.1} mm; the rest follows the blend shapes",
        // max: an empty selection's fraction can be −0.0 in round-off.
        (100.0 * s.area_fraction).max(0.0),
        100.0 * threshold,
        100.0 * onset,
        weights.len(),
        if plan.animated { "frames" } else { "shapes at weight 1" },
        margin * 1e3
    );
    let record = StagePlan::ran(Stage::Select, why, t.elapsed().as_secs_f64() * 1e3);
    (Some(s), record)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::setup::test_support::bump_sheet;

    fn tri() -> [Vector3<f64>; 3] {
        [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.3, 0.8, 0.0),
        ]
    }

    #[test]
    fn principal_stretch_of_known_deformations() {
        let r = tri();
        // A rotation about z and a translation: no stretch.
        let rot = nalgebra::Rotation3::from_axis_angle(&Vector3::z_axis(), 0.7);
        let moved = r.map(|p| rot * p + Vector3::new(1.0, 2.0, 3.0));
        assert!((smaller_stretch(r, moved) - 1.0).abs() < 1e-12);
        // 10 % compression along x, 20 % stretch along y: s_min = 0.9.
        let squashed = r.map(|p| Vector3::new(0.9 * p.x, 1.2 * p.y, 0.0));
        assert!((smaller_stretch(r, squashed) - 0.9).abs() < 1e-12);
        // Folded out of plane it is still measured in its own plane: a rigid fold keeps 1.
        let tilted = r.map(|p| Vector3::new(p.x, 0.0, p.y));
        assert!((smaller_stretch(r, tilted) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn onset_strain_matches_the_bilayer_formula() {
        let mut m = crate::scene::Scene::default().materials().unwrap();
        m.skin.young = 1e6;
        m.skin.poisson = 0.0;
        m.interior.young = 1e4;
        m.interior.poisson = 0.0;
        // ¼ (3 · 10⁻²)^(2/3) = 0.02413…
        assert!((onset_strain(&m) - 0.25 * 0.03f64.powf(2.0 / 3.0)).abs() < 1e-15);
    }

    #[test]
    fn one_compressed_half_is_selected_with_its_margin_and_the_other_left_out() {
        let rest = bump_sheet(11);
        // Compress x by 5 % where x < 0 (the left half), stretch it by 5 % on the right.
        let pose: Vec<Vector3<f64>> = rest
            .positions
            .iter()
            .map(|p| Vector3::new(if p.x < 0.0 { 0.95 * p.x } else { 1.05 * p.x }, p.y, p.z))
            .collect();
        let s = select_compressed(&rest, [(pose, None)], (0.01, 0.004), false);
        for (t, tri) in rest.triangles.iter().enumerate() {
            let cx = tri.iter().map(|&v| rest.positions[v].x).sum::<f64>() / 3.0;
            if cx < 0.0 {
                assert!(s.simulated[t], "compressed triangle {t} left out");
            } else if cx > 0.004 + 0.004 {
                assert!(
                    !s.simulated[t],
                    "stretched triangle {t} at x = {cx} simulated"
                );
            }
        }
        assert!(
            s.area_fraction > 0.5 && s.area_fraction < 0.8,
            "{}",
            s.area_fraction
        );
        assert!(s.compression.iter().cloned().fold(0.0, f64::max) > 0.04);
    }
}
