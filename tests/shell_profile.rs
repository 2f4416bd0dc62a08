//! Where the time of one Newton iteration goes on the benchmark sheet (by hand, release):
//! `FURROW_PROFILE_FACES=20000 cargo test --release --test shell_profile -- --ignored --nocapture`.

use furrow::math::Energy;
use furrow::shell::bench::bench_sheet;
use furrow::solver::kkt::{KktBlocks, KktSolver};
use std::time::Instant;

#[test]
#[ignore = "a profile that prints where an iteration's time goes, not a check"]
fn profile_one_iteration() {
    let faces: usize = std::env::var("FURROW_PROFILE_FACES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(20_000);
    let b = bench_sheet(faces).unwrap();
    let mut x = b.shell.rest.flat_positions();
    for (i, p) in b.shell.rest.positions.iter().enumerate() {
        x[3 * i + 2] = 1e-3 * (p.x * 300.0).sin() * (p.y * 200.0).cos();
    }
    let problem = b.problem(0.01, &mut x);
    let n = x.len();
    let time = |label: &str, f: &mut dyn FnMut()| {
        let t = Instant::now();
        f();
        println!("{label:40} {:8.4} s", t.elapsed().as_secs_f64());
    };
    let mut g = vec![0.0; n];
    time("gradient (membrane + bending)", &mut || {
        b.shell.eval(&x, Some(&mut g), None, false);
    });
    let mut t = Vec::new();
    time("membrane Hessian triplets", &mut || {
        t.clear();
        b.shell.membrane.eval(&x, None, Some(&mut t), false);
    });
    time("bending Hessian triplets", &mut || {
        t.clear();
        b.shell.bending.eval(&x, None, Some(&mut t), false);
    });
    time("shell Hessian triplets (exact)", &mut || {
        t.clear();
        b.shell.eval(&x, None, Some(&mut t), false);
    });
    let mut tp = Vec::new();
    time("shell Hessian triplets (projected)", &mut || {
        b.shell.eval(&x, None, Some(&mut tp), true);
    });
    let mut pinned = vec![false; n];
    for &d in &problem.pinned {
        pinned[d] = true;
    }
    let mut free_of = vec![usize::MAX; n];
    let mut nf = 0;
    for d in 0..n {
        if !pinned[d] {
            free_of[d] = nf;
            nf += 1;
        }
    }
    let cf: Vec<(usize, usize, f64)> = problem
        .constraints
        .entries
        .iter()
        .filter(|e| free_of[e.1] != usize::MAX)
        .map(|&(r, d, v)| (r, free_of[d], v))
        .collect();
    let nc = problem.constraints.rows;
    let mut kkt = KktSolver::new();
    let gamma = 500.0;
    let blocks = KktBlocks {
        free_of: &free_of,
        n_free: nf,
        n_cons: nc,
        hessian: &t,
        hessian_values: furrow::solver::kkt::HessianValues::Triplets,
        constraints: &cf,
        gamma,
        delta: 1e-4 * gamma,
        layout_key: None,
    };
    time("KKT build: pattern, AMD, symbolic, map", &mut || {
        kkt.assemble(&blocks).unwrap();
    });
    time("KKT assemble (scatter, pattern reused)", &mut || {
        kkt.assemble(&blocks).unwrap();
    });
    let mut info = None;
    time("KKT numeric LDLT", &mut || {
        info = Some(kkt.factor(1e-2 * gamma));
    });
    println!(
        "triplets {}, free dofs {nf}, constraints {nc}, {:?}",
        t.len(),
        info.unwrap()
    );
    let mut rhs = vec![1.0; nf + nc];
    time("KKT solve (GMRES, at most 4 factor solves)", &mut || {
        kkt.solve(&mut rhs, 3, 1e-15);
    });
}
