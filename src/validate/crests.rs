//! Where the wrinkle crests fall relative to the lattice's element grid: the check that
//! trilinear elements lock the wrinkles to element boundaries and quadratic B-spline
//! elements do not.
//!
//! Measurement, on the compressed slab ([`super::slab`]):
//! 1. the wrinkle wavelength λ_m of the skin's height profile ([`super::measure::wavelength`]);
//! 2. the profile minus its moving average of width λ_m
//!    ([`super::measure::detrend_moving_average`]), which keeps the wrinkle and removes the
//!    slow bend;
//! 3. crests: samples higher than both neighbours and above half the detrended RMS·√2 (a
//!    sinusoid's amplitude), refined by the vertex of the parabola through the three
//!    samples, and kept only in the central part of the slab (`margin` of the span dropped
//!    at each end, where the pinned ends disturb the pattern);
//! 4. the phase of each crest within its cell, u = (x − x_face,k) / (x_face,k+1 − x_face,k) ∈
//!    [0, 1), with the faces' deformed positions ([`super::slab::SlabResult::faces`]), so u = 0
//!    is an element boundary and u = ½ a cell centre.
//!
//! Statistics of N phases (circular, angle θ = 2π u):
//! - the mean resultant length R = |Σ e^{iθ}| / N: 1 when every crest sits at the same phase,
//!   ~1/√N for uniform phases (E\[R²\] = 1/N; Rayleigh: P(R ≥ r) ≈ e^{−N r²});
//! - the boundary alignment V = Σ cos θ / N: +1 when every crest is on a boundary, −1 at cell
//!   centres, 0 on average for uniform phases with standard deviation 1/√(2N) (so √(2N) V is
//!   a z-score of locking to boundaries);
//! - the fraction of crests within `band` cells of a boundary (2 · band for uniform phases).
//!
//! Faceting ([`run_facets`]): where the wrinkle is much shorter than an element (λ ≪ cell),
//! the paper's other trilinear artefact is that the C⁰ joints of the elements show in the
//! skin. On a slab whose interior is held on a smooth bend, the trilinear embedded surface
//! kinks at every face by a known slope jump J; the skin's slope jump there (fitted on the
//! bend-removed height smoothed over λ_m) over J says how much of that crease the skin
//! shows, 0 for a C¹ (quadratic B-spline) interior.

use super::measure;
use super::slab::{run_slab, SlabResult, SlabSettings};
use crate::lattice::ElementOrder;
use std::f64::consts::PI;

/// Crest positions (m, along the compression axis) of a height profile `(position (m),
/// height (m))` with wrinkles of wavelength `wavelength` (m): local maxima of the profile
/// minus its moving average of width `wavelength`, higher than half the detrended RMS · √2,
/// refined by parabolic interpolation, within `[lo, hi]` (m).
pub fn crest_positions(profile: &[(f64, f64)], wavelength: f64, lo: f64, hi: f64) -> Vec<f64> {
    let r = measure::detrend_moving_average(profile, wavelength);
    if r.len() < 3 {
        return Vec::new();
    }
    let rms = (r.iter().map(|v| v.1 * v.1).sum::<f64>() / r.len() as f64).sqrt();
    let threshold = 0.5 * std::f64::consts::SQRT_2 * rms;
    let mut out = Vec::new();
    for w in r.windows(3) {
        let [(s0, z0), (s1, z1), (s2, z2)] = [w[0], w[1], w[2]];
        if !(z1 > z0 && z1 >= z2 && z1 > threshold) {
            continue;
        }
        // Vertex of the parabola through the three samples (non-uniform spacing).
        let d0 = (z1 - z0) / (s1 - s0);
        let d1 = (z2 - z1) / (s2 - s1);
        let curv = (d1 - d0) / (s2 - s0); // half the second derivative
        let x = if curv < 0.0 {
            (0.5 * (s0 + s1) - d0 / (2.0 * curv)).clamp(s0, s2)
        } else {
            s1
        };
        if x >= lo && x <= hi {
            out.push(x);
        }
    }
    out
}

