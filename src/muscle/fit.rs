//! Fitting muscle activations to blend-shape frames.
//!
//! Per frame, with d the target displacement of the surface vertices from the neutral face
//! (m) and J the linearised map from activations to surface displacement (J = B ∂q/∂a, B the
//! embedding, computed once at rest by one factorisation and one solve per muscle, or the
//! muscles' measured responses at activation 1 when their actuation fit gives them,
//! [`Calibration`]); in the pipeline's interior, d first loses what the tracking's own pull
//! makes, B K_p⁻¹ Bᵀ k d ([`Fitter::coupled`]):
//!
//! 1. solve the QP min ½‖J a − d‖² + λ_s‖a‖² + λ_t‖a − a_prev‖², bounds ([`super::qp`]);
//! 2. Gauss–Newton, `gauss_newton` times: solve the nonlinear equilibrium q(a_k) (Newton,
//!    warm-started from the previous frame's lattice state), re-linearise J_k at q(a_k),
//!    and solve the QP for the step with the residual r_k = d − B(q(a_k) − q_rest):
//!    min ½‖J_k a − (r_k + J_k a_k)‖² + …;
//! 3. report the RMS surface residual (m): of the linear model when `gauss_newton` is 0,
//!    else of the nonlinear equilibrium at the final activations.
//!
//! λ_s and λ_t are given relative to the mean squared column norm of the rest J
//! (dimensionless `size_weight`, `time_weight`), so they do not depend on the mesh size or
//! units. A frame whose QP fails keeps the last good activations and says so.

use super::forward::{Coupling, Forward, ForwardReport};
use super::jaw::JawBone;
use super::model::Muscle;
use super::qp::{solve_qp, QpProblem, QpSolution};
use super::MuscleError;
use crate::coupling::embedding::Embedding;
use crate::fem::{Interior, Material};
use crate::lattice::Lattice;
use crate::solver::SolveStatus;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::time::Instant;

type V3 = Vector3<f64>;

/// Settings of the activation fit.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FitSettings {
    /// λ_s relative to the mean ‖J_m‖² (dimensionless, ≥ 0): prefers small activations and
    /// picks one answer when J is rank-deficient.
    pub size_weight: f64,
    /// λ_t relative to the mean ‖J_m‖² (dimensionless, ≥ 0): prefers activations close to
    /// the previous frame's.
    pub time_weight: f64,
    /// Gauss–Newton re-linearisations with the nonlinear forward model per frame (0: the
    /// linear model only).
    pub gauss_newton: usize,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            size_weight: 1e-4,
            time_weight: 1e-3,
            gauss_newton: 0,
        }
    }
}

impl FitSettings {
    /// Check the fields; the error names the one that is wrong.
    pub fn validate(&self) -> Result<(), MuscleError> {
        for (field, v) in [
            ("size_weight", self.size_weight),
            ("time_weight", self.time_weight),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(MuscleError::Settings {
                    field,
                    msg: format!("must be a finite number ≥ 0, got {v}"),
                });
            }
        }
        if self.gauss_newton > 50 {
            return Err(MuscleError::Settings {
                field: "gauss_newton",
                msg: format!("at most 50 re-linearisations, got {}", self.gauss_newton),
            });
        }
        Ok(())
    }
}

/// What the actuation fit measured of each muscle in the pipeline's interior, for the
/// activation fit to use (one entry per muscle, or none).
#[derive(Debug, Clone, Default)]
pub struct Calibration {
    /// Each muscle's response at activation 1 (node displacements, flat, m): the rest J's
    /// columns in place of the linearised response.
    pub responses: Vec<Vec<f64>>,
}

/// What happened to a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum FrameStatus {
    /// Activations fitted.
    Fitted,
    /// The QP failed; the previous frame's activations were kept.
    QpFailedKeptPrevious,
    /// A Gauss–Newton QP failed; the last good activations of this frame were kept.
    GaussNewtonStopped,
    /// The target has a non-finite coordinate; the previous activations were kept.
    InvalidTarget,
}

/// The fit of one frame.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FrameFit {
    /// Activations, one per muscle (dimensionless).
    pub activations: Vec<f64>,
    /// RMS distance (m) between the fitted surface and the target over the vertices.
    pub rms_residual: f64,
    /// RMS displacement (m) of the target from the neutral face over the vertices: the scale
    /// `rms_residual` is judged against.
    pub rms_displacement: f64,
    /// Outcome.
    pub status: FrameStatus,
    /// The outcome of the frame's last QP (`NotFinite` for a target with a non-finite
    /// coordinate, where no QP ran).
    pub qp_status: SolveStatus,
    /// Clarabel's own name for the last QP's status, for the user.
    pub clarabel_status: String,
    /// Gauss–Newton re-linearisations done.
    pub gauss_newton: usize,
    /// The last equilibrium solve (with Gauss–Newton only).
    pub forward: Option<ForwardReport>,
    /// Time spent in QPs (s).
    pub qp_s: f64,
    /// Time for the whole frame (s).
    pub total_s: f64,
}

