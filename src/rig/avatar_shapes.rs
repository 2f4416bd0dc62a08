//! The avatar head's blend shapes, named as Ready Player Me names them: the 52 ARKit shapes
//! ([`ARKIT_NAMES`] order) then the 15 Oculus visemes ([`VISEME_NAMES`]).
//!
//! The ARKit shapes are [`super::head_shapes`]'s smooth fields, except the ones that fold the
//! surface as real rigs do, where a margin strip of the lips or lids tucks in over a hinge row
//! (at weight 1 it lies [`TUCK_BEHIND_DEG`] behind the skin across the hinge, so the surface
//! turns about 160° there without passing through itself; the turn fades over a lateral
//! plateau):
//!
//! - `mouthPressLeft` / `mouthPressRight`: the lips close in by one row ([`LIP_ROW`]) so
//!   their hinge rows meet at the slit, and each lip's margin strip (the slit row) tucks in
//!   behind them: the lips pressed together into a line. The two are a linear split of one
//!   press (they add up to it), whose whole is `viseme_PP`.
//! - `mouthRollUpper` / `mouthRollLower`: the lip's red (the two strips between the slit and
//!   the vermilion border, two rows out) turns in over itself about the border, and the lip
//!   comes in so the border meets the other lip at the slit.
//! - `eyeBlinkLeft` / `eyeBlinkRight`: the lids slide over the eyeball (rotating about its
//!   centre) until the upper lid covers it and meets the lower lid [`BLINK_DROP`] below the
//!   eye line, and both press one row ([`LID_ROW`]) further, their margin strips tucking in
//!   behind the line where they meet.
//!
//! The jaw's shapes (`jawOpen`, `jawForward`, `jawLeft`, `jawRight`, `tongueOut`) move the
//! lower face with a weight that is whole over the lower lip as well as below it (fading
//! toward the mouth's corners), so the lower lip's rows travel with its margin and the open
//! jaw does not fold the lip over ([`jaw_weight`]), and fade from the chin down the throat
//! ([`jaw_mask`]), so the skin under the chin is not pushed into the neck.
//!
//! Each viseme is a fixed mix of ARKit shapes ([`VISEMES`]), so the eyes, teeth and mouth
//! interior get theirs from their own ARKit deltas by the same mix.

use super::avatar_head::{
    lid_fall, lid_lens, AvatarHead, SlitCopy, GAP_HALF, LID_DOWN, LID_ROW, LID_UP, LIP_ROW,
    MOUTH_HALF_WIDTH, MOUTH_Y,
};
use super::head::{frame, EYE};
use super::head_shapes::{
    front_mask, shape_deltas, Sample, ARKIT_NAMES, JAW_ANGLE, JAW_FORWARD, JAW_PIVOT_YZ, JAW_SIDE,
};
use super::surface::{bump, smoothstep, window};
use nalgebra::{Rotation3, Unit, Vector3};

/// The 15 viseme names, in Oculus' order.
pub const VISEME_NAMES: [&str; 15] = [
    "viseme_sil",
    "viseme_PP",
    "viseme_FF",
    "viseme_TH",
    "viseme_DD",
    "viseme_kk",
    "viseme_CH",
    "viseme_SS",
    "viseme_nn",
    "viseme_RR",
    "viseme_aa",
    "viseme_E",
    "viseme_I",
    "viseme_O",
    "viseme_U",
];

/// The shapes that fold the surface (past 150° between adjacent triangles at weight 1).
pub const FOLDING: [&str; 7] = [
    "eyeBlinkLeft",
    "eyeBlinkRight",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthRollLower",
    "mouthRollUpper",
    "viseme_PP",
];

