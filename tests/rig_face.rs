//! Tests of the procedural face rig (`furrow::rig::face::generate`).
//!
//! Every check measures the generated data directly (topology, geometry, deformation gradients);
//! none of them reads the generator's internal parameters. Run with `-- --nocapture` to see the
//! measured numbers.

use std::collections::{HashMap, HashSet};
use std::sync::OnceLock;

use furrow::rig::face::{generate, FaceRig};
use nalgebra::{Matrix2, Vector2, Vector3};

fn rig() -> &'static FaceRig {
    static RIG: OnceLock<FaceRig> = OnceLock::new();
    RIG.get_or_init(generate)
}

fn region<'a>(rig: &'a FaceRig, name: &str) -> &'a [usize] {
    rig.region(name)
        .unwrap_or_else(|| panic!("rig has no region {name}"))
}

fn deltas<'a>(rig: &'a FaceRig, name: &str) -> &'a [Vector3<f64>] {
    &rig.target(name)
        .unwrap_or_else(|| panic!("rig has no target {name}"))
        .positions
}

/// Positions at weight 1 of target `name`.
fn deformed(rig: &FaceRig, name: &str) -> Vec<Vector3<f64>> {
    rig.mesh
        .positions
        .iter()
        .zip(deltas(rig, name))
        .map(|(p, d)| p + d)
        .collect()
}

/// Undirected edge → number of incident triangles.
fn edge_counts(tris: &[[usize; 3]]) -> HashMap<(usize, usize), usize> {
    let mut m = HashMap::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *m.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    m
}

/// Engineering strain of triangle `t` along the world direction `dir` projected onto the rest
/// triangle's plane: |F d| − 1 with F the 2D deformation gradient (rest → deformed).
fn directional_strain(
    rest: &[Vector3<f64>],
    def: &[Vector3<f64>],
    t: [usize; 3],
    dir: Vector3<f64>,
) -> Option<f64> {
    let (e1, e2) = (rest[t[1]] - rest[t[0]], rest[t[2]] - rest[t[0]]);
    let n = e1.cross(&e2);
    if n.norm() == 0.0 {
        return None;
    }
    let n = n.normalize();
    let d = dir - n * n.dot(&dir);
    if d.norm() < 1e-6 {
        return None;
    }
    let d = d.normalize();
    // d = a e1 + b e2 (solve the Gram system).
    let g = Matrix2::new(e1.dot(&e1), e1.dot(&e2), e1.dot(&e2), e2.dot(&e2));
    let ab = g.try_inverse()? * Vector2::new(e1.dot(&d), e2.dot(&d));
    let (f1, f2) = (def[t[1]] - def[t[0]], def[t[2]] - def[t[0]]);
    Some((f1 * ab.x + f2 * ab.y).norm() - 1.0)
}

/// Area-weighted mean directional strain over the triangles with all three vertices in `verts`.
fn mean_region_strain(rig: &FaceRig, shape: &str, verts: &[usize], dir: Vector3<f64>) -> f64 {
    let inside: HashSet<usize> = verts.iter().copied().collect();
    let def = deformed(rig, shape);
    let (mut sum, mut area) = (0.0, 0.0);
    for (k, &t) in rig.mesh.triangles.iter().enumerate() {
        if t.iter().all(|v| inside.contains(v)) {
            if let Some(e) = directional_strain(&rig.mesh.positions, &def, t, dir) {
                let a = rig.mesh.triangle_area(k);
                sum += a * e;
                area += a;
            }
        }
    }
    assert!(area > 0.0, "region for {shape} holds no whole triangle");
    sum / area
}

#[test]
fn size_counts_and_finiteness() {
    let r = rig();
    let n = r.mesh.vertex_count();
    let (lo, hi) = r.mesh.bounding_box().unwrap();
    let size = hi - lo;
    println!(
        "vertices {n}, triangles {}, bbox size {size:?} m",
        r.mesh.triangle_count()
    );
    assert!((9_000..=11_000).contains(&n), "vertex count {n}");
    assert!((0.18..=0.22).contains(&size.y), "height {} m", size.y);
    assert!((0.12..=0.18).contains(&size.x), "width {} m", size.x);
    assert!(r
        .mesh
        .positions
        .iter()
        .all(|p| p.iter().all(|c| c.is_finite())));
    for t in &r.targets {
        assert_eq!(t.positions.len(), n, "{}", t.name);
        assert!(
            t.positions.iter().all(|p| p.iter().all(|c| c.is_finite())),
            "{}",
            t.name
        );
        let max = t.positions.iter().map(|d| d.norm()).fold(0.0, f64::max);
        println!("{:>13}: max |delta| {:.2} mm", t.name, max * 1e3);
        // mm to cm scale: every shape moves something by at least 2 mm and nothing by 4 cm.
        assert!((0.002..0.04).contains(&max), "{} max delta {max} m", t.name);
        let normals = t.normals.as_ref().expect("normal deltas");
        assert!(normals.iter().all(|p| p.iter().all(|c| c.is_finite())));
    }
    for tri in &r.mesh.triangles {
        assert!(tri.iter().all(|&v| v < n));
        assert!(tri[0] != tri[1] && tri[1] != tri[2] && tri[0] != tri[2]);
    }
}

#[test]
fn has_the_required_shapes_and_regions() {
    let r = rig();
    for name in [
        "brow_raise",
        "brow_frown",
        "squint_left",
        "squint_right",
        "nose_wrinkle",
        "smile_left",
        "smile_right",
        "jaw_open",
        "pucker",
    ] {
        assert!(r.target(name).is_some(), "missing target {name}");
    }
    for name in [
        "upper_lip",
        "lower_lip",
        "forehead",
        "glabella",
        "crow_left",
        "crow_right",
        "nose_bridge",
        "nasolabial_left",
        "nasolabial_right",
    ] {
        let v = region(r, name);
        println!("region {name}: {} vertices", v.len());
        assert!(v.len() >= 10, "region {name} has {} vertices", v.len());
    }
}

