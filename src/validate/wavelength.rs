//! Wavelength validation: the compressed slab ([`super::slab`]) over a grid of stiffness
//! ratios E_x/E_q and skin thicknesses h, the wrinkle wavelength measured from the skin's
//! height profile against the formula λ = 2π h [(1 − ν_q²) E_x / (3 (1 − ν_x²) E_q)]^(1/3).
//!
//! What this checks, and what it does not: in the embedded-shell method the interior's
//! stiffness reaches the skin's wrinkle wavelength only through the cluster width σ, which
//! is computed from the formula's λ ([`crate::coupling::cluster_width::sigma_for_wavelength`]).
//! The sweep therefore checks that the frequency-limited constraints make the skin wrinkle at
//! the λ they were built for, across skin thickness-to-wavelength ratios h/λ from 1/20
//! (E_x/E_q = 10²) to 1/94 (10⁴); the slab is scaled with λ, so every point has the same
//! number of vertices per λ and of wavelengths in the slab. It is not an independent check
//! of the formula itself (that is the dense volumetric reference, [`super::dense`]).
//! Measured with [`super::measure::wavelength`] (zero crossings, detrended).

use super::measure;
use super::slab::{run_slab, SlabSettings};
use crate::coupling::wavelength::Bilayer;

/// Interior Young's modulus E_q of the sweep (Pa): soft tissue. Only ratios matter.
pub const INTERIOR_MODULUS: f64 = 1.0e4;

/// Poisson ratio of skin and interior in the sweep (the paper's Table 1 uses equal ratios).
pub const POISSON: f64 = 0.45;

/// One grid point of the sweep.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct WavelengthRow {
    /// Stiffness ratio E_x / E_q (dimensionless).
    pub ratio: f64,
    /// Skin thickness h (m).
    pub thickness: f64,
    /// Predicted critical wavelength λ (m).
    pub predicted: f64,
    /// Measured wavelength (m); NaN when no wrinkle could be measured.
    pub measured: f64,
    /// Wrinkle amplitude (m): half the crest-to-trough height of the fitted sinusoid.
    pub amplitude: f64,
    /// Relative error |measured − predicted| / predicted (NaN when not measured).
    pub error: f64,
    /// Zero crossings used for the measurement ([`super::measure::wavelength`]).
    pub crossings: usize,
    /// Whether every shell statics of the run converged.
    pub converged: bool,
    /// Wall-clock seconds of the run.
    pub seconds: f64,
}

/// The bilayer of a sweep point: E_q = [`INTERIOR_MODULUS`], E_x = ratio · E_q, ν = [`POISSON`].
pub fn bilayer(ratio: f64, thickness: f64) -> Bilayer {
    Bilayer {
        thickness,
        skin_modulus: ratio * INTERIOR_MODULUS,
        skin_poisson: POISSON,
        interior_modulus: INTERIOR_MODULUS,
        interior_poisson: POISSON,
    }
}

/// Run one grid point with the default slab of [`SlabSettings::new`].
pub fn run_point(ratio: f64, thickness: f64) -> anyhow::Result<WavelengthRow> {
    let s = SlabSettings::new(bilayer(ratio, thickness));
    run_point_with(&s)
}

/// Run one slab and measure its wavelength.
pub fn run_point_with(s: &SlabSettings) -> anyhow::Result<WavelengthRow> {
    let r = run_slab(s)?;
    let (measured, amplitude, crossings) = match measure::wavelength(&r.profile) {
        Some(m) => (m.wavelength, m.amplitude, m.crossings),
        None => (f64::NAN, f64::NAN, 0),
    };
    Ok(WavelengthRow {
        ratio: s.bilayer.skin_modulus / s.bilayer.interior_modulus,
        thickness: s.bilayer.thickness,
        predicted: r.predicted,
        measured,
        amplitude,
        error: (measured - r.predicted).abs() / r.predicted,
        crossings,
        converged: r.converged,
        seconds: r.seconds,
    })
}

/// Run the slab over every (ratio, thickness) pair (ratios outer, thicknesses inner; h in
/// m) and return one row per pair; `progress` is called with the number of points done.
pub fn sweep(
    ratios: &[f64],
    thicknesses: &[f64],
    progress: &dyn Fn(usize),
) -> anyhow::Result<Vec<WavelengthRow>> {
    let mut rows = Vec::with_capacity(ratios.len() * thicknesses.len());
    for &ratio in ratios {
        for &h in thicknesses {
            rows.push(run_point(ratio, h)?);
            progress(rows.len());
        }
    }
    Ok(rows)
}

/// Median and largest relative error over the measured rows (NaN rows count as failures:
/// they make the largest error infinite).
pub fn summary(rows: &[WavelengthRow]) -> (f64, f64) {
    let mut e: Vec<f64> = rows
        .iter()
        .map(|r| {
            if r.error.is_finite() {
                r.error
            } else {
                f64::INFINITY
            }
        })
        .collect();
    e.sort_by(f64::total_cmp);
    if e.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let med = if e.len() % 2 == 1 {
        e[e.len() / 2]
    } else {
        0.5 * (e[e.len() / 2 - 1] + e[e.len() / 2])
    };
    (med, *e.last().expect("non-empty"))
}
