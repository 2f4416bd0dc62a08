//! The face node's rigid motion: the animated translation, rotation and scale of the face's
//! node and of its ancestors, as the world-space map from the displayed pose to the pose at a
//! time. A capture rig's head turns and nods this way; the blend shapes act in the node's
//! frame.

use super::accessor::AccessorReader;
use super::animation::{channel_track, Interpolation, WeightTrack};
use super::error::{GltfError, GltfResult};
use super::scene::{local_matrix, node_trs, parents, quaternion, trs_matrix};
use nalgebra::{Matrix4, UnitQuaternion};
use std::path::Path;

/// The animated channels of one node of the face's ancestor chain.
#[derive(Debug, Clone)]
struct NodeChannels {
    /// The node's JSON (its static transform).
    json: serde_json::Value,
    translation: Option<WeightTrack>,
    rotation: Option<WeightTrack>,
    scale: Option<WeightTrack>,
}

impl NodeChannels {
    /// The node's local transform at time `t` (s): animated channels override the static ones.
    fn local_at(&self, t: f64) -> Matrix4<f64> {
        if self.translation.is_none() && self.rotation.is_none() && self.scale.is_none() {
            return local_matrix(&self.json);
        }
        let (mut tr, mut rot, mut sc) = node_trs(&self.json);
        if let Some(tk) = &self.translation {
            tr = tk.sample(t);
        }
        if let Some(tk) = &self.rotation {
            rot = sample_rotation(tk, t);
        }
        if let Some(tk) = &self.scale {
            sc = tk.sample(t);
        }
        trs_matrix(&tr, &rot, &sc)
    }
}

/// A rotation channel at time `t` (s): spherical linear interpolation between LINEAR keys (as
/// glTF asks), the Hermite curve renormalised for CUBICSPLINE, the key held for STEP.
fn sample_rotation(track: &WeightTrack, t: f64) -> UnitQuaternion<f64> {
    let n = track.times.len();
    if track.interpolation != Interpolation::Linear
        || n < 2
        || t <= track.times[0]
        || t >= track.times[n - 1]
    {
        return quaternion(&track.sample(t));
    }
    let k = track.times.partition_point(|&x| x <= t) - 1;
    let (t0, t1) = (track.times[k], track.times[k + 1]);
    let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 0.0 };
    let (a, mut b) = (
        quaternion(&track.values[k]),
        quaternion(&track.values[k + 1]),
    );
    if a.coords.dot(&b.coords) < 0.0 {
        b = UnitQuaternion::new_unchecked(-b.into_inner());
    }
    a.try_slerp(&b, s, 1e-12).unwrap_or(a)
}

/// The face node's motion over an animation: the world-space map G(t) = W(t) W₀⁻¹ from the
/// displayed pose (W₀, where the mesh is loaded) to the pose at time t (file units).
#[derive(Debug, Clone)]
pub struct NodeMotion {
    /// The face node's ancestors from the root down to it, with their channels.
    chain: Vec<NodeChannels>,
    /// W₀⁻¹: the inverse of the face node's world matrix in the displayed pose.
    rest_inverse: Matrix4<f64>,
    /// Names (or indices) of the animated nodes, for the report.
    pub animated: Vec<String>,
    /// Last key time of the node channels (s).
    pub duration: f64,
}

impl NodeMotion {
    /// G(t) at time `t` (s): world points of the displayed pose to world points at `t`.
    pub fn at(&self, t: f64) -> Matrix4<f64> {
        let w = self
            .chain
            .iter()
            .fold(Matrix4::<f64>::identity(), |w, c| w * c.local_at(t));
        w * self.rest_inverse
    }

    /// G(t) with its translation scaled by `metres_per_unit`: the motion of the rig as it is
    /// simulated (rescaled about the origin).
    pub fn at_scaled(&self, t: f64, metres_per_unit: f64) -> Matrix4<f64> {
        let mut g = self.at(t);
        for r in 0..3 {
            g[(r, 3)] *= metres_per_unit;
        }
        g
    }
}

