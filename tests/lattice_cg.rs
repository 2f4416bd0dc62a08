//! Conjugate gradients in the single linearised backward Euler step: the trajectory error
//! that CG's relative tolerance causes, against the time discretisation error of backward
//! Euler itself, and CG against the exact (Cholesky) solve.
#![allow(clippy::needless_range_loop)]

use furrow::fem::bench::cube_lattice;
use furrow::fem::{BackwardEuler, Interior, LinearSolver, Material, StepSettings};

/// The bench cube (n³ quadratic cells of 2 cm, soft tissue, bottom two control-point layers
/// pinned) sagging under gravity from rest: node positions (flat, m) after each step up to
/// time `t_end` (s), recorded every `record` steps.
fn sag(n: usize, dt: f64, t_end: f64, record: usize, solver: LinearSolver) -> Vec<Vec<f64>> {
    let h = 0.02;
    let lat = cube_lattice(n, h).unwrap();
    let int = Interior::new(&lat, &Material::default()).unwrap();
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < h).collect();
    let settings = StepSettings {
        dt,
        gravity: [0.0, 0.0, -furrow::fem::GRAVITY],
        linear_solver: solver,
        tangent: furrow::fem::Tangent::Consistent,
        max_newton: 1,
        ..Default::default()
    };
    let mut be = BackwardEuler::new(int, lat.rest_flat(), pinned, settings).unwrap();
    let zero = vec![0.0; be.q.len()];
    let steps = (t_end / dt).round() as usize;
    let mut out = Vec::new();
    for k in 1..=steps {
        be.step(&zero, None).unwrap();
        if k % record == 0 {
            out.push(be.q.clone());
        }
    }
    out
}

/// Largest node distance (m) between two trajectories at the same recorded times.
fn max_gap(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    assert_eq!(a.len(), b.len());
    let mut m: f64 = 0.0;
    for (x, y) in a.iter().zip(b) {
        for n in 0..x.len() / 3 {
            let d = (0..3)
                .map(|i| (x[3 * n + i] - y[3 * n + i]).powi(2))
                .sum::<f64>()
                .sqrt();
            m = m.max(d);
        }
    }
    m
}

fn cg(rel_tol: f64) -> LinearSolver {
    LinearSolver::ConjugateGradient {
        rel_tol,
        max_iter: 2000,
    }
}

/// 50 steps (1 s) of the 6³-cell bench cube sagging under gravity with one linearised
/// backward Euler step per time step: the trajectories with CG at rel_tol 1e-4 and 1e-3
/// against CG at 1e-8 must differ far less (< 1/10) than the same run at dt = 0.02 s
/// against dt = 0.01 s (the time discretisation error of backward Euler). CG at 1e-8 must
/// agree with Cholesky to far below both.
#[test]
fn cg_tolerance_error_is_far_below_the_time_step_error() {
    let n = 6;
    let (dt, t_end) = (0.02, 1.0);
    let tight = sag(n, dt, t_end, 1, cg(1e-8));
    let loose4 = sag(n, dt, t_end, 1, cg(1e-4));
    let loose3 = sag(n, dt, t_end, 1, cg(1e-3));
    let half = sag(n, dt / 2.0, t_end, 2, cg(1e-8));
    let exact = sag(n, dt, t_end, 1, LinearSolver::Cholesky);
    let time_err = max_gap(&tight, &half);
    let tol4 = max_gap(&tight, &loose4);
    let tol3 = max_gap(&tight, &loose3);
    let chol = max_gap(&tight, &exact);
    let sag_depth = {
        let last = tight.last().unwrap();
        let rest = &sag(n, dt, dt, 1, cg(1e-8))[0];
        max_gap(std::slice::from_ref(last), std::slice::from_ref(rest))
    };
    println!(
        "time step error {time_err:.3e} m; CG 1e-4: {tol4:.3e} m; CG 1e-3: {tol3:.3e} m; \
         CG 1e-8 vs Cholesky {chol:.3e} m; motion {sag_depth:.3e} m"
    );
    assert!(
        time_err > 1e-2 * sag_depth,
        "the run must move: {time_err} vs {sag_depth}"
    );
    assert!(tol4 < 0.1 * time_err, "rel_tol 1e-4: {tol4} vs {time_err}");
    assert!(tol3 < 0.1 * time_err, "rel_tol 1e-3: {tol3} vs {time_err}");
    assert!(
        chol < 1e-3 * time_err,
        "CG 1e-8 vs Cholesky: {chol} vs {time_err}"
    );
}

/// With coupling terms (K_x, F_x: a spring between two far-apart nodes and a pull on one)
/// CG multiplies the assembled matrix; one step agrees with the Cholesky step.
#[test]
fn cg_with_coupling_terms_matches_cholesky() {
    let h = 0.02;
    let n = 4;
    let lat = cube_lattice(n, h).unwrap();
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.5 * h).collect();
    let (a, b) = (lat.node_count() - 1, lat.node_count() / 2);
    let k = 50.0;
    let mut stiffness = Vec::new();
    for i in 0..3 {
        let (ra, rb) = (3 * a + i, 3 * b + i);
        stiffness.extend([(ra, ra, k), (rb, rb, k), (ra, rb, -k), (rb, ra, -k)]);
    }
    let mut force = vec![0.0; 3 * lat.node_count()];
    force[3 * a] = 0.05;
    let run = |solver: LinearSolver| {
        let int = Interior::new(&lat, &Material::default()).unwrap();
        let settings = StepSettings {
            linear_solver: solver,
            tangent: furrow::fem::Tangent::Consistent,
            max_newton: 1,
            ..Default::default()
        };
        let mut be = BackwardEuler::new(int, lat.rest_flat(), pinned.clone(), settings).unwrap();
        let zero = vec![0.0; be.q.len()];
        let extra = furrow::fem::ExtraTerms::new(&stiffness, &force);
        for _ in 0..3 {
            be.step(&zero, Some(&extra)).unwrap();
        }
        be.q
    };
    let rest = lat.rest_flat();
    let qc = run(LinearSolver::Cholesky);
    let qg = run(cg(1e-10));
    let motion = max_gap(std::slice::from_ref(&qc), &[rest]);
    let gap = max_gap(&[qc], &[qg]);
    println!("CG vs Cholesky with K_x: {gap:.3e} m of motion {motion:.3e} m");
    assert!(motion > 1e-4, "{motion}");
    assert!(gap < 1e-7 * motion, "{gap} vs {motion}");
}
