//! Lattice benchmark (ignored by default; speed is measured, never asserted):
//! `cargo test --release --test lattice_bench -- --ignored --nocapture`.
#![allow(clippy::needless_range_loop)]

#[test]
#[ignore = "a benchmark that prints timings, not a check"]
fn bench_lattice_1000_elements() {
    for elements in [125, 1000] {
        let v = furrow::fem::bench::bench_lattice(elements).unwrap();
        println!("{}", serde_json::to_string_pretty(&v).unwrap());
    }
}
