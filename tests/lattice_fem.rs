//! Finite-difference checks of the corotated interior energy, rigid-motion invariance and the
//! uniform-strain patch test.
#![allow(clippy::needless_range_loop)]

mod lattice_support;

use furrow::lattice::{ElementOrder, Lattice};
use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::Energy;
use lattice_support::{transform, two_cells};
use nalgebra::{Matrix3, Rotation3, Vector3};

type V = Vector3<f64>;

fn noise(i: usize) -> f64 {
    let x = ((i as f64 + 1.0) * 78.233).sin() * 43758.5453;
    2.0 * (x - x.floor()) - 1.0
}

/// Deformed states: random, random + large rotation, and inverted (squashed through itself).
fn states(lat: &Lattice) -> Vec<(&'static str, Vec<f64>)> {
    let rest = lat.rest_flat();
    let rand: Vec<f64> = rest
        .iter()
        .enumerate()
        .map(|(i, x)| x + 0.02 * noise(i))
        .collect();
    let rot = *Rotation3::from_euler_angles(0.7, -1.1, 2.0).matrix();
    let rotated = transform(&rand, &rot, V::new(0.3, -0.1, 0.2));
    let squash = Matrix3::from_diagonal(&V::new(1.1, 0.9, -0.4));
    let inverted = transform(&rand, &(rot * squash), V::zeros());
    vec![
        ("random", rand),
        ("rotated", rotated),
        ("inverted", inverted),
    ]
}

#[test]
fn gradient_matches_finite_differences() {
    for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
        let (lat, int) = two_cells(order, 1.0e5);
        for (name, q) in states(&lat) {
            let min_det = (0..lat.elements.len())
                .flat_map(|e| int.deformation_gradients(&q, e))
                .map(|f| f.determinant())
                .fold(f64::INFINITY, f64::min);
            assert_eq!(
                name == "inverted",
                min_det < 0.0,
                "{name}: min det F {min_det}"
            );
            let r = check_gradient(&int, &q, 0.1);
            println!(
                "{order:?} {name}: gradient rel error {:.2e} (step {:.0e})",
                r.rel_error, r.step
            );
            assert!(r.rel_error < 1e-7, "{order:?} {name}: {r:?}");
        }
    }
}

/// The emitted Hessian is the exact Hessian of the energy with each element's rotation frozen
/// (the corotational stiffness R K₀ Rᵀ); finite differences of that energy's gradient check it.
#[test]
fn hessian_matches_finite_differences_of_the_frozen_rotation_energy() {
    for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
        let (lat, int) = two_cells(order, 1.0e5);
        for (name, q) in states(&lat) {
            let frozen = int.frozen_at(&q);
            let g = check_gradient(&frozen, &q, 0.1);
            let h = check_hessian(&frozen, &q, 0.1);
            println!(
                "{order:?} {name}: frozen gradient {:.2e}, Hessian {:.2e}",
                g.rel_error, h.rel_error
            );
            assert!(
                g.rel_error < 1e-7 && h.rel_error < 1e-7,
                "{order:?} {name}: {g:?} {h:?}"
            );
            // Frozen at the element rotations of q, the frozen energy equals the true one at
            // q (the true one differs only through the rotation's dependence on q).
            let (e_true, e_frozen) = (
                int.eval(&q, None, None, false),
                frozen.eval(&q, None, None, false),
            );
            assert!(
                (e_true - e_frozen).abs() <= 1e-12 * e_true.abs(),
                "{name}: {e_true} vs {e_frozen}"
            );
            // The projected consistent tangent is symmetric positive semi-definite.
            let mut t = Vec::new();
            int.eval(&q, None, Some(&mut t), true);
            let n = int.dofs();
            let d = furrow::math::sparse::dense_from_triplets(n, &t);
            let m = nalgebra::DMatrix::from_row_slice(n, n, &d);
            assert!((&m - m.transpose()).amax() < 1e-9 * m.amax());
            let ev = m.symmetric_eigen().eigenvalues;
            assert!(
                ev.min() > -1e-9 * ev.max(),
                "{name}: min eigenvalue {}",
                ev.min()
            );
        }
    }
}

/// The consistent tangent (the rotation's derivative included) is the exact Hessian of the
/// corotational energy: finite differences of its exact gradient check it, including under
/// large rotation and in an inverted element.
#[test]
fn consistent_tangent_matches_finite_differences() {
    for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
        let (lat, int) = two_cells(order, 1.0e5);
        for (name, q) in states(&lat) {
            let h = check_hessian(&int, &q, 0.1);
            println!("{order:?} {name}: consistent Hessian {:.2e}", h.rel_error);
            assert!(h.rel_error < 1e-6, "{order:?} {name}: {h:?}");
        }
    }
}

/// Rigid motions store no energy and produce no force; a uniform stretch F = diag(1+ε, 1, 1)
/// stores exactly V (μ + λ/2) ε² (B-splines reproduce linear maps).
#[test]
fn rigid_motion_is_free_and_uniform_stretch_matches_closed_form() {
    let (lat, int) = two_cells(ElementOrder::Quadratic, 1.0e5);
    let rest = lat.rest_flat();
    let rot = *Rotation3::from_euler_angles(2.0, 0.4, -2.5).matrix();
    let q = transform(&rest, &rot, V::new(1.0, 2.0, 3.0));
    let mut g = vec![0.0; q.len()];
    let e = int.eval(&q, Some(&mut g), None, false);
    assert!(e.abs() < 1e-18, "rigid energy {e}");
    assert!(g.iter().all(|x| x.abs() < 1e-9), "rigid force");
    let eps = 0.01;
    let q = transform(
        &rest,
        &Matrix3::from_diagonal(&V::new(1.0 + eps, 1.0, 1.0)),
        V::zeros(),
    );
    let e = int.eval(&q, None, None, false);
    let vol = 0.2 * 0.1 * 0.1;
    let exact = vol * (int.mu + 0.5 * int.lambda) * eps * eps;
    assert!((e - exact).abs() < 1e-12 * exact, "{e} vs {exact}");
    // Mass: total = ρ V, gravity force = m g.
    assert!((int.total_mass() - 1000.0 * vol).abs() < 1e-12);
}
