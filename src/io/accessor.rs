//! Accessor decoding: every component type the glTF 2.0 spec allows, normalized integers
//! (including `KHR_mesh_quantization` attributes), byte strides, sparse accessors, and buffer
//! views compressed with `EXT_meshopt_compression`.

use super::container::Container;
use super::error::{GltfError, GltfResult};
use super::meshopt_view;
use std::cell::RefCell;
use std::collections::HashMap;
use std::path::Path;
use std::rc::Rc;

/// A decoded accessor: `count` elements of `components` values each, as f64, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// Number of elements.
    pub count: usize,
    /// Components per element (1 for SCALAR, 3 for VEC3, …).
    pub components: usize,
    /// `count × components` values; normalized integers already mapped to [−1, 1] or [0, 1].
    pub data: Vec<f64>,
}

impl Decoded {
    /// Element `i` as a 3-vector (for VEC3 accessors).
    pub fn vec3(&self, i: usize) -> nalgebra::Vector3<f64> {
        let c = self.components;
        nalgebra::Vector3::new(self.data[i * c], self.data[i * c + 1], self.data[i * c + 2])
    }
}

/// Where a run of accessor elements lies in a buffer view and how its components are
/// encoded: what [`AccessorReader::read_packed`] reads.
#[derive(Debug, Clone, Copy)]
struct ViewSlice {
    /// Buffer view index.
    view: usize,
    /// Byte offset of the first element within the view.
    offset: usize,
    /// Number of elements.
    count: usize,
    /// Components per element (1 for SCALAR, 3 for VEC3, …).
    components: usize,
    /// glTF componentType (5120–5126).
    component_type: u64,
    /// Whether integer components are normalized to [−1, 1] or [0, 1].
    normalized: bool,
    /// Honour the view's byteStride (accessor data); false for tightly packed sparse arrays.
    use_stride: bool,
}

/// Reads accessors of one parsed file, caching decompressed buffer views.
pub struct AccessorReader<'a> {
    path: &'a Path,
    json: &'a serde_json::Value,
    buffers: &'a [Vec<u8>],
    decoded_views: RefCell<HashMap<usize, Rc<Vec<u8>>>>,
}

fn component_size(ct: u64) -> Option<usize> {
    match ct {
        5120 | 5121 => Some(1),
        5122 | 5123 => Some(2),
        5125 | 5126 => Some(4),
        _ => None,
    }
}

/// Number of components of an accessor `type` string.
pub fn type_components(t: &str) -> Option<usize> {
    match t {
        "SCALAR" => Some(1),
        "VEC2" => Some(2),
        "VEC3" => Some(3),
        "VEC4" | "MAT2" => Some(4),
        "MAT3" => Some(9),
        "MAT4" => Some(16),
        _ => None,
    }
}

fn read_component(bytes: &[u8], ct: u64, normalized: bool) -> f64 {
    match ct {
        5120 => {
            let v = bytes[0] as i8 as f64;
            if normalized {
                (v / 127.0).max(-1.0)
            } else {
                v
            }
        }
        5121 => {
            let v = bytes[0] as f64;
            if normalized {
                v / 255.0
            } else {
                v
            }
        }
        5122 => {
            let v = i16::from_le_bytes([bytes[0], bytes[1]]) as f64;
            if normalized {
                (v / 32767.0).max(-1.0)
            } else {
                v
            }
        }
        5123 => {
            let v = u16::from_le_bytes([bytes[0], bytes[1]]) as f64;
            if normalized {
                v / 65535.0
            } else {
                v
            }
        }
        5125 => u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
        _ => f32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]) as f64,
    }
}

/// A JSON value as an index or count (`None` when it is not a non-negative integer).
pub fn usize_of(v: &serde_json::Value) -> Option<usize> {
    v.as_u64().and_then(|x| usize::try_from(x).ok())
}

impl<'a> AccessorReader<'a> {
    /// A reader over the buffers of `c`, which was read from `path`.
    pub fn new(path: &'a Path, c: &'a Container) -> Self {
        Self {
            path,
            json: &c.json,
            buffers: &c.buffers,
            decoded_views: RefCell::new(HashMap::new()),
        }
    }

