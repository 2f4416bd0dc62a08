//! The lattice over the procedural face rig (`rig::face::generate()`): the two lips touch
//! along the mouth slit but get superimposed elements, and pushing the lower lip leaves the
//! upper lip (nearly) still.
#![allow(clippy::needless_range_loop)]

use furrow::fem::{BackwardEuler, Interior, LinearSolver, Material, StepSettings};
use furrow::lattice::{Lattice, LatticeSettings};
use nalgebra::Vector3;

#[test]
fn face_lips_get_superimposed_elements_and_move_independently() {
    let rig = furrow::rig::face::generate();
    let mesh = &rig.mesh;
    let region = |n: &str| {
        rig.regions
            .iter()
            .find(|(k, _)| k == n)
            .map(|(_, v)| v.clone())
            .unwrap()
    };
    let (up, lo) = (region("mouth_slit_upper"), region("mouth_slit_lower"));
    assert_eq!(up.len(), lo.len());
    let s = LatticeSettings {
        cell_size: Some(0.01),
        ..Default::default()
    };
    let lat = Lattice::build(mesh, &s).unwrap();
    assert!(!lat.closed);
    let corners = region("mouth_corners");
    let mut separate = 0;
    let mut far_shared = Vec::new();
    for (&u, &l) in up.iter().zip(&lo) {
        assert!((mesh.positions[u] - mesh.positions[l]).norm() < 1e-9);
        let (eu, el) = (lat.vertex_points[u].element, lat.vertex_points[l].element);
        assert_eq!(lat.elements[eu].cell, lat.elements[el].cell);
        separate += usize::from(eu != el);
        // Near a mouth corner the lips are one connected surface within the cell, so one
        // element there is right; away from the corners (beyond 1.5 cells, where no cell
        // holding the pair also holds a corner) they must be apart.
        let to_corner = corners
            .iter()
            .map(|&c| (mesh.positions[c] - mesh.positions[u]).norm())
            .fold(f64::INFINITY, f64::min);
        if eu == el && to_corner > 1.5 * 0.01 {
            far_shared.push((u, to_corner));
        }
    }
    assert!(
        far_shared.is_empty(),
        "slit pairs away from the corners share an element: {far_shared:?}"
    );
    println!(
        "face: {} vertices, {} elements, {} nodes ({} bone), depth {:.4} m; {separate} of {} slit pairs in superimposed elements",
        mesh.vertex_count(),
        lat.elements.len(),
        lat.node_count(),
        lat.pinned_count(),
        lat.depth,
        up.len()
    );
    // B reproduces the neutral face.
    let x = lat.embed(&lat.rest_flat());
    let err = mesh
        .positions
        .iter()
        .zip(&x)
        .map(|(p, e)| (p - e).norm())
        .fold(0.0, f64::max);
    assert!(err < 1e-12, "{err}");

    // Push the middle of the lower lip into the face and watch the upper lip 4 mm above the
    // slit; control: the same face with the slit welded shut.
    let mid = up.len() / 2;
    let p_up = mesh.positions[up[mid]];
    let above = (0..mesh.vertex_count())
        .filter(|&v| up.contains(&v) || mesh.positions[v].y > p_up.y + 1e-4)
        .min_by(|&a, &b| {
            let t = p_up + Vector3::new(0.0, 0.004, 0.0);
            (mesh.positions[a] - t)
                .norm()
                .total_cmp(&(mesh.positions[b] - t).norm())
        })
        .unwrap();
    let (dl, da) = push(mesh, &lat, lo[mid], above);
    let mut welded = mesh.clone();
    for t in &mut welded.triangles {
        for v in t.iter_mut() {
            if let Some(i) = lo.iter().position(|&l| l == *v) {
                *v = up[i];
            }
        }
    }
    let wlat = Lattice::build(&welded, &s).unwrap();
    let (dl0, da0) = push(&welded, &wlat, up[mid], above);
    println!(
        "face lips: pushed {dl:.3e} m, upper lip 4 mm above {da:.3e} m (ratio {:.2e}); welded control: {dl0:.3e} m, {da0:.3e} m (ratio {:.2e})",
        da / dl,
        da0 / dl0
    );
    assert!(dl > 1e-4 && dl0 > 1e-4);
    // The lips still meet at the mouth corners (one surface there), so the upper lip is not
    // perfectly still: measured 10.6 % of the pushed lip's motion against 86 % welded.
    assert!(
        da / dl < 0.15 && da0 / dl0 > 0.3,
        "the slit must decouple the lips"
    );
    assert!(da / dl < 0.2 * (da0 / dl0));
}

/// Displacements (pushed vertex, watched vertex) after 3 backward Euler steps (at most 3
/// Newton iterations each, enough for a displacement ratio) with a 0.05 N
/// push into the face (−z) on `pushed`, bone pinned, no gravity.
fn push(mesh: &furrow::mesh::TriMesh, lat: &Lattice, pushed: usize, watched: usize) -> (f64, f64) {
    let mat = Material {
        young: 1.0e4,
        poisson: 0.3,
        density: 1000.0,
    };
    let int = Interior::new(lat, &mat).unwrap();
    let settings = StepSettings {
        gravity: [0.0; 3],
        linear_solver: LinearSolver::ConjugateGradient {
            rel_tol: 1e-6,
            max_iter: 2000,
        },
        tangent: furrow::fem::Tangent::Consistent,
        max_newton: 3,
        ..Default::default()
    };
    let mut be = BackwardEuler::new(int, lat.rest_flat(), lat.pinned.clone(), settings).unwrap();
    let mut f = vec![0.0; 3 * lat.node_count()];
    for (n, w) in lat.weights(&lat.vertex_points[pushed]) {
        f[3 * n + 2] -= 0.05 * w;
    }
    for _ in 0..3 {
        be.step(&f, None).unwrap();
    }
    let moved = lat.embed(&be.q);
    let d = |v: usize| (moved[v] - mesh.positions[v]).norm();
    (d(pushed), d(watched))
}
