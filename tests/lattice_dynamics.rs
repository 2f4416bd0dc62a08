//! Backward Euler dynamics: free fall, recovery from inversion, superimposed-element
//! independence, one body moving as one, and the lips of a slit sheet.
#![allow(clippy::needless_range_loop)]

mod lattice_support;

use furrow::fem::{BackwardEuler, ExtraTerms, Interior, Material, SolveStatus, StepSettings};
use furrow::lattice::{Lattice, LatticeSettings};
use lattice_support::{box_mesh, merge, slit_sheet};
use nalgebra::Vector3;

type V = Vector3<f64>;

fn soft() -> Material {
    Material {
        young: 1.0e4,
        poisson: 0.3,
        density: 1000.0,
    }
}

fn no_gravity() -> StepSettings {
    StepSettings {
        gravity: [0.0; 3],
        ..Default::default()
    }
}

/// Surface force f on vertex v enters the nodes as Bᵀ f.
fn vertex_force(lat: &Lattice, v: usize, f: V) -> Vec<f64> {
    let mut out = vec![0.0; 3 * lat.node_count()];
    for (n, w) in lat.weights(&lat.vertex_points[v]) {
        for i in 0..3 {
            out[3 * n + i] += w * f[i];
        }
    }
    out
}

/// A 0.2 m block meshed 4 × 4 per face in a lattice of 0.1 m cells.
fn block_lattice() -> Lattice {
    let mesh = box_mesh(V::zeros(), V::repeat(0.2), 4);
    Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(0.1),
            ..Default::default()
        },
    )
    .unwrap()
}

/// An unpinned block under gravity follows the discrete backward Euler free fall exactly,
/// y_k = −g h² k(k+1)/2, which is g t²/2 + g h t/2: O(h) from the continuous answer.
#[test]
fn free_fall_is_exact_backward_euler() {
    let lat = block_lattice();
    for lumped in [false, true] {
        let int = Interior::new(&lat, &soft()).unwrap();
        let settings = StepSettings {
            lumped_mass: lumped,
            ..Default::default()
        };
        let mut be = BackwardEuler::new(
            int,
            lat.rest_flat(),
            vec![false; lat.node_count()],
            settings,
        )
        .unwrap();
        let zero = vec![0.0; be.q.len()];
        let (g, h) = (9.81, settings.dt);
        for k in 1..=25 {
            let rep = be.step(&zero, None).unwrap();
            assert_eq!(rep.status, SolveStatus::Converged);
            let discrete = -g * h * h * (k * (k + 1)) as f64 / 2.0;
            let t = k as f64 * h;
            for (i, (y, y0)) in be.q.iter().zip(lat.rest_flat()).enumerate() {
                let d = y - y0;
                if i % 3 == 1 {
                    assert!(
                        (d - discrete).abs() < 1e-10 * discrete.abs(),
                        "k {k}: {d} vs {discrete}"
                    );
                    // Against g t²/2 the error is g h t / 2 (first order in h).
                    assert!((d + 0.5 * g * t * t).abs() <= 0.5 * g * h * t * (1.0 + 1e-9));
                } else {
                    assert!(d.abs() < 1e-12);
                }
            }
        }
    }
}

