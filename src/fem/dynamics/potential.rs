//! The incremental potential Φ of one minimisation (inertia, elastic energy, applied force
//! and coupling terms) and its gradient, the residual norm over free DOFs, and the force
//! scale its tolerance applies to.

use super::{BackwardEuler, ExtraTerms};
use crate::math::Energy;
use std::time::Instant;

/// The fixed terms of one minimisation of Φ: the positions at the start of the step x0 (m),
/// the inertia target y₀ + h v (m) and time step h (s) (`None`: quasi-static), the applied
/// force f_ext + f_g (N, flat) and the coupling terms.
#[derive(Clone, Copy)]
pub(super) struct Terms<'a> {
    pub(super) x0: &'a [f64],
    pub(super) inertia: Option<(&'a [f64], f64)>,
    pub(super) force: &'a [f64],
    pub(super) extra: Option<&'a ExtraTerms<'a>>,
}

impl Terms<'_> {
    /// Coefficients (of M, of K) of the Newton matrix: (1, h²) for a time step, (0, 1)
    /// quasi-static.
    pub(super) fn coefficients(&self) -> (f64, f64) {
        match self.inertia {
            Some((_, h)) => (1.0, h * h),
            None => (0.0, 1.0),
        }
    }
}

impl BackwardEuler {
    /// Φ and ∇Φ at y (timed into `self.eval_clock`); the gradient is empty unless
    /// `want_grad`.
    pub(super) fn potential(&self, terms: &Terms, y: &[f64], want_grad: bool) -> (f64, Vec<f64>) {
        let t = Instant::now();
        let out = self.potential_raw(terms, y, want_grad);
        let (s, n) = self.eval_clock.get();
        self.eval_clock.set((s + t.elapsed().as_secs_f64(), n + 1));
        out
    }

    fn potential_raw(&self, terms: &Terms, y: &[f64], want_grad: bool) -> (f64, Vec<f64>) {
        let (x0, force) = (terms.x0, terms.force);
        let n = y.len();
        let mut g = if want_grad { vec![0.0; n] } else { Vec::new() };
        let mut phi = if want_grad {
            let mut cache = self.rot_cache.borrow_mut();
            let (at, rot) = &mut *cache;
            let e = self.interior.eval_with_rotations(y, &mut g, rot);
            at.clear();
            at.extend_from_slice(y);
            e
        } else {
            self.interior.eval(y, None, None, false)
        };
        if let Some((target, h)) = terms.inertia {
            let d: Vec<f64> = y.iter().zip(target).map(|(a, b)| a - b).collect();
            let md = self.mass_times(&d);
            let inv = 1.0 / (h * h);
            phi += 0.5 * inv * d.iter().zip(&md).map(|(a, b)| a * b).sum::<f64>();
            if want_grad {
                for i in 0..n {
                    g[i] += inv * md[i];
                }
            }
        }
        for i in 0..n {
            phi -= force[i] * y[i];
            if want_grad {
                g[i] -= force[i];
            }
        }
        if let Some(x) = terms.extra {
            let dy: Vec<f64> = y.iter().zip(x0).map(|(a, b)| a - b).collect();
            let mut kd = vec![0.0; n];
            for &(r, c, v) in x.stiffness {
                kd[r] += v * dy[c];
            }
            for i in 0..n {
                phi += -x.force[i] * dy[i] + 0.5 * dy[i] * kd[i];
                if want_grad {
                    g[i] += -x.force[i] + kd[i];
                }
            }
        }
        (phi, g)
    }

    pub(super) fn free_norm(&self, g: &[f64]) -> f64 {
        let mut s = 0.0;
        for n in 0..self.interior.nodes {
            if !self.pinned[n] {
                for i in 0..3 {
                    s += g[3 * n + i] * g[3 * n + i];
                }
            }
        }
        s.sqrt()
    }

    /// Force scale (N) the tolerance applies to, given the first residual `res`: the larger
    /// of it, the applied forces, and (floor) the force that strains one cell face by 1e-3 —
    /// so a state already at rest counts as converged instead of chasing round-off.
    pub(super) fn reference_force(&self, res: f64, terms: &Terms) -> f64 {
        let mut applied = self.free_norm(terms.force);
        if let Some(x) = terms.extra {
            applied += self.free_norm(x.force);
        }
        let cell_force = 1e-3 * self.interior.mu * self.interior.cell_size.powi(2);
        res.max(applied).max(cell_force)
    }
}
