//! `furrow bench lattice`: one backward Euler step of a lattice of quadratic elements, and
//! lattice construction on a face-sized open mesh.

use super::dynamics::AUTO_CG_REL_TOL;
use super::{BackwardEuler, Interior, LinearSolver, Material, StepSettings, Tangent};
use crate::lattice::{ElementOrder, Lattice, LatticeSettings};
use std::time::Instant;

/// The benchmark cube's surface (see [`crate::mesh::cube_mesh`]).
pub use crate::mesh::cube_mesh;

/// Lattice of n³ quadratic cells of side `h` (m) over the box [0, n h]³ ([`cube_mesh`]): the
/// benchmark cube.
pub fn cube_lattice(n: usize, h: f64) -> Result<Lattice, crate::lattice::LatticeError> {
    Lattice::build(
        &cube_mesh(n as f64 * h, n),
        &LatticeSettings {
            cell_size: Some(h),
            order: ElementOrder::Quadratic,
            ..Default::default()
        },
    )
}

/// Run the lattice benchmark on about `elements` quadratic elements and return its
/// measurements as a flat JSON object (elements, nodes, times in seconds).
///
/// A cube of n³ cells (n = round(∛elements), 2 cm cells, soft tissue) with its bottom two
/// control-point layers pinned falls under gravity; one warm-up step computes the pattern
/// and the symbolic Cholesky analysis, then one step is timed: `assembly_s` (element
/// rotations and matrix assembly; with CG, which multiplies element by element, only the
/// rotations and the operator update), `solve_s` (numeric factorisation and solve, or CG
/// including its block-Jacobi setup), `step_s` (the whole step including energy and
/// gradient evaluations and the line search), per `newton_iterations` (with CG, the timed
/// step starts from the warm-up step's direction). CG runs also report `best_*`: the
/// minimum of each time over 10 further steps (robust against other processes' load).
/// Prefixes: none (Cholesky, Newton to convergence), `single_newton_` (Cholesky, one
/// linearised step), `cg_` (CG at the default rel_tol [`AUTO_CG_REL_TOL`], Newton to
/// convergence), `cg_single_newton_` (the same CG, one step), `cg_single_newton_tol1e-4_`
/// (CG rel_tol 1e-4, one step).
/// `face_lattice_build_s` times [`Lattice::build`] with default settings on the procedural
/// face rig (`rig::face::generate()`, ~10k vertices), and `face_1cm_lattice_build_s` with
/// 1 cm cells.
pub fn bench_lattice(elements: usize) -> anyhow::Result<serde_json::Value> {
    let chol = bench_step(elements, LinearSolver::Cholesky, 20)?;
    let chol1 = bench_step(elements, LinearSolver::Cholesky, 1)?;
    let cg = bench_step(
        elements,
        LinearSolver::ConjugateGradient {
            rel_tol: AUTO_CG_REL_TOL,
            max_iter: 500,
        },
        20,
    )?;
    let one = bench_step(
        elements,
        LinearSolver::ConjugateGradient {
            rel_tol: AUTO_CG_REL_TOL,
            max_iter: 500,
        },
        1,
    )?;
    // The same single linearised step at the tighter CG rel_tol 1e-4 (tests/lattice_cg.rs
    // measures the trajectory error of both against backward Euler's time-step error).
    let one4 = bench_step(
        elements,
        LinearSolver::ConjugateGradient {
            rel_tol: 1e-4,
            max_iter: 500,
        },
        1,
    )?;
    let face = crate::rig::face::generate().mesh;
    let t = Instant::now();
    let face_lat = Lattice::build(&face, &LatticeSettings::default())?;
    let face_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let face_fine = Lattice::build(
        &face,
        &LatticeSettings {
            cell_size: Some(0.01),
            ..Default::default()
        },
    )?;
    let face_fine_s = t.elapsed().as_secs_f64();
    let mut out = serde_json::Map::new();
    for (prefix, v) in [
        ("", &chol),
        ("single_newton_", &chol1),
        ("cg_", &cg),
        ("cg_single_newton_", &one),
        ("cg_single_newton_tol1e-4_", &one4),
    ] {
        for (k, x) in v.as_object().expect("object") {
            if prefix.is_empty()
                || !matches!(
                    k.as_str(),
                    "elements" | "nodes" | "free_dofs" | "lattice_build_s"
                )
            {
                out.insert(format!("{prefix}{k}"), x.clone());
            }
        }
    }
    out.insert("threads".into(), rayon::current_num_threads().into());
    out.insert("face_vertices".into(), face.vertex_count().into());
    out.insert("face_elements".into(), face_lat.elements.len().into());
    out.insert("face_nodes".into(), face_lat.node_count().into());
    out.insert("face_lattice_build_s".into(), face_s.into());
    out.insert("face_1cm_elements".into(), face_fine.elements.len().into());
    out.insert("face_1cm_lattice_build_s".into(), face_fine_s.into());
    Ok(serde_json::Value::Object(out))
}

