//! Compact glTF output, as capture tools and `gltfpack -cc` write it: quantized attributes
//! (`KHR_mesh_quantization`), sparse morph targets, and every buffer view compressed with
//! `EXT_meshopt_compression` (no uncompressed fallback data, so both extensions are required).
//!
//! What [`rig_glb`] writes for a blend-shape rig (one mesh, its morph targets, a weights
//! animation):
//!
//! | data | storage |
//! | --- | --- |
//! | `POSITION` | normalized i16 VEC3 (8-byte stride); the node's uniform `scale` and `translation` dequantize it: world = t + s · q / 32767 (m) |
//! | `NORMAL` | normalized i8 VEC3 (4-byte stride) |
//! | indices | u16 (u32 past 65 535 vertices), meshopt `TRIANGLES` |
//! | target `POSITION` deltas | normalized i16 on the same grid as the positions (step s / 32767 m, exact in the node transform) |
//! | target `NORMAL` deltas | normalized i8 |
//! | targets that move less than half the vertices | sparse accessors (no dense data): the vertices whose quantized position or normal delta is non-zero, indices shared by both |
//! | animation times | f32 (s) |
//! | animation weights | normalized u16, one row of target weights per key (not compressed: see [`Codec::Plain`]) |
//!
//! [`CompactDocument`] is the reusable part: a [`Document`] whose buffer views each carry a
//! meshopt codec, laid out into a GLB with the compressed bytes in the binary chunk and a
//! data-less fallback buffer for the decoded views.

use super::glb_write::{Document, ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER};
use super::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use anyhow::bail;
use nalgebra::Vector3;
use serde_json::{json, Value};

/// Largest normalized i16 value (`SHORT` normalized maps q to q / 32767).
const I16_MAX: f64 = 32767.0;
/// Largest normalized i8 value.
const I8_MAX: f64 = 127.0;
/// Largest normalized u16 value.
const U16_MAX: f64 = 65535.0;

/// How a buffer view is compressed (`EXT_meshopt_compression` mode and element size).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// Mode `ATTRIBUTES`: elements of `stride` bytes (a multiple of 4, at most 256), deltas
    /// between consecutive elements byte by byte.
    Attributes {
        /// Bytes per element.
        stride: usize,
    },
    /// Mode `TRIANGLES`: a triangle list of 2- or 4-byte indices.
    Triangles {
        /// Bytes per index (2 or 4).
        index_size: usize,
    },
    /// Stored as is (no compression).
    Plain,
}

/// A glTF document whose buffer views are compressed with meshopt when written.
pub struct CompactDocument {
    /// The document (JSON and the uncompressed bytes of each view).
    pub doc: Document,
    /// The codec of each view (same order as `doc.view_bytes`).
    pub codecs: Vec<Codec>,
}

impl Default for CompactDocument {
    fn default() -> Self {
        Self::new()
    }
}

impl CompactDocument {
    /// An empty document.
    pub fn new() -> Self {
        Self {
            doc: Document::new(),
            codecs: Vec::new(),
        }
    }

    /// Append a view of `bytes` compressed with `codec`; `stride` is written as the view's
    /// `byteStride` (vertex attributes only), `target` as its GL target. Returns its index.
    pub fn push_view(
        &mut self,
        bytes: Vec<u8>,
        codec: Codec,
        stride: Option<usize>,
        target: Option<u32>,
    ) -> usize {
        let v = self.doc.push_view(bytes, target);
        if let Some(s) = stride {
            self.doc.json["bufferViews"][v]["byteStride"] = json!(s);
        }
        self.codecs.push(codec);
        v
    }

    /// Append an accessor (JSON as written); returns its index.
    pub fn push_accessor(&mut self, acc: Value) -> usize {
        if !self.doc.json["accessors"].is_array() {
            self.doc.json["accessors"] = json!([]);
        }
        let a = self.doc.json["accessors"]
            .as_array_mut()
            .expect("set above");
        a.push(acc);
        a.len() - 1
    }

