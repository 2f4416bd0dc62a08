//! A capture-shaped head rig (`rigs/head.glb`, `furrow rig generate --kind head`): a coarse
//! whole head (crown, back of the head, ears, a neck stub open at the bottom) of about 2.7k
//! vertices and 0.23 m tall, with the 52 ARKit blend shapes acting on the front of the face
//! and an 11 s capture-like performance (several shapes at partial weights at once, jitter on
//! every weight). Metres, +Y up, facing +Z; "Left" is the subject's left (+X). Deterministic.
//!
//! The surface is a stack of rings (horizontal cross-sections: half-width `x`, front depth
//! `zf`, back depth `zb`, each a function of height) from a pole at the crown to the open
//! neck ring, spaced evenly in a face-weighted arc length, with columns denser at the front;
//! neighbouring rings are zipped into triangles by angle. Facial features (eye sockets, brow
//! ridge, nose, lips, chin, cheekbones) and the ears are displacements along the normal. The
//! mouth is a slit: the mouth ring's front vertices are split into an upper and a lower lip
//! 0.4 mm apart.

use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use nalgebra::Vector3;

use super::head_animation::performance;
pub use super::head_shapes::EYE;
use super::head_shapes::{shape_deltas, Sample, ARKIT_NAMES};
use super::surface::{bump, smoothstep};

/// Height of the crown above the origin, m (the neck ends at −`HALF_HEIGHT`).
pub const HALF_HEIGHT: f64 = 0.115;
/// Requested height of the mouth slit, m (the actual one is the nearest ring's).
pub const MOUTH_Y_TARGET: f64 = -0.045;
/// Half-width of the mouth slit (base lateral coordinate of the corners), m.
pub const MOUTH_HALF_WIDTH: f64 = 0.024;

/// Number of rings below the crown pole.
pub const RINGS: usize = 42;
/// Mean spacing of the columns along a ring, m (denser at the front by [`FRONT_WARP`]).
pub const COLUMN_SPACING: f64 = 0.0066;
/// Column density warp: spacing at the front is (1 − w) times the mean, at the back (1 + w).
pub const FRONT_WARP: f64 = 0.3;
/// Half the gap between the upper and lower lip along the slit, m.
const LIP_GAP_HALF: f64 = 0.0002;

/// A capture-shaped blend-shape head rig.
#[derive(Debug, Clone)]
pub struct HeadRig {
    /// Neutral head surface, metres, +Y up, facing +Z.
    pub mesh: TriMesh,
    /// The 52 ARKit blend shapes ([`ARKIT_NAMES`] order) as position deltas (m) with the
    /// matching unit-normal deltas.
    pub targets: Vec<MorphTarget>,
    /// The performance: keys at 30 fps over 11 s (one weight per target per key).
    pub keys: WeightKeys,
    /// Height of the mouth slit, m.
    pub mouth_y: f64,
    /// Base lateral coordinate of the mouth corners, m.
    pub corner_x: f64,
}

/// One horizontal cross-section: height and its half-width and depths, m.
#[derive(Debug, Clone, Copy)]
pub struct Ring {
    /// Height, m.
    pub y: f64,
    /// Half-width, m.
    pub x: f64,
    /// Depth in front of the axis, m.
    pub zf: f64,
    /// Depth behind the axis, m.
    pub zb: f64,
}

/// The cross-section at meridian angle `a` ∈ [0, π] (0: the crown; π/2: the widest ring at
/// y = 0; π: the bottom of the neck). The cranium is an ellipsoid; below it the face narrows
/// to the jaw, the chin's underside recedes to the neck, the occiput curves in to the nape.
pub fn ring_at(a: f64) -> Ring {
    use std::f64::consts::FRAC_PI_2;
    if a <= FRAC_PI_2 {
        let (s, c) = a.sin_cos();
        return Ring {
            y: HALF_HEIGHT * c,
            x: 0.078 * s,
            zf: 0.095 * s,
            zb: 0.105 * s,
        };
    }
    let y = -HALF_HEIGHT * (a - FRAC_PI_2) / FRAC_PI_2;
    Ring {
        y,
        x: 0.078 - 0.018 * smoothstep(0.0, -0.06, y) - 0.008 * smoothstep(-0.06, -0.095, y),
        zf: 0.095 - 0.01 * smoothstep(0.0, -0.07, y) - 0.04 * smoothstep(-0.07, -0.095, y),
        zb: 0.105 - 0.05 * smoothstep(0.0, -0.05, y),
    }
}