/// Each viseme as a mix of ARKit shapes: (viseme, [(ARKit shape, weight)]).
pub const VISEMES: [(&str, &[(&str, f64)]); 15] = [
    ("viseme_sil", &[("mouthClose", 0.03)]),
    (
        "viseme_PP",
        &[("mouthPressLeft", 1.0), ("mouthPressRight", 1.0)],
    ),
    (
        "viseme_FF",
        &[
            ("mouthRollLower", 0.35),
            ("mouthUpperUpLeft", 0.25),
            ("mouthUpperUpRight", 0.25),
        ],
    ),
    ("viseme_TH", &[("jawOpen", 0.15), ("tongueOut", 0.35)]),
    (
        "viseme_DD",
        &[
            ("jawOpen", 0.25),
            ("mouthStretchLeft", 0.2),
            ("mouthStretchRight", 0.2),
        ],
    ),
    (
        "viseme_kk",
        &[
            ("jawOpen", 0.3),
            ("mouthStretchLeft", 0.3),
            ("mouthStretchRight", 0.3),
        ],
    ),
    (
        "viseme_CH",
        &[("jawOpen", 0.2), ("mouthFunnel", 0.6), ("mouthPucker", 0.2)],
    ),
    (
        "viseme_SS",
        &[
            ("jawOpen", 0.1),
            ("mouthStretchLeft", 0.4),
            ("mouthStretchRight", 0.4),
            ("mouthSmileLeft", 0.2),
            ("mouthSmileRight", 0.2),
        ],
    ),
    ("viseme_nn", &[("jawOpen", 0.2), ("mouthShrugUpper", 0.3)]),
    (
        "viseme_RR",
        &[
            ("jawOpen", 0.15),
            ("mouthFunnel", 0.4),
            ("mouthPucker", 0.3),
        ],
    ),
    (
        "viseme_aa",
        &[
            ("jawOpen", 0.7),
            ("mouthLowerDownLeft", 0.3),
            ("mouthLowerDownRight", 0.3),
        ],
    ),
    (
        "viseme_E",
        &[
            ("jawOpen", 0.35),
            ("mouthStretchLeft", 0.4),
            ("mouthStretchRight", 0.4),
            ("mouthUpperUpLeft", 0.2),
            ("mouthUpperUpRight", 0.2),
        ],
    ),
    (
        "viseme_I",
        &[
            ("jawOpen", 0.25),
            ("mouthSmileLeft", 0.4),
            ("mouthSmileRight", 0.4),
            ("mouthStretchLeft", 0.2),
            ("mouthStretchRight", 0.2),
        ],
    ),
    (
        "viseme_O",
        &[("jawOpen", 0.5), ("mouthFunnel", 0.6), ("mouthPucker", 0.3)],
    ),
    (
        "viseme_U",
        &[
            ("jawOpen", 0.15),
            ("mouthPucker", 0.8),
            ("mouthFunnel", 0.3),
        ],
    ),
];

/// How far behind the skin across its hinge a tucked strip lies at weight 1, deg: the
/// surface turns 180° less this there.
pub const TUCK_BEHIND_DEG: f64 = 18.0;
/// How far below the eye line the closed lids meet at the middle of the eye, m.
pub const BLINK_DROP: f64 = 0.0015;

/// Every target name of the avatar: [`ARKIT_NAMES`] then [`VISEME_NAMES`].
pub fn target_names() -> Vec<&'static str> {
    ARKIT_NAMES.iter().chain(&VISEME_NAMES).copied().collect()
}

/// Per-vertex deltas (m) of each shape.
pub type Shapes = Vec<(String, Vec<Vector3<f64>>)>;

/// The visemes mixed from `arkit` (every ARKit shape by name, in any order), in
/// [`VISEME_NAMES`] order.
pub fn visemes(arkit: &Shapes) -> Shapes {
    let n = arkit.first().map_or(0, |s| s.1.len());
    VISEMES
        .iter()
        .map(|(name, mix)| {
            let mut d = vec![Vector3::zeros(); n];
            for (shape, w) in mix.iter() {
                let (_, src) = arkit
                    .iter()
                    .find(|(s, _)| s == shape)
                    .expect("every mixed shape is an ARKit shape");
                for (di, si) in d.iter_mut().zip(src) {
                    *di += si * *w;
                }
            }
            (name.to_string(), d)
        })
        .collect()
}

