//! The dense plane-strain wrinkling simulation against the critical-wavelength formula.

use furrow::coupling::wavelength::Bilayer;
use furrow::solver::status::SolveStatus;
use furrow::validate::dense::{run, DenseCase};

/// A small case: h = 0.2 mm, E_x/E_q = 100, ν = 0.45 / 0.3 (λ_pred ≈ 4 mm).
#[test]
fn small_case_within_ten_percent_of_formula() {
    let case = DenseCase::new(Bilayer {
        thickness: 0.2e-3,
        skin_modulus: 100e3,
        skin_poisson: 0.45,
        interior_modulus: 1e3,
        interior_poisson: 0.45,
    });
    let r = run(&case).unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&r).unwrap());
    assert_eq!(r.status, SolveStatus::Converged);
    let err = r.error.expect("a wrinkle formed");
    assert!(err < 0.10, "error {err}");
}
