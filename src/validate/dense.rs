//! A dense reference simulation of wrinkling: a plane-strain strip of stiff skin bonded on a
//! deep soft substrate, compressed along its length beyond the critical strain.
//!
//! Model and choices:
//! - Geometry: strip of length L = `periods` × λ_pred (λ_pred from
//!   [`crate::coupling::wavelength::Bilayer::critical_wavelength`]), skin of thickness h on a
//!   substrate of depth `depth` × λ_pred. Units are SI; energies are per metre of depth
//!   (plane strain), so "forces" are N/m.
//! - Elements: 9-node quadratic Lagrange quadrilaterals (Q2), 3×3 Gauss quadrature. A Q2 element
//!   reproduces pure bending exactly (quadratic displacement field), so thin skin elements do not
//!   shear-lock the way bilinear ones do; the cantilever test below checks the bending
//!   stiffness against beam theory with elements of aspect ratio 10. The skin has
//!   `skin_layers` (≥ 2) element layers of its own material; substrate layers grow
//!   geometrically (factor 1.3) from the skin down to the bottom.
//! - Material: St. Venant–Kirchhoff in plane strain, W = λ_L/2 (tr E)² + μ E:E with the 2×2
//!   Green strain E = ½(FᵀF − I) (E_zz = 0) and the 3D Lamé constants of (E, ν). Geometrically
//!   nonlinear (rotations of the wrinkled skin are exact); strains stay at a few percent here.
//! - Boundary conditions: sliding sides (u_x = 0 on the left side, u_x = −εL on the right side,
//!   u_y free) and a sliding bottom (u_y = 0, u_x free) so the pre-buckling state is a uniform
//!   plane-strain compression, as in the classical analysis. With sliding sides the strip
//!   admits wavelengths 2L/m (m an integer), so the measurement resolution is about λ/(4 ×
//!   periods); `periods` defaults to a non-integer (10.3) so that the selected mode is never
//!   exactly λ_pred by construction.
//! - Imperfection: the reference geometry is shifted vertically by η(X) = a Σ_m s_m
//!   cos(mπX/L), every mode the sliding sides admit down to λ/4 with the same amplitude and a
//!   pseudo-random sign s_m (RMS ≈ `imperfection` × h / √2 at the top, tapering linearly to
//!   zero at the bottom). It does not depend on the mesh, so every resolution sees the same
//!   imperfection; it breaks the symmetry of the flat state, so the strip wrinkles in a mode
//!   that goes unstable first instead of staying on the flat branch. Near ε_c the critical
//!   strain of neighbouring modes differs by a fraction of a percent, so which mode wins also
//!   depends on the imperfection: at E_x/E_q = 100 and 10.3 periods, seeds 1–5 give
//!   λ/λ_pred = 1.048, 0.976, 1.010, 0.964, 0.959 (mean 0.991), the same at every resolution
//!   from 6 elements per λ up (see the resolution study). That ±5% scatter is the precision of
//!   this experiment, not a discretisation error; average seeds for a sharper number.
//! - Loading: compressive strain ε in `load_steps` steps from 0.5 ε_c to `strain_factor` × ε_c,
//!   with ε_c = ¼ (3 Ē_q / Ē_x)^{2/3} (Ē = E / (1 − ν²)); each step is solved to equilibrium
//!   by [`crate::solver::statics::StaticSolver`] (Newton, KKT, line search) from the previous one.
//! - Measurement: λ from the top surface height with [`super::measure::wavelength`], both
//!   against the reference (material) position along the strip — the quantity the small-strain
//!   formula predicts — and against the current position (shorter by about the factor 1 − ε).

use super::measure::{self, Measured};
use crate::coupling::wavelength::Bilayer;
use crate::math::rng::Lcg;
use crate::math::Energy;
use crate::solver::statics::{HessianMode, StaticProblem, StaticSettings, StaticSolver};
use crate::solver::status::SolveStatus;
use anyhow::{bail, Context};
use std::time::Instant;

/// Gauss points and weights of the 3-point rule on [−1, 1].
const GAUSS3: [(f64, f64); 3] = [
    (-0.774_596_669_241_483_4, 5.0 / 9.0),
    (0.0, 8.0 / 9.0),
    (0.774_596_669_241_483_4, 5.0 / 9.0),
];

