//! Building glTF binary output: buffer views, accessors with exact min/max, pruning of what
//! nothing references, and the GLB container.

use serde_json::{json, Value};

/// GL buffer-view targets.
pub const ARRAY_BUFFER: u32 = 34962;
/// GL element-array target (indices).
pub const ELEMENT_ARRAY_BUFFER: u32 = 34963;

/// A document under construction: the glTF JSON plus the bytes of each buffer view
/// (the single binary buffer is laid out at [`Document::to_glb`]).
pub struct Document {
    /// The glTF JSON; `bufferViews` byte offsets are filled in when written.
    pub json: Value,
    /// Bytes of each buffer view, same order as `json["bufferViews"]`.
    pub view_bytes: Vec<Vec<u8>>,
}

fn arr<'a>(json: &'a mut Value, key: &str) -> &'a mut Vec<Value> {
    if !json[key].is_array() {
        json[key] = json!([]);
    }
    json[key].as_array_mut().expect("set above")
}

impl Document {
    /// An empty glTF 2.0 document.
    pub fn new() -> Self {
        Self {
            json: json!({ "asset": { "version": "2.0", "generator": generator() } }),
            view_bytes: Vec::new(),
        }
    }

    /// Append a buffer view holding `bytes`; returns its index.
    pub fn push_view(&mut self, bytes: Vec<u8>, target: Option<u32>) -> usize {
        let mut v = json!({ "buffer": 0, "byteLength": bytes.len() });
        if let Some(t) = target {
            v["target"] = json!(t);
        }
        let views = arr(&mut self.json, "bufferViews");
        views.push(v);
        self.view_bytes.push(bytes);
        views.len() - 1
    }

    fn push_accessor(&mut self, acc: Value) -> usize {
        let a = arr(&mut self.json, "accessors");
        a.push(acc);
        a.len() - 1
    }

    /// Append a float accessor of `components`-vectors (VEC3, SCALAR, …) with exact min/max
    /// (computed on the f32 values written). `target` is the buffer-view target.
    pub fn push_f32(&mut self, values: &[f64], components: usize, target: Option<u32>) -> usize {
        let ty = match components {
            1 => "SCALAR",
            2 => "VEC2",
            3 => "VEC3",
            4 => "VEC4",
            16 => "MAT4",
            _ => panic!("unsupported component count {components}"),
        };
        let f: Vec<f32> = values.iter().map(|&v| v as f32).collect();
        let count = f.len() / components;
        let mut min = vec![f32::INFINITY; components];
        let mut max = vec![f32::NEG_INFINITY; components];
        for e in f.chunks_exact(components) {
            for k in 0..components {
                min[k] = min[k].min(e[k]);
                max[k] = max[k].max(e[k]);
            }
        }
        let bytes: Vec<u8> = f.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(bytes, target);
        let mut acc =
            json!({ "bufferView": view, "componentType": 5126, "count": count, "type": ty });
        if count > 0 && components <= 4 {
            acc["min"] = json!(min);
            acc["max"] = json!(max);
        }
        self.push_accessor(acc)
    }

    /// Append a triangle index accessor (u16 when every index fits below 65535, else u32).
    pub fn push_indices(&mut self, triangles: &[[usize; 3]]) -> usize {
        let max = triangles.iter().flatten().copied().max().unwrap_or(0);
        let (bytes, ct): (Vec<u8>, u32) = if max < 65535 {
            (
                triangles
                    .iter()
                    .flatten()
                    .flat_map(|&i| (i as u16).to_le_bytes())
                    .collect(),
                5123,
            )
        } else {
            (
                triangles
                    .iter()
                    .flatten()
                    .flat_map(|&i| (i as u32).to_le_bytes())
                    .collect(),
                5125,
            )
        };
        let view = self.push_view(bytes, Some(ELEMENT_ARRAY_BUFFER));
        self.push_accessor(json!({ "bufferView": view, "componentType": ct, "count": triangles.len() * 3, "type": "SCALAR" }))
    }

