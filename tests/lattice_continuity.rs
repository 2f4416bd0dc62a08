//! Continuity of the lattice map across a shared cell face, measured numerically: quadratic
//! B-spline elements are C¹ (one-sided slopes agree as the step shrinks), trilinear elements
//! are only C⁰ (a kink: the slopes differ by O(1)).
#![allow(clippy::needless_range_loop)]

mod lattice_support;

use furrow::lattice::{ElementOrder, Lattice, LatticeSettings, MaterialPoint};
use lattice_support::{box_mesh, noise};
use nalgebra::Vector3;

type V = Vector3<f64>;

/// Largest value and slope jumps across the face x = 0.1 between the two elements, for
/// a random control-point perturbation of 20 % of a cell, at one-sided step `d` (local units).
fn jumps(order: ElementOrder, d: f64) -> (f64, f64) {
    let mesh = box_mesh(V::zeros(), V::new(0.2, 0.1, 0.1), 2);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(0.1),
            order,
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(lat.elements.len(), 2);
    let (left, right) = if lat.elements[0].cell[0] == 0 {
        (0, 1)
    } else {
        (1, 0)
    };
    let q: Vec<f64> = lat
        .rest_flat()
        .iter()
        .enumerate()
        .map(|(i, x)| x + 0.02 * noise(i))
        .collect();
    let mut value_jump: f64 = 0.0;
    let mut slope_jump: f64 = 0.0;
    for s in 0..25 {
        let (eta, zeta) = (
            0.1 + 0.8 * (s % 5) as f64 / 4.0,
            0.1 + 0.8 * (s / 5) as f64 / 4.0,
        );
        let at = |e: usize, xi: f64| {
            lat.position(
                &q,
                &MaterialPoint {
                    element: e,
                    xi: [xi, eta, zeta],
                },
            )
        };
        let (l0, r0) = (at(left, 1.0), at(right, 0.0));
        value_jump = value_jump.max((l0 - r0).norm());
        let sl = (l0 - at(left, 1.0 - d)) / d;
        let sr = (at(right, d) - r0) / d;
        slope_jump = slope_jump.max((sl - sr).norm());
    }
    (value_jump, slope_jump)
}

#[test]
fn quadratic_is_c1_and_trilinear_has_a_kink() {
    for d in [1e-2, 1e-3, 1e-4] {
        let (v, s) = jumps(ElementOrder::Quadratic, d);
        // C⁰: exact up to round-off; C¹: the one-sided difference slopes differ by O(d)
        // (second derivative × d), so the jump shrinks with d.
        assert!(v < 1e-15, "quadratic value jump {v}");
        assert!(s < 0.5 * d, "quadratic slope jump {s} at step {d}");
        let (vt, st) = jumps(ElementOrder::Trilinear, d);
        assert!(vt < 1e-15, "trilinear value jump {vt}");
        // The kink does not shrink with the step: O(perturbation) = O(0.02 m per cell).
        assert!(st > 1e-3, "trilinear slope jump {st} at step {d}");
        println!("d = {d:e}: quadratic slope jump {s:.3e}, trilinear {st:.3e}");
    }
}