    /// Compress every view and write the GLB: compressed bytes in buffer 0 (the binary chunk),
    /// decoded layouts in buffer 1, a fallback buffer without data. A view that does not
    /// shrink is stored plainly in buffer 0. `EXT_meshopt_compression` is used and required.
    pub fn to_glb(mut self) -> anyhow::Result<Vec<u8>> {
        let mut bin: Vec<u8> = Vec::new();
        let mut fallback_len = 0usize;
        let views = std::mem::take(&mut self.doc.view_bytes);
        for (v, (bytes, codec)) in views.iter().zip(&self.codecs).enumerate() {
            let packed = encode(bytes, *codec)?;
            align4(&mut bin);
            let view = &mut self.doc.json["bufferViews"][v];
            view["byteLength"] = json!(bytes.len());
            match packed {
                Some((data, stride, count, mode)) => {
                    fallback_len = fallback_len.next_multiple_of(4);
                    view["buffer"] = json!(1);
                    view["byteOffset"] = json!(fallback_len);
                    fallback_len += bytes.len();
                    view["extensions"] = json!({ "EXT_meshopt_compression": {
                        "buffer": 0, "byteOffset": bin.len(), "byteLength": data.len(),
                        "byteStride": stride, "count": count, "mode": mode } });
                    bin.extend_from_slice(&data);
                }
                None => {
                    view["buffer"] = json!(0);
                    view["byteOffset"] = json!(bin.len());
                    bin.extend_from_slice(bytes);
                }
            }
        }
        align4(&mut bin);
        let j = &mut self.doc.json;
        let mut buffers = vec![json!({ "byteLength": bin.len() })];
        if fallback_len > 0 {
            buffers.push(json!({ "byteLength": fallback_len,
                "extensions": { "EXT_meshopt_compression": { "fallback": true } } }));
            for key in ["extensionsUsed", "extensionsRequired"] {
                add_extension(j, key, "EXT_meshopt_compression");
            }
        }
        j["buffers"] = json!(buffers);
        Ok(glb(j, &bin))
    }
}

/// Append `name` to the string list `json[key]` (created when absent), keeping it sorted.
pub fn add_extension(json: &mut Value, key: &str, name: &str) {
    if !json[key].is_array() {
        json[key] = json!([]);
    }
    let a = json[key].as_array_mut().expect("set above");
    if !a.iter().any(|e| e == name) {
        a.push(json!(name));
        a.sort_by(|x, y| x.as_str().cmp(&y.as_str()));
    }
}

fn align4(b: &mut Vec<u8>) {
    while b.len() % 4 != 0 {
        b.push(0);
    }
}

