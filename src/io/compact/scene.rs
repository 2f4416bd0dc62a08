//! A scene of several meshes as one GLB, as avatar exporters write them: a node tree with
//! translations, skins over joint nodes (inverse bind matrices from the joints' rest
//! placement), meshes of one or more primitives each with normals, texture coordinates, a
//! material and optional skin weights, morph targets named on each mesh
//! (`extras.targetNames`), and a weights animation that drives several nodes with the same
//! weights (one sampler per node over shared key accessors).
//!
//! | data | [`Storage::Float`] | [`Storage::Compact`] |
//! | --- | --- | --- |
//! | `POSITION` | f32 VEC3 | normalized i16 on the mesh's grid, dequantized by its node's `translation` and uniform `scale` (`KHR_mesh_quantization`) |
//! | `NORMAL` | f32 VEC3 | normalized i8 VEC3 |
//! | `TEXCOORD_0` | f32 VEC2 | normalized u16 VEC2 (clamped to [0, 1]) |
//! | `JOINTS_0` / `WEIGHTS_0` | u16 VEC4 / f32 VEC4 | refused (a skinned node ignores its transform, which carries the grid) |
//! | target deltas | f32, sparse when fewer than half the vertices move | normalized i16 positions and i8 normals, sparse likewise |
//! | animation weights | f32 | normalized u16 |
//! | buffer views | plain | `EXT_meshopt_compression` |

use super::targets::{unit_i8, TargetData, Vec3Data};
use super::{Codec, CompactDocument, Quantization};
use crate::io::glb_write::ARRAY_BUFFER;
use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde_json::{json, Value};

/// A vertex's skin influences: up to four joints (indices into the skin's joint list) and
/// their weights (summing to 1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Influences {
    /// Joint indices into [`Skin::joints`].
    pub joints: [u16; 4],
    /// Weights, summing to 1.
    pub weights: [f64; 4],
}

impl Influences {
    /// Weight 1 on joint `j`.
    pub fn rigid(j: u16) -> Self {
        Self {
            joints: [j, 0, 0, 0],
            weights: [1.0, 0.0, 0.0, 0.0],
        }
    }
}

/// One primitive: a triangle surface with its attributes, targets and material.
#[derive(Debug, Clone)]
pub struct Primitive {
    /// Positions (m, in the mesh's space) and counter-clockwise triangles.
    pub mesh: TriMesh,
    /// Unit normals, one per vertex.
    pub normals: Vec<Vector3<f64>>,
    /// Texture coordinates (u, v), one per vertex.
    pub uvs: Vec<[f64; 2]>,
    /// Morph targets (deltas in m, one per vertex); every primitive of a mesh has the same
    /// names in the same order.
    pub targets: Vec<MorphTarget>,
    /// Index into [`Scene::materials`].
    pub material: usize,
    /// Skin influences, one per vertex, when the mesh is skinned.
    pub influences: Option<Vec<Influences>>,
}

/// A mesh: named primitives sharing one target list.
#[derive(Debug, Clone)]
pub struct Mesh {
    /// Mesh name.
    pub name: String,
    /// Its primitives (at least one).
    pub primitives: Vec<Primitive>,
}

/// How a material treats the base colour's alpha.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Alpha {
    /// Alpha ignored.
    Opaque,
    /// Cut out below the given alpha.
    Mask(f64),
    /// Blended.
    Blend,
}

/// A metallic-roughness material without textures.
#[derive(Debug, Clone)]
pub struct Material {
    /// Material name.
    pub name: String,
    /// Linear RGBA base colour factor.
    pub color: [f64; 4],
    /// Metallic factor (0..1).
    pub metallic: f64,
    /// Roughness factor (0..1).
    pub roughness: f64,
    /// Alpha mode.
    pub alpha: Alpha,
    /// Whether both sides are drawn.
    pub double_sided: bool,
}

