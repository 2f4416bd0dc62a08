//! Mesh extraction: every primitive of a mesh instance, in world space, with morph targets.

use super::accessor::{usize_of, AccessorReader};
use super::error::{GltfError, GltfResult};
use super::model::MorphTarget;
use super::scene::{transform_normal, transform_point, transform_vector};
use nalgebra::{Matrix4, Vector3};
use std::path::Path;

/// How a mesh's local coordinates map to world space.
#[derive(Debug, Clone, PartialEq)]
pub enum VertexTransform {
    /// Every vertex uses its node's world matrix.
    Node(Matrix4<f64>),
    /// Skinned mesh in its rest pose: one blended joint matrix per vertex.
    PerVertex(Vec<Matrix4<f64>>),
}

impl VertexTransform {
    /// The local-to-world matrix of vertex `i`.
    pub fn of(&self, i: usize) -> &Matrix4<f64> {
        match self {
            VertexTransform::Node(m) => m,
            VertexTransform::PerVertex(v) => &v[i],
        }
    }
}

/// One mesh as placed by one node, all primitives merged (vertices concatenated, not welded).
#[derive(Debug, Clone)]
pub struct MeshInstance {
    /// Node index that instances the mesh.
    pub node: usize,
    /// Mesh index.
    pub mesh: usize,
    /// Mesh name (or node name, or `mesh_N`).
    pub name: String,
    /// World-space vertex positions (m, assuming the file's unit is the metre, as glTF says).
    pub positions: Vec<Vector3<f64>>,
    /// World-space unit normals, when every primitive has NORMAL.
    pub normals: Option<Vec<Vector3<f64>>>,
    /// Triangles (strips and fans converted); points and lines are skipped.
    pub triangles: Vec<[usize; 3]>,
    /// Morph targets with world-space deltas.
    pub targets: Vec<MorphTarget>,
    /// Default morph weights (node.weights, else mesh.weights, else zeros).
    pub default_weights: Vec<f64>,
    /// Local-to-world transform of each vertex (for writing results back in local space).
    pub to_world: VertexTransform,
    /// First vertex of each primitive in the merged arrays, and its vertex count.
    pub primitive_ranges: Vec<(usize, usize)>,
    /// Primitives skipped because they are not triangles (mode 0–3).
    pub skipped_primitives: usize,
}

fn check_finite(path: &Path, what: &str, v: &[f64]) -> GltfResult<()> {
    if let Some(i) = v.iter().position(|x| !x.is_finite()) {
        return Err(GltfError::new(
            path,
            format!("{what} has a non-finite value (NaN or infinity) at component {i}"),
        ));
    }
    Ok(())
}

/// Triangles of a primitive from its indices and mode.
fn triangulate(mode: u64, idx: &[usize]) -> Vec<[usize; 3]> {
    match mode {
        4 => idx.chunks_exact(3).map(|c| [c[0], c[1], c[2]]).collect(),
        5 => (2..idx.len())
            .map(|i| {
                if i % 2 == 0 {
                    [idx[i - 2], idx[i - 1], idx[i]]
                } else {
                    [idx[i - 1], idx[i - 2], idx[i]]
                }
            })
            .collect(),
        6 => (2..idx.len())
            .map(|i| [idx[0], idx[i - 1], idx[i]])
            .collect(),
        _ => Vec::new(),
    }
}

/// Rest-pose skinning matrices for each vertex of a skinned primitive.
fn skin_matrices(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    skin: usize,
    world: &[Matrix4<f64>],
    attrs: &serde_json::Value,
    count: usize,
) -> GltfResult<Vec<Matrix4<f64>>> {
    let s = json["skins"]
        .get(skin)
        .ok_or_else(|| GltfError::new(path, format!("skin {skin} does not exist")))?;
    let joints: Vec<usize> = s["joints"]
        .as_array()
        .map(|a| a.iter().filter_map(usize_of).collect())
        .unwrap_or_default();
    for &j in &joints {
        if j >= world.len() {
            return Err(GltfError::new(
                path,
                format!("skin {skin} names joint node {j}, which does not exist"),
            ));
        }
    }
    let ibm: Vec<Matrix4<f64>> = match usize_of(&s["inverseBindMatrices"]) {
        Some(a) => {
            let d = reader.read(a)?;
            if d.components != 16 || d.count < joints.len() {
                return Err(GltfError::new(
                    path,
                    format!("skin {skin}: inverseBindMatrices must be MAT4 with one per joint"),
                ));
            }
            (0..joints.len())
                .map(|i| Matrix4::from_column_slice(&d.data[i * 16..i * 16 + 16]))
                .collect()
        }
        None => vec![Matrix4::identity(); joints.len()],
    };
    let jm: Vec<Matrix4<f64>> = joints
        .iter()
        .zip(&ibm)
        .map(|(&j, b)| world[j] * b)
        .collect();
    let mut out = vec![Matrix4::zeros(); count];
    let mut any = false;
    for set in 0..4 {
        let (Some(ja), Some(wa)) = (
            usize_of(&attrs[format!("JOINTS_{set}")]),
            usize_of(&attrs[format!("WEIGHTS_{set}")]),
        ) else {
            continue;
        };
        any = true;
        let j = reader.read(ja)?;
        let w = reader.read(wa)?;
        if j.count != count || w.count != count || j.components != 4 || w.components != 4 {
            return Err(GltfError::new(
                path,
                format!("JOINTS_{set}/WEIGHTS_{set} must be VEC4 with one entry per vertex"),
            ));
        }
        for v in 0..count {
            for k in 0..4 {
                let wt = w.data[v * 4 + k];
                if wt != 0.0 {
                    let ji = j.data[v * 4 + k] as usize;
                    let m = jm.get(ji).ok_or_else(|| {
                        GltfError::new(
                            path,
                            format!(
                                "vertex {v} uses joint {ji} of skin {skin}, which has {} joints",
                                jm.len()
                            ),
                        )
                    })?;
                    out[v] += m * wt;
                }
            }
        }
    }
    if !any {
        return Err(GltfError::new(
            path,
            format!("a primitive skinned by skin {skin} has no JOINTS_0/WEIGHTS_0"),
        ));
    }
    Ok(out)
}

