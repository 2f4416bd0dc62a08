//! Studies over dense runs: a sweep of stiffness ratios and skin thicknesses, an ensemble of
//! imperfection seeds, and a resolution study.

use super::case::{DenseCase, DenseResult};
use super::run::run;
use crate::solver::status::SolveStatus;
use anyhow::Context;

/// One row of [`sweep`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SweepRow {
    /// Stiffness ratio E_x / E_q (dimensionless).
    pub ratio: f64,
    /// Skin thickness h (m).
    pub thickness: f64,
    /// Predicted λ (m).
    pub predicted: f64,
    /// Measured λ against reference positions (m), if a wrinkle formed.
    pub measured: Option<f64>,
    /// Relative error against the formula.
    pub error: Option<f64>,
    /// Admissible wavelength 2L/m nearest to the prediction (m), see [`DenseResult`].
    pub nearest_admissible: f64,
    /// Predicted critical strain ε_c (dimensionless).
    pub critical_strain: f64,
    /// Fitted onset strain ε₀ of the post-buckling law, see [`DenseResult`].
    pub onset_strain: Option<f64>,
    /// Q2 elements.
    pub elements: usize,
    /// Degrees of freedom.
    pub dofs: usize,
    /// Wall-clock seconds of the run.
    pub seconds: f64,
    /// Solve status (`converged` or the first failure).
    pub status: SolveStatus,
}

/// Run `base` over every (stiffness ratio E_x/E_q, skin thickness h (m)) pair: the skin
/// modulus is kept and E_q = E_x / ratio. Rows in the order ratios × thicknesses.
pub fn sweep(
    base: &DenseCase,
    ratios: &[f64],
    thicknesses: &[f64],
) -> anyhow::Result<Vec<SweepRow>> {
    let mut rows = Vec::new();
    for &ratio in ratios {
        for &h in thicknesses {
            let mut case = *base;
            case.bilayer.thickness = h;
            case.bilayer.interior_modulus = base.bilayer.skin_modulus / ratio;
            let r =
                run(&case).with_context(|| format!("dense run E_x/E_q = {ratio}, h = {h} m"))?;
            rows.push(SweepRow {
                ratio,
                thickness: h,
                predicted: r.predicted,
                measured: r.measured,
                error: r.error,
                nearest_admissible: r.nearest_admissible,
                critical_strain: r.critical_strain,
                onset_strain: r.onset_strain,
                elements: r.elements,
                dofs: r.dofs,
                seconds: r.seconds,
                status: r.status,
            });
        }
    }
    Ok(rows)
}

/// The same case run with several imperfection seeds (the mode a finite strip selects
/// scatters by a few percent with the imperfection; the mean is the sharper estimate).
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Ensemble {
    /// Predicted λ (m).
    pub predicted: f64,
    /// Mean measured λ (m) over the runs that formed a wrinkle; `None` if none did.
    pub mean: Option<f64>,
    /// Smallest and largest measured λ (m).
    pub range: Option<(f64, f64)>,
    /// Relative error of the mean against the formula.
    pub error: Option<f64>,
    /// Runs that converged at every step and formed a wrinkle.
    pub valid_runs: usize,
    /// Total wall-clock seconds.
    pub seconds: f64,
    /// The individual runs.
    pub runs: Vec<DenseResult>,
}

/// Run `base` once per seed in `seeds` and average the measured wavelengths of the runs that
/// converged and formed a wrinkle.
pub fn ensemble(base: &DenseCase, seeds: &[u64]) -> anyhow::Result<Ensemble> {
    let mut runs = Vec::with_capacity(seeds.len());
    for &seed in seeds {
        let mut c = *base;
        c.seed = seed;
        runs.push(run(&c).with_context(|| format!("dense run with seed {seed}"))?);
    }
    let ok: Vec<f64> = runs
        .iter()
        .filter(|r| r.status == SolveStatus::Converged)
        .filter_map(|r| r.measured)
        .collect();
    let predicted = base.bilayer.critical_wavelength();
    let mean = (!ok.is_empty()).then(|| ok.iter().sum::<f64>() / ok.len() as f64);
    let range = (!ok.is_empty()).then(|| {
        ok.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                (a.min(v), b.max(v))
            })
    });
    Ok(Ensemble {
        predicted,
        mean,
        range,
        error: mean.map(|m| (m - predicted).abs() / predicted),
        valid_runs: ok.len(),
        seconds: runs.iter().map(|r| r.seconds).sum(),
        runs,
    })
}

/// One row of [`resolution_study`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ResolutionRow {
    /// Elements per predicted wavelength.
    pub elements_per_wavelength: usize,
    /// Degrees of freedom.
    pub dofs: usize,
    /// Wall-clock seconds of the run.
    pub seconds: f64,
    /// Measured λ (m), if a wrinkle formed.
    pub measured: Option<f64>,
    /// Relative error against the formula.
    pub error_formula: Option<f64>,
    /// Relative error against the finest resolution's λ.
    pub error_finest: Option<f64>,
    /// Solve status.
    pub status: SolveStatus,
}

/// Run `base` at each resolution (elements per wavelength); errors are against the formula
/// and against the finest (largest) resolution given.
pub fn resolution_study(
    base: &DenseCase,
    resolutions: &[usize],
) -> anyhow::Result<Vec<ResolutionRow>> {
    let mut results = Vec::new();
    for &r in resolutions {
        let mut case = *base;
        case.elements_per_wavelength = r;
        results.push(run(&case).with_context(|| format!("dense run at {r} elements per λ"))?);
    }
    let finest = results
        .iter()
        .max_by_key(|r| r.case.elements_per_wavelength)
        .and_then(|r| r.measured);
    Ok(results
        .iter()
        .map(|r| ResolutionRow {
            elements_per_wavelength: r.case.elements_per_wavelength,
            dofs: r.dofs,
            seconds: r.seconds,
            measured: r.measured,
            error_formula: r.error,
            error_finest: match (r.measured, finest) {
                (Some(m), Some(f)) => Some((m - f).abs() / f),
                _ => None,
            },
            status: r.status,
        })
        .collect())
}
