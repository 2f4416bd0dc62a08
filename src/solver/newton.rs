//! The one Newton iteration with backtracking line search shared by the skin statics
//! ([`super::statics`]) and the interior's backward Euler ([`crate::fem::dynamics`]).
//!
//! The core owns the control flow, the same for both:
//!
//! 1. test the current iterate ([`NewtonProblem::check`]): converged, not finite, or go on;
//! 2. stop at the iteration limit;
//! 3. compute a Newton direction ([`NewtonProblem::direction`]; each problem keeps its own
//!    linear solver: KKT LDLᵀ with lagged factors and GMRES for the skin, Cholesky or
//!    conjugate gradients for the interior) and count the iteration;
//! 4. backtrack along it ([`backtrack`]): try the step length t = 1, let the problem judge
//!    the trial ([`NewtonProblem::trial`], its own Armijo rule on its own merit), and shrink
//!    t by half or to the minimiser of a quadratic fit until a trial is accepted;
//! 5. move to the accepted trial ([`NewtonProblem::accept`]) or, when none was accepted,
//!    let the problem retry with another direction or stop ([`NewtonProblem::rejected`]).
//!
//! Step lengths t are dimensionless fractions of the Newton direction.

use super::status::SolveStatus;

/// Step lengths below this fraction of the Newton direction are not tried.
pub const MIN_STEP: f64 = 1e-12;

/// What the convergence test found at the current iterate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Check {
    /// Not converged: take another Newton step.
    Continue,
    /// The residual meets the tolerance.
    Converged,
    /// The residual is NaN or infinite.
    NotFinite,
}

/// A quadratic model m(s) = f0 + f0′ s + c s² of a merit along the search line, fitted
/// through the value at the last trial step t; its minimiser is the next step to try.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct QuadraticFit {
    /// Merit at step 0, f0 (units of the merit, e.g. J or N²).
    pub value0: f64,
    /// Directional derivative at step 0, f0′ (merit units per unit step).
    pub slope0: f64,
    /// Merit at the trial step, f(t).
    pub value: f64,
}

impl QuadraticFit {
    /// Minimiser of the model through f(t), clamped to [0.1 t, 0.5 t] (0.5 t when the model
    /// has no minimum).
    pub fn next_step(&self, t: f64) -> f64 {
        let c = (self.value - self.value0 - self.slope0 * t) / (t * t);
        let s = if c > 0.0 {
            -self.slope0 / (2.0 * c)
        } else {
            0.5 * t
        };
        s.clamp(0.1 * t, 0.5 * t)
    }
}

/// The problem's judgement of one trial step.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Verdict {
    /// The trial satisfies the problem's acceptance rule (Armijo or similar).
    pub accepted: bool,
    /// A quadratic model for choosing the next, shorter step; `None` halves the step.
    pub fit: Option<QuadraticFit>,
}

/// Outcome of a backtracking search.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Backtrack {
    /// The accepted step length, or `None` when no trial was accepted.
    pub step: Option<f64>,
    /// Trials evaluated.
    pub trials: usize,
}

/// Backtracking line search: try t = 1, then, while `judge(t)` rejects, a shorter step:
/// half of t after the first trial or when the verdict has no fit, else the clamped
/// minimiser of the verdict's quadratic fit. Stops after `max_trials` trials or when the
/// step falls below [`MIN_STEP`].
pub fn backtrack(max_trials: usize, mut judge: impl FnMut(f64) -> Verdict) -> Backtrack {
    let mut t = 1.0;
    for trial in 0..max_trials {
        let verdict = judge(t);
        if verdict.accepted {
            return Backtrack {
                step: Some(t),
                trials: trial + 1,
            };
        }
        t = match verdict.fit {
            Some(fit) if trial > 0 => fit.next_step(t),
            _ => 0.5 * t,
        };
        if t < MIN_STEP {
            return Backtrack {
                step: None,
                trials: trial + 1,
            };
        }
    }
    Backtrack {
        step: None,
        trials: max_trials,
    }
}

/// What the problem does after its line search found no acceptable step.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rejection {
    /// Compute another direction from the same iterate (e.g. with a fresh factorisation
    /// instead of a lagged one).
    Retry,
    /// End the solve with this status.
    Stop(SolveStatus),
}

/// A nonlinear problem Newton's method can drive. The problem holds the current iterate,
/// its residual and the last direction; the core calls the methods in the order of the
/// module notes.
pub trait NewtonProblem {
    /// Error of bad input or a failed linear solve that ends the solve at once.
    type Error;

    /// Convergence test at the current iterate.
    fn check(&mut self) -> Check;