/// A compressed view: bytes, element stride, element count and meshopt mode name.
type Packed = (Vec<u8>, usize, usize, &'static str);

/// The compressed view, or `None` when compression does not shrink it (or its length does not
/// fit the codec, or the codec is [`Codec::Plain`]).
fn encode(bytes: &[u8], codec: Codec) -> anyhow::Result<Option<Packed>> {
    let out = match codec {
        Codec::Attributes { stride } => {
            if stride == 0 || stride % 4 != 0 || stride > 256 {
                bail!("meshopt ATTRIBUTES stride {stride} must be a multiple of 4 in 4..=256");
            }
            if bytes.is_empty() || bytes.len() % stride != 0 {
                return Ok(None);
            }
            let count = bytes.len() / stride;
            let mut buf = vec![0u8; unsafe_bound(count, stride)];
            // SAFETY: `buf` holds the bound meshopt asks for; `bytes` holds count × stride
            // bytes; the stride was checked above (multiple of 4, at most 256).
            let size = unsafe {
                meshopt::ffi::meshopt_encodeVertexBufferLevel(
                    buf.as_mut_ptr(),
                    buf.len(),
                    bytes.as_ptr().cast(),
                    count,
                    stride,
                    2,
                    0,
                )
            };
            if size == 0 {
                bail!("meshopt could not encode a view of {count} × {stride} bytes");
            }
            buf.truncate(size);
            (buf, stride, count, "ATTRIBUTES")
        }
        Codec::Triangles { index_size } => {
            let indices: Vec<u32> = match index_size {
                2 => bytes
                    .chunks_exact(2)
                    .map(|c| u16::from_le_bytes([c[0], c[1]]) as u32)
                    .collect(),
                4 => bytes
                    .chunks_exact(4)
                    .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
                    .collect(),
                _ => bail!("meshopt TRIANGLES index size {index_size} must be 2 or 4"),
            };
            if indices.is_empty() || indices.len() % 3 != 0 {
                return Ok(None);
            }
            let vertices = indices.iter().copied().max().unwrap_or(0) as usize + 1;
            let data = meshopt::encode_index_buffer(&indices, vertices)?;
            (data, index_size, indices.len(), "TRIANGLES")
        }
        Codec::Plain => return Ok(None),
    };
    Ok((out.0.len() < bytes.len()).then_some(out))
}

/// meshopt's bound on the encoded size of `count` elements of `stride` bytes.
fn unsafe_bound(count: usize, stride: usize) -> usize {
    // SAFETY: a pure size computation.
    unsafe { meshopt::ffi::meshopt_encodeVertexBufferBound(count, stride) }
}

/// A GLB container of `json` and the binary chunk `bin` (already 4-byte aligned).
fn glb(json: &mut Value, bin: &[u8]) -> Vec<u8> {
    let obj = json.as_object_mut().expect("document is an object");
    obj.retain(|_, v| !v.is_null());
    let mut js = serde_json::to_vec(&json).expect("JSON serialises");
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let total = 12 + 8 + js.len() + 8 + bin.len();
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
    out.extend_from_slice(b"BIN\0");
    out.extend_from_slice(bin);
    out
}

/// The position grid of a quantized mesh: world = `translation` + `scale` · q / 32767 (m)
/// for normalized i16 q, with `translation` and `scale` exact f32 values (they are the node's
/// TRS, so a loader's f32 transform dequantizes exactly as the f64 one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantization {
    /// Centre of the bounding box (m), rounded to f32.
    pub translation: Vector3<f64>,
    /// Half the largest bounding-box extent, or the largest delta component if larger (m),
    /// rounded up to an f32.
    pub scale: f64,
}

/// `x` rounded to the nearest f32 (as f64).
fn f32_round(x: f64) -> f64 {
    x as f32 as f64
}

impl Quantization {
    /// The grid for `mesh` and the deltas of `targets` (every delta component must fit in
    /// ±scale). Errors on an empty mesh.
    pub fn of(mesh: &TriMesh, targets: &[MorphTarget]) -> anyhow::Result<Self> {
        let Some((lo, hi)) = mesh.bounding_box() else {
            bail!("the mesh has no vertices to quantize");
        };
        let c = (lo + hi) / 2.0;
        let translation = Vector3::new(f32_round(c.x), f32_round(c.y), f32_round(c.z));
        let mut half: f64 = mesh
            .positions
            .iter()
            .map(|p| (p - translation).abs().max())
            .fold(0.0, f64::max);
        for t in targets {
            for d in &t.positions {
                half = half.max(d.abs().max());
            }
        }
        let half = half.max(1e-9);
        let mut s = half as f32;
        if (s as f64) < half {
            s = f32::from_bits(s.to_bits() + 1);
        }
        Ok(Self {
            translation,
            scale: s as f64,
        })
    }

    /// The grid step (m): the largest position or delta error is half of it per component.
    pub fn step(&self) -> f64 {
        self.scale / I16_MAX
    }

    /// Quantized position (normalized i16 components).
    pub fn point(&self, p: &Vector3<f64>) -> [i16; 3] {
        self.delta(&(p - self.translation))
    }

    /// Quantized delta on the same grid (normalized i16 components).
    pub fn delta(&self, d: &Vector3<f64>) -> [i16; 3] {
        let q = |x: f64| (x / self.scale * I16_MAX).round().clamp(-I16_MAX, I16_MAX) as i16;
        [q(d.x), q(d.y), q(d.z)]
    }
}

