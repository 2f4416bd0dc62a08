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

#[test]
fn lips_are_separate_surfaces_that_touch() {
    let r = rig();
    let (upper, lower) = (region(r, "upper_lip"), region(r, "lower_lip"));
    let (su, sl) = (region(r, "mouth_slit_upper"), region(r, "mouth_slit_lower"));
    let up: HashSet<usize> = upper.iter().copied().collect();
    let lo: HashSet<usize> = lower.iter().copied().collect();
    assert!(up.is_disjoint(&lo), "upper and lower lip share vertices");
    assert!(su.iter().all(|v| up.contains(v)) && sl.iter().all(|v| lo.contains(v)));
    assert_eq!(su.len(), sl.len());
    assert!(su.len() >= 10, "slit has only {} vertices", su.len());
    // No triangle and no edge joins the two lips.
    for t in &r.mesh.triangles {
        let (a, b) = (
            t.iter().any(|v| up.contains(v)),
            t.iter().any(|v| lo.contains(v)),
        );
        assert!(!(a && b), "triangle {t:?} joins the lips");
    }
    // Along the slit the two sides coincide at neutral.
    let p = &r.mesh.positions;
    let gap0 = su
        .iter()
        .zip(sl)
        .map(|(&a, &b)| (p[a] - p[b]).norm())
        .fold(0.0, f64::max);
    assert!(gap0 < 1e-9, "neutral slit gap {gap0} m");
    // The slit spans the mouth: 3 to 7 cm between the corners.
    let c = region(r, "mouth_corners");
    let width = (p[c[1]] - p[c[0]]).norm();
    println!(
        "slit: {} vertex pairs, corner-to-corner {:.1} mm",
        su.len(),
        width * 1e3
    );
    assert!((0.03..0.07).contains(&width));
    // Only jaw_open parts the lips: at weight 1 they separate by a few mm to cm, most at the
    // centre, and every other shape keeps them together.
    for t in &r.targets {
        let gaps: Vec<f64> = su
            .iter()
            .zip(sl)
            .map(|(&a, &b)| (p[a] + t.positions[a] - p[b] - t.positions[b]).norm())
            .collect();
        let max = gaps.iter().copied().fold(0.0, f64::max);
        if t.name == "jaw_open" {
            let centre = gaps[gaps.len() / 2];
            let (first, last) = (gaps[0], gaps[gaps.len() - 1]);
            println!(
                "jaw_open slit gap: centre {:.2} mm, ends {:.2} / {:.2} mm",
                centre * 1e3,
                first * 1e3,
                last * 1e3
            );
            assert!(
                (0.005..0.04).contains(&centre),
                "jaw_open centre gap {centre} m"
            );
            assert!(
                first < 0.5 * centre && last < 0.5 * centre,
                "gap does not close toward the corners"
            );
            assert!(
                gaps.iter().all(|&g| g > 1e-5),
                "some slit pair does not separate"
            );
        } else {
            assert!(max < 1e-9, "{} opens the mouth by {max} m", t.name);
        }
    }
}

/// World direction, region and the strain bound for each wrinkle shape.
fn compression_cases() -> Vec<(&'static str, &'static str, Vector3<f64>)> {
    let x = Vector3::x();
    let y = Vector3::y();
    let pull_l = Vector3::new(0.42, 0.91, 0.0).normalize();
    let pull_r = Vector3::new(-0.42, 0.91, 0.0).normalize();
    vec![
        ("brow_raise", "forehead", y),
        ("brow_frown", "glabella", x),
        ("squint_left", "crow_left", y),
        ("squint_right", "crow_right", y),
        ("nose_wrinkle", "nose_bridge", y),
        ("smile_left", "nasolabial_left", pull_l),
        ("smile_right", "nasolabial_right", pull_r),
        ("pucker", "upper_lip", x),
        ("pucker", "lower_lip", x),
    ]
}

#[test]
fn wrinkle_shapes_compress_the_skin_where_faces_wrinkle() {
    let r = rig();
    for (shape, reg, dir) in compression_cases() {
        let verts = region(r, reg);
        let along = mean_region_strain(r, shape, verts, dir);
        // The in-plane direction perpendicular to `dir` (in the face plane, roughly).
        let perp = Vector3::z().cross(&dir).normalize();
        let across = mean_region_strain(r, shape, verts, perp);
        println!(
            "{shape:>13} in {reg:<16}: strain along {:+.1} %, across {:+.1} %",
            along * 100.0,
            across * 100.0
        );
        assert!(
            along < -0.05,
            "{shape}: mean strain {along} in {reg} is not compressive enough"
        );
        assert!(
            along > -0.45,
            "{shape}: mean strain {along} in {reg} is implausibly strong"
        );
        assert!(
            along < across,
            "{shape}: compression in {reg} is not along the expected direction"
        );
    }
}

