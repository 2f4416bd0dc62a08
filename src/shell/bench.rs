//! `furrow bench shell`: a compressed square sheet solved to equilibrium from a warm start.
//!
//! The sheet (0.1 m square, near-equilateral triangles, E = 1 MPa, ν = 0.3, h = 0.5 mm)
//! has its boundary pinned and moved towards the centre (in-plane compression) and its
//! centre clamped by 15 linear constraints (Gaussian-weighted mean positions of five
//! patches), like the skin's cluster constraints. A preparation solve from the flat sheet
//! (with a small out-of-plane imperfection) at 1 % compression finds the wrinkled
//! equilibrium; the measured solve then moves the boundary to 1.05 % and re-solves from that
//! state, as one animation frame follows the previous one. Both solves use
//! [`HessianMode::Auto`](crate::solver::HessianMode) and the energy merit in the line search
//! (the residual-only rule of DESIGN.md crawls once the sheet wrinkles).

use super::sheet::equilateral_sheet;
use super::{Shell, ShellMaterial};
use crate::solver::{LinearConstraints, SolveReport, StaticProblem, StaticSettings, StaticSolver};
use serde_json::json;
use std::time::Instant;

/// The benchmark problem: shell, pinned boundary dofs, centre constraints, rest state.
pub struct BenchSheet {
    /// The shell.
    pub shell: Shell,
    /// Boundary vertex indices.
    pub boundary: Vec<usize>,
    /// Centre constraints.
    pub constraints: LinearConstraints,
    /// Side length (m).
    pub side: f64,
}

/// Build the benchmark sheet with about `faces` triangles.
pub fn bench_sheet(faces: usize) -> anyhow::Result<BenchSheet> {
    anyhow::ensure!(
        faces >= 50,
        "bench shell needs at least 50 faces (got {faces})"
    );
    let side = 0.1;
    // faces ≈ ny (2 nx + 1), ny ≈ nx · 2/√3 for a square.
    let nx = ((faces as f64 / (4.0 / 3f64.sqrt())).sqrt())
        .round()
        .max(4.0) as usize;
    let a = side / nx as f64;
    let ny = ((side / (a * 3f64.sqrt() / 2.0)).round() as usize).max(2);
    let sheet = equilateral_sheet(nx, ny, a);
    let mat = ShellMaterial {
        young: 1.0e6,
        poisson: 0.3,
        thickness: 5.0e-4,
    };
    let mesh = sheet.mesh.clone();
    let shell = Shell::new(mesh, mat)?;
    let mut on_boundary = vec![false; shell.rest.vertex_count()];
    for &e in &shell.topology.boundary_edges {
        let [u, v] = shell.topology.edges[e];
        on_boundary[u] = true;
        on_boundary[v] = true;
    }
    let boundary: Vec<usize> = (0..on_boundary.len()).filter(|&v| on_boundary[v]).collect();
    let (lx, ly) = (nx as f64 * a, ny as f64 * a * 3f64.sqrt() / 2.0);
    let centre = [0.5 * lx, 0.5 * ly];
    let sigma = 0.04 * side;
    let mut c = LinearConstraints::none();
    let offsets = [[0.0, 0.0], [1.0, 0.0], [-1.0, 0.0], [0.0, 1.0], [0.0, -1.0]];
    for off in offsets {
        let cc = [
            centre[0] + 1.5 * sigma * off[0],
            centre[1] + 1.5 * sigma * off[1],
        ];
        let mut w: Vec<(usize, f64)> = Vec::new();
        for (v, p) in shell.rest.positions.iter().enumerate() {
            let d2 = (p.x - cc[0]).powi(2) + (p.y - cc[1]).powi(2);
            if d2 < 4.0 * sigma * sigma {
                w.push((v, (-d2 / (2.0 * sigma * sigma)).exp()));
            }
        }
        let total: f64 = w.iter().map(|t| t.1).sum();
        anyhow::ensure!(total > 0.0, "bench sheet too coarse for its centre clamp");
        for axis in 0..3 {
            let mut rhs = 0.0;
            for &(v, wv) in &w {
                c.entries.push((c.rows, 3 * v + axis, wv / total));
                rhs += wv / total * shell.rest.positions[v][axis];
            }
            c.rhs.push(rhs);
            c.rows += 1;
        }
    }
    Ok(BenchSheet {
        shell,
        boundary,
        constraints: c,
        side,
    })
}

