//! `furrow bench shell`: a compressed square sheet solved to equilibrium from a warm start.
//!
//! The sheet (0.1 m square, near-equilateral triangles, E = 1 MPa, ν = 0.3, h = 0.5 mm)
//! has its boundary pinned and moved towards the centre (in-plane compression) and its
//! centre clamped by 15 linear constraints (Gaussian-weighted mean positions of five
//! patches), like the skin's cluster constraints. A preparation solve from the flat sheet
//! (with a small out-of-plane imperfection) at 1 % compression finds the wrinkled
//! equilibrium (sheets above 30,000 faces start it from the prolonged equilibrium of a sheet
//! with a quarter of the faces, coarse to fine, instead of the flat sheet); the measured solve then moves the boundary to 1.05 % and re-solves from that
//! state, as one animation frame follows the previous one. Both solves use
//! [`HessianMode::Auto`](crate::solver::HessianMode) and the energy merit in the line search
//! (the residual-only rule crawls once the sheet wrinkles).

use super::sheet::equilateral_sheet;
use super::{Shell, ShellMaterial};
use crate::mesh::TriMesh;
use crate::solver::{
    LinearAlgebra, LinearConstraints, SolveReport, StaticProblem, StaticSettings, StaticSolver,
};
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
        "linear_solves": r.linear_solves,
        "lagged_directions": r.lagged_directions,
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

/// Sheets above this many faces start their preparation from the prolonged equilibrium of a
/// sheet with a quarter of the faces instead of from the flat sheet.
pub const COARSE_TO_FINE_FACES: usize = 30_000;

/// Flat-sheet positions (m) of `b` with the deterministic out-of-plane imperfection
/// (1e-4 of the side) that breaks the flat symmetry.
fn perturbed_flat(b: &BenchSheet) -> Vec<f64> {
    let mut x = b.shell.rest.flat_positions();
    for (i, p) in b.shell.rest.positions.iter().enumerate() {
        let s = (p.x * 937.0 + p.y * 613.0).sin() * (p.x * 411.0 - p.y * 287.0).cos();
        x[3 * i + 2] = 1e-4 * b.side * s;
    }
    x
}

/// Displacement field (m) of a flat-rest coarse sheet carried to the rest positions of a fine
/// one: each fine vertex takes the barycentric mix of the displacements of the coarse triangle
/// containing its rest position (rest domains mapped onto each other by their bounding boxes).
/// Returns fine positions x = X + u.
pub fn prolong_displacement(coarse: &TriMesh, coarse_x: &[f64], fine: &TriMesh) -> Vec<f64> {
    let (clo, chi) = coarse.bounding_box().expect("non-empty coarse sheet");
    let (flo, fhi) = fine.bounding_box().expect("non-empty fine sheet");
    let scale = [
        (chi.x - clo.x) / (fhi.x - flo.x).max(f64::MIN_POSITIVE),
        (chi.y - clo.y) / (fhi.y - flo.y).max(f64::MIN_POSITIVE),
    ];
    // Bucket grid over the coarse triangles' bounding boxes.
    let edge = coarse
        .triangles
        .iter()
        .map(|t| (coarse.positions[t[1]] - coarse.positions[t[0]]).norm())
        .fold(0.0, f64::max)
        .max(f64::MIN_POSITIVE);
    let nb = [
        (((chi.x - clo.x) / edge).ceil() as usize).max(1),
        (((chi.y - clo.y) / edge).ceil() as usize).max(1),
    ];
    let cell = |x: f64, y: f64| {
        let i = (((x - clo.x) / edge).floor().max(0.0) as usize).min(nb[0] - 1);
        let j = (((y - clo.y) / edge).floor().max(0.0) as usize).min(nb[1] - 1);
        (i, j)
    };
    let mut buckets: Vec<Vec<usize>> = vec![Vec::new(); nb[0] * nb[1]];
    for (t, tri) in coarse.triangles.iter().enumerate() {
        let ps = tri.map(|v| coarse.positions[v]);
        let (x0, x1) = (
            ps.iter().map(|p| p.x).fold(f64::INFINITY, f64::min),
            ps.iter().map(|p| p.x).fold(f64::NEG_INFINITY, f64::max),
        );
        let (y0, y1) = (
            ps.iter().map(|p| p.y).fold(f64::INFINITY, f64::min),
            ps.iter().map(|p| p.y).fold(f64::NEG_INFINITY, f64::max),
        );
        let (i0, j0) = cell(x0, y0);
        let (i1, j1) = cell(x1, y1);
        for j in j0..=j1 {
            for i in i0..=i1 {
                buckets[j * nb[0] + i].push(t);
            }
        }
    }
    let mut x = fine.flat_positions();
    for (v, p) in fine.positions.iter().enumerate() {
        let q = [
            clo.x + (p.x - flo.x) * scale[0],
            clo.y + (p.y - flo.y) * scale[1],
        ];
        let (i, j) = cell(q[0], q[1]);
        // The containing triangle, or the one whose worst barycentric is least negative.
        let mut best = (f64::NEG_INFINITY, 0usize, [0.0; 3]);
        for &t in &buckets[j * nb[0] + i] {
            let [a, b, c] = coarse.triangles[t].map(|w| coarse.positions[w]);
            let det = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
            if det.abs() < f64::MIN_POSITIVE {
                continue;
            }
            let l1 = ((q[0] - a.x) * (c.y - a.y) - (c.x - a.x) * (q[1] - a.y)) / det;
            let l2 = ((b.x - a.x) * (q[1] - a.y) - (q[0] - a.x) * (b.y - a.y)) / det;
            let l = [1.0 - l1 - l2, l1, l2];
            let worst = l[0].min(l[1]).min(l[2]);
            if worst > best.0 {
                best = (worst, t, l);
            }
        }
        let tri = coarse.triangles[best.1];
        for axis in 0..3 {
            let mut u = 0.0;
            for (k, &w) in tri.iter().enumerate() {
                u += best.2[k] * (coarse_x[3 * w + axis] - coarse.positions[w][axis]);
            }
            x[3 * v + axis] += u;
        }
    }
    x
}