/// The point of ring `r` at azimuth `phi` (0 at the front, +X at π/2), m.
pub fn ring_point(r: &Ring, phi: f64) -> Vector3<f64> {
    let (s, c) = phi.sin_cos();
    let z = if c >= 0.0 { r.zf } else { r.zb };
    Vector3::new(r.x * s, r.y, z * c)
}

/// Azimuth of column fraction `u` ∈ [0, 1): denser at the front (u = 0).
fn azimuth(u: f64) -> f64 {
    warped_azimuth(u, FRONT_WARP)
}

/// Azimuth (rad) of column fraction `u` ∈ [0, 1) with front warp `warp`: the spacing at the
/// front is (1 − `warp`) times the mean, at the back (1 + `warp`).
pub fn warped_azimuth(u: f64, warp: f64) -> f64 {
    let t = std::f64::consts::TAU * u;
    t - warp * t.sin()
}

/// Meridian angles of the [`RINGS`] rings below the pole: even steps of arc length (the
/// longest of the front, back and side profiles), steps over the face 1.6 times shorter.
fn ring_angles() -> Vec<f64> {
    let steps = 8000;
    let at = |k: usize| ring_at(std::f64::consts::PI * k as f64 / steps as f64);
    let mut cumulative = vec![0.0];
    for k in 0..steps {
        let (a, b) = (at(k), at(k + 1));
        let dy = b.y - a.y;
        let d = [b.x - a.x, b.zf - a.zf, b.zb - a.zb]
            .iter()
            .map(|dr| dr.hypot(dy))
            .fold(0.0, f64::max);
        let face = 1.0 + 0.6 * bump((0.5 * (a.y + b.y) + 0.02) / 0.075);
        cumulative.push(cumulative[k] + d * face);
    }
    let total = cumulative[steps];
    (1..=RINGS)
        .map(|r| {
            let goal = total * r as f64 / RINGS as f64;
            let k = cumulative.partition_point(|&c| c < goal).clamp(1, steps);
            let f = (goal - cumulative[k - 1]) / (cumulative[k] - cumulative[k - 1]).max(1e-300);
            std::f64::consts::PI * (k as f64 - 1.0 + f.clamp(0.0, 1.0)) / steps as f64
        })
        .collect()
}

/// Even column count of a ring from its perimeter (Ramanujan's ellipse formula), at least 6.
fn columns(r: &Ring) -> usize {
    columns_at(r, COLUMN_SPACING)
}

/// Even column count of ring `r` for a mean column spacing of `spacing` (m), at least 6.
pub fn columns_at(r: &Ring, spacing: f64) -> usize {
    let (a, b) = (r.x, 0.5 * (r.zf + r.zb));
    let p = std::f64::consts::PI * (3.0 * (a + b) - ((3.0 * a + b) * (a + 3.0 * b)).sqrt());
    (2 * (p / (2.0 * spacing)).round() as usize).max(6)
}

/// The neutral surface before features: positions, triangles, each vertex's ring (0 is the
/// pole), the lower-lip copies of the slit (appended last) and the mouth ring.
struct Base {
    positions: Vec<Vector3<f64>>,
    triangles: Vec<[usize; 3]>,
    ring_of: Vec<usize>,
    lower_lip: Vec<bool>,
    mouth_ring: usize,
    corner_x: f64,
}