    /// Drop accessors and buffer views that nothing references, renumbering the rest;
    /// returns, for each view before pruning, whether it was kept. A reference to an
    /// accessor or view the document does not have is refused (the rig it came from is
    /// broken there).
    pub fn prune(&mut self) -> anyhow::Result<Vec<bool>> {
        let j = &mut self.json;
        let na = j["accessors"].as_array().map_or(0, |a| a.len());
        let mut used_acc = vec![false; na];
        let mut dangling = None;
        mark_accessor_refs(j, &mut |i| match used_acc.get_mut(i) {
            Some(u) => *u = true,
            None => dangling = Some(("accessor", i)),
        });
        let mut used_view = vec![false; self.view_bytes.len()];
        if let Some((what, i)) = dangling {
            anyhow::bail!("the glTF refers to {what} {i}, which it does not have");
        }
        remap_accessor_refs(j, &renumber(&used_acc));
        if let Some(accs) = j.get_mut("accessors").and_then(|v| v.as_array_mut()) {
            *accs = keep_used(std::mem::take(accs), &used_acc);
        }
        mark_view_refs(j, &mut |i| match used_view.get_mut(i) {
            Some(u) => *u = true,
            None => dangling = Some(("bufferView", i)),
        });
        if let Some((what, i)) = dangling {
            anyhow::bail!("the glTF refers to {what} {i}, which it does not have");
        }
        remap_view_refs(j, &renumber(&used_view));
        if let Some(views) = j.get_mut("bufferViews").and_then(|v| v.as_array_mut()) {
            *views = keep_used(std::mem::take(views), &used_view);
        }
        self.view_bytes = keep_used(std::mem::take(&mut self.view_bytes), &used_view);
        Ok(used_view)
    }

    /// Lay out the binary buffer (views 4-byte aligned), fill offsets, and write a GLB.
    pub fn to_glb(&mut self) -> Vec<u8> {
        let mut bin = Vec::new();
        if let Some(views) = self
            .json
            .get_mut("bufferViews")
            .and_then(|v| v.as_array_mut())
        {
            for (v, bytes) in views.iter_mut().zip(&self.view_bytes) {
                while bin.len() % 4 != 0 {
                    bin.push(0);
                }
                v["buffer"] = json!(0);
                v["byteOffset"] = json!(bin.len());
                v["byteLength"] = json!(bytes.len());
                bin.extend_from_slice(bytes);
            }
        }
        while bin.len() % 4 != 0 {
            bin.push(0);
        }
        let obj = self.json.as_object_mut().expect("document is an object");
        obj.retain(|_, v| !v.is_null());
        if bin.is_empty() {
            obj.remove("buffers");
            obj.remove("bufferViews");
        } else {
            obj.insert("buffers".into(), json!([{ "byteLength": bin.len() }]));
        }
        for k in [
            "accessors",
            "bufferViews",
            "animations",
            "meshes",
            "nodes",
            "images",
            "samplers",
            "textures",
            "materials",
            "skins",
            "cameras",
            "scenes",
            "extensionsUsed",
            "extensionsRequired",
        ] {
            if obj
                .get(k)
                .and_then(|v| v.as_array())
                .is_some_and(|a| a.is_empty())
            {
                obj.remove(k);
            }
        }
        glb_container(&self.json, &bin)
    }
}

/// A GLB container: the header, the JSON chunk (`json`, padded with spaces) and, when `bin`
/// (4-byte aligned) is not empty, the binary chunk.
pub fn glb_container(json: &Value, bin: &[u8]) -> Vec<u8> {
    let mut js = serde_json::to_vec(json).expect("JSON serialises");
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let total = 12 + 8 + js.len() + if bin.is_empty() { 0 } else { 8 + bin.len() };
    let mut out = Vec::with_capacity(total);
    out.extend_from_slice(b"glTF");
    out.extend_from_slice(&2u32.to_le_bytes());
    out.extend_from_slice(&(total as u32).to_le_bytes());
    out.extend_from_slice(&(js.len() as u32).to_le_bytes());
    out.extend_from_slice(b"JSON");
    out.extend_from_slice(&js);
    if !bin.is_empty() {
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(bin);
    }
    out
}

impl Default for Document {
    fn default() -> Self {
        Self::new()
    }
}

/// The `asset.generator` string furrow writes.
pub fn generator() -> String {
    format!("furrow {}", env!("CARGO_PKG_VERSION"))
}

/// The elements of array `key` of `v` (none when it is missing or not an array).
fn items<'a>(v: &'a Value, key: &str) -> impl Iterator<Item = &'a Value> {
    v[key].as_array().into_iter().flatten()
}

/// The elements of array `key` of `v`, mutably (none when it is missing or not an array).
fn items_mut<'a>(v: &'a mut Value, key: &str) -> impl Iterator<Item = &'a mut Value> {
    v.get_mut(key)
        .and_then(|v| v.as_array_mut())
        .into_iter()
        .flatten()
}

/// The values of object `key` of `v`, mutably (none when it is missing or not an object).
fn values_mut<'a>(v: &'a mut Value, key: &str) -> impl Iterator<Item = &'a mut Value> {
    v.get_mut(key)
        .and_then(|v| v.as_object_mut())
        .into_iter()
        .flat_map(|o| o.values_mut())
}

/// Hand index `v` (when it is one) to `used`.
fn mark(v: &Value, used: &mut impl FnMut(usize)) {
    if let Some(i) = v.as_u64() {
        used(usize::try_from(i).unwrap_or(usize::MAX));
    }
}

