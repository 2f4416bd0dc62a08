//! The wrinkle layer as glTF: the rig as its artist made it, on the refined skin (its
//! primitives with their materials, attributes and UV seams, its blend shapes and their
//! animation), plus wrinkle targets: modes of the clip's wrinkles animated in the rig's own
//! weights channel, or, for a still rig, one corrective per blend shape.
//!
//! Everything comes in world space on the refined skin's vertices (m, as simulated) and is
//! written in the face's local coordinates (the file's units) on the split face's vertices
//! ([`super::split`]). Storage ([`Precision`]):
//!
//! | data | `Float` | `Quantized` (`KHR_mesh_quantization`) |
//! | --- | --- | --- |
//! | base `POSITION` | f32 | f32 (the rig's rest shape, exact) |
//! | base `NORMAL` | f32 | normalized i8 |
//! | the rig's shapes: `POSITION` deltas | f32 | f32 (exact) |
//! | wrinkle modes: `POSITION` deltas | f32 | normalized i16 at full range: the mode divided by its largest component a (file units), its weights multiplied by a (so a mode stays within ±1 at any weight in [−1, 1]); f32 when a mode's largest deltas exceed one file unit |
//! | correctives: `POSITION` deltas | f32 | f32 rounded to 16 mantissa bits |
//! | `NORMAL` deltas | f32 | normalized i8 within ±1, else f32 rounded to 12 mantissa bits |
//! | targets moving under half the vertices | sparse | sparse |
//!
//! With `compress`, every new view is compressed with `EXT_meshopt_compression` (rounded
//! floats with its `EXPONENTIAL` filter), and the file decodes to the same values as without.

use super::carry;
use super::compact::{CompactDocument, TargetData, Vec3Data};
use super::export;
use super::face_weights::{self, WrinkleKeys};
use super::glb_write::ARRAY_BUFFER;
use super::load::Rig;
use super::mesh::VertexTransform;
use super::origin::{LocalFrames, VertexOrigin};
use super::split::{self, FaceMap, SplitFace, SplitPrimitive};
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde_json::{json, Value};

/// Mantissa bits of floats rounded for the `EXPONENTIAL` filter: normal deltas.
const NORMAL_BITS: i32 = 12;
/// Mantissa bits of corrective position deltas.
const CORRECTIVE_BITS: i32 = 16;

/// One morph target on the refined skin (world space).
#[derive(Debug, Clone, PartialEq)]
pub struct LayerTarget {
    /// Its name in `extras.targetNames`.
    pub name: String,
    /// Position deltas per refined vertex (m).
    pub positions: Vec<Vector3<f64>>,
    /// Normal deltas per refined vertex (unitless).
    pub normals: Vec<Vector3<f64>>,
}

/// What the wrinkle layer writes.
#[derive(Debug, Clone, PartialEq)]
pub struct Layer {
    /// The refined skin at rest (m).
    pub base: Vec<Vector3<f64>>,
    /// Its unit vertex normals at rest.
    pub base_normals: Vec<Vector3<f64>>,
    /// The rig's blend shapes on the refined skin, in the rig's order.
    pub shapes: Vec<LayerTarget>,
    /// The wrinkle targets, after the rig's shapes.
    pub wrinkles: Vec<LayerTarget>,
    /// The wrinkle targets' weights per written frame (each within [−1, 1]); `None` for
    /// correctives, whose weight is the shape's own (driven by the engine).
    pub keys: Option<WrinkleKeys>,
}

/// How accessors are stored (see the module table).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Precision {
    /// 32-bit floats everywhere.
    Float,
    /// `KHR_mesh_quantization` where it keeps the error small.
    Quantized,
}

/// How to write the layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LayerOptions {
    /// Accessor storage.
    pub precision: Precision,
    /// Compress with `EXT_meshopt_compression`.
    pub compress: bool,
}

