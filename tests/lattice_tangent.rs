//! The interior's consistent tangent: Newton on a twisted bar converges quadratically with
//! it and only linearly with the frozen-rotation stiffness.
//!
//! A bar of 2 × 2 × 6 quadratic cells (2 cm, soft tissue) along z, its two bottom control
//! point layers pinned at rest and its two top layers pinned after a 90° twist about the
//! bar's axis; the free nodes start at rest and one quasi-static solve finds the twisted
//! equilibrium (large rotations, moderate strain). The residual after k Newton iterations is
//! read from solves limited to k iterations from the same start.

mod lattice_support;

use furrow::fem::{BackwardEuler, Interior, Material, SolveStatus, StepSettings, Tangent};
use furrow::lattice::{ElementOrder, Lattice, LatticeSettings};
use lattice_support::box_mesh;
use nalgebra::{Rotation3, Vector3};

type V = Vector3<f64>;

/// The bar's stepper at its twisted start, Newton limited to `iterations`.
fn twisted_bar(tangent: Tangent, iterations: usize) -> BackwardEuler {
    let h = 0.02;
    let (w, l) = (2.0 * h, 6.0 * h);
    let mesh = box_mesh(V::zeros(), V::new(w, w, l), 6);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(h),
            order: ElementOrder::Quadratic,
            ..Default::default()
        },
    )
    .unwrap();
    let int = Interior::new(&lat, &Material::default()).unwrap();
    let (zmin, zmax) = lat
        .rest
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), p| {
            (a.min(p.z), b.max(p.z))
        });
    let axis = V::new(w / 2.0, w / 2.0, 0.0);
    let twist = Rotation3::from_axis_angle(&V::z_axis(), std::f64::consts::FRAC_PI_2);
    let mut q = lat.rest_flat();
    let mut pinned = vec![false; lat.node_count()];
    for (n, p) in lat.rest.iter().enumerate() {
        if p.z < zmin + 1.5 * h {
            pinned[n] = true;
        } else if p.z > zmax - 1.5 * h {
            pinned[n] = true;
            let r = axis + twist * (p - axis);
            q[3 * n..3 * n + 3].copy_from_slice(&[r.x, r.y, p.z]);
        }
    }
    let settings = StepSettings {
        max_newton: iterations,
        tolerance: 1e-13,
        gravity: [0.0; 3],
        tangent,
        ..StepSettings::default()
    };
    BackwardEuler::new(int, q, pinned, settings).unwrap()
}

/// Residual (N) after each of the first `n` Newton iterations.
fn residuals(tangent: Tangent, n: usize) -> Vec<f64> {
    (1..=n)
        .map(|k| {
            let mut be = twisted_bar(tangent, k);
            let zero = vec![0.0; be.q.len()];
            be.quasi_static(&zero, None).unwrap().residual
        })
        .collect()
}

#[test]
fn newton_on_a_twisted_bar_converges_quadratically_with_the_consistent_tangent() {
    let cons = residuals(Tangent::Consistent, 25);
    let frozen = residuals(Tangent::Frozen, 25);
    let sci = |r: &[f64]| {
        r.iter()
            .map(|v| format!("{v:.2e}"))
            .collect::<Vec<_>>()
            .join(" ")
    };
    println!("consistent: {}\nfrozen:     {}", sci(&cons), sci(&frozen));
    // The residual's exponent in the asymptotic phase: with ρ_k = r_k / r_0,
    // log ρ_{k+1} / log ρ_k is 2 for quadratic convergence and near 1 for linear.
    let exponents = |r: &[f64]| -> Vec<f64> {
        r.windows(2)
            .map(|w| (w[0] / r[0], w[1] / r[0]))
            .filter(|&(a, _)| a < 1e-3 && a > 1e-12)
            .map(|(a, b)| b.ln() / a.ln())
            .collect()
    };
    let (ec, ef) = (exponents(&cons), exponents(&frozen));
    println!("exponents: consistent {ec:.2?}, frozen {ef:.2?}");
    let best = ec.iter().cloned().fold(0.0, f64::max);
    assert!(best > 1.8, "no quadratic phase: exponents {ec:?}");
    assert!(ef.iter().all(|&e| e < 1.3), "frozen is linear: {ef:?}");
    let reach = |r: &[f64]| r.iter().position(|&v| v < 1e-10 * r[0]);
    let (rc, rf) = (reach(&cons), reach(&frozen));
    println!("iterations to 1e-10 r0: consistent {rc:?}, frozen {rf:?}");
    assert!(rc.is_some_and(|k| k < 12), "consistent: {cons:?}");
    assert!(
        rf.is_none(),
        "frozen reached 1e-10 within 25 iterations: {frozen:?}"
    );
    // The solve converges to the tolerance asked, the same state both ways.
    let mut a = twisted_bar(Tangent::Consistent, 40);
    let mut b = twisted_bar(Tangent::Frozen, 200);
    let zero = vec![0.0; a.q.len()];
    let ra = a.quasi_static(&zero, None).unwrap();
    let rb = b.quasi_static(&zero, None).unwrap();
    println!("consistent {ra:?}\nfrozen {rb:?}");
    assert_eq!(ra.status, SolveStatus::Converged);
    let diff =
        a.q.iter()
            .zip(&b.q)
            .fold(0.0f64, |m, (x, y)| m.max((x - y).abs()));
    assert!(diff < 1e-8, "states differ by {diff} m");
}
