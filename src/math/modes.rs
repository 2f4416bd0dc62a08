//! A few modes for many frames: the truncated SVD of a clip of per-vertex vector fields
//! (wrinkle offsets, m), with as many modes as it takes for the largest per-vertex error of
//! any frame to fall under a tolerance, and least-squares fits of companion fields (normal
//! offsets) on the chosen modes' coefficients.
//!
//! The data matrix A (3n × F: frame k's field in column k, x y z per vertex) is decomposed as
//! A = U Σ Vᵀ (faer's thin SVD, sequential so the bits do not depend on the thread count). With
//! the first K modes, frame k is reconstructed as Σ_m u_m c_km, c_km = σ_m v_km, the least-
//! squares coefficients (the modes are orthonormal). K grows from 0 until
//! max_k max_v ‖a_k(v) − Σ_m u_m(v) c_km‖ ≤ tolerance, or the cap, or the rank, is reached.
//! Signs are fixed so that each mode's largest-magnitude entry (the first among equals) is
//! positive: the same frames give the same modes, bit for bit.

use anyhow::bail;
use faer::linalg::svd::{self, ComputeSvdVectors};
use faer::{Mat, Par};
use nalgebra::Vector3;
use rayon::prelude::*;

/// What decided the number of modes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum ModeBound {
    /// The largest per-frame error reached the tolerance.
    Error,
    /// The cap on the number of modes (the error may still be above the tolerance).
    Cap,
    /// Every mode with a non-zero singular value is used: the reconstruction is exact (to
    /// round-off).
    Rank,
}

/// A truncated modal basis of a clip.
#[derive(Debug, Clone)]
pub struct ModeBasis {
    /// The K modes, each one vector per vertex (orthonormal as 3n-vectors).
    pub modes: Vec<Vec<Vector3<f64>>>,
    /// Per frame, the K coefficients c_km (units of the data: a frame is Σ_m c_km u_m).
    pub coefficients: Vec<Vec<f64>>,
    /// Per frame, the largest per-vertex error of the reconstruction (units of the data).
    pub frame_error: Vec<f64>,
    /// The largest of `frame_error`.
    pub error: f64,
    /// What decided K.
    pub bound: ModeBound,
    /// All singular values of the clip (descending), for the report.
    pub singular_values: Vec<f64>,
}

/// Largest vector norm in the clip `a` (see [`clip_matrix`]; 0 for an empty clip).
pub fn largest_norm(a: &Mat<f64>) -> f64 {
    frame_errors(a).into_iter().fold(0.0, f64::max)
}

/// The data matrix of a clip: frame k's field (one vector per vertex, `n` vertices) in column
/// k, x y z per vertex. `frame(k)` gives frame k.
pub fn clip_matrix(
    frames: usize,
    n: usize,
    frame: impl Fn(usize) -> anyhow::Result<Vec<Vector3<f64>>>,
) -> anyhow::Result<Mat<f64>> {
    let mut a = Mat::<f64>::zeros(3 * n, frames);
    for k in 0..frames {
        let f = frame(k)?;
        if f.len() != n {
            bail!("frame {k} has {} vertices, expected {n}", f.len());
        }
        for (i, d) in f.iter().enumerate() {
            for c in 0..3 {
                a[(3 * i + c, k)] = d[c];
            }
        }
    }
    Ok(a)
}

/// The truncated SVD basis of the clip `a` (see [`clip_matrix`]; consumed: it becomes the
/// residual) with the fewest modes whose largest per-vertex error over every frame is at most
/// `tolerance`, at most `cap` modes.
pub fn truncated_basis(mut a: Mat<f64>, tolerance: f64, cap: usize) -> anyhow::Result<ModeBasis> {
    let (rows, f) = a.shape();
    let n = rows / 3;
    if f == 0 || n == 0 || rows % 3 != 0 {
        bail!("no frames to reduce");
    }
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        bail!("the mode tolerance must be a non-negative length, got {tolerance}");
    }
    let (u, s, v) = thin_svd(&a)?;
    let sigma0 = s.first().copied().unwrap_or(0.0);
    let rank = s.iter().take_while(|&&x| x > 1e-13 * sigma0).count();
    let mut frame_error = frame_errors(&a);
    let mut k_modes = 0;
    let bound = loop {
        if frame_error.iter().all(|&e| e <= tolerance) {
            break ModeBound::Error;
        }
        if k_modes == rank {
            break ModeBound::Rank;
        }
        if k_modes == cap {
            break ModeBound::Cap;
        }
        let m = k_modes;
        let um = u.col(m);
        a.par_col_iter_mut().enumerate().for_each(|(k, r)| {
            let c = s[m] * v[(k, m)];
            for (ri, ui) in r.iter_mut().zip(um.iter()) {
                *ri -= ui * c;
            }
        });
        frame_error = frame_errors(&a);
        k_modes += 1;
    };
    let modes = (0..k_modes)
        .map(|m| {
            (0..n)
                .map(|i| Vector3::new(u[(3 * i, m)], u[(3 * i + 1, m)], u[(3 * i + 2, m)]))
                .collect()
        })
        .collect();
    let coefficients = (0..f)
        .map(|k| (0..k_modes).map(|m| s[m] * v[(k, m)]).collect())
        .collect();
    let error = frame_error.iter().copied().fold(0.0, f64::max);
    Ok(ModeBasis {
        modes,
        coefficients,
        frame_error,
        error,
        bound,
        singular_values: s,
    })
}