/// The activation fitter of one lattice and muscle set.
pub struct Fitter {
    /// The forward model (interior + muscles).
    pub forward: Forward,
    /// Fit settings.
    pub settings: FitSettings,
    /// Absolute λ_s (m²).
    pub lambda_size: f64,
    /// Absolute λ_t (m²).
    pub lambda_time: f64,
    /// Time spent computing the rest Jacobian (s).
    pub jacobian_s: f64,
    /// The embedding B of the lattice's surface vertices.
    embed: Embedding,
    vertices: usize,
    rest_surface: Vec<f64>,
    /// Rest J, column-major (3V × m), m per unit activation.
    j0: Vec<f64>,
    jtj0: Vec<f64>,
    prev_a: Vec<f64>,
    prev_q: Vec<f64>,
}

/// Activation bounds of the muscles.
fn bounds_of(muscles: &[Muscle]) -> Vec<[f64; 2]> {
    muscles.iter().map(|m| m.bounds).collect()
}

impl Fitter {
    /// A fitter for `muscles` in `lattice` made of `material`: builds the interior and the
    /// rest Jacobian (one factorisation, one solve per muscle).
    pub fn new(
        lattice: &Lattice,
        material: &Material,
        muscles: Vec<Muscle>,
        settings: FitSettings,
    ) -> Result<Self, MuscleError> {
        Self::coupled(lattice, material, muscles, settings, None, None, None)
    }

    /// [`Self::new`] in the interior the pipeline runs: with the tracking's `coupling`,
    /// J = B K_p⁻¹ F includes its stiffness (or J's columns are the `calibration`'s measured
    /// responses), and each frame's target is first relieved of what the tracking's pull
    /// alone makes, B K_p⁻¹ Bᵀ k d (one solve with the rest factorisation), so that
    /// activations fit the rest. The jaw's `bone` and the muscle that turns it
    /// ([`Forward::bone`]) are in the forward model before J is taken, so a linearised J
    /// carries the bone's turn too.
    pub fn coupled(
        lattice: &Lattice,
        material: &Material,
        muscles: Vec<Muscle>,
        settings: FitSettings,
        coupling: Option<Coupling>,
        calibration: Option<Calibration>,
        bone: Option<(usize, JawBone)>,
    ) -> Result<Self, MuscleError> {
        let responses = calibration.map(|c| c.responses).unwrap_or_default();
        settings.validate()?;
        let interior = Interior::new(lattice, material)?;
        let rest = lattice.rest_flat();
        let mut forward = Forward::new(interior, muscles, rest.clone(), lattice.pinned.clone())?;
        if let Some(c) = coupling {
            forward = forward.with_coupling(c);
        }
        forward.bone = bone;
        let m = forward.muscles().len();
        if !responses.is_empty() && responses.len() != m {
            return Err(MuscleError::Input(format!(
                "{} responses for {m} muscles",
                responses.len()
            )));
        }
        let embed = Embedding::of_lattice(lattice);
        let vertices = lattice.vertex_points.len();
        let mut f = Self {
            forward,
            settings,
            lambda_size: 0.0,
            lambda_time: 0.0,
            jacobian_s: 0.0,
            embed,
            vertices,
            rest_surface: Vec::new(),
            j0: Vec::new(),
            jtj0: Vec::new(),
            prev_a: Vec::new(),
            prev_q: rest.clone(),
        };
        f.rest_surface = f.surface(&rest);
        let t = Instant::now();
        let m = f.forward.muscles().len();
        let a0 = vec![0.0; m];
        let cols = if responses.is_empty() {
            f.forward.response(&rest, &a0)?
        } else {
            responses
        };
        f.j0 = f.surface_columns(&cols);
        f.jtj0 = f.gram(&f.j0);
        f.jacobian_s = t.elapsed().as_secs_f64();
        let mean = if m > 0 {
            (0..m).map(|i| f.jtj0[i * m + i]).sum::<f64>() / m as f64
        } else {
            0.0
        };
        f.lambda_size = settings.size_weight * mean;
        f.lambda_time = settings.time_weight * mean;
        f.prev_a = f
            .forward
            .muscles()
            .iter()
            .map(|mu| 0.0f64.clamp(mu.bounds[0], mu.bounds[1]))
            .collect();
        Ok(f)
    }