/// A block squashed through itself (z → −0.3 z about its middle) and released recovers its
/// rest shape up to a rigid motion, without NaN, under backward Euler.
#[test]
fn inverted_block_recovers() {
    let lat = block_lattice();
    let int = Interior::new(&lat, &soft()).unwrap();
    let q0: Vec<f64> = lat
        .rest
        .iter()
        .flat_map(|p| [p.x, p.y, 0.1 - 0.3 * (p.z - 0.1)])
        .collect();
    let min_det = |be: &BackwardEuler| {
        (0..lat.elements.len())
            .flat_map(|e| be.interior.deformation_gradients(&be.q, e))
            .map(|f| f.determinant())
            .fold(f64::INFINITY, f64::min)
    };
    let mut be = BackwardEuler::new(int, q0, vec![false; lat.node_count()], no_gravity()).unwrap();
    assert!(min_det(&be) < 0.0);
    let zero = vec![0.0; be.q.len()];
    let mut worst = 0usize;
    let mut unconverged = 0;
    for _ in 0..100 {
        let rep = be.step(&zero, None).unwrap();
        worst = worst.max(rep.iterations);
        unconverged += usize::from(rep.status != SolveStatus::Converged);
        assert!(be.q.iter().all(|x| x.is_finite()), "NaN in state");
    }
    let mut strain: f64 = 0.0;
    for e in 0..lat.elements.len() {
        for f in be.interior.deformation_gradients(&be.q, e) {
            strain = strain.max((f.transpose() * f - nalgebra::Matrix3::identity()).norm());
        }
    }
    println!("after 2 s: min det F {:.4}, max |FᵀF − I| {strain:.2e}, max Newton iterations {worst}, steps not converged {unconverged}", min_det(&be));
    assert!(min_det(&be) > 0.9);
    assert!(strain < 1e-2, "{strain}");
}

/// A step taken again from where the same step ended (a later coupling pass) reaches the
/// same positions and velocities, in fewer Newton iterations than from the inertial
/// predictor; a start of the wrong length is refused.
#[test]
fn a_step_started_at_its_own_end_gives_the_same_answer_sooner() {
    let lat = block_lattice();
    let q0: Vec<f64> = lat
        .rest
        .iter()
        .flat_map(|p| [p.x, p.y, 0.1 - 0.5 * (p.z - 0.1)])
        .collect();
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.0).collect();
    let stepper = || {
        let int = Interior::new(&lat, &soft()).unwrap();
        BackwardEuler::new(int, q0.clone(), pinned.clone(), no_gravity()).unwrap()
    };
    let zero = vec![0.0; q0.len()];
    let mut cold = stepper();
    let from_predictor = cold.step(&zero, None).unwrap();
    assert_eq!(from_predictor.status, SolveStatus::Converged);
    let mut warm = stepper();
    let from_end = warm.step_from(&zero, None, Some(&cold.q)).unwrap();
    assert_eq!(from_end.status, SolveStatus::Converged);
    println!(
        "Newton iterations: {} from the predictor, {} from the step's end",
        from_predictor.iterations, from_end.iterations
    );
    assert!(from_end.iterations < from_predictor.iterations);
    let scale = q0.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (a, b) in warm.q.iter().zip(&cold.q) {
        assert!((a - b).abs() < 1e-7 * scale, "{a} vs {b}");
    }
    for (a, b) in warm.v.iter().zip(&cold.v) {
        assert!((a - b).abs() < 1e-7 * scale / warm.settings.dt);
    }
    assert!(warm.step_from(&zero, None, Some(&zero[1..])).is_err());
}

/// A coupling stiffness given with a layout key ([`ExtraTerms::layout`]) steps exactly as
/// one the step hashes, over several steps whose stiffness values change under the same
/// key (the matrix layout is placed once); a new key still has its triplets checked, so an
/// index out of range is refused.
#[test]
fn a_coupling_stiffness_keyed_by_its_layout_steps_as_the_hashed_one() {
    let lat = block_lattice();
    let n = 3 * lat.rest.len();
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.0).collect();
    // A spring network between neighbouring dofs, both triangles, and a pull.
    let spring = |k: f64| -> Vec<(usize, usize, f64)> {
        (0..n - 3)
            .flat_map(|i| [(i, i, k), (i + 3, i + 3, k), (i, i + 3, -k), (i + 3, i, -k)])
            .collect()
    };
    let force: Vec<f64> = (0..n)
        .map(|i| if i % 3 == 2 { -0.05 } else { 0.0 })
        .collect();
    let stepper = || {
        let int = Interior::new(&lat, &soft()).unwrap();
        BackwardEuler::new(int, lat.rest_flat(), pinned.clone(), no_gravity()).unwrap()
    };
    let zero = vec![0.0; n];
    let (mut hashed, mut keyed) = (stepper(), stepper());
    let key = furrow::fem::triplet_layout_key(&spring(1.0));
    for step in 0..4 {
        let k = spring(10.0 * (1.0 + step as f64));
        let a = hashed
            .step(&zero, Some(&ExtraTerms::new(&k, &force)))
            .unwrap();
        let keyed_terms = ExtraTerms {
            layout: Some(key),
            ..ExtraTerms::new(&k, &force)
        };
        let b = keyed.step(&zero, Some(&keyed_terms)).unwrap();
        assert_eq!(a.status, SolveStatus::Converged);
        assert_eq!(a.iterations, b.iterations);
        assert_eq!(hashed.q, keyed.q, "step {step}");
        assert_eq!(hashed.v, keyed.v);
    }
    let mut bad = spring(1.0);
    bad.push((n, 0, 1.0));
    let refused = keyed.step(
        &zero,
        Some(&ExtraTerms {
            layout: Some(key ^ 1),
            ..ExtraTerms::new(&bad, &force)
        }),
    );
    assert!(refused.is_err());
}

