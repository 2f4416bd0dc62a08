//! Wrinkle wavelength and amplitude from a surface height profile.
//!
//! Input: samples `(s, z)` of the surface height `z` (m) at position `s` (m) along the
//! compression axis, in any order, possibly non-uniformly spaced.
//!
//! Method (zero crossings, two detrending passes):
//! 1. remove a least-squares quadratic in `s` (the global bend and Poisson thickening), count
//!    zero crossings over the central 80% of the span and get a first wavelength λ₀;
//! 2. remove instead a moving average of width exactly λ₀ (the exact integral of the piecewise
//!    linear profile over `[s − λ₀/2, s + λ₀/2]`): it annihilates a sinusoid of period λ₀ and
//!    keeps any linear trend and any variation much slower than λ₀, so it removes the low
//!    frequency part without eating into a wrinkle when only a few periods are present; count
//!    the crossings again where the window fits inside the profile.
//!
//! Crossings are located by linear interpolation between samples, with hysteresis (a crossing
//! counts only once the height has gone beyond ±10% of the amplitude on the other side) so that
//! noise does not add spurious crossings. The wavelength is twice the slope of a least-squares
//! line through the crossing positions against their index (it uses all crossings, not just the
//! first and last).
//!
//! Why zero crossings and not the FFT peak: simulated profiles often hold only a few periods,
//! where the FFT peak is biased by leakage (a non-integer number of periods in the window) and
//! its bins are 1/span apart; crossings are unbiased for a sinusoid whatever the phase and the
//! number of periods, and need no resampling of non-uniform samples. The amplitude and a
//! coherence check come from a least-squares sinusoid fit at the measured wavelength over the
//! central region: if that sinusoid explains less than half of the detrended variance, the
//! profile is not a wrinkle (noise, a single bump) and the answer is `None`.

use nalgebra::{DMatrix, DVector};

/// A measured wrinkle.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct Measured {
    /// Wrinkle wavelength (m): distance between two successive crests.
    pub wavelength: f64,
    /// Wrinkle amplitude (m): half the crest-to-trough height of the fitted sinusoid.
    pub amplitude: f64,
    /// Number of zero crossings of the detrended height used for the wavelength.
    pub crossings: usize,
    /// How the wavelength was obtained (see the module documentation).
    pub method: &'static str,
}

/// Thresholds of [`wavelength_with`]. The defaults suit simulated profiles.
#[derive(Clone, Debug)]
pub struct MeasureOptions {
    /// Fraction of the span ignored at each end (boundary effects), dimensionless in [0, 0.4].
    pub margin: f64,
    /// Smallest amplitude that counts as a wrinkle, as a fraction of the mean sample spacing
    /// (dimensionless). Below it the profile is flat up to round-off.
    pub min_amplitude_per_spacing: f64,
    /// Smallest fraction of the detrended variance the fitted sinusoid must explain
    /// (dimensionless, in [0, 1]).
    pub min_coherence: f64,
    /// Smallest number of zero crossings (3 crossings = one full period).
    pub min_crossings: usize,
}

impl Default for MeasureOptions {
    fn default() -> Self {
        Self {
            margin: 0.1,
            min_amplitude_per_spacing: 1e-6,
            min_coherence: 0.5,
            min_crossings: 3,
        }
    }
}

/// Wrinkle wavelength (m) and amplitude (m) of a height profile `(position along the
/// compression axis (m), height (m))`, with the default [`MeasureOptions`]. `None` when there is
/// no wrinkle: fewer than 8 finite samples, fewer than 3 crossings, amplitude below 1e-6 of the
/// mean sample spacing, or a profile that is not sinusoidal (fit explains < 50% of variance).
pub fn wavelength(profile: &[(f64, f64)]) -> Option<Measured> {
    wavelength_with(profile, &MeasureOptions::default())
}

