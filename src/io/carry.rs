//! Vertex data of the loaded face carried to exported vertices by their origin (up to three
//! loaded vertices and weights): texture coordinates and colours interpolate, skin influences
//! blend (each joint's weight summed over the origins, the strongest kept, renormalised).

use super::accessor::AccessorReader;
use super::glb_write::{Document, ARRAY_BUFFER};
use super::load::Rig;
use super::mesh::VertexTransform;
use super::origin::VertexOrigin;
use anyhow::bail;
use serde_json::{json, Value};

/// `components` values per loaded vertex (`values`), interpolated at each origin.
pub fn interpolate(values: &[f64], components: usize, origin: &[VertexOrigin]) -> Vec<f64> {
    let mut out = Vec::with_capacity(origin.len() * components);
    for o in origin {
        for k in 0..components {
            out.push(
                (0..3)
                    .map(|j| o.weights[j] * values[o.vertices[j] * components + k])
                    .sum(),
            );
        }
    }
    out
}

/// Skin influences at each origin: `joints[s]` and `weights[s]` are the loaded vertices'
/// `JOINTS_s` / `WEIGHTS_s` (4 per vertex). Each joint's weight is summed over the origin's
/// vertices (times their weights), the 4 × sets strongest are kept (ties by joint index) and
/// renormalised to sum to one. Returns the new sets, in the same layout.
pub fn blend_influences(
    joints: &[Vec<f64>],
    weights: &[Vec<f64>],
    origin: &[VertexOrigin],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let sets = joints.len().min(weights.len());
    let keep = 4 * sets;
    let mut oj = vec![Vec::with_capacity(origin.len() * 4); sets];
    let mut ow = vec![Vec::with_capacity(origin.len() * 4); sets];
    let mut acc: Vec<(u32, f64)> = Vec::new();
    for o in origin {
        acc.clear();
        for j in 0..3 {
            if o.weights[j] == 0.0 {
                continue;
            }
            let v = o.vertices[j];
            for s in 0..sets {
                for k in 0..4 {
                    let (jt, wt) = (joints[s][4 * v + k] as u32, weights[s][4 * v + k]);
                    if wt == 0.0 {
                        continue;
                    }
                    match acc.iter_mut().find(|e| e.0 == jt) {
                        Some(e) => e.1 += wt * o.weights[j],
                        None => acc.push((jt, wt * o.weights[j])),
                    }
                }
            }
        }
        acc.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        acc.truncate(keep);
        let total: f64 = acc.iter().map(|e| e.1).sum();
        for s in 0..sets {
            for k in 0..4 {
                let (jt, wt) = acc.get(4 * s + k).copied().unwrap_or((0, 0.0));
                oj[s].push(jt as f64);
                ow[s].push(if total > 0.0 { wt / total } else { 0.0 });
            }
        }
    }
    (oj, ow)
}

/// Attributes of the original face primitives carried to the exported vertices (all
/// primitives merged: the frame-sequence form has one primitive).
pub(crate) fn carried_attributes(
    rig: &Rig,
    doc: &mut Document,
    origin: &[VertexOrigin],
) -> anyhow::Result<serde_json::Map<String, Value>> {
    let f = rig.face();
    let c = &rig.container;
    let reader = AccessorReader::new(&rig.path, c);
    let prims: Vec<&Value> = f
        .primitives
        .iter()
        .map(|s| &c.json["meshes"][f.mesh]["primitives"][s.json])
        .collect();
    let skinned = matches!(f.to_world, VertexTransform::PerVertex(_));
    // Attributes present in any primitive are carried (zeros where a primitive lacks one),
    // because the kept material may sample any texture coordinate set.
    let mut names: Vec<String> = Vec::new();
    for p in &prims {
        for k in p["attributes"]
            .as_object()
            .into_iter()
            .flatten()
            .map(|(k, _)| k)
        {
            if carried(k, skinned) && !names.contains(k) {
                names.push(k.clone());
            }
        }
    }
    names.sort();
    let mut values = std::collections::BTreeMap::new();
    for name in &names {
        let (all, comps) = gather(rig, &reader, &prims, name)?;
        if all.len() / comps.max(1) < f.positions.len() {
            bail!(
                "{}: attribute {name} has fewer entries than the face has vertices",
                rig.path.display()
            );
        }
        values.insert(name.clone(), (all, comps));
    }
    let mut out = serde_json::Map::new();
    let sets: Vec<String> = names
        .iter()
        .filter_map(|n| n.strip_prefix("JOINTS_"))
        .filter(|s| values.contains_key(&format!("WEIGHTS_{s}")))
        .map(String::from)
        .collect();
    let js: Vec<Vec<f64>> = sets
        .iter()
        .map(|s| values[&format!("JOINTS_{s}")].0.clone())
        .collect();
    let ws: Vec<Vec<f64>> = sets
        .iter()
        .map(|s| values[&format!("WEIGHTS_{s}")].0.clone())
        .collect();
    let (bj, bw) = blend_influences(&js, &ws, origin);
    for (i, s) in sets.iter().enumerate() {
        out.insert(format!("JOINTS_{s}"), json!(push_joints(doc, &bj[i])));
        out.insert(
            format!("WEIGHTS_{s}"),
            json!(doc.push_f32(&bw[i], 4, Some(ARRAY_BUFFER))),
        );
    }
    for (name, (all, comps)) in &values {
        if name.starts_with("JOINTS_") || name.starts_with("WEIGHTS_") {
            continue;
        }
        let vals = interpolate(all, *comps, origin);
        out.insert(
            name.clone(),
            json!(doc.push_f32(&vals, *comps, Some(ARRAY_BUFFER))),
        );
    }
    Ok(out)
}

