//! The jaw's hinge, fitted from the blend shape that opens it. Capture rigs have no skeleton:
//! their `jawOpen` (or `jaw_open`) shape carries the lower face round the jaw's axis, so the
//! vertices it moves rigidly give the hinge. A rigid fit (Kabsch) on the vertices it moves
//! most, refitted on those the rotation explains to 3 %, gives the rotation R and the translation t
//! at weight 1; the hinge is R's axis and angle through the point p on the axis with
//! (I − R) p = t.

use nalgebra::{Matrix3, Vector3};

type V = Vector3<f64>;

/// A vertex turns with the jaw when the rigid fit misses it by less than this fraction of its
/// displacement (dimensionless): vertices the jaw drags only partly (the cheeks) are left out.
const RIGID: f64 = 0.03;

/// Shape names that open the jaw (compared without case and underscores).
pub const JAW_SHAPES: [&str; 2] = ["jawopen", "jaw_open"];

/// A fitted jaw hinge.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct Hinge {
    /// The blend shape it was fitted from.
    pub shape: String,
    /// Unit axis of rotation (model space), oriented so the shape turns by +`angle_deg`.
    pub axis: [f64; 3],
    /// The point on the axis nearest the origin (m).
    pub pivot_m: [f64; 3],
    /// Opening angle at weight 1 (degrees): the largest a vertex turns by about the hinge.
    pub angle_deg: f64,
    /// Vertices the rigid rotation explains (within 3 % of their displacement).
    pub vertices: usize,
    /// RMS miss of the rotation over those vertices, relative to their RMS displacement.
    pub residual: f64,
}

/// Whether `name` is a jaw-opening shape.
pub fn is_jaw_shape(name: &str) -> bool {
    let n: String = name.to_lowercase().chars().filter(|c| *c != '_').collect();
    JAW_SHAPES.iter().any(|s| s.replace('_', "") == n)
}

/// The rigid motion (R, t) taking `from[i]` to `to[i]` over the indices `pick` in the least
/// squares sense (Kabsch).
fn rigid_fit(from: &[V], to: &[V], pick: &[usize]) -> (Matrix3<f64>, V) {
    let n = pick.len() as f64;
    let cf = pick.iter().map(|&i| from[i]).sum::<V>() / n;
    let ct = pick.iter().map(|&i| to[i]).sum::<V>() / n;
    let h: Matrix3<f64> = pick
        .iter()
        .map(|&i| (from[i] - cf) * (to[i] - ct).transpose())
        .sum();
    let svd = h.svd(true, true);
    let (u, vt) = (svd.u.unwrap_or_default(), svd.v_t.unwrap_or_default());
    let mut d = Matrix3::identity();
    d[(2, 2)] = (vt.transpose() * u.transpose()).determinant().signum();
    let r = vt.transpose() * d * u.transpose();
    (r, ct - r * cf)
}

/// Fit the hinge of shape `name` with offsets `delta` (m) from the rest positions `rest` (m);
/// None when the shape barely moves anything or no rotation explains it.
pub fn fit_hinge(name: &str, rest: &[V], delta: &[V]) -> Option<Hinge> {
    let norms: Vec<f64> = delta.iter().map(|d| d.norm()).collect();
    let max = norms.iter().cloned().fold(0.0, f64::max);
    if max <= 0.0 || max.is_nan() || rest.len() != delta.len() {
        return None;
    }
    let moved: Vec<V> = rest.iter().zip(delta).map(|(x, d)| x + d).collect();
    let mut pick: Vec<usize> = (0..rest.len()).filter(|&i| norms[i] > 0.5 * max).collect();
    let mut fit = None;
    for _ in 0..4 {
        if pick.len() < 3 {
            return None;
        }
        let (r, t) = rigid_fit(rest, &moved, &pick);
        let miss = |i: usize| (r * rest[i] + t - moved[i]).norm();
        let next: Vec<usize> = (0..rest.len())
            .filter(|&i| norms[i] > 0.1 * max && miss(i) < RIGID * norms[i])
            .collect();
        let done = next == pick;
        fit = Some((r, t));
        pick = next;
        if done {
            break;
        }
    }
    let (r, t) = fit?;
    if pick.len() < 3 {
        return None;
    }
    let mut h = hinge_of(name, &r, &t, (rest, &moved, &pick))?;
    h.angle_deg = full_angle(&h, rest, delta, 0.1 * max).to_degrees();
    Some(h)
}

