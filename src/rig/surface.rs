//! The neutral face surface: a parametric mask over the front of an ellipsoid-like head.
//!
//! Coordinates are metres, +Y up, the face looks along +Z, the origin is near the head centre.
//! The "left" of the face is the subject's left, which is +X.
//!
//! The surface is `P(θ, y) = B(θ, y) + h(x_b, y) N_B(θ, y)`: a base head `B` (a horizontal
//! ellipse of half-width `A(y)` and half-depth `C(y)` at each height `y`, azimuth `θ` measured
//! from +Z toward +X) displaced along its unit normal `N_B` by a smooth relief `h` (brow ridge,
//! eye sockets with closed lids, nose with tip and nostril wings, cheekbones, cheeks, lips, chin)
//! written in terms of the base lateral coordinate `x_b = A(y) sin θ` and the height `y`.
//!
//! It is sampled on a triangular lattice: rows at equal arc length along the central profile,
//! alternately `2K+1` and `2K+2` vertices at equal azimuth steps, so every row is mirror symmetric
//! and the triangles are close to equilateral. The mouth is a slit cut along one row between the
//! two mouth corners: the vertices strictly between the corners are duplicated, the upper lip uses
//! one copy and the lower lip the other, so the lips touch at neutral but share no vertex.
//! The corners themselves stay shared, so the face is one connected surface around the mouth.
//! The eyes are closed: shallow sockets covered by a lid bulge (no eye holes).

use nalgebra::Vector3;

use crate::mesh::TriMesh;

/// Half-width of the base head at cheekbone height, m.
pub const HALF_WIDTH: f64 = 0.075;
/// Half-depth of the base head (centre to the front of the face), m.
pub const HALF_DEPTH: f64 = 0.09;
/// Height of the upper rim (top of the forehead), m.
pub const Y_TOP: f64 = 0.10;
/// Height of the lower rim (under the chin), m.
pub const Y_BOTTOM: f64 = -0.10;
/// Azimuth of the side rims from the front (rad): 80°, just in front of the ears.
pub const THETA_MAX: f64 = 80.0 * std::f64::consts::PI / 180.0;
/// Requested height of the mouth slit, m (the actual one is the nearest lattice row).
pub const MOUTH_Y_TARGET: f64 = -0.05;
/// Requested half-width of the mouth slit (base lateral coordinate of the corners), m.
pub const MOUTH_HALF_WIDTH_TARGET: f64 = 0.024;
/// Lateral position of the eye centres (|x|), m.
pub const EYE_X: f64 = 0.033;
/// Height of the eye centres, m.
pub const EYE_Y: f64 = 0.017;

/// Which side of the mouth slit a vertex belongs to (only meaningful near the slit).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Side {
    /// At or above the mouth line (upper lip side).
    Upper,
    /// Below the mouth line (lower lip side), including the lower copies of the slit vertices.
    Lower,
}

/// Everything known about one vertex of the mask: its parameters and its local frame.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Azimuth from +Z toward +X, rad.
    pub theta: f64,
    /// Height, m (also the base surface's y).
    pub y: f64,
    /// Base lateral coordinate `A(y) sin θ`, m (the relief and the blend shapes use it).
    pub x: f64,
    /// Side of the mouth slit.
    pub side: Side,
    /// Neutral position, m.
    pub pos: Vector3<f64>,
    /// Unit tangent of the base head along increasing θ (≈ +X on the front of the face).
    pub e_u: Vector3<f64>,
    /// Unit tangent of the base head orthogonal to `e_u`, ≈ +Y ("up the face").
    pub e_v: Vector3<f64>,
    /// Unit outward normal of the base head (not of the relief: see [`base_frame`]).
    pub n: Vector3<f64>,
}