/// The wrinkled equilibrium at 1 % compression that the measured solve starts from, the
/// solver that found it (its multipliers, γ and last state carry over to the next solve, as
/// from one frame to the next) and the report of that solve. Sheets above
/// [`COARSE_TO_FINE_FACES`] start from the prolonged equilibrium of a sheet with a quarter of
/// the faces (recursively), smaller ones from the perturbed flat sheet. Also returns the
/// number of levels.
fn prepare(
    b: &BenchSheet,
    faces: usize,
    settings: &StaticSettings,
) -> anyhow::Result<(Vec<f64>, StaticSolver, SolveReport, usize)> {
    let (mut x, levels) = if faces > COARSE_TO_FINE_FACES {
        let coarse = bench_sheet(faces / 4)?;
        let (cx, _, _, levels) = prepare(&coarse, faces / 4, settings)?;
        (
            prolong_displacement(&coarse.shell.rest, &cx, &b.shell.rest),
            levels + 1,
        )
    } else {
        (perturbed_flat(b), 1)
    };
    let mut solver = StaticSolver::new(*settings)?;
    let problem = b.problem(0.01, &mut x);
    let report = solver.solve(&b.shell, &problem, &mut x)?;
    Ok((x, solver, report, levels))
}

/// Run the shell benchmark on a sheet of about `faces` triangles with the skin's fast linear
/// algebra ([`LinearAlgebra::FAST`]) and the reference ([`LinearAlgebra::REFERENCE`]), and
/// return the measurements as a flat JSON object (see [`bench_shell_with`]).
pub fn bench_shell(faces: usize) -> anyhow::Result<serde_json::Value> {
    bench_shell_with(faces, LinearAlgebra::FAST)
}