/// The linear response of backward Euler steps to a constant extra force is the steps'
/// own change to first order: one and two steps of a block pulled sideways against springs
/// anchored at rest, taken again with a small extra force, move by what `linear_response`
/// predicts from the last Newton factor (within 1e-3 of the change; the corotational block
/// is nearly linear there); without a factor (no step yet) there is none.
#[test]
fn the_linear_response_of_steps_is_their_change_under_a_small_extra_force() {
    let lat = block_lattice();
    let n = 3 * lat.rest.len();
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.0).collect();
    let stepper = || {
        let int = Interior::new(&lat, &soft()).unwrap();
        BackwardEuler::new(int, lat.rest_flat(), pinned.clone(), no_gravity()).unwrap()
    };
    assert!(stepper().linear_response(&vec![0.0; n], 1).is_none());
    let pull: Vec<f64> = (0..n)
        .map(|i| if i % 3 == 0 { 0.02 } else { 0.0 })
        .collect();
    let df: Vec<f64> = (0..n)
        .map(|i| 1e-4 * (((i * 7919) % 13) as f64 - 6.0))
        .collect();
    let stiffness: Vec<(usize, usize, f64)> = (0..n).map(|i| (i, i, 0.5)).collect();
    for steps in [1, 2] {
        let (mut base, mut pushed) = (stepper(), stepper());
        let pulled: Vec<f64> = pull.iter().zip(&df).map(|(a, b)| a + b).collect();
        // ExtraTerms' stiffness is about each step's start: its force carries the springs
        // to their fixed anchors at rest, as the pipeline carries the skin's.
        let rest = lat.rest_flat();
        let anchored = |be: &BackwardEuler| -> Vec<f64> {
            be.q.iter()
                .zip(&rest)
                .map(|(q, r)| -0.5 * (q - r))
                .collect()
        };
        for _ in 0..steps {
            let f = anchored(&base);
            base.step(&pull, Some(&ExtraTerms::new(&stiffness, &f)))
                .unwrap();
            let f = anchored(&pushed);
            pushed
                .step(&pulled, Some(&ExtraTerms::new(&stiffness, &f)))
                .unwrap();
        }
        let (dy, dv) = base.linear_response(&df, steps).unwrap();
        let change: Vec<f64> = pushed.q.iter().zip(&base.q).map(|(a, b)| a - b).collect();
        let dvel: Vec<f64> = pushed.v.iter().zip(&base.v).map(|(a, b)| a - b).collect();
        let size = change.iter().map(|c| c * c).sum::<f64>().sqrt();
        let off = change
            .iter()
            .zip(&dy)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        let vsize = dvel.iter().map(|c| c * c).sum::<f64>().sqrt();
        let voff = dvel
            .iter()
            .zip(&dv)
            .map(|(a, b)| (a - b).powi(2))
            .sum::<f64>()
            .sqrt();
        println!("{steps} steps: change {size:.3e} m, off by {off:.3e}; velocity off {voff:.3e} of {vsize:.3e}");
        assert!(size > 0.0 && off < 1e-3 * size, "{off} of {size}");
        // The velocity change is a difference of positions over h: 1e-2 of it.
        assert!(voff < 1e-2 * vsize, "{voff} of {vsize}");
    }
}

