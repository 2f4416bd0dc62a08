//! The shell benchmark: a small run in CI (it must converge), the 2k / 20k / 80k table by hand:
//! `cargo test --release --test shell_bench -- --ignored --nocapture`.

use furrow::shell::bench::bench_shell;

#[test]
fn small_bench_converges() {
    let v = bench_shell(500).unwrap();
    println!("{v}");
    assert_eq!(v["prep_status"], "converged", "{v}");
    assert_eq!(v["status"], "converged", "{v}");
    assert!(v["max_out_of_plane_m"].as_f64().unwrap() > 1e-4, "compressed sheet should wrinkle: {v}");
}

#[test]
#[ignore]
fn bench_table() {
    for faces in [2_000usize, 20_000, 80_000] {
        let v = bench_shell(faces).unwrap();
        println!("{v}");
    }
}