/// The thin SVD of `a` (sequential): U (3n × r), the singular values (descending) and V
/// (F × r), r = min(3n, F), each mode's sign fixed (largest-magnitude entry of u positive).
fn thin_svd(a: &Mat<f64>) -> anyhow::Result<(Mat<f64>, Vec<f64>, Mat<f64>)> {
    let (m, n) = a.shape();
    let r = m.min(n);
    let mut u = Mat::<f64>::zeros(m, r);
    let mut v = Mat::<f64>::zeros(n, r);
    let mut s = faer::diag::Diag::<f64>::zeros(r);
    let par = Par::Seq;
    let scratch = svd::svd_scratch::<f64>(
        m,
        n,
        ComputeSvdVectors::Thin,
        ComputeSvdVectors::Thin,
        par,
        Default::default(),
    );
    let mut mem = faer::dyn_stack::MemBuffer::new(scratch);
    svd::svd(
        a.as_ref(),
        s.as_mut(),
        Some(u.as_mut()),
        Some(v.as_mut()),
        par,
        faer::dyn_stack::MemStack::new(&mut mem),
        Default::default(),
    )
    .map_err(|e| anyhow::anyhow!("the SVD of the clip did not converge: {e:?}"))?;
    let sv: Vec<f64> = (0..r).map(|i| s[i]).collect();
    for j in 0..r {
        let mut best = 0;
        for i in 0..m {
            if u[(i, j)].abs() > u[(best, j)].abs() {
                best = i;
            }
        }
        if u[(best, j)] < 0.0 {
            for i in 0..m {
                u[(i, j)] = -u[(i, j)];
            }
            for i in 0..n {
                v[(i, j)] = -v[(i, j)];
            }
        }
    }
    Ok((u, sv, v))
}

/// Largest per-vertex norm of each frame's residual (columns of `r`, x y z per vertex).
fn frame_errors(r: &Mat<f64>) -> Vec<f64> {
    r.par_col_iter()
        .map(|c| {
            let mut worst = 0.0f64;
            for i in 0..c.nrows() / 3 {
                let v = Vector3::new(c[3 * i], c[3 * i + 1], c[3 * i + 2]);
                worst = worst.max(v.norm());
            }
            worst
        })
        .collect()
}

/// Least-squares fields for known coefficients, accumulated frame by frame: the K fields g_m
/// (one vector per vertex) minimising Σ_k Σ_v ‖y_k(v) − Σ_m g_m(v) c_km‖² over the frames
/// added, by the normal equations (CᵀC) Gᵀ = Cᵀ Y.
pub struct FieldFit {
    /// Σ_k c_k c_kᵀ (K × K).
    ctc: nalgebra::DMatrix<f64>,
    /// Σ_k y_k(v) c_km, per vertex and mode.
    yc: Vec<Vec<Vector3<f64>>>,
}

impl FieldFit {
    /// An empty fit of `modes` fields over `n` vertices.
    pub fn new(modes: usize, n: usize) -> Self {
        Self {
            ctc: nalgebra::DMatrix::zeros(modes, modes),
            yc: vec![vec![Vector3::zeros(); modes]; n],
        }
    }

    /// Add frame `y` (one vector per vertex) with coefficients `c` (one per mode).
    pub fn add(&mut self, y: &[Vector3<f64>], c: &[f64]) -> anyhow::Result<()> {
        let k = self.ctc.nrows();
        if c.len() != k || y.len() != self.yc.len() {
            bail!(
                "a frame of {} vectors and {} coefficients for a fit of {} vertices and {k} modes",
                y.len(),
                c.len(),
                self.yc.len()
            );
        }
        for i in 0..k {
            for j in 0..k {
                self.ctc[(i, j)] += c[i] * c[j];
            }
        }
        self.yc.par_iter_mut().zip(y).for_each(|(acc, yv)| {
            for (a, cm) in acc.iter_mut().zip(c) {
                *a += yv * *cm;
            }
        });
        Ok(())
    }