impl Material {
    /// An opaque, single-sided, non-metallic material of `color` and `roughness`.
    pub fn opaque(name: &str, color: [f64; 4], roughness: f64) -> Self {
        Self {
            name: name.into(),
            color,
            metallic: 0.0,
            roughness,
            alpha: Alpha::Opaque,
            double_sided: false,
        }
    }
}

/// A node: a translation (m) relative to its parent, children, and optionally a mesh and the
/// skin that deforms it.
#[derive(Debug, Clone, Default)]
pub struct Node {
    /// Node name.
    pub name: String,
    /// Translation relative to the parent, m.
    pub translation: Vector3<f64>,
    /// Child node indices.
    pub children: Vec<usize>,
    /// Index into [`Scene::meshes`].
    pub mesh: Option<usize>,
    /// Index into [`Scene::skins`].
    pub skin: Option<usize>,
}

/// A skin: its joint nodes, the first being the skeleton root; each joint's inverse bind
/// matrix undoes its rest placement (the nodes' translations as given).
#[derive(Debug, Clone)]
pub struct Skin {
    /// Skin name.
    pub name: String,
    /// Joint node indices.
    pub joints: Vec<usize>,
}

/// A weights animation driving `nodes` (each instancing a mesh with as many targets as each
/// key has weights) with the same keys.
#[derive(Debug, Clone)]
pub struct WeightClip {
    /// Animation name.
    pub name: String,
    /// Key times (s) and one weight per target per key, interpolated linearly.
    pub keys: WeightKeys,
    /// The animated nodes.
    pub nodes: Vec<usize>,
}

/// A whole scene.
#[derive(Debug, Clone, Default)]
pub struct Scene {
    /// Every node.
    pub nodes: Vec<Node>,
    /// The scene's root nodes.
    pub roots: Vec<usize>,
    /// Every mesh.
    pub meshes: Vec<Mesh>,
    /// Every material.
    pub materials: Vec<Material>,
    /// Every skin.
    pub skins: Vec<Skin>,
    /// The weights animation, if any.
    pub clip: Option<WeightClip>,
}

/// How a scene's data is stored (see the module table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Storage {
    /// Float attributes, plain buffer views.
    Float,
    /// Quantized attributes, meshopt-compressed buffer views.
    Compact,
}

/// The scene as GLB bytes in `storage`. Errors when the scene is inconsistent (an index out
/// of range, per-vertex arrays of the wrong length, primitives of a mesh with different
/// targets) or when a compact scene has a skinned or translated mesh node.
pub fn scene_glb(scene: &Scene, storage: Storage) -> anyhow::Result<Vec<u8>> {
    check_scene(scene, storage)?;
    let mut cd = CompactDocument::new();
    let mut grids = vec![None; scene.meshes.len()];
    let mut meshes = Vec::with_capacity(scene.meshes.len());
    for (mi, m) in scene.meshes.iter().enumerate() {
        let grid = match storage {
            Storage::Float => None,
            Storage::Compact => Some(mesh_grid(m)?),
        };
        grids[mi] = grid;
        meshes.push(push_mesh(&mut cd, m, grid.as_ref()));
    }
    let world = world_translations(scene);
    let j = &mut cd.doc.json;
    j["meshes"] = json!(meshes);
    j["materials"] = json!(scene
        .materials
        .iter()
        .map(material_json)
        .collect::<Vec<_>>());
    j["nodes"] = json!(scene
        .nodes
        .iter()
        .map(|n| node_json(n, n.mesh.and_then(|m| grids[m].as_ref())))
        .collect::<Vec<_>>());
    j["scenes"] = json!([{ "nodes": scene.roots }]);
    j["scene"] = json!(0);
    let skins: Vec<Value> = scene
        .skins
        .iter()
        .map(|s| {
            let ibm: Vec<f64> = s
                .joints
                .iter()
                .flat_map(|&jn| {
                    let t = world[jn];
                    [
                        1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, -t.x, -t.y,
                        -t.z, 1.0,
                    ]
                })
                .collect();
            let acc = cd.push_f32(&ibm, 16, None);
            json!({ "name": s.name, "joints": s.joints, "skeleton": s.joints[0],
                "inverseBindMatrices": acc })
        })
        .collect();
    if !skins.is_empty() {
        cd.doc.json["skins"] = json!(skins);
    }
    if let Some(clip) = &scene.clip {
        push_clip(&mut cd, clip, storage);
    }
    cd.prune()?;
    cd.to_glb(storage == Storage::Compact)
}