/// Two boxes in shared cells: pushing one leaves the other exactly still; the pushed one
/// gains exactly the impulse (momentum Σ M v = k h F, internal forces sum to zero).
#[test]
fn superimposed_bodies_are_independent_and_one_body_moves_as_one() {
    let a = box_mesh(V::new(0.0, 0.0, 0.0), V::new(0.25, 0.2, 0.2), 5);
    let b = box_mesh(V::new(0.26, 0.0, 0.0), V::new(0.5, 0.2, 0.2), 5);
    let mesh = merge(&a, &b);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(0.1),
            ..Default::default()
        },
    )
    .unwrap();
    let int = Interior::new(&lat, &soft()).unwrap();
    let masses = int.node_masses();
    let mut be = BackwardEuler::new(
        int,
        lat.rest_flat(),
        vec![false; lat.node_count()],
        no_gravity(),
    )
    .unwrap();
    // Push the corner vertex of body b nearest to body a, along −x (toward a).
    let vb = (a.positions.len()..mesh.positions.len())
        .min_by(|&i, &j| {
            mesh.positions[i]
                .norm()
                .total_cmp(&mesh.positions[j].norm())
        })
        .unwrap();
    let force = V::new(-0.5, 0.2, 0.0);
    let f = vertex_force(&lat, vb, force);
    let steps = 10;
    for _ in 0..steps {
        let rep = be.step(&f, None).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
    }
    let rest = lat.rest_flat();
    let moved = lat.embed(&be.q);
    let disp = |v: usize| (moved[v] - mesh.positions[v]).norm();
    let max_a = (0..a.positions.len()).map(disp).fold(0.0, f64::max);
    let min_b = (a.positions.len()..mesh.positions.len())
        .map(disp)
        .fold(f64::INFINITY, f64::min);
    println!("body a max displacement {max_a:e} m, body b min displacement {min_b:e} m");
    // Round-off only (the bodies share no node; F at rest is I to ~1e-16).
    assert!(max_a < 1e-12 * min_b, "the untouched body moved {max_a}");
    assert!(min_b > 1e-4, "every vertex of the pushed body moves");
    // Momentum of the pushed body (lumped masses: Σ m v equals Σ M v for consistent M).
    let mut p = V::zeros();
    for (n, m) in masses.iter().enumerate() {
        p += V::new(be.v[3 * n], be.v[3 * n + 1], be.v[3 * n + 2]) * *m;
    }
    let want = force * (steps as f64 * be.settings.dt);
    assert!(
        (p - want).norm() < 1e-8 * want.norm(),
        "momentum {p} vs {want}"
    );
    assert!(be.q.iter().zip(&rest).all(|(x, r)| (x - r).is_finite()));
}

/// Push the lower-lip vertex at the middle of the slit into the face for 10 steps; return
/// (pushed vertex displacement, displacement of the vertex 5 mm above it), m.
fn push_lower_lip(half_slit: f64) -> (f64, f64) {
    let (mesh, _upper, _lower) = slit_sheet(0.07, 0.005, half_slit);
    let s = LatticeSettings {
        cell_size: Some(0.0125),
        depth: Some(0.02),
        ..Default::default()
    };
    let lat = Lattice::build(&mesh, &s).unwrap();
    let int = Interior::new(&lat, &soft()).unwrap();
    let mut be =
        BackwardEuler::new(int, lat.rest_flat(), lat.pinned.clone(), no_gravity()).unwrap();
    // The pushed vertex: on y = 0 at x = 0, on the lower side (the last duplicate when slit).
    let at = |p: V| {
        (0..mesh.positions.len())
            .filter(|&v| (mesh.positions[v] - p).norm() < 1e-9)
            .max()
            .unwrap()
    };
    let pushed = at(V::zeros());
    let above = at(V::new(0.0, 0.005, 0.0));
    let f = vertex_force(&lat, pushed, V::new(0.0, 0.0, -0.05));
    for _ in 0..10 {
        be.step(&f, None).unwrap();
    }
    let moved = lat.embed(&be.q);
    let d = |v: usize| (moved[v] - mesh.positions[v]).norm();
    (d(pushed), d(above))
}

