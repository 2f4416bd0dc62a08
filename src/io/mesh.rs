//! Mesh extraction: every primitive of a mesh instance, in world space, with morph targets.

use super::accessor::{usize_of, AccessorReader, Decoded};
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

/// Where one triangle primitive of a mesh lies in its instance's merged vertex arrays.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PrimitiveSpan {
    /// The primitive's index in the mesh's JSON `primitives`.
    pub json: usize,
    /// Its first vertex in the merged arrays.
    pub first: usize,
    /// Its vertex count.
    pub count: usize,
}

impl PrimitiveSpan {
    /// The merged vertex indices of the primitive.
    pub fn vertices(&self) -> std::ops::Range<usize> {
        self.first..self.first + self.count
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
    /// The merged triangle primitives, in the mesh's order: each one's JSON index, first
    /// vertex and vertex count in the merged arrays.
    pub primitives: Vec<PrimitiveSpan>,
    /// Primitives skipped because they are not triangles (mode 0–3).
    pub skipped_primitives: usize,
}

impl MeshInstance {
    /// The instance restricted to the primitives whose span `keep` marks (one flag per
    /// [`PrimitiveSpan`], in order): their vertices renumbered in order, their triangles,
    /// their morph deltas and transforms. Also returns, for each kept vertex, its index in
    /// `self`.
    pub fn restricted(&self, keep: &[bool]) -> (MeshInstance, Vec<usize>) {
        let mut whole_of = Vec::new();
        let mut spans = Vec::new();
        let mut new_of = vec![usize::MAX; self.positions.len()];
        for (span, _) in self.primitives.iter().zip(keep).filter(|(_, &k)| k) {
            spans.push(PrimitiveSpan {
                json: span.json,
                first: whole_of.len(),
                count: span.count,
            });
            for v in span.vertices() {
                new_of[v] = whole_of.len();
                whole_of.push(v);
            }
        }
        let pick = |v: &[Vector3<f64>]| whole_of.iter().map(|&i| v[i]).collect::<Vec<_>>();
        let triangles = self
            .triangles
            .iter()
            .map(|t| t.map(|v| new_of[v]))
            .filter(|t| t.iter().all(|&v| v != usize::MAX))
            .collect();
        let targets = self
            .targets
            .iter()
            .map(|t| MorphTarget {
                name: t.name.clone(),
                positions: pick(&t.positions),
                normals: t.normals.as_deref().map(pick),
            })
            .collect();
        let to_world = match &self.to_world {
            VertexTransform::Node(m) => VertexTransform::Node(*m),
            VertexTransform::PerVertex(ms) => {
                VertexTransform::PerVertex(whole_of.iter().map(|&i| ms[i]).collect())
            }
        };
        let restricted = MeshInstance {
            node: self.node,
            mesh: self.mesh,
            name: self.name.clone(),
            positions: pick(&self.positions),
            normals: self.normals.as_deref().map(pick),
            triangles,
            targets,
            default_weights: self.default_weights.clone(),
            to_world,
            primitives: spans,
            skipped_primitives: self.skipped_primitives,
        };
        (restricted, whole_of)
    }

    /// Scale the instance by `f` (metres per file unit): every position and morph delta, and
    /// the local-to-world transforms with them.
    pub fn scale(&mut self, f: f64) {
        let s = Matrix4::new_scaling(f);
        self.positions.iter_mut().for_each(|p| *p *= f);
        for t in &mut self.targets {
            t.positions.iter_mut().for_each(|d| *d *= f);
        }
        match &mut self.to_world {
            VertexTransform::Node(w) => *w = s * *w,
            VertexTransform::PerVertex(ws) => ws.iter_mut().for_each(|w| *w = s * *w),
        }
    }
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
    let (mesh, mj) = instanced_mesh(path, json, node)?;
    let name = mj["name"]
        .as_str()
        .or(nj["name"].as_str())
        .map(String::from)
        .unwrap_or(format!("mesh_{mesh}"));
    let prims = mj["primitives"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[]);
    let names = target_names(path, mj, mesh, &name, prims)?;
    let src = InstanceSource {
        path,
        reader,
        json,
        world,
        node,
        mesh,
        name: &name,
        skin: usize_of(&nj["skin"]),
    };
    let mut merged = Merged::new(&names);
    for (pi, p) in prims.iter().enumerate() {
        merged.add_primitive(&src, pi, p)?;
    }
    let default_weights: Vec<f64> = nj["weights"]
        .as_array()
        .or(mj["weights"].as_array())
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(0.0)).collect())
        .unwrap_or_else(|| vec![0.0; names.len()]);
    let to_world = if src.skin.is_some() {
        VertexTransform::PerVertex(merged.per_vertex)
    } else {
        VertexTransform::Node(world[node])
    };
    Ok(MeshInstance {
        node,
        mesh,
        name,
        positions: merged.positions,
        normals: merged.normals,
        triangles: merged.triangles,
        targets: merged.targets,
        default_weights,
        to_world,
        primitives: merged.spans,
        skipped_primitives: merged.skipped,
    })
}