/// A written layer.
#[derive(Debug, Clone)]
pub struct Written {
    /// The GLB.
    pub bytes: Vec<u8>,
    /// Index of the face's mesh in it.
    pub mesh: usize,
    /// Per wrinkle target, the factor its weights were multiplied by in the file (its
    /// deltas divided by it).
    pub weight_scale: Vec<f64>,
    /// For each vertex of the written face (primitives in order, vertices concatenated), its
    /// refined vertex.
    pub refined_of_vertex: Vec<usize>,
    /// What the user should know (primitives riding along, weights resampled).
    pub notes: Vec<String>,
}

/// The kind of a target, which decides its storage.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Kind {
    /// The artist's shape: positions exact.
    Shape,
    /// A wrinkle mode whose weights may absorb its amplitude (largest |weight| given).
    Mode(f64),
    /// A corrective, weighted as its shape.
    Corrective,
}

/// A target's local deltas on the export vertices and how to store them.
struct Local {
    positions: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    /// Divide the deltas by this (the weights are multiplied by it).
    scale: f64,
    pos: Store,
    nrm: Store,
}

/// A storage choice for a VEC3 attribute.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Store {
    F32,
    Exp(i32),
    I16,
    I8,
}

impl Store {
    fn data(self, v: &[Vector3<f64>], scale: f64) -> Vec3Data {
        let s: Vec<Vector3<f64>> = v.iter().map(|d| d / scale).collect();
        match self {
            Store::F32 => Vec3Data::f32_of(&s),
            Store::Exp(bits) => Vec3Data::exp_of(&s, bits),
            Store::I16 => Vec3Data::I16(s.iter().map(super::compact::targets::unit_i16).collect()),
            Store::I8 => Vec3Data::I8(s.iter().map(super::compact::targets::unit_i8).collect()),
        }
    }
}

/// Largest absolute component of a field.
fn largest(v: &[Vector3<f64>]) -> f64 {
    v.iter().map(|d| d.abs().max()).fold(0.0, f64::max)
}

/// How to store a target of `kind` with local deltas `pos`, `nrm`.
fn choose(
    kind: Kind,
    pos: &[Vector3<f64>],
    nrm: &[Vector3<f64>],
    precision: Precision,
) -> (f64, Store, Store) {
    if precision == Precision::Float {
        return (1.0, Store::F32, Store::F32);
    }
    let a = largest(pos);
    let (scale, p) = match kind {
        Kind::Shape => (1.0, Store::F32),
        Kind::Corrective => (1.0, Store::Exp(CORRECTIVE_BITS)),
        Kind::Mode(w) if a > 0.0 && a * w <= 1.0 => (a, Store::I16),
        Kind::Mode(_) => (1.0, Store::F32),
    };
    let n = if largest(nrm) / scale <= 1.0 {
        Store::I8
    } else {
        Store::Exp(NORMAL_BITS)
    };
    (scale, p, n)
}

