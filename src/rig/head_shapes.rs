//! The 52 ARKit blend shapes of the head rig ([`super::head`]): smooth, compactly supported
//! displacement fields (mm to cm) on the front of the face.
//!
//! Each field is written in the local frame of the neutral surface (`e_u` ≈ +X and `e_v` ≈ +Y
//! along the skin, `n` outward) as a function of the vertex's position, except the jaw's,
//! which rotate or translate the lower face. "Left" is the subject's left (+X); each right
//! shape is its left one evaluated at −x with the lateral motion mirrored. Every field is
//! multiplied by a mask that is exactly 0 behind z = 5 mm (the back of the head and the ears)
//! and below y = −0.105 m (the neck), so those vertices never move.
//!
//! Brows up compress the forehead vertically, brows down the glabella; smiles push the mouth
//! corners up and out toward the cheekbones and the cheeks up; squints draw the skin toward
//! the eye's horizontal line (crow's feet); the jaw opens by rotating the lower face 14°.

use nalgebra::{Rotation3, Vector3};

use super::surface::{bump, smoothstep, window};

/// Centre of the left eye (x, y), m; the right eye is its mirror image.
pub const EYE: (f64, f64) = (0.032, 0.022);

/// The 52 ARKit blend-shape names, in ARKit's order (the order of [`shape_deltas`]).
pub const ARKIT_NAMES: [&str; 52] = [
    "eyeBlinkLeft",
    "eyeLookDownLeft",
    "eyeLookInLeft",
    "eyeLookOutLeft",
    "eyeLookUpLeft",
    "eyeSquintLeft",
    "eyeWideLeft",
    "eyeBlinkRight",
    "eyeLookDownRight",
    "eyeLookInRight",
    "eyeLookOutRight",
    "eyeLookUpRight",
    "eyeSquintRight",
    "eyeWideRight",
    "jawForward",
    "jawLeft",
    "jawRight",
    "jawOpen",
    "mouthClose",
    "mouthFunnel",
    "mouthPucker",
    "mouthLeft",
    "mouthRight",
    "mouthSmileLeft",
    "mouthSmileRight",
    "mouthFrownLeft",
    "mouthFrownRight",
    "mouthDimpleLeft",
    "mouthDimpleRight",
    "mouthStretchLeft",
    "mouthStretchRight",
    "mouthRollLower",
    "mouthRollUpper",
    "mouthShrugLower",
    "mouthShrugUpper",
    "mouthPressLeft",
    "mouthPressRight",
    "mouthLowerDownLeft",
    "mouthLowerDownRight",
    "mouthUpperUpLeft",
    "mouthUpperUpRight",
    "browDownLeft",
    "browDownRight",
    "browInnerUp",
    "browOuterUpLeft",
    "browOuterUpRight",
    "cheekPuff",
    "cheekSquintLeft",
    "cheekSquintRight",
    "noseSneerLeft",
    "noseSneerRight",
    "tongueOut",
];

/// Jaw opening angle at weight 1, rad (14°).
pub const JAW_ANGLE: f64 = 14.0 * std::f64::consts::PI / 180.0;
/// Jaw rotation axis: parallel to X through this point (y, z), m (in front of the ears).
pub const JAW_PIVOT_YZ: (f64, f64) = (0.0, -0.005);
/// Forward travel of the jaw at `jawForward` weight 1, m.
pub const JAW_FORWARD: f64 = 0.006;
/// Sideways travel of the jaw at `jawLeft` or `jawRight` weight 1, m.
pub const JAW_SIDE: f64 = 0.007;

/// A vertex of the neutral head as the shapes see it.
#[derive(Debug, Clone, Copy)]
pub struct Sample {
    /// Position, m.
    pub pos: Vector3<f64>,
    /// Unit outward normal.
    pub n: Vector3<f64>,
    /// Unit tangent ≈ +X along the skin.
    pub e_u: Vector3<f64>,
    /// Unit tangent ≈ +Y along the skin.
    pub e_v: Vector3<f64>,
    /// Whether the vertex is below the mouth slit (the lower lip's copies included).
    pub lower: bool,
}

/// Where the mouth is: slit height and corner half-width, m.
#[derive(Debug, Clone, Copy)]
struct Mouth {
    y: f64,
    corner: f64,
}

/// A sample seen from one side: `m` = +1 for a left shape, −1 for a right one; `x` is the
/// mirrored lateral coordinate (positive on the shape's side).
struct Side<'a> {
    s: &'a Sample,
    m: f64,
    x: f64,
    y: f64,
}

impl Side<'_> {
    /// Displacement `du` (toward the shape's side), `dv` (up), `dn` (out), m.
    fn local(&self, du: f64, dv: f64, dn: f64) -> Vector3<f64> {
        self.s.e_u * (du * self.m) + self.s.e_v * dv + self.s.n * dn
    }
}