/// Lateral weight of the lip folds at base lateral coordinate `x` (m): 1 over the middle
/// 16 mm, 0 from 2 mm inside the slit's ends (a fade over a few columns, so the fold dies
/// out without crumpling the strip).
pub fn lip_plateau(x: f64) -> f64 {
    1.0 - smoothstep(0.008, MOUTH_HALF_WIDTH - 0.002, x.abs())
}

/// Lateral weight of the lid folds at offset `x_rel` (m) from the eye's centre: 1 over the
/// middle 6 mm, 0 from 2 mm inside the eye's corners.
pub fn lid_plateau(x_rel: f64) -> f64 {
    1.0 - smoothstep(0.003, 0.011, x_rel.abs())
}

/// Where the polyline `row` (vertices sorted by x) passes `x` at rest: its segment's ends and
/// the weight of the second end.
fn bracket(rest: &[Vector3<f64>], row: &[usize], x: f64) -> ([usize; 2], f64) {
    let i = (0..row.len() - 1)
        .min_by(|&i, &j| {
            let gap = |k: usize| {
                let (a, b) = (rest[row[k]].x, rest[row[k + 1]].x);
                (a - x).max(x - b).max(0.0)
            };
            gap(i).total_cmp(&gap(j))
        })
        .unwrap_or(0);
    let (a, b) = (row[i], row[i + 1]);
    let f = ((x - rest[a].x) / (rest[b].x - rest[a].x)).clamp(0.0, 1.0);
    ([a, b], f)
}

/// Fold each `(vertex, weight)` of `movers` in over the hinge polyline `hinge` (vertices
/// sorted by x), the way into the surface at `pos`: about the hinge's direction at rest at the
/// mover's x (so a hinge that the shape bends along its length still folds its strip
/// straight), through the hinge's point there now, by the weight times the turn that lays the
/// mover [`TUCK_BEHIND_DEG`] behind the skin on the far side of the hinge (toward the
/// polyline `beyond` at that x).
fn tuck(
    head: &AvatarHead,
    pos: &mut [Vector3<f64>],
    hinge: &[usize],
    beyond: &[usize],
    movers: &[(usize, f64)],
) {
    let rest = &head.mesh.positions;
    let normals = head.mesh.vertex_normals_of(pos);
    let behind = TUCK_BEHIND_DEG.to_radians();
    for &(v, w) in movers {
        if w == 0.0 || hinge.len() < 2 || beyond.len() < 2 {
            continue;
        }
        let x = rest[v].x;
        let ([a, b], f) = bracket(rest, hinge, x);
        let h = pos[a].lerp(&pos[b], f);
        let t = Unit::new_normalize(rest[b] - rest[a]);
        let n = normals[a].lerp(&normals[b], f);
        let ([c, e], g) = bracket(rest, beyond, x);
        let far = pos[c].lerp(&pos[e], g);
        // The plane across the hinge: `e_a` toward the far skin, `e_b` into the surface.
        let flat = |u: Vector3<f64>| u - t.into_inner() * u.dot(&t);
        let e_a = flat(far - h).normalize();
        let e_b = flat(-n - e_a * (-n).dot(&e_a)).normalize();
        let d = pos[v] - h;
        let (dt, dp) = (t.into_inner() * d.dot(&t), flat(d));
        let mut from = dp.dot(&e_b).atan2(dp.dot(&e_a));
        if from < behind {
            from += std::f64::consts::TAU;
        }
        let to = from + (behind - from) * w;
        pos[v] = h + dt + (e_a * to.cos() + e_b * to.sin()) * dp.norm();
    }
}

