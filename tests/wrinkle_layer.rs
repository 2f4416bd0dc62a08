//! The wrinkle layer (the default export): the rig kept on the refined skin (its two
//! primitives, materials, UV seam, blend shape and weights), wrinkle modes in its weights
//! channel; float, quantized and compressed files read back with furrow's loader, the Khronos
//! validator and Blender; a still rig's correctives.

mod common;

use furrow::io::accessor::AccessorReader;
use furrow::io::layer::{layer_glb, LayerOptions, Precision, Written};
use furrow::io::load::{load_bytes, LoadOptions, Rig};
use furrow::pipeline::layer::{self, Clip, LayerInput};
use furrow::pipeline::step::{blend::weld_positions, compose::carry};
use furrow::pipeline::{self, RunOptions, RunOutput};
use furrow::scene::Scene;
use nalgebra::Vector3;
use serde_json::json;
use std::path::{Path, PathBuf};

/// Sheet side (m) and cells per side: 8.3 mm edges, refined twice for the default skin.
const SIDE: f64 = 0.1;
const CELLS: usize = 12;
/// Frames of the clip (one key per frame at 30 fps).
const FRAMES: usize = 10;

/// The squeeze: the left half compressed towards the middle by 15 %, the right half
/// stretched as much (m).
fn squeeze(x: f64) -> f64 {
    (SIDE / 2.0 - x).abs() * 0.15
}

