//! Skin refinement for the wrinkle wavelength: wrinkles of length λ need several shell
//! vertices per λ, so a skin mesh that is too coarse is refined where the skin is simulated
//! (the `select` stage's triangles, or all of it) by 1-to-4 subdivision up to a user limit of
//! levels, with a conforming red-green transition to the coarse rest
//! ([`crate::mesh::redgreen`]). New vertices are placed by the interpolating modified
//! butterfly rule ([`crate::mesh::butterfly`]): coarse vertices stay where they are and the
//! refined surface is smooth rather than faceted (the skin's rest angles would keep facets as
//! creases), faded to plain midpoints across the transition band, so the coarse skin beyond it
//! keeps its exact shape.
//!
//! The criterion is λ / ā ≥ N, ā the mean edge length of the triangles to refine, N the
//! vertices per wavelength (default [`DEFAULT_VERTICES_PER_WAVELENGTH`] = 6). Why 6: a
//! sinusoid of wavenumber k sampled at spacing a has the discrete (hinge / second-difference)
//! curvature 2(1 − cos ka)/a² = k² sinc²(ka/2); at N = 6 (ka = π/3) that is 0.91 k², so the
//! bending energy of the wave is 17% low and the wavelength, which scales as the cube root of
//! the bending rigidity, is about 6% short. At N = 4 the wavelength would be 15% short and at
//! N = 2 (Nyquist) the wave cannot be represented at all; N = 8 gives under 2%. Six is the
//! smallest count whose error stays within the validation's 15% bound with a margin, at a
//! quarter of the vertices N = 12 would need; validation scenes use more.
//!
//! Every refined vertex carries its row of the subdivision operator S (weights over the
//! unrefined vertices): blend shapes are carried onto the refined mesh with it. Every refined
//! triangle carries its [`Ancestor`] (the unrefined triangle and its corners' barycentric
//! coordinates there): surface data and the lattice element a vertex embeds in follow that.

use crate::lattice::{Lattice, MaterialPoint};
use crate::mesh::redgreen::{self, RedGreen};
pub use crate::mesh::redgreen::{Ancestor, Smoothing};
use crate::mesh::TriMesh;
use anyhow::bail;

/// Default number of skin vertices per wrinkle wavelength (see the module notes).
pub const DEFAULT_VERTICES_PER_WAVELENGTH: f64 = 6.0;

/// Default largest number of subdivision levels (each multiplies the vertex count by ~4).
pub const DEFAULT_MAX_LEVELS: usize = 3;

/// How far, and how, a skin may be refined.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RefineSettings {
    /// Required vertices per wavelength N = λ / mean edge (dimensionless, ≥ 2).
    pub vertices_per_wavelength: f64,
    /// Largest number of 1-to-4 subdivision levels allowed.
    pub max_levels: usize,
    /// How new vertices are placed (default: the modified butterfly rule).
    pub smoothing: Smoothing,
}

impl Default for RefineSettings {
    fn default() -> Self {
        Self {
            vertices_per_wavelength: DEFAULT_VERTICES_PER_WAVELENGTH,
            max_levels: DEFAULT_MAX_LEVELS,
            smoothing: Smoothing::Butterfly,
        }
    }
}

/// What refinement did (for the user's report).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct RefineReport {
    /// Most subdivision levels applied to a triangle of the region (0 when it was fine
    /// enough).
    pub levels: usize,
    /// Triangles of the region refined fewer than `levels` times: thicker skin, whose longer
    /// wavelength needs fewer (0 when the skin is uniform).
    pub fewer_levels: usize,
    /// Vertex count before.
    pub vertices_before: usize,
    /// Vertex count after refinement.
    pub vertices_after: usize,
    /// Triangle count before.
    pub triangles_before: usize,
    /// Triangle count after refinement.
    pub triangles_after: usize,
    /// Unrefined triangles of the region, each refined `levels` times.
    pub region_triangles: usize,
    /// Refined triangles of the transition band outside the region: red at fewer levels
    /// and the green closures.
    pub band_triangles: usize,
    /// Green (1-to-2 and 1-to-3 closure) triangles among them.
    pub transition_triangles: usize,
    /// Mean edge length of the region before (m).
    pub mean_edge_before: f64,
    /// Mean edge length of the region after (m).
    pub mean_edge_after: f64,
    /// The shortest wrinkle wavelength λ the mesh was refined for (m).
    pub wavelength: f64,
    /// λ / mean edge after refinement, the least over the region's triangles refined alike
    /// (vertices per wavelength).
    pub vertices_per_wavelength: f64,
    /// How new vertices were placed.
    pub smoothing: Smoothing,
}

