//! The avatar's head surface (`furrow rig generate --kind avatar`): the capture-shaped head of
//! [`super::head`] (its cross-sections, features and ears) remeshed at about 2,000 vertices,
//! with the openings a downloaded avatar has: a mouth slit between lips modelled closed
//! (0.4 mm apart) and two eye openings between lids that rest on the eyeballs. Metres, +Y up,
//! facing +Z, the origin near the head's centre; "Left" is the subject's left (+X).
//!
//! The rings (horizontal cross-sections, zipped into triangles by azimuth) are spaced evenly
//! in a face-weighted arc length, except that rings pass exactly through the rows the folding
//! shapes hinge on: the mouth slit and two rows [`LIP_ROW`] apart above and below it (the
//! lip's margin strip and the vermilion border), the eye line and one row [`LID_ROW`] above
//! and below it (the lid margins). Each slit is cut along its ring: its vertices are split
//! into an upper and a lower copy [`GAP_HALF`] either side. The eyes are then opened: the
//! upper lid raised [`LID_UP`] and the lower lowered [`LID_DOWN`] at the middle of the eye
//! (a lens profile, zero at the corners), fading over [`LID_FALL`] above and below, and every
//! vertex that would lie within [`LID_CLEARANCE`] of its eyeball is pushed out onto that
//! clearance.

use super::head::{
    columns_at, features, orient_outward, ring_at, ring_point, warped_azimuth, zip, Ring, EYE,
    HALF_HEIGHT,
};
use super::surface::{bump, smoothstep};
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use std::f64::consts::PI;

/// Height of the mouth slit's ring, m.
pub const MOUTH_Y: f64 = -0.045;
/// Half-width of the mouth slit (base lateral coordinate), m.
pub const MOUTH_HALF_WIDTH: f64 = 0.024;
/// Spacing of the rows above and below the mouth slit, m.
pub const LIP_ROW: f64 = 0.0025;
/// Spacing of the rows above and below the eye line, m.
pub const LID_ROW: f64 = 0.002;
/// Half the gap between the two copies of a slit, m.
pub const GAP_HALF: f64 = 0.0002;
/// Half-width of each eye slit about the eye's centre (base lateral coordinate), m.
pub const EYE_HALF_WIDTH: f64 = 0.013;
/// Rise of the upper lid at the middle of the open eye, m.
pub const LID_UP: f64 = 0.0045;
/// Drop of the lower lid at the middle of the open eye, m.
pub const LID_DOWN: f64 = 0.003;
/// Distance from the lid rows over which the eye's opening fades out, m.
pub const LID_FALL: f64 = 0.012;
/// Radius of an eyeball, m.
pub const EYE_RADIUS: f64 = 0.012;
/// Least distance of the lids from their eyeball's surface, m.
pub const LID_CLEARANCE: f64 = 0.0008;
/// Mean face-weighted arc length between rings, m.
const RING_SPACING: f64 = 0.0082;
/// Mean spacing of the columns along a ring, m.
const COLUMN_SPACING: f64 = 0.011;
/// Column density warp (see [`warped_azimuth`]).
const FRONT_WARP: f64 = 0.65;

/// Which slit a vertex is the lower copy of.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SlitCopy {
    /// An ordinary vertex (or a slit's upper copy).
    None,
    /// The lower lip's copy of a mouth slit vertex.
    Lip,
    /// The lower lid's copy of an eye slit vertex.
    Lid,
}

/// The avatar's neutral head and where its rows are.
#[derive(Debug, Clone)]
pub struct AvatarHead {
    /// Neutral surface (m), counter-clockwise seen from outside, seamless.
    pub mesh: TriMesh,
    /// Each vertex before the features and the eyes' opening (m): its ring's point.
    pub base: Vec<Vector3<f64>>,
    /// Each vertex's ring (0 is the crown's pole).
    pub ring_of: Vec<usize>,
    /// Which slit each vertex is the lower copy of.
    pub copy: Vec<SlitCopy>,
    /// Each ring's vertices in column order (front first; slit rings list the upper copies).
    pub rings: Vec<Vec<usize>>,
    /// Ring of the mouth slit.
    pub mouth_ring: usize,
    /// Ring of the eye slits.
    pub eye_ring: usize,
    /// Height of the lower lip's slit copies, m.
    pub mouth_y: f64,
    /// Base lateral coordinate of the mouth corners, m.
    pub corner_x: f64,
    /// Eyeball centres, left (+X) first, m.
    pub eyes: [Vector3<f64>; 2],
}

