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
    /// Bone (pinned) lattice nodes that turn with the jaw, when the muscles drive it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub bone_nodes: Option<usize>,
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
    fit_rigid(name, rest, delta).map(|(h, _)| h)
}

/// [`fit_hinge`], with the vertices the rotation explains (indices into `rest`).
fn fit_rigid(name: &str, rest: &[V], delta: &[V]) -> Option<(Hinge, Vec<usize>)> {
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
    Some((h, pick))
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
        bone_nodes: None,
    })
}

/// The jaw's bone: the bone (pinned) lattice nodes that turn with the jaw about its hinge,
/// so that the muscle of the shape that opens it turns them by its activation times the
/// shape's angle, and the flesh follows the bone instead of being pulled along.
#[derive(Debug, Clone, PartialEq)]
pub struct JawBone {
    /// The blend shape that opens the jaw (index into the rig's shapes).
    pub shape: usize,
    /// The pinned lattice nodes that turn with the jaw (sorted).
    pub nodes: Vec<usize>,
    /// Their rest positions (m).
    pub rest: Vec<V>,
    /// Unit axis of the hinge (model space).
    pub axis: V,
    /// A point on the hinge's axis (m).
    pub pivot: V,
    /// The jaw's angle at the shape's weight 1 (rad).
    pub angle: f64,
}

impl JawBone {
    /// The jaw's bone of a face whose welded vertices rest at `rest` (m) with blend shapes
    /// `targets` (offsets, m), embedded in `lattice`: the hinge of its first jaw-opening
    /// shape, and the pinned nodes whose nearest vertex at rest is one the hinge turns
    /// rigidly (bone under the chin and the lower teeth, not under the cheeks the jaw only
    /// drags). None without a jaw shape, a hinge, or a node that turns.
    pub fn find(
        lattice: &crate::lattice::Lattice,
        rest: &[V],
        targets: &[crate::io::model::MorphTarget],
    ) -> Option<(JawBone, Hinge)> {
        let shape = targets.iter().position(|t| is_jaw_shape(&t.name))?;
        let (mut hinge, turning) =
            fit_rigid(&targets[shape].name, rest, &targets[shape].positions)?;
        let mut rigid = vec![false; rest.len()];
        turning.iter().for_each(|&v| rigid[v] = true);
        let nearest = |p: &V| {
            (0..rest.len()).min_by(|&a, &b| {
                (rest[a] - p)
                    .norm_squared()
                    .total_cmp(&(rest[b] - p).norm_squared())
            })
        };
        let nodes: Vec<usize> = (0..lattice.node_count())
            .filter(|&n| lattice.pinned[n])
            .filter(|&n| nearest(&lattice.rest[n]).is_some_and(|v| rigid[v]))
            .collect();
        if nodes.is_empty() {
            return None;
        }
        hinge.bone_nodes = Some(nodes.len());
        let bone = JawBone {
            shape,
            rest: nodes.iter().map(|&n| lattice.rest[n]).collect(),
            nodes,
            axis: V::from(hinge.axis).normalize(),
            pivot: V::from(hinge.pivot_m),
            angle: hinge.angle_deg.to_radians(),
        };
        Some((bone, hinge))
    }

    /// The bone nodes' positions at opening `a` (a fraction of the shape's angle, m): their
    /// rest positions turned by a · angle about the hinge.
    fn turned(&self, a: f64) -> impl Iterator<Item = (usize, V)> + '_ {
        let r = nalgebra::Rotation3::from_axis_angle(
            &nalgebra::Unit::new_unchecked(self.axis),
            a * self.angle,
        );
        self.nodes
            .iter()
            .zip(&self.rest)
            .map(move |(&n, x)| (n, r * (x - self.pivot) + self.pivot))
    }

    /// Write the bone nodes' positions at opening `a` into `q` (flat node positions, m).
    pub fn place(&self, a: f64, q: &mut [f64]) {
        for (n, y) in self.turned(a) {
            q[3 * n..3 * n + 3].copy_from_slice(y.as_slice());
        }
    }

    /// The bone nodes' displacements from rest at opening `a` (flat over `nodes` nodes, m;
    /// zero at the other nodes).
    pub fn displacement(&self, a: f64, nodes: usize) -> Vec<f64> {
        let mut out = vec![0.0; 3 * nodes];
        for ((n, y), x) in self.turned(a).zip(&self.rest) {
            out[3 * n..3 * n + 3].copy_from_slice((y - x).as_slice());
        }
        out
    }

    /// The angle the bone nodes of `q` (flat node positions, m) stand at about the hinge
    /// (rad): the rotation about the axis that best takes their rest positions to them in
    /// the plane across the axis, atan2(Σ (u × w)·axis, Σ u·w) over their offsets from the
    /// axis at rest (u) and in `q` (w), so nodes near the axis weigh little; a · angle when
    /// placed at opening a.
    pub fn angle_of(&self, q: &[f64]) -> f64 {
        let flat = |v: V| v - self.axis * self.axis.dot(&v);
        let (mut cross, mut dot) = (0.0, 0.0);
        for (&n, x) in self.nodes.iter().zip(&self.rest) {
            let y = V::new(q[3 * n], q[3 * n + 1], q[3 * n + 2]);
            let (u, w) = (flat(x - self.pivot), flat(y - self.pivot));
            cross += u.cross(&w).dot(&self.axis);
            dot += u.dot(&w);
        }
        cross.atan2(dot)
    }

    /// d/da of the bone nodes' positions at opening `a` (flat over `nodes` nodes, m per unit
    /// opening; zero at the other nodes): angle · axis × (y − pivot) at their turned
    /// positions y.
    pub fn velocity(&self, a: f64, nodes: usize) -> Vec<f64> {
        let mut out = vec![0.0; 3 * nodes];
        for (n, y) in self.turned(a) {
            let w = self.axis.cross(&(y - self.pivot)) * self.angle;
            out[3 * n..3 * n + 3].copy_from_slice(w.as_slice());
        }
        out
    }
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