/// The sampled mask: mesh, per-vertex samples, mirror map and the mouth slit.
#[derive(Debug, Clone)]
pub struct Mask {
    /// Neutral triangle mesh (m), counter-clockwise seen from outside.
    pub mesh: TriMesh,
    /// One sample per vertex.
    pub samples: Vec<Sample>,
    /// `mirror[v]` is the vertex at the mirror image (x → −x) of `v`.
    pub mirror: Vec<usize>,
    /// Upper-lip copies of the slit vertices, ordered by increasing x.
    pub slit_upper: Vec<usize>,
    /// Lower-lip copies of the slit vertices, same order as `slit_upper`.
    pub slit_lower: Vec<usize>,
    /// The two shared mouth-corner vertices (−x first).
    pub corners: [usize; 2],
    /// Height of the mouth slit, m.
    pub mouth_y: f64,
    /// Base lateral coordinate |x| of the mouth corners, m.
    pub corner_x: f64,
    /// Vertices on the outer rim of the mask (the open back edge).
    pub rim: Vec<usize>,
}

/// Cubic smoothstep from 0 at `e0` to 1 at `e1` (works for `e0 > e1` too).
pub fn smoothstep(e0: f64, e1: f64, x: f64) -> f64 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// 1 inside `|x| < r0`, smoothly 0 beyond `r0 + w` (a smoothstep fall-off of width `w`, m).
pub fn window(ax: f64, r0: f64, w: f64) -> f64 {
    1.0 - smoothstep(r0, r0 + w, ax)
}

/// Compactly supported C² bump `(1 − r²)³` for `|r| < 1`, else 0.
pub fn bump(r: f64) -> f64 {
    let s = 1.0 - r * r;
    if s > 0.0 {
        s * s * s
    } else {
        0.0
    }
}

/// Unnormalised Gaussian `exp(−(a² + b²)/2)` of two scaled coordinates.
pub fn gauss2(a: f64, b: f64) -> f64 {
    (-0.5 * (a * a + b * b)).exp()
}

/// Half-width `A(y)` of the base head at height `y`, m: narrower toward the top of the forehead
/// and toward the jaw.
fn half_width(y: f64) -> f64 {
    if y >= 0.0 {
        let r = (y / 0.16).powf(2.5);
        HALF_WIDTH * (1.0 - r).powf(0.4)
    } else {
        HALF_WIDTH * (1.0 - 0.28 * smoothstep(-0.01, -0.1, y))
    }
}

/// Half-depth `C(y)` of the base head at height `y`, m: the forehead slopes back at the top and
/// the surface turns under the chin at the bottom.
fn half_depth(y: f64) -> f64 {
    if y >= 0.0 {
        let r = (y / 0.14).powf(2.2);
        HALF_DEPTH * (1.0 - r).powf(1.0 / 2.2)
    } else {
        let r = (-y / 0.128).powi(3);
        HALF_DEPTH * (1.0 - r).cbrt()
    }
}

/// Orthonormal frame `(e_u, e_v, n)` of the smooth base head at `(theta, y)`: `e_u` along
/// increasing θ, `n` outward, `e_v = n × e_u` (≈ +Y). It varies slowly (radii ≥ 7 cm), so
/// displacements written in it stay smooth over the nose, lips and brows.
pub fn base_frame(theta: f64, y: f64) -> (Vector3<f64>, Vector3<f64>, Vector3<f64>) {
    let h = 1e-6;
    let pt = (base_point(theta + h, y) - base_point(theta - h, y)) / (2.0 * h);
    let py = (base_point(theta, y + h) - base_point(theta, y - h)) / (2.0 * h);
    let n = pt.cross(&py).normalize();
    let e_u = pt.normalize();
    (e_u, n.cross(&e_u), n)
}

/// Point of the base head at azimuth `theta` and height `y`, m.
fn base_point(theta: f64, y: f64) -> Vector3<f64> {
    Vector3::new(half_width(y) * theta.sin(), y, half_depth(y) * theta.cos())
}

/// Unit outward normal of the base head.
fn base_normal(theta: f64, y: f64) -> Vector3<f64> {
    base_frame(theta, y).2
}

