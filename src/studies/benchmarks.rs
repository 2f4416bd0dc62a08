//! The benchmark table: shell energy assembly, shell solve at several face counts with the
//! growth exponent of its cost, one interior (lattice) step, the activation fit per frame
//! (and, from the CLI, the whole demo), as CSV rows and a markdown table (the one
//! `docs/performance.md` quotes).
//!
//! Each benchmark is the same code as its `furrow bench …` subcommand; this module only
//! runs them in one process (so ratios between them come from one machine state) and fits
//! the growth law t ≈ c · n^p of the shell solve against face count ([`super::fit`]).

use super::fit::{power_law, PowerLaw};
use crate::math::Energy;
use std::fmt::Write as _;
use std::time::Instant;

/// One measured number.
#[derive(Debug, Clone, PartialEq)]
pub struct BenchRow {
    /// Which benchmark (`shell_assembly`, `shell_solve`, `lattice_step`, `fit`, `demo`).
    pub benchmark: String,
    /// Problem size (faces, elements, lattice cells or frames; see `size_unit`).
    pub size: usize,
    /// What `size` counts.
    pub size_unit: String,
    /// The measured quantity (e.g. `total_s`, `newton_iterations`).
    pub metric: String,
    /// Its value (seconds for `*_s`, milliseconds for `*_ms`, counts otherwise).
    pub value: f64,
}

/// What to run.
#[derive(Debug, Clone, PartialEq)]
pub struct SuiteSettings {
    /// Face counts of the shell benchmarks (sheet of about that many triangles).
    pub faces: Vec<usize>,
    /// Quadratic elements of the lattice benchmark.
    pub elements: usize,
    /// Lattice cells of the activation-fit benchmark.
    pub cells: usize,
}

impl Default for SuiteSettings {
    fn default() -> Self {
        Self {
            faces: vec![2_000, 20_000, 80_000],
            elements: 1_000,
            cells: 2_000,
        }
    }
}

fn row(benchmark: &str, size: usize, unit: &str, metric: &str, value: f64) -> BenchRow {
    BenchRow {
        benchmark: benchmark.into(),
        size,
        size_unit: unit.into(),
        metric: metric.into(),
        value,
    }
}

/// Copy the named numeric fields of a benchmark's JSON result into rows.
fn rows_from(
    v: &serde_json::Value,
    benchmark: &str,
    size: usize,
    unit: &str,
    fields: &[(&str, &str)],
) -> Vec<BenchRow> {
    fields
        .iter()
        .filter_map(|&(key, metric)| {
            v.get(key)
                .and_then(|x| x.as_f64())
                .map(|x| row(benchmark, size, unit, metric, x))
        })
        .collect()
}

/// Shell energy assembly: energy, gradient and exact Hessian triplets of the benchmark sheet
/// with about `faces` triangles (slightly wrinkled), best of three evaluations (s).
pub fn shell_assembly(faces: usize) -> anyhow::Result<Vec<BenchRow>> {
    let b = crate::shell::bench::bench_sheet(faces)?;
    let mut x = b.shell.rest.flat_positions();
    for (i, p) in b.shell.rest.positions.iter().enumerate() {
        x[3 * i + 2] = 1e-4 * b.side * (p.x * 937.0 + p.y * 613.0).sin();
    }
    let n = b.shell.rest.triangle_count();
    let mut trip = Vec::with_capacity(b.shell.triplet_count());
    let mut grad = vec![0.0; x.len()];
    let mut best = f64::INFINITY;
    for _ in 0..3 {
        trip.clear();
        grad.fill(0.0);
        let t = Instant::now();
        let e = b.shell.eval(&x, Some(&mut grad), Some(&mut trip), false);
        best = best.min(t.elapsed().as_secs_f64());
        anyhow::ensure!(e.is_finite(), "shell assembly: non-finite energy");
    }
    Ok(vec![
        row("shell_assembly", n, "faces", "eval_s", best),
        row(
            "shell_assembly",
            n,
            "faces",
            "hessian_triplets",
            trip.len() as f64,
        ),
    ])
}

