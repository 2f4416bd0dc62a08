//! The per-frame activation QP, solved with clarabel:
//!
//!   min_a ½‖J a − d‖² + λ_s ‖a‖² + λ_t ‖a − a_prev‖²   subject to  lo ≤ a ≤ hi,
//!
//! given through the normal equations: P = JᵀJ + 2(λ_s + λ_t) I, q = −Jᵀd − 2 λ_t a_prev
//! (J in m per unit activation, d in m, λ in m²). Clarabel's interior-point answer is then
//! polished: the bounds it meets (within 10⁻⁶ of the range) are fixed, the reduced normal
//! equations are solved exactly (dense Cholesky) and the result is accepted when it meets the
//! KKT conditions (free activations inside their bounds, multipliers of the fixed ones with
//! the right sign). Either way the returned activations are clamped to the bounds, so bounds
//! hold exactly.

use crate::solver::SolveStatus;
use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

/// One QP: the normal-equation data of the least-squares term and the regularisation.
#[derive(Debug, Clone, Copy)]
pub struct QpProblem<'a> {
    /// JᵀJ, m × m row-major (m² per unit activation²).
    pub jtj: &'a [f64],
    /// Jᵀd, length m (m² per unit activation).
    pub jtd: &'a [f64],
    /// Size weight λ_s (m²).
    pub lambda_size: f64,
    /// Temporal weight λ_t (m²).
    pub lambda_time: f64,
    /// Previous frame's activations (length m).
    pub previous: &'a [f64],
    /// Bounds [lo, hi] per activation.
    pub bounds: &'a [[f64; 2]],
}

/// How clarabel's status maps onto the solver outcome: `Solved` and `AlmostSolved` answer
/// the QP; the rest leave no answer.
pub fn outcome_of(status: SolverStatus) -> SolveStatus {
    match status {
        SolverStatus::Solved | SolverStatus::AlmostSolved => SolveStatus::Converged,
        SolverStatus::MaxIterations | SolverStatus::MaxTime => SolveStatus::IterationLimit,
        SolverStatus::PrimalInfeasible
        | SolverStatus::DualInfeasible
        | SolverStatus::AlmostPrimalInfeasible
        | SolverStatus::AlmostDualInfeasible => SolveStatus::Infeasible,
        SolverStatus::InsufficientProgress => SolveStatus::Stalled,
        _ => SolveStatus::Failed,
    }
}

/// The answer of one QP.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct QpSolution {
    /// Activations (within bounds), or empty when the QP failed.
    pub activations: Vec<f64>,
    /// `Converged` when the answer is used; otherwise why there is none.
    pub status: SolveStatus,
    /// Clarabel's own status, as it names it (e.g. "Solved", "AlmostSolved", "MaxIterations").
    pub clarabel_status: String,
    /// Clarabel's interior-point iterations.
    pub iterations: u32,
    /// Whether the exact active-set polish was accepted.
    pub polished: bool,
}

/// Solve one activation QP (see the module notes).
pub fn solve_qp(p: &QpProblem) -> QpSolution {
    let m = p.jtd.len();
    let failed = |outcome: SolveStatus, status: String, it: u32| QpSolution {
        activations: Vec::new(),
        status: outcome,
        clarabel_status: status,
        iterations: it,
        polished: false,
    };
    if m == 0 {
        return QpSolution {
            activations: Vec::new(),
            status: SolveStatus::Converged,
            clarabel_status: "Empty".into(),
            iterations: 0,
            polished: true,
        };
    }
    let reg = 2.0 * (p.lambda_size + p.lambda_time);
    let hess = |i: usize, j: usize| p.jtj[i * m + j] + if i == j { reg } else { 0.0 };
    let lin: Vec<f64> = (0..m)
        .map(|i| -p.jtd[i] - 2.0 * p.lambda_time * p.previous[i])
        .collect();
    if (0..m * m).any(|k| !p.jtj[k].is_finite()) || lin.iter().any(|v| !v.is_finite()) {
        return failed(SolveStatus::NotFinite, "NonFiniteData".into(), 0);
    }
    // Scale the objective to order one (clarabel's tolerances are absolute and relative).
    let scale = (0..m).map(|i| hess(i, i)).fold(0.0f64, f64::max);
    let scale = if scale > 0.0 && scale.is_finite() {
        1.0 / scale
    } else {
        1.0
    };
    // Upper triangle of P, column by column.
    let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
    for j in 0..m {
        for i in 0..=j {
            rowval.push(i);
            nzval.push(hess(i, j) * scale);
        }
        colptr.push(rowval.len());
    }
    let pm = CscMatrix::new(m, m, colptr, rowval, nzval);
    let q: Vec<f64> = lin.iter().map(|v| v * scale).collect();
    // A = [I; −I], b = [hi; −lo], s ≥ 0.
    let (mut colptr, mut rowval, mut nzval) = (vec![0usize], Vec::new(), Vec::new());
    for j in 0..m {
        rowval.extend([j, m + j]);
        nzval.extend([1.0, -1.0]);
        colptr.push(rowval.len());
    }
    let am = CscMatrix::new(2 * m, m, colptr, rowval, nzval);
    let b: Vec<f64> = p
        .bounds
        .iter()
        .map(|bd| bd[1])
        .chain(p.bounds.iter().map(|bd| -bd[0]))
        .collect();
    let cones = [SupportedConeT::NonnegativeConeT(2 * m)];
    let settings = DefaultSettingsBuilder::default()
        .verbose(false)
        .presolve_enable(false)
        .tol_gap_abs(1e-10)
        .tol_gap_rel(1e-10)
        .tol_feas(1e-10)
        .max_iter(100)
        .build()
        .expect("valid clarabel settings");
    let mut solver = match DefaultSolver::new(&pm, &q, &am, &b, &cones, settings) {
        Ok(s) => s,
        Err(e) => return failed(SolveStatus::Failed, format!("SetupError({e})"), 0),
    };
    solver.solve();
    let sol = &solver.solution;
    let status = format!("{:?}", sol.status);
    let outcome = outcome_of(sol.status);
    if !outcome.is_converged() {
        return failed(outcome, status, sol.iterations);
    }
    if sol.x.iter().any(|v| !v.is_finite()) {
        return failed(SolveStatus::NotFinite, status, sol.iterations);
    }
    let clamp = |a: &mut Vec<f64>| {
        for (v, bd) in a.iter_mut().zip(p.bounds) {
            *v = v.clamp(bd[0], bd[1]);
        }
    };
    let mut a = sol.x.clone();
    clamp(&mut a);
    let polished = polish(p, &hess, &lin, &a);
    let is_polished = polished.is_some();
    let mut a = polished.unwrap_or(a);
    clamp(&mut a);
    QpSolution {
        activations: a,
        status: SolveStatus::Converged,
        clarabel_status: status,
        iterations: sol.iterations,
        polished: is_polished,
    }
}

