//! The shell benchmark: a small run in CI (it must converge), the 2k / 20k / 80k table by hand:
//! `cargo test --release --test shell_bench -- --ignored --nocapture` (or set
//! `FURROW_BENCH_FACES=2000,20000` to choose sizes).

use furrow::shell::bench::bench_shell;

#[test]
fn small_bench_converges() {
    let v = bench_shell(500).unwrap();
    println!("{v}");
    assert_eq!(v["prep_status"], "converged", "{v}");
    assert_eq!(v["status"], "converged", "{v}");
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

#[test]
#[ignore]
fn bench_table() {
    let sizes: Vec<usize> = std::env::var("FURROW_BENCH_FACES")
        .ok()
        .map(|s| s.split(',').filter_map(|t| t.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![2_000, 20_000, 80_000]);
    for faces in sizes {
        let v = bench_shell(faces).unwrap();
        println!("{v}");
    }
}