    /// Compute the Newton direction at the current iterate. `iteration` counts the
    /// directions computed before this one (0 for the first). `Ok(Some(status))` ends the
    /// solve (no usable direction), uncounted.
    fn direction(&mut self, iteration: usize) -> Result<Option<SolveStatus>, Self::Error>;

    /// Evaluate and judge the trial point at step length `t` along the last direction.
    fn trial(&mut self, t: f64) -> Verdict;

    /// Move to the trial point of the accepted step `t` (the last one [`Self::trial`]
    /// evaluated); `Some(status)` ends the solve there (e.g. the step was too short to
    /// make progress).
    fn accept(&mut self, t: f64) -> Option<SolveStatus>;

    /// The line search along the last direction accepted no step.
    fn rejected(&mut self) -> Rejection;
}

/// Limits of one Newton solve.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct NewtonLimits {
    /// Most Newton directions computed.
    pub max_iterations: usize,
    /// Most trial steps per line search.
    pub max_trials: usize,
}

/// Record of one Newton solve.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NewtonRecord {
    /// How the solve ended.
    pub status: SolveStatus,
    /// Newton directions computed (iterations).
    pub iterations: usize,
    /// Line-search trials evaluated over all iterations.
    pub trials: usize,
    /// Accepted steps.
    pub accepted_steps: usize,
    /// Length of the last accepted step (NaN when none was).
    pub last_step: f64,
}