/// The jaw's angle at weight 1 (rad): where a shape fades the jaw's motion out, its vertices
/// turn by a fraction of the angle about the same hinge, so the largest angle a vertex turns
/// by about the fitted hinge (among those that move by more than `floor` (m), keep their
/// distance to the axis and do not slide along it, to 3 %) is the jaw's.
fn full_angle(h: &Hinge, rest: &[V], delta: &[V], floor: f64) -> f64 {
    let a = V::from(h.axis);
    let p = V::from(h.pivot_m);
    let flat = |v: V| v - a * a.dot(&v);
    rest.iter()
        .zip(delta)
        .filter(|(_, d)| d.norm() > floor)
        .filter_map(|(x, d)| {
            let (u, w) = (flat(x - p), flat(x + d - p));
            let turning =
                (w.norm() - u.norm()).abs() < RIGID * d.norm() && a.dot(d).abs() < RIGID * d.norm();
            turning.then(|| u.cross(&w).dot(&a).atan2(u.dot(&w)))
        })
        .fold(h.angle_deg.to_radians(), f64::max)
}

/// The hinge (axis, angle, pivot) of the rigid motion x ↦ R x + t, with its fit statistics.
fn hinge_of(
    name: &str,
    r: &Matrix3<f64>,
    t: &V,
    (rest, moved, pick): (&[V], &[V], &[usize]),
) -> Option<Hinge> {
    let rot = nalgebra::Rotation3::from_matrix(r);
    let (axis, angle) = rot.axis_angle()?;
    let a = axis.into_inner();
    // (I − R) p = t on the plane through the origin perpendicular to the axis.
    let m = Matrix3::identity() - r + a * a.transpose();
    let p = m.try_inverse()? * t;
    let (mut miss2, mut disp2) = (0.0, 0.0);
    for &i in pick {
        miss2 += (r * rest[i] + t - moved[i]).norm_squared();
        disp2 += (moved[i] - rest[i]).norm_squared();
    }
    Some(Hinge {
        shape: name.to_string(),
        axis: [a.x, a.y, a.z],
        pivot_m: [p.x, p.y, p.z],
        angle_deg: angle.to_degrees(),
        vertices: pick.len(),
        residual: (miss2 / disp2.max(f64::MIN_POSITIVE)).sqrt(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Rotation3;

    #[test]
    fn a_rotated_block_with_a_fading_margin_gives_its_hinge() {
        let pivot = V::new(0.0, 0.01, -0.02);
        let rot = Rotation3::from_axis_angle(&V::x_axis(), 12f64.to_radians());
        let mut rest = Vec::new();
        let mut delta = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                let x = V::new(0.01 * i as f64 - 0.05, -0.01 * j as f64, 0.05);
                // Rows below y = −0.03 follow the jaw fully; above, the motion fades out.
                let w = ((-x.y) / 0.03).min(1.0);
                rest.push(x);
                delta.push((rot * (x - pivot) + pivot - x) * w);
            }
        }
        let h = fit_hinge("jawOpen", &rest, &delta).unwrap();
        assert!((h.angle_deg - 12.0).abs() < 1e-9, "{h:?}");
        assert!((h.axis[0].abs() - 1.0).abs() < 1e-12);
        // The pivot's y and z (x is free along the axis: the nearest point has x = 0).
        assert!((h.pivot_m[1] - 0.01).abs() < 1e-9 && (h.pivot_m[2] + 0.02).abs() < 1e-9);
        assert!(h.residual < 1e-9 && h.vertices == 70, "{h:?}");
        assert!(is_jaw_shape("jaw_open") && is_jaw_shape("jawOpen") && !is_jaw_shape("jawLeft"));
    }
}
