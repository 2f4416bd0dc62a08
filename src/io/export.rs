//! Writing wrinkled frames back to glTF.
//!
//! The original scene is kept (other meshes, skins, materials, other animation channels); the
//! face mesh is replaced by the frame sequence. In the animated form every frame is one morph
//! target and a weights animation shows frame k at time k / fps; in the per-frame form each file
//! holds the scene with the face at one frame and no animation. Buffers are re-packed into one
//! GLB buffer (meshopt views decompressed, external images embedded), and what nothing uses any
//! more is pruned.

use super::accessor::AccessorReader;
use super::atomic::{self, Overwrite};
use super::carry::carried_attributes;
use super::container::ImageSource;
use super::glb_write::{generator, Document, ARRAY_BUFFER};
use super::load::Rig;
use super::model::{MorphTarget, WeightKeys};
use super::origin::{LocalFrames, VertexOrigin};
use crate::mesh::TriMesh;
use anyhow::{bail, Context};
use base64::Engine;
use nalgebra::Vector3;
use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// A sequence of face frames to export, all sharing one topology.
pub struct FrameSet<'a> {
    /// Triangles of the exported face (counter-clockwise).
    pub triangles: &'a [[usize; 3]],
    /// World-space positions (m) per frame.
    pub frames: &'a [Vec<Vector3<f64>>],
    /// Origin of each exported vertex in the loaded face.
    pub origin: &'a [VertexOrigin],
    /// Frames per second (frame k is shown at k / fps seconds).
    pub fps: f64,
    /// The rig's morph weights of each frame: the primitives of the face mesh that ride along
    /// show their own blend shapes at them (empty: at rest).
    pub weights: &'a [Vec<f64>],
}

impl FrameSet<'_> {
    fn check(&self, face_vertices: usize) -> anyhow::Result<()> {
        let n = self.origin.len();
        if self.frames.is_empty() {
            bail!("no frames to export");
        }
        if !(self.fps.is_finite() && self.fps > 0.0) {
            bail!("fps must be positive, got {}", self.fps);
        }
        for (k, f) in self.frames.iter().enumerate() {
            if f.len() != n {
                bail!("frame {k} has {} vertices, expected {n}", f.len());
            }
            if let Some(i) = f
                .iter()
                .position(|p| !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()))
            {
                bail!("frame {k} vertex {i} is not finite (NaN or infinity); refusing to write it");
            }
        }
        if let Some(t) = self.triangles.iter().find(|t| t.iter().any(|&i| i >= n)) {
            bail!("triangle {t:?} indexes past {n} vertices");
        }
        if let Some(o) = self
            .origin
            .iter()
            .find(|o| o.vertices.iter().any(|&v| v >= face_vertices))
        {
            bail!("vertex origin {o:?} indexes past the face's {face_vertices} vertices");
        }
        Ok(())
    }
}

/// The loaded file as a writable document: views decompressed, images embedded.
pub(crate) fn base_document(rig: &Rig) -> anyhow::Result<Document> {
    let c = &rig.container;
    let reader = AccessorReader::new(&rig.path, c);
    let mut json = c.json.clone();
    let nv = json["bufferViews"].as_array().map_or(0, |a| a.len());
    let mut view_bytes = Vec::with_capacity(nv);
    for v in 0..nv {
        let bytes = reader.view_bytes(v)?;
        view_bytes.push((*bytes).clone());
        let view = &mut json["bufferViews"][v];
        if let Some(ext) = view.get_mut("extensions").and_then(|e| e.as_object_mut()) {
            ext.remove("EXT_meshopt_compression");
            if ext.is_empty() {
                view.as_object_mut().expect("object").remove("extensions");
            }
        }
    }
    let mut doc = Document { json, view_bytes };
    for key in ["extensionsUsed", "extensionsRequired"] {
        if let Some(a) = doc.json.get_mut(key).and_then(|v| v.as_array_mut()) {
            a.retain(|e| e != "EXT_meshopt_compression");
        }
    }
    doc.json["asset"]["generator"] = json!(generator());
    // Embed images so the GLB stands alone.
    let ni = doc.json["images"].as_array().map_or(0, |a| a.len());
    for i in 0..ni {
        let Some(uri) = doc.json["images"][i]["uri"].as_str().map(String::from) else {
            continue;
        };
        let (bytes, mime) = if let Some(rest) = uri.strip_prefix("data:") {
            let comma = rest.find(',').context("malformed image data URI")?;
            let mime = rest[..comma].trim_end_matches(";base64").to_string();
            (
                base64::engine::general_purpose::STANDARD
                    .decode(&rest[comma + 1..])
                    .context("bad base64 in image URI")?,
                mime,
            )
        } else {
            image_file(rig, i, &uri)?
        };
        let v = doc.push_view(bytes, None);
        let im = doc.json["images"][i].as_object_mut().expect("image object");
        im.remove("uri");
        im.insert("bufferView".into(), json!(v));
        im.insert("mimeType".into(), json!(mime));
    }
    Ok(doc)
}