    /// The muscles.
    pub fn muscles(&self) -> &[Muscle] {
        self.forward.muscles()
    }

    /// Number of surface vertices.
    pub fn vertex_count(&self) -> usize {
        self.vertices
    }

    /// Forget the previous frame (activations to zero within bounds, lattice at rest).
    pub fn reset(&mut self) {
        self.prev_a = self
            .forward
            .muscles()
            .iter()
            .map(|mu| 0.0f64.clamp(mu.bounds[0], mu.bounds[1]))
            .collect();
        self.prev_q = self.forward.rest.clone();
    }

    /// Embedded surface B q (flat, 3V, m).
    fn surface(&self, q: &[f64]) -> Vec<f64> {
        self.embed.positions_flat(q)
    }

    /// B applied to each node-space column, concatenated column-major (3V × m).
    fn surface_columns(&self, cols: &[Vec<f64>]) -> Vec<f64> {
        cols.par_iter().flat_map_iter(|c| self.surface(c)).collect()
    }

    /// JᵀJ (m × m, row-major) of a column-major J with 3V rows.
    fn gram(&self, j: &[f64]) -> Vec<f64> {
        let r = 3 * self.vertices;
        let m = j.len().checked_div(r).unwrap_or(0);
        let rows: Vec<Vec<f64>> = (0..m)
            .into_par_iter()
            .map(|a| {
                let ca = &j[a * r..(a + 1) * r];
                (0..m)
                    .map(|b| {
                        let cb = &j[b * r..(b + 1) * r];
                        ca.iter().zip(cb).map(|(x, y)| x * y).sum()
                    })
                    .collect()
            })
            .collect();
        rows.concat()
    }

    fn jt_times(&self, j: &[f64], d: &[f64]) -> Vec<f64> {
        let r = d.len();
        j.par_chunks(r.max(1))
            .map(|c| c.iter().zip(d).map(|(x, y)| x * y).sum())
            .collect()
    }

    fn j_times(&self, j: &[f64], a: &[f64]) -> Vec<f64> {
        let r = 3 * self.vertices;
        let mut out = vec![0.0; r];
        for (m, &am) in a.iter().enumerate() {
            if am != 0.0 {
                out.iter_mut()
                    .zip(&j[m * r..(m + 1) * r])
                    .for_each(|(o, v)| *o += am * v);
            }
        }
        out
    }

    fn rms(&self, r: &[f64]) -> f64 {
        if self.vertices == 0 {
            return 0.0;
        }
        (r.iter().map(|v| v * v).sum::<f64>() / self.vertices as f64).sqrt()
    }

    /// Surface (m, one point per vertex) of the linear model at activations `a`:
    /// rest + J a.
    pub fn predict_linear(&self, a: &[f64]) -> Vec<V3> {
        let d = self.j_times(&self.j0, a);
        self.rest_surface
            .chunks_exact(3)
            .zip(d.chunks_exact(3))
            .map(|(p, u)| V3::new(p[0] + u[0], p[1] + u[1], p[2] + u[2]))
            .collect()
    }

    /// The tracking's pull Bᵀ k d (N, flat over node dofs) towards surface displacements `d`
    /// (flat, m), when the fitter stands for a pipeline with tracking.
    fn tracking_load(&self, d: &[f64]) -> Option<Vec<f64>> {
        let c = self.forward.coupling.as_ref()?;
        if c.tracking.is_empty() {
            return None;
        }
        Some(c.tracking_load(&self.embed, d))
    }

    /// Surface (m) of the nonlinear equilibrium at activations `a` (solved from rest).
    pub fn predict(&mut self, a: &[f64]) -> Result<(Vec<V3>, ForwardReport), MuscleError> {
        let rest = self.forward.rest.clone();
        let (q, rep) = self.forward.equilibrium(a, &rest)?;
        let x = self.surface(&q);
        Ok((
            x.chunks_exact(3)
                .map(|p| V3::new(p[0], p[1], p[2]))
                .collect(),
            rep,
        ))
    }

    fn qp(&self, jtj: &[f64], jtd: &[f64], bounds: &[[f64; 2]]) -> QpSolution {
        solve_qp(&QpProblem {
            jtj,
            jtd,
            lambda_size: self.lambda_size,
            lambda_time: self.lambda_time,
            previous: &self.prev_a,
            bounds,
        })
    }