/// Whether a vertex attribute of the face is carried to the export: texture coordinates,
/// colours, and skin influences of a skinned face (positions and normals are written anew;
/// tangents would be stale on a wrinkled surface).
pub(crate) fn carried(name: &str, skinned: bool) -> bool {
    name.starts_with("TEXCOORD_")
        || name.starts_with("COLOR_")
        || (skinned && (name.starts_with("JOINTS_") || name.starts_with("WEIGHTS_")))
}

/// Attribute `name` of the face's skin primitives `prims` (its spans' JSON), concatenated in the loaded
/// face's vertex order (zeros for a primitive without it), and its component count.
fn gather(
    rig: &Rig,
    reader: &AccessorReader,
    prims: &[&Value],
    name: &str,
) -> anyhow::Result<(Vec<f64>, usize)> {
    let f = rig.face();
    let mut comps = 0;
    for p in prims {
        if let Some(a) = p["attributes"][name].as_u64() {
            comps = reader.read(a as usize)?.components;
        }
    }
    let mut all = Vec::new();
    for (pi, p) in prims.iter().enumerate() {
        let count = f.primitives.get(pi).map_or(0, |s| s.count);
        match p["attributes"][name].as_u64() {
            Some(a) => {
                let d = reader.read(a as usize)?;
                if d.count != count {
                    bail!(
                        "{}: attribute {name} of primitive {pi} has {} entries for {count} vertices",
                        rig.path.display(),
                        d.count
                    );
                }
                all.extend(d.data);
            }
            None => all.extend(std::iter::repeat_n(0.0, count * comps)),
        }
    }
    Ok((all, comps))
}

/// A JOINTS accessor (u16 VEC4) of joint indices `j` (4 per vertex); returns its index.
pub(crate) fn push_joints(doc: &mut Document, j: &[f64]) -> usize {
    let bytes: Vec<u8> = j.iter().flat_map(|&v| (v as u16).to_le_bytes()).collect();
    let view = doc.push_view(bytes, Some(ARRAY_BUFFER));
    let a = doc.json["accessors"]
        .as_array_mut()
        .expect("accessors exist");
    a.push(
        json!({ "bufferView": view, "componentType": 5123, "count": j.len() / 4, "type": "VEC4" }),
    );
    a.len() - 1
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uvs_interpolate_and_influences_blend() {
        let uv = [0.0, 0.0, 1.0, 0.0, 0.0, 1.0];
        let o = VertexOrigin {
            vertices: [0, 1, 2],
            weights: [0.5, 0.25, 0.25],
        };
        assert_eq!(interpolate(&uv, 2, &[o]), vec![0.25, 0.25]);
        // Vertex 0: joint 3 only; vertex 1: joints 3 and 5 half each; vertex 2 unused.
        let joints = vec![vec![3., 0., 0., 0., 3., 5., 0., 0., 9., 0., 0., 0.]];
        let weights = vec![vec![1., 0., 0., 0., 0.5, 0.5, 0., 0., 1., 0., 0., 0.]];
        let mid = VertexOrigin {
            vertices: [0, 1, 2],
            weights: [0.5, 0.5, 0.0],
        };
        let (j, w) = blend_influences(&joints, &weights, &[mid]);
        assert_eq!(j[0][..2], [3.0, 5.0]);
        assert!((w[0][0] - 0.75).abs() < 1e-15 && (w[0][1] - 0.25).abs() < 1e-15);
        assert_eq!(w[0][2..], [0.0, 0.0]);
    }
}