/// Relief of the face above the base head along its normal, m, at base lateral coordinate `x`
/// and height `y`. `mouth_y` is the height of the mouth slit.
pub fn relief(x: f64, y: f64, mouth_y: f64) -> f64 {
    let ax = x.abs();
    let mut h = 0.0;
    // Brow ridge: a band above the eyes, curving up laterally, a little lower at the midline.
    let brow_y = 0.037 + 0.004 * (ax / 0.035).powi(2);
    h += 0.0045
        * (-0.5 * ((y - brow_y) / 0.008).powi(2)).exp()
        * (1.0 - smoothstep(0.05, 0.07, ax))
        * (1.0 - 0.3 * (-0.5 * (ax / 0.008).powi(2)).exp());
    // Eye sockets with closed lids over the eyeballs.
    let ex = ax - EYE_X;
    let ey = y - EYE_Y;
    h -= 0.016 * gauss2(ex / 0.016, ey / 0.011);
    h += 0.0085 * gauss2(ex / 0.0115, ey / 0.0065);
    // Lid line: a faint crease where the closed lids meet, slightly below the eye centre.
    h -= 0.0008 * gauss2(ex / 0.009, (ey + 0.002) / 0.0025);
    // Nose: dorsum from the nasion (y ≈ 0.028) to the tip (y ≈ −0.016), steep drop below it.
    let (y_nasion, y_tip) = (0.03, -0.016);
    let along = smoothstep(y_nasion + 0.008, y_tip, y);
    let drop = if y < y_tip {
        (-((y - y_tip) / 0.0075).powi(2)).exp()
    } else {
        1.0
    };
    let height =
        0.0035 * smoothstep(y_nasion + 0.022, y_nasion - 0.004, y) + 0.0165 * along.powf(1.2);
    let half = 0.0065 + 0.004 * along;
    h += height * drop * (-0.5 * (ax / half).powi(2)).exp();
    // Nose tip bulb and nostril wings (alae).
    h += 0.003 * gauss2(ax / 0.007, (y - y_tip) / 0.006);
    h += 0.0065 * gauss2((ax - 0.0145) / 0.0055, (y + 0.021) / 0.0062);
    // Cheekbones and cheeks.
    h += 0.005 * gauss2((ax - 0.048) / 0.016, y / 0.014);
    h += 0.003 * gauss2((ax - 0.036) / 0.015, (y + 0.022) / 0.015);
    // Muzzle over the dental arch.
    h += 0.008 * gauss2(ax / 0.03, (y - mouth_y) / 0.028);
    // Lips: upper and lower vermilion, a shallow groove along the mouth line.
    // The vermilion is fullest at the centre and thins toward the corners; the upper lip has a
    // Cupid's bow (two peaks either side of the philtrum).
    let lip_w = 1.0 - smoothstep(0.006, 0.028, ax);
    let bow = 0.0012 * gauss2((ax - 0.006) / 0.004, 0.0);
    let upper_c = mouth_y + 0.002 + 0.0035 * lip_w + bow;
    let lower_c = mouth_y - 0.002 - 0.0045 * lip_w;
    h += 0.004 * lip_w * (-0.5 * ((y - upper_c) / (0.0025 + 0.002 * lip_w)).powi(2)).exp();
    h += 0.0045 * lip_w * (-0.5 * ((y - lower_c) / (0.0025 + 0.0025 * lip_w)).powi(2)).exp();
    h -= 0.0012 * lip_w * (-0.5 * ((y - mouth_y) / 0.003).powi(2)).exp();
    // Philtrum: two faint ridges from the nose base to the upper lip.
    h += 0.0008 * gauss2((ax - 0.005) / 0.0025, (y - mouth_y - 0.014) / 0.006);
    // Nasolabial folds: shallow creases from the nostril wings to beside the mouth corners.
    let (fx, fy) = (ax - 0.021 - 0.012 * ((-0.02 - y) / 0.04), y + 0.04);
    h -= 0.0015 * gauss2(fx / 0.004, fy / 0.02);
    // Mentolabial sulcus and chin.
    h -= 0.002 * gauss2(ax / 0.018, (y - mouth_y + 0.019) / 0.0045);
    h += 0.009 * gauss2(ax / 0.017, (y + 0.083) / 0.011);
    h
}

