//! Wavelength validation: the compressed slab ([`super::slab`]) over a grid of stiffness
//! ratios E_x/E_q and skin thicknesses h, the wrinkle wavelength measured from the skin's
//! height profile against the formula λ = 2π h [(1 − ν_q²) E_x / (3 (1 − ν_x²) E_q)]^(1/3).

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
    /// Relative error |measured − predicted| / predicted (NaN when not measured).
    pub error: f64,
    /// Zero crossings used for the measurement.
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

/// A measured wrinkle wavelength (m) and the number of zero crossings it came from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Crossings {
    /// Wavelength: twice the mean distance between successive zero crossings (m).
    pub wavelength: f64,
    /// Zero crossings counted.
    pub count: usize,
}

/// Wavelength from zero crossings of a height profile `(s, w)` (m, m; ordered by s), over
/// the central part of the span (a fraction `margin` ignored at each end). A crossing counts
/// only once the height has gone beyond ±10 % of the largest |w| on the other side
/// (hysteresis against noise). The wavelength is twice the least-squares slope of crossing
/// position against crossing index. `None` with fewer than 3 crossings.
pub fn zero_crossings(profile: &[(f64, f64)], margin: f64) -> Option<Crossings> {
    if profile.len() < 3 {
        return None;
    }
    let (s0, s1) = (profile[0].0, profile[profile.len() - 1].0);
    let (lo, hi) = (s0 + margin * (s1 - s0), s1 - margin * (s1 - s0));
    let pts: Vec<(f64, f64)> = profile
        .iter()
        .copied()
        .filter(|p| p.0 >= lo && p.0 <= hi)
        .collect();
    let amp = pts.iter().map(|p| p.1.abs()).fold(0.0, f64::max);
    if amp.is_nan() || amp <= 0.0 {
        return None;
    }
    let band = 0.1 * amp;
    let mut crossings = Vec::new();
    let mut state = 0i32; // sign of the last excursion beyond the band
    let mut pending: Option<f64> = None; // most recent sign change of w
    for k in 0..pts.len() {
        let (s, w) = pts[k];
        if k > 0 {
            let (sp, wp) = pts[k - 1];
            if (wp < 0.0) != (w < 0.0) && wp != w {
                pending = Some(sp + (s - sp) * wp / (wp - w));
            }
        }
        let side = if w > band {
            1
        } else if w < -band {
            -1
        } else {
            0
        };
        if side != 0 {
            if state != 0 && side != state {
                if let Some(z) = pending.take() {
                    crossings.push(z);
                }
            }
            state = side;
            pending = None;
        }
    }
    if crossings.len() < 3 {
        return None;
    }
    let n = crossings.len() as f64;
    let mi = (n - 1.0) / 2.0;
    let ms = crossings.iter().sum::<f64>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (i, &c) in crossings.iter().enumerate() {
        num += (i as f64 - mi) * (c - ms);
        den += (i as f64 - mi).powi(2);
    }
    Some(Crossings {
        wavelength: 2.0 * num / den,
        count: crossings.len(),
    })
}

/// Run one grid point with the default slab of [`SlabSettings::new`].
pub fn run_point(ratio: f64, thickness: f64) -> anyhow::Result<WavelengthRow> {
    let s = SlabSettings::new(bilayer(ratio, thickness));
    run_point_with(&s)
}

/// Run one slab and measure its wavelength.
pub fn run_point_with(s: &SlabSettings) -> anyhow::Result<WavelengthRow> {
    let r = run_slab(s)?;
    let m = zero_crossings(&r.profile, 0.1);
    let (measured, crossings) = match m {
        Some(c) => (c.wavelength, c.count),
        None => (f64::NAN, 0),
    };
    Ok(WavelengthRow {
        ratio: s.bilayer.skin_modulus / s.bilayer.interior_modulus,
        thickness: s.bilayer.thickness,
        predicted: r.predicted,
        measured,
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

#[cfg(test)]
mod tests {
    use super::*;

    /// A sampled sinusoid of known period gives that period; noise below the hysteresis band
    /// adds no crossings.
    #[test]
    fn zero_crossings_of_a_sinusoid() {
        let period = 0.37;
        let p: Vec<(f64, f64)> = (0..400)
            .map(|i| {
                let s = i as f64 * 0.01;
                let noise = 0.02 * ((i * 7919) % 13) as f64 / 13.0 - 0.01;
                (
                    s,
                    (2.0 * std::f64::consts::PI * s / period + 0.3).sin() + noise,
                )
            })
            .collect();
        let c = zero_crossings(&p, 0.1).unwrap();
        assert!((c.wavelength - period).abs() < 0.01 * period, "{c:?}");
        assert!(zero_crossings(&[(0.0, 0.0), (1.0, 0.0), (2.0, 0.0)], 0.0).is_none());
    }
}