/// The mouth's margin rows: (vertex, lateral weight) of the upper lip's slit row, or the
/// lower lip's when `lower`.
fn lip_margin(head: &AvatarHead, lower: bool) -> Vec<(usize, f64)> {
    (0..head.mesh.positions.len())
        .filter(|&v| {
            let b = head.base[v];
            head.ring_of[v] == head.mouth_ring
                && (head.copy[v] == SlitCopy::Lip) == lower
                && b.z > 0.0
                && b.x.abs() < MOUTH_HALF_WIDTH
        })
        .map(|v| (v, lip_plateau(head.base[v].x)))
        .collect()
}

/// Both lips pressed together (the whole press; see the module notes).
pub fn press(head: &AvatarHead) -> Vec<Vector3<f64>> {
    let rest = &head.mesh.positions;
    let mut pos = rest.clone();
    for (v, p) in pos.iter_mut().enumerate() {
        let b = head.base[v];
        let w = lip_plateau(b.x) * front_mask(&rest[v]);
        if w == 0.0 {
            continue;
        }
        let (upper, _) = head.row(v, head.mouth_ring, SlitCopy::Lip);
        let g = 1.0 - smoothstep(LIP_ROW, LIP_ROW + 0.01, (b.y - MOUTH_Y).abs());
        let dir = if upper { -1.0 } else { 1.0 };
        p.y += dir * (LIP_ROW - GAP_HALF) * w * g;
    }
    let m = head.mouth_ring;
    for (lower, hinge, beyond) in [(false, m - 1, m - 2), (true, m + 1, m + 2)] {
        let row = |r: usize| head.front_row(r, SlitCopy::None);
        tuck(
            head,
            &mut pos,
            &row(hinge),
            &row(beyond),
            &lip_margin(head, lower),
        );
    }
    pos.iter().zip(rest).map(|(p, r)| p - r).collect()
}

/// One lip's red rolled in over itself (the upper lip's, or the lower's when `lower`).
pub fn roll(head: &AvatarHead, lower: bool) -> Vec<Vector3<f64>> {
    let rest = &head.mesh.positions;
    let mut pos = rest.clone();
    let mut movers = Vec::new();
    for (v, p) in pos.iter_mut().enumerate() {
        let b = head.base[v];
        let (upper, row) = head.row(v, head.mouth_ring, SlitCopy::Lip);
        let w = lip_plateau(b.x) * front_mask(&rest[v]);
        if upper == lower || w == 0.0 {
            continue;
        }
        let g = 1.0 - smoothstep(2.0 * LIP_ROW, 2.0 * LIP_ROW + 0.014, (b.y - MOUTH_Y).abs());
        let dir = if upper { -1.0 } else { 1.0 };
        p.y += dir * (2.0 * LIP_ROW - GAP_HALF) * w * g;
        if row < 2 && b.x.abs() < MOUTH_HALF_WIDTH {
            movers.push((v, w));
        }
    }
    let (m, row) = (head.mouth_ring, |r: usize| {
        head.front_row(r, SlitCopy::None)
    });
    let (hinge, beyond) = if lower {
        (m + 2, m + 3)
    } else {
        (m - 2, m - 3)
    };
    tuck(head, &mut pos, &row(hinge), &row(beyond), &movers);
    pos.iter().zip(rest).map(|(p, r)| p - r).collect()
}