/// The slit sheet: pushing the middle of the lower lip into the face leaves the upper lip
/// nearly still, while on a sheet without the slit the same push drags the skin above along.
/// The lips are one surface around the mouth corners and the corner elements share nodes
/// with both lips up to two cells away (quadratic support), so the coupling through the
/// corners' flesh is small but not exactly zero.
#[test]
fn pushing_the_lower_lip_leaves_the_upper_lip_still() {
    let (dl, du) = push_lower_lip(0.045);
    let (dl0, du0) = push_lower_lip(0.0);
    println!("slit: pushed {dl:.3e} m, 5 mm above {du:.3e} m (ratio {:.2e}); no slit: pushed {dl0:.3e} m, above {du0:.3e} m (ratio {:.2e})", du / dl, du0 / dl0);
    assert!(dl > 1e-4 && dl0 > 1e-4);
    assert!(du0 > 0.2 * dl0, "control: a connected sheet moves together");
    assert!(du < 0.02 * dl, "upper lip moved {du} for lower {dl}");
}

/// The extra-stiffness hook: a z-spring of stiffness k on one surface vertex, given as
/// K_x = k b bᵀ (b the vertex's row of B), changes the quasi-static z-displacement of that
/// vertex under a z-force from u₀ = c f to c f / (1 + k c) (Sherman–Morrison, linear regime).
#[test]
fn extra_stiffness_hook_matches_sherman_morrison() {
    let mesh = box_mesh(V::zeros(), V::new(0.2, 0.2, 0.1), 4);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(0.05),
            ..Default::default()
        },
    )
    .unwrap();
    let int = Interior::new(&lat, &soft()).unwrap();
    // Bottom two node layers pinned (a block glued to the ground), push the top centre down.
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.05).collect();
    let v = (0..mesh.positions.len())
        .min_by(|&i, &j| {
            let d = |k: usize| (mesh.positions[k] - V::new(0.1, 0.1, 0.1)).norm();
            d(i).total_cmp(&d(j))
        })
        .unwrap();
    let fz = -1e-3;
    let f = vertex_force(&lat, v, V::new(0.0, 0.0, fz));
    let mut be =
        BackwardEuler::new(int.clone(), lat.rest_flat(), pinned.clone(), no_gravity()).unwrap();
    let rep = be.quasi_static(&f, None).unwrap();
    assert_eq!(rep.status, SolveStatus::Converged);
    let u0 = lat.embed(&be.q)[v].z - mesh.positions[v].z;
    let c = u0 / fz;
    let k = 2.0 / c; // a spring twice as stiff as the block there: u drops to a third
    let w = lat.weights(&lat.vertex_points[v]);
    let trip: Vec<(usize, usize, f64)> = w
        .iter()
        .flat_map(|&(a, wa)| {
            w.iter()
                .map(move |&(b, wb)| (3 * a + 2, 3 * b + 2, k * wa * wb))
        })
        .collect();
    let zero = vec![0.0; be.q.len()];
    let mut be2 = BackwardEuler::new(int, lat.rest_flat(), pinned, no_gravity()).unwrap();
    let rep = be2
        .quasi_static(&f, Some(&ExtraTerms::new(&trip, &zero)))
        .unwrap();
    assert_eq!(rep.status, SolveStatus::Converged);
    let uk = lat.embed(&be2.q)[v].z - mesh.positions[v].z;
    let want = c * fz / (1.0 + k * c);
    println!(
        "u0 {u0:.4e} m, with spring {uk:.4e} m, Sherman–Morrison {want:.4e} m, rel. diff {:.2e}",
        (uk - want).abs() / want.abs()
    );
    assert!((uk - want).abs() < 1e-3 * want.abs());
}