/// The bytes and MIME type of image `i` of `rig`, whose URI `uri` names a file: read from
/// where it was judged when the rig was loaded (inside the rig's folder unless outside paths
/// were allowed), typed by the extension the URI names.
fn image_file(rig: &Rig, i: usize, uri: &str) -> anyhow::Result<(Vec<u8>, String)> {
    let file = match rig.container.images.get(i) {
        Some(ImageSource::File(f)) => f,
        Some(ImageSource::Unreadable(why)) => bail!("{}: {why}", rig.path.display()),
        Some(ImageSource::Embedded) | None => bail!(
            "{}: image {i} ({uri}) was not resolved when the rig was read",
            rig.path.display()
        ),
    };
    let b = std::fs::read(&file.path).with_context(|| {
        format!(
            "{}: image {i} ({}) cannot be read",
            rig.path.display(),
            file.path.display()
        )
    })?;
    let mime = match file
        .named
        .extension()
        .and_then(|e| e.to_str())
        .map(|e| e.to_ascii_lowercase())
        .as_deref()
    {
        Some("png") => "image/png",
        Some("jpg") | Some("jpeg") => "image/jpeg",
        Some("webp") => "image/webp",
        Some("ktx2") => "image/ktx2",
        _ => bail!(
            "{}: image {i} ({uri}) has an unknown type",
            rig.path.display()
        ),
    };
    Ok((b, mime.to_string()))
}

fn flat(v: &[Vector3<f64>]) -> Vec<f64> {
    v.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
}

/// A primitive of the face mesh that rides along, in the frame-sequence form: its own
/// attributes and material, its position at each frame's weights (`set.weights`) as one
/// target per frame when `with_targets`, else its position at the first frame's weights.
fn riding_frames(
    rig: &Rig,
    doc: &mut Document,
    json: &Value,
    set: &FrameSet,
    with_targets: bool,
) -> anyhow::Result<Value> {
    let reader = AccessorReader::new(&rig.path, &rig.container);
    let mut prim = json.clone();
    let base = match json["attributes"]["POSITION"].as_u64() {
        Some(a) => reader.read(a as usize)?.data,
        None => return Ok(prim),
    };
    let mut deltas = Vec::new();
    for t in json["targets"].as_array().into_iter().flatten() {
        deltas.push(match t["POSITION"].as_u64() {
            Some(a) => reader.read(a as usize)?.data,
            None => vec![0.0; base.len()],
        });
    }
    let blend = |w: Option<&Vec<f64>>| -> Vec<f64> {
        let mut d = vec![0.0; base.len()];
        for (delta, &wt) in deltas.iter().zip(w.into_iter().flatten()) {
            if wt != 0.0 {
                d.iter_mut().zip(delta).for_each(|(a, b)| *a += wt * b);
            }
        }
        d
    };
    let object = prim.as_object_mut().expect("primitive object");
    object.remove("targets");
    if with_targets {
        let first = blend(set.weights.first());
        let frames = set.frames.len();
        let targets: Vec<Value> = (0..frames)
            .map(|k| {
                let d: Vec<f64> = blend(set.weights.get(k))
                    .iter()
                    .zip(&first)
                    .map(|(a, b)| a - b)
                    .collect();
                json!({ "POSITION": doc.push_f32(&d, 3, Some(ARRAY_BUFFER)) })
            })
            .collect();
        let at: Vec<f64> = base.iter().zip(&first).map(|(a, b)| a + b).collect();
        object.insert("attributes".into(), json["attributes"].clone());
        prim["attributes"]["POSITION"] = json!(doc.push_f32(&at, 3, Some(ARRAY_BUFFER)));
        prim["targets"] = json!(targets);
    } else if !deltas.is_empty() {
        let d = blend(set.weights.first());
        let at: Vec<f64> = base.iter().zip(&d).map(|(a, b)| a + b).collect();
        prim["attributes"]["POSITION"] = json!(doc.push_f32(&at, 3, Some(ARRAY_BUFFER)));
    }
    Ok(prim)
}