/// The lids of the eye on side `sx` (+1 left, −1 right) closed and pressed together.
pub fn blink(head: &AvatarHead, sx: f64) -> Vec<Vector3<f64>> {
    let rest = &head.mesh.positions;
    let c = head.eyes[if sx > 0.0 { 0 } else { 1 }];
    let mut pos = rest.clone();
    let mut movers = [Vec::new(), Vec::new()];
    for (v, p) in pos.iter_mut().enumerate() {
        let b = head.base[v];
        let x_rel = sx * b.x - EYE.0;
        let (lens, q) = (lid_lens(x_rel), lid_plateau(x_rel));
        if b.z <= 0.0 || sx * b.x <= 0.0 || lens == 0.0 {
            continue;
        }
        let (upper, row) = head.row(v, head.eye_ring, SlitCopy::Lid);
        let press = (LID_ROW - GAP_HALF) * q;
        let dy = if upper {
            -((LID_UP + BLINK_DROP) * lens + press)
        } else {
            (LID_DOWN - BLINK_DROP) * lens + press
        } * lid_fall((b.y - EYE.1).abs());
        // Slide over the eyeball: turn about the x axis through its centre to the new height.
        let r = *p - c;
        let rho = r.y.hypot(r.z);
        let beta = ((r.y + dy) / rho).clamp(-1.0, 1.0).asin();
        *p = c + Vector3::new(r.x, rho * beta.sin(), rho * beta.cos() * r.z.signum());
        if row == 0 {
            movers[usize::from(!upper)].push((v, q));
        }
    }
    let e = head.eye_ring;
    let row = |r: usize| {
        let mut row = head.front_row(r, SlitCopy::None);
        row.retain(|&v| sx * head.base[v].x > 0.0);
        row
    };
    for (k, (hinge, beyond)) in [(e - 1, e - 2), (e + 1, e + 2)].into_iter().enumerate() {
        tuck(head, &mut pos, &row(hinge), &row(beyond), &movers[k]);
    }
    pos.iter().zip(rest).map(|(p, r)| p - r).collect()
}

/// Jaw weight of head vertex `v` (sample `s`): the capture head's ramp below the mouth
/// (whole 3 cm below it, rising toward the cheeks beyond the corners) and, on the lower lip's
/// side of the slit, the rest of the way to 1 by a lens across the mouth (1 in the middle, 0
/// at the corners), so the whole lower lip moves as one with its margin.
pub fn jaw_weight(head: &AvatarHead, v: usize, s: &Sample) -> f64 {
    let (m_y, corner) = (head.mouth_y, head.corner_x);
    let ax = s.pos.x.abs();
    let top = m_y + 0.025 * smoothstep(corner, corner + 0.025, ax);
    let below = smoothstep(top, m_y - 0.03, s.pos.y) * window(ax, 0.05, 0.025);
    if !s.lower {
        return below;
    }
    let r = head.base[v].x / corner;
    let lens = if r.abs() < 1.0 {
        (1.0 - r * r).powi(2)
    } else {
        0.0
    };
    below + (1.0 - below) * lens
}

/// The mask of the jaw's shapes at `p` (m): 0 behind z = 5 mm (as [`front_mask`]) and fading
/// from the chin (y = −65 mm) down to the neck's open end (y = −115 mm), so the jaw pulls the
/// skin under the chin back and the throat with it rather than pushing it into the neck.
pub fn jaw_mask(p: &Vector3<f64>) -> f64 {
    smoothstep(0.005, 0.035, p.z) * smoothstep(-0.115, -0.065, p.y)
}

/// The jaw's shapes with [`jaw_weight`], by name; `None` for the other shapes.
fn jaw_shape(name: &str, head: &AvatarHead, samples: &[Sample]) -> Option<Vec<Vector3<f64>>> {
    let pivot = Vector3::new(0.0, JAW_PIVOT_YZ.0, JAW_PIVOT_YZ.1);
    let rotate = |p: &Vector3<f64>, angle: f64| {
        let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), angle);
        rot * (p - pivot) - (p - pivot)
    };
    let field = |v: usize, s: &Sample| -> Vector3<f64> {
        let w = jaw_weight(head, v, s);
        let lip = if s.lower {
            bump((s.pos.x / 0.032).hypot((s.pos.y - head.mouth_y) / 0.014))
        } else {
            0.0
        };
        match name {
            "jawOpen" => rotate(&s.pos, JAW_ANGLE) * w,
            "jawForward" => Vector3::z() * (JAW_FORWARD * w),
            "jawLeft" => Vector3::x() * (JAW_SIDE * w),
            "jawRight" => Vector3::x() * (-JAW_SIDE * w),
            _ => rotate(&s.pos, 0.3 * JAW_ANGLE) * w + (s.n * 0.003 - s.e_v * 0.002) * lip,
        }
    };
    let known = ["jawOpen", "jawForward", "jawLeft", "jawRight", "tongueOut"];
    known.contains(&name).then(|| {
        samples
            .iter()
            .enumerate()
            .map(|(v, s)| field(v, s) * jaw_mask(&s.pos))
            .collect()
    })
}

