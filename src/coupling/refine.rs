//! Skin refinement for the wrinkle wavelength: wrinkles of length λ need several shell
//! vertices per λ, so a skin mesh that is too coarse is refined by 1-to-4 midpoint
//! subdivision (no smoothing: the surface stays exactly where it was, so the embedding and
//! the rest shape are unchanged) up to a user limit of levels.
//!
//! The criterion is λ / ā ≥ N, ā the mean edge length, N the vertices per wavelength
//! (default [`DEFAULT_VERTICES_PER_WAVELENGTH`] = 6). Why 6: a sinusoid of wavenumber k
//! sampled at spacing a has the discrete (hinge / second-difference) curvature
//! 2(1 − cos ka)/a² = k² sinc²(ka/2); at N = 6 (ka = π/3) that is 0.91 k², so the bending
//! energy of the wave is 17% low and the wavelength, which scales as the cube root of the
//! bending rigidity, is about 6% short. At N = 4 the wavelength would be 15% short and at
//! N = 2 (Nyquist) the wave cannot be represented at all; N = 8 gives under 2%. Six is the
//! smallest count whose error stays within the validation's 15% bound with a margin, at a
//! quarter of the vertices N = 12 would need; validation scenes use more.
//!
//! Every refined vertex carries its origin: weights over the original vertices (a midpoint
//! is ½ + ½ of its edge's ends; after several levels the weights are barycentric in an
//! original triangle), so exporters can map per-vertex data and [`embed_refined`] can locate
//! the new vertices in the lattice.

use crate::lattice::{Lattice, MaterialPoint};
use crate::mesh::TriMesh;
use anyhow::bail;
use std::collections::HashMap;

/// Default number of skin vertices per wrinkle wavelength (see the module notes).
pub const DEFAULT_VERTICES_PER_WAVELENGTH: f64 = 6.0;

/// Default largest number of subdivision levels (each multiplies the vertex count by ~4).
pub const DEFAULT_MAX_LEVELS: usize = 3;

/// How far a skin may be refined.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineSettings {
    /// Required vertices per wavelength N = λ / mean edge (dimensionless, ≥ 2).
    pub vertices_per_wavelength: f64,
    /// Largest number of 1-to-4 subdivision levels allowed.
    pub max_levels: usize,
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            vertices_per_wavelength: DEFAULT_VERTICES_PER_WAVELENGTH,
            max_levels: DEFAULT_MAX_LEVELS,
        }
    }
}

/// What refinement did (for the user's report).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RefineReport {
    /// Subdivision levels applied (0 when the mesh was fine enough).
    pub levels: usize,
    /// Vertex count before and after.
    pub vertices_before: usize,
    /// Vertex count after refinement.
    pub vertices_after: usize,
    /// Triangle count after refinement.
    pub triangles_after: usize,
    /// Mean edge length before (m).
    pub mean_edge_before: f64,
    /// Mean edge length after (m).
    pub mean_edge_after: f64,
    /// The wrinkle wavelength λ the mesh was refined for (m).
    pub wavelength: f64,
    /// λ / mean edge after refinement (vertices per wavelength).
    pub vertices_per_wavelength: f64,
}

/// Where a refined triangle lies in the unrefined mesh: its ancestor triangle and the
/// barycentric coordinates of its three corners in it (in the ancestor's corner order). Data
/// that lives on the surface rather than moving with the shapes (UVs, thickness, skin
/// weights, which element a vertex embeds in) follows these, not the subdivision weights.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Ancestor {
    /// The unrefined triangle this one lies in.
    pub triangle: usize,
    /// Barycentric coordinates of each corner in `triangle` (each sums to one).
    pub bary: [[f64; 3]; 3],
}

/// A refined skin: the mesh, the origin of each vertex, and the report.
#[derive(Debug, Clone)]
pub struct Refined {
    /// The refined mesh (positions in m); original vertices keep their indices.
    pub mesh: TriMesh,
    /// For each refined vertex, (original vertex, weight) pairs; weights sum to one and the
    /// position is the weighted sum of the original positions. This is the subdivision
    /// operator S: blend-shape deltas are carried onto the refined mesh with it.
    pub origin: Vec<Vec<(usize, f64)>>,
    /// For each refined triangle, its ancestor in the unrefined mesh.
    pub ancestor: Vec<Ancestor>,
    /// What was done.
    pub report: RefineReport,
}

