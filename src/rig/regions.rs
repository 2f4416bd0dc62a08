//! Named vertex regions of the face mask (for tests, masks and reports).
//!
//! Regions are boxes or ellipses in the base coordinates `(x, y)` of [`super::surface`] (m,
//! +X is the subject's left). The lips are split by the side of the mouth slit, so `upper_lip`
//! and `lower_lip` are disjoint even though they touch along the slit.

use super::surface::{Mask, Sample, Side, EYE_X};

/// Names of the regions, in the order [`regions`] returns them.
pub const REGION_NAMES: [&str; 14] = [
    "upper_lip",
    "lower_lip",
    "forehead",
    "glabella",
    "crow_left",
    "crow_right",
    "nose_bridge",
    "nasolabial_left",
    "nasolabial_right",
    "chin",
    "mouth_slit_upper",
    "mouth_slit_lower",
    "mouth_corners",
    "rim",
];

/// Whether `s` lies in region `name` (geometric regions only).
fn contains(name: &str, s: &Sample, mask: &Mask) -> bool {
    let (x, y, ax) = (s.x, s.y, s.x.abs());
    let my = mask.mouth_y;
    let lip_x = ax < mask.corner_x;
    match name {
        "upper_lip" => s.side == Side::Upper && lip_x && y >= my && y <= my + 0.013,
        "lower_lip" => s.side == Side::Lower && lip_x && y <= my && y >= my - 0.013,
        "forehead" => ax < 0.04 && (0.05..=0.088).contains(&y),
        "glabella" => ax < 0.01 && (0.026..=0.05).contains(&y),
        "crow_left" => (EYE_X + 0.019..=EYE_X + 0.035).contains(&x) && (0.006..=0.028).contains(&y),
        "crow_right" => {
            (EYE_X + 0.019..=EYE_X + 0.035).contains(&-x) && (0.006..=0.028).contains(&y)
        }
        "nose_bridge" => ax < 0.007 && (0.0..=0.022).contains(&y),
        "nasolabial_left" => (x - 0.031).hypot(y - my - 0.017) < 0.009,
        "nasolabial_right" => (x + 0.031).hypot(y - my - 0.017) < 0.009,
        "chin" => ax < 0.02 && (-0.095..=-0.07).contains(&y),
        _ => false,
    }
}

/// All named regions as sorted vertex index lists. The slit lists are paired (same order, by
/// increasing x); `mouth_corners` is `[−x corner, +x corner]`; `rim` is the outer boundary.
pub fn regions(mask: &Mask) -> Vec<(String, Vec<usize>)> {
    REGION_NAMES
        .iter()
        .map(|&name| {
            let v = match name {
                "mouth_slit_upper" => mask.slit_upper.clone(),
                "mouth_slit_lower" => mask.slit_lower.clone(),
                "mouth_corners" => mask.corners.to_vec(),
                "rim" => {
                    let mut r = mask.rim.clone();
                    r.sort_unstable();
                    r
                }
                _ => (0..mask.samples.len())
                    .filter(|&v| contains(name, &mask.samples[v], mask))
                    .collect(),
            };
            (name.to_string(), v)
        })
        .collect()
}