/// Central-profile arc length table: `(y_k, s_k)` with `s` the arc length of the base profile
/// at θ = 0 from `Y_BOTTOM` (m).
fn profile_arclength(samples: usize) -> Vec<(f64, f64)> {
    let mut out = Vec::with_capacity(samples + 1);
    let mut s = 0.0;
    let mut prev = base_point(0.0, Y_BOTTOM);
    out.push((Y_BOTTOM, 0.0));
    for k in 1..=samples {
        let y = Y_BOTTOM + (Y_TOP - Y_BOTTOM) * k as f64 / samples as f64;
        let p = base_point(0.0, y);
        s += (p - prev).norm();
        prev = p;
        out.push((y, s));
    }
    out
}

/// Height y at arc length `s` along the central profile (linear interpolation in the table).
fn y_at_arclength(table: &[(f64, f64)], s: f64) -> f64 {
    let k = table
        .partition_point(|&(_, sk)| sk < s)
        .clamp(1, table.len() - 1);
    let (y0, s0) = table[k - 1];
    let (y1, s1) = table[k];
    y0 + (y1 - y0) * (s - s0) / (s1 - s0)
}

/// The parametric face surface with a fixed mouth height.
#[derive(Debug, Clone, Copy)]
pub struct FaceSurface {
    /// Height of the mouth line, m.
    pub mouth_y: f64,
}

impl FaceSurface {
    /// Surface point at azimuth `theta` (rad) and height `y` (m).
    pub fn point(&self, theta: f64, y: f64) -> Vector3<f64> {
        let x = half_width(y) * theta.sin();
        base_point(theta, y) + relief(x, y, self.mouth_y) * base_normal(theta, y)
    }
}