/// Mean edge length (m) over the unique edges of `mesh` (0 for a mesh without triangles).
pub fn mean_edge(mesh: &TriMesh) -> f64 {
    let mut seen = std::collections::HashSet::new();
    let (mut sum, mut count) = (0.0, 0usize);
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            if seen.insert((a.min(b), a.max(b))) {
                sum += (mesh.positions[a] - mesh.positions[b]).norm();
                count += 1;
            }
        }
    }
    if count == 0 {
        0.0
    } else {
        sum / count as f64
    }
}

/// One level of 1-to-4 midpoint subdivision. Returns the new mesh and, for each new vertex
/// (after the old ones, which keep their indices), the two old vertices it is the midpoint of.
/// Winding is preserved.
pub fn subdivide(mesh: &TriMesh) -> (TriMesh, Vec<[usize; 2]>) {
    let n = mesh.positions.len();
    let mut positions = mesh.positions.clone();
    let mut mids: HashMap<(usize, usize), usize> = HashMap::new();
    let mut parents = Vec::new();
    let mut mid = |a: usize, b: usize, positions: &mut Vec<nalgebra::Vector3<f64>>| {
        let key = (a.min(b), a.max(b));
        *mids.entry(key).or_insert_with(|| {
            positions.push(0.5 * (mesh.positions[a] + mesh.positions[b]));
            parents.push([key.0, key.1]);
            n + parents.len() - 1
        })
    };
    let mut triangles = Vec::with_capacity(4 * mesh.triangles.len());
    for &[a, b, c] in &mesh.triangles {
        let ab = mid(a, b, &mut positions);
        let bc = mid(b, c, &mut positions);
        let ca = mid(c, a, &mut positions);
        triangles.push([a, ab, ca]);
        triangles.push([ab, b, bc]);
        triangles.push([ca, bc, c]);
        triangles.push([ab, bc, ca]);
    }
    (TriMesh::new(positions, triangles), parents)
}

/// Refine `mesh` until it holds `settings.vertices_per_wavelength` vertices per wavelength
/// `lambda` (m), by midpoint subdivision (surface unchanged). Refuses, saying what would be
/// needed, when more than `settings.max_levels` levels would be required.
pub fn refine_for_wavelength(
    mesh: &TriMesh,
    lambda: f64,
    settings: &RefineSettings,
) -> anyhow::Result<Refined> {
    if !(lambda.is_finite() && lambda > 0.0) {
        bail!("wrinkle wavelength must be a positive length in metres, got {lambda}");
    }
    let npl = settings.vertices_per_wavelength;
    if !(npl.is_finite() && npl >= 2.0) {
        bail!(
            "vertices_per_wavelength must be at least 2 (Nyquist), got {npl}; the default is \
             {DEFAULT_VERTICES_PER_WAVELENGTH}"
        );
    }
    if mesh.triangles.is_empty() {
        bail!("the skin mesh has no triangles to refine");
    }
    let edge0 = mean_edge(mesh);
    // Each level halves every edge: levels = ⌈log₂(N ā / λ)⌉.
    let need = (npl * edge0 / lambda).log2().ceil().max(0.0) as usize;
    if need > settings.max_levels {
        bail!(
            "the skin mesh is too coarse for wrinkles of wavelength λ = {:.3} mm: its mean edge \
             is {:.3} mm ({:.2} vertices per λ, {npl} needed), which takes {need} levels of \
             1-to-4 subdivision (about {} vertices) but max_levels = {}; raise the limit, \
             give a finer skin mesh, or use a thicker or stiffer skin (larger λ)",
            lambda * 1e3,
            edge0 * 1e3,
            lambda / edge0,
            mesh.positions.len() * 4usize.pow(need as u32),
            settings.max_levels
        );
    }
    let mut cur = mesh.clone();
    let mut origin: Vec<Vec<(usize, f64)>> =
        (0..mesh.positions.len()).map(|v| vec![(v, 1.0)]).collect();
    for _ in 0..need {
        let (next, parents) = subdivide(&cur);
        for [a, b] in parents {
            let mut w: Vec<(usize, f64)> = origin[a]
                .iter()
                .chain(&origin[b])
                .map(|&(v, x)| (v, 0.5 * x))
                .collect();
            w.sort_by_key(|p| p.0);
            let mut merged: Vec<(usize, f64)> = Vec::with_capacity(w.len());
            for (v, x) in w {
                match merged.last_mut() {
                    Some(last) if last.0 == v => last.1 += x,
                    _ => merged.push((v, x)),
                }
            }
            origin.push(merged);
        }
        cur = next;
    }
    let ancestor = uniform_ancestors(mesh, &cur, &origin, need);
    let edge1 = mean_edge(&cur);
    let report = RefineReport {
        levels: need,
        vertices_before: mesh.positions.len(),
        vertices_after: cur.positions.len(),
        triangles_after: cur.triangles.len(),
        mean_edge_before: edge0,
        mean_edge_after: edge1,
        wavelength: lambda,
        vertices_per_wavelength: lambda / edge1,
    };
    Ok(Refined {
        mesh: cur,
        origin,
        ancestor,
        report,
    })
}

