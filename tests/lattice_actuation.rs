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

/// Two actuation muscles on every element of `int`, made from whole-lattice rest changes as
/// generated muscles are: a bend and squeeze, and a turn about x that grows along y (up to a
/// third of a radian across a cell) with a squeeze along x. Returns them and their changes.
fn two_muscles(lat: &Lattice, int: &Interior) -> (Vec<furrow::muscle::Muscle>, [Vec<f64>; 2]) {
    let rest = lat.rest_flat();
    let bend: Vec<f64> = rest
        .chunks(3)
        .flat_map(|p| {
            let (x, y, z) = (p[0], p[1], p[2]);
            [-0.08 * x * y * 4.0, 0.08 * (x * x * 3.0 - z), -0.08 * z]
        })
        .collect();
    let turn: Vec<f64> = rest
        .chunks(3)
        .flat_map(|p| {
            let (s, c) = (8.0 * p[1]).sin_cos();
            [
                -0.05 * p[0],
                p[1] * c - p[2] * s - p[1],
                p[1] * s + p[2] * c - p[2],
            ]
        })
        .collect();
    let all: Vec<usize> = (0..int.elements.len()).collect();
    let muscle = |name: &str, change: &[f64]| {
        let x: Vec<f64> = rest.iter().zip(change).map(|(a, b)| a + b).collect();
        let mut m =
            furrow::muscle::actuation::actuation_muscle(name, &all, &int.local_displacements(&x));
        m.rest_change = change
            .chunks(3)
            .enumerate()
            .map(|(n, s)| (n, [s[0], s[1], s[2]]))
            .collect();
        m
    };
    (
        vec![muscle("bend", &bend), muscle("turn", &turn)],
        [bend, turn],
    )
}

/// Muscles combine as their rest changes add: at a = e_m the blend is muscle m's own offsets,
/// and at any activations the lattice moved by Σ a_m s_m is a zero-energy, zero-force state
/// whatever the stiffness (the blended shape is made exactly, as the rig blends it). Adding
/// the offsets instead, Σ a_m d_m, leaves that state stressed: each element's turn is taken
/// out before blending, so what a shape turns keeps its full size at partial activation.
#[test]
fn muscles_combine_as_their_rest_changes_add() {
    use furrow::muscle::blend::ActuationBlend;
    for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
        let (lat, mut int) = two_cells(order, 1e5);
        let (muscles, [bend, turn]) = two_muscles(&lat, &int);
        let rest = lat.rest_flat();
        let blend = ActuationBlend::new(&int, &muscles, &rest);
        for (m, a) in [(0, [1.0, 0.0]), (1, [0.0, 1.0])] {
            let d = blend.field(&int, &muscles, &a);
            let own = &muscles[m].actuation;
            let err = d
                .iter()
                .zip(own)
                .map(|(x, y)| (x - y).abs())
                .fold(0.0, f64::max);
            assert!(err < 1e-12, "{order:?} muscle {m}: {err:.1e}");
        }
        let a = [0.3, 0.6];
        let x: Vec<f64> = (0..rest.len())
            .map(|i| rest[i] + a[0] * bend[i] + a[1] * turn[i])
            .collect();
        let force_at = |int: &mut Interior, d: Vec<f64>| {
            int.set_actuation(d).unwrap();
            let mut g = vec![0.0; x.len()];
            let e = int.eval(&x, Some(&mut g), None, false);
            (e, g.iter().map(|v| v.abs()).fold(0.0, f64::max))
        };
        let blended = blend.field(&int, &muscles, &a);
        let (e, g) = force_at(&mut int, blended);
        let n = muscles[0].actuation.len();
        let summed: Vec<f64> = (0..n)
            .map(|i| a[0] * muscles[0].actuation[i] + a[1] * muscles[1].actuation[i])
            .collect();
        let (e_sum, g_sum) = force_at(&mut int, summed);
        println!("{order:?}: blended shape {e:.1e} J, {g:.1e} N; offsets summed {e_sum:.1e} J, {g_sum:.1e} N");
        assert!(
            e.abs() < 1e-12 * e_sum && g < 1e-9 * g_sum,
            "{e} {g} / {e_sum} {g_sum}"
        );
        assert!(e_sum > 0.0);
    }
}

/// A muscle's unit actuation at activations a, ∂d/∂a_m ([`ActuationBlend::tangents`]: the
/// derivative of the elements' local displacements, rotation included), matches central
/// differences of the blended offsets, and so does the force it makes, −∂∇E/∂a_m
/// ([`furrow::muscle::unit_forces`]), against differences of the actuated interior's gradient.
#[test]
fn blend_tangent_and_unit_force_match_finite_differences() {
    use furrow::muscle::blend::ActuationBlend;
    use furrow::muscle::unit_forces;
    let (lat, mut int) = two_cells(ElementOrder::Quadratic, 1e5);
    let (muscles, _) = two_muscles(&lat, &int);
    let rest = lat.rest_flat();
    let blend = ActuationBlend::new(&int, &muscles, &rest);
    let n3 = 3 * int.nodes_per_element();
    let a = [0.4, 0.7];
    let x: Vec<f64> = rest
        .iter()
        .enumerate()
        .map(|(i, r)| r + 0.01 * noise(i + 3))
        .collect();
    int.set_actuation(blend.field(&int, &muscles, &a)).unwrap();
    let forces = unit_forces(&int, &muscles, &blend, &a, &x);
    let h = 1e-6;
    let rel = |x: &[f64], y: &[f64]| {
        x.iter()
            .zip(y)
            .map(|(p, q)| (p - q).powi(2))
            .sum::<f64>()
            .sqrt()
            / y.iter().map(|v| v * v).sum::<f64>().sqrt()
    };
    let tangents = blend.tangents(&int, &muscles, &a);
    for (m, (elements, rates)) in tangents.iter().enumerate() {
        let (mut ap, mut am) = (a, a);
        ap[m] += h;
        am[m] -= h;
        let (dp, dm) = (
            blend.field(&int, &muscles, &ap),
            blend.field(&int, &muscles, &am),
        );
        let fd: Vec<f64> = elements
            .iter()
            .flat_map(|&e| (e * n3..(e + 1) * n3).map(|i| (dp[i] - dm[i]) / (2.0 * h)))
            .collect();
        let err = rel(rates, &fd);
        let grad_at = |int: &mut Interior, d: Vec<f64>| {
            int.set_actuation(d).unwrap();
            let mut g = vec![0.0; x.len()];
            int.eval(&x, Some(&mut g), None, false);
            g
        };
        let (gp, gm) = (grad_at(&mut int, dp), grad_at(&mut int, dm));
        let force_fd: Vec<f64> = gp
            .iter()
            .zip(&gm)
            .map(|(p, q)| -(p - q) / (2.0 * h))
            .collect();
        let force_err = rel(&forces[m], &force_fd);
        println!(
            "muscle {m}: tangent {err:.1e}, unit force {force_err:.1e} from central differences"
        );
        assert!(err < 1e-7, "muscle {m}: tangent {err:.1e}");
        assert!(force_err < 1e-6, "muscle {m}: unit force {force_err:.1e}");
        assert_eq!(elements.len(), int.elements.len());
    }
}
