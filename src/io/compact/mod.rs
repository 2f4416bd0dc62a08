//! Compact glTF output, as capture tools and `gltfpack -cc` write it: quantized attributes
//! (`KHR_mesh_quantization`), sparse morph targets, and buffer views compressed with
//! `EXT_meshopt_compression` (no uncompressed fallback data, so both extensions are required
//! when used). This is furrow's one writer of such data: the capture-shaped rig
//! ([`rig::rig_glb`]), the multi-mesh avatar scenes ([`scene::scene_glb`], which also writes
//! them plainly in floats) and the wrinkle layer export (`io::layer`) all write through it.
//!
//! [`CompactDocument`] is a [`Document`] whose buffer views each carry a meshopt codec, laid
//! out into a GLB either plainly (every view in the binary chunk) or compressed (the
//! compressed bytes in the binary chunk and a data-less fallback buffer for the decoded
//! views). [`targets`] stores morph targets (float, normalized i16 or i8, dense or sparse);
//! [`rig`] writes a whole blend-shape rig; [`scene`] a scene of several meshes, skins and
//! materials.

pub mod rig;
pub mod scene;
pub mod targets;

pub use rig::{rig_glb, Quantization};
pub use targets::{TargetData, Vec3Data};

use super::glb_write::{Document, ELEMENT_ARRAY_BUFFER};
use anyhow::bail;
use serde_json::{json, Value};