/// Replace the face by the frames: `animated` true gives morph targets + weights animation,
/// false gives the single frame `frames[0]` with no animation at all.
fn replace_face(rig: &Rig, set: &FrameSet, animated: bool) -> anyhow::Result<Document> {
    let f = rig.face();
    set.check(f.positions.len())?;
    let mut doc = base_document(rig)?;
    let local = LocalFrames::new(rig, set.origin)?;
    let topo = TriMesh::new(Vec::new(), set.triangles.to_vec());
    let n = set.origin.len();
    let local_pos = |k: usize| -> Vec<Vector3<f64>> {
        (0..n).map(|i| local.point(i, &set.frames[k][i])).collect()
    };
    let local_nrm = |k: usize| -> Vec<Vector3<f64>> {
        topo.vertex_normals_of(&set.frames[k])
            .iter()
            .enumerate()
            .map(|(i, nw)| local.normal(i, nw))
            .collect()
    };
    let p0 = local_pos(0);
    let n0 = local_nrm(0);
    let mut attrs = carried_attributes(rig, &mut doc, set.origin)?;
    attrs.insert(
        "POSITION".into(),
        json!(doc.push_f32(&flat(&p0), 3, Some(ARRAY_BUFFER))),
    );
    attrs.insert(
        "NORMAL".into(),
        json!(doc.push_f32(&flat(&n0), 3, Some(ARRAY_BUFFER))),
    );
    let indices = doc.push_indices(set.triangles);
    let mut prim = json!({ "attributes": attrs, "indices": indices, "mode": 4 });
    let first_skin = f.primitives.first().map_or(0, |s| s.json);
    if let Some(m) = rig.container.json["meshes"][f.mesh]["primitives"][first_skin].get("material")
    {
        prim["material"] = m.clone();
    }
    let frames = set.frames.len();
    let with_targets = animated && frames > 1;
    let mut mesh = json!({ "name": format!("{} (furrow)", f.name), "primitives": [] });
    if with_targets {
        let mut targets = Vec::with_capacity(frames);
        for k in 0..frames {
            let pk = local_pos(k);
            let nk = local_nrm(k);
            let dp: Vec<Vector3<f64>> = pk.iter().zip(&p0).map(|(a, b)| a - b).collect();
            let dn: Vec<Vector3<f64>> = nk.iter().zip(&n0).map(|(a, b)| a - b).collect();
            targets.push(json!({
                "POSITION": doc.push_f32(&flat(&dp), 3, Some(ARRAY_BUFFER)),
                "NORMAL": doc.push_f32(&flat(&dn), 3, Some(ARRAY_BUFFER)),
            }));
        }
        prim["targets"] = json!(targets);
        mesh["weights"] = json!(vec![0.0; frames]);
        mesh["extras"] = json!({ "targetNames": (0..frames).map(|k| format!("frame_{k:05}")).collect::<Vec<_>>() });
    }
    let mut prims = vec![prim];
    for part in rig.parts.riding() {
        let json = &rig.container.json["meshes"][f.mesh]["primitives"][part.primitive];
        prims.push(riding_frames(rig, &mut doc, json, set, with_targets)?);
    }
    mesh["primitives"] = json!(prims);
    install_face_mesh(&mut doc.json, rig, mesh)
        .as_object_mut()
        .expect("node object")
        .remove("weights");
    // Animations: drop the face's old weight channels (and everything, for a still frame).
    if animated {
        strip_face_weight_channels(&mut doc.json, f.node);
        if with_targets {
            let times: Vec<f64> = (0..frames).map(|k| k as f64 / set.fps).collect();
            let mut onehot = vec![0.0; frames * frames];
            for k in 0..frames {
                onehot[k * frames + k] = 1.0;
            }
            let input = doc.push_f32(&times, 1, None);
            let output = doc.push_f32(&onehot, 1, None);
            let anims = doc
                .json
                .as_object_mut()
                .expect("object")
                .entry("animations")
                .or_insert(json!([]));
            anims.as_array_mut().expect("array").push(json!({
                "name": "furrow_wrinkles",
                "samplers": [{ "input": input, "output": output, "interpolation": "LINEAR" }],
                "channels": [{ "sampler": 0, "target": { "node": f.node, "path": "weights" } }],
            }));
        }
    } else {
        doc.json
            .as_object_mut()
            .expect("object")
            .remove("animations");
    }
    hoist_skinned_meshes(&mut doc.json);
    doc.prune()?;
    Ok(doc)
}