/// Normalized i8 components of a normal or normal delta (clamped to [−1, 1]).
fn unit_i8(n: &Vector3<f64>) -> [i8; 3] {
    let q = |x: f64| (x * I8_MAX).round().clamp(-I8_MAX, I8_MAX) as i8;
    [q(n.x), q(n.y), q(n.z)]
}

/// Min and max per component of quantized values, as JSON integer arrays (glTF bounds of
/// normalized accessors are the stored integers, not the normalized values).
fn min_max<const N: usize, T: Copy + Into<i64>>(q: &[[T; N]]) -> (Value, Value) {
    let mut lo = [i64::MAX; N];
    let mut hi = [i64::MIN; N];
    for e in q {
        for k in 0..N {
            let v = e[k].into();
            lo[k] = lo[k].min(v);
            hi[k] = hi[k].max(v);
        }
    }
    (json!(lo.to_vec()), json!(hi.to_vec()))
}

/// Bytes of i16 VEC3 elements padded to 8 bytes each (vertex attribute layout).
fn i16x3_padded(q: &[[i16; 3]]) -> Vec<u8> {
    q.iter()
        .flat_map(|e| [e[0], e[1], e[2], 0])
        .flat_map(i16::to_le_bytes)
        .collect()
}

/// Bytes of i8 VEC3 elements padded to 4 bytes each.
fn i8x3_padded(q: &[[i8; 3]]) -> Vec<u8> {
    q.iter()
        .flat_map(|e| [e[0], e[1], e[2], 0])
        .map(|b| b as u8)
        .collect()
}

impl CompactDocument {
    /// A dense normalized i16 VEC3 vertex attribute (8-byte stride); returns the accessor.
    fn push_i16x3(&mut self, q: &[[i16; 3]]) -> usize {
        let view = self.push_view(
            i16x3_padded(q),
            Codec::Attributes { stride: 8 },
            Some(8),
            Some(ARRAY_BUFFER),
        );
        let (min, max) = min_max(q);
        self.push_accessor(
            json!({ "bufferView": view, "componentType": 5122, "normalized": true,
            "count": q.len(), "type": "VEC3", "min": min, "max": max }),
        )
    }

    /// A dense normalized i8 VEC3 vertex attribute (4-byte stride); returns the accessor.
    fn push_i8x3(&mut self, q: &[[i8; 3]]) -> usize {
        let view = self.push_view(
            i8x3_padded(q),
            Codec::Attributes { stride: 4 },
            Some(4),
            Some(ARRAY_BUFFER),
        );
        self.push_accessor(
            json!({ "bufferView": view, "componentType": 5120, "normalized": true,
            "count": q.len(), "type": "VEC3" }),
        )
    }

    /// A triangle index accessor (u16 below 65 535 vertices, else u32), meshopt `TRIANGLES`.
    fn push_triangles(&mut self, triangles: &[[usize; 3]]) -> usize {
        let max = triangles.iter().flatten().copied().max().unwrap_or(0);
        let (bytes, ct, size): (Vec<u8>, u32, usize) = if max < 65535 {
            let b = triangles
                .iter()
                .flatten()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            (b, 5123, 2)
        } else {
            let b = triangles
                .iter()
                .flatten()
                .flat_map(|&i| (i as u32).to_le_bytes())
                .collect();
            (b, 5125, 4)
        };
        let view = self.push_view(
            bytes,
            Codec::Triangles { index_size: size },
            None,
            Some(ELEMENT_ARRAY_BUFFER),
        );
        self.push_accessor(json!({ "bufferView": view, "componentType": ct,
            "count": triangles.len() * 3, "type": "SCALAR" }))
    }
}

/// One morph target's quantized deltas, dense or sparse.
struct QuantTarget {
    positions: Vec<[i16; 3]>,
    normals: Option<Vec<[i8; 3]>>,
}