/// Phase u ∈ [0, 1) of position `x` (m) within its cell, given the cells' face positions
/// `faces` (m, increasing): u = 0 on a face (an element boundary), ½ at the cell centre.
/// `None` outside `[faces[0], faces[last])`.
pub fn cell_phase(x: f64, faces: &[f64]) -> Option<f64> {
    if faces.len() < 2 || !(x >= faces[0] && x < faces[faces.len() - 1]) {
        return None;
    }
    let k = faces.partition_point(|&f| f <= x) - 1;
    let u = (x - faces[k]) / (faces[k + 1] - faces[k]);
    Some(u.clamp(0.0, 1.0) % 1.0)
}

/// Circular statistics of crest phases (see the module documentation).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct PhaseStats {
    /// Number of phases N.
    pub count: usize,
    /// Mean resultant length R ∈ [0, 1] of θ = 2π u (1 = all at one phase).
    pub resultant: f64,
    /// Mean phase (in cells, [0, 1)) of the resultant; meaningless when R is small.
    pub mean_phase: f64,
    /// Boundary alignment V = mean cos 2π u ∈ [−1, 1] (+1 = all on element boundaries).
    pub alignment: f64,
    /// √(2N) V: standard normal for uniform phases, large when locked to boundaries.
    pub alignment_z: f64,
    /// Rayleigh test p-value e^{−N R²} (small = not uniform), approximate for N ≳ 10.
    pub rayleigh_p: f64,
    /// Fraction of phases within `band` cells of a boundary (2 · band for uniform phases).
    pub near_boundary: f64,
    /// The band (cells) used for `near_boundary`.
    pub band: f64,
}

/// Statistics of phases `u` (cells, in [0, 1)); `band` (cells, < ½) for the near-boundary
/// fraction. All NaN (and count 0) for no phases.
pub fn phase_stats(u: &[f64], band: f64) -> PhaseStats {
    let n = u.len() as f64;
    let (c, s) = u.iter().fold((0.0, 0.0), |(c, s), &v| {
        (c + (2.0 * PI * v).cos(), s + (2.0 * PI * v).sin())
    });
    let (c, s) = (c / n, s / n);
    let resultant = c.hypot(s);
    let near = u.iter().filter(|&&v| v.min(1.0 - v) < band).count() as f64 / n;
    PhaseStats {
        count: u.len(),
        resultant,
        mean_phase: (s.atan2(c) / (2.0 * PI)).rem_euclid(1.0),
        alignment: c,
        alignment_z: (2.0 * n).sqrt() * c,
        rayleigh_p: (-n * resultant * resultant).exp(),
        near_boundary: near,
        band,
    }
}

/// Crests of one slab run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CrestRun {
    /// Element order of the lattice.
    pub order: ElementOrder,
    /// Lattice cells along the slab.
    pub cells_along: usize,
    /// Rest cell size (m).
    pub cell: f64,
    /// Predicted critical wavelength λ (m).
    pub predicted: f64,
    /// Measured wavelength (m) (NaN when no wrinkle was measured).
    pub measured: f64,
    /// Measured λ over the deformed mean cell size (dimensionless).
    pub lambda_over_cell: f64,
    /// Crest positions (m, deformed x).
    pub crests: Vec<f64>,
    /// Phase of each crest in its cell (cells, [0, 1)).
    pub phases: Vec<f64>,
    /// Phases (cells) of the crests of the skin's absolute height z, with the prescribed
    /// bend removed ([`bend_removed_profile`]), instead of its height w above the embedded
    /// surface (the same where the embedded surface is flat).
    pub height_phases: Vec<f64>,
    /// How much of the wrinkle the interior follows: RMS of the embedded surface's height
    /// B q over RMS of the skin's height w above it, both detrended by the moving average of
    /// width λ_m along the middle row (dimensionless; 0 = the interior stays smooth).
    pub surface_ratio: f64,
    /// Whether every shell statics converged.
    pub converged: bool,
    /// Wall-clock seconds of the slab run.
    pub seconds: f64,
}

/// Cells along the default 8 λ slab of the crest check: λ/cell ≈ 0.78, 0.91, 1.17, 1.42
/// (coarse lattices, non-commensurate ratios so that crests ignoring the grid sample all
/// phases).
pub const CELLS: [usize; 4] = [6, 7, 9, 11];