/// The shell benchmark with the linear algebra `fast` against the reference, each from the
/// same prepared state: faces, vertices, constraints, then `fast`'s warm-start solve
/// (Newton iterations, residual in N, times in seconds, status), `prep_*` fields for its
/// preparation solve from the flat sheet, `reference_*` fields for the reference's warm
/// solve, and `speedup`, the reference's warm-solve time over `fast`'s (one process).
pub fn bench_shell_with(faces: usize, fast: LinearAlgebra) -> anyhow::Result<serde_json::Value> {
    let t_build = Instant::now();
    let b = bench_sheet(faces)?;
    let build_s = t_build.elapsed().as_secs_f64();
    let (fast_run, x) = bench_solver(&b, faces, fast)?;
    let (reference, _) = bench_solver(&b, faces, LinearAlgebra::REFERENCE)?;
    let zmax = x.chunks(3).map(|c| c[2].abs()).fold(0.0, f64::max);
    let mut out = json!({
        "faces": b.shell.rest.triangle_count(),
        "vertices": b.shell.rest.vertex_count(),
        "constraints": b.constraints.rows,
        "build_s": build_s,
        "max_out_of_plane_m": zmax,
        "threads": rayon::current_num_threads(),
        "lagged_solves": fast.lagged_solves,
        "precision": fast.precision,
    });
    let obj = out.as_object_mut().expect("object");
    for (k, v) in fast_run.as_object().expect("object") {
        obj.insert(k.clone(), v.clone());
    }
    for (k, v) in reference.as_object().expect("object") {
        if !k.starts_with("prep_") {
            obj.insert(format!("reference_{k}"), v.clone());
        }
    }
    let speedup = reference["total_s"].as_f64().unwrap_or(f64::NAN)
        / fast_run["total_s"].as_f64().unwrap_or(f64::NAN);
    obj.insert("speedup".into(), json!(speedup));
    Ok(out)
}

/// Prepare the sheet `b` with the reference linear algebra (deterministic, so every solver
/// starts from the same state, with the same lagged factor) and time its warm solve with the
/// linear algebra `linear`: the warm solve's report with the preparation's as `prep_*`
/// fields, and the final state.
fn bench_solver(
    b: &BenchSheet,
    faces: usize,
    linear: LinearAlgebra,
) -> anyhow::Result<(serde_json::Value, Vec<f64>)> {
    let settings = StaticSettings {
        tolerance: b.tolerance(),
        max_iterations: 400,
        energy_merit: true,
        ..Default::default()
    };
    let t_prep = Instant::now();
    let (mut x, mut solver, prep, levels) =
        prepare(b, faces, &LinearAlgebra::REFERENCE.apply(settings))?;
    let prep_wall_s = t_prep.elapsed().as_secs_f64();
    solver.settings = linear.apply(settings);
    let problem = b.problem(0.0105, &mut x);
    let warm = solver.solve(&b.shell, &problem, &mut x)?;
    let mut out = report_json(&warm);
    let obj = out.as_object_mut().expect("object");
    for (k, v) in report_json(&prep).as_object().expect("object") {
        obj.insert(format!("prep_{k}"), v.clone());
    }
    obj.insert("prep_levels".into(), json!(levels));
    obj.insert("prep_wall_s".into(), json!(prep_wall_s));
    Ok((out, x))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// On a sheet refined by halving the edge, every fine vertex is a coarse vertex or the
    /// midpoint of a coarse edge: an arbitrary coarse field must arrive unchanged at the
    /// former and as the edge mean at the latter (a wrong containing triangle breaks this).
    #[test]
    fn prolongation_is_piecewise_linear_on_the_coarse_triangles() {
        let coarse = equilateral_sheet(6, 8, 0.1 / 6.0).mesh;
        let fine = equilateral_sheet(12, 16, 0.1 / 12.0).mesh;
        let field = |v: usize, a: usize| ((v * 7 + a * 13) as f64 * 0.731).sin() * 1e-3;
        let mut cx = coarse.flat_positions();
        for (i, c) in cx.iter_mut().enumerate() {
            *c += field(i / 3, i % 3);
        }
        let fx = prolong_displacement(&coarse, &cx, &fine);
        let key =
            |p: nalgebra::Vector3<f64>| ((p.x * 1e6).round() as i64, (p.y * 1e6).round() as i64);
        let mut expect = std::collections::HashMap::new();
        for t in &coarse.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                let m = (coarse.positions[a] + coarse.positions[b]) / 2.0;
                let d = [0, 1, 2].map(|ax| (field(a, ax) + field(b, ax)) / 2.0);
                expect.insert(key(m), d);
                expect.insert(key(coarse.positions[a]), [0, 1, 2].map(|ax| field(a, ax)));
            }
        }
        for (v, p) in fine.positions.iter().enumerate() {
            let d = expect
                .get(&key(*p))
                .expect("fine vertex on a coarse vertex or edge");
            for a in 0..3 {
                let got = fx[3 * v + a] - p[a];
                assert!(
                    (got - d[a]).abs() < 1e-12,
                    "vertex {v} axis {a}: {got} against {}",
                    d[a]
                );
            }
        }
    }
}