/// Quadratic Lagrange shape functions on [−1, 1] at nodes −1, 0, 1 and their derivatives.
fn lagrange2(t: f64) -> ([f64; 3], [f64; 3]) {
    (
        [0.5 * t * (t - 1.0), 1.0 - t * t, 0.5 * t * (t + 1.0)],
        [t - 0.5, -2.0 * t, t + 0.5],
    )
}

/// Lamé constants (λ_L, μ) in Pa of Young's modulus `e` (Pa) and Poisson ratio `nu`.
pub fn lame(e: f64, nu: f64) -> (f64, f64) {
    (
        e * nu / ((1.0 + nu) * (1.0 - 2.0 * nu)),
        e / (2.0 * (1.0 + nu)),
    )
}

/// A structured mesh of 9-node quadratic quadrilaterals on a rectangle.
///
/// Nodes form a grid of `columns` × `rows` (row-major from the bottom-left, node index =
/// row × columns + column); element `e` lists its nodes as `[i + 3 j]` with i along x and j
/// along y, i, j ∈ {0, 1, 2}.
#[derive(Debug, Clone)]
pub struct QuadMesh {
    /// Reference node positions (x along the strip, y up), m.
    pub nodes: Vec<[f64; 2]>,
    /// Nodes of each element (9 per element).
    pub elements: Vec<[usize; 9]>,
    /// Element layer index from the bottom (0-based) of each element.
    pub element_row: Vec<usize>,
    /// Number of node columns (2 × elements along x + 1).
    pub columns: usize,
    /// Number of node rows (2 × element layers + 1).
    pub rows: usize,
}

impl QuadMesh {
    /// A grid of `nx` elements of equal width over [0, `length`] (m) and element layers with
    /// boundaries `ys` (m, increasing, `ys.len()` − 1 layers). Mid-side nodes sit halfway.
    pub fn rectangle(length: f64, nx: usize, ys: &[f64]) -> Self {
        let ny = ys.len() - 1;
        let columns = 2 * nx + 1;
        let rows = 2 * ny + 1;
        let mut nodes = Vec::with_capacity(columns * rows);
        for r in 0..rows {
            let y = if r % 2 == 0 {
                ys[r / 2]
            } else {
                0.5 * (ys[r / 2] + ys[r / 2 + 1])
            };
            for c in 0..columns {
                nodes.push([length * c as f64 / (columns - 1) as f64, y]);
            }
        }
        let mut elements = Vec::with_capacity(nx * ny);
        let mut element_row = Vec::with_capacity(nx * ny);
        for ey in 0..ny {
            for ex in 0..nx {
                let mut e = [0usize; 9];
                for j in 0..3 {
                    for i in 0..3 {
                        e[i + 3 * j] = (2 * ey + j) * columns + 2 * ex + i;
                    }
                }
                elements.push(e);
                element_row.push(ey);
            }
        }
        Self {
            nodes,
            elements,
            element_row,
            columns,
            rows,
        }
    }

    /// Node index of grid column `c` and row `r`.
    pub fn node(&self, c: usize, r: usize) -> usize {
        r * self.columns + c
    }
}

/// St. Venant–Kirchhoff plane-strain elastic energy (J per metre of depth) of a Q2 mesh;
/// dofs are the current positions (x, y) of every node, m (2 per node).
pub struct PlaneStrainSvk {
    n_nodes: usize,
    elements: Vec<[usize; 9]>,
    /// (λ_L, μ) per element, Pa.
    lame: Vec<(f64, f64)>,
    /// Per element, per Gauss point: reference shape-function gradients (1/m) and
    /// weight × det J (m²).
    quad: Vec<[([[f64; 2]; 9], f64); 9]>,
}