/// How a buffer view is compressed (`EXT_meshopt_compression` mode and element size).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Codec {
    /// Mode `ATTRIBUTES`: elements of `stride` bytes (a multiple of 4, at most 256), deltas
    /// between consecutive elements byte by byte.
    Attributes {
        /// Bytes per element.
        stride: usize,
    },
    /// Mode `ATTRIBUTES` with filter `EXPONENTIAL`: f32 VEC3 elements (12 bytes) stored as
    /// 8-bit exponent and `bits`-bit mantissa per component. Lossless only for values already
    /// on that grid ([`exp_round`]): writers round first, so the compressed file decodes to the
    /// plain one's values.
    Exponential {
        /// Mantissa bits (1..=24).
        bits: i32,
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

    /// A document of the views of `doc`, every one stored as is ([`Codec::Plain`]).
    pub fn from_document(doc: Document) -> Self {
        let codecs = vec![Codec::Plain; doc.view_bytes.len()];
        Self { doc, codecs }
    }

    /// Append a float accessor of `components`-vectors (see [`Document::push_f32`]), its view
    /// compressed as `ATTRIBUTES` elements of one vector; returns the accessor.
    pub fn push_f32(&mut self, values: &[f64], components: usize, target: Option<u32>) -> usize {
        let a = self.doc.push_f32(values, components, target);
        self.codecs.push(Codec::Attributes {
            stride: 4 * components,
        });
        a
    }

    /// A JOINTS accessor (u16 VEC4) of joint indices `j` (4 per vertex), its view compressed
    /// as 8-byte elements; returns the accessor.
    pub fn push_joints(&mut self, j: &[f64]) -> usize {
        let a = crate::io::carry::push_joints(&mut self.doc, j);
        self.codecs.push(Codec::Attributes { stride: 8 });
        a
    }

    /// A triangle index accessor (u16 below 65 535 vertices, else u32), meshopt `TRIANGLES`.
    pub fn push_triangles(&mut self, triangles: &[[usize; 3]]) -> usize {
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

    /// Drop accessors and views that nothing references (see [`Document::prune`]), with
    /// their codecs.
    pub fn prune(&mut self) -> anyhow::Result<()> {
        let used = self.doc.prune()?;
        let codecs = std::mem::take(&mut self.codecs);
        self.codecs = codecs
            .into_iter()
            .zip(used)
            .filter(|(_, u)| *u)
            .map(|(c, _)| c)
            .collect();
        Ok(())
    }

    /// Write the GLB: with `compress`, see [`Self::into_compressed_glb`]; without, every view
    /// as is in the binary chunk (the same document, decoded).
    pub fn to_glb(mut self, compress: bool) -> anyhow::Result<Vec<u8>> {
        if compress {
            self.into_compressed_glb()
        } else {
            Ok(self.doc.to_glb())
        }
    }

    /// Compress every view and write the GLB: compressed bytes in buffer 0 (the binary chunk),
    /// decoded layouts in buffer 1, a fallback buffer without data. A view that does not
    /// shrink is stored plainly in buffer 0. `EXT_meshopt_compression` is used and required.
    fn into_compressed_glb(mut self) -> anyhow::Result<Vec<u8>> {
        let mut bin: Vec<u8> = Vec::new();
        let mut fallback_len = 0usize;
        let views = std::mem::take(&mut self.doc.view_bytes);
        for (v, (bytes, codec)) in views.iter().zip(&self.codecs).enumerate() {
            let packed = encode(bytes, *codec)?;
            align4(&mut bin);
            let view = &mut self.doc.json["bufferViews"][v];
            view["byteLength"] = json!(bytes.len());
            match packed {
                Some((data, stride, count, mode, filter)) => {
                    fallback_len = fallback_len.next_multiple_of(4);
                    view["buffer"] = json!(1);
                    view["byteOffset"] = json!(fallback_len);
                    fallback_len += bytes.len();
                    let mut ext = json!({ "buffer": 0, "byteOffset": bin.len(),
                        "byteLength": data.len(), "byteStride": stride, "count": count,
                        "mode": mode });
                    if let Some(f) = filter {
                        ext["filter"] = json!(f);
                    }
                    view["extensions"] = json!({ "EXT_meshopt_compression": ext });
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

/// A compressed view: bytes, element stride, element count, meshopt mode and filter names.
type Packed = (Vec<u8>, usize, usize, &'static str, Option<&'static str>);

/// f32 VEC3 values rounded to the `EXPONENTIAL` filter's grid of `bits` mantissa bits per
/// component (each component its own exponent): what a meshopt decoder returns for them.
pub fn exp_round(values: &[[f32; 3]], bits: i32) -> Vec<[f32; 3]> {
    let mut e = meshopt::encode_filter_exp(values, bits, meshopt::EncodeExpMode::Separate);
    meshopt::decode_filter_exp(&mut e);
    e.iter().map(|v| v.map(f32::from_bits)).collect()
}

/// `triangles` as meshopt's `TRIANGLES` codec returns them: it may rotate a triangle's
/// corners (keeping its winding) to code it shorter. A writer that stores these compresses
/// them to a stream that decodes to exactly what its uncompressed file holds.
pub fn codec_triangles(triangles: &[[usize; 3]]) -> anyhow::Result<Vec<[usize; 3]>> {
    let idx: Vec<u32> = triangles.iter().flatten().map(|&i| i as u32).collect();
    if idx.is_empty() {
        return Ok(Vec::new());
    }
    let vertices = idx.iter().copied().max().unwrap_or(0) as usize + 1;
    let coded = meshopt::encode_index_buffer(&idx, vertices)?;
    let back: Vec<u32> = meshopt::decode_index_buffer(&coded, idx.len())?;
    Ok(back
        .chunks_exact(3)
        .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
        .collect())
}

/// meshopt `ATTRIBUTES` encoding (version 0, as `EXT_meshopt_compression` specifies) of
/// `count` elements of `stride` bytes.
fn encode_attributes(bytes: &[u8], count: usize, stride: usize) -> anyhow::Result<Vec<u8>> {
    let mut buf = vec![0u8; unsafe_bound(count, stride)];
    // SAFETY: `buf` holds the bound meshopt asks for; `bytes` holds count × stride bytes; the
    // callers check the stride (a multiple of 4, at most 256).
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
    Ok(buf)
}

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
            let buf = encode_attributes(bytes, count, stride)?;
            (buf, stride, count, "ATTRIBUTES", None)
        }
        Codec::Exponential { bits } => {
            if bytes.is_empty() || bytes.len() % 12 != 0 {
                return Ok(None);
            }
            let values: Vec<[f32; 3]> = bytes
                .chunks_exact(12)
                .map(|c| {
                    std::array::from_fn(|k| {
                        f32::from_le_bytes(c[4 * k..4 * k + 4].try_into().expect("4 bytes"))
                    })
                })
                .collect();
            if exp_round(&values, bits) != values {
                // Not on the filter's grid: compressing it filtered would change it.
                return encode(bytes, Codec::Attributes { stride: 12 });
            }
            let raw: Vec<u8> =
                meshopt::encode_filter_exp(&values, bits, meshopt::EncodeExpMode::Separate)
                    .iter()
                    .flatten()
                    .flat_map(|x| x.to_le_bytes())
                    .collect();
            let buf = encode_attributes(&raw, values.len(), 12)?;
            (buf, 12, values.len(), "ATTRIBUTES", Some("EXPONENTIAL"))
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
            (data, index_size, indices.len(), "TRIANGLES", None)
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

/// A GLB container of `json` (null members dropped) and the binary chunk `bin` (already
/// 4-byte aligned).
fn glb(json: &mut Value, bin: &[u8]) -> Vec<u8> {
    let obj = json.as_object_mut().expect("document is an object");
    obj.retain(|_, v| !v.is_null());
    super::glb_write::glb_container(json, bin)
}
