//! Local smooth refinement (`mesh::redgreen`, `coupling::refine`): the transition is
//! conforming, the butterfly rule is interpolating and smooth, and it fades to midpoints
//! across the transition band.

use furrow::coupling::refine::{refine_region, RefineSettings, Smoothing};
use furrow::mesh::redgreen::{self, graded_levels, RedGreen};
use furrow::mesh::TriMesh;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Triangles per undirected edge.
fn edge_counts(m: &TriMesh) -> HashMap<(usize, usize), usize> {
    let mut e = HashMap::new();
    for t in &m.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *e.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    e
}

/// Total length (m) of the edges with one triangle.
fn boundary_length(m: &TriMesh) -> f64 {
    edge_counts(m)
        .iter()
        .filter(|(_, &n)| n == 1)
        .map(|(&(a, b), _)| (m.positions[a] - m.positions[b]).norm())
        .sum()
}

/// Euler characteristic V − E + F (of the vertices on triangles).
fn euler(m: &TriMesh) -> i64 {
    let used: std::collections::HashSet<usize> = m.triangles.iter().flatten().copied().collect();
    used.len() as i64 - edge_counts(m).len() as i64 + m.triangles.len() as i64
}

/// The refined mesh `flat` (placed by midpoints) is conforming: every edge has one or two
/// triangles, no vertex lies inside another triangle's edge (a T-junction), the boundary is
/// the coarse one (same length: a crack would add both sides of it) and the topology too.
fn assert_conforming(coarse: &TriMesh, flat: &TriMesh) {
    let edges = edge_counts(flat);
    let coarse_edges = edge_counts(coarse);
    let max_coarse = coarse_edges.values().copied().max().unwrap_or(0);
    assert!(
        edges.values().all(|&n| n == 1 || n == 2 || n <= max_coarse),
        "an edge with no or too many triangles"
    );
    let (bl, bc) = (boundary_length(flat), boundary_length(coarse));
    assert!(
        (bl - bc).abs() < 1e-9 * bc.max(1e-9),
        "boundary {bl} vs {bc}"
    );
    assert_eq!(euler(flat), euler(coarse));
    // No vertex strictly inside an edge: hash the vertices on a grid of the longest edge.
    let cell = edges
        .keys()
        .map(|&(a, b)| (flat.positions[a] - flat.positions[b]).norm())
        .fold(0.0, f64::max);
    let key = |p: &Vector3<f64>| (p / cell).map(|c| c.floor() as i64);
    let mut grid: HashMap<Vector3<i64>, Vec<usize>> = HashMap::new();
    for (v, p) in flat.positions.iter().enumerate() {
        grid.entry(key(p)).or_default().push(v);
    }
    for &(a, b) in edges.keys() {
        let (pa, pb) = (flat.positions[a], flat.positions[b]);
        let len = (pb - pa).norm();
        let k = key(&pa);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(vs) = grid.get(&(k + Vector3::new(dx, dy, dz))) else {
                        continue;
                    };
                    for &v in vs.iter().filter(|&&v| v != a && v != b) {
                        let p = flat.positions[v];
                        let t = (p - pa).dot(&(pb - pa)) / (len * len);
                        let off = (pa + (pb - pa) * t - p).norm();
                        assert!(
                            !(t > 1e-9 && t < 1.0 - 1e-9 && off < 1e-9 * len),
                            "vertex {v} lies inside edge ({a}, {b})"
                        );
                    }
                }
            }
        }
    }
}

/// Per triangle of `m`: all its corners above height `y` (m).
fn above(m: &TriMesh, y: f64) -> Vec<bool> {
    m.triangles
        .iter()
        .map(|t| t.iter().all(|&v| m.positions[v].y > y))
        .collect()
}

/// The face rig welded (its seams joined), as the pipeline refines it.
fn welded_face() -> TriMesh {
    let rig = furrow::rig::face::generate();
    let m = &rig.mesh;
    furrow::pipeline::setup::weld::weld(&m.positions, &[], &m.triangles, 1e-9).mesh
}

#[test]
fn a_partly_refined_face_is_conforming_with_green_closures() {
    let m = welded_face();
    // The forehead (upper third) refined two levels; the mouth slit and the open rim are
    // boundaries elsewhere.
    let (lo, hi) = m.bounding_box().unwrap();
    let cut = lo.y + 0.66 * (hi.y - lo.y);
    let region = above(&m, cut);
    for levels in [1, 2, 3] {
        let flat = redgreen::refine(&m, &region, levels, Smoothing::Midpoint);
        let smooth = redgreen::refine(&m, &region, levels, Smoothing::Butterfly);
        let greens = flat.green.iter().filter(|&&g| g).count();
        println!(
            "{levels} level(s): {} → {} vertices, {} green triangles",
            m.positions.len(),
            flat.mesh.positions.len(),
            greens
        );
        assert!(greens > 0);
        assert_conforming(&m, &flat.mesh);
        assert_eq!(smooth.mesh.triangles, flat.mesh.triangles);
        // Green triangles are never in the region, and nothing outside region and band is
        // touched.
        for (f, a) in flat.ancestor.iter().enumerate() {
            assert!(!(flat.green[f] && region[a.triangle]));
        }
    }
    // The whole skin: uniform red refinement, no closures.
    let all = redgreen::refine(&m, &vec![true; m.triangles.len()], 1, Smoothing::Midpoint);
    assert!(all.green.iter().all(|&g| !g));
    assert_eq!(all.mesh.triangles.len(), 4 * m.triangles.len());
    assert_conforming(&m, &all.mesh);
}

