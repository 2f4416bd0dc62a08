//! `furrow report tradeoff` and `furrow report stability` on a reduced set: small sheet rigs,
//! few frames. Run with `cargo test --release --test reports`.

use furrow::report::stability::{self, run_all};
use furrow::report::tradeoff::{self, sheet_rig, SheetRig};
use furrow::scene::Scene;
use std::process::Command;

/// Every stability case ends with a named outcome, no output is non-finite, and a case that
/// stops says why.
#[test]
fn stability_cases_end_with_a_named_status_and_finite_outputs() {
    let rows = run_all(true, 16, 0.1, &|_, _| {});
    eprintln!("{}", stability::to_markdown(&rows));
    assert!(rows.len() >= 14, "{} cases", rows.len());
    for r in &rows {
        assert!(
            ["converged", "not_converged", "refused"].contains(&r.outcome.as_str()),
            "{}: {} ended {} ({})",
            r.case,
            r.parameter,
            r.outcome,
            r.message
        );
        assert!(!r.non_finite, "{} {}: non-finite output", r.case, r.parameter);
        assert!(
            r.interior_residual.is_finite() && r.shell_residual.is_finite(),
            "{} {}: residuals {} {}",
            r.case,
            r.parameter,
            r.interior_residual,
            r.shell_residual
        );
        if r.outcome == "refused" {
            assert!(
                r.message.len() > 20,
                "{} {}: refused without a message",
                r.case,
                r.parameter
            );
        }
        if r.outcome == "not_converged" {
            assert!(
                r.interior_status.contains('(') || r.shell_status.contains('('),
                "{} {}: not converged but no stage names a status: {} / {}",
                r.case,
                r.parameter,
                r.interior_status,
                r.shell_status
            );
        }
    }
    // The defaults converge; the baseline actually simulated frames.
    let base = rows.iter().find(|r| r.case == "baseline").unwrap();
    assert_eq!(base.outcome, "converged", "{}", base.message);
    assert!(base.frames >= 3);
    // The inverted interior recovers its rest shape.
    let inv = rows.iter().find(|r| r.case == "inverted_start").unwrap();
    assert_eq!(inv.outcome, "converged", "{}", inv.message);
    // The CSV has one line per case plus the header.
    let csv = stability::to_csv(&rows);
    assert_eq!(csv.lines().count(), rows.len() + 1);
    assert_eq!(csv.lines().next().unwrap(), stability::CSV_HEADER);
}