impl QuantTarget {
    /// Vertices whose quantized position or normal delta is non-zero, padded with unmoved
    /// vertices to a multiple of 4 (so the sparse views fit 12-byte meshopt elements).
    fn support(&self) -> Vec<usize> {
        let n = self.positions.len();
        let moved = |i: usize| {
            self.positions[i] != [0; 3] || self.normals.as_ref().is_some_and(|v| v[i] != [0; 3])
        };
        let mut s: Vec<usize> = (0..n).filter(|&i| moved(i)).collect();
        let mut extra = (4 - s.len() % 4) % 4;
        let mut i = 0;
        let mut pad = Vec::new();
        while extra > 0 && i < n {
            if !moved(i) {
                pad.push(i);
                extra -= 1;
            }
            i += 1;
        }
        s.extend(pad);
        s.sort_unstable();
        s
    }
}

impl CompactDocument {
    /// The target's accessors as a glTF target object: sparse when it moves fewer than half
    /// the vertices, else dense.
    fn push_target(&mut self, t: &QuantTarget) -> Value {
        let n = t.positions.len();
        let support = t.support();
        if support.len() * 2 >= n || support.len() % 4 != 0 {
            let mut o = json!({ "POSITION": self.push_i16x3(&t.positions) });
            if let Some(nq) = &t.normals {
                o["NORMAL"] = json!(self.push_i8x3(nq));
            }
            return o;
        }
        let m = support.len();
        if m == 0 {
            let zero = json!([0, 0, 0]);
            let pa = self.push_accessor(json!({ "componentType": 5122, "normalized": true,
                "count": n, "type": "VEC3", "min": zero, "max": zero }));
            return json!({ "POSITION": pa });
        }
        let (ibytes, ict): (Vec<u8>, u32) = if n <= 65536 {
            let b = support
                .iter()
                .flat_map(|&i| (i as u16).to_le_bytes())
                .collect();
            (b, 5123)
        } else {
            let b = support
                .iter()
                .flat_map(|&i| (i as u32).to_le_bytes())
                .collect();
            (b, 5125)
        };
        let index_view = self.push_view(ibytes, Codec::Attributes { stride: 4 }, None, None);
        let pvals: Vec<u8> = support
            .iter()
            .flat_map(|&i| t.positions[i])
            .flat_map(i16::to_le_bytes)
            .collect();
        let pview = self.push_view(pvals, Codec::Attributes { stride: 12 }, None, None);
        let (min, max) = min_max(&t.positions);
        let sparse = |values: usize| {
            json!({ "count": m, "indices": { "bufferView": index_view, "componentType": ict },
                    "values": { "bufferView": values } })
        };
        let pa = self.push_accessor(json!({ "componentType": 5122, "normalized": true,
            "count": n, "type": "VEC3", "min": min, "max": max, "sparse": sparse(pview) }));
        let mut o = json!({ "POSITION": pa });
        if let Some(nq) = &t.normals {
            let nvals: Vec<u8> = support
                .iter()
                .flat_map(|&i| nq[i])
                .map(|b| b as u8)
                .collect();
            let nview = self.push_view(nvals, Codec::Attributes { stride: 12 }, None, None);
            let na = self.push_accessor(json!({ "componentType": 5120, "normalized": true,
                "count": n, "type": "VEC3", "sparse": sparse(nview) }));
            o["NORMAL"] = json!(na);
        }
        o
    }