    fn err(&self, m: String) -> GltfError {
        GltfError::new(self.path, m)
    }

    /// The bytes of buffer view `v` (decompressed when it uses `EXT_meshopt_compression`).
    pub fn view_bytes(&self, v: usize) -> GltfResult<Rc<Vec<u8>>> {
        if let Some(b) = self.decoded_views.borrow().get(&v) {
            return Ok(b.clone());
        }
        let view = self.json["bufferViews"]
            .get(v)
            .ok_or_else(|| self.err(format!("bufferView {v} does not exist")))?;
        let ext = &view["extensions"]["EXT_meshopt_compression"];
        let bytes = if ext.is_object() {
            meshopt_view::decode(self.path, v, ext, self.buffers)?
        } else {
            let b = usize_of(&view["buffer"])
                .ok_or_else(|| self.err(format!("bufferView {v} has no valid 'buffer'")))?;
            let off = usize_of(&view["byteOffset"]).unwrap_or(0);
            let len = usize_of(&view["byteLength"])
                .ok_or_else(|| self.err(format!("bufferView {v} has no valid 'byteLength'")))?;
            let buf = self
                .buffers
                .get(b)
                .ok_or_else(|| self.err(format!("bufferView {v} refers to missing buffer {b}")))?;
            let end = off.saturating_add(len);
            buf.get(off..end)
                .ok_or_else(|| {
                    self.err(format!(
                        "bufferView {v} (bytes {off}..{end}) lies outside buffer {b} ({} bytes)",
                        buf.len()
                    ))
                })?
                .to_vec()
        };
        let rc = Rc::new(bytes);
        self.decoded_views.borrow_mut().insert(v, rc.clone());
        Ok(rc)
    }

    /// The byte stride declared by buffer view `v`. An `EXT_meshopt_compression` view's own
    /// `byteStride` is the codec's element size, not the accessors' stride: a view without
    /// `byteStride` holds its accessors tightly packed, compressed or not.
    fn view_stride(&self, v: usize) -> Option<usize> {
        usize_of(&self.json["bufferViews"][v]["byteStride"])
    }

    /// Read the elements `s` describes, tightly packed unless `s.use_stride` and the view
    /// declares a stride; `what` names the accessor in errors.
    fn read_packed(&self, what: &str, s: &ViewSlice) -> GltfResult<Vec<f64>> {
        let ViewSlice {
            view: v,
            offset,
            count,
            components: ncomp,
            component_type: ct,
            normalized,
            use_stride,
        } = *s;
        let bytes = self.view_bytes(v)?;
        let cs = component_size(ct)
            .ok_or_else(|| self.err(format!("{what}: bad componentType {ct}")))?;
        let elem = cs * ncomp;
        let stride = if use_stride {
            self.view_stride(v).unwrap_or(elem)
        } else {
            elem
        };
        if stride < elem {
            return Err(self.err(format!(
                "{what}: byteStride {stride} is smaller than an element ({elem} bytes)"
            )));
        }
        if count > 0 {
            let need = offset
                .checked_add(stride.saturating_mul(count - 1))
                .and_then(|x| x.checked_add(elem))
                .unwrap_or(usize::MAX);
            if need > bytes.len() {
                return Err(self.err(format!(
                    "{what}: reads bytes up to {need} of bufferView {v}, which has only {} (out of bounds)",
                    bytes.len()
                )));
            }
        }
        let mut out = Vec::with_capacity(count * ncomp);
        for i in 0..count {
            let base = offset + i * stride;
            for k in 0..ncomp {
                out.push(read_component(&bytes[base + k * cs..], ct, normalized));
            }
        }
        Ok(out)
    }

