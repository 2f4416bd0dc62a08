//! One dense run: the strip compressed in load steps from half the critical strain to the
//! final one, each solved to equilibrium, and the wrinkle measured at the end.

use super::case::{DenseCase, DenseResult, StepRecord};
use super::readout::{onset_fit, top_amplitude, top_profiles};
use super::strip::Strip;
use crate::solver::statics::{HessianMode, StaticSettings, StaticSolver};
use crate::solver::status::SolveStatus;
use crate::validate::measure;
use std::time::Instant;

/// Run one dense wrinkling simulation (see [`crate::validate::dense`]) and measure λ.
/// Errors are bad input; the numerical outcome is in `status`.
pub fn run(case: &DenseCase) -> anyhow::Result<DenseResult> {
    let t0 = Instant::now();
    case.validate()?;
    let lambda = case.bilayer.critical_wavelength();
    let eps_c = case.critical_strain();
    let strip = Strip::new(case, lambda)?;
    let mut x: Vec<f64> = strip.mesh.nodes.iter().flat_map(|p| [p[0], p[1]]).collect();
    let ramp = compress_strip(&strip, case, eps_c, &mut x)?;
    let onset = onset_fit(&ramp.steps, 0.1 * case.bilayer.thickness);
    let (reference, current) = top_profiles(&strip.mesh, &x);
    let finite = x.iter().all(|v| v.is_finite());
    let m_ref = if finite {
        measure::wavelength(&reference)
    } else {
        None
    };
    let m_cur = if finite {
        measure::wavelength(&current)
    } else {
        None
    };
    let length = strip.length;
    Ok(DenseResult {
        case: *case,
        predicted: lambda,
        measured: m_ref.as_ref().map(|m| m.wavelength),
        measured_current: m_cur.as_ref().map(|m| m.wavelength),
        error: m_ref
            .as_ref()
            .map(|m| (m.wavelength - lambda).abs() / lambda),
        amplitude: m_ref.as_ref().map(|m| m.amplitude),
        measurement: m_ref,
        nearest_admissible: 2.0 * length / (2.0 * length / lambda).round().max(1.0),
        critical_strain: eps_c,
        onset_strain: onset.map(|o| o.0),
        onset_slope: onset.map(|o| o.1),
        strain: ramp.strain,
        length,
        elements: strip.mesh.elements.len(),
        dofs: 2 * strip.mesh.nodes.len(),
        iterations: ramp.iterations,
        seconds: t0.elapsed().as_secs_f64(),
        status: ramp.status,
        residual: ramp.residual,
        steps: ramp.steps,
    })
}

/// What the load steps of a dense run did, together.
struct Ramp {
    /// One record per load step solved.
    steps: Vec<StepRecord>,
    /// `Converged`, or the first failing step's status.
    status: SolveStatus,
    /// Newton iterations summed over the steps.
    iterations: usize,
    /// Final residual norm (N/m) of the last step.
    residual: f64,
    /// Last applied compressive strain (dimensionless).
    strain: f64,
}

/// Compress the strip in `case.load_steps` steps from 0.5 `eps_c` to `strain_factor` ×
/// `eps_c`, solving each step to equilibrium from the previous one in `x` (flat positions,
/// m); stops early at a non-finite state.
fn compress_strip(
    strip: &Strip,
    case: &DenseCase,
    eps_c: f64,
    x: &mut [f64],
) -> anyhow::Result<Ramp> {
    let (mesh, length) = (&strip.mesh, strip.length);
    let ex_bar =
        case.bilayer.skin_modulus / (1.0 - case.bilayer.skin_poisson * case.bilayer.skin_poisson);
    let settings = StaticSettings {
        tolerance: 1e-9 * ex_bar * case.bilayer.thickness,
        max_iterations: 60,
        hessian: HessianMode::Auto,
        energy_merit: true,
        ..Default::default()
    };
    let mut solver = StaticSolver::new(settings)?;
    let mut ramp = Ramp {
        steps: Vec::with_capacity(case.load_steps),
        status: SolveStatus::Converged,
        iterations: 0,
        residual: 0.0,
        strain: 0.0,
    };
    for step in 0..case.load_steps {
        let f = step as f64 / (case.load_steps - 1) as f64;
        let strain = eps_c * (0.5 + f * (case.strain_factor - 0.5));
        ramp.strain = strain;
        if step == 0 {
            // Start from the uniform compression (the pre-buckling state up to the Poisson
            // bulge): moving only the right side would crush its elements and send Newton
            // through unstable states.
            for (n, p) in mesh.nodes.iter().enumerate() {
                x[2 * n] = p[0] * (1.0 - strain);
            }
        }
        for r in 0..mesh.rows {
            let n = mesh.node(mesh.columns - 1, r);
            x[2 * n] = length * (1.0 - strain);
        }
        let rep = solver.solve(&strip.energy, &strip.problem, x)?;
        ramp.steps.push(StepRecord {
            strain,
            iterations: rep.iterations,
            modified_hessian_steps: rep.modified_hessian_steps,
            residual: rep.residual,
            status: rep.status,
            seconds: rep.total_s,
            assembly_factor_search_s: [rep.assembly_s, rep.factor_s, rep.line_search_s],
            amplitude: top_amplitude(mesh, x, length),
        });
        ramp.iterations += rep.iterations;
        ramp.residual = rep.residual;
        if rep.status != SolveStatus::Converged && ramp.status == SolveStatus::Converged {
            ramp.status = rep.status;
        }
        if matches!(rep.status, SolveStatus::NotFinite) {
            break;
        }
    }
    Ok(ramp)
}