/// Exact solve on the active set guessed from `a`; `None` when the guess fails the KKT
/// conditions or the reduced matrix is singular.
fn polish(
    p: &QpProblem,
    hess: &dyn Fn(usize, usize) -> f64,
    lin: &[f64],
    a: &[f64],
) -> Option<Vec<f64>> {
    let m = a.len();
    // 0 free, −1 at lower, +1 at upper.
    let side: Vec<i8> = (0..m)
        .map(|i| {
            let [lo, hi] = p.bounds[i];
            let tol = 1e-6 * (hi - lo).max(1e-12);
            if hi - lo <= 1e-12 || a[i] - lo <= tol {
                -1
            } else if hi - a[i] <= tol {
                1
            } else {
                0
            }
        })
        .collect();
    let free: Vec<usize> = (0..m).filter(|&i| side[i] == 0).collect();
    let mut x: Vec<f64> = (0..m)
        .map(|i| match side[i] {
            -1 => p.bounds[i][0],
            1 => p.bounds[i][1],
            _ => 0.0,
        })
        .collect();
    if !free.is_empty() {
        let nf = free.len();
        let h = DMatrix::from_fn(nf, nf, |r, c| hess(free[r], free[c]));
        let rhs = DVector::from_fn(nf, |r, _| {
            let i = free[r];
            -lin[i]
                - (0..m)
                    .filter(|&j| side[j] != 0)
                    .map(|j| hess(i, j) * x[j])
                    .sum::<f64>()
        });
        let chol = nalgebra::Cholesky::new(h.clone())?;
        // Reject nearly singular reduced systems (rank-deficient J without regularisation).
        let d = chol.l().diagonal();
        let (dmin, dmax) = d.iter().fold((f64::INFINITY, 0.0f64), |(lo, hi), v| {
            (lo.min(*v), hi.max(*v))
        });
        if dmin.is_nan() || dmin <= 1e-7 * dmax {
            return None;
        }
        let sol = chol.solve(&rhs);
        for (r, &i) in free.iter().enumerate() {
            x[i] = sol[r];
        }
    }
    let scale: f64 = (0..m)
        .map(|i| hess(i, i).abs())
        .fold(0.0, f64::max)
        .max(1e-300);
    for i in 0..m {
        let [lo, hi] = p.bounds[i];
        let tol = 1e-9 * (hi - lo).abs().max(1.0);
        if !x[i].is_finite() || x[i] < lo - tol || x[i] > hi + tol {
            return None;
        }
        let grad: f64 = (0..m).map(|j| hess(i, j) * x[j]).sum::<f64>() + lin[i];
        let gtol = 1e-9 * scale * (1.0 + x.iter().map(|v| v.abs()).fold(0.0, f64::max));
        // At the lower bound the objective may only rise inwards (grad ≥ 0), at the upper
        // bound grad ≤ 0.
        match side[i] {
            -1 if p.bounds[i][1] > p.bounds[i][0] && grad < -gtol => return None,
            1 if grad > gtol => return None,
            _ => {}
        }
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 2-variable QP with a known answer: min ½‖a − t‖², t = (0.3, 1.7), bounds [0, 1]:
    /// a = (0.3, 1), exactly, polished.
    #[test]
    fn box_projection_is_exact() {
        let jtj = [1.0, 0.0, 0.0, 1.0];
        let jtd = [0.3, 1.7];
        let p = QpProblem {
            jtj: &jtj,
            jtd: &jtd,
            lambda_size: 0.0,
            lambda_time: 0.0,
            previous: &[0.0, 0.0],
            bounds: &[[0.0, 1.0], [0.0, 1.0]],
        };
        let s = solve_qp(&p);
        assert_eq!(s.status, SolveStatus::Converged);
        assert!(s.polished);
        assert!((s.activations[0] - 0.3).abs() < 1e-14);
        assert_eq!(s.activations[1], 1.0);
    }
}