/// The slab of the crest check: [`SlabSettings::new`] for a skin 1000× stiffer than the
/// interior (h = 0.3 mm, equal Poisson ratios 0.45, λ ≈ 13.1 mm), with `cells` cells along
/// and element `order`.
pub fn slab_settings(order: ElementOrder, cells: usize) -> SlabSettings {
    let mut s = SlabSettings::new(super::wavelength::bilayer(1000.0, 0.3e-3));
    s.cells_along = cells;
    s.order = order;
    s
}

/// Run [`slab_settings`] for every order and cell count (orders outer); `progress` is called
/// with the number of runs done.
pub fn sweep(
    orders: &[ElementOrder],
    cells: &[usize],
    progress: &dyn Fn(usize),
) -> anyhow::Result<Vec<CrestRun>> {
    let mut out = Vec::new();
    for &o in orders {
        for &c in cells {
            out.push(run_crests(&slab_settings(o, c))?);
            progress(out.len());
        }
    }
    Ok(out)
}

/// Fraction of the profile's span ignored at each end when collecting crests.
pub const MARGIN: f64 = 0.1;

/// Crests and their cell phases of a finished slab run (`margin`: fraction of the span
/// dropped at each end). The wavelength used for detrending is the measured one, or the
/// predicted one when no wrinkle was measured.
pub fn crests_of(r: &SlabResult, margin: f64) -> (f64, Vec<f64>, Vec<f64>) {
    let measured = measure::wavelength(&r.profile)
        .map(|m| m.wavelength)
        .unwrap_or(f64::NAN);
    let lambda = if measured.is_finite() {
        measured
    } else {
        r.predicted
    };
    let (s0, s1) = match (r.profile.first(), r.profile.last()) {
        (Some(a), Some(b)) => (a.0, b.0),
        _ => return (measured, Vec::new(), Vec::new()),
    };
    let m = margin * (s1 - s0);
    let crests = crest_positions(&r.profile, lambda, s0 + m, s1 - m);
    let phases = crests
        .iter()
        .filter_map(|&x| cell_phase(x, &r.faces))
        .collect();
    (measured, crests, phases)
}

/// RMS of the detrended embedded-surface height over RMS of the detrended skin height w
/// along the middle row (moving average of width `wavelength`, m).
fn surface_ratio(r: &SlabResult, wavelength: f64) -> f64 {
    let rms = |p: Vec<(f64, f64)>| {
        let d = measure::detrend_moving_average(&p, wavelength);
        (d.iter().map(|v| v.1 * v.1).sum::<f64>() / d.len().max(1) as f64).sqrt()
    };
    let surface = rms(r.row.iter().map(|s| (s.x, s.surface_z)).collect());
    let skin = rms(r.profile.clone());
    surface / skin
}

/// Run one slab and find where its crests fall in the element grid.
pub fn run_crests(s: &SlabSettings) -> anyhow::Result<CrestRun> {
    let r = run_slab(s)?;
    let (measured, crests, phases) = crests_of(&r, MARGIN);
    let z = SlabResult {
        profile: bend_removed_profile(s, &r),
        ..r.clone()
    };
    let (_, _, height_phases) = crests_of(&z, MARGIN);
    let mean_cell = match (r.faces.first(), r.faces.last()) {
        (Some(a), Some(b)) if r.faces.len() > 1 => (b - a) / (r.faces.len() - 1) as f64,
        _ => f64::NAN,
    };
    Ok(CrestRun {
        order: s.order,
        cells_along: s.cells_along,
        cell: r.cell,
        predicted: r.predicted,
        measured,
        lambda_over_cell: measured / mean_cell,
        surface_ratio: surface_ratio(
            &r,
            if measured.is_finite() {
                measured
            } else {
                r.predicted
            },
        ),
        crests,
        phases,
        height_phases,
        converged: r.converged,
        seconds: r.seconds,
    })
}

// ---------------------------------------------------------------------------------------
// Faceting: the trilinear element boundaries seen in the skin (the paper's high-frequency
// artefact, λ ≪ cell).
// ---------------------------------------------------------------------------------------