/// Shell solve from a warm start ([`crate::shell::bench::bench_shell`]).
pub fn shell_solve(faces: usize) -> anyhow::Result<Vec<BenchRow>> {
    let v = crate::shell::bench::bench_shell(faces)?;
    let n = v["faces"].as_u64().unwrap_or(faces as u64) as usize;
    Ok(rows_from(
        &v,
        "shell_solve",
        n,
        "faces",
        &[
            ("vertices", "vertices"),
            ("newton_iterations", "newton_iterations"),
            ("factorizations", "factorizations"),
            ("linear_solves", "linear_solves"),
            ("assembly_s", "assembly_s"),
            ("factorisation_s", "factorisation_s"),
            ("solve_s", "solve_s"),
            ("line_search_s", "line_search_s"),
            ("total_s", "total_s"),
            ("residual", "residual_n"),
            ("reference_total_s", "reference_total_s"),
            ("reference_factorizations", "reference_factorizations"),
            ("speedup", "speedup"),
        ],
    ))
}

/// One backward Euler step of a lattice of about `elements` quadratic elements
/// ([`crate::fem::bench::bench_lattice`]): the single linearised step (one Newton iteration,
/// conjugate gradients) and the step solved to convergence (direct and CG).
pub fn lattice_step(elements: usize) -> anyhow::Result<Vec<BenchRow>> {
    let v = crate::fem::bench::bench_lattice(elements)?;
    let n = v["elements"].as_u64().unwrap_or(elements as u64) as usize;
    Ok(rows_from(
        &v,
        "lattice_step",
        n,
        "elements",
        &[
            ("free_dofs", "free_dofs"),
            ("cg_single_newton_assembly_s", "linearised_assembly_s"),
            ("cg_single_newton_solve_s", "linearised_solve_s"),
            ("cg_single_newton_energy_s", "linearised_energy_s"),
            ("cg_single_newton_step_s", "linearised_step_s"),
            ("cg_single_newton_cg_iterations", "linearised_cg_iterations"),
            (
                "cg_single_newton_best_step_s",
                "linearised_best_of_10_step_s",
            ),
            (
                "cg_single_newton_best_solve_s",
                "linearised_best_of_10_solve_s",
            ),
            (
                "cg_single_newton_best_energy_s",
                "linearised_best_of_10_energy_s",
            ),
            ("cg_step_s", "converged_cg_step_s"),
            ("cg_newton_iterations", "converged_cg_newton_iterations"),
            ("step_s", "converged_cholesky_step_s"),
            ("face_lattice_build_s", "face_lattice_build_s"),
        ],
    ))
}

/// Activation fit of 52 muscles per frame ([`crate::muscle::bench::bench_fit`]).
pub fn fit_per_frame(cells: usize) -> anyhow::Result<Vec<BenchRow>> {
    let v = crate::muscle::bench::bench_fit(cells, 1)?;
    let n = v["elements"].as_u64().unwrap_or(cells as u64) as usize;
    Ok(rows_from(
        &v,
        "fit",
        n,
        "elements",
        &[
            ("qp_ms_mean", "qp_ms_mean"),
            ("qp_ms_max", "qp_ms_max"),
            ("frame_ms_mean", "frame_ms_mean"),
            ("jacobian_s", "jacobian_s"),
            ("clip_s", "clip_s"),
        ],
    ))
}

