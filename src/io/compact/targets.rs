//! Morph targets as stored: each VEC3 attribute (POSITION or NORMAL deltas) as 32-bit floats,
//! normalized i16 or normalized i8 (`KHR_mesh_quantization`: signed normalized deltas decode as
//! max(q / 32767, −1) and max(q / 127, −1)), dense, or sparse when fewer than half the
//! vertices move (a target's attributes share one list of sparse indices: the vertices where
//! any of them is non-zero as stored).
//!
//! Dense layouts follow the extension's 4-byte alignment (i16 VEC3 padded to 8 bytes, i8 VEC3
//! to 4); sparse values are tightly packed, as glTF reads them. Sparse lists are padded with
//! unmoved vertices to a multiple of 4 entries, so every view fits whole 12-byte (and 4-byte
//! index) meshopt elements.

use super::{add_extension, exp_round, Codec, CompactDocument};
use crate::io::glb_write::ARRAY_BUFFER;
use nalgebra::Vector3;
use serde_json::{json, Value};

/// Largest normalized i16 value.
const I16_MAX: f64 = 32767.0;
/// Largest normalized i8 value.
const I8_MAX: f64 = 127.0;

/// One VEC3 attribute of a morph target, one value per vertex, as stored.
#[derive(Debug, Clone, PartialEq)]
pub enum Vec3Data {
    /// 32-bit floats (any range).
    F32(Vec<[f32; 3]>),
    /// 32-bit floats on the `EXPONENTIAL` filter's grid of the given mantissa bits
    /// ([`exp_round`]): plain files store the floats, compressed ones the filter's encoding,
    /// and both decode to the same values.
    F32Exp(Vec<[f32; 3]>, i32),
    /// Normalized i16: q / 32767, within [−1, 1].
    I16(Vec<[i16; 3]>),
    /// Normalized i8: q / 127, within [−1, 1].
    I8(Vec<[i8; 3]>),
}

/// Normalized i16 components of a vector within [−1, 1] (clamped).
pub fn unit_i16(v: &Vector3<f64>) -> [i16; 3] {
    let q = |x: f64| (x * I16_MAX).round().clamp(-I16_MAX, I16_MAX) as i16;
    [q(v.x), q(v.y), q(v.z)]
}

/// Normalized i8 components of a vector within [−1, 1] (clamped).
pub fn unit_i8(v: &Vector3<f64>) -> [i8; 3] {
    let q = |x: f64| (x * I8_MAX).round().clamp(-I8_MAX, I8_MAX) as i8;
    [q(v.x), q(v.y), q(v.z)]
}

impl Vec3Data {
    /// 32-bit floats of `v`.
    pub fn f32_of(v: &[Vector3<f64>]) -> Self {
        Self::F32(
            v.iter()
                .map(|d| [d.x as f32, d.y as f32, d.z as f32])
                .collect(),
        )
    }

    /// `v` rounded to the `EXPONENTIAL` filter's grid of `bits` mantissa bits.
    pub fn exp_of(v: &[Vector3<f64>], bits: i32) -> Self {
        let f: Vec<[f32; 3]> = v
            .iter()
            .map(|d| [d.x as f32, d.y as f32, d.z as f32])
            .collect();
        Self::F32Exp(exp_round(&f, bits), bits)
    }

    /// Number of vertices.
    pub fn len(&self) -> usize {
        match self {
            Self::F32(v) | Self::F32Exp(v, _) => v.len(),
            Self::I16(v) => v.len(),
            Self::I8(v) => v.len(),
        }
    }

    /// True when there are no vertices.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether vertex `i`'s stored value is zero.
    fn is_zero(&self, i: usize) -> bool {
        match self {
            Self::F32(v) | Self::F32Exp(v, _) => v[i] == [0.0; 3],
            Self::I16(v) => v[i] == [0; 3],
            Self::I8(v) => v[i] == [0; 3],
        }
    }

    /// Vertex `i` as a glTF loader decodes it.
    pub fn decoded(&self, i: usize) -> Vector3<f64> {
        match self {
            Self::F32(v) | Self::F32Exp(v, _) => v[i].map(|x| x as f64).into(),
            Self::I16(v) => v[i].map(|q| (q as f64 / I16_MAX).max(-1.0)).into(),
            Self::I8(v) => v[i].map(|q| (q as f64 / I8_MAX).max(-1.0)).into(),
        }
    }

    /// glTF componentType and whether it is normalized.
    fn component(&self) -> (u32, bool) {
        match self {
            Self::F32(_) | Self::F32Exp(..) => (5126, false),
            Self::I16(_) => (5122, true),
            Self::I8(_) => (5120, true),
        }
    }

