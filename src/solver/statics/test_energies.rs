//! Small energies and problems with known answers that the quasi-static solver's unit tests
//! solve: double wells and a quartic over 6 dofs, and a chain of springs over 5.

use super::{LinearConstraints, StaticProblem};
use crate::math::Energy;

/// E = k Σ (x_i² − w)² / 4 over 6 dofs: a quartic for w = 0; for w > 0 every dof is a
/// double well, its curvature k (3 x_i² − w) negative for |x_i| < √(w/3).
pub(super) struct Wells {
    pub(super) k: f64,
    pub(super) w: f64,
}
/// E = Σ x_i⁴ / 4.
pub(super) const QUARTIC: Wells = Wells { k: 1.0, w: 0.0 };
impl Energy for Wells {
    fn dofs(&self) -> usize {
        6
    }
    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        _p: bool,
    ) -> f64 {
        let (k, w) = (self.k, self.w);
        if let Some(g) = grad {
            for (gi, xi) in g.iter_mut().zip(x) {
                *gi += k * xi * (xi * xi - w);
            }
        }
        if let Some(h) = hess {
            for (i, xi) in x.iter().enumerate() {
                h.push((i, i, k * (3.0 * xi * xi - w)));
            }
        }
        k * x.iter().map(|v| (v * v - w).powi(2) / 4.0).sum::<f64>()
    }
}

/// Springs in series between dofs i and i + 1 of a chain of 5 dofs, with energy
/// E_i(Δ) = k_i (Δ²/2 + quartic · Δ⁴/4) (hardening when quartic > 0).
pub(super) struct SpringChain {
    pub(super) k: [f64; 4],
    pub(super) quartic: f64,
    /// Say the triplet count (16), so the solver scatters its Hessians.
    pub(super) scatters: bool,
}
/// Unit linear springs: E = Σ (x_{i+1} − x_i)² / 2.
pub(super) const LINEAR_CHAIN: SpringChain = SpringChain {
    k: [1.0; 4],
    quartic: 0.0,
    scatters: false,
};
impl Energy for SpringChain {
    fn dofs(&self) -> usize {
        5
    }
    fn triplet_count(&self) -> Option<usize> {
        self.scatters.then_some(16)
    }
    fn eval(
        &self,
        x: &[f64],
        grad: Option<&mut [f64]>,
        hess: Option<&mut Vec<(usize, usize, f64)>>,
        _p: bool,
    ) -> f64 {
        let (k, c) = (self.k, self.quartic);
        let d: Vec<f64> = (0..4).map(|i| x[i + 1] - x[i]).collect();
        if let Some(g) = grad {
            for i in 0..4 {
                let f = k[i] * (d[i] + c * d[i].powi(3));
                g[i] -= f;
                g[i + 1] += f;
            }
        }
        if let Some(h) = hess {
            for i in 0..4 {
                let s = k[i] * (1.0 + 3.0 * c * d[i] * d[i]);
                h.extend([(i, i, s), (i + 1, i + 1, s), (i, i + 1, -s), (i + 1, i, -s)]);
            }
        }
        (0..4)
            .map(|i| k[i] * (d[i].powi(2) / 2.0 + c * d[i].powi(4) / 4.0))
            .sum()
    }
}

/// The [`QUARTIC`]'s test problem: x0 pinned, x1 + x2 = 2, forces 8 on x3 and −1 on x4.
pub(super) fn quartic_problem() -> StaticProblem {
    StaticProblem {
        pinned: vec![0],
        constraints: LinearConstraints {
            rows: 1,
            entries: vec![(0, 1, 1.0), (0, 2, 1.0)],
            rhs: vec![2.0],
        },
        forces: vec![0.0, 0.0, 0.0, 8.0, -1.0, 0.0],
    }
}