    /// Decode accessor `a` into f64 values (sparse substitution applied).
    pub fn read(&self, a: usize) -> GltfResult<Decoded> {
        let acc = self.json["accessors"]
            .get(a)
            .ok_or_else(|| self.err(format!("accessor {a} does not exist")))?;
        let what = format!("accessor {a}");
        let count =
            usize_of(&acc["count"]).ok_or_else(|| self.err(format!("{what}: missing count")))?;
        let ct = acc["componentType"].as_u64().unwrap_or(0);
        let cs = component_size(ct)
            .ok_or_else(|| self.err(format!("{what}: bad componentType {ct}")))?;
        let ty = acc["type"].as_str().unwrap_or("");
        let ncomp =
            type_components(ty).ok_or_else(|| self.err(format!("{what}: bad type {ty:?}")))?;
        if ty.starts_with("MAT") && cs < 4 {
            return Err(self.err(format!(
                "{what}: matrices of 1- or 2-byte components are not supported"
            )));
        }
        let normalized = acc["normalized"].as_bool().unwrap_or(false);
        if normalized && (ct == 5125 || ct == 5126) {
            return Err(self.err(format!(
                "{what}: normalized is only allowed for 8- and 16-bit integers"
            )));
        }
        if count > (1 << 24) || (count * ncomp > (1 << 26)) {
            return Err(self.err(format!("{what}: count {count} is implausibly large")));
        }
        let offset = usize_of(&acc["byteOffset"]).unwrap_or(0);
        let mut data = match usize_of(&acc["bufferView"]) {
            Some(view) => self.read_packed(
                &what,
                &ViewSlice {
                    view,
                    offset,
                    count,
                    components: ncomp,
                    component_type: ct,
                    normalized,
                    use_stride: true,
                },
            )?,
            None => vec![0.0; count * ncomp],
        };
        let sparse = &acc["sparse"];
        if sparse.is_object() {
            let sc = usize_of(&sparse["count"])
                .ok_or_else(|| self.err(format!("{what}: sparse.count missing")))?;
            if sc > count {
                return Err(self.err(format!("{what}: sparse.count {sc} exceeds count {count}")));
            }
            let iv = usize_of(&sparse["indices"]["bufferView"])
                .ok_or_else(|| self.err(format!("{what}: sparse.indices.bufferView missing")))?;
            let ioff = usize_of(&sparse["indices"]["byteOffset"]).unwrap_or(0);
            let ict = sparse["indices"]["componentType"].as_u64().unwrap_or(0);
            if !matches!(ict, 5121 | 5123 | 5125) {
                return Err(self.err(format!(
                    "{what}: sparse index componentType {ict} must be unsigned"
                )));
            }
            let idx = self.read_packed(
                &what,
                &ViewSlice {
                    view: iv,
                    offset: ioff,
                    count: sc,
                    components: 1,
                    component_type: ict,
                    normalized: false,
                    use_stride: false,
                },
            )?;
            let vv = usize_of(&sparse["values"]["bufferView"])
                .ok_or_else(|| self.err(format!("{what}: sparse.values.bufferView missing")))?;
            let voff = usize_of(&sparse["values"]["byteOffset"]).unwrap_or(0);
            let vals = self.read_packed(
                &what,
                &ViewSlice {
                    view: vv,
                    offset: voff,
                    count: sc,
                    components: ncomp,
                    component_type: ct,
                    normalized,
                    use_stride: false,
                },
            )?;
            for (j, &i) in idx.iter().enumerate() {
                let i = i as usize;
                if i >= count {
                    return Err(self.err(format!(
                        "{what}: sparse index {i} is out of range (count {count})"
                    )));
                }
                data[i * ncomp..(i + 1) * ncomp].copy_from_slice(&vals[j * ncomp..(j + 1) * ncomp]);
            }
        }
        Ok(Decoded {
            count,
            components: ncomp,
            data,
        })
    }

    /// Decode an index accessor into vertex indices, checking they are unsigned integers.
    pub fn read_indices(&self, a: usize) -> GltfResult<Vec<usize>> {
        let ct = self.json["accessors"][a]["componentType"]
            .as_u64()
            .unwrap_or(0);
        if !matches!(ct, 5121 | 5123 | 5125) {
            return Err(self.err(format!(
                "accessor {a}: indices must be unsigned integers (componentType {ct})"
            )));
        }
        let d = self.read(a)?;
        if d.components != 1 {
            return Err(self.err(format!("accessor {a}: indices must be SCALAR")));
        }
        Ok(d.data.iter().map(|&v| v as usize).collect())
    }
}
