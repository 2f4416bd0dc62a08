//! The two-step solve of DESIGN.md ("The two-step solve"), one frame: the skin's statics at
//! the interior's current node positions q, then the interior's step under the skin's force
//! Bᵀ F_x and stiffness Bᵀ K_x B, held fixed within the step.

use super::embedded::EmbeddedShell;
use crate::fem::dynamics::{BackwardEuler, ExtraTerms, SolveReport as StepReport};
use crate::solver::SolveReport;
use anyhow::bail;
use std::time::Instant;

/// What one two-step frame did: the shell statics report, the interior step report and the
/// time (s) of each stage.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TwoStepReport {
    /// Shell statics (step 1): status, iterations, residual (N), constraint violation (m).
    pub shell: SolveReport,
    /// Interior backward Euler (or quasi-static) solve (step 2).
    pub interior: StepReport,
    /// Wall-clock seconds of the shell statics.
    pub shell_s: f64,
    /// Wall-clock seconds forming Bᵀ K_x B and Bᵀ F_x.
    pub coupling_s: f64,
    /// Wall-clock seconds of the interior solve.
    pub interior_s: f64,
}

/// How the interior solve of [`two_step_with`] treats time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InteriorMode {
    /// One backward Euler step of `interior.settings.dt`.
    Dynamic,
    /// Quasi-static equilibrium of the interior with the skin terms (velocities zeroed).
    QuasiStatic,
}

/// One frame of the two-step scheme: shell statics at the interior's current q, then one
/// backward Euler step of the interior with the external node forces `f_ext` (flat, N) and
/// the skin's Bᵀ F_x and Bᵀ K_x B (held fixed within the step).
pub fn two_step(
    interior: &mut BackwardEuler,
    skin: &mut EmbeddedShell,
    f_ext: &[f64],
) -> anyhow::Result<TwoStepReport> {
    two_step_with(interior, skin, f_ext, InteriorMode::Dynamic)
}

/// [`two_step`] with the interior solve chosen by `mode` (quasi-static for validation scenes).
pub fn two_step_with(
    interior: &mut BackwardEuler,
    skin: &mut EmbeddedShell,
    f_ext: &[f64],
    mode: InteriorMode,
) -> anyhow::Result<TwoStepReport> {
    if interior.interior.nodes != skin.node_count() {
        bail!(
            "the skin is embedded in {} nodes but the interior has {}",
            skin.node_count(),
            interior.interior.nodes
        );
    }
    let t = Instant::now();
    let shell = skin.solve(&interior.q)?;
    let shell_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (stiffness, force) = skin.coupling_terms();
    let coupling_s = t.elapsed().as_secs_f64();
    let extra = ExtraTerms::new(&stiffness, &force);
    let t = Instant::now();
    let rep = match mode {
        InteriorMode::Dynamic => interior.step(f_ext, Some(&extra))?,
        InteriorMode::QuasiStatic => interior.quasi_static(f_ext, Some(&extra))?,
    };
    let interior_s = t.elapsed().as_secs_f64();
    Ok(TwoStepReport {
        shell,
        interior: rep,
        shell_s,
        coupling_s,
        interior_s,
    })
}