    /// Fit one frame whose target surface is `target` (m, one point per vertex, in the
    /// vertex order of the lattice's mesh). Numerical failures are statuses; errors are
    /// only for input of the wrong size.
    pub fn fit_frame(&mut self, target: &[V3]) -> Result<FrameFit, MuscleError> {
        let t0 = Instant::now();
        if target.len() != self.vertices {
            return Err(MuscleError::Input(format!(
                "the target has {} vertices, the face {}",
                target.len(),
                self.vertices
            )));
        }
        let bounds = bounds_of(self.forward.muscles());
        let mut fit = FrameFit {
            activations: self.prev_a.clone(),
            rms_residual: f64::NAN,
            rms_displacement: f64::NAN,
            status: FrameStatus::Fitted,
            qp_status: SolveStatus::Converged,
            clarabel_status: String::new(),
            gauss_newton: 0,
            forward: None,
            qp_s: 0.0,
            total_s: 0.0,
        };
        let d: Vec<f64> = target
            .iter()
            .zip(self.rest_surface.chunks_exact(3))
            .flat_map(|(p, r)| [p.x - r[0], p.y - r[1], p.z - r[2]])
            .collect();
        if d.iter().any(|v| !v.is_finite()) {
            fit.status = FrameStatus::InvalidTarget;
            fit.qp_status = SolveStatus::NotFinite;
            fit.clarabel_status = "NotRun".into();
            fit.rms_residual = f64::INFINITY;
            fit.total_s = t0.elapsed().as_secs_f64();
            return Ok(fit);
        }
        fit.rms_displacement = self.rms(&d);
        let load = self.tracking_load(&d);
        let d_full = d.clone();
        let tracked = match &load {
            Some(f) => {
                let y = self.forward.solve_at_rest(f)?;
                self.surface(&y)
            }
            None => vec![0.0; d.len()],
        };
        let d: Vec<f64> = d.iter().zip(&tracked).map(|(a, b)| a - b).collect();
        let tq = Instant::now();
        let jtd = self.jt_times(&self.j0, &d);
        let sol = self.qp(&self.jtj0, &jtd, &bounds);
        fit.qp_s += tq.elapsed().as_secs_f64();
        fit.clarabel_status = sol.clarabel_status.clone();
        fit.qp_status = sol.status;
        let mut a = match sol.status {
            SolveStatus::Converged => sol.activations,
            _ => {
                fit.status = FrameStatus::QpFailedKeptPrevious;
                self.prev_a.clone()
            }
        };
        let mut residual = {
            let ja = self.j_times(&self.j0, &a);
            let r: Vec<f64> = d.iter().zip(&ja).map(|(x, y)| x - y).collect();
            self.rms(&r)
        };
        if self.settings.gauss_newton > 0 && fit.status == FrameStatus::Fitted {
            let mut q_start = self.prev_q.clone();
            for _ in 0..self.settings.gauss_newton {
                let (q, rep) = self
                    .forward
                    .equilibrium_loaded(&a, &q_start, load.as_deref())?;
                fit.forward = Some(rep);
                let x = self.surface(&q);
                let r: Vec<f64> = d_full
                    .iter()
                    .zip(x.iter().zip(&self.rest_surface))
                    .map(|(di, (xi, ri))| di - (xi - ri))
                    .collect();
                let cols = self.forward.response(&q, &a)?;
                let jk = self.surface_columns(&cols);
                let jtj = self.gram(&jk);
                let ja = self.j_times(&jk, &a);
                let deff: Vec<f64> = r.iter().zip(&ja).map(|(x, y)| x + y).collect();
                let tq = Instant::now();
                let jtd = self.jt_times(&jk, &deff);
                let sol = self.qp(&jtj, &jtd, &bounds);
                fit.qp_s += tq.elapsed().as_secs_f64();
                fit.clarabel_status = sol.clarabel_status.clone();
                fit.qp_status = sol.status;
                fit.gauss_newton += 1;
                q_start = q;
                match sol.status {
                    SolveStatus::Converged => a = sol.activations,
                    _ => {
                        fit.status = FrameStatus::GaussNewtonStopped;
                        break;
                    }
                }
            }
            let (q, rep) = self
                .forward
                .equilibrium_loaded(&a, &q_start, load.as_deref())?;
            fit.forward = Some(rep);
            let x = self.surface(&q);
            let r: Vec<f64> = d_full
                .iter()
                .zip(x.iter().zip(&self.rest_surface))
                .map(|(di, (xi, ri))| di - (xi - ri))
                .collect();
            residual = self.rms(&r);
            self.prev_q = q;
        }
        fit.activations = a.clone();
        fit.rms_residual = residual;
        self.prev_a = a;
        fit.total_s = t0.elapsed().as_secs_f64();
        Ok(fit)
    }
}
