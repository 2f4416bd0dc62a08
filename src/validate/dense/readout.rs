//! What the dense run reads off the strip's top surface: the wrinkle amplitude, the onset
//! of the post-buckling law fitted over the load steps, and the height profiles whose
//! wavelength is measured.

use super::case::StepRecord;
use super::mesh::QuadMesh;
use crate::solver::status::SolveStatus;

/// √2 × RMS about the mean of the vertical displacement of the top row over the central 80%
/// of the strip (m).
pub(super) fn top_amplitude(mesh: &QuadMesh, x: &[f64], length: f64) -> f64 {
    let top = mesh.rows - 1;
    let u: Vec<f64> = (0..mesh.columns)
        .map(|c| mesh.node(c, top))
        .filter(|&n| (mesh.nodes[n][0] - 0.5 * length).abs() <= 0.4 * length)
        .map(|n| x[2 * n + 1] - mesh.nodes[n][1])
        .collect();
    let mean = u.iter().sum::<f64>() / u.len() as f64;
    (2.0 * u.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / u.len() as f64).sqrt()
}

/// Onset strain ε₀ and slope c of the post-buckling law A² = c (ε − ε₀), fitted by least
/// squares over the steps whose amplitude exceeds `min_amp` (m); `None` with fewer than two.
/// Theory (Huang, Hong and Suo 2005, film on substrate): ε₀ = ε_c, c = h² / ε_c.
pub(super) fn onset_fit(steps: &[StepRecord], min_amp: f64) -> Option<(f64, f64)> {
    let pts: Vec<(f64, f64)> = steps
        .iter()
        .filter(|s| s.amplitude > min_amp && s.status == SolveStatus::Converged)
        .map(|s| (s.strain, s.amplitude * s.amplitude))
        .collect();
    if pts.len() < 2 {
        return None;
    }
    let n = pts.len() as f64;
    let me = pts.iter().map(|p| p.0).sum::<f64>() / n;
    let ma = pts.iter().map(|p| p.1).sum::<f64>() / n;
    let sxy: f64 = pts.iter().map(|p| (p.0 - me) * (p.1 - ma)).sum();
    let sxx: f64 = pts.iter().map(|p| (p.0 - me).powi(2)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let c = sxy / sxx;
    if !(c > 0.0 && c.is_finite()) {
        return None;
    }
    Some((me - ma / c, c))
}

/// A height profile along the strip: (position along the strip, height), both in m.
pub(super) type Profile = Vec<(f64, f64)>;

/// The top row's height profile from flat positions `x` (m): (reference x, current y) and
/// (current x, current y), ordered along the strip.
pub(super) fn top_profiles(mesh: &QuadMesh, x: &[f64]) -> (Profile, Profile) {
    let top = mesh.rows - 1;
    let mut reference = Vec::with_capacity(mesh.columns);
    let mut current = Vec::with_capacity(mesh.columns);
    for c in 0..mesh.columns {
        let n = mesh.node(c, top);
        reference.push((mesh.nodes[n][0], x[2 * n + 1]));
        current.push((x[2 * n], x[2 * n + 1]));
    }
    (reference, current)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The onset fit recovers ε₀ and c from exact post-buckling data and ignores the
    /// pre-buckling steps below the amplitude threshold.
    #[test]
    fn onset_fit_recovers_known_law() {
        let (e0, c) = (0.02, 3e-6);
        let steps: Vec<StepRecord> = [0.01, 0.015, 0.022, 0.025, 0.03]
            .iter()
            .map(|&eps: &f64| StepRecord {
                strain: eps,
                iterations: 1,
                modified_hessian_steps: 0,
                residual: 0.0,
                status: SolveStatus::Converged,
                seconds: 0.0,
                assembly_factor_search_s: [0.0; 3],
                amplitude: if eps > e0 {
                    (c * (eps - e0)).sqrt()
                } else {
                    1e-7
                },
            })
            .collect();
        let (fe0, fc) = onset_fit(&steps, 1e-5).unwrap();
        assert!(
            (fe0 - e0).abs() < 1e-12 && (fc - c).abs() < 1e-15,
            "{fe0} {fc}"
        );
        assert!(onset_fit(&steps[..3], 1e-5).is_none());
    }
}