/// [`wavelength`] with explicit thresholds.
pub fn wavelength_with(profile: &[(f64, f64)], opts: &MeasureOptions) -> Option<Measured> {
    let mut p: Vec<(f64, f64)> = profile
        .iter()
        .copied()
        .filter(|(s, z)| s.is_finite() && z.is_finite())
        .collect();
    if p.len() < 8 {
        return None;
    }
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    // Merge duplicate positions (average their heights) so interpolation is well defined.
    let mut q: Vec<(f64, f64)> = Vec::with_capacity(p.len());
    let mut count = 1.0;
    for &(s, z) in &p {
        match q.last_mut() {
            Some(last) if s == last.0 => {
                count += 1.0;
                last.1 += (z - last.1) / count;
            }
            _ => {
                q.push((s, z));
                count = 1.0;
            }
        }
    }
    if q.len() < 8 {
        return None;
    }
    let s: Vec<f64> = q.iter().map(|v| v.0).collect();
    let z: Vec<f64> = q.iter().map(|v| v.1).collect();
    let (s0, s1) = (s[0], s[s.len() - 1]);
    let span = s1 - s0;
    if span <= 0.0 {
        return None;
    }
    let spacing = span / (s.len() - 1) as f64;
    let margin = opts.margin.clamp(0.0, 0.4) * span;

    // Pass 1: quadratic detrend.
    let r1 = polynomial_residual(&s, &z, 2);
    let (lo1, hi1) = (s0 + margin, s1 - margin);
    let c1 = crossings(&s, &r1, lo1, hi1);
    if c1.len() < opts.min_crossings.max(2) {
        return None;
    }
    let lambda0 = 2.0 * crossing_slope(&c1);
    if !(lambda0.is_finite() && lambda0 > 0.0) {
        return None;
    }

    // Pass 2: moving average of width λ₀.
    let mut best = (
        lambda0,
        c1.len(),
        r1,
        lo1,
        hi1,
        "zero crossings, quadratic detrend",
    );
    let half = 0.5 * lambda0;
    let (lo2, hi2) = (s0 + margin.max(half), s1 - margin.max(half));
    if hi2 > lo2 {
        let cum = cumulative(&s, &z);
        let r2: Vec<f64> = s
            .iter()
            .zip(&z)
            .map(|(&si, &zi)| {
                if si - half >= s0 && si + half <= s1 {
                    zi - (integral_at(&s, &z, &cum, si + half)
                        - integral_at(&s, &z, &cum, si - half))
                        / lambda0
                } else {
                    0.0
                }
            })
            .collect();
        let c2 = crossings(&s, &r2, lo2, hi2);
        if c2.len() >= opts.min_crossings.max(2) {
            let l2 = 2.0 * crossing_slope(&c2);
            if l2.is_finite() && l2 > 0.0 {
                best = (
                    l2,
                    c2.len(),
                    r2,
                    lo2,
                    hi2,
                    "zero crossings, moving-average detrend",
                );
            }
        }
    }
    let (lambda, n_cross, resid, lo, hi, method) = best;

    // Amplitude and coherence: least-squares a cos + b sin + c at the measured wavelength.
    let (amplitude, coherence) = sine_fit(&s, &resid, lo, hi, lambda)?;
    if !(amplitude.is_finite() && lambda.is_finite()) {
        return None;
    }
    if amplitude < opts.min_amplitude_per_spacing * spacing || coherence < opts.min_coherence {
        return None;
    }
    Some(Measured {
        wavelength: lambda,
        amplitude,
        crossings: n_cross,
        method,
    })
}

/// The finite samples of a profile `(position, value)` ordered by position, the first of
/// any samples at the same position kept.
pub fn sorted_finite(profile: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut p: Vec<(f64, f64)> = profile
        .iter()
        .copied()
        .filter(|(s, z)| s.is_finite() && z.is_finite())
        .collect();
    p.sort_by(|a, b| a.0.total_cmp(&b.0));
    p.dedup_by(|b, a| a.0 == b.0);
    p
}