/// Replace index `v` (when it is one) by its new number in `map`.
fn remap(v: &mut Value, map: &[Option<usize>]) {
    if let Some(i) = v.as_u64() {
        *v = json!(map[i as usize].expect("referenced object is kept"));
    }
}

/// Mark the accessors referenced by meshes (attributes, indices, morph targets), skins
/// (inverse bind matrices) and animation samplers (input and output).
fn mark_accessor_refs(j: &Value, used: &mut impl FnMut(usize)) {
    for m in items(j, "meshes") {
        for p in items(m, "primitives") {
            for a in p["attributes"].as_object().into_iter().flatten() {
                mark(a.1, used);
            }
            mark(&p["indices"], used);
            for t in items(p, "targets") {
                for a in t.as_object().into_iter().flatten() {
                    mark(a.1, used);
                }
            }
        }
    }
    for s in items(j, "skins") {
        mark(&s["inverseBindMatrices"], used);
    }
    for a in items(j, "animations") {
        for s in items(a, "samplers") {
            mark(&s["input"], used);
            mark(&s["output"], used);
        }
    }
}

/// Renumber the accessor references [`mark_accessor_refs`] finds by `map`.
fn remap_accessor_refs(j: &mut Value, map: &[Option<usize>]) {
    for m in items_mut(j, "meshes") {
        for p in items_mut(m, "primitives") {
            for a in values_mut(p, "attributes") {
                remap(a, map);
            }
            if p.get("indices").is_some() {
                remap(&mut p["indices"], map);
            }
            for t in items_mut(p, "targets") {
                for a in t.as_object_mut().into_iter().flatten() {
                    remap(a.1, map);
                }
            }
        }
    }
    for s in items_mut(j, "skins") {
        if s.get("inverseBindMatrices").is_some() {
            remap(&mut s["inverseBindMatrices"], map);
        }
    }
    for a in items_mut(j, "animations") {
        for s in items_mut(a, "samplers") {
            remap(&mut s["input"], map);
            remap(&mut s["output"], map);
        }
    }
}

/// Mark the buffer views referenced by accessors (including sparse ones) and images.
fn mark_view_refs(j: &Value, used: &mut impl FnMut(usize)) {
    for a in items(j, "accessors") {
        mark(&a["bufferView"], used);
        mark(&a["sparse"]["indices"]["bufferView"], used);
        mark(&a["sparse"]["values"]["bufferView"], used);
    }
    for im in items(j, "images") {
        mark(&im["bufferView"], used);
    }
}

/// Renumber the buffer-view references [`mark_view_refs`] finds by `map`.
fn remap_view_refs(j: &mut Value, map: &[Option<usize>]) {
    for a in items_mut(j, "accessors") {
        if a.get("bufferView").is_some() {
            remap(&mut a["bufferView"], map);
        }
        if a["sparse"].is_object() {
            remap(&mut a["sparse"]["indices"]["bufferView"], map);
            remap(&mut a["sparse"]["values"]["bufferView"], map);
        }
    }
    for im in items_mut(j, "images") {
        if im.get("bufferView").is_some() {
            remap(&mut im["bufferView"], map);
        }
    }
}

/// The items whose entry in `used` is true, in order.
fn keep_used<T>(items: Vec<T>, used: &[bool]) -> Vec<T> {
    items
        .into_iter()
        .enumerate()
        .filter(|(i, _)| used[*i])
        .map(|(_, x)| x)
        .collect()
}

/// New index of each kept object (`None` for dropped ones).
fn renumber(used: &[bool]) -> Vec<Option<usize>> {
    let mut next = 0;
    used.iter()
        .map(|&u| {
            if u {
                next += 1;
                Some(next - 1)
            } else {
                None
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A view referenced by an image that the document does not have (a loader fuzz find:
    /// pruning indexed past the views and panicked) is refused with its number; references
    /// in range are pruned and renumbered.
    #[test]
    fn prune_refuses_a_reference_past_the_end_and_renumbers_the_rest() {
        let mut doc = Document::new();
        let unused = doc.push_view(vec![0; 4], None);
        let used = doc.push_view(vec![1; 4], None);
        assert_eq!((unused, used), (0, 1));
        doc.json["images"] = json!([{ "bufferView": used, "mimeType": "image/png" }]);
        let kept = doc.prune().unwrap();
        assert_eq!(kept, vec![false, true]);
        assert_eq!(doc.json["images"][0]["bufferView"], json!(0));
        assert_eq!(doc.view_bytes, vec![vec![1; 4]]);
        doc.json["images"] = json!([{ "bufferView": 6, "mimeType": "image/png" }]);
        let err = doc.prune().unwrap_err().to_string();
        assert!(err.contains("bufferView 6"), "{err}");
    }
}
