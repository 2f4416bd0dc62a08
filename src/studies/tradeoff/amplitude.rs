//! The phase-free wrinkle error: a run's wrinkle amplitude per region (cubes of side 2 λ over
//! the blend-shape surface) against the reference run's, which does not depend on where the
//! crests fall; and the relative change of the slab's measured amplitude and wavelength.

use super::distance::key;
use crate::mesh::TriMesh;
use crate::pipeline;
use nalgebra::Vector3;
use std::collections::HashMap;

/// Wrinkle amplitude scale of a rig run: RMS over vertices and frames of the wrinkled minus
/// the blend-shape-only surface (m). Used to set the rig's error tolerances.
pub fn wrinkle_rms(out: &pipeline::RunOutput) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (f, g) in out.frames.iter().zip(&out.smooth) {
        for (p, q) in f.iter().zip(g) {
            s += (p - q).norm_squared();
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// |a / b − 1| of two optional positive measurements (a wrinkle amplitude or wavelength, m);
/// 1 when either is missing or not positive (no wrinkle counts as entirely wrong), 0 when
/// both are missing (neither run wrinkled).
pub fn relative_change(a: Option<f64>, b: Option<f64>) -> f64 {
    match (a, b) {
        (Some(a), Some(b)) if a > 0.0 && b > 0.0 => (a / b - 1.0).abs(),
        (None, None) => 0.0,
        _ => 1.0,
    }
}

/// Side (m) of the regions of [`amplitude_map`] for a run: two critical wavelengths of its
/// report, so each region holds whole wrinkles; when no skin was simulated (λ not finite),
/// an eighth of the largest extent of the first blend-shape frame.
pub fn region_size(out: &pipeline::RunOutput) -> f64 {
    let lambda = out.report.wavelength_m;
    if lambda.is_finite() && lambda > 0.0 {
        return 2.0 * lambda;
    }
    let Some(first) = out.smooth.first() else {
        return 1.0;
    };
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for p in first {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi - lo).max();
    if extent.is_finite() && extent > 0.0 {
        extent / 8.0
    } else {
        1.0
    }
}

/// Wrinkle amplitude per region and frame: for each written frame, a map from a region
/// (cube of side `region` m, indexed by the floor of the blend-shape position / `region`) to
/// (Σ A w² (m⁴), Σ A (m²)), with w = (wrinkled − blend-shape position) · n the wrinkle
/// height along the blend-shape surface's unit vertex normal n and A the vertex's share of
/// that surface's area (a third of its triangles'): an RMS over the surface, so meshes of
/// different resolution (a skin refined only where it is simulated) weigh alike.
#[derive(Debug, Clone)]
pub struct AmplitudeMap {
    /// Region side (m).
    pub region: f64,
    /// Per frame: region → (Σ A w² in m⁴, Σ A in m²).
    pub frames: Vec<HashMap<[i64; 3], (f64, f64)>>,
}

impl AmplitudeMap {
    /// Build from per-frame wrinkled and blend-shape positions (m) of the same vertices and
    /// the triangles that give the normals.
    pub fn new(
        frames: &[Vec<Vector3<f64>>],
        smooth: &[Vec<Vector3<f64>>],
        triangles: &[[usize; 3]],
        region: f64,
    ) -> Self {
        let topo = TriMesh {
            positions: Vec::new(),
            triangles: triangles.to_vec(),
        };
        let maps = frames
            .iter()
            .zip(smooth)
            .map(|(f, g)| {
                let normals = topo.vertex_normals_of(g);
                let area = topo.vertex_areas_of(g);
                let mut m: HashMap<[i64; 3], (f64, f64)> = HashMap::new();
                for (((p, q), n), a) in f.iter().zip(g).zip(&normals).zip(&area) {
                    let w = (p - q).dot(n);
                    let e = m.entry(key(q, region)).or_insert((0.0, 0.0));
                    e.0 += a * w * w;
                    e.1 += a;
                }
                m
            })
            .collect();
        Self {
            region,
            frames: maps,
        }
    }
}

/// The [`AmplitudeMap`] of a rig run with regions of side `region` (m).
pub fn amplitude_map(out: &pipeline::RunOutput, region: f64) -> AmplitudeMap {
    AmplitudeMap::new(&out.frames, &out.smooth, &out.triangles, region)
}

/// Phase-free relative error of a run's wrinkle amplitude map against the reference's:
/// √(Σ A_ref (a − a_ref)² / Σ A_ref a_ref²) over frames and the reference's regions, with a
/// the region's area-weighted RMS wrinkle height (m) and A_ref the reference's surface area
/// there (so regions weigh by their size whatever either run's resolution). A region the run lacks counts
/// as a = 0. Dimensionless: 0 for the same amplitudes wherever the crests are, 1 for no
/// wrinkles; 0 when the reference has no wrinkles and neither has the run.
pub fn amplitude_error(run: &AmplitudeMap, reference: &AmplitudeMap) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (k, rf) in reference.frames.iter().enumerate() {
        let empty = HashMap::new();
        let rn = run.frames.get(k).unwrap_or(&empty);
        // In key order: the sums do not depend on the hash map's iteration order.
        let mut keys: Vec<&[i64; 3]> = rf.keys().collect();
        keys.sort_unstable();
        for key in keys {
            let (sq, area) = rf[key];
            if area <= 0.0 {
                continue;
            }
            let a_ref = (sq / area).sqrt();
            let a = rn
                .get(key)
                .filter(|&&(_, m)| m > 0.0)
                .map_or(0.0, |&(s, m)| (s / m).sqrt());
            num += area * (a - a_ref).powi(2);
            den += area * a_ref * a_ref;
        }
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else if num > 0.0 {
        1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Wrinkled positions, smooth positions and triangles of a test surface.
    type Wrinkled = (Vec<Vector3<f64>>, Vec<Vector3<f64>>, Vec<[usize; 3]>);

    /// A flat grid (z = 0, x in [0, 4), y in [0, 2)) with a wrinkle w = A sin(2π x / λ + φ)
    /// along its normal: (wrinkled, smooth, triangles).
    fn wrinkled_grid(a: f64, lambda: f64, phi: f64) -> Wrinkled {
        let xs: Vec<f64> = (0..80).map(|i| i as f64 * 0.05).collect();
        wrinkled_grid_at(&xs, |x| {
            a * (2.0 * std::f64::consts::PI * x / lambda + phi).sin()
        })
    }

    /// A flat grid with columns at `xs` and rows 0.05 apart (y in [0, 2)), displaced along
    /// its normal by w(x): (wrinkled, smooth, triangles).
    fn wrinkled_grid_at(xs: &[f64], w: impl Fn(f64) -> f64) -> Wrinkled {
        let (nx, ny, h) = (xs.len(), 40, 0.05);
        let mut smooth = Vec::new();
        for j in 0..ny {
            for &x in xs {
                smooth.push(Vector3::new(x, j as f64 * h, 0.0));
            }
        }
        let id = |i: usize, j: usize| j * nx + i;
        let mut tris = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let wrinkled = smooth.iter().map(|p| p + Vector3::z() * w(p.x)).collect();
        (wrinkled, smooth, tris)
    }

    /// A region half wrinkled and half flat scores the same whether its wrinkled half is
    /// sampled as densely as the rest or four times as densely (a skin refined only where it
    /// is simulated): the RMS is over area, not over vertices (counting vertices gave 0.26).
    #[test]
    fn amplitude_error_does_not_depend_on_the_resolution() {
        let w = |x: f64| {
            if x < 2.0 {
                0.01 * (2.0 * std::f64::consts::PI * x / 0.5).sin()
            } else {
                0.0
            }
        };
        let uniform: Vec<f64> = (0..80).map(|i| i as f64 * 0.05).collect();
        let refined: Vec<f64> = (0..160)
            .map(|i| i as f64 * 0.0125)
            .chain((40..80).map(|i| i as f64 * 0.05))
            .collect();
        let map = |xs: &[f64]| {
            let (wr, s, t) = wrinkled_grid_at(xs, w);
            AmplitudeMap::new(&[wr], &[s], &t, 4.0)
        };
        let e = amplitude_error(&map(&refined), &map(&uniform));
        assert!(e < 0.02, "{e}");
    }

    /// The amplitude error is phase-free: wrinkles shifted by a quarter wavelength (whose
    /// surface distance is as large as the wrinkles) score ~0; regions of 2.5 wavelengths
    /// bound the phase dependence of a region's mean square by 1/(4π · 2.5) ≈ 3 %; a 20 %
    /// larger amplitude scores 0.2; no wrinkles score 1.
    #[test]
    fn amplitude_error_ignores_the_phase_and_sees_the_size() {
        let map = |a: f64, lambda: f64, phi: f64| {
            let (w, s, t) = wrinkled_grid(a, lambda, phi);
            AmplitudeMap::new(&[w], &[s], &t, 2.0)
        };
        let a = 0.01;
        for lambda in [1.0, 0.8] {
            let reference = map(a, lambda, 0.0);
            let shifted = amplitude_error(&map(a, lambda, 0.5 * std::f64::consts::PI), &reference);
            assert!(shifted < 0.05, "λ = {lambda}: shifted error {shifted}");
            let bigger = amplitude_error(&map(1.2 * a, lambda, 0.3), &reference);
            assert!(
                (bigger - 0.2).abs() < 0.03,
                "λ = {lambda}: 1.2 A gives {bigger}"
            );
            let none = amplitude_error(&map(0.0, lambda, 0.0), &reference);
            assert!((none - 1.0).abs() < 1e-12, "no wrinkles give {none}");
            assert!(amplitude_error(&reference, &reference) < 1e-12);
        }
        // Regions of whole periods with whole sample counts: phase-free but for the grid's
        // border columns, which hold half a column's area (0.7 %).
        let e = amplitude_error(&map(a, 1.0, 1.0), &map(a, 1.0, 0.0));
        assert!(e < 0.01, "{e}");
        assert_eq!(relative_change(Some(2.0), Some(1.0)), 1.0);
        assert_eq!(relative_change(None, Some(1.0)), 1.0);
        assert_eq!(relative_change(None, None), 0.0);
        assert!((relative_change(Some(0.9), Some(1.0)) - 0.1).abs() < 1e-12);
    }
}