/// An icosahedron subdivided `n` times onto the unit sphere (m).
fn icosphere(n: usize) -> TriMesh {
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut p: Vec<Vector3<f64>> = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ]
    .iter()
    .map(|c| Vector3::from(*c).normalize())
    .collect();
    let t = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    let mut m = TriMesh::new(p.clone(), t);
    for _ in 0..n {
        let all = vec![true; m.triangles.len()];
        m = redgreen::refine(&m, &all, 1, Smoothing::Midpoint).mesh;
        p = m.positions.iter().map(|x| x.normalize()).collect();
        m.positions = p.clone();
    }
    m
}

/// Largest and RMS distance (m) of the vertices of `m` from the unit sphere.
fn sphere_error(m: &TriMesh) -> (f64, f64) {
    let d: Vec<f64> = m.positions.iter().map(|p| (p.norm() - 1.0).abs()).collect();
    let max = d.iter().copied().fold(0.0, f64::max);
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len() as f64).sqrt();
    (max, rms)
}

#[test]
fn butterfly_is_interpolating_and_closer_to_a_sphere_than_midpoints() {
    // 42 vertices (12 of valence 5) refined twice.
    let m = icosphere(1);
    let all = vec![true; m.triangles.len()];
    let flat = redgreen::refine(&m, &all, 2, Smoothing::Midpoint);
    let smooth = redgreen::refine(&m, &all, 2, Smoothing::Butterfly);
    let (fmax, frms) = sphere_error(&flat.mesh);
    let (smax, srms) = sphere_error(&smooth.mesh);
    println!(
        "sphere of 42 vertices refined twice: midpoints {fmax:.4} max / {frms:.4} RMS, butterfly \
         {smax:.4} / {srms:.4} (radius 1)"
    );
    // The coarse vertices stay on the sphere, exactly.
    for v in 0..m.positions.len() {
        assert_eq!(smooth.mesh.positions[v], m.positions[v]);
    }
    assert!(smax < fmax / 4.0 && srms < frms / 4.0);
    // Every refined triangle keeps its orientation (no fold from the smoothing).
    for t in &smooth.mesh.triangles {
        let p = t.map(|v| smooth.mesh.positions[v]);
        let n = (p[1] - p[0]).cross(&(p[2] - p[0]));
        assert!(n.dot(&(p[0] + p[1] + p[2])) > 0.0);
    }
}

/// The fade τ of each refined vertex: its ancestor barycentrics over the coarse vertices' fade.
fn fades(m: &TriMesh, r: &RedGreen, fade: &[f64]) -> Vec<f64> {
    let mut tau = vec![f64::NAN; r.mesh.positions.len()];
    for (tri, a) in r.mesh.triangles.iter().zip(&r.ancestor) {
        let c = m.triangles[a.triangle];
        for (k, &v) in tri.iter().enumerate() {
            tau[v] = (0..3).map(|i| a.bary[k][i] * fade[c[i]]).sum();
        }
    }
    tau
}

#[test]
fn the_smoothing_fades_to_midpoints_across_the_band() {
    let m = icosphere(2);
    // The upper cap refined twice: a band of one ring at one level, then green closures.
    let region = above(&m, 0.3);
    let flat = redgreen::refine(&m, &region, 2, Smoothing::Midpoint);
    let smooth = redgreen::refine(&m, &region, 2, Smoothing::Butterfly);
    assert_conforming(&m, &flat.mesh);
    let (_, fade) = graded_levels(&m, &region, 2);
    let tau = fades(&m, &smooth, &fade);
    let mut err: HashMap<&str, (f64, f64, usize)> = HashMap::new();
    for v in m.positions.len()..smooth.mesh.positions.len() {
        let (p, q) = (smooth.mesh.positions[v], flat.mesh.positions[v]);
        let class = if tau[v] == 0.0 {
            // No smoothing at all: the plain midpoint, bit for bit.
            assert_eq!(p, q, "vertex {v}");
            "0"
        } else if tau[v] == 1.0 {
            "1"
        } else {
            "between"
        };
        let e = err.entry(class).or_insert((0.0, 0.0, 0));
        e.0 += (p.norm() - 1.0).abs();
        e.1 += (q.norm() - 1.0).abs();
        e.2 += 1;
    }
    println!("mean distance from the sphere by fade, butterfly vs midpoint: {err:?}");
    for class in ["0", "between", "1"] {
        assert!(
            err.get(class).is_some_and(|e| e.2 > 0),
            "no vertex faded {class}"
        );
    }
    // Fully smoothed vertices are much closer; half-faded ones in between.
    let ratio = |c: &str| err[c].0 / err[c].1;
    assert!(ratio("1") < 0.25, "{}", ratio("1"));
    assert!(ratio("between") > ratio("1") && ratio("between") < 0.9);
}