/// Distance to the eye of the side, scaled by (rx, ry).
fn eye_r(q: &Side, dy: f64, rx: f64, ry: f64) -> f64 {
    ((q.x - EYE.0) / rx).hypot((q.y - EYE.1 - dy) / ry)
}

/// Upper lid down over the eye, lower lid up a little.
fn blink(q: &Side) -> Vector3<f64> {
    let upper = bump(eye_r(q, 0.004, 0.02, 0.011));
    let lower = bump(eye_r(q, -0.008, 0.016, 0.007));
    q.local(0.0, -0.007 * upper + 0.002 * lower, 0.0)
}

/// Lids following the gaze: (du, dv) at the eye.
fn look(q: &Side, du: f64, dv: f64) -> Vector3<f64> {
    let w = bump(eye_r(q, 0.0, 0.02, 0.016));
    q.local(du * w, dv * w, 0.0)
}

/// Skin drawn toward the eye's horizontal line at the outer corner (crow's feet), cheek up.
fn eye_squint(q: &Side) -> Vector3<f64> {
    let t = (q.y - (EYE.1 - 0.001)) / 0.011;
    let wx = bump((q.x - (EYE.0 + 0.017)) / 0.03);
    let cheek = bump(((q.x - EYE.0 - 0.005) / 0.022).hypot((q.y - EYE.1 + 0.028) / 0.016));
    q.local(
        0.0,
        -0.0025 * t * (-0.5 * t * t).exp() * wx + 0.002 * cheek,
        0.0015 * cheek,
    )
}

/// Upper lid and the skin below the brow up.
fn eye_wide(q: &Side) -> Vector3<f64> {
    q.local(0.0, 0.003 * bump(eye_r(q, 0.007, 0.022, 0.013)), 0.0)
}

/// Vertical brow raise profile at height `y`: rises over the brow, falls to the hairline.
fn brow_lift(y: f64) -> f64 {
    if y < 0.037 {
        smoothstep(0.014, 0.037, y)
    } else {
        1.0 - 0.92 * smoothstep(0.037, 0.095, y)
    }
}

/// Frontalis, medial part: inner brows up 7 mm, forehead compressed toward the hairline.
fn brow_inner_up(s: &Sample) -> Vector3<f64> {
    let w = window(s.pos.x.abs(), 0.012, 0.025);
    s.e_v * (0.007 * brow_lift(s.pos.y) * w)
}

/// Frontalis, lateral part: the outer brow of the side up 6 mm.
fn brow_outer_up(q: &Side) -> Vector3<f64> {
    let w = bump((q.x - 0.042) / 0.03);
    q.local(0.0, 0.006 * brow_lift(q.y) * w, 0.0)
}

/// Corrugator and depressor supercilii: brow down 4 mm and toward the midline 2 mm; the
/// glabella compressed.
fn brow_down(q: &Side) -> Vector3<f64> {
    let w = bump(((q.x - 0.02) / 0.032).hypot((q.y - 0.04) / 0.018));
    q.local(-0.002 * w, -0.004 * w, 0.0005 * w)
}

/// Jaw weight of a vertex: 1 on the jaw below the mouth, fading over 3 cm; the lower lip's
/// slit copies get a lens profile (1 at the centre, 0 at the corners).
fn jaw_weight(s: &Sample, m: &Mouth) -> f64 {
    let ax = s.pos.x.abs();
    let top = m.y + 0.025 * smoothstep(m.corner, m.corner + 0.025, ax);
    let below = smoothstep(top, m.y - 0.03, s.pos.y) * window(ax, 0.05, 0.025);
    if !s.lower || s.pos.y > m.y + 0.001 {
        return below;
    }
    let r = s.pos.x / m.corner;
    let lens = if r.abs() < 1.0 {
        (1.0 - r * r).powi(2)
    } else {
        0.0
    };
    below + (1.0 - below) * lens
}

/// The lower face rotated by `angle` (rad) about the jaw axis, weighted.
fn jaw_rotate(s: &Sample, m: &Mouth, angle: f64) -> Vector3<f64> {
    let w = jaw_weight(s, m);
    if w == 0.0 {
        return Vector3::zeros();
    }
    let pivot = Vector3::new(0.0, JAW_PIVOT_YZ.0, JAW_PIVOT_YZ.1);
    let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), angle);
    let r = s.pos - pivot;
    (rot * r - r) * w
}

/// Lip weight around the mouth: 1 on the lips, 0 beyond 3 cm across and 1.4 cm up or down.
fn lips(s: &Sample, m: &Mouth) -> f64 {
    bump((s.pos.x / 0.032).hypot((s.pos.y - m.y) / 0.014))
}