/// Vertices (x, y, u, v) and triangles of one half of the sheet: columns `i0..=i1`, the UVs
/// u = x / SIDE + `u_offset` (each half its own chart), v = y / SIDE.
fn half(i0: usize, i1: usize, u_offset: f64) -> (Vec<[f64; 4]>, Vec<[u16; 3]>) {
    let h = SIDE / CELLS as f64;
    let w = i1 - i0 + 1;
    let mut v = Vec::new();
    for j in 0..=CELLS {
        for i in i0..=i1 {
            let (x, y) = (i as f64 * h, j as f64 * h);
            v.push([x, y, x / SIDE + u_offset, y / SIDE]);
        }
    }
    let id = |i: usize, j: usize| (j * w + i) as u16;
    let mut t = Vec::new();
    for j in 0..CELLS {
        for i in 0..w - 1 {
            t.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            t.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    (v, t)
}

/// Bytes and JSON builder for the test rig.
struct Bin {
    bytes: Vec<u8>,
    json: serde_json::Value,
}

impl Bin {
    fn accessor(&mut self, data: Vec<u8>, acc: serde_json::Value) -> usize {
        while self.bytes.len() % 4 != 0 {
            self.bytes.push(0);
        }
        let views = self.json["bufferViews"].as_array_mut().unwrap();
        views
            .push(json!({ "buffer": 0, "byteOffset": self.bytes.len(), "byteLength": data.len() }));
        let view = views.len() - 1;
        self.bytes.extend(data);
        let mut acc = acc;
        acc["bufferView"] = json!(view);
        let accs = self.json["accessors"].as_array_mut().unwrap();
        accs.push(acc);
        accs.len() - 1
    }

    fn f32s(&mut self, v: &[f64], ty: &str, bounds: bool) -> usize {
        let comps = match ty {
            "SCALAR" => 1,
            "VEC2" => 2,
            _ => 3,
        };
        let mut acc = json!({ "componentType": 5126, "count": v.len() / comps, "type": ty });
        if bounds {
            let (mut lo, mut hi) = (vec![f32::MAX; comps], vec![f32::MIN; comps]);
            for e in v.chunks(comps) {
                for k in 0..comps {
                    lo[k] = lo[k].min(e[k] as f32);
                    hi[k] = hi[k].max(e[k] as f32);
                }
            }
            acc["min"] = json!(lo);
            acc["max"] = json!(hi);
        }
        let data = v.iter().flat_map(|x| (*x as f32).to_le_bytes()).collect();
        self.accessor(data, acc)
    }
}

/// The test rig: a 10 cm sheet in two primitives (left and right halves, two materials, the
/// middle column duplicated: a UV seam), one blend shape "squeeze" animated 0 → 1 over 10
/// frames (a key per frame), a second animation of the face's weights, and a tiny "eye" mesh
/// with one target whose weights channel shares the face's sampler.
fn seam_rig(animated: bool) -> Vec<u8> {
    let mut b = Bin {
        bytes: Vec::new(),
        json: json!({ "asset": { "version": "2.0" }, "scene": 0, "scenes": [{ "nodes": [0, 1] }],
            "bufferViews": [], "accessors": [],
            "materials": [{ "name": "left" }, { "name": "right", "pbrMetallicRoughness": { "baseColorFactor": [0.2, 0.4, 0.8, 1.0] } }] }),
    };
    let mut prims = Vec::new();
    for (m, (i0, i1, off)) in [(0, CELLS / 2, 0.0), (CELLS / 2, CELLS, 1.0)]
        .into_iter()
        .enumerate()
    {
        let (v, t) = half(i0, i1, off);
        let pos: Vec<f64> = v.iter().flat_map(|p| [p[0], p[1], 0.0]).collect();
        let uv: Vec<f64> = v.iter().flat_map(|p| [p[2], p[3]]).collect();
        let d: Vec<f64> = v.iter().flat_map(|p| [squeeze(p[0]), 0.0, 0.0]).collect();
        let pa = b.f32s(&pos, "VEC3", true);
        let ua = b.f32s(&uv, "VEC2", false);
        let da = b.f32s(&d, "VEC3", true);
        let idx: Vec<u8> = t.iter().flatten().flat_map(|i| i.to_le_bytes()).collect();
        let ia = b.accessor(
            idx,
            json!({ "componentType": 5123, "count": t.len() * 3, "type": "SCALAR" }),
        );
        prims.push(
            json!({ "attributes": { "POSITION": pa, "TEXCOORD_0": ua }, "indices": ia,
            "material": m, "targets": [{ "POSITION": da }] }),
        );
    }
    let eye_p = b.f32s(
        &[0.3, 0.0, 0.0, 0.301, 0.0, 0.0, 0.3, 0.001, 0.0],
        "VEC3",
        true,
    );
    let eye_d = b.f32s(
        &[0.0, 0.0, 1e-4, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
        "VEC3",
        true,
    );
    b.json["meshes"] = json!([
        { "name": "face", "primitives": prims, "extras": { "targetNames": ["squeeze"] } },
        { "name": "eye", "primitives": [{ "attributes": { "POSITION": eye_p }, "targets": [{ "POSITION": eye_d }] }] }
    ]);
    b.json["nodes"] = json!([{ "name": "face", "mesh": 0 }, { "name": "eye", "mesh": 1 }]);
    if animated {
        let times: Vec<f64> = (0..FRAMES).map(|k| k as f64 / 30.0).collect();
        let weights: Vec<f64> = (0..FRAMES)
            .map(|k| k as f64 / (FRAMES - 1) as f64)
            .collect();
        let ti = b.f32s(&times, "SCALAR", true);
        let wo = b.f32s(&weights, "SCALAR", false);
        let t2 = b.f32s(&[0.0, 0.5], "SCALAR", true);
        let w2 = b.f32s(&[0.0, 0.5], "SCALAR", false);
        b.json["animations"] = json!([
            { "name": "performance", "samplers": [{ "input": ti, "output": wo }],
              "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } },
                           { "sampler": 0, "target": { "node": 1, "path": "weights" } }] },
            { "name": "other", "samplers": [{ "input": t2, "output": w2, "interpolation": "STEP" }],
              "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }] }
        ]);
    }
    b.json["buffers"] = json!([{ "byteLength": b.bytes.len() }]);
    common::glb_bytes(&b.json, &b.bytes)
}

/// The rig at `path`, loaded, and its pipeline run (every frame, default scene).
fn run(path: &Path) -> (Rig, RunOutput) {
    let rig = load_bytes(path, &std::fs::read(path).unwrap(), &LoadOptions::default()).unwrap();
    let opts = RunOptions::new(Scene::default());
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    (rig, out)
}

fn write(
    rig: &Rig,
    out: &RunOutput,
    built: &layer::Built,
    precision: Precision,
    compress: bool,
) -> Written {
    let opts = LayerOptions {
        precision,
        compress,
    };
    layer_glb(rig, &out.face_map, &built.layer, opts).unwrap()
}

/// A frame-sequence export (`--export sequence`) read back: its face and its animation.
fn load_sequence(path: &Path) -> Rig {
    let opts = LoadOptions {
        mesh: Some("face (furrow)".into()),
        animation: Some("furrow_wrinkles".into()),
        ..Default::default()
    };
    load_bytes(path, &std::fs::read(path).unwrap(), &opts).unwrap()
}

fn load(path: &Path, bytes: &[u8]) -> Rig {
    load_bytes(path, bytes, &LoadOptions::default()).unwrap()
}

/// Largest distance between the file's frames (every target at its animation's weights) and
/// `reference` (per written frame, per refined vertex; m).
fn frame_error(back: &Rig, w: &Written, reference: &[Vec<Vector3<f64>>]) -> f64 {
    let track = back.track.as_ref().expect("the layer's weights animation");
    let mut worst = 0.0f64;
    for (k, r) in reference.iter().enumerate() {
        let p = back.blend(&track.sample(k as f64 / 30.0));
        for (i, &v) in w.refined_of_vertex.iter().enumerate() {
            worst = worst.max((p[i] - r[v]).norm());
        }
    }
    worst
}

#[test]
fn the_layer_keeps_the_rig_and_reproduces_the_frames_in_every_storage() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("seam.glb");
    std::fs::write(&path, seam_rig(true)).unwrap();
    let (rig, out) = run(&path);
    assert!(out.animated && out.frames.len() == FRAMES);
    let map = &out.face_map;
    assert!(
        map.refined_count() > 4 * 13 * 14,
        "refined: {}",
        map.refined_count()
    );
    let input = LayerInput {
        rig: &rig,
        map,
        frames: &out.frames,
        weights: &out.weights,
        clip: Clip::Animated {
            fps: 30.0,
            first_frame: 0,
            clip_frames: FRAMES,
        },
    };
    let built = layer::build(&input).unwrap();
    let rep = &built.report;
    eprintln!("{rep:?}");
    let depth = rep.wrinkle_depth_m;
    assert!(depth > 1e-4, "the squeeze wrinkles: depth {depth}");
    assert!(
        rep.wrinkle_targets >= 1 && rep.basis_error_of_depth <= 0.02,
        "{rep:?}"
    );
    // The blend-shape surface the layer starts from is the run's own.
    for (a, b) in built.smooth.iter().zip(&out.smooth) {
        assert_eq!(a, b);
    }
    let float = write(&rig, &out, &built, Precision::Float, false);
    let quant = write(&rig, &out, &built, Precision::Quantized, false);
    let packed = write(&rig, &out, &built, Precision::Quantized, true);
    let files: Vec<PathBuf> = [
        ("float", &float),
        ("quantized", &quant),
        ("compressed", &packed),
    ]
    .iter()
    .map(|(n, w)| {
        let p = dir.path().join(format!("{n}.glb"));
        std::fs::write(&p, &w.bytes).unwrap();
        p
    })
    .collect();
    eprintln!(
        "sizes: float {} B, quantized {} B, compressed {} B",
        float.bytes.len(),
        quant.bytes.len(),
        packed.bytes.len()
    );
    assert!(quant.bytes.len() < float.bytes.len() && packed.bytes.len() < quant.bytes.len());
    let fb = load(&files[0], &float.bytes);
    check_rig_kept(&rig, &out, &fb, &float);
    // The float file reproduces the frame sequence within the basis error (and f32).
    let e_float = frame_error(&fb, &float, &out.frames);
    assert!(
        e_float <= rep.basis_error_m + 1e-6,
        "{e_float} vs {}",
        rep.basis_error_m
    );
    // The quantized file decodes to the float layer within 1 % of the depth, and to the
    // frames within 3 % together with the basis.
    let qb = load(&files[1], &quant.bytes);
    let float_layer: Vec<Vec<Vector3<f64>>> = (0..FRAMES)
        .map(|k| {
            let p = fb.blend(&fb.track.as_ref().unwrap().sample(k as f64 / 30.0));
            let mut r = vec![Vector3::zeros(); map.refined_count()];
            for (i, &v) in float.refined_of_vertex.iter().enumerate() {
                r[v] = p[i];
            }
            r
        })
        .collect();
    let e_quant = frame_error(&qb, &quant, &float_layer);
    let e_total = frame_error(&qb, &quant, &out.frames);
    eprintln!(
        "errors of depth: float {:.4}, quantized vs float {:.5}, total {:.4}",
        e_float / depth,
        e_quant / depth,
        e_total / depth
    );
    assert!(e_quant < 0.01 * depth && e_total < 0.03 * depth);
    // The compressed file reads back to the same accessors as the uncompressed one.
    let cb = load(&files[2], &packed.bytes);
    same_accessors(&qb, &cb);
    let decoded = dir.path().join("decoded.glb");
    std::fs::write(&decoded, furrow::io::export::decoded_glb(&cb).unwrap()).unwrap();
    if let Some(v) = common::validate(&[files[0].clone(), files[1].clone(), decoded.clone()]) {
        common::assert_valid(&v);
    }
    let names = ["squeeze"]
        .iter()
        .map(|s| s.to_string())
        .chain((0..rep.wrinkle_targets).map(|m| format!("wrinkle_{m:02}")));
    check_blender(&files[1], &names.collect::<Vec<_>>());
}

/// The float file keeps the rig: two primitives with their materials and the UV seam, the
/// squeeze unchanged at the original vertices and S-carried at the refined ones, the rig's
/// weights in its channel (keys kept) with the wrinkle weights within ±1, the other animation
/// padded, the eye's channel on its own sampler.
fn check_rig_kept(rig: &Rig, out: &RunOutput, back: &Rig, w: &Written) {
    let j = &back.container.json;
    let face = back.face();
    let mesh = &j["meshes"][face.mesh];
    let prims = mesh["primitives"].as_array().unwrap();
    assert_eq!(prims.len(), 2);
    assert_eq!(
        (prims[0]["material"].as_u64(), prims[1]["material"].as_u64()),
        (Some(0), Some(1))
    );
    assert_eq!(j["materials"][1]["name"], "right");
    let n_targets = face.targets.len();
    assert_eq!(mesh["extras"]["targetNames"][0], "squeeze");
    assert_eq!(face.targets[0].name, "squeeze");
    // UVs: linear on the flat sheet, so interpolation is exact; each side of the seam keeps
    // its chart (the left half's u in [0, ½], the right's in [1½, 2]).
    let uv = back.face_attribute("TEXCOORD_0").unwrap();
    let mut seam = [0, 0];
    for (r, span) in face.primitives.iter().enumerate() {
        for i in span.vertices() {
            let p = face.positions[i];
            let (u, v) = (uv.data[2 * i], uv.data[2 * i + 1]);
            assert!(
                (u - (p.x / SIDE + r as f64)).abs() < 1e-6 && (v - p.y / SIDE).abs() < 1e-6,
                "uv {u} {v} at {p}"
            );
            if (p.x - SIDE / 2.0).abs() < 1e-7 {
                seam[r] += 1;
            }
        }
    }
    assert!(
        seam[0] > CELLS && seam[0] == seam[1],
        "seam vertices per side: {seam:?}"
    );
    // The squeeze: S applied to the loaded deltas, and at the original vertices exactly the
    // file's own values.
    let map = &out.face_map;
    let lf = rig.face();
    let welded = weld_positions(
        &lf.targets[0].positions,
        &map.welded_of_loaded,
        map.welded_count,
    );
    let carried = carry(&map.subdivision, &welded);
    let mut originals = 0;
    for (i, &v) in w.refined_of_vertex.iter().enumerate() {
        let d = face.targets[0].positions[i];
        assert!(
            (d - carried[v]).norm() < 1e-7,
            "vertex {i}: {d} vs {}",
            carried[v]
        );
        if let Some(l) = lf.positions.iter().position(|p| *p == face.positions[i]) {
            assert_eq!(d, lf.targets[0].positions[l], "original vertex {l}");
            originals += 1;
        }
    }
    assert_eq!(originals, lf.positions.len());
    // Weights: the rig's own values at its own keys, the wrinkle weights in [−1, 1].
    let track = back.track.as_ref().unwrap();
    let orig = rig.track.as_ref().unwrap();
    assert_eq!(track.times, orig.times);
    for (a, b) in track.values.iter().zip(&orig.values) {
        assert_eq!(a[0], b[0]);
        assert!(a[1..].iter().all(|x| x.abs() <= 1.0 + 1e-6));
    }
    // The other animation's face channel is padded with zeros; the eye has its own sampler.
    let reader = AccessorReader::new(&back.path, &back.container);
    let other = &j["animations"][1]["samplers"][0];
    let vals = reader
        .read(other["output"].as_u64().unwrap() as usize)
        .unwrap();
    assert_eq!(vals.data.len(), 2 * n_targets);
    assert!(vals.data[1..n_targets].iter().all(|&x| x == 0.0) && vals.data[n_targets] == 0.5);
    let chans = &j["animations"][0]["channels"];
    assert_ne!(chans[0]["sampler"], chans[1]["sampler"]);
    let eye_out =
        &j["animations"][0]["samplers"][chans[1]["sampler"].as_u64().unwrap() as usize]["output"];
    assert_eq!(
        reader
            .read(eye_out.as_u64().unwrap() as usize)
            .unwrap()
            .data
            .len(),
        FRAMES
    );
}

/// Every accessor of `a` and `b` decodes to the same values.
fn same_accessors(a: &Rig, b: &Rig) {
    let (ja, jb) = (
        &a.container.json["accessors"],
        &b.container.json["accessors"],
    );
    let n = ja.as_array().unwrap().len();
    assert_eq!(n, jb.as_array().unwrap().len());
    let (ra, rb) = (
        AccessorReader::new(&a.path, &a.container),
        AccessorReader::new(&b.path, &b.container),
    );
    for i in 0..n {
        assert_eq!(ra.read(i).unwrap(), rb.read(i).unwrap(), "accessor {i}");
    }
    assert!(b
        .extensions_used
        .iter()
        .any(|e| e == "EXT_meshopt_compression"));
}

/// Blender imports `file` with the rig's and the wrinkle shape keys and an action animating
/// them.
fn check_blender(file: &Path, names: &[String]) {
    let Some(r) = common::blender_import(file) else {
        return;
    };
    assert!(r["error"].is_null(), "{r}");
    let face = r["objects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["name"] == "face")
        .expect("face object");
    let keys: Vec<&str> = face["shape_keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap())
        .collect();
    assert_eq!(keys[0], "Basis");
    assert_eq!(
        keys[1..],
        names.iter().map(|s| s.as_str()).collect::<Vec<_>>()[..],
        "{r}"
    );
    assert_eq!(face["materials"].as_array().unwrap().len(), 2, "{r}");
    let curves: Vec<String> = r["actions"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|a| {
            a["fcurves"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_str().unwrap().to_string())
        })
        .collect();
    for n in names {
        assert!(
            curves.contains(&format!("key_blocks[\"{n}\"].value")),
            "{n} not animated: {r}"
        );
    }
}

/// A still rig (no animation): each shape solved alone at weight 1 gives a corrective
/// `<shape>_wrinkle`; read back, the shape at 1 plus its corrective is furrow's own solve of
/// the shape within the storage error; the file validates and Blender imports it.
#[test]
fn a_still_rig_gets_one_corrective_per_wrinkling_shape() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("still.glb");
    std::fs::write(&path, seam_rig(false)).unwrap();
    let (rig, out) = run(&path);
    assert!(!out.animated);
    assert_eq!(out.weights, vec![vec![1.0]]);
    let input = LayerInput {
        rig: &rig,
        map: &out.face_map,
        frames: &out.frames,
        weights: &out.weights,
        clip: Clip::Still { first_shape: 0 },
    };
    let mut built = layer::build(&input).unwrap();
    assert_eq!(built.layer.wrinkles.len(), 1);
    assert_eq!(built.layer.wrinkles[0].name, "squeeze_wrinkle");
    let w = write(&rig, &out, &built, Precision::Quantized, false);
    layer::check_file(&rig, &mut built, &w, &out.frames).unwrap();
    let f = built.report.file.as_ref().unwrap();
    eprintln!("{:?}", built.report);
    assert!(f.total_error_of_depth < 0.01, "{f:?}");
    // Independently: the squeeze and its corrective at 1 against the solve.
    let file = dir.path().join("out.glb");
    std::fs::write(&file, &w.bytes).unwrap();
    let back = load(&file, &w.bytes);
    assert!(back.track.is_none());
    let p = back.blend(&[1.0, 1.0]);
    let depth = built.report.wrinkle_depth_m;
    for (i, &v) in w.refined_of_vertex.iter().enumerate() {
        assert!((p[i] - out.frames[0][v]).norm() < 0.01 * depth);
    }
    if let Some(v) = common::validate(std::slice::from_ref(&file)) {
        common::assert_valid(&v);
    }
    if let Some(r) = common::blender_import(&file) {
        assert!(r["error"].is_null(), "{r}");
        assert!(r.to_string().contains("squeeze_wrinkle"), "{r}");
    }
}

/// The CLI writes the layer by default with its report, refuses flags the sequence form does
/// not take, and `--export sequence` keeps one target per frame.
#[test]
fn animate_writes_the_layer_and_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("seam.glb");
    std::fs::write(&path, seam_rig(true)).unwrap();
    let furrow = || std::process::Command::new(env!("CARGO_BIN_EXE_furrow"));
    let out = dir.path().join("out.glb");
    let rep = dir.path().join("r.json");
    let o = furrow()
        .arg("animate")
        .arg(&path)
        .arg("-o")
        .arg(&out)
        .arg("--report")
        .arg(&rep)
        .arg("--compress")
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let said = String::from_utf8_lossy(&o.stdout);
    assert!(
        said.contains("wrinkle targets") && said.contains("meshopt"),
        "{said}"
    );
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(&rep).unwrap()).unwrap();
    let e = &r["export"];
    assert_eq!(e["form"], "wrinkle_layer");
    assert!(e["wrinkle_targets"].as_u64().unwrap() >= 1);
    assert_eq!(
        e["file"]["bytes"].as_u64().unwrap() as usize,
        std::fs::metadata(&out).unwrap().len() as usize
    );
    assert!(e["weights"].as_str().unwrap().contains("kept"), "{e}");
    let bad = furrow()
        .arg("animate")
        .arg(&path)
        .arg("-o")
        .arg(dir.path().join("x.glb"))
        .args(["--export", "sequence", "--compress"])
        .output()
        .unwrap();
    assert_eq!(bad.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&bad.stderr).contains("--compress"));
    let seq = dir.path().join("seq.glb");
    let o = furrow()
        .arg("animate")
        .arg(&path)
        .arg("-o")
        .arg(&seq)
        .args(["--export", "sequence", "--quiet"])
        .output()
        .unwrap();
    assert!(o.status.success());
    assert_eq!(load_sequence(&seq).face().targets.len(), FRAMES);
}