    /// The fields, CᵀC regularised by 1e-12 of its trace (a mode without weight gets none).
    pub fn solve(self) -> anyhow::Result<Vec<Vec<Vector3<f64>>>> {
        let k = self.ctc.nrows();
        let mut ctc = self.ctc;
        let reg = 1e-12 * ctc.trace().max(f64::MIN_POSITIVE);
        for i in 0..k {
            ctc[(i, i)] += reg;
        }
        let Some(chol) = ctc.cholesky() else {
            bail!("the coefficients' normal matrix is not positive definite");
        };
        let inv = chol.inverse();
        let fields: Vec<Vec<Vector3<f64>>> = self
            .yc
            .par_iter()
            .map(|yc| {
                (0..k)
                    .map(|m| (0..k).map(|j| yc[j] * inv[(j, m)]).sum())
                    .collect()
            })
            .collect();
        Ok((0..k)
            .map(|m| fields.iter().map(|g| g[m]).collect())
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Frames made of two fixed fields with known weights, plus a third small one: the basis
    /// needs two modes for a tolerance above the third field's size and three below it, and
    /// the signs are fixed.
    #[test]
    fn modes_grow_until_the_largest_vertex_error_is_met() {
        let n = 50;
        let field = |a: f64, b: f64| -> Vec<Vector3<f64>> {
            (0..n)
                .map(|i| {
                    let x = i as f64 / n as f64;
                    Vector3::new((a * x).sin(), (b * x).cos(), a * x * x)
                })
                .collect()
        };
        let (g1, g2, g3) = (field(3.0, 1.0), field(7.0, 2.0), field(11.0, 5.0));
        let frames: Vec<Vec<Vector3<f64>>> = (0..20)
            .map(|k| {
                let t = k as f64 / 19.0;
                (0..n)
                    .map(|i| g1[i] * t + g2[i] * (1.0 - t) * t + g3[i] * 1e-3 * (5.0 * t).sin())
                    .collect()
            })
            .collect();
        let a = || clip_matrix(frames.len(), n, |k| Ok(frames[k].clone())).unwrap();
        let b2 = truncated_basis(a(), 0.05, 10).unwrap();
        assert_eq!(b2.modes.len(), 2, "errors {:?}", b2.frame_error);
        assert_eq!(b2.bound, ModeBound::Error);
        assert!(b2.error <= 0.05);
        let b3 = truncated_basis(a(), 0.0, 10).unwrap();
        assert_eq!(b3.modes.len(), 3);
        assert_eq!(b3.bound, ModeBound::Rank);
        let capped = truncated_basis(a(), 0.0, 1).unwrap();
        assert_eq!((capped.modes.len(), capped.bound), (1, ModeBound::Cap));
        // Reconstruction from modes and coefficients matches the reported error.
        for (k, fr) in frames.iter().enumerate() {
            let worst = (0..n)
                .map(|i| {
                    let r: Vector3<f64> =
                        (0..2).map(|m| b2.modes[m][i] * b2.coefficients[k][m]).sum();
                    (fr[i] - r).norm()
                })
                .fold(0.0, f64::max);
            assert!((worst - b2.frame_error[k]).abs() < 1e-12);
        }
        for m in &b3.modes {
            let big = m
                .iter()
                .flat_map(|v| v.iter().copied())
                .fold(0.0f64, |a, x| if x.abs() > a.abs() { x } else { a });
            assert!(big > 0.0, "largest entry of each mode is positive");
        }
        // The same frames give the same bits.
        let again = truncated_basis(a(), 0.05, 10).unwrap();
        assert_eq!(again.modes, b2.modes);
        assert_eq!(again.coefficients, b2.coefficients);
    }

    #[test]
    fn fitted_fields_recover_a_linear_model() {
        let n = 7;
        let g: Vec<Vec<Vector3<f64>>> = (0..2)
            .map(|m| {
                (0..n)
                    .map(|i| Vector3::new(i as f64, m as f64, (i * m) as f64 * 0.5))
                    .collect()
            })
            .collect();
        let coeffs: Vec<Vec<f64>> = (0..9)
            .map(|k| vec![(k as f64).sin(), 0.3 * k as f64 - 1.0])
            .collect();
        let y: Vec<Vec<Vector3<f64>>> = coeffs
            .iter()
            .map(|c| (0..n).map(|i| g[0][i] * c[0] + g[1][i] * c[1]).collect())
            .collect();
        let mut fit = FieldFit::new(2, n);
        for (yk, c) in y.iter().zip(&coeffs) {
            fit.add(yk, c).unwrap();
        }
        assert!(fit.add(&y[0], &coeffs[0][..1]).is_err());
        let fit = fit.solve().unwrap();
        for m in 0..2 {
            for i in 0..n {
                assert!((fit[m][i] - g[m][i]).norm() < 1e-8, "{m} {i}");
            }
        }
        assert!(truncated_basis(Mat::zeros(0, 0), 0.1, 3).is_err());
    }
}