/// Cells along the faceting slab: 4 cells over 16 λ, so each cell is 4 λ (λ/cell ≈ 0.26
/// measured): the wrinkle is much shorter than an element, the paper's "high wrinkle
/// frequency" regime in which the C⁰ joints of trilinear elements show in the skin.
pub const FACET_CELLS: usize = 4;

/// The slab of the faceting check: [`slab_settings`] 16 λ long with [`FACET_CELLS`] cells
/// (cell = 4 λ ≈ 52 mm) and a fully held interior bent by a sine of amplitude 0.3 λ (3.9 mm)
/// and period 10.8 λ (2.7 cells, incommensurate with the grid so every face sees a different
/// bend phase), phase 0.3 period. The trilinear interpolant of that bend has slope jumps of
/// 0.07–0.24 rad at the interior faces, comparable to the wrinkle's slope 2π A/λ ≈ 0.5
/// (A ≈ 0.08 λ measured); the quadratic B-spline surface is C¹ (no jumps).
pub fn facet_slab_settings(order: ElementOrder) -> SlabSettings {
    let mut s = slab_settings(order, FACET_CELLS);
    s.length = 16.0;
    s.bend = 0.3;
    s.bend_period = 10.8;
    s.bend_phase = 0.3;
    s
}

/// Slope jumps (rad, small-angle: right slope − left slope, in the deformed frame) of the
/// trilinear interpolant of the bend at the interior faces i = 1 ..= cells_along − 1 of a
/// held, affinely compressed slab: (b_{i+1} − 2 b_i + b_{i−1}) / (cell (1 − ε)), b_i the bend
/// height at face i. This is the kink a trilinear lattice puts in the embedded surface;
/// quadratic B-spline surfaces have none.
pub fn trilinear_slope_jumps(s: &SlabSettings, r: &SlabResult) -> Vec<f64> {
    let eps = r.strains.last().copied().unwrap_or(0.0);
    let b = |i: usize| s.bend_height(r.predicted, i as f64 * r.cell);
    (1..s.cells_along)
        .map(|i| (b(i + 1) - 2.0 * b(i) + b(i - 1)) / (r.cell * (1.0 - eps)))
        .collect()
}

/// The skin's height along the middle row minus the least-squares fit of {1, X, sin θ,
/// cos θ}, θ = 2π (X/P + φ), in the rest position X (P, φ the bend's period and phase): removes
/// the prescribed smooth bend whatever amplitude each element order gives it (a quadratic
/// B-spline scales a sampled sine down), leaving the wrinkle and anything tied to the grid.
/// `(deformed x (m), height (m))`, ordered by x. With no bend only the line is removed.
pub fn bend_removed_profile(s: &SlabSettings, r: &SlabResult) -> Vec<(f64, f64)> {
    use nalgebra::{Matrix4, Vector4};
    let period = s.bend_period * r.predicted;
    let basis = |x: f64| {
        let a = 2.0 * PI * (x / period + s.bend_phase);
        if s.bend > 0.0 {
            Vector4::new(1.0, x / r.length, a.sin(), a.cos())
        } else {
            Vector4::new(1.0, x / r.length, 0.0, 0.0)
        }
    };
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    for v in &r.row {
        let b = basis(v.rest_x);
        ata += b * b.transpose();
        atb += b * v.z;
    }
    if s.bend <= 0.0 {
        ata[(2, 2)] = 1.0;
        ata[(3, 3)] = 1.0;
    }
    let coef = ata.try_inverse().unwrap_or_else(Matrix4::zeros) * atb;
    r.row
        .iter()
        .map(|v| (v.x, v.z - coef.dot(&basis(v.rest_x))))
        .collect()
}

/// The moving average of width `width` (m) of a profile `(position (m), height (m))` (the
/// exact mean of the piecewise linear profile over [x − width/2, x + width/2]): a sinusoid
/// of period `width` averages to zero, so with `width` = λ_m it removes the wrinkle and keeps
/// the slow shape. Samples whose window does not fit are dropped; ordered by position.
pub fn moving_average(profile: &[(f64, f64)], width: f64) -> Vec<(f64, f64)> {
    let p = measure::sorted_finite(profile);
    measure::detrend_moving_average(&p, width)
        .into_iter()
        .filter_map(|(x, d)| {
            let i = p.binary_search_by(|v| v.0.total_cmp(&x)).ok()?;
            Some((x, p[i].1 - d))
        })
        .collect()
}