/// The height profile `(position (m), height (m))` minus its moving average of width `width`
/// (m): the exact mean of the piecewise linear profile over `[s − width/2, s + width/2]`. A
/// sinusoid of period `width` passes unchanged (its mean over one period is zero), while
/// linear trends and variations much slower than `width` are removed. Samples are sorted by
/// position (non-finite ones and duplicate positions after the first dropped); samples whose
/// window does not fit inside the profile are dropped. Empty when fewer than 2 samples
/// remain or `width` is not positive.
pub fn detrend_moving_average(profile: &[(f64, f64)], width: f64) -> Vec<(f64, f64)> {
    let p = sorted_finite(profile);
    if p.len() < 2 || !(width.is_finite() && width > 0.0) {
        return Vec::new();
    }
    let s: Vec<f64> = p.iter().map(|v| v.0).collect();
    let z: Vec<f64> = p.iter().map(|v| v.1).collect();
    let (s0, s1) = (s[0], s[s.len() - 1]);
    let half = 0.5 * width;
    let cum = cumulative(&s, &z);
    s.iter()
        .zip(&z)
        .filter(|(&si, _)| si - half >= s0 && si + half <= s1)
        .map(|(&si, &zi)| {
            let mean = (integral_at(&s, &z, &cum, si + half)
                - integral_at(&s, &z, &cum, si - half))
                / width;
            (si, zi - mean)
        })
        .collect()
}

/// Residual of a least-squares polynomial of `degree` in the position (normalised to [-1, 1]).
fn polynomial_residual(s: &[f64], z: &[f64], degree: usize) -> Vec<f64> {
    let (s0, s1) = (s[0], s[s.len() - 1]);
    let mid = 0.5 * (s0 + s1);
    let half = 0.5 * (s1 - s0);
    let n = s.len();
    let a = DMatrix::from_fn(n, degree + 1, |i, j| ((s[i] - mid) / half).powi(j as i32));
    let b = DVector::from_column_slice(z);
    let coef = match a.clone().svd(true, true).solve(&b, 1e-12) {
        Ok(c) => c,
        Err(_) => return z.to_vec(),
    };
    let fit = a * coef;
    z.iter().zip(fit.iter()).map(|(zi, fi)| zi - fi).collect()
}

/// Zero crossings (positions, m) of the piecewise linear `r(s)` with hysteresis, counting only
/// samples with position in `[lo, hi]`.
fn crossings(s: &[f64], r: &[f64], lo: f64, hi: f64) -> Vec<f64> {
    let idx: Vec<usize> = (0..s.len()).filter(|&i| s[i] >= lo && s[i] <= hi).collect();
    if idx.len() < 2 {
        return Vec::new();
    }
    let rms = (idx.iter().map(|&i| r[i] * r[i]).sum::<f64>() / idx.len() as f64).sqrt();
    let tau = 0.1 * std::f64::consts::SQRT_2 * rms;
    if rms == 0.0 || !rms.is_finite() {
        return Vec::new();
    }
    let mut out = Vec::new();
    let mut last: Option<(usize, f64)> = None; // last committed sample index and its sign
    for &i in &idx {
        if r[i].abs() <= tau {
            continue;
        }
        let sign = r[i].signum();
        if let Some((j, sj)) = last {
            if sign != sj {
                // All zero crossings of the segments between j and i; average their positions.
                let (mut sum, mut cnt) = (0.0, 0.0);
                for k in j..i {
                    let (a, b) = (r[k], r[k + 1]);
                    if (a <= 0.0 && b > 0.0) || (a >= 0.0 && b < 0.0) {
                        let t = a / (a - b);
                        sum += s[k] + t * (s[k + 1] - s[k]);
                        cnt += 1.0;
                    }
                }
                if cnt > 0.0 {
                    out.push(sum / cnt);
                }
            }
        }
        last = Some((i, sign));
    }
    out
}

/// Least-squares slope of crossing position against crossing index (m per crossing = λ/2).
fn crossing_slope(c: &[f64]) -> f64 {
    let n = c.len() as f64;
    let mean_i = (n - 1.0) / 2.0;
    let mean_c = c.iter().sum::<f64>() / n;
    let (mut num, mut den) = (0.0, 0.0);
    for (i, &ci) in c.iter().enumerate() {
        let di = i as f64 - mean_i;
        num += di * (ci - mean_c);
        den += di * di;
    }
    num / den
}