    /// Bytes of the listed elements, each padded to `pad` bytes (0: tightly packed).
    fn bytes(&self, idx: &mut dyn Iterator<Item = usize>, pad: bool) -> Vec<u8> {
        let mut out = Vec::new();
        for i in idx {
            match self {
                Self::F32(v) | Self::F32Exp(v, _) => {
                    v[i].iter().for_each(|x| out.extend(x.to_le_bytes()))
                }
                Self::I16(v) => {
                    v[i].iter().for_each(|x| out.extend(x.to_le_bytes()));
                    if pad {
                        out.extend([0, 0]);
                    }
                }
                Self::I8(v) => {
                    out.extend(v[i].map(|x| x as u8));
                    if pad {
                        out.push(0);
                    }
                }
            }
        }
        out
    }

    /// Bytes per dense (vertex-attribute) element.
    fn dense_stride(&self) -> usize {
        match self {
            Self::F32(_) | Self::F32Exp(..) => 12,
            Self::I16(_) => 8,
            Self::I8(_) => 4,
        }
    }

    /// Per-component bounds over every vertex, as glTF writes them: the floats, or the stored
    /// integers of a normalized accessor.
    fn bounds(&self) -> (Value, Value) {
        let mut lo = [f64::INFINITY; 3];
        let mut hi = [f64::NEG_INFINITY; 3];
        for i in 0..self.len() {
            let e: [f64; 3] = match self {
                Self::F32(v) | Self::F32Exp(v, _) => v[i].map(|x| x as f64),
                Self::I16(v) => v[i].map(|x| x as f64),
                Self::I8(v) => v[i].map(|x| x as f64),
            };
            for k in 0..3 {
                lo[k] = lo[k].min(e[k]);
                hi[k] = hi[k].max(e[k]);
            }
        }
        match self {
            Self::F32(_) | Self::F32Exp(..) => {
                (json!(lo.map(|x| x as f32)), json!(hi.map(|x| x as f32)))
            }
            _ => (json!(lo.map(|x| x as i64)), json!(hi.map(|x| x as i64))),
        }
    }

    /// A VEC3 accessor's JSON for these values: component type, `normalized`, and the
    /// bounds when `bounds`.
    fn accessor(&self, bounds: bool) -> Value {
        let (ct, normalized) = self.component();
        let mut acc = json!({ "componentType": ct, "count": self.len(), "type": "VEC3" });
        if normalized {
            acc["normalized"] = json!(true);
        }
        if bounds {
            let (min, max) = self.bounds();
            acc["min"] = min;
            acc["max"] = max;
        }
        acc
    }

    /// Whether this storage needs `KHR_mesh_quantization`.
    fn quantized(&self) -> bool {
        !matches!(self, Self::F32(_) | Self::F32Exp(..))
    }

    /// The codec of a view of these values with elements of `stride` bytes.
    fn codec(&self, stride: usize) -> Codec {
        match self {
            Self::F32Exp(_, bits) => Codec::Exponential { bits: *bits },
            _ => Codec::Attributes { stride },
        }
    }
}

/// A morph target as stored: its POSITION deltas and, when it has them, NORMAL deltas.
#[derive(Debug, Clone, PartialEq)]
pub struct TargetData {
    /// Position deltas.
    pub positions: Vec3Data,
    /// Normal deltas.
    pub normals: Option<Vec3Data>,
}