/// Slope jump (rad, small-angle: right slope − left slope) at `xf` (m) of a profile that was
/// smoothed by a moving average of width `blur` (m, 0 for none): the least-squares fit of
/// a + b d + c d² + κ g(d) to the samples with |d| = |x − xf| ≤ `half` (m) gives 2κ, g the
/// moving average of |d| (|d| beyond blur/2, (d² + blur²/4)/blur inside). A kink of slope
/// jump J smoothed by that moving average gives exactly J (plus sampling error); a C¹
/// profile gives ≈ 0 (the quadratic absorbs its curvature); a kink blurred further (by the
/// skin's own smoothness) gives less than J. `None` with fewer than 8 samples in the window.
pub fn slope_jump(profile: &[(f64, f64)], xf: f64, half: f64, blur: f64) -> Option<f64> {
    use nalgebra::{Matrix4, Vector4};
    let mut ata = Matrix4::<f64>::zeros();
    let mut atb = Vector4::<f64>::zeros();
    let mut n = 0;
    let bw = blur / half;
    for &(x, z) in profile {
        let d = (x - xf) / half;
        if d.abs() <= 1.0 {
            let g = if d.abs() >= 0.5 * bw {
                d.abs()
            } else {
                (d * d + 0.25 * bw * bw) / bw
            };
            let b = Vector4::new(1.0, d, d * d, g);
            ata += b * b.transpose();
            atb += b * z;
            n += 1;
        }
    }
    if n < 8 {
        return None;
    }
    let c = ata.try_inverse()? * atb;
    Some(2.0 * c[3] / half)
}

/// How much of the trilinear kink the skin shows at some positions: the least-squares
/// factor f = Σ J_skin J / Σ J² over faces (J the trilinear slope jump of the embedded
/// surface at that face, J_skin the skin's measured slope jump), 1 = the skin creases as
/// much as the trilinear embedded surface, 0 = smooth.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct KinkFraction {
    /// Offset of the probed positions from the faces (cells): 0 = on the element
    /// boundaries, ½ = at cell centres (the null positions, no kink there for either order).
    pub offset: f64,
    /// The factor f (dimensionless).
    pub fraction: f64,
    /// J_skin / J per face used (dimensionless).
    pub per_face: Vec<f64>,
}

/// The outcome of one faceting slab run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct FacetRun {
    /// Element order of the lattice.
    pub order: ElementOrder,
    /// Predicted critical wavelength λ (m).
    pub predicted: f64,
    /// Measured wavelength of the bend-removed skin height (m; NaN when none was measured).
    pub measured: f64,
    /// Measured λ over the deformed mean cell size (dimensionless).
    pub lambda_over_cell: f64,
    /// Wrinkle amplitude of the bend-removed skin height (m; NaN when none was measured).
    pub amplitude: f64,
    /// Trilinear slope jumps (rad) at the interior faces ([`trilinear_slope_jumps`]).
    pub jumps: Vec<f64>,
    /// Half-width (m) of the window of [`slope_jump`] (1.5 λ_m); its blur is λ_m.
    pub window: f64,
    /// The skin's kink fraction on the faces (offset 0).
    pub at_faces: KinkFraction,
    /// The same at cell centres (offset ½): the null model, ≈ 0 for any order.
    pub at_centres: KinkFraction,
    /// Whether every shell statics converged.
    pub converged: bool,
    /// Wall-clock seconds of the slab run.
    pub seconds: f64,
}