    /// A LINEAR weights animation of node 0: f32 times (s), normalized u16 weights (one row of
    /// `targets` weights per key, each clamped to [0, 1]).
    fn push_weights_animation(&mut self, keys: &WeightKeys, targets: usize) {
        let times: Vec<u8> = keys
            .times
            .iter()
            .flat_map(|&t| (t as f32).to_le_bytes())
            .collect();
        let tview = self.push_view(times, Codec::Attributes { stride: 4 }, None, None);
        let (t0, t1) = (
            keys.times[0] as f32,
            keys.times[keys.times.len() - 1] as f32,
        );
        let input = self.push_accessor(json!({ "bufferView": tview, "componentType": 5126,
            "count": keys.times.len(), "type": "SCALAR", "min": [t0], "max": [t1] }));
        let w: Vec<u8> = keys
            .weights
            .iter()
            .flatten()
            .map(|&x| (x.clamp(0.0, 1.0) * U16_MAX).round() as u16)
            .flat_map(u16::to_le_bytes)
            .collect();
        // Stored plainly: furrow's loader reads a view without `byteStride` at the meshopt
        // element size (`io::accessor`), so a compressed view must use the accessor's own
        // element size, and 2-byte weights are not a multiple of 4.
        let wview = self.push_view(w, Codec::Plain, None, None);
        let output = self.push_accessor(json!({ "bufferView": wview, "componentType": 5123,
            "normalized": true, "count": keys.times.len() * targets, "type": "SCALAR" }));
        self.doc.json["animations"] = json!([{
            "name": "performance",
            "samplers": [{ "input": input, "output": output, "interpolation": "LINEAR" }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }],
        }]);
    }
}

/// Check the rig's arrays agree (deltas per vertex, a weight per target per key).
fn check_rig(mesh: &TriMesh, targets: &[MorphTarget], keys: &WeightKeys) -> anyhow::Result<()> {
    let n = mesh.positions.len();
    if n == 0 || mesh.triangles.is_empty() {
        bail!("the mesh has no triangles to write");
    }
    for t in targets {
        let bad_normals = t.normals.as_ref().is_some_and(|v| v.len() != n);
        if t.positions.len() != n || bad_normals {
            bail!(
                "target {} has deltas for {} of {n} vertices",
                t.name,
                t.positions.len()
            );
        }
    }
    super::export::check_weight_keys(keys, targets.len())?;
    let all_finite = mesh
        .positions
        .iter()
        .all(|p| p.iter().all(|x| x.is_finite()))
        && targets
            .iter()
            .all(|t| t.positions.iter().all(|p| p.iter().all(|x| x.is_finite())));
    if !all_finite {
        bail!("the mesh or a target has a non-finite value (NaN or infinity)");
    }
    Ok(())
}