#[test]
fn generation_is_deterministic() {
    let a = generate();
    let b = rig();
    assert_eq!(a.mesh, b.mesh);
    assert_eq!(a.targets, b.targets);
    assert_eq!(a.keys, b.keys);
    assert_eq!(a.regions, b.regions);
}

#[test]
fn manifold_connected_and_open_at_the_back() {
    let r = rig();
    let edges = edge_counts(&r.mesh.triangles);
    assert!(edges.values().all(|&c| c <= 2), "non-manifold edge");
    // One connected surface (through the mouth corners).
    let n = r.mesh.vertex_count();
    let mut adj = vec![Vec::new(); n];
    for &(a, b) in edges.keys() {
        adj[a].push(b);
        adj[b].push(a);
    }
    let mut seen = vec![false; n];
    let mut stack = vec![0];
    seen[0] = true;
    while let Some(v) = stack.pop() {
        for &w in &adj[v] {
            if !seen[w] {
                seen[w] = true;
                stack.push(w);
            }
        }
    }
    assert!(seen.iter().all(|&s| s), "mesh is not one connected surface");

    let slit: HashSet<usize> = region(r, "mouth_slit_upper")
        .iter()
        .chain(region(r, "mouth_slit_lower"))
        .chain(region(r, "mouth_corners"))
        .copied()
        .collect();
    let boundary: HashSet<usize> = edges
        .iter()
        .filter(|(_, &c)| c == 1)
        .flat_map(|(&(a, b), _)| [a, b])
        .collect();
    assert!(
        !boundary.is_empty(),
        "closed mesh: the mask must be open at the back"
    );
    let zmax = r
        .mesh
        .positions
        .iter()
        .map(|p| p.z)
        .fold(f64::MIN, f64::max);
    let mut rim_count = 0;
    for &v in &boundary {
        if slit.contains(&v) {
            continue;
        }
        rim_count += 1;
        let p = r.mesh.positions[v];
        // On the rim: at the sides well behind the face front, or at the top/bottom edge.
        let on_rim = p.z < zmax - 0.06 || p.y.abs() > 0.085;
        assert!(
            on_rim,
            "boundary vertex {v} at {p:?} is on the face, not on the rim"
        );
    }
    println!(
        "boundary: {rim_count} rim vertices, {} slit vertices; zmax {zmax:.4} m",
        slit.len()
    );
    // Every boundary vertex that is not on the slit is in the published rim region.
    let rim: HashSet<usize> = region(r, "rim").iter().copied().collect();
    assert!(boundary.iter().all(|v| slit.contains(v) || rim.contains(v)));
    // Nothing behind the ears: the mask covers only the front of the head.
    let zmin = r
        .mesh
        .positions
        .iter()
        .map(|p| p.z)
        .fold(f64::MAX, f64::min);
    assert!(
        zmin > -0.01,
        "mask reaches z = {zmin} m, behind the head centre"
    );
}

#[test]
fn triangles_face_outward() {
    let r = rig();
    let p = &r.mesh.positions;
    let mut front = (0usize, 0.0f64);
    for (k, &[a, b, c]) in r.mesh.triangles.iter().enumerate() {
        let nrm = (p[b] - p[a]).cross(&(p[c] - p[a])).normalize();
        let centroid = (p[a] + p[b] + p[c]) / 3.0;
        // The head is star-shaped about its centre: outward normals point away from it.
        assert!(
            nrm.dot(&centroid.normalize()) > 0.05,
            "triangle {k} faces inward: n {nrm:?}"
        );
        if centroid.x.abs() < 0.03 && centroid.y.abs() < 0.08 {
            front.0 += 1;
            front.1 += nrm.z;
        }
    }
    let mean_nz = front.1 / front.0 as f64;
    println!(
        "mean normal z over {} front triangles: {mean_nz:.3}",
        front.0
    );
    assert!(mean_nz > 0.8);
}

#[test]
fn triangle_quality() {
    let r = rig();
    let p = &r.mesh.positions;
    let (mut min_angle, mut max_ratio) = (f64::MAX, 0.0f64);
    let (mut emin, mut emax) = (f64::MAX, 0.0f64);
    for &[a, b, c] in &r.mesh.triangles {
        let l = [
            (p[b] - p[a]).norm(),
            (p[c] - p[b]).norm(),
            (p[a] - p[c]).norm(),
        ];
        for k in 0..3 {
            let (u, v) = (
                p[[b, c, a][k]] - p[[a, b, c][k]],
                p[[c, a, b][k]] - p[[a, b, c][k]],
            );
            min_angle = min_angle.min(u.angle(&v).to_degrees());
        }
        let (lo, hi) = (
            l.iter().copied().fold(f64::MAX, f64::min),
            l.iter().copied().fold(0.0, f64::max),
        );
        max_ratio = max_ratio.max(hi / lo);
        emin = emin.min(lo);
        emax = emax.max(hi);
    }
    println!(
        "min angle {min_angle:.1} deg, max per-triangle edge ratio {max_ratio:.2}, edges {:.2}..{:.2} mm",
        emin * 1e3,
        emax * 1e3
    );
    assert!(min_angle > 20.0);
    assert!(max_ratio < 3.0);
    assert!(emax / emin < 6.0);
}