/// Write the wrinkle layer of `rig` (its face refined as `map` says) as a GLB.
pub fn layer_glb(
    rig: &Rig,
    map: &FaceMap,
    layer: &Layer,
    opts: LayerOptions,
) -> anyhow::Result<Written> {
    let face = rig.face();
    let mesh_json = &rig.container.json["meshes"][face.mesh];
    let split = split::split_face(face, mesh_json, map).with_context(|| {
        format!(
            "{}: the refined face does not fit this rig",
            rig.path.display()
        )
    })?;
    check_layer(layer, map, face.targets.len())?;
    let local = LocalFrames::new(rig, &split.origin)?;
    let locals = local_targets(layer, &split, &local, opts.precision);
    let mut cd = CompactDocument::from_document(export::base_document(rig)?);
    let base = Base::of(layer, &split, &local, opts.precision);
    let mut prims = Vec::new();
    for p in &split.primitives {
        prims.push(write_primitive(&mut cd, rig, (&split, p), &base, &locals)?);
    }
    let k = layer.wrinkles.len();
    for &j in &split.unrefined {
        prims.push(riding_primitive(&mut cd, &mesh_json["primitives"][j], k));
    }
    // The mesh's own order: refined skin and riding primitives as the artist laid them out.
    let order: Vec<usize> = split
        .primitives
        .iter()
        .map(|p| p.json)
        .chain(split.unrefined.iter().copied())
        .collect();
    let mut by_json: Vec<(usize, Value)> = order.into_iter().zip(prims).collect();
    by_json.sort_by_key(|(j, _)| *j);
    let prims: Vec<Value> = by_json.into_iter().map(|(_, p)| p).collect();
    let names: Vec<&str> = layer
        .shapes
        .iter()
        .chain(&layer.wrinkles)
        .map(|t| t.name.as_str())
        .collect();
    let mut mesh = mesh_json.clone();
    mesh["primitives"] = json!(prims);
    let mut weights: Vec<f64> = mesh_json["weights"]
        .as_array()
        .map(|a| a.iter().map(|v| v.as_f64().unwrap_or(0.0)).collect())
        .unwrap_or_default();
    weights.resize(face.targets.len(), 0.0);
    weights.extend(std::iter::repeat_n(0.0, k));
    mesh["weights"] = json!(weights);
    if !mesh["extras"].is_object() {
        mesh["extras"] = json!({});
    }
    mesh["extras"]["targetNames"] = json!(names);
    let node = export::install_face_mesh(&mut cd.doc.json, rig, mesh);
    if let Some(w) = node.get_mut("weights").and_then(|w| w.as_array_mut()) {
        w.extend(std::iter::repeat_n(json!(0.0), k));
    }
    let mesh_index = node["mesh"].as_u64().unwrap_or(0) as usize;
    let weight_scale: Vec<f64> = locals[layer.shapes.len()..]
        .iter()
        .map(|l| l.scale)
        .collect();
    let keys = layer.keys.as_ref().map(|keys| {
        let mut keys = keys.clone();
        for w in &mut keys.weights {
            w.iter_mut().zip(&weight_scale).for_each(|(x, s)| *x *= s);
        }
        keys
    });
    let mut notes: Vec<String> = split
        .unrefined
        .iter()
        .map(|&j| {
            let why = rig.parts.parts.iter().find(|p| p.primitive == j).map_or(
                "no skin triangle left after welding",
                |p| {
                    if p.skin {
                        "no skin triangle left after welding"
                    } else {
                        p.reason.describe()
                    }
                },
            );
            format!("primitive {j} of the face rides along unchanged ({why})")
        })
        .collect();
    if k > 0 {
        notes.extend(face_weights::install(&mut cd, rig, keys.as_ref(), k)?);
    }
    export::hoist_skinned_meshes(&mut cd.doc.json);
    cd.prune()?;
    let bytes = cd.to_glb(opts.compress)?;
    Ok(Written {
        bytes,
        mesh: mesh_index,
        weight_scale,
        refined_of_vertex: split.refined,
        notes,
    })
}

/// Check the layer's fields cover the refined skin and its shapes the rig's.
fn check_layer(layer: &Layer, map: &FaceMap, rig_targets: usize) -> anyhow::Result<()> {
    let n = map.refined_count();
    let fields = layer.shapes.iter().chain(&layer.wrinkles);
    if layer.base.len() != n
        || layer.base_normals.len() != n
        || fields
            .clone()
            .any(|t| t.positions.len() != n || t.normals.len() != n)
    {
        bail!("the wrinkle layer's fields do not cover the {n} refined vertices");
    }
    if layer.shapes.len() != rig_targets {
        bail!(
            "the layer carries {} shapes for a rig of {rig_targets}",
            layer.shapes.len()
        );
    }
    if let Some(k) = &layer.keys {
        if k.weights.iter().any(|w| w.len() != layer.wrinkles.len()) {
            bail!("the wrinkle weights do not match the wrinkle targets");
        }
    }
    let all = fields
        .flat_map(|t| t.positions.iter().chain(&t.normals))
        .chain(&layer.base)
        .all(|p| p.iter().all(|x| x.is_finite()));
    if !all {
        bail!("the wrinkle layer has a non-finite value; nothing was written");
    }
    Ok(())
}

