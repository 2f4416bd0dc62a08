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

use super::weld::Welded;
use crate::io::load::Rig;
use crate::mesh::grid::PointGrid;
use crate::mesh::TriMesh;
use crate::pipeline::plan::Plan;
use crate::pipeline::record::StagePlan;
use crate::pipeline::step::blend::weld_positions;
use crate::scene::{Materials, Scene};
use nalgebra::{Matrix2, Vector3};
use rayon::prelude::*;
use std::collections::HashMap;
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
/// same vertices, m); 0 where no pose compresses it.
pub fn largest_compression<P: AsRef<[Vector3<f64>]>>(
    rest: &TriMesh,
    poses: impl IntoIterator<Item = P>,
) -> Vec<f64> {
    let mut worst = vec![0.0f64; rest.triangles.len()];
    for pose in poses {
        let pose = pose.as_ref();
        for (t, tri) in rest.triangles.iter().enumerate() {
            let s = smaller_stretch(tri.map(|v| rest.positions[v]), tri.map(|v| pose[v]));
            worst[t] = worst[t].max(1.0 - s);
        }
    }
    worst
}

/// The triangles of `mesh` with a vertex within `margin` (m) of a vertex of a `seed` triangle
/// (straight-line distance over the rest shape): the seeds grown by the margin.
pub fn grow(mesh: &TriMesh, seed: &[bool], margin: f64) -> Vec<bool> {
    let mut seeded = vec![false; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if seed[t] {
            for &v in tri {
                seeded[v] = true;
            }
        }
    }
    let seeds = (0..mesh.positions.len()).filter(|&v| seeded[v]);
    let grid = PointGrid::new(margin, seeds.map(|v| (v, mesh.positions[v])));
    let near = |p: &Vector3<f64>| {
        grid.near(p)
            .any(|s| (mesh.positions[s] - p).norm() <= margin)
    };
    let reached: Vec<bool> = mesh.positions.iter().map(near).collect();
    mesh.triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| seed[t] || tri.iter().any(|&v| reached[v]))
        .collect()
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
}

/// Select the triangles of `rest` compressed beyond `threshold` in some pose, grown by
/// `margin` (m).
pub fn select_compressed<P: AsRef<[Vector3<f64>]>>(
    rest: &TriMesh,
    poses: impl IntoIterator<Item = P>,
    threshold: f64,
    margin: f64,
) -> Selection {
    let compression = largest_compression(rest, poses);
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
    }
}

/// Dihedral turn (rad) across a skin edge beyond which the blend shapes are taken to fold
/// the skin over itself: the two triangles' normals, which agree at rest, point more than
/// 150° apart. The skin has no contact, so such targets are outside the model.
pub const FOLD_ANGLE: f64 = 150.0 * std::f64::consts::PI / 180.0;

/// The first edge of `rest` that `pose` folds over (see [`FOLD_ANGLE`]): the two triangles
/// and the angle (rad) between their normals, or `None`.
pub fn first_fold(rest: &TriMesh, pose: &[Vector3<f64>]) -> Option<(usize, usize, f64)> {
    fold_in(rest, &judged_edges(rest), pose)
}

/// The pairs of triangles (in edge order) sharing an edge whose normals agree at rest: the
/// edges a fold is judged on (a crease at rest, or a non-manifold pair, is not judged).
fn judged_edges(rest: &TriMesh) -> Vec<(usize, usize)> {
    let normals: Vec<Option<Vector3<f64>>> = (0..rest.triangles.len())
        .map(|t| triangle_normal(rest, &rest.positions, t))
        .collect();
    let mut by_edge: HashMap<(usize, usize), usize> = HashMap::new();
    let mut pairs = Vec::new();
    for (t, tri) in rest.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let Some(u) = by_edge.insert((a.min(b), a.max(b)), t) else {
                continue;
            };
            if let (Some(n0), Some(n1)) = (normals[u], normals[t]) {
                if n0.dot(&n1) > 0.0 {
                    pairs.push((u, t));
                }
            }
        }
    }
    pairs
}

/// Unit normal of triangle `t` of `mesh` at positions `p`, `None` when degenerate.
fn triangle_normal(mesh: &TriMesh, p: &[Vector3<f64>], t: usize) -> Option<Vector3<f64>> {
    let [a, b, c] = mesh.triangles[t].map(|v| p[v]);
    (b - a).cross(&(c - a)).try_normalize(1e-300)
}