/// Every shape of the head in [`target_names`] order: position deltas (m).
pub fn head_shapes(head: &AvatarHead) -> Shapes {
    let normals = head.mesh.vertex_normals();
    let samples: Vec<Sample> = head
        .mesh
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
                lower: head.copy[v] == SlitCopy::Lip || head.ring_of[v] > head.mouth_ring,
            }
        })
        .collect();
    let mut shapes = shape_deltas(&samples, head.mouth_y, head.corner_x);
    let full = press(head);
    let split = |left: bool| -> Vec<Vector3<f64>> {
        full.iter()
            .zip(&head.base)
            .map(|(d, b)| {
                let s = smoothstep(-0.004, 0.004, b.x);
                d * if left { s } else { 1.0 - s }
            })
            .collect()
    };
    for (name, d) in shapes.iter_mut() {
        match name.as_str() {
            "eyeBlinkLeft" => *d = blink(head, 1.0),
            "eyeBlinkRight" => *d = blink(head, -1.0),
            "mouthPressLeft" => *d = split(true),
            "mouthPressRight" => *d = split(false),
            "mouthRollLower" => *d = roll(head, true),
            "mouthRollUpper" => *d = roll(head, false),
            _ => {
                if let Some(j) = jaw_shape(name, head, &samples) {
                    *d = j;
                }
            }
        }
    }
    let v = visemes(&shapes);
    shapes.extend(v);
    shapes
}

#[cfg(test)]
mod tests {
    use super::super::avatar_head::generate;
    use super::*;

    /// At the middle of the mouth the press brings the lips' hinge rows together at the slit
    /// (0.4 mm apart) and lays each margin strip in behind its own lip.
    #[test]
    fn the_press_meets_the_lips_and_tucks_their_margins_behind() {
        let head = generate();
        let d = press(&head);
        let at_middle = |ring: usize, copy: SlitCopy| {
            let v = *head
                .front_row(ring, copy)
                .iter()
                .min_by(|&&a, &&b| head.base[a].x.abs().total_cmp(&head.base[b].x.abs()))
                .expect("a front row");
            head.mesh.positions[v] + d[v]
        };
        let m = head.mouth_ring;
        let (h_u, h_l) = (
            at_middle(m - 1, SlitCopy::None),
            at_middle(m + 1, SlitCopy::None),
        );
        let (m_u, m_l) = (at_middle(m, SlitCopy::None), at_middle(m, SlitCopy::Lip));
        assert!((h_u.y - h_l.y - 2.0 * GAP_HALF).abs() < 2e-4, "{h_u} {h_l}");
        assert!(m_u.y > h_u.y + 1e-3 && m_u.z < h_u.z - 5e-4, "{m_u} {h_u}");
        assert!(m_l.y < h_l.y - 1e-3 && m_l.z < h_l.z - 5e-4, "{m_l} {h_l}");
    }

    /// Every shape is there, in order, with a delta per vertex; the left press and the right
    /// add up to viseme_PP.
    #[test]
    fn the_head_has_every_shape_and_the_presses_add_up_to_pp() {
        let head = generate();
        let shapes = head_shapes(&head);
        let names: Vec<&str> = shapes.iter().map(|s| s.0.as_str()).collect();
        assert_eq!(names, target_names());
        let n = head.mesh.positions.len();
        assert!(shapes.iter().all(|s| s.1.len() == n));
        let get = |name: &str| &shapes.iter().find(|s| s.0 == name).expect("shape").1;
        let (l, r, pp) = (
            get("mouthPressLeft"),
            get("mouthPressRight"),
            get("viseme_PP"),
        );
        for v in 0..n {
            assert!((l[v] + r[v] - pp[v]).norm() < 1e-12);
        }
    }
}