/// Every target's deltas in local coordinates on the export vertices, with its storage.
fn local_targets(
    layer: &Layer,
    split: &SplitFace,
    local: &LocalFrames,
    precision: Precision,
) -> Vec<Local> {
    let kinds =
        layer
            .shapes
            .iter()
            .map(|_| Kind::Shape)
            .chain(
                layer
                    .wrinkles
                    .iter()
                    .enumerate()
                    .map(|(m, _)| match &layer.keys {
                        Some(k) => {
                            Kind::Mode(k.weights.iter().map(|w| w[m].abs()).fold(0.0, f64::max))
                        }
                        None => Kind::Corrective,
                    }),
            );
    layer
        .shapes
        .iter()
        .chain(&layer.wrinkles)
        .zip(kinds)
        .map(|(t, kind)| {
            let positions: Vec<Vector3<f64>> = split
                .refined
                .iter()
                .enumerate()
                .map(|(i, &v)| local.vector(i, &t.positions[v]))
                .collect();
            let normals: Vec<Vector3<f64>> = split
                .refined
                .iter()
                .enumerate()
                .map(|(i, &v)| local.normal_delta(i, &t.normals[v]))
                .collect();
            let (scale, pos, nrm) = choose(kind, &positions, &normals, precision);
            Local {
                positions,
                normals,
                scale,
                pos,
                nrm,
            }
        })
        .collect()
}

/// The rest surface in local coordinates on the export vertices.
struct Base {
    positions: Vec<Vector3<f64>>,
    normals: Vec<Vector3<f64>>,
    normal_store: Store,
}

impl Base {
    fn of(layer: &Layer, split: &SplitFace, local: &LocalFrames, precision: Precision) -> Self {
        let v = &split.refined;
        Self {
            positions: v
                .iter()
                .enumerate()
                .map(|(i, &r)| local.point(i, &layer.base[r]))
                .collect(),
            normals: v
                .iter()
                .enumerate()
                .map(|(i, &r)| local.normal(i, &layer.base_normals[r]))
                .collect(),
            normal_store: match precision {
                Precision::Float => Store::F32,
                Precision::Quantized => Store::I8,
            },
        }
    }
}

/// Write primitive `p` of the split face: its attributes, indices and targets; returns its
/// JSON (the original primitive's, with these).
fn write_primitive(
    cd: &mut CompactDocument,
    rig: &Rig,
    (split, p): (&SplitFace, &SplitPrimitive),
    base: &Base,
    locals: &[Local],
) -> anyhow::Result<Value> {
    let r = p.first..p.first + p.count;
    let mut attrs = carried_attributes(cd, rig, p, &split.origin[r.clone()])?;
    let pos = Vec3Data::f32_of(&base.positions[r.clone()]);
    attrs.insert("POSITION".into(), json!(cd.push_vec3(&pos, true)));
    let nrm = base.normal_store.data(&base.normals[r.clone()], 1.0);
    attrs.insert("NORMAL".into(), json!(cd.push_vec3(&nrm, false)));
    let indices = cd.push_triangles(&super::compact::codec_triangles(&p.triangles)?);
    let targets: Vec<Value> = locals
        .iter()
        .map(|l| {
            let t = TargetData {
                positions: l.pos.data(&l.positions[r.clone()], l.scale),
                normals: Some(l.nrm.data(&l.normals[r.clone()], l.scale)),
            };
            cd.push_target(&t)
        })
        .collect();
    let mut prim = rig.container.json["meshes"][rig.face().mesh]["primitives"][p.json].clone();
    prim["attributes"] = Value::Object(attrs);
    prim["indices"] = json!(indices);
    prim["mode"] = json!(4);
    prim["targets"] = json!(targets);
    if let Some(ext) = prim.get_mut("extensions").and_then(|e| e.as_object_mut()) {
        ext.remove("KHR_draco_mesh_compression");
        if ext.is_empty() {
            prim.as_object_mut().expect("object").remove("extensions");
        }
    }
    Ok(prim)
}