#[test]
fn shapes_are_local() {
    let r = rig();
    type Far = fn(&Vector3<f64>) -> bool;
    let cases: [(&str, Far); 9] = [
        ("brow_raise", |p| p.y < 0.0),
        ("brow_frown", |p| p.y < 0.0 || p.x.abs() > 0.07),
        ("squint_left", |p| p.x < -0.01 || p.y < -0.04 || p.y > 0.06),
        ("squint_right", |p| p.x > 0.01 || p.y < -0.04 || p.y > 0.06),
        ("nose_wrinkle", |p| {
            p.y > 0.07 || p.y < -0.065 || p.x.abs() > 0.05
        }),
        ("smile_left", |p| p.x < -0.035 || p.y > 0.035),
        ("smile_right", |p| p.x > 0.035 || p.y > 0.035),
        ("jaw_open", |p| p.y > -0.02),
        ("pucker", |p| p.y > 0.0 || p.x.abs() > 0.06 || p.y < -0.095),
    ];
    for (shape, far) in cases {
        let d = deltas(r, shape);
        let (mut count, mut max) = (0, 0.0f64);
        for (p, dv) in r.mesh.positions.iter().zip(d) {
            if far(p) {
                count += 1;
                max = max.max(dv.norm());
            }
        }
        println!(
            "{shape:>13}: {count} far vertices move at most {:.3e} m",
            max
        );
        assert!(count > 1000);
        assert!(max < 1e-4, "{shape} moves far-away skin by {max} m");
    }
}

/// Index of the vertex at the mirror image (x → −x) of each vertex, found by position
/// (duplicated slit vertices are matched within their own copy).
fn mirror_map(r: &FaceRig) -> Vec<usize> {
    let lower: HashSet<usize> = region(r, "mouth_slit_lower").iter().copied().collect();
    let key = |p: &Vector3<f64>| ((p.x * 1e3).floor() as i64, (p.y * 1e3).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (v, p) in r.mesh.positions.iter().enumerate() {
        grid.entry(key(p)).or_default().push(v);
    }
    (0..r.mesh.vertex_count())
        .map(|v| {
            let p = r.mesh.positions[v];
            let q = Vector3::new(-p.x, p.y, p.z);
            let (kx, ky) = key(&q);
            let mut best = (f64::MAX, usize::MAX);
            for dx in -1..=1 {
                for dy in -1..=1 {
                    for &w in grid
                        .get(&(kx + dx, ky + dy))
                        .map_or(&[][..], |c| c.as_slice())
                    {
                        if lower.contains(&w) != lower.contains(&v) {
                            continue;
                        }
                        let d = (r.mesh.positions[w] - q).norm();
                        if d < best.0 {
                            best = (d, w);
                        }
                    }
                }
            }
            assert!(
                best.0 < 1e-9,
                "vertex {v} has no mirror image (nearest {} m)",
                best.0
            );
            best.1
        })
        .collect()
}

#[test]
fn left_and_right_are_mirror_images() {
    let r = rig();
    let m = mirror_map(r);
    let mirror = |d: &Vector3<f64>| Vector3::new(-d.x, d.y, d.z);
    let pairs = [
        ("squint_left", "squint_right"),
        ("smile_left", "smile_right"),
        ("brow_raise", "brow_raise"),
        ("brow_frown", "brow_frown"),
        ("nose_wrinkle", "nose_wrinkle"),
        ("jaw_open", "jaw_open"),
        ("pucker", "pucker"),
    ];
    for (a, b) in pairs {
        let (da, db) = (deltas(r, a), deltas(r, b));
        let err = (0..da.len())
            .map(|v| (db[m[v]] - mirror(&da[v])).norm())
            .fold(0.0, f64::max);
        println!("mirror {a} -> {b}: max error {err:.2e} m");
        assert!(err < 1e-12, "{b} is not the mirror image of {a}: {err} m");
    }
    // Left shapes act on the left (+x) side.
    for name in ["squint_left", "smile_left"] {
        let d = deltas(r, name);
        let side = |sgn: f64| -> f64 {
            r.mesh
                .positions
                .iter()
                .zip(d)
                .filter(|(p, _)| p.x * sgn > 0.0)
                .map(|(_, dv)| dv.norm())
                .sum()
        };
        assert!(
            side(1.0) > 5.0 * side(-1.0),
            "{name} acts mostly on the wrong side"
        );
    }
}

#[test]
fn animation_exercises_every_shape() {
    let r = rig();
    let k = &r.keys;
    let n = r.targets.len();
    assert_eq!(k.times.len(), k.weights.len());
    let duration = k.times.last().unwrap() - k.times[0];
    println!("animation: {} keys, {duration:.2} s", k.times.len());
    assert!(duration >= 4.0);
    for w in k.times.windows(2) {
        assert!(
            (w[1] - w[0] - 1.0 / 30.0).abs() < 1e-9,
            "keys are not at 30 fps"
        );
    }
    assert!(k.weights.iter().all(|row| row.len() == n));
    assert!(k
        .weights
        .iter()
        .flatten()
        .all(|&w| (0.0..=1.0).contains(&w)));
    assert!(
        k.weights[0]
            .iter()
            .chain(k.weights.last().unwrap())
            .all(|&w| w == 0.0),
        "must start and end neutral"
    );
    for t in 0..n {
        let peak = k.weights.iter().map(|row| row[t]).fold(0.0, f64::max);
        assert!(peak >= 0.9, "{} peaks at {peak}", r.targets[t].name);
        // Each shape has a moment alone.
        let solo = k
            .weights
            .iter()
            .any(|row| row[t] >= 0.9 && (0..n).all(|s| s == t || row[s] <= 0.05));
        assert!(solo, "{} is never shown alone", r.targets[t].name);
    }
    // At least two keys with two or more shapes above 0.5 (combinations).
    let combos = k
        .weights
        .iter()
        .filter(|row| row.iter().filter(|&&w| w > 0.5).count() >= 2)
        .count();
    assert!(combos >= 2);
    // Smooth: no weight jumps by more than 0.25 between consecutive keys.
    for w in k.weights.windows(2) {
        assert!(w[0].iter().zip(&w[1]).all(|(a, b)| (a - b).abs() < 0.25));
    }
}