impl TargetData {
    /// Vertices where a stored delta is non-zero, padded with unmoved vertices to a multiple
    /// of 4 (see the module notes).
    fn support(&self) -> Vec<usize> {
        let n = self.positions.len();
        let moved = |i: usize| {
            !self.positions.is_zero(i) || self.normals.as_ref().is_some_and(|v| !v.is_zero(i))
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
    /// A dense VEC3 vertex attribute (bounds written when `bounds`); returns the accessor.
    pub fn push_vec3(&mut self, d: &Vec3Data, bounds: bool) -> usize {
        let stride = d.dense_stride();
        let bytes = d.bytes(&mut (0..d.len()), true);
        let view = self.push_view(bytes, d.codec(stride), Some(stride), Some(ARRAY_BUFFER));
        let mut acc = d.accessor(bounds);
        acc["bufferView"] = json!(view);
        self.mark_quantized(d);
        self.push_accessor(acc)
    }

    /// Require `KHR_mesh_quantization` when `d` is stored quantized.
    fn mark_quantized(&mut self, d: &Vec3Data) {
        if d.quantized() {
            for key in ["extensionsUsed", "extensionsRequired"] {
                add_extension(&mut self.doc.json, key, "KHR_mesh_quantization");
            }
        }
    }

    /// The target's accessors as a glTF target object: sparse when it moves fewer than half
    /// the vertices, else dense. POSITION carries its bounds (glTF requires them).
    pub fn push_target(&mut self, t: &TargetData) -> Value {
        let n = t.positions.len();
        let support = t.support();
        if support.len() * 2 >= n {
            let mut o = json!({ "POSITION": self.push_vec3(&t.positions, true) });
            if let Some(nq) = &t.normals {
                o["NORMAL"] = json!(self.push_vec3(nq, false));
            }
            return o;
        }
        let index_view = if support.is_empty() {
            None
        } else {
            let (bytes, ct): (Vec<u8>, u32) = if n <= 65536 {
                let b = support.iter().flat_map(|&i| (i as u16).to_le_bytes());
                (b.collect(), 5123)
            } else {
                let b = support.iter().flat_map(|&i| (i as u32).to_le_bytes());
                (b.collect(), 5125)
            };
            let v = self.push_view(bytes, Codec::Attributes { stride: 4 }, None, None);
            Some((v, ct))
        };
        let mut o =
            json!({ "POSITION": self.push_sparse(&t.positions, &support, index_view, true) });
        if let Some(nq) = &t.normals {
            o["NORMAL"] = json!(self.push_sparse(nq, &support, index_view, false));
        }
        o
    }

    /// A sparse VEC3 accessor of `d` over `support` (indices in `index_view`: view and
    /// componentType), zero elsewhere; no substitution at all when the support is empty.
    fn push_sparse(
        &mut self,
        d: &Vec3Data,
        support: &[usize],
        index_view: Option<(usize, u32)>,
        bounds: bool,
    ) -> usize {
        let mut acc = d.accessor(bounds);
        if let Some((iv, ict)) = index_view {
            let values = d.bytes(&mut support.iter().copied(), false);
            let vv = self.push_view(values, d.codec(12), None, None);
            acc["sparse"] = json!({ "count": support.len(),
                "indices": { "bufferView": iv, "componentType": ict },
                "values": { "bufferView": vv } });
        }
        self.mark_quantized(d);
        self.push_accessor(acc)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_values_decode_as_the_spec_says() {
        let i16s = Vec3Data::I16(vec![[32767, -32767, -32768], [1, 0, -1]]);
        assert_eq!(i16s.decoded(0), Vector3::new(1.0, -1.0, -1.0));
        assert_eq!(i16s.decoded(1).x, 1.0 / 32767.0);
        let i8s = Vec3Data::I8(vec![[127, -128, 64]]);
        assert_eq!(i8s.decoded(0), Vector3::new(1.0, -1.0, 64.0 / 127.0));
        assert_eq!(unit_i16(&Vector3::new(2.0, -0.5, 0.0)), [32767, -16384, 0]);
        assert_eq!(unit_i8(&Vector3::new(0.5, -1.0, 1e-3)), [64, -127, 0]);
        // Dense i16 elements are padded to 8 bytes, sparse ones packed in 6.
        assert_eq!(i16s.bytes(&mut (0..2), true).len(), 16);
        assert_eq!(i16s.bytes(&mut (1..2), false), vec![1, 0, 0, 0, 255, 255]);
    }

    #[test]
    fn few_moving_vertices_make_a_sparse_target_sharing_its_indices() {
        let n = 40;
        let mut p = vec![[0i16; 3]; n];
        p[3] = [5, 0, 0];
        p[17] = [0, -7, 1];
        let mut nr = vec![[0.0f32; 3]; n];
        nr[20] = [0.25, 0.0, 0.0];
        let t = TargetData {
            positions: Vec3Data::I16(p),
            normals: Some(Vec3Data::F32(nr)),
        };
        // Vertices 3, 17 and 20 move; vertex 0 pads the list to 4.
        assert_eq!(t.support(), vec![0, 3, 17, 20]);
        let mut cd = CompactDocument::new();
        let o = cd.push_target(&t);
        let acc = &cd.doc.json["accessors"];
        let pa = &acc[o["POSITION"].as_u64().unwrap() as usize];
        let na = &acc[o["NORMAL"].as_u64().unwrap() as usize];
        assert_eq!(pa["sparse"]["count"], 4);
        assert_eq!(pa["sparse"]["indices"], na["sparse"]["indices"]);
        assert_eq!(pa["min"], json!([0, -7, 0]));
        assert_eq!(pa["max"], json!([5, 0, 1]));
        assert_eq!(pa["normalized"], true);
        assert!(na["normalized"].is_null() && na["componentType"] == 5126);
        assert_eq!(
            cd.doc.json["extensionsRequired"],
            json!(["KHR_mesh_quantization"])
        );
    }
}
