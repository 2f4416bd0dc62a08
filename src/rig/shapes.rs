//! The blend shapes: smooth, compactly supported displacement fields (mm to cm) that compress the
//! skin tangentially where real faces wrinkle.
//!
//! Each field is written per vertex in the local frame of the neutral surface (`e_u` ≈ +X,
//! `e_v` ≈ +Y along the skin, `n` outward), as functions of the base lateral coordinate `x` and
//! the height `y` (see [`super::surface`]), except `jaw_open`, which is a rotation of the lower
//! face. Right-side shapes are the exact mirror images (x → −x) of the left-side ones, built from
//! the mask's mirror map. "Left" is the subject's left, +X.
//!
//! | name | muscle (roughly) | motion | skin compressed |
//! |---|---|---|---|
//! | `brow_raise` | frontalis | brows up 8 mm, hairline fixed | forehead, vertically (horizontal lines) |
//! | `brow_frown` | corrugator | medial brows together 3 mm and down 2 mm | glabella, horizontally (vertical lines) |
//! | `squint_left/right` | orbicularis oculi | skin drawn toward the eye's horizontal line, cheek up | outer eye corner, vertically (crow's feet) |
//! | `nose_wrinkle` | nasalis, levator labii alaeque nasi, procerus | lower nose up 4 mm, glabella down | nose bridge, vertically |
//! | `smile_left/right` | zygomaticus major | mouth corner up and out 9 mm toward the cheekbone, cheek bulges | nasolabial region and cheek, along the pull |
//! | `jaw_open` | jaw depressors | lower face rotates 10° about a jaw axis; lower lip leaves the upper lip | (none: the lips part) |
//! | `pucker` | orbicularis oris | lips drawn toward the mouth centre (up to 35 %) and 7 mm forward | lips, around the mouth |

use nalgebra::{Rotation3, Vector3};

use super::surface::{bump, smoothstep, window, Mask, Sample, Side, EYE_X, EYE_Y};

/// Names of the blend shapes, in the order [`shape_deltas`] returns them.
pub const SHAPE_NAMES: [&str; 9] = [
    "brow_raise",
    "brow_frown",
    "squint_left",
    "squint_right",
    "nose_wrinkle",
    "smile_left",
    "smile_right",
    "jaw_open",
    "pucker",
];

/// Jaw opening angle at weight 1, rad (10°).
pub const JAW_ANGLE: f64 = 10.0 * std::f64::consts::PI / 180.0;
/// Jaw rotation axis: parallel to X through this point (y, z), m (in front of the ears).
pub const JAW_PIVOT_YZ: (f64, f64) = (0.005, -0.005);

/// Displacement `du e_u + dv e_v + dn n` in the local frame of `s`, m.
fn local(s: &Sample, du: f64, dv: f64, dn: f64) -> Vector3<f64> {
    s.e_u * du + s.e_v * dv + s.n * dn
}

/// Frontalis: brows up, forehead compressed vertically toward the fixed hairline.
fn brow_raise(s: &Sample) -> Vector3<f64> {
    let y = s.y;
    let f = if y < 0.037 {
        smoothstep(0.012, 0.037, y)
    } else {
        1.0 - 0.92 * smoothstep(0.037, 0.097, y)
    };
    local(s, 0.0, 0.008 * f * window(s.x.abs(), 0.05, 0.025), 0.0)
}

/// Corrugator: medial brows pulled together and down; glabella compressed horizontally.
fn brow_frown(s: &Sample) -> Vector3<f64> {
    let (x, y) = (s.x, s.y);
    let gy = bump((y - 0.038) / 0.03);
    let q = x / 0.011;
    let du = -0.003 * q * (-0.5 * q * q).exp() * gy;
    let dv = -0.002 * bump((y - 0.036) / 0.025) * window(x.abs(), 0.02, 0.025);
    let dn = 0.001 * gy * (-0.5 * q * q).exp();
    local(s, du, dv, dn)
}

/// Orbicularis oculi, left eye: skin drawn vertically toward the eye's horizontal line at the
/// outer corner (crow's feet), cheek pushed up under the eye.
fn squint_left(s: &Sample) -> Vector3<f64> {
    let (x, y) = (s.x, s.y);
    let q = (y - (EYE_Y - 0.001)) / 0.011;
    let wx = bump((x - (EYE_X + 0.017)) / 0.03);
    let mut dv = -0.0025 * q * (-0.5 * q * q).exp() * wx;
    let cheek = bump(((x - EYE_X - 0.005) / 0.022).hypot((y + 0.006) / 0.016));
    dv += 0.002 * cheek;
    local(s, 0.0, dv, 0.0015 * cheek)
}

/// Nasalis, levator labii superioris alaeque nasi, procerus: lower nose up, glabella down;
/// nose bridge compressed vertically.
fn nose_wrinkle(s: &Sample, mouth_y: f64) -> Vector3<f64> {
    let (ax, y) = (s.x.abs(), s.y);
    let up = smoothstep(0.03, -0.012, y) * (1.0 - smoothstep(-0.028, mouth_y + 0.003, y));
    let mut dv = 0.004 * up * window(ax, 0.02, 0.018);
    dv -= 0.0015 * bump((y - 0.036) / 0.018) * window(ax, 0.012, 0.02);
    local(s, 0.0, dv, 0.0)
}