/// The first of the judged triangle pairs `edges` that `pose` folds over (see
/// [`first_fold`]).
fn fold_in(
    rest: &TriMesh,
    edges: &[(usize, usize)],
    pose: &[Vector3<f64>],
) -> Option<(usize, usize, f64)> {
    let cos_fold = FOLD_ANGLE.cos();
    edges.iter().find_map(|&(u, t)| {
        let (p0, p1) = (
            triangle_normal(rest, pose, u)?,
            triangle_normal(rest, pose, t)?,
        );
        let c = p0.dot(&p1);
        (c < cos_fold).then(|| (u, t, c.clamp(-1.0, 1.0).acos()))
    })
}

/// Refuse blend shapes that fold the welded skin over itself in some pose of the clip (or,
/// for a still rig, some shape at weight 1): the error names the first such frame or shape,
/// the two triangles, the angle and the limit. Poses are judged in parallel.
pub fn check_folds(rig: &Rig, plan: &Plan, welded: &Welded, path: &str) -> anyhow::Result<()> {
    let (weights, what) = pose_weights(plan);
    let count = welded.mesh.positions.len();
    let edges = judged_edges(&welded.mesh);
    let fold = weights.par_iter().enumerate().find_map_first(|(k, w)| {
        let pose = weld_positions(&rig.blend(w), &welded.of_loaded, count);
        fold_in(&welded.mesh, &edges, &pose).map(|f| (k, f))
    });
    if let Some((k, (a, b, angle))) = fold {
        let which = match what {
            PoseKind::Frames => format!("frame {k}"),
            PoseKind::Shapes => {
                format!("shape {k} (\"{}\") at weight 1", rig.face().targets[k].name)
            }
        };
        anyhow::bail!(
            "{path}: the blend shapes fold the skin over itself: in {which}, skin triangles {a} and {b}, which share an edge, turn {:.0}° apart (limit {:.0}°). furrow's skin has no contact, so such targets are outside its model; check the shape weights (values far beyond 1) or the shape itself",
            angle.to_degrees(),
            FOLD_ANGLE.to_degrees()
        );
    }
    Ok(())
}

/// What the poses of [`pose_weights`] are.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum PoseKind {
    /// Every frame of the clip.
    Frames,
    /// Each shape alone at weight 1 (a still rig).
    Shapes,
}

/// The weights of the poses the skin is judged on: every frame at the run's fps, or for a
/// still rig each shape at weight 1.
fn pose_weights(plan: &Plan) -> (Vec<Vec<f64>>, PoseKind) {
    let kind = if plan.animated {
        PoseKind::Frames
    } else {
        PoseKind::Shapes
    };
    (plan.weights.clone(), kind)
}

/// The `select` stage: with `skin.simulate = "compressed"` (the default), the welded triangles
/// some pose of the rig compresses past the threshold, grown by one λ (of the thickest skin);
/// `None` with `"all"`. The poses are every frame of the clip at the run's fps (whatever
/// frames are written), or for a still rig each shape at weight 1.
pub fn select_skin(
    rig: &Rig,
    scene: &Scene,
    plan: &Plan,
    welded: &Welded,
) -> (Option<Selection>, StagePlan) {
    if scene.skin.simulate.as_deref() == Some("all") {
        let why = "skin.simulate = all: the whole skin is simulated";
        return (None, StagePlan::skipped("select", why));
    }
    let t = Instant::now();
    let onset = onset_strain(&plan.materials);
    let threshold = scene.skin.compression_threshold.unwrap_or(0.5 * onset);
    let (weights, _) = pose_weights(plan);
    let count = welded.mesh.positions.len();
    let poses = weights
        .iter()
        .map(|w| weld_positions(&rig.blend(w), &welded.of_loaded, count));
    let margin = plan.skin.lambda_max;
    let s = select_compressed(&welded.mesh, poses, threshold, margin);
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
    let record = StagePlan::ran("select", why, t.elapsed().as_secs_f64() * 1e3);
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
    fn a_fold_is_found_and_a_bend_is_not() {
        let rest = bump_sheet(9);
        // Bending the sheet up by 90° along x = 0 is no fold.
        let bend = |p: &Vector3<f64>| {
            if p.x < 0.0 {
                *p
            } else {
                Vector3::new(0.0, p.y, p.z + p.x)
            }
        };
        let bent: Vec<Vector3<f64>> = rest.positions.iter().map(bend).collect();
        assert!(first_fold(&rest, &bent).is_none());
        // Mirroring the left half onto the right (x ↦ −x for x < 0) folds it over.
        let folded: Vec<Vector3<f64>> = rest
            .positions
            .iter()
            .map(|p| Vector3::new(p.x.abs(), p.y, p.z))
            .collect();
        let (a, b, angle) = first_fold(&rest, &folded).expect("a fold");
        assert!(angle > FOLD_ANGLE && a != b, "{angle}");
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
        let s = select_compressed(&rest, [pose], 0.01, 0.004);
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
