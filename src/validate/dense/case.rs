//! A dense wrinkling case (the bilayer and its discretisation, checked) and what a run of it
//! reports, overall and per load step.

use crate::coupling::wavelength::Bilayer;
use crate::solver::status::SolveStatus;
use crate::validate::measure::Measured;
use anyhow::bail;

/// One dense wrinkling case: the bilayer and the discretisation.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct DenseCase {
    /// Skin thickness, moduli and Poisson ratios (SI).
    pub bilayer: Bilayer,
    /// Resolution knob: quadratic elements per predicted wavelength along the strip (≥ 2);
    /// the substrate's first layer is as thick as one element is wide, halved.
    pub elements_per_wavelength: usize,
    /// Element layers across the skin (≥ 2).
    pub skin_layers: usize,
    /// Strip length in predicted wavelengths (dimensionless, ≥ 2).
    pub periods: f64,
    /// Substrate depth in predicted wavelengths (dimensionless, ≥ 1).
    pub depth: f64,
    /// Final compressive strain as a multiple of the critical strain ε_c (> 1).
    pub strain_factor: f64,
    /// Number of load steps from 0.5 ε_c to the final strain (≥ 2).
    pub load_steps: usize,
    /// Amplitude of the geometric imperfection as a fraction of the skin thickness (> 0).
    pub imperfection: f64,
    /// Seed of the deterministic imperfection.
    pub seed: u64,
}

impl DenseCase {
    /// A case for `bilayer` with the default discretisation: 8 elements per wavelength, 2
    /// skin layers, 10.3 periods, depth 2 λ, compressed to 1.3 ε_c in 9 steps, imperfection
    /// 1% of h.
    pub fn new(bilayer: Bilayer) -> Self {
        Self {
            bilayer,
            elements_per_wavelength: 8,
            skin_layers: 2,
            periods: 10.3,
            depth: 2.0,
            strain_factor: 1.3,
            load_steps: 9,
            imperfection: 0.01,
            seed: 1,
        }
    }

    /// Check every field; the error names the field.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.bilayer
            .validate()
            .map_err(|e| anyhow::anyhow!("dense case bilayer: {e}"))?;
        if self.bilayer.interior_poisson >= 0.5 {
            bail!("dense case: interior_poisson must be below 0.5 for the compressible St. Venant–Kirchhoff model");
        }
        if self.elements_per_wavelength < 2 {
            bail!("dense case: elements_per_wavelength must be at least 2");
        }
        if self.skin_layers < 2 {
            bail!("dense case: skin_layers must be at least 2 (the skin is resolved by its own element layers)");
        }
        let pos = |v: f64, min: f64, name: &str| -> anyhow::Result<()> {
            if v.is_finite() && v >= min {
                Ok(())
            } else {
                bail!("dense case: {name} = {v} must be at least {min}")
            }
        };
        pos(self.periods, 2.0, "periods")?;
        pos(self.depth, 1.0, "depth")?;
        pos(self.imperfection, 1e-12, "imperfection")?;
        if !(self.strain_factor.is_finite() && self.strain_factor > 1.0) {
            bail!(
                "dense case: strain_factor = {} must be above 1 (beyond the critical strain)",
                self.strain_factor
            );
        }
        if self.load_steps < 2 {
            bail!("dense case: load_steps must be at least 2");
        }
        if self.critical_strain() > 0.2 {
            bail!(
                "dense case: critical strain {:.3} is above 0.2 (modulus ratio too small for the small-strain formula)",
                self.critical_strain()
            );
        }
        Ok(())
    }

    /// Critical compressive strain ε_c = ¼ (3 Ē_q / Ē_x)^{2/3} (dimensionless), Ē = E/(1 − ν²).
    pub fn critical_strain(&self) -> f64 {
        let b = &self.bilayer;
        let ex = b.skin_modulus / (1.0 - b.skin_poisson.powi(2));
        let eq = b.interior_modulus / (1.0 - b.interior_poisson.powi(2));
        0.25 * (3.0 * eq / ex).powf(2.0 / 3.0)
    }
}

/// Outcome of a dense run.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DenseResult {
    /// The case that was run.
    pub case: DenseCase,
    /// Predicted critical wavelength λ (m), DESIGN.md formula.
    pub predicted: f64,
    /// Measured wavelength against the reference position along the strip (m); `None` when
    /// no wrinkle was found.
    pub measured: Option<f64>,
    /// Measured wavelength against the current position (m) (shorter by about 1 − ε).
    pub measured_current: Option<f64>,
    /// Relative error |measured − predicted| / predicted; `None` without a wrinkle.
    pub error: Option<f64>,
    /// Wrinkle amplitude (m).
    pub amplitude: Option<f64>,
    /// The full measurement (reference positions).
    pub measurement: Option<Measured>,
    /// The wavelength 2L/m (m an integer) the sliding-sided strip admits that is nearest to
    /// the prediction (m): the best the strip can do; |nearest − predicted| is the
    /// quantisation floor of `error`.
    pub nearest_admissible: f64,
    /// Predicted critical strain ε_c (dimensionless).
    pub critical_strain: f64,
    /// Onset strain ε₀ (dimensionless) of the fitted post-buckling law A² = c (ε − ε₀) over
    /// the steps with amplitude above h/10; theory: ε₀ = ε_c. `None` with fewer than two
    /// such steps.
    pub onset_strain: Option<f64>,
    /// Slope c of that law (m²); theory: h² / ε_c.
    pub onset_slope: Option<f64>,
    /// Final applied compressive strain (dimensionless).
    pub strain: f64,
    /// Strip length L (m).
    pub length: f64,
    /// Number of Q2 elements.
    pub elements: usize,
    /// Number of degrees of freedom (2 per node, pinned ones included).
    pub dofs: usize,
    /// Total Newton iterations over all load steps.
    pub iterations: usize,
    /// Wall-clock seconds of the whole run (mesh, solves, measurement).
    pub seconds: f64,
    /// Status of the load steps: `converged` when every step converged, else the first
    /// failing step's status.
    pub status: SolveStatus,
    /// Final residual norm (N/m) of the last step.
    pub residual: f64,
    /// One entry per load step.
    pub steps: Vec<StepRecord>,
}

/// What one load step of a dense run did.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct StepRecord {
    /// Applied compressive strain (dimensionless).
    pub strain: f64,
    /// Newton iterations.
    pub iterations: usize,
    /// Iterations that used a projected or shifted Hessian (the state was unstable).
    pub modified_hessian_steps: usize,
    /// Final residual norm (N/m).
    pub residual: f64,
    /// Outcome of the step.
    pub status: SolveStatus,
    /// Wall-clock seconds of the step.
    pub seconds: f64,
    /// Seconds of that spent assembling Hessians / factorising / in line searches.
    pub assembly_factor_search_s: [f64; 3],
    /// Wrinkle amplitude after the step (m): √2 × RMS of the top surface's vertical
    /// displacement about its mean over the central 80% of the strip (no wavelength needed,
    /// so it also measures the growth of the imperfection below ε_c).
    pub amplitude: f64,
}