/// Trapezoid cumulative integral of the piecewise linear profile at the samples (m²).
fn cumulative(s: &[f64], z: &[f64]) -> Vec<f64> {
    let mut c = vec![0.0; s.len()];
    for i in 1..s.len() {
        c[i] = c[i - 1] + 0.5 * (z[i - 1] + z[i]) * (s[i] - s[i - 1]);
    }
    c
}

/// Exact integral of the piecewise linear profile from `s[0]` to `x` (x inside the span).
fn integral_at(s: &[f64], z: &[f64], cum: &[f64], x: f64) -> f64 {
    let k = match s.partition_point(|&v| v <= x) {
        0 => 0,
        p => (p - 1).min(s.len() - 2),
    };
    let h = s[k + 1] - s[k];
    let d = x - s[k];
    let slope = if h > 0.0 { (z[k + 1] - z[k]) / h } else { 0.0 };
    cum[k] + d * z[k] + 0.5 * d * d * slope
}

/// Least-squares fit r ≈ a cos(2πs/λ) + b sin(2πs/λ) + c over samples in [lo, hi]:
/// returns (amplitude √(a²+b²) in m, fraction of the variance explained).
fn sine_fit(s: &[f64], r: &[f64], lo: f64, hi: f64, lambda: f64) -> Option<(f64, f64)> {
    let idx: Vec<usize> = (0..s.len()).filter(|&i| s[i] >= lo && s[i] <= hi).collect();
    if idx.len() < 4 {
        return None;
    }
    let k = 2.0 * std::f64::consts::PI / lambda;
    let a = DMatrix::from_fn(idx.len(), 3, |row, col| {
        let x = s[idx[row]];
        match col {
            0 => (k * x).cos(),
            1 => (k * x).sin(),
            _ => 1.0,
        }
    });
    let b = DVector::from_iterator(idx.len(), idx.iter().map(|&i| r[i]));
    let coef = a.clone().svd(true, true).solve(&b, 1e-12).ok()?;
    let mean = b.mean();
    let total: f64 = b.iter().map(|v| (v - mean).powi(2)).sum();
    let resid = (&a * &coef - &b).norm_squared();
    if total <= 0.0 {
        return None;
    }
    let explained = 1.0 - resid / total;
    Some((coef[0].hypot(coef[1]), explained))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    use crate::math::rng::Lcg;

    /// Approximately standard normal (sum of 12 uniforms − 6).
    fn normal(rng: &mut Lcg) -> f64 {
        (0..12).map(|_| rng.next_f64()).sum::<f64>() - 6.0
    }

    fn profile(
        n: usize,
        span: f64,
        lambda: f64,
        amp: f64,
        phase: f64,
        trend: impl Fn(f64) -> f64,
    ) -> Vec<(f64, f64)> {
        (0..n)
            .map(|i| {
                let s = span * i as f64 / (n - 1) as f64;
                (s, amp * (2.0 * PI * s / lambda + phase).sin() + trend(s))
            })
            .collect()
    }

    fn rel(a: f64, b: f64) -> f64 {
        (a - b).abs() / b
    }

    #[test]
    fn pure_sine_many_periods() {
        // 10.3 periods of a 4.04 mm wrinkle, 400 samples: the linear interpolation error of
        // each crossing is O((Δs/λ)²) ≈ 1e-3 of Δs and averages out over the regression
        // (measured 6e-7); allow 1e-4.
        let lambda = 4.04e-3;
        let p = profile(400, 10.3 * lambda, lambda, 1e-4, 0.3, |_| 0.0);
        let m = wavelength(&p).expect("wrinkle");
        assert!(rel(m.wavelength, lambda) < 1e-4, "{m:?}");
        assert!(rel(m.amplitude, 1e-4) < 1e-2, "{m:?}");
        assert!(m.crossings >= 14);
    }

    #[test]
    fn sine_on_large_quadratic_and_cubic_trend() {
        // Trend 50× the wrinkle amplitude (a bent slab): the moving-average pass removes it
        // (measured 2.3e-4; allow 2e-3).
        let lambda = 2e-3;
        let span = 8.4 * lambda;
        let p = profile(600, span, lambda, 2e-5, 1.0, |s| {
            let u = s / span;
            1e-3 * (u * u - 0.3 * u * u * u) + 5e-4 * u
        });
        let m = wavelength(&p).expect("wrinkle");
        assert!(rel(m.wavelength, lambda) < 2e-3, "{m:?}");
        assert!(rel(m.amplitude, 2e-5) < 0.05, "{m:?}");
    }

    #[test]
    fn noisy_sine() {
        // Gaussian noise of 10% of the amplitude: hysteresis keeps crossings single; the
        // regression over ~20 crossings averages the jitter (measured 1.3e-3). Allow 5e-3.
        let lambda = 3e-3;
        let mut rng = Lcg::from_state(7);
        let p: Vec<(f64, f64)> = profile(500, 11.7 * lambda, lambda, 1e-4, 0.0, |_| 0.0)
            .into_iter()
            .map(|(s, z)| (s, z + 1e-5 * normal(&mut rng)))
            .collect();
        let m = wavelength(&p).expect("wrinkle");
        assert!(rel(m.wavelength, lambda) < 5e-3, "{m:?}");
        assert!(rel(m.amplitude, 1e-4) < 0.05, "{m:?}");
    }

    #[test]
    fn non_uniform_shuffled_samples() {
        // Random positions (uniform density, unordered) with a linear trend (measured 4e-6;
        // allow 1e-3).
        let lambda = 5e-3;
        let span = 9.5 * lambda;
        let mut rng = Lcg::from_state(42);
        let mut p: Vec<(f64, f64)> = (0..700)
            .map(|_| {
                let s = span * rng.next_f64();
                (s, 3e-5 * (2.0 * PI * s / lambda).cos() + 0.02 * s)
            })
            .collect();
        p.push((0.0, 0.0));
        p.push((span, 3e-5 * (2.0 * PI * span / lambda).cos() + 0.02 * span));
        p.reverse();
        let m = wavelength(&p).expect("wrinkle");
        assert!(rel(m.wavelength, lambda) < 1e-3, "{m:?}");
    }

    #[test]
    fn few_periods_with_trend() {
        // Only 3.3 periods and a quadratic trend: 4 crossings (measured 2.0e-3); allow 1%.
        let lambda = 1e-2;
        let span = 3.3 * lambda;
        let p = profile(200, span, lambda, 1e-4, 0.7, |s| 2e-4 * (s / span).powi(2));
        let m = wavelength(&p).expect("wrinkle");
        assert!(rel(m.wavelength, lambda) < 1e-2, "{m:?}");
    }

    #[test]
    fn no_wrinkle_gives_none() {
        let span = 0.05;
        // Flat.
        let flat = profile(300, span, 1e-2, 0.0, 0.0, |_| 1e-3);
        assert!(wavelength(&flat).is_none());
        // A pure smooth trend (no oscillation).
        let trend = profile(300, span, 1e-2, 0.0, 0.0, |s| 0.1 * s * s + 0.01 * s);
        assert!(wavelength(&trend).is_none());
        // Round-off size ripples: amplitude 1e-12 m against a spacing ~1.7e-4 m.
        let tiny = profile(300, span, 5e-3, 1e-12, 0.0, |_| 0.0);
        assert!(wavelength(&tiny).is_none());
        // White noise: no single sinusoid explains half of it.
        let mut rng = Lcg::from_state(3);
        let noise: Vec<(f64, f64)> = (0..400)
            .map(|i| (i as f64 * 1e-4, 1e-4 * normal(&mut rng)))
            .collect();
        assert!(wavelength(&noise).is_none());
        // Too few samples, and non-finite samples.
        assert!(wavelength(&[(0.0, 0.0), (1.0, 1.0)]).is_none());
        let nan = vec![(f64::NAN, f64::NAN); 50];
        assert!(wavelength(&nan).is_none());
    }
}