/// Run a (bent, held) slab and measure how much of the trilinear kink at each element
/// boundary shows in the skin: the bend-removed skin height ([`bend_removed_profile`]) is
/// smoothed by a moving average of width λ_m (the wrinkle averages out), and its slope jump
/// ([`slope_jump`], half-window 1.5 λ_m) is compared with the trilinear interpolant's
/// ([`trilinear_slope_jumps`]) at the faces and at the cell centres. Faces whose window
/// leaves the central part of the profile (`MARGIN`) are skipped.
pub fn run_facets(s: &SlabSettings) -> anyhow::Result<FacetRun> {
    let r = run_slab(s)?;
    let profile = bend_removed_profile(s, &r);
    let m = measure::wavelength(&profile);
    let measured = m.as_ref().map(|m| m.wavelength).unwrap_or(f64::NAN);
    let lambda = if measured.is_finite() {
        measured
    } else {
        r.predicted
    };
    let smooth = moving_average(&profile, lambda);
    let jumps = trilinear_slope_jumps(s, &r);
    let (x0, x1) = match (profile.first(), profile.last()) {
        (Some(a), Some(b)) => (a.0, b.0),
        _ => anyhow::bail!("the slab run returned an empty profile"),
    };
    let (lo, hi) = (x0 + MARGIN * (x1 - x0), x1 - MARGIN * (x1 - x0));
    let half = 1.5 * lambda;
    let mean_cell = (r.faces[r.faces.len() - 1] - r.faces[0]) / (r.faces.len() - 1) as f64;
    let probe = |offset: f64| {
        let (mut num, mut den, mut per_face) = (0.0, 0.0, Vec::new());
        for (k, &j) in jumps.iter().enumerate() {
            let xf = r.faces[k + 1] + offset * mean_cell;
            if xf - half < lo || xf + half > hi {
                continue;
            }
            if let Some(js) = slope_jump(&smooth, xf, half, lambda) {
                num += js * j;
                den += j * j;
                per_face.push(js / j);
            }
        }
        KinkFraction {
            offset,
            fraction: num / den,
            per_face,
        }
    };
    let (at_faces, at_centres) = (probe(0.0), probe(0.5));
    Ok(FacetRun {
        order: s.order,
        predicted: r.predicted,
        measured,
        lambda_over_cell: measured / mean_cell,
        amplitude: m.map(|m| m.amplitude).unwrap_or(f64::NAN),
        jumps,
        window: half,
        at_faces,
        at_centres,
        converged: r.converged,
        seconds: r.seconds,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sinusoid on a quadratic trend, sampled unevenly: the crests come back at the
    /// sinusoid's maxima to a small fraction of the sample spacing.
    #[test]
    fn crests_of_a_sinusoid_on_a_trend() {
        let lambda = 1.0;
        let phase = 0.3;
        let profile: Vec<(f64, f64)> = (0..=200)
            .map(|i| {
                let s = i as f64 * 0.05 + 0.004 * ((i * 7) % 5) as f64;
                let z = (2.0 * PI * (s - phase) / lambda).cos() + 0.02 * (s - 5.0).powi(2);
                (s, z)
            })
            .collect();
        let c = crest_positions(&profile, lambda, 1.0, 9.0);
        // Crests at phase + k λ inside [1, 9]: 1.3, 2.3, ..., 8.3.
        assert_eq!(c.len(), 8, "{c:?}");
        for (k, x) in c.iter().enumerate() {
            let want = 1.3 + k as f64;
            assert!((x - want).abs() < 0.01, "crest {x} vs {want}");
        }
    }

    /// Known answers of the kink fit: a kink of slope jump J = 0.2 on a parabola, with a
    /// wrinkle of period 1 on top, moving-averaged over the wrinkle's period: the fit gives J
    /// to 2 %; the same profile without the kink gives |J| < 0.005; at a point 2 periods from
    /// the kink it gives |J| < 0.005.
    #[test]
    fn slope_jump_of_a_blurred_kink() {
        let lambda = 1.0;
        let make = |jump: f64| -> Vec<(f64, f64)> {
            (0..=400)
                .map(|i| {
                    let x = i as f64 * 0.05;
                    let z = 0.5 * jump * (x - 10.0).abs()
                        + 0.01 * (x - 7.0).powi(2)
                        + 0.08 * (2.0 * PI * x / lambda + 0.4).sin();
                    (x, z)
                })
                .collect()
        };
        let smooth = moving_average(&make(0.2), lambda);
        let j = slope_jump(&smooth, 10.0, 1.5 * lambda, lambda).unwrap();
        assert!((j - 0.2).abs() < 0.004, "{j}");
        let j0 = slope_jump(&moving_average(&make(0.0), lambda), 10.0, 1.5, lambda).unwrap();
        assert!(j0.abs() < 0.005, "{j0}");
        let jf = slope_jump(&smooth, 13.5, 1.5, lambda).unwrap();
        assert!(jf.abs() < 0.005, "{jf}");
        // Without the blur in the model, the fit sees only part of the blurred kink.
        let jn = slope_jump(&smooth, 10.0, 1.5, 0.0).unwrap();
        println!("blurred kink: {j:.4} with the blur modelled, {jn:.4} without (J = 0.2)");
        assert_eq!(slope_jump(&smooth, 100.0, 1.5, lambda), None);
    }

    /// The bend height follows its formula, phase included; with no bend it is 0.
    #[test]
    fn bend_height_and_phase() {
        let mut s = facet_slab_settings(ElementOrder::Trilinear);
        let lambda = 0.01;
        // sin(2π (x/P + φ)) at x = 0 is sin(2π · 0.3); a quarter period later it is cos.
        let p = s.bend_period * lambda;
        let a = s.bend * lambda;
        assert!((s.bend_height(lambda, 0.0) - a * (2.0 * PI * 0.3).sin()).abs() < 1e-15);
        assert!((s.bend_height(lambda, 0.25 * p) - a * (2.0 * PI * 0.3).cos()).abs() < 1e-15);
        s.bend = 0.0;
        assert_eq!(s.bend_height(lambda, 0.3), 0.0);
    }

    #[test]
    fn phase_within_cell() {
        let faces = [0.0, 1.0, 2.5, 3.0];
        assert_eq!(cell_phase(0.25, &faces), Some(0.25));
        assert_eq!(cell_phase(1.75, &faces), Some(0.5));
        assert_eq!(cell_phase(2.5, &faces), Some(0.0));
        assert_eq!(cell_phase(3.0, &faces), None);
        assert_eq!(cell_phase(-0.1, &faces), None);
    }

    /// Known answers: all phases on boundaries give R = V = 1; phases spread evenly give
    /// R = V = 0; all at cell centres give R = 1, V = −1.
    #[test]
    fn phase_statistics_known_answers() {
        let locked = [0.0, 0.02, 0.98, 0.0];
        let s = phase_stats(&locked, 0.1);
        assert!(s.resultant > 0.99 && s.alignment > 0.99);
        assert_eq!(s.near_boundary, 1.0);
        let even: Vec<f64> = (0..10).map(|i| i as f64 / 10.0).collect();
        let s = phase_stats(&even, 0.15);
        assert!(s.resultant < 1e-12 && s.alignment.abs() < 1e-12);
        // u = 0, 0.1 and 0.9 are within 0.15 of a boundary: 3 of 10.
        assert!((s.near_boundary - 0.3).abs() < 1e-12);
        let centre = [0.5; 5];
        let s = phase_stats(&centre, 0.1);
        assert!((s.resultant - 1.0).abs() < 1e-12 && (s.alignment + 1.0).abs() < 1e-12);
        assert!((s.mean_phase - 0.5).abs() < 1e-12);
        assert_eq!(s.near_boundary, 0.0);
    }

    /// The null model: N uniform pseudo-random phases give E[R²] = 1/N and a standard normal
    /// √(2N) V; over 400 draws of N = 20 the means match to sampling error.
    #[test]
    fn null_model_of_uniform_phases() {
        let mut rng = crate::math::rng::Lcg::from_state(12345);
        let mut next = || rng.next_f64();
        let (draws, n) = (400, 20);
        let (mut r2, mut z2) = (0.0, 0.0);
        for _ in 0..draws {
            let u: Vec<f64> = (0..n).map(|_| next()).collect();
            let s = phase_stats(&u, 0.1);
            r2 += s.resultant.powi(2) * n as f64;
            z2 += s.alignment_z.powi(2);
        }
        // N R² is exponential with mean 1 and z² is χ²₁ (mean 1, sd √2): with 400 draws the
        // means have standard errors 0.05 and 0.07.
        let (r2, z2) = (r2 / draws as f64, z2 / draws as f64);
        assert!((r2 - 1.0).abs() < 0.2, "mean N R² = {r2}");
        assert!((z2 - 1.0).abs() < 0.25, "mean z² = {z2}");
    }
}