/// The index and JSON of the mesh node `node` instances; fails when it has none.
fn instanced_mesh<'j>(
    path: &Path,
    json: &'j serde_json::Value,
    node: usize,
) -> GltfResult<(usize, &'j serde_json::Value)> {
    let mesh = usize_of(&json["nodes"][node]["mesh"])
        .ok_or_else(|| GltfError::new(path, format!("node {node} has no mesh")))?;
    let mj = json["meshes"].get(mesh).ok_or_else(|| {
        GltfError::new(
            path,
            format!("node {node} refers to mesh {mesh}, which does not exist"),
        )
    })?;
    Ok((mesh, mj))
}

/// Names of the morph targets of mesh `mesh` (`extras.targetNames`, else `target_N`), after
/// checking every primitive has as many targets as the first.
fn target_names(
    path: &Path,
    mj: &serde_json::Value,
    mesh: usize,
    name: &str,
    prims: &[serde_json::Value],
) -> GltfResult<Vec<String>> {
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
    Ok((0..target_count)
        .map(|t| {
            mj["extras"]["targetNames"][t]
                .as_str()
                .map(String::from)
                .unwrap_or(format!("target_{t}"))
        })
        .collect())
}

/// What every primitive of one mesh instance is read with: the file, the instancing node
/// and the mesh.
struct InstanceSource<'a> {
    /// The file (names errors).
    path: &'a Path,
    /// Accessor reader of the file.
    reader: &'a AccessorReader<'a>,
    /// The file's glTF JSON.
    json: &'a serde_json::Value,
    /// World matrix of every node.
    world: &'a [Matrix4<f64>],
    /// The instancing node.
    node: usize,
    /// The mesh index.
    mesh: usize,
    /// The instance's name.
    name: &'a str,
    /// The node's skin, if it is skinned.
    skin: Option<usize>,
}

impl InstanceSource<'_> {
    /// The POSITION accessor of primitive `pi` (attributes `attrs`), checked VEC3 and finite.
    fn positions(&self, pi: usize, attrs: &serde_json::Value) -> GltfResult<Decoded> {
        let (path, mesh) = (self.path, self.mesh);
        let pa = usize_of(&attrs["POSITION"]).ok_or_else(|| {
            GltfError::new(path, format!("mesh {mesh} primitive {pi} has no POSITION"))
        })?;
        let pos = self.reader.read(pa)?;
        if pos.components != 3 {
            return Err(GltfError::new(
                path,
                format!("accessor {pa}: POSITION must be VEC3"),
            ));
        }
        check_finite(
            path,
            &format!(
                "mesh {mesh} ({}) primitive {pi} POSITION (accessor {pa})",
                self.name
            ),
            &pos.data,
        )?;
        Ok(pos)
    }

    /// The local-to-world matrix of each of the `count` vertices of a primitive with
    /// attributes `attrs`: skinned in the rest pose, or the node's world matrix.
    fn vertex_matrices(
        &self,
        attrs: &serde_json::Value,
        count: usize,
    ) -> GltfResult<Vec<Matrix4<f64>>> {
        match self.skin {
            Some(s) => skin_matrices(
                self.path,
                self.reader,
                self.json,
                s,
                self.world,
                attrs,
                count,
            ),
            None => Ok(vec![self.world[self.node]; count]),
        }
    }

    /// The vertex indices of primitive `pi` (its vertices in order when it has none),
    /// checked below `count`.
    fn indices(&self, pi: usize, p: &serde_json::Value, count: usize) -> GltfResult<Vec<usize>> {
        let idx: Vec<usize> = match usize_of(&p["indices"]) {
            Some(ia) => self.reader.read_indices(ia)?,
            None => (0..count).collect(),
        };
        if let Some(&bad) = idx.iter().find(|&&i| i >= count) {
            return Err(GltfError::new(
                self.path,
                format!(
                    "mesh {} primitive {pi}: index {bad} is out of range ({count} vertices)",
                    self.mesh
                ),
            ));
        }
        Ok(idx)
    }

    /// The world-space NORMAL of each vertex, when accessor `na` is given; checked VEC3 with
    /// one per vertex and finite.
    fn normals(&self, na: usize, xf: &[Matrix4<f64>]) -> GltfResult<Vec<Vector3<f64>>> {
        let count = xf.len();
        let n = self.reader.read(na)?;
        if n.count != count || n.components != 3 {
            return Err(GltfError::new(
                self.path,
                format!("accessor {na}: NORMAL must be VEC3 with one per vertex"),
            ));
        }
        check_finite(self.path, &format!("accessor {na} (NORMAL)"), &n.data)?;
        Ok((0..count)
            .map(|v| transform_normal(&xf[v], &n.vec3(v)))
            .collect())
    }

    /// The world-space `key` (POSITION or NORMAL) deltas of morph target `ti` (JSON `t`),
    /// one per vertex of transform `xf`; `None` when the target lacks `key`.
    fn target_delta(
        &self,
        t: &serde_json::Value,
        ti: usize,
        key: &str,
        xf: &[Matrix4<f64>],
    ) -> GltfResult<Option<Vec<Vector3<f64>>>> {
        let (path, count) = (self.path, xf.len());
        match usize_of(&t[key]) {
            None => Ok(None),
            Some(a) => {
                let d = self.reader.read(a)?;
                if d.count != count || d.components != 3 {
                    return Err(GltfError::new(path, format!("accessor {a}: target {ti} {key} must be VEC3 with one per vertex ({count})")));
                }
                check_finite(
                    path,
                    &format!("mesh {} target {ti} {key} (accessor {a})", self.mesh),
                    &d.data,
                )?;
                Ok(Some(
                    (0..count)
                        .map(|v| transform_vector(&xf[v], &d.vec3(v)))
                        .collect(),
                ))
            }
        }
    }
}