/// Run Newton's method on `problem` within `limits` (see the module notes).
pub fn solve<P: NewtonProblem>(
    problem: &mut P,
    limits: &NewtonLimits,
) -> Result<NewtonRecord, P::Error> {
    let mut record = NewtonRecord {
        status: SolveStatus::IterationLimit,
        iterations: 0,
        trials: 0,
        accepted_steps: 0,
        last_step: f64::NAN,
    };
    record.status = loop {
        match problem.check() {
            Check::Continue => {}
            Check::Converged => break SolveStatus::Converged,
            Check::NotFinite => break SolveStatus::NotFinite,
        }
        if record.iterations >= limits.max_iterations {
            break SolveStatus::IterationLimit;
        }
        if let Some(status) = problem.direction(record.iterations)? {
            break status;
        }
        record.iterations += 1;
        let search = backtrack(limits.max_trials, |t| problem.trial(t));
        record.trials += search.trials;
        match search.step {
            Some(t) => {
                record.accepted_steps += 1;
                record.last_step = t;
                if let Some(status) = problem.accept(t) {
                    break status;
                }
            }
            None => match problem.rejected() {
                Rejection::Retry => {}
                Rejection::Stop(status) => break status,
            },
        }
    };
    Ok(record)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Minimise f(x) = Σ (a_i/2) (x_i − c_i)² + (b/4) Σ (x_i − c_i)⁴ (minimiser c, f = 0) by
    /// Newton with an Armijo rule on f; `stretch` multiplies every direction (1: exact
    /// Newton), so a stretched direction overshoots and the search must backtrack.
    struct QuadQuartic {
        a: Vec<f64>,
        b: f64,
        c: Vec<f64>,
        x: Vec<f64>,
        dir: Vec<f64>,
        trial_x: Vec<f64>,
        stretch: f64,
        steps: Vec<f64>,
    }

    impl QuadQuartic {
        fn new(x: Vec<f64>, stretch: f64) -> Self {
            let n = x.len();
            Self {
                a: (1..=n).map(|i| i as f64).collect(),
                b: 2.0,
                c: (0..n).map(|i| 0.5 - 0.3 * i as f64).collect(),
                x,
                dir: vec![0.0; n],
                trial_x: vec![0.0; n],
                stretch,
                steps: Vec::new(),
            }
        }
        fn f(&self, x: &[f64]) -> f64 {
            (0..x.len())
                .map(|i| {
                    let d = x[i] - self.c[i];
                    0.5 * self.a[i] * d * d + 0.25 * self.b * d.powi(4)
                })
                .sum()
        }
        fn grad(&self, x: &[f64]) -> Vec<f64> {
            (0..x.len())
                .map(|i| {
                    let d = x[i] - self.c[i];
                    self.a[i] * d + self.b * d.powi(3)
                })
                .collect()
        }
    }

    impl NewtonProblem for QuadQuartic {
        type Error = ();
        fn check(&mut self) -> Check {
            let g = self.grad(&self.x);
            let n = g.iter().map(|v| v * v).sum::<f64>().sqrt();
            if !n.is_finite() {
                Check::NotFinite
            } else if n <= 1e-12 {
                Check::Converged
            } else {
                Check::Continue
            }
        }
        fn direction(&mut self, _iteration: usize) -> Result<Option<SolveStatus>, ()> {
            // Diagonal Hessian a_i + 3 b d²: the direction solves it exactly.
            let g = self.grad(&self.x);
            for i in 0..self.x.len() {
                let d = self.x[i] - self.c[i];
                self.dir[i] = -self.stretch * g[i] / (self.a[i] + 3.0 * self.b * d * d);
            }
            Ok(None)
        }
        fn trial(&mut self, t: f64) -> Verdict {
            let g = self.grad(&self.x);
            let slope: f64 = g.iter().zip(&self.dir).map(|(a, b)| a * b).sum();
            for i in 0..self.x.len() {
                self.trial_x[i] = self.x[i] + t * self.dir[i];
            }
            let (f0, ft) = (self.f(&self.x), self.f(&self.trial_x));
            Verdict {
                accepted: ft <= f0 + 1e-4 * t * slope,
                fit: Some(QuadraticFit {
                    value0: f0,
                    slope0: slope,
                    value: ft,
                }),
            }
        }
        fn accept(&mut self, t: f64) -> Option<SolveStatus> {
            self.x.copy_from_slice(&self.trial_x);
            self.steps.push(t);
            None
        }
        fn rejected(&mut self) -> Rejection {
            Rejection::Stop(SolveStatus::LineSearchFailed)
        }
    }

    const LIMITS: NewtonLimits = NewtonLimits {
        max_iterations: 50,
        max_trials: 30,
    };

    #[test]
    fn newton_finds_the_minimiser_of_a_quadratic_plus_quartic() {
        let mut p = QuadQuartic::new(vec![3.0, -2.0, 1.5, 4.0], 1.0);
        let rec = solve(&mut p, &LIMITS).unwrap();
        assert_eq!(rec.status, SolveStatus::Converged);
        assert!(rec.iterations < 15, "{rec:?}");
        for (x, c) in p.x.iter().zip(&p.c) {
            assert!((x - c).abs() < 1e-12, "{x} vs {c}");
        }
        // Near the answer Newton takes full steps (quadratic convergence).
        assert_eq!(p.steps.last(), Some(&1.0));
        assert_eq!(rec.accepted_steps, rec.iterations);
    }

    #[test]
    fn overshooting_directions_make_the_search_backtrack() {
        // Directions 4× too long: on the quadratic part the exact step is t = 1/4, and the
        // quadratic fit of f along the line finds it after t = 1 and t = 1/2 fail.
        let mut p = QuadQuartic::new(vec![1.0, 0.2], 4.0);
        p.b = 0.0;
        let rec = solve(&mut p, &LIMITS).unwrap();
        assert_eq!(rec.status, SolveStatus::Converged);
        assert_eq!(rec.iterations, 1);
        assert_eq!(rec.trials, 3);
        assert!((p.steps[0] - 0.25).abs() < 1e-15);
        // With the quartic (far out, where Newton's own steps are short, a 4× step may
        // still descend) the search backtracks near the answer and converges.
        let mut p = QuadQuartic::new(vec![3.0, -2.0], 4.0);
        let rec = solve(&mut p, &LIMITS).unwrap();
        assert_eq!(rec.status, SolveStatus::Converged, "{rec:?}");
        assert!(p.steps.iter().any(|&t| t < 1.0));
        assert!((p.x[0] - p.c[0]).abs() < 1e-12 && (p.x[1] - p.c[1]).abs() < 1e-12);
        assert!(rec.trials > rec.iterations);
    }

    #[test]
    fn ascent_directions_fail_and_the_limit_stops() {
        // Directions pointing uphill: no step is accepted.
        let mut p = QuadQuartic::new(vec![1.0, 1.0], -1.0);
        let rec = solve(&mut p, &LIMITS).unwrap();
        assert_eq!(rec.status, SolveStatus::LineSearchFailed);
        assert_eq!(rec.iterations, 1);
        assert!(rec.last_step.is_nan());
        // One iteration allowed, not converged after it.
        let mut p = QuadQuartic::new(vec![3.0, -2.0], 1.0);
        let limits = NewtonLimits {
            max_iterations: 1,
            ..LIMITS
        };
        let rec = solve(&mut p, &limits).unwrap();
        assert_eq!(rec.status, SolveStatus::IterationLimit);
        assert_eq!(rec.iterations, 1);
    }

    #[test]
    fn backtrack_halves_without_a_fit() {
        let mut tried = Vec::new();
        let b = backtrack(30, |t| {
            tried.push(t);
            Verdict {
                accepted: t <= 0.1,
                fit: None,
            }
        });
        assert_eq!(b.step, Some(0.0625));
        assert_eq!(tried, [1.0, 0.5, 0.25, 0.125, 0.0625]);
    }
}