/// One measured backward Euler step (after a warm-up step) with the given linear solver and
/// Newton iteration cap.
fn bench_step(
    elements: usize,
    solver: LinearSolver,
    max_newton: usize,
) -> anyhow::Result<serde_json::Value> {
    anyhow::ensure!(elements >= 1, "need at least one element");
    let n = ((elements as f64).cbrt().round() as usize).max(1);
    let h = 0.02;
    let mesh = cube_mesh(n as f64 * h, n);
    let t = Instant::now();
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(h),
            order: ElementOrder::Quadratic,
            ..Default::default()
        },
    )?;
    let build_s = t.elapsed().as_secs_f64();
    let int = Interior::new(&lat, &Material::default())?;
    let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < h).collect();
    let settings = StepSettings {
        gravity: [0.0, 0.0, -super::GRAVITY],
        linear_solver: solver,
        tangent: Tangent::Consistent,
        max_newton,
        ..Default::default()
    };
    let mut be = BackwardEuler::new(int, lat.rest_flat(), pinned, settings)?;
    let zero = vec![0.0; be.q.len()];
    let t = Instant::now();
    let first = be.step(&zero, None)?;
    let first_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let rep = be.step(&zero, None)?;
    let step_s = t.elapsed().as_secs_f64();
    let iters = rep.iterations.max(1) as f64;
    // Best of `repeats` further steps (robust against load from other processes).
    let repeats = if matches!(solver, LinearSolver::ConjugateGradient { .. }) {
        10
    } else {
        0
    };
    let mut best = [f64::INFINITY; 4];
    for _ in 0..repeats {
        let t = Instant::now();
        let r = be.step(&zero, None)?;
        let s = t.elapsed().as_secs_f64();
        let it = r.iterations.max(1) as f64;
        for (b, v) in best
            .iter_mut()
            .zip([s, r.assembly_s / it, r.solve_s / it, r.energy_s])
        {
            *b = b.min(v);
        }
    }

    let mut out = serde_json::json!({
        "elements": lat.elements.len(),
        "nodes": lat.node_count(),
        "free_dofs": 3 * (lat.node_count() - be.pinned.iter().filter(|&&p| p).count()),
        "lattice_build_s": build_s,
        "first_step_s": first_s,
        "first_step_newton_iterations": first.iterations,
        "newton_iterations": rep.iterations,
        "status": rep.status.as_str(),
        "assembly_s": rep.assembly_s / iters,
        "solve_s": rep.solve_s / iters,
        "step_s": step_s,
        "step_per_iteration_s": step_s / iters,
        "cg_iterations": rep.cg_iterations,
        "energy_s": rep.energy_s,
        "first_step_cg_iterations": first.cg_iterations,
        "evaluations": rep.evaluations,
        "relative_residual": rep.relative_residual,
    });
    if repeats > 0 {
        for (k, v) in ["step_s", "assembly_s", "solve_s", "energy_s"]
            .iter()
            .zip(best)
        {
            out[format!("best_{k}")] = v.into();
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    /// The benchmark runs and reports consistent numbers on a tiny lattice (no timing claims).
    #[test]
    fn bench_runs_on_a_small_lattice() {
        let v = super::bench_lattice(8).unwrap();
        assert_eq!(v["elements"], 8);
        assert_eq!(v["nodes"], 64);
        assert!(v["step_s"].as_f64().unwrap() > 0.0);
        assert_eq!(v["status"], "converged");
    }
}