/// Refuse a scene whose parts do not fit together (see [`scene_glb`]).
fn check_scene(scene: &Scene, storage: Storage) -> anyhow::Result<()> {
    let nn = scene.nodes.len();
    for (i, n) in scene.nodes.iter().enumerate() {
        if n.children.iter().any(|&c| c >= nn) || n.mesh.is_some_and(|m| m >= scene.meshes.len()) {
            bail!(
                "node {i} ({}) refers to a node or mesh it does not have",
                n.name
            );
        }
        if n.skin.is_some_and(|s| s >= scene.skins.len()) {
            bail!(
                "node {i} ({}) refers to a skin the scene does not have",
                n.name
            );
        }
        let meshed = n.mesh.is_some();
        if storage == Storage::Compact
            && meshed
            && (n.skin.is_some() || n.translation != Vector3::zeros())
        {
            bail!("node {i} ({}): a compact mesh node carries the grid, so it can be neither skinned nor translated", n.name);
        }
    }
    if scene.roots.iter().any(|&r| r >= nn)
        || scene
            .skins
            .iter()
            .any(|s| s.joints.is_empty() || s.joints.iter().any(|&j| j >= nn))
    {
        bail!("a root or skin joint is not a node of the scene");
    }
    for m in &scene.meshes {
        let first = m
            .primitives
            .first()
            .with_context(|| format!("mesh {} has no primitive", m.name))?;
        let names: Vec<&str> = first.targets.iter().map(|t| t.name.as_str()).collect();
        for p in &m.primitives {
            check_primitive(&m.name, p, &names, scene.materials.len())?;
        }
    }
    if let Some(c) = &scene.clip {
        for &n in &c.nodes {
            let targets = scene
                .nodes
                .get(n)
                .and_then(|n| n.mesh)
                .map(|m| scene.meshes[m].primitives[0].targets.len());
            let Some(targets) = targets else {
                bail!("the clip animates node {n}, which has no mesh");
            };
            crate::io::export::check_weight_keys(&c.keys, targets)?;
        }
    }
    Ok(())
}

/// Refuse a primitive of mesh `mesh` whose per-vertex arrays, targets (other than `names`)
/// or material (of `materials`) do not fit.
fn check_primitive(
    mesh: &str,
    p: &Primitive,
    names: &[&str],
    materials: usize,
) -> anyhow::Result<()> {
    let n = p.mesh.positions.len();
    if n == 0 || p.mesh.triangles.is_empty() || p.mesh.triangles.iter().flatten().any(|&v| v >= n) {
        bail!("a primitive of mesh {mesh} has no triangles or indexes past its {n} vertices");
    }
    let infl = p.influences.as_ref().map_or(n, |v| v.len());
    if p.normals.len() != n || p.uvs.len() != n || infl != n {
        bail!("a primitive of mesh {mesh} has normals, texture coordinates or skin influences for other than its {n} vertices");
    }
    let same = p.targets.len() == names.len()
        && p.targets.iter().zip(names).all(|(t, &name)| t.name == name);
    if !same
        || p.targets
            .iter()
            .any(|t| t.positions.len() != n || t.normals.as_ref().is_some_and(|v| v.len() != n))
    {
        bail!("the primitives of mesh {mesh} do not carry the same targets, one delta per vertex");
    }
    if p.material >= materials {
        bail!(
            "a primitive of mesh {mesh} uses material {}, which the scene does not have",
            p.material
        );
    }
    Ok(())
}