/// Ancestors of `levels` of uniform 1-to-4 subdivision of `coarse` into `fine`: triangle f
/// lies in coarse triangle f / 4^levels, and a corner's barycentric coordinates are its
/// origin weights on that triangle's corners (a midpoint's origin lies on its ancestor).
fn uniform_ancestors(
    coarse: &TriMesh,
    fine: &TriMesh,
    origin: &[Vec<(usize, f64)>],
    levels: usize,
) -> Vec<Ancestor> {
    let per = 4usize.pow(levels as u32);
    fine.triangles
        .iter()
        .enumerate()
        .map(|(f, tri)| {
            let triangle = f / per;
            let corners = coarse.triangles[triangle];
            let bary = tri.map(|v| {
                corners.map(|c| {
                    origin[v]
                        .iter()
                        .find(|&&(o, _)| o == c)
                        .map_or(0.0, |&(_, w)| w)
                })
            });
            Ancestor { triangle, bary }
        })
        .collect()
}

/// Per-triangle values (e.g. skin thickness, m) carried from the unrefined mesh to the
/// refined one: each level of [`subdivide`] replaces triangle t by triangles 4t..4t+3, so a
/// refined triangle f inherits the value of original triangle f / 4^levels. Fails when
/// `values` does not hold one value per original triangle.
pub fn carry_face_values(refined: &Refined, values: &[f64]) -> anyhow::Result<Vec<f64>> {
    let per = 4usize.pow(refined.report.levels as u32);
    if values.len() * per != refined.mesh.triangles.len() {
        bail!(
            "{} per-triangle values for a mesh of {} triangles refined {} level(s) ({} triangles)",
            values.len(),
            refined.mesh.triangles.len() / per,
            refined.report.levels,
            refined.mesh.triangles.len()
        );
    }
    Ok((0..refined.mesh.triangles.len())
        .map(|f| values[f / per])
        .collect())
}

/// Material points of the refined vertices in `lattice`, whose `vertex_points` embed the
/// original mesh: each new vertex goes into the element of one of its original vertices
/// (the one whose cell contains it, else the nearest), so superimposed elements (upper and
/// lower lip) keep their skin.
pub fn embed_refined(lattice: &Lattice, refined: &Refined) -> anyhow::Result<Vec<MaterialPoint>> {
    let n0 = lattice.vertex_points.len();
    let mut out = Vec::with_capacity(refined.mesh.positions.len());
    for (v, o) in refined.origin.iter().enumerate() {
        let p = refined.mesh.positions[v];
        let mut best: Option<(f64, MaterialPoint)> = None;
        for &(ov, _) in o {
            if ov >= n0 {
                bail!(
                    "the lattice embeds {n0} vertices but the refined mesh refers to original \
                     vertex {ov}; build the lattice over the unrefined mesh"
                );
            }
            let mp = lattice.locate_in_element(lattice.vertex_points[ov].element, &p);
            // Distance (in cells) outside [0, 1]³; 0 inside.
            let out_by = mp
                .xi
                .iter()
                .map(|&x| (-x).max(x - 1.0).max(0.0))
                .fold(0.0, f64::max);
            if best.as_ref().is_none_or(|b| out_by < b.0) {
                best = Some((out_by, mp));
            }
        }
        out.push(best.expect("origin is never empty").1);
    }
    Ok(out)
}