/// Upper (`up` true) or lower lip weight.
fn lip(s: &Sample, m: &Mouth, up: bool) -> f64 {
    if s.lower == up {
        0.0
    } else {
        lips(s, m)
    }
}

/// Orbicularis oris: lips toward the mouth centre (up to 35 %) and 7 mm forward.
fn pucker(s: &Sample, m: &Mouth) -> Vector3<f64> {
    let (dx, dy) = (s.pos.x, s.pos.y - m.y);
    let rho = dx.hypot(1.5 * dy) / 0.055;
    if rho >= 1.0 {
        return Vector3::zeros();
    }
    let k = 0.35 * (1.0 - rho * rho).powi(2);
    s.e_u * (-k * dx) + s.e_v * (-0.5 * k * dy) + Vector3::z() * (0.007 * bump(rho))
}

/// Lips forward 6 mm and apart vertically (the funnel's opening), corners in a little.
fn funnel(s: &Sample, m: &Mouth) -> Vector3<f64> {
    let w = lips(s, m);
    let dv = if s.lower { -0.002 } else { 0.002 } * w;
    s.e_u * (-0.1 * s.pos.x * w) + s.e_v * dv + Vector3::z() * (0.006 * w)
}

/// The mouth corner of the side moved by (du, dv, dn), fading over `r` m.
fn corner(q: &Side, m: &Mouth, r: f64, d: (f64, f64, f64)) -> Vector3<f64> {
    let w = bump((q.x - m.corner).hypot(q.y - m.y) / r);
    q.local(d.0 * w, d.1 * w, d.2 * w)
}

/// Zygomaticus major: corner up and out toward the cheekbone (9 mm), nasolabial region
/// compressed along the pull, the cheek pushed up and out.
fn smile(q: &Side, m: &Mouth) -> Vector3<f64> {
    let (px, py) = (0.42, 0.907_524_104_304_180_7);
    let (dx, dy) = (q.x - m.corner, q.y - m.y);
    let along = dx * px + dy * py;
    let across = -dx * py + dy * px;
    let f = if along >= 0.0 {
        1.0 - smoothstep(0.0, 0.05, along)
    } else {
        smoothstep(-0.045, -0.008, along)
    };
    let a = 0.009 * f * bump(across / 0.028);
    let cheek = bump((q.x - 0.042).hypot(q.y + 0.012) / 0.025);
    q.local(a * px, a * py + 0.003 * cheek, 0.003 * cheek)
}

/// Depressor anguli oris: corner down 5 mm and out 1 mm; skin below the corner compressed.
fn frown(q: &Side, m: &Mouth) -> Vector3<f64> {
    corner(q, m, 0.03, (0.001, -0.005, 0.0))
}

/// The cheek under the eye of the side pushed up 3 mm (the under-eye skin compressed).
fn cheek_squint(q: &Side) -> Vector3<f64> {
    let w = bump(((q.x - 0.04) / 0.025).hypot((q.y + 0.002) / 0.02));
    q.local(0.0, 0.003 * w, 0.001 * w)
}

/// Levator labii superioris alaeque nasi: the side of the nose and the nostril up 4 mm, the
/// glabella down; the nose bridge compressed on that side.
fn nose_sneer(q: &Side) -> Vector3<f64> {
    let up = bump(((q.x - 0.012) / 0.016).hypot((q.y + 0.01) / 0.022));
    let glabella = bump((q.x / 0.015).hypot((q.y - 0.034) / 0.015));
    q.local(0.0, 0.004 * up - 0.0015 * glabella, 0.0)
}

/// Both cheeks blown out 8 mm.
fn cheek_puff(s: &Sample, m: &Mouth) -> Vector3<f64> {
    let w = bump(((s.pos.x.abs() - 0.038) / 0.028).hypot((s.pos.y - m.y - 0.008) / 0.025));
    s.n * (0.008 * w)
}