/// Give the face node `mesh` (JSON) in the document `json` of `rig`: it replaces the face's
/// mesh, or is added when another node also uses that mesh (the others keep it). Returns the
/// face node's JSON.
pub(crate) fn install_face_mesh<'j>(json: &'j mut Value, rig: &Rig, mesh: Value) -> &'j mut Value {
    let f = rig.face();
    let shared = rig.container.json["nodes"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
        .any(|(i, nd)| i != f.node && nd["mesh"].as_u64() == Some(f.mesh as u64));
    let mesh_index = if shared {
        let ms = json["meshes"].as_array_mut().expect("meshes exist");
        ms.push(mesh);
        ms.len() - 1
    } else {
        json["meshes"][f.mesh] = mesh;
        f.mesh
    };
    let node = &mut json["nodes"][f.node];
    node["mesh"] = json!(mesh_index);
    node
}

/// A skinned mesh ignores its node's parents (glTF 2.0 §3.7.3), and the validator warns when
/// such a node is not a root. Move each one's mesh and skin to a new root node in the same
/// scenes (the original node keeps its place and children), retargeting its weight channels:
/// the picture is unchanged.
pub(crate) fn hoist_skinned_meshes(json: &mut Value) {
    let nodes = json["nodes"].as_array().cloned().unwrap_or_default();
    let mut parent = vec![None; nodes.len()];
    for (i, n) in nodes.iter().enumerate() {
        for c in n["children"]
            .as_array()
            .into_iter()
            .flatten()
            .filter_map(|c| c.as_u64())
        {
            if let Some(p) = parent.get_mut(c as usize) {
                *p = Some(i);
            }
        }
    }
    for (i, n) in nodes.iter().enumerate() {
        if parent[i].is_none() || !n["skin"].is_u64() || !n["mesh"].is_u64() {
            continue;
        }
        let mut root = i;
        while let Some(p) = parent[root] {
            root = p;
        }
        let mut hoisted = json!({ "mesh": n["mesh"], "skin": n["skin"] });
        if let Some(name) = n["name"].as_str() {
            hoisted["name"] = json!(format!("{name} (skinned mesh)"));
        }
        if n.get("weights").is_some() {
            hoisted["weights"] = n["weights"].clone();
        }
        let new_index = {
            let ns = json["nodes"].as_array_mut().expect("nodes exist");
            ns.push(hoisted);
            ns.len() - 1
        };
        let old = json["nodes"][i].as_object_mut().expect("node object");
        old.remove("mesh");
        old.remove("skin");
        old.remove("weights");
        for sc in json
            .get_mut("scenes")
            .and_then(|v| v.as_array_mut())
            .into_iter()
            .flatten()
        {
            if let Some(list) = sc.get_mut("nodes").and_then(|v| v.as_array_mut()) {
                if list.iter().any(|v| v.as_u64() == Some(root as u64)) {
                    list.push(json!(new_index));
                }
            }
        }
        for a in json
            .get_mut("animations")
            .and_then(|v| v.as_array_mut())
            .into_iter()
            .flatten()
        {
            for c in a
                .get_mut("channels")
                .and_then(|v| v.as_array_mut())
                .into_iter()
                .flatten()
            {
                if c["target"]["path"] == "weights"
                    && c["target"]["node"].as_u64() == Some(i as u64)
                {
                    c["target"]["node"] = json!(new_index);
                }
            }
        }
    }
}