/// Embedding triplets (vertex, node, weight) of B for material points.
pub fn embedding_triplets(lattice: &Lattice, points: &[MaterialPoint]) -> Vec<(usize, usize, f64)> {
    let mut t = Vec::new();
    for (v, mp) in points.iter().enumerate() {
        for (node, w) in lattice.weights(mp) {
            if w != 0.0 {
                t.push((v, node, w));
            }
        }
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::LatticeSettings;
    use crate::mesh::topology::Topology;
    use crate::shell::sheet::equilateral_sheet;

    /// Two levels: each refined triangle's value is its original ancestor's, checked
    /// geometrically (the refined centroid lies inside the ancestor triangle); a list of the
    /// wrong length is refused.
    #[test]
    fn face_values_follow_their_ancestor_triangle() {
        let m = equilateral_sheet(4, 3, 1e-3).mesh;
        let r = refine_for_wavelength(&m, 1.6e-3, &RefineSettings::default()).unwrap();
        assert_eq!(r.report.levels, 2);
        let vals: Vec<f64> = (0..m.triangles.len()).map(|t| t as f64).collect();
        let carried = carry_face_values(&r, &vals).unwrap();
        for (f, tri) in r.mesh.triangles.iter().enumerate() {
            let c = tri
                .iter()
                .map(|&v| r.mesh.positions[v])
                .sum::<nalgebra::Vector3<f64>>()
                / 3.0;
            let [a, b, d] = m.triangles[carried[f] as usize].map(|v| m.positions[v]);
            // Barycentric coordinates of c in the ancestor (all > 0 inside).
            let area =
                |p: nalgebra::Vector3<f64>,
                 q: nalgebra::Vector3<f64>,
                 s: nalgebra::Vector3<f64>| { (q - p).cross(&(s - p)).z };
            let tot = area(a, b, d);
            let l = [
                area(c, b, d) / tot,
                area(a, c, d) / tot,
                area(a, b, c) / tot,
            ];
            assert!(
                l.iter().all(|&x| x > 0.0),
                "refined {f} outside ancestor: {l:?}"
            );
        }
        assert!(carry_face_values(&r, &vals[1..]).is_err());
    }

    /// Every refined vertex sits at the weighted sum of its origins, weights sum to one, and
    /// every refined triangle's corners sit at their barycentric coordinates in the ancestor.
    fn check_origin(mesh0: &TriMesh, r: &Refined) {
        assert_eq!(r.ancestor.len(), r.mesh.triangles.len());
        for (tri, a) in r.mesh.triangles.iter().zip(&r.ancestor) {
            let corners = mesh0.triangles[a.triangle].map(|v| mesh0.positions[v]);
            for (k, &v) in tri.iter().enumerate() {
                assert!((a.bary[k].iter().sum::<f64>() - 1.0).abs() < 1e-12);
                let p = (0..3).fold(nalgebra::Vector3::zeros(), |acc, j| {
                    acc + a.bary[k][j] * corners[j]
                });
                assert!((p - r.mesh.positions[v]).norm() < 1e-12);
            }
        }
        assert_eq!(r.origin.len(), r.mesh.positions.len());
        for (v, o) in r.origin.iter().enumerate() {
            let s: f64 = o.iter().map(|p| p.1).sum();
            assert!((s - 1.0).abs() < 1e-12);
            let p = o.iter().fold(nalgebra::Vector3::zeros(), |acc, &(u, w)| {
                acc + w * mesh0.positions[u]
            });
            assert!((p - r.mesh.positions[v]).norm() < 1e-12);
        }
    }

    /// A sheet of edge 1 mm: λ = 10 mm needs nothing; λ = 3 mm needs one level (6 × 1/3 = 2
    /// → log₂ 2 = 1), which halves every edge, quadruples the triangles, adds one vertex per
    /// edge, (about) halves the mean edge, keeps the area and the winding; λ = 0.1 mm would need 6 levels and is refused
    /// with a message that names λ, the edge, and max_levels.
    #[test]
    fn sheet_refinement_levels_counts_and_refusal() {
        let sheet = equilateral_sheet(10, 8, 1e-3);
        let m = &sheet.mesh;
        let s = RefineSettings::default();
        let r0 = refine_for_wavelength(m, 10e-3, &s).unwrap();
        assert_eq!(r0.report.levels, 0);
        assert_eq!(r0.mesh, *m);
        let r1 = refine_for_wavelength(m, 3e-3, &s).unwrap();
        let edges = Topology::new(m).unwrap().edges.len();
        assert_eq!(r1.report.levels, 1);
        assert_eq!(r1.mesh.positions.len(), m.positions.len() + edges);
        assert_eq!(r1.mesh.triangles.len(), 4 * m.triangles.len());
        // Every child edge is half a parent edge (the inner triangle's edges are halves of the
        // opposite sides), so the mean halves up to the mix of edge lengths (2 %).
        let ratio = r1.report.mean_edge_after / r1.report.mean_edge_before;
        assert!((ratio - 0.5).abs() < 0.01, "{ratio}");
        assert!(r1.report.vertices_per_wavelength >= 6.0, "{:?}", r1.report);
        assert!((r1.mesh.area() - m.area()).abs() < 1e-15);
        for t in 0..r1.mesh.triangles.len() {
            let [a, b, c] = r1.mesh.triangles[t];
            let p = &r1.mesh.positions;
            assert!((p[b] - p[a]).cross(&(p[c] - p[a])).z > 0.0);
        }
        Topology::new(&r1.mesh).unwrap();
        check_origin(m, &r1);
        let r2 = refine_for_wavelength(
            m,
            1.2e-3,
            &RefineSettings {
                vertices_per_wavelength: 6.0,
                max_levels: 3,
            },
        )
        .unwrap();
        assert_eq!(r2.report.levels, 3);
        check_origin(m, &r2);
        let err = refine_for_wavelength(m, 0.1e-3, &s)
            .unwrap_err()
            .to_string();
        assert!(
            err.contains("λ = 0.100 mm")
                && err.contains("max_levels = 3")
                && err.contains("6 levels"),
            "{err}"
        );
        assert!(refine_for_wavelength(m, -1.0, &s).is_err());
        let bad = RefineSettings {
            vertices_per_wavelength: 1.0,
            max_levels: 3,
        };
        assert!(refine_for_wavelength(m, 3e-3, &bad)
            .unwrap_err()
            .to_string()
            .contains("vertices_per_wavelength"));
    }

    /// The face rig's mesh refined for the paper's λ = 4.04 mm: the report is consistent,
    /// origins reproduce positions, the area is unchanged, and the refined vertices embedded
    /// in the face's lattice (through their origins' elements) sit where they are at rest.
    #[test]
    fn face_rig_refinement_and_embedding() {
        let rig = crate::rig::face::generate();
        let m = &rig.mesh;
        let edge = mean_edge(m);
        let r = refine_for_wavelength(m, 4.04e-3, &RefineSettings::default()).unwrap();
        println!("face: {:?}", r.report);
        let want = (6.0 * edge / 4.04e-3).log2().ceil().max(0.0) as usize;
        assert_eq!(r.report.levels, want);
        assert!(r.report.levels >= 1, "face edge {edge}");
        assert!(r.report.vertices_per_wavelength >= 6.0);
        assert!((r.mesh.area() - m.area()).abs() < 1e-12 * m.area().max(1.0));
        check_origin(m, &r);
        let lat = Lattice::build(m, &LatticeSettings::default()).unwrap();
        let pts = embed_refined(&lat, &r).unwrap();
        let q = lat.rest_flat();
        let mut worst: f64 = 0.0;
        for (v, mp) in pts.iter().enumerate() {
            worst = worst.max((lat.position(&q, mp) - r.mesh.positions[v]).norm());
        }
        println!("refined embedding: max |B q_rest − x| = {worst:.2e} m");
        assert!(worst < 1e-9, "{worst}");
        let t = embedding_triplets(&lat, &pts);
        assert!(t
            .iter()
            .all(|&(v, n, w)| v < pts.len() && n < lat.node_count() && w.is_finite()));
    }
}