/// Zip ring `a` (above) and ring `b` (below), both starting at the front, into triangles
/// by azimuth (each ring's indices in column order).
pub fn zip(a: &[usize], b: &[usize], out: &mut Vec<[usize; 3]>) {
    let (na, nb) = (a.len(), b.len());
    let (mut i, mut j) = (0, 0);
    while i < na || j < nb {
        let ua = (i + 1) as f64 / na as f64;
        let ub = (j + 1) as f64 / nb as f64;
        if j >= nb || (i < na && ua <= ub) {
            out.push([a[i], a[(i + 1) % na], b[j % nb]]);
            i += 1;
        } else {
            out.push([a[i % na], b[(j + 1) % nb], b[j]]);
            j += 1;
        }
    }
}

/// Build the rings, zip them, and cut the mouth slit.
fn build_base() -> Base {
    let rings: Vec<Ring> = ring_angles().into_iter().map(ring_at).collect();
    let mouth_ring = 1
        + (0..rings.len())
            .min_by(|&p, &q| {
                (rings[p].y - MOUTH_Y_TARGET)
                    .abs()
                    .total_cmp(&(rings[q].y - MOUTH_Y_TARGET).abs())
            })
            .unwrap_or(0);
    let mut positions = vec![Vector3::new(0.0, HALF_HEIGHT, 0.0)];
    let mut ring_of = vec![0];
    let mut ids: Vec<Vec<usize>> = vec![vec![0]];
    for (k, r) in rings.iter().enumerate() {
        let n = columns(r);
        let mut row = Vec::with_capacity(n);
        for c in 0..n {
            row.push(positions.len());
            positions.push(ring_point(r, azimuth(c as f64 / n as f64)));
            ring_of.push(k + 1);
        }
        ids.push(row);
    }
    // The slit: the mouth ring's front vertices within the mouth's half-width; the lower lip
    // gets copies, the two lips are moved apart by the gap.
    let slit: Vec<usize> = ids[mouth_ring]
        .iter()
        .copied()
        .filter(|&v| positions[v].z > 0.0 && positions[v].x.abs() < MOUTH_HALF_WIDTH)
        .collect();
    let corner_x = ids[mouth_ring]
        .iter()
        .map(|&v| positions[v])
        .filter(|p| p.z > 0.0 && p.x.abs() >= MOUTH_HALF_WIDTH)
        .map(|p| p.x.abs())
        .fold(f64::INFINITY, f64::min);
    let mut lower_of = std::collections::HashMap::new();
    for &v in &slit {
        let mut p = positions[v];
        positions[v].y += LIP_GAP_HALF;
        p.y -= LIP_GAP_HALF;
        lower_of.insert(v, positions.len());
        positions.push(p);
        ring_of.push(mouth_ring);
    }
    let mut lower_lip = vec![false; positions.len()];
    for &l in lower_of.values() {
        lower_lip[l] = true;
    }
    let mut triangles = Vec::new();
    for k in 0..ids.len() - 1 {
        let above: Vec<usize> = if k == mouth_ring {
            ids[k]
                .iter()
                .map(|v| *lower_of.get(v).unwrap_or(v))
                .collect()
        } else {
            ids[k].clone()
        };
        if k == 0 {
            let b = &ids[1];
            for j in 0..b.len() {
                triangles.push([0, b[(j + 1) % b.len()], b[j]]);
            }
        } else {
            zip(&above, &ids[k + 1], &mut triangles);
        }
    }
    Base {
        positions,
        triangles,
        ring_of,
        lower_lip,
        mouth_ring,
        corner_x,
    }
}

/// Outward displacement (m) of the facial features and ears at base point `p` (m), for the
/// mouth slit at height `mouth_y` (m).
pub fn features(p: &Vector3<f64>, mouth_y: f64) -> f64 {
    let (x, y, ax) = (p.x, p.y, p.x.abs());
    let front = smoothstep(0.0, 0.04, p.z);
    let eye = ((ax - EYE.0) / 0.022).hypot((y - EYE.1) / 0.016);
    let mut h = -0.007 * bump(eye) + 0.004 * bump(eye * 1.6);
    h += 0.004 * bump((y - 0.042) / 0.012) * (1.0 - smoothstep(0.045, 0.065, ax));
    let ridge = smoothstep(0.032, -0.012, y) * smoothstep(-0.024, -0.012, y);
    h += 0.022 * ridge * (-(x / 0.009).powi(2)).exp();
    h += 0.008 * bump(((ax - 0.014) / 0.012).hypot((y + 0.016) / 0.01));
    h += 0.006 * bump((x / 0.03).hypot((y - mouth_y) / 0.014));
    h += 0.007 * bump((x / 0.025).hypot((y + 0.074) / 0.016));
    h += 0.005 * bump(((ax - 0.048) / 0.025).hypot(y / 0.02));
    let ear = ((p.z + 0.018) / 0.016).hypot((y - 0.005) / 0.032);
    h * front + 0.016 * bump(ear) * smoothstep(0.06, 0.072, ax)
}