/// Remove `weights` channels that target `node` (their samplers too), and empty animations.
fn strip_face_weight_channels(json: &mut Value, node: usize) {
    let Some(anims) = json.get_mut("animations").and_then(|v| v.as_array_mut()) else {
        return;
    };
    for a in anims.iter_mut() {
        let chans: Vec<Value> = a["channels"].as_array().cloned().unwrap_or_default();
        let keep: Vec<Value> = chans
            .into_iter()
            .filter(|c| {
                !(c["target"]["path"] == "weights"
                    && c["target"]["node"].as_u64() == Some(node as u64))
            })
            .collect();
        let samplers = a["samplers"].as_array().cloned().unwrap_or_default();
        let mut used: Vec<usize> = keep
            .iter()
            .filter_map(|c| c["sampler"].as_u64())
            .map(|s| s as usize)
            .collect();
        used.sort_unstable();
        used.dedup();
        let new_samplers: Vec<Value> = used
            .iter()
            .filter_map(|&s| samplers.get(s).cloned())
            .collect();
        let keep: Vec<Value> = keep
            .into_iter()
            .map(|mut c| {
                let s = c["sampler"].as_u64().unwrap_or(0) as usize;
                c["sampler"] = json!(used.iter().position(|&u| u == s).unwrap_or(0));
                c
            })
            .collect();
        a["channels"] = json!(keep);
        a["samplers"] = json!(new_samplers);
    }
    anims.retain(|a| a["channels"].as_array().is_some_and(|c| !c.is_empty()));
}

/// The loaded file written back decoded: every `EXT_meshopt_compression` view decompressed
/// (the extension dropped), external images embedded, unused data pruned, nothing else
/// changed. This is what a viewer without meshopt support (Blender 3.4) or the Khronos
/// validator, which does not check meshopt, is given for a compressed file.
pub fn decoded_glb(rig: &Rig) -> anyhow::Result<Vec<u8>> {
    let mut doc = base_document(rig)?;
    doc.prune()?;
    Ok(doc.to_glb())
}

/// The whole scene with the face replaced by the animated frame sequence, as GLB bytes.
pub fn animated_glb(rig: &Rig, set: &FrameSet) -> anyhow::Result<Vec<u8>> {
    Ok(replace_face(rig, set, true)?.to_glb())
}

/// The scene with the face at frame `k` (no animation), as GLB bytes.
pub fn frame_glb(rig: &Rig, set: &FrameSet, k: usize) -> anyhow::Result<Vec<u8>> {
    let one = std::slice::from_ref(set.frames.get(k).context("frame index out of range")?);
    let single = FrameSet {
        triangles: set.triangles,
        frames: one,
        origin: set.origin,
        fps: set.fps,
        weights: set.weights.get(k).map_or(&[], std::slice::from_ref),
    };
    Ok(replace_face(rig, &single, false)?.to_glb())
}

/// Write the animated GLB to `path` (atomically).
pub fn write_animated(
    rig: &Rig,
    set: &FrameSet,
    path: &Path,
    overwrite: Overwrite,
) -> anyhow::Result<()> {
    let bytes = animated_glb(rig, set)?;
    atomic::write(path, &bytes, overwrite)
}