/// The demo's rig over a short clip (frames 0–11, the brow raise: wrinkles from frame 8): the layer, read back, is the sequence export, read back,
/// within the modes' 2 % and 3 % with the quantization.
#[test]
fn the_layer_reproduces_the_sequence_export_on_the_demo_clip() {
    let face = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb");
    let dir = tempfile::tempdir().unwrap();
    let rig = load_bytes(
        &face,
        &std::fs::read(&face).unwrap(),
        &LoadOptions::default(),
    )
    .unwrap();
    let count = pipeline::plan::clip_weights(&rig, 30.0).0.len();
    let opts = RunOptions::new(Scene::default())
        .frames(pipeline::frames::FrameRange { start: 0, end: 12 });
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    let seq = dir.path().join("seq.glb");
    let set = furrow::io::export::FrameSet {
        triangles: &out.triangles,
        frames: &out.frames,
        origin: &out.origin,
        fps: 30.0,
        weights: &[],
    };
    furrow::io::export::write_animated(&rig, &set, &seq, furrow::io::atomic::Overwrite::Refuse)
        .unwrap();
    let sb = load_sequence(&seq);
    let sequence: Vec<Vec<Vector3<f64>>> = (0..12)
        .map(|k| sb.blend(&sb.track.as_ref().unwrap().sample(k as f64 / 30.0)))
        .collect();
    let input = LayerInput {
        rig: &rig,
        map: &out.face_map,
        frames: &out.frames,
        weights: &out.weights,
        clip: Clip::Animated {
            fps: 30.0,
            first_frame: 0,
            clip_frames: count,
        },
    };
    let built = layer::build(&input).unwrap();
    let rep = &built.report;
    let w = write(&rig, &out, &built, Precision::Quantized, false);
    let file = dir.path().join("layer.glb");
    std::fs::write(&file, &w.bytes).unwrap();
    let lb = load(&file, &w.bytes);
    let e = frame_error(&lb, &w, &sequence);
    let depth = rep.wrinkle_depth_m;
    eprintln!(
        "demo :12 — K {}, basis {:.3} %, layer vs sequence {:.3} % of {:.3} mm",
        rep.wrinkle_targets,
        100.0 * rep.basis_error_of_depth,
        100.0 * e / depth,
        depth * 1e3
    );
    assert!(depth > 5e-4 && rep.basis_error_of_depth <= 0.02);
    assert!(e <= 0.03 * depth, "{e} of {depth}");
}