/// The quantization grid of mesh `m`: the box of all its primitives and their deltas.
fn mesh_grid(m: &Mesh) -> anyhow::Result<Quantization> {
    let all = TriMesh::new(
        m.primitives
            .iter()
            .flat_map(|p| p.mesh.positions.iter().copied())
            .collect(),
        Vec::new(),
    );
    let targets: Vec<MorphTarget> = m
        .primitives
        .iter()
        .flat_map(|p| p.targets.iter().cloned())
        .collect();
    Quantization::of(&all, &targets)
}

/// Each node's rest translation in the scene (m): its own plus its ancestors'.
fn world_translations(scene: &Scene) -> Vec<Vector3<f64>> {
    let mut world = vec![Vector3::zeros(); scene.nodes.len()];
    let mut stack: Vec<(usize, Vector3<f64>)> =
        scene.roots.iter().map(|&r| (r, Vector3::zeros())).collect();
    while let Some((n, parent)) = stack.pop() {
        world[n] = parent + scene.nodes[n].translation;
        for &c in &scene.nodes[n].children {
            stack.push((c, world[n]));
        }
    }
    world
}

/// The mesh's JSON, its accessors pushed to `cd` (quantized on `grid` when given).
fn push_mesh(cd: &mut CompactDocument, m: &Mesh, grid: Option<&Quantization>) -> Value {
    let prims: Vec<Value> = m
        .primitives
        .iter()
        .map(|p| push_primitive(cd, p, grid))
        .collect();
    let names: Vec<&str> = m.primitives[0]
        .targets
        .iter()
        .map(|t| t.name.as_str())
        .collect();
    let mut mj = json!({ "name": m.name, "primitives": prims });
    if !names.is_empty() {
        mj["weights"] = json!(vec![0.0; names.len()]);
        mj["extras"] = json!({ "targetNames": names });
    }
    mj
}

/// One primitive's JSON, its accessors pushed to `cd`.
fn push_primitive(cd: &mut CompactDocument, p: &Primitive, grid: Option<&Quantization>) -> Value {
    let (pos, nrm) = match grid {
        None => (
            Vec3Data::f32_of(&p.mesh.positions),
            Vec3Data::f32_of(&p.normals),
        ),
        Some(q) => (
            Vec3Data::I16(p.mesh.positions.iter().map(|x| q.point(x)).collect()),
            Vec3Data::I8(p.normals.iter().map(unit_i8).collect()),
        ),
    };
    let mut attrs = json!({
        "POSITION": cd.push_vec3(&pos, true),
        "NORMAL": cd.push_vec3(&nrm, false),
        "TEXCOORD_0": push_uvs(cd, &p.uvs, grid.is_some()),
    });
    if let Some(infl) = &p.influences {
        let joints: Vec<f64> = infl.iter().flat_map(|i| i.joints.map(f64::from)).collect();
        let weights: Vec<f64> = infl.iter().flat_map(|i| i.weights).collect();
        attrs["JOINTS_0"] = json!(cd.push_joints(&joints));
        attrs["WEIGHTS_0"] = json!(cd.push_f32(&weights, 4, Some(ARRAY_BUFFER)));
    }
    let indices = cd.push_triangles(&p.mesh.triangles);
    let mut pj =
        json!({ "attributes": attrs, "indices": indices, "material": p.material, "mode": 4 });
    if !p.targets.is_empty() {
        let targets: Vec<Value> = p
            .targets
            .iter()
            .map(|t| {
                let data = match grid {
                    None => TargetData {
                        positions: Vec3Data::f32_of(&t.positions),
                        normals: t.normals.as_deref().map(Vec3Data::f32_of),
                    },
                    Some(q) => TargetData {
                        positions: Vec3Data::I16(t.positions.iter().map(|d| q.delta(d)).collect()),
                        normals: t
                            .normals
                            .as_ref()
                            .map(|v| Vec3Data::I8(v.iter().map(unit_i8).collect())),
                    },
                };
                cd.push_target(&data)
            })
            .collect();
        pj["targets"] = json!(targets);
    }
    pj
}