/// Write one GLB per frame into `dir` as `frame_00000.glb`, … (each atomically), calling
/// `on_frame(k)` after frame k is written (for progress); returns the paths.
pub fn write_frames_dir(
    rig: &Rig,
    set: &FrameSet,
    dir: &Path,
    overwrite: Overwrite,
    on_frame: &dyn Fn(usize),
) -> anyhow::Result<Vec<PathBuf>> {
    let paths: Vec<PathBuf> = (0..set.frames.len())
        .map(|k| dir.join(format!("frame_{k:05}.glb")))
        .collect();
    atomic::check_free(&paths, overwrite)?;
    for (k, p) in paths.iter().enumerate() {
        atomic::write(p, &frame_glb(rig, set, k)?, overwrite)?;
        on_frame(k);
    }
    Ok(paths)
}

/// Weight keys fit a rig of `targets` morph targets: one weight vector per key time, each with
/// one weight per target.
pub fn check_weight_keys(keys: &WeightKeys, targets: usize) -> anyhow::Result<()> {
    if keys.weights.len() != keys.times.len() || keys.weights.iter().any(|w| w.len() != targets) {
        bail!("weight keys do not match the times and the {targets} targets");
    }
    Ok(())
}

/// A fresh blend-shape rig file: one mesh with morph targets (names in `extras.targetNames`)
/// and a linear weights animation, as GLB bytes. Positions in metres.
pub fn rig_glb(
    name: &str,
    mesh: &TriMesh,
    targets: &[MorphTarget],
    keys: &WeightKeys,
) -> anyhow::Result<Vec<u8>> {
    let n = mesh.positions.len();
    if let Some(t) = targets.iter().find(|t| t.positions.len() != n) {
        bail!(
            "target {} has {} deltas for {n} vertices",
            t.name,
            t.positions.len()
        );
    }
    check_weight_keys(keys, targets.len())?;
    let mut doc = Document::new();
    let pos = doc.push_f32(&flat(&mesh.positions), 3, Some(ARRAY_BUFFER));
    let nrm = doc.push_f32(&flat(&mesh.vertex_normals()), 3, Some(ARRAY_BUFFER));
    let idx = doc.push_indices(&mesh.triangles);
    let tj: Vec<Value> = targets
        .iter()
        .map(|t| {
            let mut o =
                json!({ "POSITION": doc.push_f32(&flat(&t.positions), 3, Some(ARRAY_BUFFER)) });
            if let Some(n) = t.normals.as_ref().filter(|n| n.len() == t.positions.len()) {
                o["NORMAL"] = json!(doc.push_f32(&flat(n), 3, Some(ARRAY_BUFFER)));
            }
            o
        })
        .collect();
    let mut prim = json!({ "attributes": { "POSITION": pos, "NORMAL": nrm }, "indices": idx, "material": 0, "mode": 4 });
    if !tj.is_empty() {
        prim["targets"] = json!(tj);
    }
    doc.json["materials"] = json!([{ "name": "skin", "pbrMetallicRoughness": { "baseColorFactor": [0.87, 0.68, 0.58, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6 } }]);
    let mut m = json!({ "name": name, "primitives": [prim] });
    if !targets.is_empty() {
        m["weights"] = json!(vec![0.0; targets.len()]);
        m["extras"] =
            json!({ "targetNames": targets.iter().map(|t| t.name.clone()).collect::<Vec<_>>() });
    }
    doc.json["meshes"] = json!([m]);
    doc.json["nodes"] = json!([{ "name": name, "mesh": 0 }]);
    doc.json["scenes"] = json!([{ "nodes": [0] }]);
    doc.json["scene"] = json!(0);
    if !keys.times.is_empty() && !targets.is_empty() {
        let input = doc.push_f32(&keys.times, 1, None);
        let output = doc.push_f32(&keys.weights.concat(), 1, None);
        doc.json["animations"] = json!([{
            "name": "performance",
            "samplers": [{ "input": input, "output": output, "interpolation": "LINEAR" }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }],
        }]);
    }
    Ok(doc.to_glb())
}
