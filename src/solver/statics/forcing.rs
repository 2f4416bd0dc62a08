//! The inexact-Newton forcing term: how accurately a Newton direction's KKT system is
//! solved, relative to the residual.

/// Largest relative tolerance of a KKT solve far from the solution (the loosest
/// Eisenstat–Walker forcing term).
const FORCING_MAX: f64 = 1e-3;

/// Largest relative tolerance of a KKT solve within 100× of the target residual, where
/// landing 10× below the target asks less than [`FORCING_MAX`]: a last step solved this
/// loosely lands on the same equilibrium with fewer GMRES solves, so the lagged factor lasts.
const FORCING_NEAR: f64 = 0.1;

/// Relative tolerance of the KKT solve for the Newton direction at residual norm `rn` (N)
/// after a step from `rn_prev` (inexact Newton, Eisenstat and Walker 1996, choice 2):
/// 0.9 (rn / rn_prev)², at most [`FORCING_MAX`], and never tighter than needed to land
/// 10× below the target `tolerance` (N) (up to [`FORCING_NEAR`]) nor than `floor` (the
/// settings' linear tolerance).
pub(super) fn forcing(floor: f64, tolerance: f64, rn: f64, rn_prev: Option<f64>) -> f64 {
    let ew = rn_prev.map_or(FORCING_MAX, |p| 0.9 * (rn / p).powi(2));
    ew.min(FORCING_MAX)
        .max((0.1 * tolerance / rn).min(FORCING_NEAR))
        .max(floor)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The forcing term: 1e-3 on a first step, Eisenstat–Walker's 0.9 (rn/rn_prev)² below
    /// that, loosened to land 10× below the target near it (up to 0.1), never under the floor.
    #[test]
    fn the_forcing_term_asks_no_more_than_the_target_needs() {
        let close = |a: f64, b: f64| (a - b).abs() <= 1e-12 * b;
        assert!(close(forcing(1e-10, 3.6e-4, 5.0, None), 1e-3));
        assert!(close(forcing(1e-10, 1e-9, 1e-3, Some(1.0)), 9e-7));
        // One step from the target: 10× below it needs 1.8e-2.
        assert!(close(forcing(1e-10, 3.6e-4, 2e-3, Some(5.0)), 1.8e-2));
        assert!(close(forcing(1e-10, 3.6e-4, 3e-4, Some(5.0)), 0.1));
        assert!(close(forcing(1e-2, 1e-9, 1.0, None), 1e-2));
    }
}
