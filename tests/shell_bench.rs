//! The shell benchmark: a small run in CI (it must converge), and the benchmark suite's
//! files on tiny sizes. The 2k / 20k / 80k table: `furrow bench suite --out out/bench` (or
//! by hand: `cargo test --release --test shell_bench -- --ignored --nocapture`, with
//! `FURROW_BENCH_FACES=2000,20000` to choose sizes).

use furrow::shell::bench::{bench_shell, bench_shell_with};
use furrow::solver::LinearAlgebra;
use std::process::Command;

#[test]
fn small_bench_converges() {
    let v = bench_shell(500).unwrap();
    println!("{v}");
    assert_eq!(v["prep_status"], "converged", "{v}");
    assert_eq!(v["status"], "converged", "{v}");
    assert_eq!(v["reference_status"], "converged", "{v}");
    assert!(v["speedup"].as_f64().unwrap() > 0.0, "{v}");
    // A 5 % boundary change from an equilibrium: the pinned-motion predictor plus a few
    // Newton steps (5 measured; 11 before the predictor at 2k faces).
    assert!(
        v["newton_iterations"].as_u64().unwrap() <= 8,
        "warm start should take a few iterations: {v}"
    );
    assert!(
        v["max_out_of_plane_m"].as_f64().unwrap() > 1e-4,
        "compressed sheet should wrinkle: {v}"
    );
}

/// The lagged-factor cap changes the cost, not the answer: with `--lagged-solves 0` no
/// direction is lagged and every one is factorised, and the wrinkled sheet it reaches has
/// the same largest out-of-plane displacement as with the default cap (to 1e-6 relative:
/// both solve to 1e-9 of the membrane force scale).
#[test]
fn lagged_cap_changes_the_cost_not_the_sheet() {
    let every = bench_shell_with(
        500,
        LinearAlgebra {
            lagged_solves: 0,
            ..LinearAlgebra::FAST
        },
    )
    .unwrap();
    let lagged = bench_shell(500).unwrap();
    for v in [&every, &lagged] {
        assert_eq!(v["status"], "converged", "{v}");
    }
    assert_eq!(every["lagged_solves"], 0, "{every}");
    assert_eq!(every["lagged_directions"], 0, "{every}");
    assert!(
        every["factorizations"].as_u64() >= every["newton_iterations"].as_u64(),
        "{every}"
    );
    let (a, b) = (
        every["max_out_of_plane_m"].as_f64().unwrap(),
        lagged["max_out_of_plane_m"].as_f64().unwrap(),
    );
    assert!((a - b).abs() <= 1e-6 * a.abs(), "{a} against {b}");
}

/// `furrow bench suite` on tiny sizes writes a CSV with every benchmark and the growth
/// exponent rows, a markdown table, and refuses to overwrite them without --force.
#[test]
fn bench_suite_writes_csv_and_table() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("bench");
    let run = |force: bool| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_furrow"));
        c.args([
            "--quiet",
            "bench",
            "suite",
            "--faces",
            "200,800",
            "--elements",
            "8",
        ])
        .args(["--cells", "200", "--no-demo", "--out"])
        .arg(&out);
        if force {
            c.arg("--force");
        }
        c.output().unwrap()
    };
    let o = run(false);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("bench_suite.csv")).unwrap();
    assert!(csv.starts_with("benchmark,size,size_unit,metric,value\n"));
    for b in ["shell_assembly", "shell_solve", "lattice_step", "fit"] {
        assert!(csv.contains(&format!("\n{b},")), "{b} missing:\n{csv}");
    }
    let exponent: f64 = csv
        .lines()
        .find(|l| l.starts_with("shell_solve,0,exponent,exponent_of_total_s,"))
        .and_then(|l| l.rsplit(',').next())
        .and_then(|v| v.parse().ok())
        .expect("growth exponent row");
    assert!(exponent.is_finite() && exponent > 0.0, "{exponent}");
    // Every value is a finite number.
    for l in csv.lines().skip(1) {
        let v: f64 = l.rsplit(',').next().unwrap().parse().unwrap();
        assert!(v.is_finite(), "{l}");
    }
    let md = std::fs::read_to_string(out.join("bench_suite.md")).unwrap();
    assert!(md.contains("| growth |"), "{md}");
    let again = run(false);
    assert!(!again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(
        err.contains("bench_suite.csv") || err.contains("bench_suite.md"),
        "{err}"
    );
    assert!(run(true).status.success());
}
