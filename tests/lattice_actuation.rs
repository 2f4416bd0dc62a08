//! The actuated interior (a muscle's change of the rest state, Phace-style): finite-difference
//! checks of its gradient, consistent Hessian and actuation force, rigid-motion invariance,
//! and the property the muscles rely on: a compatible actuation makes its shape at zero energy
//! whatever the stiffness.
#![allow(clippy::needless_range_loop)]

mod lattice_support;

use furrow::fem::Interior;
use furrow::lattice::{ElementOrder, Lattice};
use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::Energy;
use lattice_support::{noise, transform, two_cells};
use nalgebra::{Rotation3, Vector3};

type V = Vector3<f64>;

/// The actuation whose rest state is the lattice bent and squeezed by a smooth field of a few
/// per cent (a shape's rest change), and a random deformed state far from it.
fn actuated(lat: &Lattice, int: &mut Interior, amplitude: f64) -> (Vec<f64>, Vec<f64>) {
    let rest = lat.rest_flat();
    let shaped: Vec<f64> = rest
        .chunks(3)
        .flat_map(|p| {
            let (x, y, z) = (p[0], p[1], p[2]);
            [
                x - amplitude * x * y * 4.0,
                y + amplitude * (x * x * 3.0 - z),
                z * (1.0 - amplitude),
            ]
        })
        .collect();
    int.set_actuation(Vec::new()).unwrap();
    let d = int.local_displacements(&shaped);
    int.set_actuation(d).unwrap();
    let state: Vec<f64> = rest
        .iter()
        .enumerate()
        .map(|(i, x)| x + 0.02 * noise(i))
        .collect();
    (shaped, state)
}

#[test]
fn actuated_gradient_hessian_and_force_match_finite_differences() {
    for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
        let (lat, mut int) = two_cells(order, 1e5);
        let (_, q) = actuated(&lat, &mut int, 0.05);
        let rot = *Rotation3::from_euler_angles(0.7, -1.1, 2.0).matrix();
        for (name, x) in [
            ("random", q.clone()),
            ("rotated", transform(&q, &rot, V::new(0.3, -0.1, 0.2))),
        ] {
            let g = check_gradient(&int, &x, 0.1);
            let h = check_hessian(&int, &x, 0.1);
            println!(
                "{order:?} {name}: actuated gradient {:.2e}, Hessian {:.2e}",
                g.rel_error, h.rel_error
            );
            assert!(g.rel_error < 1e-7, "{order:?} {name}: {g:?}");
            assert!(h.rel_error < 1e-6, "{order:?} {name}: {h:?}");
            // The actuation force is −∂(∇E)/∂s for offsets d + s d₁ (d₁ on one element).
            let n3 = 3 * int.nodes_per_element();
            let d0 = int.actuation().to_vec();
            let d1: Vec<f64> = (0..n3).map(|i| 0.01 * noise(i + 7)).collect();
            let mut force = vec![0.0; x.len()];
            int.actuation_force(&x, &[1], &d1, &mut force);
            let s = 1e-6;
            let grad_at = |int: &mut Interior, sign: f64| {
                let mut d = d0.clone();
                for i in 0..n3 {
                    d[n3 + i] += sign * s * d1[i];
                }
                int.set_actuation(d).unwrap();
                let mut g = vec![0.0; x.len()];
                int.eval(&x, Some(&mut g), None, false);
                g
            };
            let (gp, gm) = (grad_at(&mut int, 1.0), grad_at(&mut int, -1.0));
            int.set_actuation(d0).unwrap();
            let num: Vec<f64> = gp
                .iter()
                .zip(&gm)
                .map(|(a, b)| -(a - b) / (2.0 * s))
                .collect();
            let err = num
                .iter()
                .zip(&force)
                .map(|(a, b)| (a - b).powi(2))
                .sum::<f64>()
                .sqrt()
                / force.iter().map(|v| v * v).sum::<f64>().sqrt();
            println!("{order:?} {name}: actuation force {err:.2e}");
            assert!(err < 1e-6, "{order:?} {name}: actuation force {err:.2e}");
        }
    }
}

/// E(R x + t) = E(x) and ∇E(R x + t) = R ∇E(x) with the rest state actuated.
#[test]
fn actuated_energy_is_invariant_under_rigid_motion() {
    let (lat, mut int) = two_cells(ElementOrder::Quadratic, 1e5);
    let (_, q) = actuated(&lat, &mut int, 0.05);
    let rot = *Rotation3::from_euler_angles(2.0, 0.4, -2.5).matrix();
    let moved = transform(&q, &rot, V::new(1.0, 2.0, 3.0));
    let mut g = vec![0.0; q.len()];
    let mut gm = vec![0.0; q.len()];
    let e = int.eval(&q, Some(&mut g), None, false);
    let em = int.eval(&moved, Some(&mut gm), None, false);
    assert!(e > 0.0);
    assert!((e - em).abs() < 1e-10 * e, "{e} vs {em}");
    let rotated = transform(&g, &rot, V::zeros());
    let err = rotated
        .iter()
        .zip(&gm)
        .map(|(a, b)| (a - b).abs())
        .fold(0.0, f64::max);
    let scale = g.iter().map(|v| v.abs()).fold(0.0, f64::max);
    assert!(err < 1e-9 * scale, "{err} of {scale}");
}

/// A compatible actuation (the local displacements of a deformed state) makes that state, and
/// any rigid motion of it, a zero-energy, zero-force equilibrium for any stiffness; at rest the
/// actuation force of that state is Σ_e K₀ d_e, the elastic force the shape change releases.
#[test]
fn a_compatible_actuation_makes_its_shape_whatever_the_stiffness() {
    for young in [1e3, 1e6] {
        let (lat, mut int) = two_cells(ElementOrder::Quadratic, young);
        let (shaped, _) = actuated(&lat, &mut int, 0.08);
        let rot = *Rotation3::from_euler_angles(0.3, 1.2, -0.4).matrix();
        for x in [
            shaped.clone(),
            transform(&shaped, &rot, V::new(0.1, 0.0, -2.0)),
        ] {
            let mut g = vec![0.0; x.len()];
            let e = int.eval(&x, Some(&mut g), None, false);
            let gmax = g.iter().map(|v| v.abs()).fold(0.0, f64::max);
            // Relative to the force the actuation releases at rest.
            let mut f0 = vec![0.0; x.len()];
            let all: Vec<usize> = (0..lat.elements.len()).collect();
            let d = int.actuation().to_vec();
            int.actuation_force(&lat.rest_flat(), &all, &d, &mut f0);
            let fmax = f0.iter().map(|v| v.abs()).fold(0.0, f64::max);
            println!("E = {young:.0e}: energy {e:.2e} J, force {gmax:.2e} of {fmax:.2e} N");
            assert!(
                e.abs() < 1e-20 * young && gmax < 1e-10 * fmax,
                "{e} {gmax} {fmax}"
            );
        }
    }
}