impl PlaneStrainSvk {
    /// The energy of `mesh` with element materials `(E (Pa), ν)` per element. Fails when an
    /// element is inverted or degenerate in the reference configuration.
    pub fn new(mesh: &QuadMesh, materials: &[(f64, f64)]) -> anyhow::Result<Self> {
        if materials.len() != mesh.elements.len() {
            bail!(
                "{} materials given for {} elements",
                materials.len(),
                mesh.elements.len()
            );
        }
        let mut quad = Vec::with_capacity(mesh.elements.len());
        for (k, el) in mesh.elements.iter().enumerate() {
            let mut q = [([[0.0; 2]; 9], 0.0); 9];
            for (gj, &(eta, wj)) in GAUSS3.iter().enumerate() {
                for (gi, &(xi, wi)) in GAUSS3.iter().enumerate() {
                    let (nx, dx) = lagrange2(xi);
                    let (ny, dy) = lagrange2(eta);
                    // dN/dξ, dN/dη
                    let mut dn = [[0.0; 2]; 9];
                    for j in 0..3 {
                        for i in 0..3 {
                            dn[i + 3 * j] = [dx[i] * ny[j], nx[i] * dy[j]];
                        }
                    }
                    let mut jac = [[0.0; 2]; 2]; // J[a][b] = dX_a / dξ_b
                    for (a, &n) in el.iter().enumerate() {
                        let p = mesh.nodes[n];
                        for r in 0..2 {
                            for c in 0..2 {
                                jac[r][c] += p[r] * dn[a][c];
                            }
                        }
                    }
                    let det = jac[0][0] * jac[1][1] - jac[0][1] * jac[1][0];
                    if !(det.is_finite() && det > 0.0) {
                        bail!("element {k} is inverted or degenerate (det J = {det:e})");
                    }
                    let inv = [
                        [jac[1][1] / det, -jac[0][1] / det],
                        [-jac[1][0] / det, jac[0][0] / det],
                    ];
                    let mut g = [[0.0; 2]; 9];
                    for a in 0..9 {
                        // dN/dX_c = Σ_b dN/dξ_b dξ_b/dX_c
                        for c in 0..2 {
                            g[a][c] = dn[a][0] * inv[0][c] + dn[a][1] * inv[1][c];
                        }
                    }
                    q[gi + 3 * gj] = (g, wi * wj * det);
                }
            }
            quad.push(q);
        }
        Ok(Self {
            n_nodes: mesh.nodes.len(),
            elements: mesh.elements.clone(),
            lame: materials.iter().map(|&(e, nu)| lame(e, nu)).collect(),
            quad,
        })
    }

    /// Energy of one element (J/m); adds its gradient (18) and Hessian (18 × 18 row-major).
    fn element(
        &self,
        k: usize,
        x: &[f64],
        mut grad: Option<&mut [f64; 18]>,
        mut hess: Option<&mut [f64; 324]>,
    ) -> f64 {
        let el = &self.elements[k];
        let (lam, mu) = self.lame[k];
        let mut e_total = 0.0;
        for (g, wj) in self.quad[k].iter() {
            let mut f = [[0.0; 2]; 2];
            for a in 0..9 {
                let p = [x[2 * el[a]], x[2 * el[a] + 1]];
                for r in 0..2 {
                    for c in 0..2 {
                        f[r][c] += p[r] * g[a][c];
                    }
                }
            }
            // Green strain and second Piola–Kirchhoff stress.
            let mut e = [[0.0; 2]; 2];
            for r in 0..2 {
                for c in 0..2 {
                    e[r][c] = 0.5 * (f[0][r] * f[0][c] + f[1][r] * f[1][c]);
                }
                e[r][r] -= 0.5;
            }
            let tr = e[0][0] + e[1][1];
            let ee = e[0][0] * e[0][0] + 2.0 * e[0][1] * e[0][1] + e[1][1] * e[1][1];
            e_total += wj * (0.5 * lam * tr * tr + mu * ee);
            if grad.is_none() && hess.is_none() {
                continue;
            }
            let mut s = [
                [2.0 * mu * e[0][0], 2.0 * mu * e[0][1]],
                [2.0 * mu * e[1][0], 2.0 * mu * e[1][1]],
            ];
            s[0][0] += lam * tr;
            s[1][1] += lam * tr;
            if let Some(gr) = grad.as_deref_mut() {
                // P = F S; ∂W/∂x_a = P g_a
                let mut p = [[0.0; 2]; 2];
                for r in 0..2 {
                    for c in 0..2 {
                        p[r][c] = f[r][0] * s[0][c] + f[r][1] * s[1][c];
                    }
                }
                for a in 0..9 {
                    for r in 0..2 {
                        gr[2 * a + r] += wj * (p[r][0] * g[a][0] + p[r][1] * g[a][1]);
                    }
                }
            }
            if let Some(h) = hess.as_deref_mut() {
                // K[(a,i),(b,k)] = w [ δ_ik g_a·S g_b + λ (F g_a)_i (F g_b)_k
                //                     + μ ((F Fᵀ)_ik g_a·g_b + (F g_b)_i (F g_a)_k) ]
                let mut fg = [[0.0; 2]; 9];
                let mut sg = [[0.0; 2]; 9];
                for a in 0..9 {
                    for r in 0..2 {
                        fg[a][r] = f[r][0] * g[a][0] + f[r][1] * g[a][1];
                        sg[a][r] = s[r][0] * g[a][0] + s[r][1] * g[a][1];
                    }
                }
                let mut fft = [[0.0; 2]; 2];
                for r in 0..2 {
                    for c in 0..2 {
                        fft[r][c] = f[r][0] * f[c][0] + f[r][1] * f[c][1];
                    }
                }
                for a in 0..9 {
                    for b in 0..9 {
                        let gsg = g[a][0] * sg[b][0] + g[a][1] * sg[b][1];
                        let gg = g[a][0] * g[b][0] + g[a][1] * g[b][1];
                        for i in 0..2 {
                            for kk in 0..2 {
                                let mut v = lam * fg[a][i] * fg[b][kk]
                                    + mu * (fft[i][kk] * gg + fg[b][i] * fg[a][kk]);
                                if i == kk {
                                    v += gsg;
                                }
                                h[(2 * a + i) * 18 + 2 * b + kk] += wj * v;
                            }
                        }
                    }
                }
            }
        }
        e_total
    }
}

