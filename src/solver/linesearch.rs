//! Backtracking line search on the residual norm (DESIGN.md): Armijo with α = 1e-4; try
//! step 1, then 0.5, then the minimiser of a quadratic fit of ‖r‖², clamped to
//! [0.1, 0.5] times the last step.

/// Armijo constant on the residual norm.
pub const ARMIJO: f64 = 1e-4;

/// Result of a line search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum LineSearch {
    /// Accepted step length and residual norm there.
    Accepted {
        /// Step length.
        step: f64,
        /// Residual norm at the step.
        residual: f64,
    },
    /// No acceptable step within the trials.
    Failed,
}

/// Search along a Newton direction. `phi(t)` returns the residual norm at step `t`
/// (NaN/∞ counts as unacceptable); `phi0` is its value at 0. For a Newton direction the
/// derivative of ‖r‖² at 0 is −2‖r‖², which the quadratic fit uses.
pub fn residual_line_search(phi0: f64, mut phi: impl FnMut(f64) -> f64, max_trials: usize) -> LineSearch {
    let mut t = 1.0;
    let f0 = phi0 * phi0;
    for trial in 0..max_trials {
        let p = phi(t);
        if p.is_finite() && p <= (1.0 - ARMIJO * t) * phi0 {
            return LineSearch::Accepted { step: t, residual: p };
        }
        let next = if trial == 0 || !p.is_finite() {
            0.5 * t
        } else {
            // m(s) = f0 − 2 f0 s + c s², fitted through m(t) = p².
            let c = (p * p - f0 + 2.0 * f0 * t) / (t * t);
            let s = if c > 0.0 { f0 / c } else { 0.5 * t };
            s.clamp(0.1 * t, 0.5 * t)
        };
        t = next;
        if t < 1e-12 {
            break;
        }
    }
    LineSearch::Failed
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_step_accepted_on_linear_residual_and_backtracks_on_overshoot() {
        // r(t) = (1 − t) r0: exact Newton, t = 1 accepted.
        assert_eq!(
            residual_line_search(2.0, |t| 2.0 * (1.0 - t), 10),
            LineSearch::Accepted { step: 1.0, residual: 0.0 }
        );
        // r(t) = |1 − 4t| (direction 4× too long): 1 and 0.5 fail, the quadratic fit of
        // ‖r‖² = (1 − 4t)² through t = 0.5 gives c = (1 − 1 + 1)/0.25 = 4, s = 1/4, inside
        // [0.05, 0.25]: accepted exactly at the root.
        match residual_line_search(1.0, |t| (1.0 - 4.0 * t).abs(), 10) {
            LineSearch::Accepted { step, residual } => {
                assert!((step - 0.25).abs() < 1e-15 && residual < 1e-15)
            }
            LineSearch::Failed => panic!("should accept"),
        }
        // A direction that only increases the residual fails.
        assert_eq!(residual_line_search(1.0, |t| 1.0 + t, 20), LineSearch::Failed);
        assert_eq!(residual_line_search(1.0, |_| f64::NAN, 20), LineSearch::Failed);
    }
}