/// Sample the mask on a triangular lattice of `rows` rows with `2k + 1` vertices on even rows
/// and `2k + 2` on odd rows, and cut the mouth slit.
///
/// # Panics
/// If the lattice is too coarse to hold a mouth slit (`k < 10` or `rows < 24`; use
/// [`crate::rig::face::generate_with`], which validates its settings).
pub fn build_mask(k: usize, rows: usize) -> Mask {
    assert!(
        k >= 10 && rows >= 24,
        "face mask lattice too coarse: k = {k}, rows = {rows}"
    );
    let n_even = 2 * k + 1;
    let dtheta = THETA_MAX / k as f64;
    let table = profile_arclength(4000);
    let total = table.last().map_or(0.0, |&(_, s)| s);
    let ys: Vec<f64> = (0..rows)
        .map(|j| y_at_arclength(&table, total * j as f64 / (rows - 1) as f64))
        .collect();
    // The mouth row: nearest to the requested height.
    let jm = (0..rows)
        .min_by(|&a, &b| {
            (ys[a] - MOUTH_Y_TARGET)
                .abs()
                .total_cmp(&(ys[b] - MOUTH_Y_TARGET).abs())
        })
        .unwrap_or(0);
    let surface = FaceSurface { mouth_y: ys[jm] };
    let row_len = |j: usize| if j % 2 == 0 { n_even } else { n_even + 1 };
    let theta_of = |i: usize, j: usize| (i as f64 - (row_len(j) - 1) as f64 / 2.0) * dtheta;

    let mut samples = Vec::new();
    let mut mirror = Vec::new();
    let mut row_start = Vec::with_capacity(rows);
    for (j, &y) in ys.iter().enumerate() {
        row_start.push(samples.len());
        let n = row_len(j);
        for i in 0..n {
            let theta = theta_of(i, j);
            let side = if j >= jm { Side::Upper } else { Side::Lower };
            samples.push(make_sample(&surface, theta, y, side));
            mirror.push(row_start[j] + n - 1 - i);
        }
    }
    // Slit on row jm: positions strictly between the corners.
    let nm = row_len(jm);
    let slit_cols: Vec<usize> = (0..nm)
        .filter(|&i| samples[row_start[jm] + i].x.abs() < MOUTH_HALF_WIDTH_TARGET)
        .collect();
    let (first, last) = (slit_cols[0], slit_cols[slit_cols.len() - 1]);
    let corners = [row_start[jm] + first - 1, row_start[jm] + last + 1];
    let corner_x = samples[corners[1]].x;
    let slit_upper: Vec<usize> = slit_cols.iter().map(|&i| row_start[jm] + i).collect();
    let mut slit_lower = Vec::with_capacity(slit_upper.len());
    let lower_base = samples.len();
    for (c, &v) in slit_upper.iter().enumerate() {
        let mut s = samples[v];
        s.side = Side::Lower;
        samples.push(s);
        slit_lower.push(lower_base + c);
    }
    let slit_count = slit_upper.len();
    for c in 0..slit_count {
        let mv = mirror[slit_upper[c]];
        let mc = slit_upper.iter().position(|&u| u == mv).unwrap_or(c);
        mirror.push(lower_base + mc);
    }

    // Index of lattice vertex (i, j) as seen from the strip above (`from_below == false`) or
    // below the row.
    let idx = |i: usize, j: usize, from_below: bool| -> usize {
        if j == jm && from_below && i >= first && i <= last {
            lower_base + (i - first)
        } else {
            row_start[j] + i
        }
    };
    let mut triangles = Vec::with_capacity(2 * samples.len());
    for j in 0..rows - 1 {
        let lo = |i: usize| idx(i, j, false);
        let up = |i: usize| idx(i, j + 1, true);
        let n = row_len(j);
        if n == n_even {
            // Lower row A (n), upper row B (n + 1): B_i < A_i < B_{i+1}.
            for i in 0..n {
                triangles.push([lo(i), up(i + 1), up(i)]);
                if i + 1 < n {
                    triangles.push([lo(i), lo(i + 1), up(i + 1)]);
                }
            }
        } else {
            // Lower row B (n), upper row A (n − 1): B_i < A_i < B_{i+1}.
            for i in 0..n - 1 {
                triangles.push([lo(i), lo(i + 1), up(i)]);
                if i + 1 < n - 1 {
                    triangles.push([up(i), lo(i + 1), up(i + 1)]);
                }
            }
        }
    }
    let mut rim = Vec::new();
    for (j, &start) in row_start.iter().enumerate() {
        let n = row_len(j);
        if j == 0 || j == rows - 1 {
            rim.extend(start..start + n);
        } else {
            rim.push(start);
            rim.push(start + n - 1);
        }
    }
    let positions = samples.iter().map(|s| s.pos).collect();
    Mask {
        mesh: TriMesh::new(positions, triangles),
        samples,
        mirror,
        slit_upper,
        slit_lower,
        corners,
        mouth_y: surface.mouth_y,
        corner_x,
        rim,
    }
}