#[test]
fn levels_come_from_the_region_and_the_refusal_names_them() {
    // A sphere whose upper cap is twice as fine as the rest: the cap needs a level less than
    // the mean edge of the whole mesh says.
    let coarse = icosphere(2);
    let cap = above(&coarse, 0.2);
    let mut m = redgreen::refine(&coarse, &cap, 1, Smoothing::Midpoint);
    m.mesh.positions.iter_mut().for_each(|p| *p = p.normalize());
    let region: Vec<bool> = m.ancestor.iter().map(|a| cap[a.triangle]).collect();
    let m = m.mesh;
    let (whole, part) = (
        furrow::coupling::refine::mean_edge(&m),
        furrow::coupling::refine::mean_edge_of(&m, |t| region[t]),
    );
    let s = RefineSettings::default();
    // λ such that the cap needs exactly one level and the whole mesh two.
    let lambda = 6.0 * part / 1.9;
    assert!(
        (6.0 * whole / lambda).log2().ceil() >= 2.0,
        "{whole} {part}"
    );
    let r = refine_region(&m, Some(&region), lambda, &s).unwrap();
    assert_eq!(r.report.levels, 1);
    assert!(r.report.vertices_per_wavelength >= s.vertices_per_wavelength);
    assert!((r.report.mean_edge_before - part).abs() < 1e-15);
    let err = refine_region(&m, Some(&region), 1e-3, &s).unwrap_err();
    assert!(err.to_string().contains("max_levels = 3"), "{err}");
}

/// A thin patch inside a thicker skin: the face's forehead refined for a wavelength half the
/// rest's takes one level more than the rest, the levels change by at most one between
/// triangles sharing a vertex, the mesh is conforming (green closures where the patch meets
/// the rest), and it has fewer vertices than refining everything for the thin patch; the
/// report counts the triangles refined less and the least vertices per wavelength of either.
#[test]
fn a_thin_patch_is_refined_further_than_the_skin_around_it() {
    use furrow::coupling::refine::{refine_for_wavelengths, DEFAULT_VERTICES_PER_WAVELENGTH};
    let m = welded_face();
    let (lo, hi) = m.bounding_box().unwrap();
    let patch = above(&m, lo.y + 0.75 * (hi.y - lo.y));
    let thick = 8e-3;
    let lambda: Vec<f64> = patch
        .iter()
        .map(|&p| if p { 0.5 * thick } else { thick })
        .collect();
    let mid = RefineSettings {
        smoothing: Smoothing::Midpoint,
        ..RefineSettings::default()
    };
    let r = refine_for_wavelengths(&m, None, &lambda, &mid).unwrap();
    let uniform = refine_region(&m, None, 0.5 * thick, &mid).unwrap();
    let coarse = refine_region(&m, None, thick, &mid).unwrap();
    let (l, rep) = (&r.subdivision.level, &r.report);
    println!("{rep:?}");
    assert!(coarse.report.levels >= 1);
    assert_eq!(rep.levels, coarse.report.levels + 1);
    assert_eq!(rep.levels, uniform.report.levels);
    for t in 0..m.triangles.len() {
        let want = if patch[t] { rep.levels } else { rep.levels - 1 };
        assert_eq!(l[t], want, "triangle {t}");
    }
    assert_eq!(
        rep.fewer_levels,
        patch.iter().filter(|&&p| !p).count(),
        "the thick skin is refined less"
    );
    assert!(rep.vertices_per_wavelength >= DEFAULT_VERTICES_PER_WAVELENGTH * 0.9);
    assert!(rep.wavelength == 0.5 * thick);
    assert!(r.subdivision.green.iter().any(|&g| g));
    assert_conforming(&m, &r.subdivision.mesh);
    let (n, n_thin) = (
        r.subdivision.mesh.positions.len(),
        uniform.subdivision.mesh.positions.len(),
    );
    assert!(n < n_thin / 2, "{n} vertices against {n_thin}");
    // Levels of triangles sharing a vertex differ by at most one (here: a patch two levels
    // above the unrefined rest, graded).
    let target: Vec<usize> = patch.iter().map(|&p| if p { 2 } else { 0 }).collect();
    let (level, _) = redgreen::graded_levels_by_triangle(&m, &target);
    let mut at: Vec<Vec<usize>> = vec![Vec::new(); m.positions.len()];
    for (t, tri) in m.triangles.iter().enumerate() {
        tri.iter().for_each(|&v| at[v].push(level[t]));
    }
    for ls in at.iter().filter(|ls| !ls.is_empty()) {
        let (a, b) = (ls.iter().min().unwrap(), ls.iter().max().unwrap());
        assert!(b - a <= 1, "levels {ls:?} at one vertex");
    }
    assert!(level.contains(&1) && level.contains(&0));
}