impl BenchSheet {
    /// Problem with the boundary pinned; `x` gets boundary positions scaled by
    /// (1 − compression) about the sheet centre.
    pub fn problem(&self, compression: f64, x: &mut [f64]) -> StaticProblem {
        let (lo, hi) = self.shell.rest.bounding_box().expect("non-empty sheet");
        let c = (lo + hi) / 2.0;
        let mut pinned = Vec::with_capacity(3 * self.boundary.len());
        for &v in &self.boundary {
            let p = self.shell.rest.positions[v];
            let q = c + (p - c) * (1.0 - compression);
            x[3 * v] = q.x;
            x[3 * v + 1] = q.y;
            x[3 * v + 2] = 0.0;
            pinned.extend([3 * v, 3 * v + 1, 3 * v + 2]);
        }
        StaticProblem {
            pinned,
            constraints: self.constraints.clone(),
            forces: Vec::new(),
        }
    }

    /// Residual tolerance (N): 1e-9 of the membrane force scale E h · side.
    pub fn tolerance(&self) -> f64 {
        1e-9 * self.shell.material.stretch_stiffness() * self.side
    }
}

fn report_json(r: &SolveReport) -> serde_json::Value {
    json!({
        "status": r.status.as_str(),
        "newton_iterations": r.iterations,
        "factorizations": r.factorizations,
        "modified_hessian_steps": r.modified_hessian_steps,
        "residual": r.residual,
        "assembly_s": r.assembly_s,
        "factorisation_s": r.factor_s,
        "symbolic_s": r.symbolic_s,
        "solve_s": r.solve_s,
        "line_search_s": r.line_search_s,
        "total_s": r.total_s,
    })
}

/// Run the shell benchmark on a sheet of about `faces` triangles and return its measurements
/// as a flat JSON object: faces, vertices, constraints, then the warm-start solve (newton
/// iterations, residual in N, times in seconds, status) and `prep_*` fields for the
/// preparation solve from the flat sheet.
pub fn bench_shell(faces: usize) -> anyhow::Result<serde_json::Value> {
    let t_build = Instant::now();
    let b = bench_sheet(faces)?;
    let build_s = t_build.elapsed().as_secs_f64();
    let settings = StaticSettings {
        tolerance: b.tolerance(),
        max_iterations: 400,
        energy_merit: true,
        ..Default::default()
    };
    let mut solver = StaticSolver::new(settings)?;
    let mut x = b.shell.rest.flat_positions();
    // Deterministic small imperfection (1e-4 of the side) to break the flat symmetry.
    for (i, p) in b.shell.rest.positions.iter().enumerate() {
        let s = (p.x * 937.0 + p.y * 613.0).sin() * (p.x * 411.0 - p.y * 287.0).cos();
        x[3 * i + 2] = 1e-4 * b.side * s;
    }
    let problem = b.problem(0.01, &mut x);
    let prep = solver.solve(&b.shell, &problem, &mut x)?;
    let problem = b.problem(0.0105, &mut x);
    let warm = solver.solve(&b.shell, &problem, &mut x)?;
    let zmax = x.chunks(3).map(|c| c[2].abs()).fold(0.0, f64::max);
    let mut out = json!({
        "faces": b.shell.rest.triangle_count(),
        "vertices": b.shell.rest.vertex_count(),
        "constraints": b.constraints.rows,
        "build_s": build_s,
        "max_out_of_plane_m": zmax,
    });
    let obj = out.as_object_mut().expect("object");
    for (k, v) in report_json(&warm).as_object().expect("object") {
        obj.insert(k.clone(), v.clone());
    }
    for (k, v) in report_json(&prep).as_object().expect("object") {
        obj.insert(format!("prep_{k}"), v.clone());
    }
    obj.insert("threads".into(), json!(rayon::current_num_threads()));
    Ok(out)
}
