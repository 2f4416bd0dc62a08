//! Finite-difference checks of analytic gradients and Hessians.
//!
//! Central differences with a sweep of step sizes; the reported error is the best over the
//! sweep, because truncation error falls and round-off error grows as the step shrinks.

use super::energy::Energy;
use super::sparse::dense_from_triplets;
use super::vector::norm;

/// Result of a finite-difference comparison: the best relative error over the step sweep and
/// the step (in the units of `x`) at which it was reached.
#[derive(Debug, Clone, Copy)]
pub struct FdReport {
    /// ‖analytic − numeric‖ / max(‖analytic‖, ‖numeric‖, tiny), at the best step.
    pub rel_error: f64,
    /// The step size giving `rel_error`.
    pub step: f64,
}

const STEPS: [f64; 7] = [1e-2, 3e-3, 1e-3, 3e-4, 1e-4, 3e-5, 1e-5];

fn rel(a: &[f64], b: &[f64]) -> f64 {
    let diff: f64 = a
        .iter()
        .zip(b)
        .map(|(x, y)| (x - y).powi(2))
        .sum::<f64>()
        .sqrt();
    let (na, nb) = (norm(a), norm(b));
    diff / na.max(nb).max(1e-300)
}

/// Compare the analytic gradient of `e` at `x` with central differences of its value.
/// `scale` is a length typical of `x` (steps are `scale × {1e-2 … 1e-5}`).
pub fn check_gradient(e: &dyn Energy, x: &[f64], scale: f64) -> FdReport {
    let n = x.len();
    let mut g = vec![0.0; n];
    e.eval(x, Some(&mut g), None, false);
    let mut best = FdReport {
        rel_error: f64::INFINITY,
        step: 0.0,
    };
    let mut xp = x.to_vec();
    for s in STEPS {
        let h = s * scale;
        let mut num = vec![0.0; n];
        for i in 0..n {
            xp[i] = x[i] + h;
            let ep = e.eval(&xp, None, None, false);
            xp[i] = x[i] - h;
            let em = e.eval(&xp, None, None, false);
            xp[i] = x[i];
            num[i] = (ep - em) / (2.0 * h);
        }
        let r = rel(&g, &num);
        if r < best.rel_error {
            best = FdReport {
                rel_error: r,
                step: h,
            };
        }
    }
    best
}

/// Compare the analytic Hessian of `e` at `x` (unprojected) with central differences of its
/// analytic gradient.
pub fn check_hessian(e: &dyn Energy, x: &[f64], scale: f64) -> FdReport {
    let n = x.len();
    let mut trip = Vec::new();
    e.eval(x, None, Some(&mut trip), false);
    let h_an = dense_from_triplets(n, &trip);
    let mut best = FdReport {
        rel_error: f64::INFINITY,
        step: 0.0,
    };
    let mut xp = x.to_vec();
    for s in STEPS {
        let h = s * scale;
        let mut num = vec![0.0; n * n];
        for j in 0..n {
            let mut gp = vec![0.0; n];
            let mut gm = vec![0.0; n];
            xp[j] = x[j] + h;
            e.eval(&xp, Some(&mut gp), None, false);
            xp[j] = x[j] - h;
            e.eval(&xp, Some(&mut gm), None, false);
            xp[j] = x[j];
            for i in 0..n {
                num[i * n + j] = (gp[i] - gm[i]) / (2.0 * h);
            }
        }
        let r = rel(&h_an, &num);
        if r < best.rel_error {
            best = FdReport {
                rel_error: r,
                step: h,
            };
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A quartic with a known gradient and Hessian: E = Σ x_i⁴ / 4 + x_0 x_1.
    struct Quartic;
    impl Energy for Quartic {
        fn dofs(&self) -> usize {
            3
        }
        fn eval(
            &self,
            x: &[f64],
            grad: Option<&mut [f64]>,
            hess: Option<&mut Vec<(usize, usize, f64)>>,
            _psd: bool,
        ) -> f64 {
            if let Some(g) = grad {
                for i in 0..3 {
                    g[i] += x[i].powi(3);
                }
                g[0] += x[1];
                g[1] += x[0];
            }
            if let Some(h) = hess {
                for i in 0..3 {
                    h.push((i, i, 3.0 * x[i] * x[i]));
                }
                h.push((0, 1, 1.0));
                h.push((1, 0, 1.0));
            }
            x.iter().map(|v| v.powi(4) / 4.0).sum::<f64>() + x[0] * x[1]
        }
    }

    /// The same quartic with a wrong Hessian, which the checker must catch.
    struct WrongHessian;
    impl Energy for WrongHessian {
        fn dofs(&self) -> usize {
            3
        }
        fn eval(
            &self,
            x: &[f64],
            grad: Option<&mut [f64]>,
            hess: Option<&mut Vec<(usize, usize, f64)>>,
            psd: bool,
        ) -> f64 {
            let v = Quartic.eval(x, grad, None, psd);
            if let Some(h) = hess {
                for i in 0..3 {
                    h.push((i, i, 2.0 * x[i] * x[i]));
                }
            }
            v
        }
    }

    #[test]
    fn checker_accepts_correct_derivatives_and_rejects_wrong_ones() {
        let x = [0.3, -0.7, 1.1];
        assert!(check_gradient(&Quartic, &x, 1.0).rel_error < 1e-8);
        assert!(check_hessian(&Quartic, &x, 1.0).rel_error < 1e-8);
        assert!(check_hessian(&WrongHessian, &x, 1.0).rel_error > 1e-2);
    }
}