impl AvatarHead {
    /// Which side of slit ring `ring` (lower copies `copy`) vertex `v` is on, and how many
    /// rows from the slit: (true, k) k rows above, (false, k) k rows below (0: a copy on the
    /// slit itself).
    pub fn row(&self, v: usize, ring: usize, copy: SlitCopy) -> (bool, usize) {
        let r = self.ring_of[v];
        match r.cmp(&ring) {
            std::cmp::Ordering::Less => (true, ring - r),
            std::cmp::Ordering::Greater => (false, r - ring),
            std::cmp::Ordering::Equal => (self.copy[v] != copy, 0),
        }
    }

    /// The front vertices (z > 0 at the base) of ring `ring` sorted by x, with every slit
    /// vertex replaced by its lower copy of kind `lower` when it is not [`SlitCopy::None`].
    pub fn front_row(&self, ring: usize, lower: SlitCopy) -> Vec<usize> {
        let n = self.mesh.positions.len();
        let mut row: Vec<usize> = if lower == SlitCopy::None {
            self.rings[ring].clone()
        } else {
            let mut r: Vec<usize> = (0..n)
                .filter(|&v| self.ring_of[v] == ring && self.copy[v] == lower)
                .collect();
            let copied: Vec<f64> = r.iter().map(|&v| self.base[v].x).collect();
            r.extend(
                self.rings[ring]
                    .iter()
                    .copied()
                    .filter(|&v| !copied.iter().any(|&x| (self.base[v].x - x).abs() < 1e-12)),
            );
            r
        };
        row.retain(|&v| self.base[v].z > 0.0);
        row.sort_by(|&a, &b| self.base[a].x.total_cmp(&self.base[b].x));
        row
    }
}

/// The lens profile of an eye slit at lateral offset `x_rel` (m) from the eye's centre:
/// 1 at the middle, 0 at and beyond the corners.
pub fn lid_lens(x_rel: f64) -> f64 {
    let r = x_rel / EYE_HALF_WIDTH;
    if r.abs() < 1.0 {
        (1.0 - r * r).powi(2)
    } else {
        0.0
    }
}

/// Weight of the rows `d` m above or below the eye line in the lids' motion: 1 on the lid
/// rows, fading to 0 over [`LID_FALL`].
pub fn lid_fall(d: f64) -> f64 {
    1.0 - smoothstep(LID_ROW, LID_ROW + LID_FALL, d)
}