/// Unit pull direction of the left smile in (x, y): from the mouth corner toward the cheekbone.
pub const SMILE_PULL: (f64, f64) = (0.42, 0.907_524_104_304_180_7);

/// Zygomaticus major, left: mouth corner pulled up and out toward the cheekbone; the
/// nasolabial region and cheek compressed along the pull; the cheek bulges.
fn smile_left(s: &Sample, mouth_y: f64, corner_x: f64) -> Vector3<f64> {
    let (px, py) = SMILE_PULL;
    let (dx, dy) = (s.x - corner_x, s.y - mouth_y);
    let along = dx * px + dy * py;
    let across = -dx * py + dy * px;
    let f = if along >= 0.0 {
        1.0 - smoothstep(0.0, 0.05, along)
    } else {
        smoothstep(-0.045, -0.008, along)
    };
    let a = 0.009 * f * bump(across / 0.028);
    let cheek = bump((s.x - 0.04).hypot(s.y + 0.018) / 0.025);
    local(s, a * px, a * py, 0.003 * cheek)
}

/// Jaw opening weight of a vertex: 1 on the jaw, 0 on the upper lip and above the cheeks, and
/// across the slit a lens profile that is 1 at the mouth centre and 0 at the corners.
fn jaw_weight(s: &Sample, mouth_y: f64, corner_x: f64) -> f64 {
    // The jaw's influence fades over 3 cm below the mouth line and, beside the mouth corners,
    // reaches up to 2.5 cm above it (the cheeks follow the jaw partly), so the stretch spreads.
    let top = mouth_y + 0.025 * smoothstep(corner_x, corner_x + 0.025, s.x.abs());
    let below = smoothstep(top, mouth_y - 0.03, s.y);
    if s.side == Side::Upper || s.y > mouth_y {
        return below;
    }
    let r = s.x / corner_x;
    let lens = if r.abs() < 1.0 {
        (1.0 - r * r).powi(2)
    } else {
        0.0
    };
    below + (1.0 - below) * lens
}

/// Jaw depressors: the lower face rotates by [`JAW_ANGLE`] about the jaw axis; the lower lip
/// leaves the upper lip (the slit opens, most at the centre, not at the corners).
fn jaw_open(s: &Sample, mouth_y: f64, corner_x: f64) -> Vector3<f64> {
    let w = jaw_weight(s, mouth_y, corner_x);
    if w == 0.0 {
        return Vector3::zeros();
    }
    let pivot = Vector3::new(0.0, JAW_PIVOT_YZ.0, JAW_PIVOT_YZ.1);
    let rot = Rotation3::from_axis_angle(&Vector3::x_axis(), JAW_ANGLE);
    let r = s.pos - pivot;
    (rot * r - r) * w
}

/// Orbicularis oris: contraction toward the mouth centre (circumferential compression of the
/// lips, up to 35 %; vertical pull at half that rate) and a forward push of the lips.
fn pucker(s: &Sample, mouth_y: f64) -> Vector3<f64> {
    let (dx, dy) = (s.x, s.y - mouth_y);
    let rho = dx.hypot(1.5 * dy) / 0.06;
    if rho >= 1.0 {
        return Vector3::zeros();
    }
    let k = 0.35 * (1.0 - rho * rho).powi(2);
    // The forward push is a translation along +Z (not along the normal): pushing a strongly
    // curved lip along its normal would stretch it and cancel the contraction.
    local(s, -k * dx, -0.5 * k * dy, 0.0) + Vector3::z() * (0.007 * bump(rho))
}

/// Per-vertex deltas (m) of every shape in [`SHAPE_NAMES`] order.
pub fn shape_deltas(mask: &Mask) -> Vec<(String, Vec<Vector3<f64>>)> {
    let (my, cx) = (mask.mouth_y, mask.corner_x);
    let field = |f: &dyn Fn(&Sample) -> Vector3<f64>| -> Vec<Vector3<f64>> {
        mask.samples.iter().map(f).collect()
    };
    let mirrored = |left: &[Vector3<f64>]| -> Vec<Vector3<f64>> {
        mask.mirror
            .iter()
            .map(|&m| {
                let d = left[m];
                Vector3::new(-d.x, d.y, d.z)
            })
            .collect()
    };
    let squint_l = field(&squint_left);
    let smile_l = field(&|s| smile_left(s, my, cx));
    let mut out = Vec::with_capacity(SHAPE_NAMES.len());
    for name in SHAPE_NAMES {
        let d = match name {
            "brow_raise" => field(&brow_raise),
            "brow_frown" => field(&brow_frown),
            "squint_left" => squint_l.clone(),
            "squint_right" => mirrored(&squint_l),
            "nose_wrinkle" => field(&|s| nose_wrinkle(s, my)),
            "smile_left" => smile_l.clone(),
            "smile_right" => mirrored(&smile_l),
            "jaw_open" => field(&|s| jaw_open(s, my, cx)),
            _ => field(&|s| pucker(s, my)),
        };
        out.push((name.to_string(), d));
    }
    out
}