/// Left-side shapes (and their right mirrors) by name, for `q` on the shape's side.
fn sided(name: &str, q: &Side, m: &Mouth) -> Option<Vector3<f64>> {
    let base = name.strip_suffix("Left").or(name.strip_suffix("Right"))?;
    Some(match base {
        "eyeBlink" => blink(q),
        "eyeLookDown" => look(q, 0.0, -0.002),
        "eyeLookIn" => look(q, -0.0015, 0.0),
        "eyeLookOut" => look(q, 0.0015, 0.0),
        "eyeLookUp" => look(q, 0.0, 0.002),
        "eyeSquint" => eye_squint(q),
        "eyeWide" => eye_wide(q),
        "mouthSmile" => smile(q, m),
        "mouthFrown" => frown(q, m),
        "mouthDimple" => corner(q, m, 0.022, (0.004, 0.0, -0.002)),
        "mouthStretch" => corner(q, m, 0.035, (0.006, -0.004, 0.0)),
        "mouthPress" => {
            let w = bump((q.x - 0.012) / 0.025) * lips(q.s, m);
            q.local(
                0.0,
                if q.s.lower { 0.0015 } else { -0.0015 } * w,
                -0.001 * w,
            )
        }
        "mouthLowerDown" => {
            let w = bump((q.x - 0.01) / 0.03) * lip(q.s, m, false);
            q.local(0.0, -0.005 * w, 0.001 * w)
        }
        "mouthUpperUp" => {
            let w = bump((q.x - 0.01) / 0.03) * bump((q.s.pos.y - m.y - 0.006) / 0.02);
            q.local(0.0, 0.005 * w * f64::from(u8::from(!q.s.lower)), 0.0)
        }
        "browDown" => brow_down(q),
        "browOuterUp" => brow_outer_up(q),
        "cheekSquint" => cheek_squint(q),
        "noseSneer" => nose_sneer(q),
        "jaw" | "mouth" => return None,
        _ => return None,
    })
}

/// Shapes without a side, and the sideways jaw and mouth shifts.
fn central(name: &str, s: &Sample, m: &Mouth) -> Vector3<f64> {
    let jaw = || jaw_weight(s, m);
    let mouth_shift = || bump((s.pos.x / 0.045).hypot((s.pos.y - m.y) / 0.03));
    match name {
        "jawOpen" => jaw_rotate(s, m, JAW_ANGLE),
        "jawForward" => Vector3::z() * (JAW_FORWARD * jaw()),
        "jawLeft" => Vector3::x() * (JAW_SIDE * jaw()),
        "jawRight" => Vector3::x() * (-JAW_SIDE * jaw()),
        "mouthLeft" => Vector3::x() * (0.008 * mouth_shift()),
        "mouthRight" => Vector3::x() * (-0.008 * mouth_shift()),
        "mouthClose" => {
            let dv = if s.lower { 0.004 } else { -0.003 };
            s.e_v * (dv * lips(s, m))
        }
        "mouthFunnel" => funnel(s, m),
        "mouthPucker" => pucker(s, m),
        "mouthRollLower" => s.e_v * (0.002 * lip(s, m, false)) - s.n * (0.004 * lip(s, m, false)),
        "mouthRollUpper" => s.e_v * (-0.002 * lip(s, m, true)) - s.n * (0.004 * lip(s, m, true)),
        "mouthShrugLower" => {
            let w = bump((s.pos.x / 0.03).hypot((s.pos.y - m.y + 0.02) / 0.025));
            s.e_v * (0.004 * w * f64::from(u8::from(s.lower))) + s.n * (0.001 * w)
        }
        "mouthShrugUpper" => s.e_v * (0.003 * lip(s, m, true)),
        "browInnerUp" => brow_inner_up(s),
        "cheekPuff" => cheek_puff(s, m),
        "tongueOut" => {
            jaw_rotate(s, m, 0.3 * JAW_ANGLE) + (s.n * 0.003 - s.e_v * 0.002) * lip(s, m, false)
        }
        _ => Vector3::zeros(),
    }
}

/// The mask every shape is multiplied by: exactly 0 behind z = 5 mm and below y = −0.105 m.
pub fn front_mask(p: &Vector3<f64>) -> f64 {
    smoothstep(0.005, 0.035, p.z) * smoothstep(-0.105, -0.09, p.y)
}

/// Per-vertex deltas (m) of every shape in [`ARKIT_NAMES`] order, for the slit at height
/// `mouth_y` with corners at ±`corner_x` (m).
pub fn shape_deltas(
    samples: &[Sample],
    mouth_y: f64,
    corner_x: f64,
) -> Vec<(String, Vec<Vector3<f64>>)> {
    let m = Mouth {
        y: mouth_y,
        corner: corner_x,
    };
    ARKIT_NAMES
        .iter()
        .map(|&name| {
            let sign = if name.ends_with("Right") { -1.0 } else { 1.0 };
            let d = samples
                .iter()
                .map(|s| {
                    let mask = front_mask(&s.pos);
                    if mask == 0.0 {
                        return Vector3::zeros();
                    }
                    let q = Side {
                        s,
                        m: sign,
                        x: sign * s.pos.x,
                        y: s.pos.y,
                    };
                    sided(name, &q, &m).unwrap_or_else(|| central(name, s, &m)) * mask
                })
                .collect();
            (name.to_string(), d)
        })
        .collect()
}