/// Meridian angles (rad, 0 at the crown) of the rings: every height in `required` (m) is a
/// ring; between them rings are spaced evenly in face-weighted arc length.
fn ring_angles(required: &[f64]) -> Vec<f64> {
    let steps = 8000;
    let at = |k: usize| ring_at(PI * k as f64 / steps as f64);
    let mut cumulative = vec![0.0];
    for k in 0..steps {
        let (a, b) = (at(k), at(k + 1));
        let dy = b.y - a.y;
        let d = [b.x - a.x, b.zf - a.zf, b.zb - a.zb]
            .iter()
            .map(|dr| dr.hypot(dy))
            .fold(0.0, f64::max);
        let face = 1.0 + 0.9 * bump((0.5 * (a.y + b.y) + 0.015) / 0.07);
        cumulative.push(cumulative[k] + d * face);
    }
    let arc = |a: f64| {
        let s = (a / PI * steps as f64).clamp(0.0, steps as f64);
        let k = (s.floor() as usize).min(steps - 1);
        cumulative[k] + (s - k as f64) * (cumulative[k + 1] - cumulative[k])
    };
    let angle_of_arc = |goal: f64| {
        let k = cumulative.partition_point(|&c| c < goal).clamp(1, steps);
        let f = (goal - cumulative[k - 1]) / (cumulative[k] - cumulative[k - 1]).max(1e-300);
        PI * (k as f64 - 1.0 + f.clamp(0.0, 1.0)) / steps as f64
    };
    let angle_of_y = |y: f64| {
        let (mut lo, mut hi) = (0.0, PI);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if ring_at(mid).y > y {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    };
    let mut anchors: Vec<f64> = required.iter().map(|&y| angle_of_y(y)).collect();
    anchors.sort_by(f64::total_cmp);
    anchors.push(PI);
    let (mut out, mut lo) = (Vec::new(), 0.0);
    for hi in anchors {
        let (c0, c1) = (arc(lo), arc(hi));
        let n = ((c1 - c0) / RING_SPACING).round().max(1.0) as usize;
        out.extend((1..n).map(|k| angle_of_arc(c0 + (c1 - c0) * k as f64 / n as f64)));
        out.push(hi);
        lo = hi;
    }
    out
}

/// The surface before features: positions, triangles, rings and slit copies.
struct Base {
    positions: Vec<Vector3<f64>>,
    triangles: Vec<[usize; 3]>,
    ring_of: Vec<usize>,
    copy: Vec<SlitCopy>,
    rings: Vec<Vec<usize>>,
    mouth_ring: usize,
    eye_ring: usize,
    corner_x: f64,
}

/// Build the rings, cut the mouth and eye slits, and zip the rings into triangles.
fn build_base() -> Base {
    let required = [
        EYE.1 + LID_ROW,
        EYE.1,
        EYE.1 - LID_ROW,
        MOUTH_Y + 2.0 * LIP_ROW,
        MOUTH_Y + LIP_ROW,
        MOUTH_Y,
        MOUTH_Y - LIP_ROW,
        MOUTH_Y - 2.0 * LIP_ROW,
    ];
    let rings: Vec<Ring> = ring_angles(&required).into_iter().map(ring_at).collect();
    let ring_index = |y: f64| {
        1 + rings
            .iter()
            .position(|r| (r.y - y).abs() < 1e-9)
            .unwrap_or(0)
    };
    let (mouth_ring, eye_ring) = (ring_index(MOUTH_Y), ring_index(EYE.1));
    let mut positions = vec![Vector3::new(0.0, HALF_HEIGHT, 0.0)];
    let mut ring_of = vec![0];
    let mut ids: Vec<Vec<usize>> = vec![vec![0]];
    for (k, r) in rings.iter().enumerate() {
        let n = columns_at(r, COLUMN_SPACING);
        let row: Vec<usize> = (positions.len()..positions.len() + n).collect();
        positions
            .extend((0..n).map(|c| ring_point(r, warped_azimuth(c as f64 / n as f64, FRONT_WARP))));
        ring_of.extend(std::iter::repeat_n(k + 1, n));
        ids.push(row);
    }
    let mut copy = vec![SlitCopy::None; positions.len()];
    let mut lower_of = std::collections::HashMap::new();
    let slits = [
        (mouth_ring, SlitCopy::Lip, MOUTH_HALF_WIDTH, 0.0),
        (eye_ring, SlitCopy::Lid, EYE_HALF_WIDTH, EYE.0),
    ];
    for (ring, kind, half, centre) in slits {
        for &v in &ids[ring] {
            let p = positions[v];
            if p.z <= 0.0 || (p.x.abs() - centre).abs() >= half {
                continue;
            }
            positions[v].y += GAP_HALF;
            lower_of.insert(v, positions.len());
            positions.push(p - Vector3::y() * GAP_HALF);
            ring_of.push(ring);
            copy.push(kind);
        }
    }
    let corner_x = ids[mouth_ring]
        .iter()
        .map(|&v| positions[v])
        .filter(|p| p.z > 0.0 && p.x.abs() >= MOUTH_HALF_WIDTH)
        .map(|p| p.x.abs())
        .fold(f64::INFINITY, f64::min);
    let mut triangles = Vec::new();
    let b = &ids[1];
    for j in 0..b.len() {
        triangles.push([0, b[(j + 1) % b.len()], b[j]]);
    }
    for k in 1..ids.len() - 1 {
        let above: Vec<usize> = ids[k]
            .iter()
            .map(|v| *lower_of.get(v).unwrap_or(v))
            .collect();
        zip(&above, &ids[k + 1], &mut triangles);
    }
    Base {
        positions,
        triangles,
        ring_of,
        copy,
        rings: ids,
        mouth_ring,
        eye_ring,
        corner_x,
    }
}

/// Open the eyes: raise the upper lids and lower the lower lids (see the module notes).
fn open_eyes(head: &mut AvatarHead) {
    for v in 0..head.mesh.positions.len() {
        let b = head.base[v];
        if b.z <= 0.0 {
            continue;
        }
        let lens = lid_lens(b.x.abs() - EYE.0);
        if lens == 0.0 {
            continue;
        }
        let (upper, _) = head.row(v, head.eye_ring, SlitCopy::Lid);
        let g = lid_fall((b.y - EYE.1).abs());
        let dy = if upper { LID_UP } else { -LID_DOWN };
        head.mesh.positions[v].y += dy * lens * g;
    }
}

/// Place each eyeball as far forward as its lid margins allow (their middle at least
/// [`LID_CLEARANCE`] in front of it), then push every vertex closer than that out onto it.
fn fit_eyes(head: &mut AvatarHead) {
    let reach = EYE_RADIUS + LID_CLEARANCE;
    for (k, sx) in [1.0, -1.0].into_iter().enumerate() {
        let cy = EYE.1 + 0.5 * (LID_UP - LID_DOWN);
        let mut cz = f64::INFINITY;
        for v in 0..head.mesh.positions.len() {
            let b = head.base[v];
            if head.ring_of[v] != head.eye_ring || b.z <= 0.0 || lid_lens(sx * b.x - EYE.0) < 0.4 {
                continue;
            }
            let p = head.mesh.positions[v];
            let (dx, dy) = (p.x - sx * EYE.0, p.y - cy);
            cz = cz.min(p.z - (reach * reach - dx * dx - dy * dy).max(0.0).sqrt());
        }
        let c = Vector3::new(sx * EYE.0, cy, cz);
        for p in head.mesh.positions.iter_mut() {
            let r = *p - c;
            if p.z > 0.0 && r.norm() < reach {
                *p = c + r.normalize() * reach;
            }
        }
        head.eyes[k] = c;
    }
}

/// Generate the avatar's neutral head (see the module notes). Deterministic.
pub fn generate() -> AvatarHead {
    let base = build_base();
    let mut mesh = TriMesh::new(base.positions.clone(), base.triangles);
    orient_outward(&mut mesh);
    let mouth_y = MOUTH_Y - GAP_HALF;
    let n0 = mesh.vertex_normals();
    for (p, n) in mesh.positions.iter_mut().zip(&n0) {
        *p += n * features(p, mouth_y);
    }
    let mut head = AvatarHead {
        mesh,
        base: base.positions,
        ring_of: base.ring_of,
        copy: base.copy,
        rings: base.rings,
        mouth_ring: base.mouth_ring,
        eye_ring: base.eye_ring,
        mouth_y,
        corner_x: base.corner_x,
        eyes: [Vector3::zeros(); 2],
    };
    open_eyes(&mut head);
    fit_eyes(&mut head);
    head
}

#[cfg(test)]
mod tests {
    use super::*;

    /// About 2,000 vertices, a head's height, the slits where they should be, no sharp crease
    /// at rest, and no vertex within the lids' clearance of an eyeball.
    #[test]
    fn the_head_is_a_head_with_openings() {
        let h = generate();
        let m = &h.mesh;
        let (lo, hi) = m.bounding_box().expect("box");
        assert!(
            (1900..=2300).contains(&m.vertex_count()),
            "{}",
            m.vertex_count()
        );
        assert!((hi.y - lo.y - 2.0 * HALF_HEIGHT).abs() < 1e-9);
        assert!((h.base[h.rings[h.mouth_ring][0]].y - MOUTH_Y - GAP_HALF).abs() < 1e-9);
        assert!((h.base[h.rings[h.eye_ring][0]].y - EYE.1).abs() < 1e-9);
        let rest = crate::mesh::fold::WeldedSurface::new(&m.positions, &m.triangles, 1e-7);
        let max = rest
            .turns(&m.positions)
            .into_iter()
            .flatten()
            .fold(0.0, f64::max);
        assert!(max.to_degrees() < 110.0, "{}", max.to_degrees());
        for c in h.eyes {
            let near = m
                .positions
                .iter()
                .map(|p| (p - c).norm())
                .fold(1.0, f64::min);
            assert!(near >= EYE_RADIUS + LID_CLEARANCE - 1e-9, "{near}");
        }
    }
}