/// Run the suite (without the demo) and return its rows; `progress(name)` is called before
/// each benchmark.
pub fn run_suite(
    s: &SuiteSettings,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<Vec<BenchRow>> {
    let mut rows = Vec::new();
    for &f in &s.faces {
        progress(&format!("shell assembly, {f} faces"));
        rows.extend(shell_assembly(f)?);
    }
    for &f in &s.faces {
        progress(&format!("shell solve, {f} faces"));
        rows.extend(shell_solve(f)?);
    }
    progress(&format!("lattice step, {} elements", s.elements));
    rows.extend(lattice_step(s.elements)?);
    progress(&format!("activation fit, {} cells", s.cells));
    rows.extend(fit_per_frame(s.cells)?);
    Ok(rows)
}

/// Growth law of `metric` of `benchmark` against size (None with fewer than two sizes).
pub fn growth(rows: &[BenchRow], benchmark: &str, metric: &str) -> Option<PowerLaw> {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .filter(|r| r.benchmark == benchmark && r.metric == metric)
        .map(|r| (r.size as f64, r.value))
        .collect();
    power_law(&pts)
}

/// The rows as CSV (`benchmark,size,size_unit,metric,value`), then one row per growth
/// exponent of the shell (metric `exponent_of_<metric>`, size 0).
pub fn to_csv(rows: &[BenchRow]) -> String {
    let mut s = String::from("benchmark,size,size_unit,metric,value\n");
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{}",
            r.benchmark, r.size, r.size_unit, r.metric, r.value
        );
    }
    for (b, m) in growth_metrics() {
        if let Some(p) = growth(rows, b, m) {
            let _ = writeln!(s, "{b},0,exponent,exponent_of_{m},{}", p.exponent);
        }
    }
    s
}

fn growth_metrics() -> [(&'static str, &'static str); 4] {
    [
        ("shell_assembly", "eval_s"),
        ("shell_solve", "total_s"),
        ("shell_solve", "factorisation_s"),
        ("shell_solve", "assembly_s"),
    ]
}

fn value(rows: &[BenchRow], b: &str, size: usize, m: &str) -> Option<f64> {
    rows.iter()
        .find(|r| r.benchmark == b && r.size == size && r.metric == m)
        .map(|r| r.value)
}