impl Energy for PlaneStrainSvk {
    fn dofs(&self) -> usize {
        2 * self.n_nodes
    }

    fn eval(
        &self,
        x: &[f64],
        mut grad: Option<&mut [f64]>,
        mut hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64 {
        let mut total = 0.0;
        let want_g = grad.is_some();
        let want_h = hess.is_some();
        if let Some(h) = hess.as_deref_mut() {
            h.reserve(324 * self.elements.len());
        }
        for k in 0..self.elements.len() {
            let mut ge = [0.0; 18];
            let mut he = [0.0; 324];
            total += self.element(k, x, want_g.then_some(&mut ge), want_h.then_some(&mut he));
            let el = &self.elements[k];
            let dof = |l: usize| 2 * el[l / 2] + l % 2;
            if let Some(g) = grad.as_deref_mut() {
                for (l, v) in ge.iter().enumerate() {
                    g[dof(l)] += v;
                }
            }
            if let Some(h) = hess.as_deref_mut() {
                if project_psd {
                    crate::shell::psd::project_psd(&mut he, 18);
                }
                for r in 0..18 {
                    for c in 0..18 {
                        h.push((dof(r), dof(c), he[r * 18 + c]));
                    }
                }
            }
        }
        total
    }
}

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

/// √2 × RMS about the mean of the vertical displacement of the top row over the central 80%
/// of the strip (m).
fn top_amplitude(mesh: &QuadMesh, x: &[f64], length: f64) -> f64 {
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
fn onset_fit(steps: &[StepRecord], min_amp: f64) -> Option<(f64, f64)> {
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

/// The strip mesh, materials and top row of a case: returns (mesh, materials, skin bottom y).
fn build(case: &DenseCase, lambda: f64) -> (QuadMesh, Vec<(f64, f64)>, f64) {
    let b = &case.bilayer;
    let h = b.thickness;
    let length = case.periods * lambda;
    let nx = (case.periods * case.elements_per_wavelength as f64).ceil() as usize;
    let dx = length / nx as f64;
    let depth = case.depth * lambda;
    // Substrate layers from the top down: first 0.5 dx, growing by 1.3.
    let mut sub = Vec::new();
    let mut t = 0.5 * dx;
    let mut acc = 0.0;
    while acc + t < depth {
        sub.push(t);
        acc += t;
        t *= 1.3;
    }
    // Stretch the layers so they end exactly at the bottom.
    let scale = depth / acc.max(f64::MIN_POSITIVE);
    let mut ys = vec![0.0];
    for &t in sub.iter().rev() {
        let last = *ys.last().unwrap();
        ys.push(last + t * scale);
    }
    *ys.last_mut().unwrap() = depth;
    let substrate_layers = ys.len() - 1;
    for i in 1..=case.skin_layers {
        ys.push(depth + h * i as f64 / case.skin_layers as f64);
    }
    let mesh = QuadMesh::rectangle(length, nx, &ys);
    let mats = mesh
        .element_row
        .iter()
        .map(|&r| {
            if r >= substrate_layers {
                (b.skin_modulus, b.skin_poisson)
            } else {
                (b.interior_modulus, b.interior_poisson)
            }
        })
        .collect();
    (mesh, mats, depth)
}

/// Run one dense wrinkling simulation (see the module documentation) and measure λ.
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

/// The dense strip of a case, ready to compress: its imperfect mesh, energy and sliding
/// boundary conditions.
struct Strip {
    /// The mesh, with the geometric imperfection applied to its reference positions (m).
    mesh: QuadMesh,
    /// The plane-strain SVK energy of the mesh.
    energy: PlaneStrainSvk,
    /// Sliding sides and bottom (pinned dofs).
    problem: StaticProblem,
    /// Strip length L (m).
    length: f64,
}

impl Strip {
    /// The strip of `case` for predicted wavelength `lambda` (m).
    fn new(case: &DenseCase, lambda: f64) -> anyhow::Result<Self> {
        let (mut mesh, mats, depth) = build(case, lambda);
        let length = case.periods * lambda;
        add_imperfection(&mut mesh, case, length, depth + case.bilayer.thickness);
        let energy = PlaneStrainSvk::new(&mesh, &mats).context("building the dense strip")?;
        let problem = StaticProblem {
            pinned: sliding_pins(&mesh),
            ..Default::default()
        };
        Ok(Self {
            mesh,
            energy,
            problem,
            length,
        })
    }
}

/// Shift the mesh's reference positions by the geometric imperfection. Independent of the
/// mesh: every sliding-compatible mode cos(mπX/L) (strip length `length`, m) with wavelength
/// down to λ/4 gets the same amplitude and a random sign, so the mode that grows is chosen by
/// the mechanics, not by the imperfection; it tapers linearly to zero from the top `top_y`
/// (m) to the bottom.
fn add_imperfection(mesh: &mut QuadMesh, case: &DenseCase, length: f64, top_y: f64) {
    let modes = (8.0 * case.periods).ceil() as usize;
    let mut rng = Lcg::from_state(
        case.seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(17),
    );
    let signs: Vec<f64> = (0..modes).map(|_| rng.next_signed().signum()).collect();
    let amp = case.imperfection * case.bilayer.thickness / (modes as f64).sqrt();
    let eta = |x: f64| -> f64 {
        signs
            .iter()
            .enumerate()
            .map(|(m, s)| s * ((m + 1) as f64 * std::f64::consts::PI * x / length).cos())
            .sum::<f64>()
            * amp
    };
    for p in mesh.nodes.iter_mut() {
        p[1] += eta(p[0]) * (p[1] / top_y);
    }
}

/// The pinned dofs of sliding sides (x pinned) and a sliding bottom (y pinned), sorted.
fn sliding_pins(mesh: &QuadMesh) -> Vec<usize> {
    let mut pinned = Vec::new();
    for r in 0..mesh.rows {
        pinned.push(2 * mesh.node(0, r));
        pinned.push(2 * mesh.node(mesh.columns - 1, r));
    }
    for c in 0..mesh.columns {
        pinned.push(2 * mesh.node(c, 0) + 1);
    }
    pinned.sort_unstable();
    pinned.dedup();
    pinned
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

/// A height profile along the strip: (position along the strip, height), both in m.
type Profile = Vec<(f64, f64)>;

/// The top row's height profile from flat positions `x` (m): (reference x, current y) and
/// (current x, current y), ordered along the strip.
fn top_profiles(mesh: &QuadMesh, x: &[f64]) -> (Profile, Profile) {
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::fd::{check_gradient, check_hessian};

    fn small_mesh() -> QuadMesh {
        QuadMesh::rectangle(2e-3, 2, &[0.0, 0.4e-3, 1e-3])
    }

    fn perturbed(mesh: &QuadMesh, amp: f64, seed: u64) -> Vec<f64> {
        let mut rng = Lcg::from_state(seed);
        mesh.nodes
            .iter()
            .flat_map(|p| [p[0], p[1]])
            .map(|v| v + amp * rng.next_signed())
            .collect()
    }

    /// Gradient and Hessian of the SVK energy against central differences, at a strongly
    /// deformed state (random displacements of 10% of the element size, plus a rotation).
    #[test]
    fn svk_energy_matches_finite_differences() {
        let mesh = small_mesh();
        let mats: Vec<(f64, f64)> = (0..mesh.elements.len())
            .map(|k| if k < 2 { (1e4, 0.45) } else { (1e6, 0.3) })
            .collect();
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let mut x = perturbed(&mesh, 1e-4, 5);
        let (c, s) = (0.3f64.cos(), 0.3f64.sin());
        for p in x.chunks_mut(2) {
            let (a, b) = (p[0], p[1]);
            p[0] = c * a - s * b;
            p[1] = s * a + c * b;
        }
        let g = check_gradient(&e, &x, 1e-3);
        assert!(g.rel_error < 1e-7, "gradient {g:?}");
        let h = check_hessian(&e, &x, 1e-3);
        assert!(h.rel_error < 1e-7, "hessian {h:?}");
    }

    /// Rigid motions cost nothing; a uniform stretch costs the plane-strain SVK energy.
    #[test]
    fn rigid_motion_is_free_and_stretch_matches_formula() {
        let mesh = small_mesh();
        let (young, nu) = (2e5, 0.3);
        let mats = vec![(young, nu); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let (c, s) = (1.1f64.cos(), 1.1f64.sin());
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [c * p[0] - s * p[1] + 0.3, s * p[0] + c * p[1] - 0.2])
            .collect();
        let mut g = vec![0.0; x.len()];
        let w = e.eval(&x, Some(&mut g), None, false);
        assert!(w.abs() < 1e-12, "{w}");
        assert!(g.iter().all(|v| v.abs() < 1e-9), "{g:?}");
        // Uniaxial stretch 1 + a along x with y held: E_xx = a + a²/2, energy density
        // (λ_L/2 + μ) E_xx² over area 2e-3 × 1e-3.
        let a = 0.02;
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [(1.0 + a) * p[0], p[1]])
            .collect();
        let (lam, mu) = lame(young, nu);
        let exx = a + 0.5 * a * a;
        let expected = (0.5 * lam + mu) * exx * exx * 2e-6;
        let w = e.eval(&x, None, None, false);
        assert!(
            (w - expected).abs() < 1e-12 * expected.max(1.0),
            "{w} {expected}"
        );
    }

    /// Projected element Hessians are positive semi-definite: xᵀ K x ≥ 0 for random x.
    #[test]
    fn projected_hessian_is_psd() {
        let mesh = small_mesh();
        let mats = vec![(1e5, 0.3); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        // A strongly compressed state has an indefinite exact Hessian.
        let x: Vec<f64> = mesh
            .nodes
            .iter()
            .flat_map(|p| [0.6 * p[0], 0.7 * p[1]])
            .collect();
        let n = x.len();
        let mut t = Vec::new();
        e.eval(&x, None, Some(&mut t), true);
        let k = crate::math::sparse::dense_from_triplets(n, &t);
        let mut exact = Vec::new();
        e.eval(&x, None, Some(&mut exact), false);
        let ke = crate::math::sparse::dense_from_triplets(n, &exact);
        let mut rng = Lcg::from_state(9);
        let mut min_proj = f64::INFINITY;
        let mut min_exact = f64::INFINITY;
        for _ in 0..200 {
            let v: Vec<f64> = (0..n).map(|_| rng.next_signed()).collect();
            let q = |m: &[f64]| -> f64 {
                (0..n)
                    .map(|i| v[i] * (0..n).map(|j| m[i * n + j] * v[j]).sum::<f64>())
                    .sum()
            };
            min_proj = min_proj.min(q(&k));
            min_exact = min_exact.min(q(&ke));
        }
        assert!(min_proj >= -1e-9 * k.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        assert!(min_exact < 0.0, "the test state should be indefinite");
    }

    /// The structured mesh: node and element counts, corner positions, element orientation.
    #[test]
    fn rectangle_mesh_layout() {
        let m = QuadMesh::rectangle(3.0, 3, &[0.0, 1.0, 1.5]);
        assert_eq!((m.columns, m.rows), (7, 5));
        assert_eq!(m.nodes.len(), 35);
        assert_eq!(m.elements.len(), 6);
        assert_eq!(m.nodes[m.node(6, 4)], [3.0, 1.5]);
        assert_eq!(m.nodes[m.node(3, 3)], [1.5, 1.25]);
        // Element 4 (second layer, middle column): node 0 bottom-left, node 8 top-right.
        let e = m.elements[4];
        assert_eq!(m.nodes[e[0]], [1.0, 1.0]);
        assert_eq!(m.nodes[e[8]], [2.0, 1.5]);
        assert_eq!(m.element_row[4], 1);
        // Total area from the quadrature weights equals the rectangle's (4.5 m²).
        let svk = PlaneStrainSvk::new(&m, &[(1.0, 0.3); 6]).unwrap();
        let area: f64 = svk.quad.iter().flatten().map(|q| q.1).sum();
        assert!((area - 4.5).abs() < 1e-12, "{area}");
    }

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

    /// Bending without shear locking: a clamped cantilever of thickness t and length 20 t,
    /// 2 Q2 layers through the thickness, under a small tip load P (per metre of depth).
    /// Timoshenko beam theory in plane strain: δ = P ℓ³ / (3 Ē I) + P ℓ / (κ G t),
    /// Ē = E/(1 − ν²), I = t³/12, κ = 5/6. Measured: elements of aspect ratio 10 are 2.5%
    /// too stiff, aspect 2 0.4% (the remaining ~0.3% at aspect 1 is the continuum clamp,
    /// which also stops the Poisson contraction at the root). Tolerances 3% and 1%.
    #[test]
    fn cantilever_tip_deflection_matches_beam_theory() {
        for (nx, tol) in [(4usize, 0.03), (20, 0.01)] {
            cantilever(nx, tol);
        }
    }

    fn cantilever(nx: usize, tol: f64) {
        let (t, ell) = (1e-3, 20e-3);
        let (young, nu) = (1e6, 0.3);
        let mesh = QuadMesh::rectangle(ell, nx, &[0.0, 0.5 * t, t]);
        let mats = vec![(young, nu); mesh.elements.len()];
        let e = PlaneStrainSvk::new(&mesh, &mats).unwrap();
        let mut pinned = Vec::new();
        for r in 0..mesh.rows {
            let n = mesh.node(0, r);
            pinned.extend([2 * n, 2 * n + 1]);
        }
        // Tip load P distributed consistently over the 3 end nodes (1/6, 4/6, 1/6).
        let p_total = -1e-4; // N/m, tiny: linear regime
        let mut forces = vec![0.0; e.dofs()];
        for (r, w) in [(0, 1.0 / 6.0), (1, 4.0 / 6.0), (2, 1.0 / 6.0)] {
            forces[2 * mesh.node(mesh.columns - 1, r) + 1] = w * p_total;
        }
        let problem = StaticProblem {
            pinned,
            forces,
            ..Default::default()
        };
        let mut solver = StaticSolver::new(StaticSettings {
            tolerance: 1e-6 * p_total.abs(),
            ..Default::default()
        })
        .unwrap();
        let mut x: Vec<f64> = mesh.nodes.iter().flat_map(|p| [p[0], p[1]]).collect();
        let rep = solver.solve(&e, &problem, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        let tip = mesh.node(mesh.columns - 1, 1);
        let delta = x[2 * tip + 1] - mesh.nodes[tip][1];
        let ebar = young / (1.0 - nu * nu);
        let g = young / (2.0 * (1.0 + nu));
        let i = t.powi(3) / 12.0;
        let expected =
            p_total * ell.powi(3) / (3.0 * ebar * i) + p_total * ell / (5.0 / 6.0 * g * t);
        let rel = (delta - expected).abs() / expected.abs();
        assert!(
            rel < tol,
            "nx {nx}: tip {delta:e} beam theory {expected:e} rel {rel:.4}"
        );
    }
}