/// A primitive of the face that is not refined skin, as the artist wrote it (its attributes,
/// indices, material and morph targets unchanged), with `wrinkles` zero targets after the
/// rig's own (glTF gives every primitive of a mesh the same number of targets): each an
/// accessor of zeros with no buffer view.
fn riding_primitive(cd: &mut CompactDocument, json: &Value, wrinkles: usize) -> Value {
    let mut prim = json.clone();
    if wrinkles == 0 {
        return prim;
    }
    let count = json["attributes"]["POSITION"]
        .as_u64()
        .and_then(|a| cd.doc.json["accessors"][a as usize]["count"].as_u64())
        .unwrap_or(0);
    let zeros = cd.push_accessor(json!({ "componentType": 5126, "count": count,
        "type": "VEC3", "min": [0.0, 0.0, 0.0], "max": [0.0, 0.0, 0.0] }));
    let mut targets = prim["targets"].as_array().cloned().unwrap_or_default();
    targets.extend((0..wrinkles).map(|_| json!({ "POSITION": zeros })));
    prim["targets"] = json!(targets);
    prim
}

/// Primitive `p`'s own texture coordinates, colours and (skinned) influences at its export
/// vertices (`origin`, in the loaded face's numbering).
fn carried_attributes(
    cd: &mut CompactDocument,
    rig: &Rig,
    p: &SplitPrimitive,
    origin: &[VertexOrigin],
) -> anyhow::Result<serde_json::Map<String, Value>> {
    let face = rig.face();
    let skinned = matches!(face.to_world, VertexTransform::PerVertex(_));
    let pj = &rig.container.json["meshes"][face.mesh]["primitives"][p.json];
    let range = face
        .primitives
        .iter()
        .find(|s| s.json == p.json)
        .map(|s| (s.first, s.count))
        .context("primitive not loaded")?;
    let shifted: Vec<VertexOrigin> = origin
        .iter()
        .map(|o| VertexOrigin {
            vertices: o.vertices.map(|v| v - range.0),
            weights: o.weights,
        })
        .collect();
    let reader = super::accessor::AccessorReader::new(&rig.path, &rig.container);
    let read = |name: &str| -> anyhow::Result<Option<(Vec<f64>, usize)>> {
        match pj["attributes"][name].as_u64() {
            Some(a) => {
                let d = reader.read(a as usize)?;
                if d.count != range.1 {
                    bail!(
                        "{}: attribute {name} of primitive {} has {} entries for {} vertices",
                        rig.path.display(),
                        p.json,
                        d.count,
                        range.1
                    );
                }
                Ok(Some((d.data, d.components)))
            }
            None => Ok(None),
        }
    };
    let mut out = serde_json::Map::new();
    let names: Vec<String> = pj["attributes"]
        .as_object()
        .into_iter()
        .flatten()
        .map(|(k, _)| k.clone())
        .filter(|k| carry::carried(k, skinned))
        .collect();
    let mut sets = Vec::new();
    for name in &names {
        if let Some(s) = name.strip_prefix("JOINTS_") {
            if let (Some(j), Some(w)) = (read(name)?, read(&format!("WEIGHTS_{s}"))?) {
                sets.push((s.to_string(), j.0, w.0));
            }
        } else if !name.starts_with("WEIGHTS_") {
            if let Some((vals, comps)) = read(name)? {
                let v = carry::interpolate(&vals, comps, &shifted);
                out.insert(
                    name.clone(),
                    json!(cd.push_f32(&v, comps, Some(ARRAY_BUFFER))),
                );
            }
        }
    }
    let js: Vec<Vec<f64>> = sets.iter().map(|s| s.1.clone()).collect();
    let ws: Vec<Vec<f64>> = sets.iter().map(|s| s.2.clone()).collect();
    let (bj, bw) = carry::blend_influences(&js, &ws, &shifted);
    for (i, (s, _, _)) in sets.iter().enumerate() {
        out.insert(format!("JOINTS_{s}"), json!(cd.push_joints(&bj[i])));
        out.insert(
            format!("WEIGHTS_{s}"),
            json!(cd.push_f32(&bw[i], 4, Some(ARRAY_BUFFER))),
        );
    }
    Ok(out)
}
