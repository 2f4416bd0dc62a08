//! Scene graph: node transforms to world space, and which nodes instance which meshes.

use super::error::{GltfError, GltfResult};
use nalgebra::{Matrix4, Quaternion, UnitQuaternion, Vector3};
use std::path::Path;

/// `n` numbers under key `k` of a node, if it has exactly that many.
fn node_numbers(node: &serde_json::Value, k: &str, n: usize) -> Option<Vec<f64>> {
    let a = node[k].as_array()?;
    if a.len() != n {
        return None;
    }
    a.iter().map(|v| v.as_f64()).collect()
}

/// A node's static translation, rotation and scale (glTF defaults where absent).
pub fn node_trs(node: &serde_json::Value) -> (Vec<f64>, UnitQuaternion<f64>, Vec<f64>) {
    let t = node_numbers(node, "translation", 3).unwrap_or(vec![0.0; 3]);
    let r = node_numbers(node, "rotation", 4).unwrap_or(vec![0.0, 0.0, 0.0, 1.0]);
    let s = node_numbers(node, "scale", 3).unwrap_or(vec![1.0; 3]);
    (t, quaternion(&r), s)
}

/// A glTF quaternion (x, y, z, w), normalised.
pub fn quaternion(r: &[f64]) -> UnitQuaternion<f64> {
    UnitQuaternion::from_quaternion(Quaternion::new(r[3], r[0], r[1], r[2]))
}

/// translation · rotation · scale as one 4×4 matrix.
pub fn trs_matrix(t: &[f64], r: &UnitQuaternion<f64>, s: &[f64]) -> Matrix4<f64> {
    let mut m = r.to_homogeneous();
    for c in 0..3 {
        for row in 0..3 {
            m[(row, c)] *= s[c];
        }
        m[(c, 3)] = t[c];
    }
    m
}

/// The local transform of node `n` (column-major `matrix`, or translation·rotation·scale).
pub fn local_matrix(node: &serde_json::Value) -> Matrix4<f64> {
    if let Some(m) = node_numbers(node, "matrix", 16) {
        return Matrix4::from_column_slice(&m);
    }
    let (t, r, s) = node_trs(node);
    trs_matrix(&t, &r, &s)
}

/// The parent of every node (None for roots). A child that does not exist, or a node with
/// more than one parent, is an error.
pub fn parents(path: &Path, json: &serde_json::Value) -> GltfResult<Vec<Option<usize>>> {
    let nodes = json["nodes"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[]);
    let n = nodes.len();
    let mut parent: Vec<Option<usize>> = vec![None; n];
    for (i, node) in nodes.iter().enumerate() {
        if let Some(ch) = node["children"].as_array() {
            for c in ch {
                let c = c
                    .as_u64()
                    .map(|c| c as usize)
                    .filter(|&c| c < n)
                    .ok_or_else(|| {
                        GltfError::new(
                            path,
                            format!("node {i} has a child {c} that does not exist"),
                        )
                    })?;
                if parent[c].is_some() || c == i {
                    return Err(GltfError::new(path, format!("node {c} has more than one parent or is its own child (the node hierarchy must be a tree)")));
                }
                parent[c] = Some(i);
            }
        }
    }
    Ok(parent)
}

/// World matrices of every node (identity for nodes outside the displayed scene), and the
/// list of nodes reachable from the displayed scene. Cycles and multiple parents are errors.
pub fn world_matrices(
    path: &Path,
    json: &serde_json::Value,
) -> GltfResult<(Vec<Matrix4<f64>>, Vec<usize>)> {
    let nodes = json["nodes"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[]);
    let n = nodes.len();
    let parent = parents(path, json)?;
    let scene_index = json["scene"].as_u64().unwrap_or(0) as usize;
    let roots: Vec<usize> = match json["scenes"]
        .get(scene_index)
        .and_then(|s| s["nodes"].as_array())
    {
        Some(a) => a
            .iter()
            .filter_map(|v| v.as_u64())
            .map(|v| v as usize)
            .collect(),
        None => (0..n).filter(|&i| parent[i].is_none()).collect(),
    };
    let mut world = vec![Matrix4::identity(); n];
    let mut visited = vec![false; n];
    let mut order = Vec::new();
    let mut stack: Vec<(usize, Matrix4<f64>)> = Vec::new();
    for &r in &roots {
        if r >= n {
            return Err(GltfError::new(
                path,
                format!("scene {scene_index} lists node {r}, which does not exist"),
            ));
        }
        stack.push((r, Matrix4::identity()));
    }
    while let Some((i, pm)) = stack.pop() {
        if visited[i] {
            return Err(GltfError::new(
                path,
                format!(
                    "node {i} is reached twice: the node hierarchy has a cycle or a shared child"
                ),
            ));
        }
        visited[i] = true;
        order.push(i);
        let w = pm * local_matrix(&nodes[i]);
        world[i] = w;
        if let Some(ch) = nodes[i]["children"].as_array() {
            for c in ch.iter().filter_map(|c| c.as_u64()) {
                stack.push((c as usize, w));
            }
        }
    }
    Ok((world, order))
}

/// Apply an affine 4×4 transform to a point.
pub fn transform_point(m: &Matrix4<f64>, p: &Vector3<f64>) -> Vector3<f64> {
    (m * p.push(1.0)).xyz()
}

/// Apply the linear part of a 4×4 transform to a vector (a morph delta).
pub fn transform_vector(m: &Matrix4<f64>, v: &Vector3<f64>) -> Vector3<f64> {
    m.fixed_view::<3, 3>(0, 0) * v
}

/// Transform a normal by the inverse transpose of the linear part and renormalise.
pub fn transform_normal(m: &Matrix4<f64>, n: &Vector3<f64>) -> Vector3<f64> {
    let l = m.fixed_view::<3, 3>(0, 0).into_owned();
    let it = l.try_inverse().map(|i| i.transpose()).unwrap_or(l);
    let r = it * n;
    let len = r.norm();
    if len > 0.0 {
        r / len
    } else {
        *n
    }
}