/// Local frame at a vertex of unit normal `n`: (e_u ≈ +X along the skin, e_v ≈ +Y along the
/// skin), unit vectors.
pub fn frame(n: &Vector3<f64>) -> (Vector3<f64>, Vector3<f64>) {
    let up = Vector3::y() - n * n.y;
    let e_v = if up.norm() > 1e-9 {
        up.normalize()
    } else {
        Vector3::z()
    };
    (e_v.cross(n), e_v)
}

/// Generate the head rig (see the module description). Deterministic.
pub fn generate() -> HeadRig {
    let base = build_base();
    let mut mesh = TriMesh::new(base.positions.clone(), base.triangles.clone());
    orient_outward(&mut mesh);
    let mouth_y = base.positions[base
        .ring_of
        .iter()
        .position(|&r| r == base.mouth_ring)
        .unwrap_or(0)]
    .y - LIP_GAP_HALF;
    let n0 = mesh.vertex_normals();
    for (p, n) in mesh.positions.iter_mut().zip(&n0) {
        *p += n * features(p, mouth_y);
    }
    let normals = mesh.vertex_normals();
    let samples: Vec<Sample> = mesh
        .positions
        .iter()
        .zip(&normals)
        .enumerate()
        .map(|(v, (p, n))| {
            let (e_u, e_v) = frame(n);
            Sample {
                pos: *p,
                n: *n,
                e_u,
                e_v,
                lower: base.lower_lip[v] || base.ring_of[v] > base.mouth_ring,
            }
        })
        .collect();
    let targets = shape_deltas(&samples, mouth_y, base.corner_x)
        .into_iter()
        .map(|(name, positions)| {
            let dn = mesh.normal_deltas(&normals, &positions);
            MorphTarget {
                name,
                positions,
                normals: Some(dn),
            }
        })
        .collect();
    HeadRig {
        mesh,
        targets,
        keys: performance(&ARKIT_NAMES),
        mouth_y,
        corner_x: base.corner_x,
    }
}

/// Flip every triangle when the surface's normals point inward on average (the surface
/// around the origin).
pub fn orient_outward(mesh: &mut TriMesh) {
    let mut s = 0.0;
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.positions[i]);
        s += (b - a).cross(&(c - a)).dot(&((a + b + c) / 3.0));
    }
    if s < 0.0 {
        for t in &mut mesh.triangles {
            t.swap(1, 2);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn head_numbers() {
        let rig = generate();
        let m = &rig.mesh;
        let (lo, hi) = m.bounding_box().expect("box");
        let mut edges = std::collections::HashSet::new();
        for t in &m.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                edges.insert((a.min(b), a.max(b)));
            }
        }
        let mean = edges
            .iter()
            .map(|&(a, b)| (m.positions[a] - m.positions[b]).norm())
            .sum::<f64>()
            / edges.len() as f64;
        println!(
            "vertices {} triangles {} box {:?} .. {:?} mean edge {:.2} mm mouth {:.4} corner {:.4}",
            m.vertex_count(),
            m.triangle_count(),
            lo,
            hi,
            mean * 1e3,
            rig.mouth_y,
            rig.corner_x
        );
        for t in &rig.targets {
            let moved = t.positions.iter().filter(|d| d.norm() > 1e-5).count();
            let max = t.positions.iter().map(|d| d.norm()).fold(0.0, f64::max);
            println!("{} moved {} max {:.2} mm", t.name, moved, max * 1e3);
        }
    }
}