/// Extract mesh `mesh` as instanced by node `node` (world matrices from [`super::scene`]).
pub fn extract(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    node: usize,
    world: &[Matrix4<f64>],
) -> GltfResult<MeshInstance> {
    let nj = &json["nodes"][node];
    let mesh = usize_of(&nj["mesh"])
        .ok_or_else(|| GltfError::new(path, format!("node {node} has no mesh")))?;
    let mj = json["meshes"].get(mesh).ok_or_else(|| {
        GltfError::new(
            path,
            format!("node {node} refers to mesh {mesh}, which does not exist"),
        )
    })?;
    let name = mj["name"]
        .as_str()
        .or(nj["name"].as_str())
        .map(String::from)
        .unwrap_or(format!("mesh_{mesh}"));
    let prims = mj["primitives"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[]);
    let skin = usize_of(&nj["skin"]);
    let target_count = prims
        .first()
        .and_then(|p| p["targets"].as_array())
        .map_or(0, |t| t.len());
    for (pi, p) in prims.iter().enumerate() {
        let tc = p["targets"].as_array().map_or(0, |t| t.len());
        if tc != target_count {
            return Err(GltfError::new(path, format!("mesh {mesh} ({name}): morph target counts differ between primitives (primitive 0 has {target_count}, primitive {pi} has {tc})")));
        }
    }
    let names: Vec<String> = (0..target_count)
        .map(|t| {
            mj["extras"]["targetNames"][t]
                .as_str()
                .map(String::from)
                .unwrap_or(format!("target_{t}"))
        })
        .collect();
    let mut positions = Vec::new();
    let mut normals: Option<Vec<Vector3<f64>>> = Some(Vec::new());
    let mut triangles = Vec::new();
    let mut targets: Vec<MorphTarget> = names
        .iter()
        .map(|n| MorphTarget {
            name: n.clone(),
            positions: Vec::new(),
            normals: Some(Vec::new()),
        })
        .collect();
    let mut per_vertex: Vec<Matrix4<f64>> = Vec::new();
    let mut ranges = Vec::new();
    let mut skipped = 0;
    for (pi, p) in prims.iter().enumerate() {
        let mode = p["mode"].as_u64().unwrap_or(4);
        if !(4..=6).contains(&mode) {
            skipped += 1;
            continue;
        }
        let attrs = &p["attributes"];
        let pa = usize_of(&attrs["POSITION"]).ok_or_else(|| {
            GltfError::new(path, format!("mesh {mesh} primitive {pi} has no POSITION"))
        })?;
        let pos = reader.read(pa)?;
        if pos.components != 3 {
            return Err(GltfError::new(
                path,
                format!("accessor {pa}: POSITION must be VEC3"),
            ));
        }
        check_finite(
            path,
            &format!("mesh {mesh} ({name}) primitive {pi} POSITION (accessor {pa})"),
            &pos.data,
        )?;
        let count = pos.count;
        let base = positions.len();
        let xf: Vec<Matrix4<f64>> = match skin {
            Some(s) => skin_matrices(path, reader, json, s, world, attrs, count)?,
            None => vec![world[node]; count],
        };
        let idx: Vec<usize> = match usize_of(&p["indices"]) {
            Some(ia) => reader.read_indices(ia)?,
            None => (0..count).collect(),
        };
        if let Some(&bad) = idx.iter().find(|&&i| i >= count) {
            return Err(GltfError::new(
                path,
                format!(
                    "mesh {mesh} primitive {pi}: index {bad} is out of range ({count} vertices)"
                ),
            ));
        }
        for t in triangulate(mode, &idx) {
            triangles.push([t[0] + base, t[1] + base, t[2] + base]);
        }
        for v in 0..count {
            positions.push(transform_point(&xf[v], &pos.vec3(v)));
        }
        match (usize_of(&attrs["NORMAL"]), normals.as_mut()) {
            (Some(na), Some(ns)) => {
                let n = reader.read(na)?;
                if n.count != count || n.components != 3 {
                    return Err(GltfError::new(
                        path,
                        format!("accessor {na}: NORMAL must be VEC3 with one per vertex"),
                    ));
                }
                check_finite(path, &format!("accessor {na} (NORMAL)"), &n.data)?;
                ns.extend((0..count).map(|v| transform_normal(&xf[v], &n.vec3(v))));
            }
            _ => normals = None,
        }
        let tj = p["targets"].as_array().map(|a| a.as_slice()).unwrap_or(&[]);
        for (ti, t) in tj.iter().enumerate() {
            let read_delta = |key: &str| -> GltfResult<Option<Vec<Vector3<f64>>>> {
                match usize_of(&t[key]) {
                    None => Ok(None),
                    Some(a) => {
                        let d = reader.read(a)?;
                        if d.count != count || d.components != 3 {
                            return Err(GltfError::new(path, format!("accessor {a}: target {ti} {key} must be VEC3 with one per vertex ({count})")));
                        }
                        check_finite(
                            path,
                            &format!("mesh {mesh} target {ti} {key} (accessor {a})"),
                            &d.data,
                        )?;
                        Ok(Some(
                            (0..count)
                                .map(|v| transform_vector(&xf[v], &d.vec3(v)))
                                .collect(),
                        ))
                    }
                }
            };
            let dp = read_delta("POSITION")?.unwrap_or_else(|| vec![Vector3::zeros(); count]);
            targets[ti].positions.extend(dp);
            match (read_delta("NORMAL")?, targets[ti].normals.as_mut()) {
                (Some(dn), Some(tn)) => tn.extend(dn),
                _ => targets[ti].normals = None,
            }
        }
        if skin.is_some() {
            per_vertex.extend(xf);
        }
        ranges.push((base, count));
    }
    let default_weights: Vec<f64> = nj["weights"]
        .as_array()
        .or(mj["weights"].as_array())
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(0.0)).collect())
        .unwrap_or_else(|| vec![0.0; target_count]);
    Ok(MeshInstance {
        node,
        mesh,
        name,
        positions,
        normals,
        triangles,
        targets,
        default_weights,
        to_world: if skin.is_some() {
            VertexTransform::PerVertex(per_vertex)
        } else {
            VertexTransform::Node(world[node])
        },
        primitive_ranges: ranges,
        skipped_primitives: skipped,
    })
}