/// The triangle primitives of one mesh instance merged so far (vertices concatenated).
struct Merged {
    /// World-space positions (m).
    positions: Vec<Vector3<f64>>,
    /// World-space normals, while every primitive so far has NORMAL.
    normals: Option<Vec<Vector3<f64>>>,
    /// Triangles in merged vertex numbering.
    triangles: Vec<[usize; 3]>,
    /// Morph targets with world-space deltas.
    targets: Vec<MorphTarget>,
    /// Per-vertex local-to-world matrices (filled for skinned meshes only).
    per_vertex: Vec<Matrix4<f64>>,
    /// Where each merged primitive lies.
    spans: Vec<PrimitiveSpan>,
    /// Primitives skipped because they are not triangles.
    skipped: usize,
}

impl Merged {
    /// Nothing merged yet, with empty morph targets named `names`.
    fn new(names: &[String]) -> Self {
        Self {
            positions: Vec::new(),
            normals: Some(Vec::new()),
            triangles: Vec::new(),
            targets: names
                .iter()
                .map(|n| MorphTarget {
                    name: n.clone(),
                    positions: Vec::new(),
                    normals: Some(Vec::new()),
                })
                .collect(),
            per_vertex: Vec::new(),
            spans: Vec::new(),
            skipped: 0,
        }
    }

    /// Append primitive `pi` (JSON `p`) of `src`'s mesh, or count it as skipped when it is
    /// not made of triangles.
    fn add_primitive(
        &mut self,
        src: &InstanceSource,
        pi: usize,
        p: &serde_json::Value,
    ) -> GltfResult<()> {
        let mode = p["mode"].as_u64().unwrap_or(4);
        if !(4..=6).contains(&mode) {
            self.skipped += 1;
            return Ok(());
        }
        let attrs = &p["attributes"];
        let pos = src.positions(pi, attrs)?;
        let count = pos.count;
        let base = self.positions.len();
        let xf = src.vertex_matrices(attrs, count)?;
        let idx = src.indices(pi, p, count)?;
        for t in triangulate(mode, &idx) {
            self.triangles.push([t[0] + base, t[1] + base, t[2] + base]);
        }
        for v in 0..count {
            self.positions.push(transform_point(&xf[v], &pos.vec3(v)));
        }
        match (usize_of(&attrs["NORMAL"]), self.normals.as_mut()) {
            (Some(na), Some(ns)) => ns.extend(src.normals(na, &xf)?),
            _ => self.normals = None,
        }
        let tj = p["targets"].as_array().map(|a| a.as_slice()).unwrap_or(&[]);
        for (ti, t) in tj.iter().enumerate() {
            let dp = src
                .target_delta(t, ti, "POSITION", &xf)?
                .unwrap_or_else(|| vec![Vector3::zeros(); count]);
            self.targets[ti].positions.extend(dp);
            match (
                src.target_delta(t, ti, "NORMAL", &xf)?,
                self.targets[ti].normals.as_mut(),
            ) {
                (Some(dn), Some(tn)) => tn.extend(dn),
                _ => self.targets[ti].normals = None,
            }
        }
        if src.skin.is_some() {
            self.per_vertex.extend(xf);
        }
        self.spans.push(PrimitiveSpan {
            json: pi,
            first: base,
            count,
        });
        Ok(())
    }
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

/// Read attribute `name` (e.g. `TEXCOORD_0` or a custom `_THICKNESS`) of every primitive
/// of `instance` (its [`PrimitiveSpan`]s) from the file it was extracted from. Fails, naming the file, the
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
    let mut out = VertexAttribute {
        components: 0,
        data: Vec::new(),
        float: true,
    };
    for span in &instance.primitives {
        let pi = span.json;
        let p = &json["meshes"][mesh]["primitives"][pi];
        let a = usize_of(&p["attributes"][name]).ok_or_else(|| {
            GltfError::new(
                path,
                format!("{what} primitive {pi} has no vertex attribute {name}"),
            )
        })?;
        let d = reader.read(a)?;
        let count = span.count;
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