/// A refined skin: the subdivision (the mesh, with original vertices keeping their indices
/// and positions; the operator S, whose rows carry the rest shape and the blend-shape deltas
/// onto it; the ancestors; the green triangles) and the report.
#[derive(Debug, Clone)]
pub struct Refined {
    /// The subdivision.
    pub subdivision: RedGreen,
    /// What was done.
    pub report: RefineReport,
}

/// Mean edge length (m) over the unique edges of `mesh` (0 for a mesh without triangles).
pub fn mean_edge(mesh: &TriMesh) -> f64 {
    mean_edge_of(mesh, |_| true)
}

/// Mean edge length (m) over the unique edges of the triangles `t` of `mesh` with `keep(t)`
/// (0 when there are none).
pub fn mean_edge_of(mesh: &TriMesh, keep: impl Fn(usize) -> bool) -> f64 {
    let mut seen = std::collections::HashSet::new();
    let (mut sum, mut count) = (0.0, 0usize);
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if !keep(t) {
            continue;
        }
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
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

/// Refine the whole of `mesh` until it holds `settings.vertices_per_wavelength` vertices per
/// wavelength `lambda` (m) ([`refine_region`] with every triangle).
pub fn refine_for_wavelength(
    mesh: &TriMesh,
    lambda: f64,
    settings: &RefineSettings,
) -> anyhow::Result<Refined> {
    refine_region(mesh, None, lambda, settings)
}

/// Check the wavelength and the settings.
fn check_inputs(mesh: &TriMesh, lambda: f64, settings: &RefineSettings) -> anyhow::Result<()> {
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
    Ok(())
}

/// Refine the `region` triangles of `mesh` (all with `None`) until they hold
/// `settings.vertices_per_wavelength` vertices per wavelength `lambda` (m), with a conforming
/// transition to the rest (see the module notes). Refuses, saying what would be needed, when
/// more than `settings.max_levels` levels would be required.
pub fn refine_region(
    mesh: &TriMesh,
    region: Option<&[bool]>,
    lambda: f64,
    settings: &RefineSettings,
) -> anyhow::Result<Refined> {
    refine_for_wavelengths(mesh, region, &vec![lambda; mesh.triangles.len()], settings)
}

/// [`refine_region`] with a wavelength per triangle (m; a thinner skin's is shorter): triangle
/// t of the region is refined ⌈log₂(N ā / λ_t)⌉ levels, ā the region's mean edge, so a thin
/// patch is refined further than the thick skin around it (graded between, see
/// [`crate::mesh::redgreen::refine_by_triangle`]) instead of all of the skin for the thinnest.
pub fn refine_for_wavelengths(
    mesh: &TriMesh,
    region: Option<&[bool]>,
    lambda: &[f64],
    settings: &RefineSettings,
) -> anyhow::Result<Refined> {
    let shortest = lambda.iter().copied().fold(f64::INFINITY, f64::min);
    check_inputs(mesh, shortest, settings)?;
    let all = vec![true; mesh.triangles.len()];
    let region = region.unwrap_or(&all);
    if region.len() != mesh.triangles.len() || lambda.len() != mesh.triangles.len() {
        bail!(
            "{} region flags and {} wavelengths for a skin of {} triangles",
            region.len(),
            lambda.len(),
            mesh.triangles.len()
        );
    }
    let npl = settings.vertices_per_wavelength;
    let edge0 = mean_edge_of(mesh, |t| region[t]);
    // Each level halves every edge: levels = ⌈log₂(N ā / λ)⌉.
    let levels_for = |l: f64| {
        if edge0 > 0.0 {
            (npl * edge0 / l).log2().ceil().max(0.0) as usize
        } else {
            0
        }
    };
    let target: Vec<usize> = (0..region.len())
        .map(|t| if region[t] { levels_for(lambda[t]) } else { 0 })
        .collect();
    let need = target.iter().copied().max().unwrap_or(0);
    if need > settings.max_levels {
        let region_vertices = mesh.positions.len() as f64 * region_share(region);
        bail!(
            "the skin mesh is too coarse for wrinkles of wavelength λ = {:.3} mm: its mean edge \
             is {:.3} mm ({:.2} vertices per λ, {npl} needed), which takes {need} levels of \
             1-to-4 subdivision (about {:.0} vertices) but max_levels = {}; raise the limit, \
             give a finer skin mesh, or use a thicker or stiffer skin (larger λ)",
            shortest * 1e3,
            edge0 * 1e3,
            shortest / edge0,
            region_vertices * 4f64.powi(need as i32),
            settings.max_levels
        );
    }
    let rg = redgreen::refine_by_triangle(mesh, &target, settings.smoothing);
    let report = report_of(mesh, (region, edge0), lambda, &target, &rg, settings);
    Ok(Refined {
        subdivision: rg,
        report,
    })
}

/// What [`refine_for_wavelengths`] did: counts, and the mean edges and vertices per
/// wavelength of the region (the least over its triangles' levels); `edge0` is the region's
/// mean edge before (m).
fn report_of(
    mesh: &TriMesh,
    (region, edge0): (&[bool], f64),
    lambda: &[f64],
    target: &[usize],
    rg: &RedGreen,
    settings: &RefineSettings,
) -> RefineReport {
    let need = target.iter().copied().max().unwrap_or(0);
    let in_region = |f: usize| region[rg.ancestor[f].triangle];
    let edge1 = mean_edge_of(&rg.mesh, in_region);
    // Per target level: the shortest wavelength asked of it over its refined edge.
    let per_level = (0..=need).filter_map(|l| {
        let of = |f: usize| in_region(f) && target[rg.ancestor[f].triangle] == l;
        let edge = mean_edge_of(&rg.mesh, of);
        let shortest = (0..region.len())
            .filter(|&t| region[t] && target[t] == l)
            .map(|t| lambda[t])
            .fold(f64::INFINITY, f64::min);
        (edge > 0.0 && shortest.is_finite()).then(|| shortest / edge)
    });
    let in_band = |f: usize| !in_region(f) && rg.level[rg.ancestor[f].triangle] > 0;
    let region_triangles = region.iter().filter(|&&r| r).count();
    let shortest = (0..region.len())
        .filter(|&t| region[t] || region_triangles == 0)
        .map(|t| lambda[t])
        .fold(f64::INFINITY, f64::min);
    RefineReport {
        levels: need,
        fewer_levels: (0..region.len())
            .filter(|&t| region[t] && target[t] < need)
            .count(),
        vertices_before: mesh.positions.len(),
        vertices_after: rg.mesh.positions.len(),
        triangles_before: mesh.triangles.len(),
        triangles_after: rg.mesh.triangles.len(),
        region_triangles,
        band_triangles: (0..rg.mesh.triangles.len())
            .filter(|&f| in_band(f) || rg.green[f])
            .count(),
        transition_triangles: rg.green.iter().filter(|&&g| g).count(),
        mean_edge_before: edge0,
        mean_edge_after: edge1,
        wavelength: shortest,
        vertices_per_wavelength: Some(per_level.fold(f64::INFINITY, f64::min))
            .filter(|v| v.is_finite())
            .unwrap_or(0.0),
        smoothing: settings.smoothing,
    }
}

/// Share of the triangles flagged in `region` (0–1).
fn region_share(region: &[bool]) -> f64 {
    region.iter().filter(|&&r| r).count() as f64 / region.len().max(1) as f64
}

/// Material points of the vertices of the `subdivision` of `coarse` in `lattice`, whose `vertex_points` embed the
/// unrefined mesh `coarse`, at their rest (smoothed) positions. An unrefined vertex stays in its own
/// element; a new vertex goes into the element of one of its ancestor triangle's corners
/// (nearest corner first, the one whose cell contains it, else the least outside), so
/// superimposed elements (upper and lower lip in one cell) keep their skin.
pub fn embed_refined(
    lattice: &Lattice,
    coarse: &TriMesh,
    subdivision: &RedGreen,
) -> anyhow::Result<Vec<MaterialPoint>> {
    let n0 = lattice.vertex_points.len();
    if n0 != coarse.positions.len() {
        bail!(
            "the lattice embeds {n0} vertices but the unrefined mesh has {}; build the lattice \
             over the unrefined mesh",
            coarse.positions.len()
        );
    }
    let n = subdivision.mesh.positions.len();
    // Each vertex's first triangle and its corner there.
    let mut first: Vec<Option<(usize, usize)>> = vec![None; n];
    for (f, tri) in subdivision.mesh.triangles.iter().enumerate() {
        for (k, &v) in tri.iter().enumerate() {
            first[v].get_or_insert((f, k));
        }
    }
    let mut out = Vec::with_capacity(n);
    for (v, at) in first.iter().enumerate() {
        let p = subdivision.mesh.positions[v];
        if v < n0 {
            out.push(lattice.locate_in_element(lattice.vertex_points[v].element, &p));
            continue;
        }
        let Some((f, k)) = *at else {
            bail!("refined vertex {v} is on no triangle");
        };
        let anc = &subdivision.ancestor[f];
        let corners = coarse.triangles[anc.triangle];
        let mut order = [0, 1, 2];
        order.sort_by(|&i, &j| anc.bary[k][j].total_cmp(&anc.bary[k][i]));
        let mut best: Option<(f64, MaterialPoint)> = None;
        for i in order {
            let mp = lattice.locate_in_element(lattice.vertex_points[corners[i]].element, &p);
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
        out.push(best.expect("three corners").1);
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
    use nalgebra::Vector3;

    fn midpoint() -> RefineSettings {
        RefineSettings {
            smoothing: Smoothing::Midpoint,
            ..RefineSettings::default()
        }
    }

    /// S reproduces every refined position from the unrefined ones with weights summing to
    /// one, and leaves the unrefined vertices exactly where they were; the refinement `flat`
    /// by midpoints has the same topology, and every refined triangle's corners sit at their
    /// barycentric coordinates in the ancestor where midpoint subdivision puts them.
    fn check(mesh0: &TriMesh, r: &Refined, flat: &Refined) {
        assert_eq!(
            r.subdivision.mesh.triangles,
            flat.subdivision.mesh.triangles
        );
        assert_eq!(r.subdivision.ancestor, flat.subdivision.ancestor);
        assert_eq!(
            r.subdivision.ancestor.len(),
            r.subdivision.mesh.triangles.len()
        );
        for (tri, a) in r
            .subdivision
            .mesh
            .triangles
            .iter()
            .zip(&r.subdivision.ancestor)
        {
            let corners = mesh0.triangles[a.triangle].map(|v| mesh0.positions[v]);
            for (k, &v) in tri.iter().enumerate() {
                assert!((a.bary[k].iter().sum::<f64>() - 1.0).abs() < 1e-12);
                let p = (0..3).fold(Vector3::zeros(), |acc, j| acc + a.bary[k][j] * corners[j]);
                assert!((p - flat.subdivision.mesh.positions[v]).norm() < 1e-12);
            }
        }
        assert_eq!(
            r.subdivision.weights.len(),
            r.subdivision.mesh.positions.len()
        );
        for (v, o) in r.subdivision.weights.iter().enumerate() {
            let s: f64 = o.iter().map(|p| p.1).sum();
            assert!((s - 1.0).abs() < 1e-12);
            let p = redgreen::apply(o, &mesh0.positions);
            assert_eq!(p, r.subdivision.mesh.positions[v]);
            if v < mesh0.positions.len() {
                assert_eq!(o, &vec![(v, 1.0)]);
                assert_eq!(r.subdivision.mesh.positions[v], mesh0.positions[v]);
            }
        }
    }

    /// A sheet of edge 1 mm: λ = 10 mm needs nothing; λ = 3 mm needs one level (6 × 1/3 = 2
    /// → log₂ 2 = 1), which halves every edge, quadruples the triangles, adds one vertex per
    /// edge, (about) halves the mean edge, keeps the sheet flat, its area and the winding
    /// (butterfly reproduces a regular flat grid); λ = 0.1 mm would need 6 levels and is
    /// refused with a message that names λ, the edge, and max_levels.
    #[test]
    fn sheet_refinement_levels_counts_and_refusal() {
        let sheet = equilateral_sheet(10, 8, 1e-3);
        let m = &sheet.mesh;
        let s = RefineSettings::default();
        let r0 = refine_for_wavelength(m, 10e-3, &s).unwrap();
        assert_eq!(r0.report.levels, 0);
        assert_eq!(r0.subdivision.mesh, *m);
        let r1 = refine_for_wavelength(m, 3e-3, &s).unwrap();
        let edges = Topology::new(m).unwrap().edges.len();
        assert_eq!(r1.report.levels, 1);
        assert_eq!(r1.report.transition_triangles, 0);
        assert_eq!(
            r1.subdivision.mesh.positions.len(),
            m.positions.len() + edges
        );
        assert_eq!(r1.subdivision.mesh.triangles.len(), 4 * m.triangles.len());
        // Every child edge is half a parent edge (the inner triangle's edges are halves of the
        // opposite sides), so the mean halves up to the mix of edge lengths (2 %).
        let ratio = r1.report.mean_edge_after / r1.report.mean_edge_before;
        assert!((ratio - 0.5).abs() < 0.01, "{ratio}");
        assert!(r1.report.vertices_per_wavelength >= 6.0, "{:?}", r1.report);
        assert!((r1.subdivision.mesh.area() - m.area()).abs() < 1e-12 * m.area());
        assert!(r1.subdivision.mesh.positions.iter().all(|p| p.z == 0.0));
        for t in 0..r1.subdivision.mesh.triangles.len() {
            let [a, b, c] = r1.subdivision.mesh.triangles[t];
            let p = &r1.subdivision.mesh.positions;
            assert!((p[b] - p[a]).cross(&(p[c] - p[a])).z > 0.0);
        }
        Topology::new(&r1.subdivision.mesh).unwrap();
        check(
            m,
            &r1,
            &refine_for_wavelength(m, 3e-3, &midpoint()).unwrap(),
        );
        let three = RefineSettings { max_levels: 3, ..s };
        let r2 = refine_for_wavelength(m, 1.2e-3, &three).unwrap();
        assert_eq!(r2.report.levels, 3);
        let flat = RefineSettings {
            smoothing: Smoothing::Midpoint,
            ..three
        };
        check(m, &r2, &refine_for_wavelength(m, 1.2e-3, &flat).unwrap());
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
            ..s
        };
        assert!(refine_for_wavelength(m, 3e-3, &bad)
            .unwrap_err()
            .to_string()
            .contains("vertices_per_wavelength"));
    }

    /// Half a sheet refined: the levels come from the region's edges, only the region and a
    /// band around it are refined (no green triangle in the region), the far half keeps its
    /// triangles as they were, and the report counts it.
    #[test]
    fn only_the_region_and_its_band_are_refined() {
        let m = equilateral_sheet(16, 12, 1e-3).mesh;
        let centroid_x = |t: usize| {
            m.triangles[t]
                .iter()
                .map(|&v| m.positions[v].x)
                .sum::<f64>()
                / 3.0
        };
        let mid = m.positions.iter().map(|p| p.x).fold(0.0, f64::max) / 2.0;
        let region: Vec<bool> = (0..m.triangles.len())
            .map(|t| centroid_x(t) < mid)
            .collect();
        let s = RefineSettings::default();
        let r = refine_region(&m, Some(&region), 1.2e-3, &s).unwrap();
        let whole = refine_for_wavelength(&m, 1.2e-3, &s).unwrap();
        assert_eq!(r.report.levels, 3);
        assert!(
            r.subdivision.mesh.positions.len() < whole.subdivision.mesh.positions.len() * 2 / 3
        );
        assert!(r.report.transition_triangles > 0 && r.report.band_triangles > 0);
        assert_eq!(
            r.report.region_triangles,
            region.iter().filter(|&&x| x).count()
        );
        let mut untouched = 0;
        for (f, a) in r.subdivision.ancestor.iter().enumerate() {
            if region[a.triangle] {
                assert!(!r.subdivision.green[f]);
            }
            if a.bary == [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]] {
                assert_eq!(r.subdivision.mesh.triangles[f], m.triangles[a.triangle]);
                untouched += 1;
            }
        }
        assert!(untouched > m.triangles.len() / 4, "{untouched}");
        let flat = refine_region(&m, Some(&region), 1.2e-3, &midpoint()).unwrap();
        check(&m, &r, &flat);
        Topology::new(&r.subdivision.mesh).unwrap();
        // With nothing selected nothing is refined.
        let none = refine_region(&m, Some(&vec![false; region.len()]), 1.2e-3, &s).unwrap();
        assert_eq!(none.subdivision.mesh, m);
    }

    /// The face rig's mesh refined for the paper's λ = 4.04 mm: the report is consistent,
    /// S and the ancestors check out, and the refined vertices embedded in the face's lattice
    /// (in an element of their ancestor's corners) sit where they are at rest.
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
        let flat = refine_for_wavelength(m, 4.04e-3, &midpoint()).unwrap();
        check(m, &r, &flat);
        // The smoothing moves new vertices off the facets by a fraction of an edge.
        let moved = r
            .subdivision
            .mesh
            .positions
            .iter()
            .zip(&flat.subdivision.mesh.positions)
            .map(|(p, q)| (p - q).norm())
            .fold(0.0, f64::max);
        println!(
            "largest move off the facets: {:.3} mm (edge {:.3} mm)",
            moved * 1e3,
            edge * 1e3
        );
        assert!(moved > 0.0 && moved < 0.5 * edge, "{moved}");
        let lat = Lattice::build(m, &LatticeSettings::default()).unwrap();
        let pts = embed_refined(&lat, m, &r.subdivision).unwrap();
        let q = lat.rest_flat();
        let mut worst: f64 = 0.0;
        for (v, mp) in pts.iter().enumerate() {
            worst = worst.max((lat.position(&q, mp) - r.subdivision.mesh.positions[v]).norm());
        }
        println!("refined embedding: max |B q_rest − x| = {worst:.2e} m");
        assert!(worst < 1e-9, "{worst}");
        // Each new vertex is in an element of its (first triangle's) ancestor's corners.
        let mut first = vec![None; r.subdivision.mesh.positions.len()];
        for (f, tri) in r.subdivision.mesh.triangles.iter().enumerate() {
            for &v in tri {
                first[v].get_or_insert(f);
            }
        }
        for v in m.positions.len()..r.subdivision.mesh.positions.len() {
            let a = &r.subdivision.ancestor[first[v].unwrap()];
            let elements = m.triangles[a.triangle].map(|c| lat.vertex_points[c].element);
            assert!(elements.contains(&pts[v].element), "vertex {v}");
        }
        let t = embedding_triplets(&lat, &pts);
        assert!(t
            .iter()
            .all(|&(v, n, w)| v < pts.len() && n < lat.node_count() && w.is_finite()));
    }
}