/// A per-vertex attribute of a mesh instance, read in the instance's vertex order
/// (primitives concatenated as in [`extract`]): `components` values per vertex, raw (no
/// space transform; normalised integers are mapped to [0, 1] / [−1, 1] as glTF says).
#[derive(Debug, Clone, PartialEq)]
pub struct VertexAttribute {
    /// Values per vertex (1 for SCALAR, 2 for VEC2, …).
    pub components: usize,
    /// `components` × vertex count values.
    pub data: Vec<f64>,
    /// Whether every accessor holds 32-bit floats (componentType 5126).
    pub float: bool,
}

/// Read attribute `name` (e.g. `TEXCOORD_0` or a custom `_THICKNESS`) of every triangle
/// primitive of `instance` from the file it was extracted from. Fails, naming the file, the
/// mesh and the primitive, when a primitive lacks it or has a different count or type.
pub fn read_attribute(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    instance: &MeshInstance,
    name: &str,
) -> GltfResult<VertexAttribute> {
    let mesh = instance.mesh;
    let what = format!("mesh {mesh} ('{}')", instance.name);
    let prims = json["meshes"][mesh]["primitives"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[]);
    let mut out = VertexAttribute {
        components: 0,
        data: Vec::new(),
        float: true,
    };
    for (pi, p) in prims.iter().enumerate() {
        let mode = p["mode"].as_u64().unwrap_or(4);
        if !(4..=6).contains(&mode) {
            continue;
        }
        let a = usize_of(&p["attributes"][name]).ok_or_else(|| {
            GltfError::new(
                path,
                format!("{what} primitive {pi} has no vertex attribute {name}"),
            )
        })?;
        let d = reader.read(a)?;
        let count = usize_of(&p["attributes"]["POSITION"])
            .and_then(|pa| usize_of(&json["accessors"][pa]["count"]))
            .unwrap_or(d.count);
        if d.count != count {
            return Err(GltfError::new(
                path,
                format!(
                    "{what} primitive {pi}: {name} (accessor {a}) has {} values for {count} vertices",
                    d.count
                ),
            ));
        }
        if out.components != 0 && out.components != d.components {
            return Err(GltfError::new(
                path,
                format!("{what}: {name} has a different type in primitive {pi}"),
            ));
        }
        out.components = d.components;
        out.float &= json["accessors"][a]["componentType"].as_u64() == Some(5126);
        out.data.extend(d.data);
    }
    if out.data.len() != out.components * instance.positions.len() {
        return Err(GltfError::new(
            path,
            format!(
                "{what}: {name} covers {} of its {} vertices",
                out.data.len() / out.components.max(1),
                instance.positions.len()
            ),
        ));
    }
    Ok(out)
}