/// A TEXCOORD accessor: f32 VEC2, or normalized u16 VEC2 (4-byte elements) when `quantized`.
fn push_uvs(cd: &mut CompactDocument, uvs: &[[f64; 2]], quantized: bool) -> usize {
    if !quantized {
        let flat: Vec<f64> = uvs.iter().flatten().copied().collect();
        return cd.push_f32(&flat, 2, Some(ARRAY_BUFFER));
    }
    let bytes: Vec<u8> = uvs
        .iter()
        .flatten()
        .flat_map(|&u| ((u.clamp(0.0, 1.0) * 65535.0).round() as u16).to_le_bytes())
        .collect();
    let view = cd.push_view(
        bytes,
        Codec::Attributes { stride: 4 },
        Some(4),
        Some(ARRAY_BUFFER),
    );
    cd.push_accessor(
        json!({ "bufferView": view, "componentType": 5123, "normalized": true,
        "count": uvs.len(), "type": "VEC2" }),
    )
}

/// A material's JSON.
fn material_json(m: &Material) -> Value {
    let mut mj = json!({ "name": m.name, "pbrMetallicRoughness": { "baseColorFactor": m.color,
        "metallicFactor": m.metallic, "roughnessFactor": m.roughness } });
    match m.alpha {
        Alpha::Opaque => {}
        Alpha::Mask(cutoff) => {
            mj["alphaMode"] = json!("MASK");
            mj["alphaCutoff"] = json!(cutoff);
        }
        Alpha::Blend => mj["alphaMode"] = json!("BLEND"),
    }
    if m.double_sided {
        mj["doubleSided"] = json!(true);
    }
    mj
}

/// A node's JSON; a node of a quantized mesh carries the grid as its translation and scale.
fn node_json(n: &Node, grid: Option<&Quantization>) -> Value {
    let mut nj = json!({ "name": n.name });
    if let Some(q) = grid {
        let t = q.translation;
        nj["translation"] = json!([t.x, t.y, t.z]);
        nj["scale"] = json!([q.scale, q.scale, q.scale]);
    } else if n.translation != Vector3::zeros() {
        let t = n.translation;
        nj["translation"] = json!([t.x, t.y, t.z]);
    }
    if !n.children.is_empty() {
        nj["children"] = json!(n.children);
    }
    if let Some(m) = n.mesh {
        nj["mesh"] = json!(m);
    }
    if let Some(s) = n.skin {
        nj["skin"] = json!(s);
    }
    nj
}