/// A blend-shape rig as a compact GLB (see the module table): one node named `name` carrying
/// the quantization (translation, uniform scale), one mesh with `targets` (names in
/// `extras.targetNames`), normals computed from `mesh`, and a linear weights animation
/// "performance" from `keys` (omitted when there are no keys). Positions and deltas in metres.
pub fn rig_glb(
    name: &str,
    mesh: &TriMesh,
    targets: &[MorphTarget],
    keys: &WeightKeys,
) -> anyhow::Result<Vec<u8>> {
    check_rig(mesh, targets, keys)?;
    let qz = Quantization::of(mesh, targets)?;
    let mut cd = CompactDocument::new();
    let pos: Vec<[i16; 3]> = mesh.positions.iter().map(|p| qz.point(p)).collect();
    let nrm: Vec<[i8; 3]> = mesh.vertex_normals().iter().map(unit_i8).collect();
    let pa = cd.push_i16x3(&pos);
    let na = cd.push_i8x3(&nrm);
    let ia = cd.push_triangles(&mesh.triangles);
    let tj: Vec<Value> = targets
        .iter()
        .map(|t| {
            let q = QuantTarget {
                positions: t.positions.iter().map(|d| qz.delta(d)).collect(),
                normals: t.normals.as_ref().map(|v| v.iter().map(unit_i8).collect()),
            };
            cd.push_target(&q)
        })
        .collect();
    let mut prim = json!({ "attributes": { "POSITION": pa, "NORMAL": na }, "indices": ia,
        "material": 0, "mode": 4 });
    let mut m = json!({ "name": name, "primitives": [] });
    if !targets.is_empty() {
        prim["targets"] = json!(tj);
        m["weights"] = json!(vec![0.0; targets.len()]);
        m["extras"] = json!({ "targetNames": targets.iter().map(|t| &t.name).collect::<Vec<_>>() });
    }
    m["primitives"] = json!([prim]);
    let j = &mut cd.doc.json;
    j["materials"] = json!([{ "name": "skin", "pbrMetallicRoughness": {
        "baseColorFactor": [0.87, 0.68, 0.58, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6 } }]);
    j["meshes"] = json!([m]);
    let t = qz.translation;
    j["nodes"] = json!([{ "name": name, "mesh": 0, "translation": [t.x, t.y, t.z],
        "scale": [qz.scale, qz.scale, qz.scale] }]);
    j["scenes"] = json!([{ "nodes": [0] }]);
    j["scene"] = json!(0);
    for key in ["extensionsUsed", "extensionsRequired"] {
        add_extension(j, key, "KHR_mesh_quantization");
    }
    if !keys.times.is_empty() && !targets.is_empty() {
        cd.push_weights_animation(keys, targets.len());
    }
    cd.to_glb()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::accessor::AccessorReader;
    use crate::io::load::{load_bytes, LoadOptions};
    use std::path::Path;

    /// A 9 × 7 wavy sheet 8 × 6 cm with a dense target (every vertex), a sparse one (three
    /// vertices) and an empty one, and five weight keys.
    pub(crate) fn small_rig() -> (TriMesh, Vec<MorphTarget>, WeightKeys) {
        let (nx, ny) = (9, 7);
        let mut positions = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (0.01 * i as f64, 0.01 * j as f64);
                positions.push(Vector3::new(x + 0.3, y - 0.1, 0.004 * (40.0 * x).sin()));
            }
        }
        let mut triangles = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                let a = j * nx + i;
                triangles.push([a, a + 1, a + nx + 1]);
                triangles.push([a, a + nx + 1, a + nx]);
            }
        }
        let mesh = TriMesh::new(positions, triangles);
        let n = mesh.vertex_count();
        let dense: Vec<Vector3<f64>> = mesh
            .positions
            .iter()
            .map(|p| Vector3::new(0.002 * p.y, -0.001, 0.003 * (p.x * 50.0).cos()))
            .collect();
        let mut few = vec![Vector3::zeros(); n];
        few[10] = Vector3::new(0.001, 0.0, 0.0);
        few[31] = Vector3::new(0.0, -0.0023, 0.0004);
        few[32] = Vector3::new(0.0, 0.0, 0.005);
        let n0 = mesh.vertex_normals();
        let normals_of = |d: &[Vector3<f64>]| mesh.normal_deltas(&n0, d);
        let targets = vec![
            MorphTarget {
                name: "dense".into(),
                normals: Some(normals_of(&dense)),
                positions: dense,
            },
            MorphTarget {
                name: "few".into(),
                normals: Some(normals_of(&few)),
                positions: few,
            },
            MorphTarget {
                name: "none".into(),
                positions: vec![Vector3::zeros(); n],
                normals: None,
            },
        ];
        let keys = WeightKeys {
            times: vec![0.0, 0.1, 0.2, 0.3, 0.4],
            weights: vec![
                vec![0.0, 0.0, 0.0],
                vec![0.25, 0.5, 0.0],
                vec![1.0, 0.123_456, 0.0],
                vec![0.7, 1.0, 0.0],
                vec![0.0, 0.01, 0.0],
            ],
        };
        (mesh, targets, keys)
    }

    #[test]
    fn round_trip_within_the_quantization_step() {
        let (mesh, targets, keys) = small_rig();
        let bytes = rig_glb("sheet", &mesh, &targets, &keys).expect("writes");
        let qz = Quantization::of(&mesh, &targets).expect("grid");
        let rig =
            load_bytes(Path::new("sheet.glb"), &bytes, &LoadOptions::default()).expect("loads");
        let f = rig.face();
        // Half a grid step per component, plus f32 rounding of the node's TRS product.
        let tol = 0.5 * qz.step() + 1e-7 * qz.scale;
        for (a, b) in f.positions.iter().zip(&mesh.positions) {
            assert!((a - b).abs().max() <= tol, "position {a} vs {b}, tol {tol}");
        }
        assert_eq!(f.targets.len(), 3);
        for (lt, t) in f.targets.iter().zip(&targets) {
            assert_eq!(lt.name, t.name);
            for (a, b) in lt.positions.iter().zip(&t.positions) {
                assert!((a - b).abs().max() <= tol, "{}: delta {a} vs {b}", t.name);
            }
        }
        // Normals: i8 components (half-step 0.5 / 127) then renormalised.
        for (a, b) in f
            .normals
            .as_ref()
            .expect("normals")
            .iter()
            .zip(mesh.vertex_normals())
        {
            assert!((a - b).norm() < 0.01, "normal {a} vs {b}");
        }
        // Normal deltas in the file's local space, within half an i8 step.
        let reader = AccessorReader::new(&rig.path, &rig.container);
        let tj = &rig.container.json["meshes"][0]["primitives"][0]["targets"];
        for (k, t) in targets.iter().enumerate().take(2) {
            let d = reader
                .read(tj[k]["NORMAL"].as_u64().expect("NORMAL") as usize)
                .expect("reads");
            for (i, b) in t.normals.as_ref().expect("normals").iter().enumerate() {
                let e = (d.vec3(i) - b).abs().max();
                assert!(
                    e <= 0.5 / 127.0 + 1e-9 || b.abs().max() > 1.0,
                    "{}: {e}",
                    t.name
                );
            }
        }
        let track = rig.track.as_ref().expect("weights animation");
        for (time, w) in keys.times.iter().zip(&keys.weights) {
            for (a, b) in track.sample(*time).iter().zip(w) {
                assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-6, "weight {a} vs {b}");
            }
        }
    }

    #[test]
    fn targets_that_move_few_vertices_are_sparse_and_everything_is_compressed() {
        let (mesh, targets, keys) = small_rig();
        let bytes = rig_glb("sheet", &mesh, &targets, &keys).expect("writes");
        let rig =
            load_bytes(Path::new("sheet.glb"), &bytes, &LoadOptions::default()).expect("loads");
        let j = &rig.container.json;
        let tj = &j["meshes"][0]["primitives"][0]["targets"];
        let acc =
            |t: usize, k: &str| &j["accessors"][tj[t][k].as_u64().expect("accessor") as usize];
        assert!(
            acc(0, "POSITION")["sparse"].is_null(),
            "the dense target is dense"
        );
        let sparse = &acc(1, "POSITION")["sparse"];
        // Vertices 10, 31, 32 and the normals of their neighbours, padded to a multiple of 4.
        let count = sparse["count"].as_u64().expect("sparse count");
        assert!(
            count >= 3 && count % 4 == 0 && count < 40,
            "sparse count {count}"
        );
        assert!(acc(1, "POSITION")["bufferView"].is_null());
        assert_eq!(acc(1, "NORMAL")["sparse"]["indices"], sparse["indices"]);
        assert_eq!(acc(0, "POSITION")["componentType"], 5122);
        assert_eq!(acc(0, "NORMAL")["componentType"], 5120);
        for v in j["bufferViews"].as_array().expect("views") {
            assert!(v["extensions"]["EXT_meshopt_compression"].is_object() || v["buffer"] == 0);
        }
        for key in ["extensionsUsed", "extensionsRequired"] {
            assert_eq!(
                j[key],
                json!(["EXT_meshopt_compression", "KHR_mesh_quantization"])
            );
        }
        assert_eq!(
            j["buffers"][1]["extensions"]["EXT_meshopt_compression"]["fallback"],
            true
        );
    }

    #[test]
    fn quantization_grid_is_exact_in_f32_and_covers_the_mesh() {
        let (mesh, targets, _) = small_rig();
        let q = Quantization::of(&mesh, &targets).expect("grid");
        assert_eq!(q.scale, q.scale as f32 as f64);
        assert_eq!(q.translation.x, q.translation.x as f32 as f64);
        // Half the largest extent (8 cm wide sheet): at least 4 cm, at most a hair above.
        assert!(
            q.scale >= 0.04 && q.scale < 0.04 * (1.0 + 1e-6),
            "scale {}",
            q.scale
        );
    }
}