/// A markdown table (`docs/performance.md`): the shell at each size (assembly, iterations,
/// factorisation, total) with the growth exponents, then the lattice, fit and demo lines.
pub fn to_markdown(rows: &[BenchRow]) -> String {
    let fmt = |v: Option<f64>, scale: f64, digits: usize| {
        v.map(|x| format!("{:.*}", digits, x * scale))
            .unwrap_or_else(|| "–".into())
    };
    let mut s = String::new();
    s.push_str("| shell (faces) | energy+gradient+Hessian (ms) | Newton iterations | factorisations (ms, total) | assembly (ms, total) | warm solve (ms) | reference warm solve (ms) | speed-up |\n");
    s.push_str("|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    let mut sizes: Vec<usize> = rows
        .iter()
        .filter(|r| r.benchmark == "shell_solve")
        .map(|r| r.size)
        .collect();
    sizes.dedup();
    for &n in &sizes {
        // Both benchmarks build the same sheet, so their face counts agree.
        let eval = value(rows, "shell_assembly", n, "eval_s");
        let _ = writeln!(
            s,
            "| {n} | {} | {} | {} | {} | {} | {} | {}× |",
            fmt(eval, 1e3, 1),
            fmt(value(rows, "shell_solve", n, "newton_iterations"), 1.0, 0),
            fmt(value(rows, "shell_solve", n, "factorisation_s"), 1e3, 0),
            fmt(value(rows, "shell_solve", n, "assembly_s"), 1e3, 0),
            fmt(value(rows, "shell_solve", n, "total_s"), 1e3, 0),
            fmt(value(rows, "shell_solve", n, "reference_total_s"), 1e3, 0),
            fmt(value(rows, "shell_solve", n, "speedup"), 1.0, 2),
        );
    }
    let exp = |b: &str, m: &str| {
        growth(rows, b, m)
            .map(|p| format!("n^{:.2}", p.exponent))
            .unwrap_or_else(|| "–".into())
    };
    let _ = writeln!(
        s,
        "| growth | {} | | {} | {} | {} | {} | |",
        exp("shell_assembly", "eval_s"),
        exp("shell_solve", "factorisation_s"),
        exp("shell_solve", "assembly_s"),
        exp("shell_solve", "total_s"),
        exp("shell_solve", "reference_total_s"),
    );
    s.push('\n');
    let find = |b: &str, m: &str| rows.iter().find(|r| r.benchmark == b && r.metric == m);
    if let Some(r) = find("lattice_step", "linearised_step_s") {
        let n = r.size;
        let _ = writeln!(
            s,
            "- lattice step, {n} quadratic elements ({} free dofs): linearised (one Newton iteration, CG, {} iterations) best of 10 steps {} ms (CG {}, energy {}), one timed step {} ms = assembly {} + CG {} + energy {}; solved to convergence: CG {} ms ({} Newton iterations), Cholesky {} ms; face lattice build {} ms",
            fmt(value(rows, "lattice_step", n, "free_dofs"), 1.0, 0),
            fmt(value(rows, "lattice_step", n, "linearised_cg_iterations"), 1.0, 0),
            fmt(value(rows, "lattice_step", n, "linearised_best_of_10_step_s"), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "linearised_best_of_10_solve_s"), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "linearised_best_of_10_energy_s"), 1e3, 1),
            fmt(Some(r.value), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "linearised_assembly_s"), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "linearised_solve_s"), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "linearised_energy_s"), 1e3, 1),
            fmt(value(rows, "lattice_step", n, "converged_cg_step_s"), 1e3, 0),
            fmt(value(rows, "lattice_step", n, "converged_cg_newton_iterations"), 1.0, 0),
            fmt(value(rows, "lattice_step", n, "converged_cholesky_step_s"), 1e3, 0),
            fmt(value(rows, "lattice_step", n, "face_lattice_build_s"), 1e3, 0),
        );
    }
    if let Some(r) = find("fit", "qp_ms_mean") {
        let n = r.size;
        let _ = writeln!(
            s,
            "- activation fit, 52 muscles, {n} elements: QP {} ms mean / {} ms max per frame, whole frame {} ms; rest Jacobian {} s once",
            fmt(Some(r.value), 1.0, 1),
            fmt(value(rows, "fit", n, "qp_ms_max"), 1.0, 1),
            fmt(value(rows, "fit", n, "frame_ms_mean"), 1.0, 1),
            fmt(value(rows, "fit", n, "jacobian_s"), 1.0, 2),
        );
    }
    if let Some(r) = find("demo", "wall_s") {
        let _ = writeln!(
            s,
            "- whole demo (`furrow demo`, {} frames of rigs/face.glb): {} s",
            r.size,
            fmt(Some(r.value), 1.0, 1)
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Rows from a fake run: the growth exponent of t = 2e-6 n^1.5 comes out as 1.5 and the
    /// CSV and markdown carry it.
    #[test]
    fn growth_exponent_and_tables_from_rows() {
        let mut rows = Vec::new();
        for n in [1000usize, 4000, 16000] {
            let t = 2e-6 * (n as f64).powf(1.5);
            rows.push(row("shell_solve", n, "faces", "total_s", t));
            rows.push(row("shell_solve", n, "faces", "factorisation_s", 0.5 * t));
            rows.push(row("shell_solve", n, "faces", "newton_iterations", 4.0));
        }
        let p = growth(&rows, "shell_solve", "total_s").unwrap();
        assert!((p.exponent - 1.5).abs() < 1e-12, "{p:?}");
        let csv = to_csv(&rows);
        assert!(csv.starts_with("benchmark,size,size_unit,metric,value\n"));
        let exponent: f64 = csv
            .lines()
            .find_map(|l| l.strip_prefix("shell_solve,0,exponent,exponent_of_total_s,"))
            .and_then(|v| v.parse().ok())
            .expect("exponent row");
        assert!((exponent - 1.5).abs() < 1e-9, "{csv}");
        let md = to_markdown(&rows);
        assert!(md.contains("n^1.50"), "{md}");
        assert!(md.contains("| 16000 |"), "{md}");
    }
}