/// The clip as one LINEAR sampler per animated node over shared time and weight accessors:
/// f32 weights, or normalized u16 when compact.
fn push_clip(cd: &mut CompactDocument, clip: &WeightClip, storage: Storage) {
    let input = cd.push_f32(&clip.keys.times, 1, None);
    let flat: Vec<f64> = clip.keys.weights.concat();
    let output = match storage {
        Storage::Float => cd.push_f32(&flat, 1, None),
        Storage::Compact => {
            let bytes: Vec<u8> = flat
                .iter()
                .flat_map(|&w| ((w.clamp(0.0, 1.0) * 65535.0).round() as u16).to_le_bytes())
                .collect();
            let view = cd.push_view(bytes, Codec::Plain, None, None);
            cd.push_accessor(json!({ "bufferView": view, "componentType": 5123,
                "normalized": true, "count": flat.len(), "type": "SCALAR" }))
        }
    };
    let samplers: Vec<Value> = clip
        .nodes
        .iter()
        .map(|_| json!({ "input": input, "output": output, "interpolation": "LINEAR" }))
        .collect();
    let channels: Vec<Value> = clip
        .nodes
        .iter()
        .enumerate()
        .map(|(s, &n)| json!({ "sampler": s, "target": { "node": n, "path": "weights" } }))
        .collect();
    cd.doc.json["animations"] =
        json!([{ "name": clip.name, "samplers": samplers, "channels": channels }]);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::load::{load_bytes, LoadOptions};
    use std::path::Path;

    /// A scene of one joint and a skinned two-triangle mesh with one target, and an unskinned
    /// one-primitive mesh carrying the same target, driven together by a two-key clip.
    fn square_scene() -> Scene {
        let p = |x: f64, y: f64| Vector3::new(x, y, 0.0);
        let mesh = TriMesh::new(
            vec![p(0.0, 0.0), p(0.1, 0.0), p(0.1, 0.1), p(0.0, 0.1)],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let target = MorphTarget {
            name: "lift".into(),
            positions: vec![
                Vector3::zeros(),
                Vector3::zeros(),
                Vector3::z() * 0.01,
                Vector3::zeros(),
            ],
            normals: None,
        };
        let prim = |skinned: bool| Primitive {
            mesh: mesh.clone(),
            normals: vec![Vector3::z(); 4],
            uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
            targets: vec![target.clone()],
            material: 0,
            influences: skinned.then(|| vec![Influences::rigid(0); 4]),
        };
        let node = |name: &str, mesh: Option<usize>, skin: Option<usize>| Node {
            name: name.into(),
            mesh,
            skin,
            translation: if mesh.is_none() {
                Vector3::y()
            } else {
                Vector3::zeros()
            },
            ..Node::default()
        };
        Scene {
            nodes: vec![
                node("joint", None, None),
                node("a", Some(0), Some(0)),
                node("b", Some(1), None),
            ],
            roots: vec![0, 1, 2],
            meshes: vec![
                Mesh {
                    name: "a".into(),
                    primitives: vec![prim(true)],
                },
                Mesh {
                    name: "b".into(),
                    primitives: vec![prim(false)],
                },
            ],
            materials: vec![Material::opaque("m", [1.0; 4], 0.5)],
            skins: vec![Skin {
                name: "s".into(),
                joints: vec![0],
            }],
            clip: Some(WeightClip {
                name: "c".into(),
                keys: WeightKeys {
                    times: vec![0.0, 1.0],
                    weights: vec![vec![0.0], vec![1.0]],
                },
                nodes: vec![1, 2],
            }),
        }
    }

    /// The float scene loads back: the skinned mesh where its positions say (its joint's
    /// placement undone by the inverse bind matrix), its target, texture coordinates, and a
    /// weights channel for each animated node; a compact scene refuses the skinned node.
    #[test]
    fn a_float_scene_loads_back_and_a_compact_one_refuses_a_skin() {
        let scene = square_scene();
        let bytes = scene_glb(&scene, Storage::Float).unwrap();
        let opts = LoadOptions {
            mesh: Some("a".into()),
            ..Default::default()
        };
        let rig = load_bytes(Path::new("square.glb"), &bytes, &opts).unwrap();
        let f = rig.face();
        assert!((f.positions[2] - Vector3::new(0.1, 0.1, 0.0)).norm() < 1e-7);
        assert!((f.targets[0].positions[2] - Vector3::z() * 0.01).norm() < 1e-7);
        let uv = rig.face_attribute("TEXCOORD_0").unwrap();
        assert_eq!(uv.components, 2);
        let channels = &rig.container.json["animations"][0]["channels"];
        assert_eq!(channels.as_array().unwrap().len(), 2);
        assert!(rig.track.is_some());
        let err = scene_glb(&scene, Storage::Compact).unwrap_err().to_string();
        assert!(err.contains("neither skinned nor translated"), "{err}");
        let mut plain = scene;
        plain.nodes[1].skin = None;
        plain.skins.clear();
        let compact = scene_glb(&plain, Storage::Compact).unwrap();
        let rig = load_bytes(Path::new("square.glb"), &compact, &opts).unwrap();
        assert!((rig.face().positions[2] - Vector3::new(0.1, 0.1, 0.0)).norm() < 1e-5);
    }
}
