//! Backtracking line search (DESIGN.md): Armijo on the residual norm with α = 1e-4; try
//! step 1, then 0.5, then the minimiser of a quadratic fit, clamped to [0.1, 0.5] times the
//! last step.
//!
//! Optionally a step is also accepted when it satisfies the Armijo condition on an energy
//! merit ψ (the Lagrangian with the new multipliers). Thin shells need this: a Newton step
//! that moves the sheet out of plane stretches the stiff membrane to second order, so the
//! residual norm rises for any useful step length even though the energy falls, and a
//! residual-only search crawls (steps of 1e-3, hundreds of iterations in the buckling test).

use super::newton::{backtrack, QuadraticFit, Verdict};

/// Armijo constant.
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

/// What a trial step measured: residual norm ‖r‖ and (optionally) the energy merit ψ.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Trial {
    /// Residual norm (N).
    pub residual: f64,
    /// Energy merit (J); ignored when the search has no energy merit.
    pub merit: f64,
}

/// Energy merit at the start: value ψ(0) and directional derivative ψ'(0) (< 0 for a
/// descent direction).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnergyMerit {
    /// ψ(0) (J).
    pub value: f64,
    /// ψ'(0) (J per unit step).
    pub slope: f64,
}

impl EnergyMerit {
    /// The merit when it can judge steps: ψ(0) finite and ψ'(0) < 0 (a descent direction).
    pub fn descending(self) -> Option<Self> {
        (self.slope < 0.0 && self.value.is_finite()).then_some(self)
    }
}

/// Judge the trial `tr` at step `t` (the acceptance rule of the skin statics): accepted when
/// ‖r‖ satisfies Armijo, ‖r(t)‖ ≤ (1 − α t) r0, or, with a (descending) `energy` merit, when
/// ψ does, ψ(t) ≤ ψ(0) + α t ψ'(0). The quadratic fit for the next step uses ψ when it is
/// finite, else ‖r‖² with d‖r‖²/dt(0) = −2‖r‖² (a Newton direction); a non-finite residual
/// gives no fit (the step is halved).
pub fn judge(r0: f64, energy: Option<EnergyMerit>, t: f64, tr: Trial) -> Verdict {
    let res_ok = tr.residual.is_finite() && tr.residual <= (1.0 - ARMIJO * t) * r0;
    let en_ok = energy.is_some_and(|e| {
        tr.residual.is_finite()
            && tr.merit.is_finite()
            && tr.merit <= e.value + ARMIJO * t * e.slope
    });
    let fit = tr.residual.is_finite().then(|| match energy {
        Some(e) if tr.merit.is_finite() => QuadraticFit {
            value0: e.value,
            slope0: e.slope,
            value: tr.merit,
        },
        _ => QuadraticFit {
            value0: r0 * r0,
            slope0: -2.0 * r0 * r0,
            value: tr.residual * tr.residual,
        },
    });
    Verdict {
        accepted: res_ok || en_ok,
        fit,
    }
}

/// Search along a Newton direction. `eval(t)` measures the trial at step `t` (NaN/∞ are
/// rejected); `r0` is the residual norm at 0. Trials are judged by [`judge`] and shortened by
/// the Newton core's [`backtrack`].
pub fn line_search(
    r0: f64,
    energy: Option<EnergyMerit>,
    mut eval: impl FnMut(f64) -> Trial,
    max_trials: usize,
) -> LineSearch {
    let energy = energy.and_then(EnergyMerit::descending);
    let mut residual = f64::NAN;
    let search = backtrack(max_trials, |t| {
        let tr = eval(t);
        residual = tr.residual;
        judge(r0, energy, t, tr)
    });
    match search.step {
        Some(step) => LineSearch::Accepted { step, residual },
        None => LineSearch::Failed,
    }
}

/// Residual-only search (the DESIGN.md rule); `phi(t)` returns ‖r‖ at step `t`.
pub fn residual_line_search(
    r0: f64,
    mut phi: impl FnMut(f64) -> f64,
    max_trials: usize,
) -> LineSearch {
    line_search(
        r0,
        None,
        |t| Trial {
            residual: phi(t),
            merit: f64::NAN,
        },
        max_trials,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn full_step_accepted_on_linear_residual_and_backtracks_on_overshoot() {
        // r(t) = (1 − t) r0: exact Newton, t = 1 accepted.
        assert_eq!(
            residual_line_search(2.0, |t| 2.0 * (1.0 - t), 10),
            LineSearch::Accepted {
                step: 1.0,
                residual: 0.0
            }
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
        assert_eq!(
            residual_line_search(1.0, |t| 1.0 + t, 20),
            LineSearch::Failed
        );
        assert_eq!(
            residual_line_search(1.0, |_| f64::NAN, 20),
            LineSearch::Failed
        );
    }

    #[test]
    fn energy_merit_accepts_descent_steps_the_residual_rejects() {
        // ψ(t) = −t + t²/2 (minimum at 1), residual rising: energy Armijo accepts t = 1.
        let e = EnergyMerit {
            value: 0.0,
            slope: -1.0,
        };
        let ls = line_search(
            1.0,
            Some(e),
            |t| Trial {
                residual: 1.0 + t,
                merit: -t + 0.5 * t * t,
            },
            10,
        );
        assert_eq!(
            ls,
            LineSearch::Accepted {
                step: 1.0,
                residual: 2.0
            }
        );
        // ψ(t) = −t + 2t² (minimum at 1/4): 1 and 0.5 fail (ψ(0.5) = 0), fit gives 1/4.
        let ls = line_search(
            1.0,
            Some(e),
            |t| Trial {
                residual: 1.0 + t,
                merit: -t + 2.0 * t * t,
            },
            10,
        );
        assert_eq!(
            ls,
            LineSearch::Accepted {
                step: 0.25,
                residual: 1.25
            }
        );
    }
}