/// Evaluate position and frame of the surface at `(theta, y)`.
fn make_sample(surface: &FaceSurface, theta: f64, y: f64, side: Side) -> Sample {
    let (e_u, e_v, n) = base_frame(theta, y);
    Sample {
        theta,
        y,
        x: half_width(y) * theta.sin(),
        side,
        pos: surface.point(theta, y),
        e_u,
        e_v,
        n,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn smoothstep_and_bump_have_the_stated_ends() {
        assert_eq!(smoothstep(0.0, 1.0, -1.0), 0.0);
        assert_eq!(smoothstep(0.0, 1.0, 0.5), 0.5);
        assert_eq!(smoothstep(0.0, 1.0, 2.0), 1.0);
        assert_eq!(smoothstep(1.0, 0.0, 0.0), 1.0);
        assert_eq!(bump(0.0), 1.0);
        assert_eq!(bump(1.0), 0.0);
        assert_eq!(bump(-1.5), 0.0);
        // C² at r = 1: value, slope and curvature vanish (finite differences, O(h³)).
        let h = 1e-3;
        assert!(bump(1.0 - h) < 10.0 * h.powi(3));
    }

    #[test]
    fn arclength_table_inverts_the_profile() {
        let table = profile_arclength(4000);
        let total = table.last().unwrap().1;
        // The central profile is longer than the chord and shorter than twice the height.
        assert!(total > Y_TOP - Y_BOTTOM && total < 2.0 * (Y_TOP - Y_BOTTOM));
        for k in [0, 1, 17, 2000, 3999, 4000] {
            let (y, s) = table[k];
            assert!((y_at_arclength(&table, s) - y).abs() < 1e-12);
        }
        // Monotone in between.
        let ys: Vec<f64> = (0..=100)
            .map(|i| y_at_arclength(&table, total * i as f64 / 100.0))
            .collect();
        assert!(ys.windows(2).all(|w| w[1] > w[0]));
    }

    #[test]
    fn base_frame_is_orthonormal_and_tangent() {
        for &(theta, y) in &[(0.0, 0.0), (0.7, 0.05), (-1.2, -0.08), (1.3, 0.095)] {
            let (e_u, e_v, n) = base_frame(theta, y);
            for (a, b) in [(e_u, e_v), (e_v, n), (n, e_u)] {
                assert!(a.dot(&b).abs() < 1e-12);
            }
            for v in [e_u, e_v, n] {
                assert!((v.norm() - 1.0).abs() < 1e-12);
            }
            // Tangent: moving along the surface is orthogonal to n (to first order).
            let h = 1e-7;
            let dt = base_point(theta + h, y) - base_point(theta - h, y);
            let dy = base_point(theta, y + h) - base_point(theta, y - h);
            let (ct, cy) = (n.dot(&dt) / dt.norm(), n.dot(&dy) / dy.norm());
            assert!(
                ct.abs() < 1e-6 && cy.abs() < 1e-6,
                "({theta}, {y}): {ct:e} {cy:e}"
            );
            // Outward: away from the head's vertical axis.
            let p = base_point(theta, y);
            assert!(n.x * p.x + n.z * p.z > 0.0);
            assert!(e_v.y > 0.5);
        }
    }

    #[test]
    fn small_lattice_has_the_expected_counts_and_topology() {
        let (k, rows) = (20, 40);
        let m = build_mask(k, rows);
        let n_even = 2 * k + 1;
        let lattice: usize = (0..rows)
            .map(|j| if j % 2 == 0 { n_even } else { n_even + 1 })
            .sum();
        let slit = m.slit_upper.len();
        assert!(slit >= 2);
        assert_eq!(m.mesh.vertex_count(), lattice + slit);
        // Each strip between rows of n and n + 1 vertices holds 2n − 1 triangles.
        assert_eq!(m.mesh.triangle_count(), (rows - 1) * (2 * n_even - 1));
        // Euler characteristic of a disc with one hole (the mouth): V − E + F = 0.
        let mut edges = std::collections::HashSet::new();
        for t in &m.mesh.triangles {
            for i in 0..3 {
                let (a, b) = (t[i], t[(i + 1) % 3]);
                edges.insert((a.min(b), a.max(b)));
            }
        }
        let chi =
            m.mesh.vertex_count() as i64 - edges.len() as i64 + m.mesh.triangle_count() as i64;
        assert_eq!(chi, 0);
        // The mirror map is an involution.
        assert!((0..m.mirror.len()).all(|v| m.mirror[m.mirror[v]] == v));
    }
}
