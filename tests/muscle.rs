//! Muscles and the activation fit (issue 6): the active energy's derivatives and invariance,
//! the stiffness balance of a contracting block, recovery of known activations, bounds,
//! unreachable and degenerate targets, generated muscles on the face rig and on 52 ARKit
//! shapes, and the TOML rig file.
#![allow(clippy::needless_range_loop)]

use furrow::fem::{Interior, Material};
use furrow::lattice::{Lattice, LatticeSettings};
use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::Energy;
use furrow::mesh::TriMesh;
use furrow::muscle::generate::Lcg;
use furrow::muscle::{ActiveEnergy, Forward, ForwardStatus, Muscle};
use nalgebra::{Rotation3, Vector3};

type V3 = Vector3<f64>;

/// Closed box mesh [0, a.x] × [0, a.y] × [0, a.z], each face split into m × m quads.
fn box_mesh(a: V3, m: usize) -> TriMesh {
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    let frames: [(usize, f64, V3, V3); 6] = [
        (0, 1.0, V3::y(), V3::z()),
        (0, 0.0, V3::z(), V3::y()),
        (1, 1.0, V3::z(), V3::x()),
        (1, 0.0, V3::x(), V3::z()),
        (2, 1.0, V3::x(), V3::y()),
        (2, 0.0, V3::y(), V3::x()),
    ];
    let mut key = std::collections::HashMap::new();
    for (axis, side, t1, t2) in frames {
        let mut idx = vec![vec![0usize; m + 1]; m + 1];
        for (i, row) in idx.iter_mut().enumerate() {
            for (j, id) in row.iter_mut().enumerate() {
                let mut u = t1 * (i as f64 / m as f64) + t2 * (j as f64 / m as f64);
                u[axis] = side;
                let k = [0, 1, 2].map(|d| (u[d] * m as f64).round() as i64);
                *id = *key.entry(k).or_insert_with(|| {
                    pos.push(u.component_mul(&a));
                    pos.len() - 1
                });
            }
        }
        for i in 0..m {
            for j in 0..m {
                let (p, q, r, s) = (idx[i][j], idx[i + 1][j], idx[i + 1][j + 1], idx[i][j + 1]);
                tris.push([p, q, r]);
                tris.push([p, r, s]);
            }
        }
    }
    TriMesh::new(pos, tris)
}

/// A lattice over a box of `cells` cells of edge `h` (m).
fn box_lattice(cells: [usize; 3], h: f64, m: usize) -> (TriMesh, Lattice) {
    let a = V3::new(cells[0] as f64, cells[1] as f64, cells[2] as f64) * h;
    let mesh = box_mesh(a, m);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(h),
            ..Default::default()
        },
    )
    .unwrap();
    (mesh, lat)
}

fn random_vec(rng: &mut Lcg) -> V3 {
    V3::new(
        rng.next_f64() - 0.5,
        rng.next_f64() - 0.5,
        rng.next_f64() - 0.5,
    )
}

#[test]
fn lattice_of_a_box_experiment() {
    let (mesh, lat) = box_lattice([2, 2, 2], 0.01, 4);
    println!(
        "{} verts, {} elements, {} nodes, origin {:?}, dims {:?}",
        mesh.vertex_count(),
        lat.elements.len(),
        lat.node_count(),
        lat.origin,
        lat.dims
    );
}

/// The active energy of two overlapping muscles (different fibres, one with a negative
/// activation) on a randomly deformed 2×2×2 block: gradient and Hessian against central
/// differences; the PSD-projected Hessian has no negative eigenvalue.
#[test]
fn active_energy_derivatives_match_finite_differences() {
    let (_, lat) = box_lattice([2, 2, 2], 0.01, 2);
    let interior = Interior::new(&lat, &Material::default()).unwrap();
    let ne = lat.elements.len();
    let mut m1 = Muscle::uniform("a", (0..ne).collect(), V3::new(1.0, 0.2, 0.0));
    m1.max_contraction = 0.3;
    let m2 = Muscle::uniform("b", (0..ne / 2).collect(), V3::new(0.0, 0.3, 1.0));
    let muscles = [m1, m2];
    let mut rng = Lcg::new(3);
    let mut x = lat.rest_flat();
    for v in x.iter_mut() {
        *v += 0.002 * (rng.next_f64() - 0.5);
    }
    let e = ActiveEnergy::new(&interior, &muscles, &[0.7, -0.4]);
    let g = check_gradient(&e, &x, 0.01);
    let h = check_hessian(&e, &x, 0.01);
    println!("gradient rel error {:.2e}, Hessian rel error {:.2e}", g.rel_error, h.rel_error);
    assert!(g.rel_error < 1e-7, "{g:?}");
    assert!(h.rel_error < 1e-7, "{h:?}");
    // Projected Hessian: PSD.
    let n = x.len();
    let mut trip = Vec::new();
    e.eval(&x, None, Some(&mut trip), true);
    let d = furrow::math::sparse::dense_from_triplets(n, &trip);
    let mat = nalgebra::DMatrix::from_row_slice(n, n, &d);
    let eig = nalgebra::SymmetricEigen::new(mat.clone());
    let max = eig.eigenvalues.amax();
    let min = eig.eigenvalues.min();
    println!("projected Hessian eigenvalues in [{min:.3e}, {max:.3e}]");
    assert!(min > -1e-10 * max, "{min} vs {max}");
}

/// E(R x + t) = E(x) and ∇E(R x + t) = R ∇E(x) for a rotation R and translation t.
#[test]
fn active_energy_is_invariant_under_rigid_motion() {
    let (_, lat) = box_lattice([2, 2, 2], 0.01, 2);
    let interior = Interior::new(&lat, &Material::default()).unwrap();
    let ne = lat.elements.len();
    let muscles = [Muscle::uniform("a", (0..ne).collect(), V3::new(0.3, 1.0, 0.5))];
    let mut rng = Lcg::new(5);
    let mut x = lat.rest_flat();
    for v in x.iter_mut() {
        *v += 0.003 * (rng.next_f64() - 0.5);
    }
    let r = Rotation3::from_axis_angle(&nalgebra::Unit::new_normalize(V3::new(1.0, 2.0, -0.5)), 1.1);
    let t = V3::new(0.3, -0.1, 0.05);
    let y: Vec<f64> = x
        .chunks_exact(3)
        .flat_map(|p| {
            let q = r * V3::new(p[0], p[1], p[2]) + t;
            [q.x, q.y, q.z]
        })
        .collect();
    let e = ActiveEnergy::new(&interior, &muscles, &[0.8]);
    let (mut gx, mut gy) = (vec![0.0; x.len()], vec![0.0; x.len()]);
    let ex = e.eval(&x, Some(&mut gx), None, false);
    let ey = e.eval(&y, Some(&mut gy), None, false);
    assert!(ex.abs() > 1e-9, "a deformed muscle stores energy: {ex}");
    assert!((ex - ey).abs() < 1e-12 * ex.abs().max(1e-12), "{ex} vs {ey}");
    let mut err: f64 = 0.0;
    let mut norm: f64 = 0.0;
    for (a, b) in gx.chunks_exact(3).zip(gy.chunks_exact(3)) {
        let ra = r * V3::new(a[0], a[1], a[2]);
        err = err.max((ra - V3::new(b[0], b[1], b[2])).norm());
        norm = norm.max(ra.norm());
    }
    assert!(err < 1e-10 * norm, "{err} vs {norm}");
}