/// The motion of `node` in animation `anim`: None when neither the node nor an ancestor has
/// a translation, rotation or scale channel there.
pub fn node_motion(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    anim: usize,
    node: usize,
) -> GltfResult<Option<NodeMotion>> {
    let parent = parents(path, json)?;
    let mut ids = vec![node];
    while let Some(p) = parent[*ids.last().unwrap_or(&node)] {
        if ids.contains(&p) {
            return Err(GltfError::new(path, "the node hierarchy has a cycle"));
        }
        ids.push(p);
    }
    ids.reverse();
    let mut chain = Vec::with_capacity(ids.len());
    let (mut animated, mut duration) = (Vec::new(), 0.0f64);
    for &n in &ids {
        let read = |p: &str, w: usize| channel_track(path, reader, json, (anim, n), p, w);
        let c = NodeChannels {
            json: json["nodes"][n].clone(),
            translation: read("translation", 3)?,
            rotation: read("rotation", 4)?,
            scale: read("scale", 3)?,
        };
        let tracks = [&c.translation, &c.rotation, &c.scale];
        if tracks.iter().any(|t| t.is_some()) {
            let name = c.json["name"]
                .as_str()
                .map_or(format!("node {n}"), String::from);
            animated.push(name);
            for t in tracks.into_iter().flatten() {
                duration = duration.max(t.duration());
            }
        }
        chain.push(c);
    }
    if animated.is_empty() {
        return Ok(None);
    }
    let w0 = chain
        .iter()
        .fold(Matrix4::<f64>::identity(), |w, c| w * local_matrix(&c.json));
    let rest_inverse = w0.try_inverse().ok_or_else(|| {
        GltfError::new(
            path,
            format!("node {node}'s world transform is singular (a zero scale?)"),
        )
    })?;
    Ok(Some(NodeMotion {
        chain,
        rest_inverse,
        animated,
        duration,
    }))
}

/// The angle (rad) of the rotation part of an affine map's linear block, for reports.
pub fn rotation_angle(g: &Matrix4<f64>) -> f64 {
    let l = g.fixed_view::<3, 3>(0, 0).into_owned();
    let svd = l.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(vt)) => {
            let r = u * vt;
            ((r.trace() - 1.0) / 2.0).clamp(-1.0, 1.0).acos()
        }
        _ => 0.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::scene::transform_point;
    use nalgebra::Vector3;

    fn rotation_track(times: Vec<f64>, angles: &[f64]) -> WeightTrack {
        let values = angles
            .iter()
            .map(|a| {
                let q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), *a);
                vec![q.i, q.j, q.k, q.w]
            })
            .collect();
        WeightTrack {
            node: 0,
            times,
            values,
            tangents_in: vec![],
            tangents_out: vec![],
            interpolation: Interpolation::Linear,
        }
    }

    #[test]
    fn linear_rotation_keys_slerp_at_constant_rate() {
        let tk = rotation_track(vec![0.0, 1.0], &[0.0, 2.0]);
        for s in [0.1, 0.5, 0.9] {
            assert!((sample_rotation(&tk, s).angle() - 2.0 * s).abs() < 1e-12);
        }
    }

    #[test]
    fn motion_is_relative_to_the_displayed_pose_through_the_parent() {
        // Parent translated by (0, 1, 0) and rotated about y over 1 s; the child (the face)
        // is displaced by (0, 0, 1). At t = 0 the map is the identity; at t = 1 the face's
        // points turn by the key's angle about the parent's axis.
        let json = serde_json::json!({
            "nodes": [
                { "children": [1], "translation": [0.0, 1.0, 0.0] },
                { "mesh": 0, "translation": [0.0, 0.0, 1.0] }
            ]
        });
        let angle = 0.5;
        let mut chain: Vec<NodeChannels> = (0..2)
            .map(|n| NodeChannels {
                json: json["nodes"][n].clone(),
                translation: None,
                rotation: None,
                scale: None,
            })
            .collect();
        chain[0].rotation = Some(rotation_track(vec![0.0, 1.0], &[0.0, angle]));
        let w0 = local_matrix(&json["nodes"][0]) * local_matrix(&json["nodes"][1]);
        let m = NodeMotion {
            chain,
            rest_inverse: w0.try_inverse().unwrap(),
            animated: vec!["node 0".into()],
            duration: 1.0,
        };
        assert!((m.at(0.0) - Matrix4::identity()).norm() < 1e-14);
        let p = Vector3::new(0.0, 1.0, 1.0); // the face's origin in the world
        let q = transform_point(&m.at(1.0), &p);
        let want = Vector3::new(angle.sin(), 1.0, angle.cos());
        assert!((q - want).norm() < 1e-12, "{q} vs {want}");
        assert!((rotation_angle(&m.at(1.0)) - angle).abs() < 1e-12);
        let s = m.at_scaled(1.0, 0.01);
        assert!((s[(1, 3)] - 0.01 * m.at(1.0)[(1, 3)]).abs() < 1e-15);
    }
}
