//! glTF loading against known answers: the sample files' published contents, hand-computed
//! transforms, every accessor encoding, and gltfpack-compressed copies.

mod common;

use furrow::io::inspect::summarize;
use furrow::io::{load, LoadOptions};
use nalgebra::Vector3;
use serde_json::json;
use std::path::{Path, PathBuf};

fn write_glb(dir: &Path, name: &str, j: &serde_json::Value, b: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, common::glb_bytes(j, b)).unwrap();
    p
}

/// Counts from ../shared/data/README.md (the files' own documentation).
#[test]
fn shared_files_have_their_documented_contents() {
    let Some(files) = common::shared_glbs() else {
        return;
    };
    let file = |name: &str| files.iter().find(|p| p.ends_with(name)).unwrap().clone();
    let s = summarize(&file("SimpleMorph.glb")).unwrap();
    assert_eq!(
        (
            s.meshes[0].vertices,
            s.meshes[0].targets.len(),
            s.animations.len()
        ),
        (3, 2, 1)
    );
    let s = summarize(&file("AnimatedMorphCube.glb")).unwrap();
    assert_eq!((s.meshes[0].vertices, s.meshes[0].targets.len()), (24, 2));
    let s = summarize(&file("AnimatedMorphSphere.glb")).unwrap();
    assert_eq!((s.meshes[0].vertices, s.meshes[0].targets.len()), (1876, 2));
    let s = summarize(&file("MorphStressTest.glb")).unwrap();
    assert_eq!(
        (
            s.meshes[0].vertices,
            s.meshes[0].primitives,
            s.meshes[0].targets.len(),
            s.animations.len()
        ),
        (1504 + 24, 2, 8, 3)
    );
    let s = summarize(&file("RobotExpressive.glb")).unwrap();
    let heads: Vec<usize> = s
        .meshes
        .iter()
        .filter(|m| !m.targets.is_empty())
        .map(|m| m.vertices)
        .collect();
    assert_eq!(heads, vec![302, 876, 564]);
    assert!(s
        .meshes
        .iter()
        .filter(|m| !m.targets.is_empty())
        .all(|m| m.targets == ["Angry", "Surprised", "Sad"]));
    assert_eq!(s.animations.len(), 14);
    assert!(s.meshes.iter().any(|m| m.skinned));
    // The robot's feet hold zero-area triangles (gltfpack drops exactly these: 33 → 32, 34 → 32).
    let feet: Vec<(usize, f64)> = s
        .meshes
        .iter()
        .filter(|m| m.name.starts_with("Foot"))
        .map(|m| (m.slivers, m.worst_quality))
        .collect();
    assert_eq!(feet, vec![(1, 0.0), (2, 0.0)]);
    let face = summarize(
        Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("rigs/face.glb")
            .as_path(),
    )
    .unwrap();
    assert_eq!(face.meshes[0].slivers, 0);
    assert!(face.meshes[0].worst_quality > 0.5);
    // Face choice: Head_2, Head_3 and Head_4 carry the same 3 targets, but only Head_4's
    // move any vertex (the others' deltas are all zero): it is the face; --mesh picks by name.
    let r = load(&file("RobotExpressive.glb"), &LoadOptions::default()).unwrap();
    assert_eq!(r.face().name, "Head_4");
    assert!(
        r.face_reason.contains("most morph targets"),
        "{}",
        r.face_reason
    );
    let r = load(
        &file("RobotExpressive.glb"),
        &LoadOptions {
            mesh: Some("Head_3".into()),
            animation: Some("Yes".into()),
            ..Default::default()
        },
    )
    .unwrap();
    assert_eq!(r.face().positions.len(), 876);
    assert!(r.track.is_some());
    let e = load(
        &file("RobotExpressive.glb"),
        &LoadOptions {
            mesh: Some("Nose".into()),
            animation: None,
            ..Default::default()
        },
    )
    .err()
    .unwrap()
    .to_string();
    assert!(e.contains("Head_2") && e.contains("--mesh"), "{e}");
}

#[test]
fn node_transforms_are_applied_in_world_space() {
    let d = tempfile::tempdir().unwrap();
    let (mut j, b) = common::tiny_rig();
    // parent: translate (1,2,3); child (the mesh): rotate 90° about z, scale 2.
    let s = std::f64::consts::FRAC_1_SQRT_2;
    j["nodes"] = json!([
        { "children": [1], "translation": [1.0, 2.0, 3.0] },
        { "mesh": 0, "rotation": [0.0, 0.0, s, s], "scale": [2.0, 2.0, 2.0] }
    ]);
    j["animations"][0]["channels"][0]["target"]["node"] = json!(1);
    let p = write_glb(d.path(), "xf.glb", &j, &b);
    let r = load(&p, &LoadOptions::default()).unwrap();
    let f = r.face();
    // local (1,1,0) → scale (2,2,0) → rotate 90° about z (−2,2,0) → translate (−1,4,3).
    assert!(
        (f.positions[2] - Vector3::new(-1.0, 4.0, 3.0)).norm() < 1e-6,
        "{:?}",
        f.positions[2]
    );
    // the target delta (0,0,0.1) is a vector: scaled and rotated, not translated → (0,0,0.2).
    assert!((f.targets[0].positions[2] - Vector3::new(0.0, 0.0, 0.2)).norm() < 1e-6);
    // a column-major matrix gives the same answer as TRS.
    let (mut j2, b2) = (j.clone(), b.clone());
    j2["nodes"][1] = json!({ "mesh": 0, "matrix": [0.0, 2.0, 0.0, 0.0, -2.0, 0.0, 0.0, 0.0, 0.0, 0.0, 2.0, 0.0, 0.0, 0.0, 0.0, 1.0] });
    let r2 = load(
        &write_glb(d.path(), "xf2.glb", &j2, &b2),
        &LoadOptions::default(),
    )
    .unwrap();
    for (a, b) in r2.face().positions.iter().zip(&f.positions) {
        assert!((a - b).norm() < 1e-6);
    }
}

#[test]
fn quantized_normalized_sparse_and_strip_encodings_decode_exactly() {
    let d = tempfile::tempdir().unwrap();
    let (mut j, mut b) = common::tiny_rig();
    // KHR_mesh_quantization: POSITION as normalized i16 (value/32767), scale on the node.
    let q: [i16; 12] = [0, 0, 0, 32767, 0, 0, 32767, 32767, 0, 0, 32767, 0];
    let off = b.len();
    b.extend(q.iter().flat_map(|v| v.to_le_bytes()));
    // u8 triangle-strip indices 0 1 3 2 (quad as a strip).
    let ioff = b.len();
    b.extend([0u8, 1, 3, 2]);
    // sparse target: no bufferView, vertex 2 gets (0, 0, -127/127) as normalized i8.
    let soff = b.len();
    b.extend([2u8]);
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let svoff = b.len();
    b.extend([0u8, 0, 0x81, 0]); // i8: 0, 0, -127 (then padding)
    j["bufferViews"].as_array_mut().unwrap().extend([
        json!({ "buffer": 0, "byteOffset": off, "byteLength": 24 }),
        json!({ "buffer": 0, "byteOffset": ioff, "byteLength": 4 }),
        json!({ "buffer": 0, "byteOffset": soff, "byteLength": 1 }),
        json!({ "buffer": 0, "byteOffset": svoff, "byteLength": 3 }),
    ]);
    j["buffers"][0]["byteLength"] = json!(b.len());
    j["accessors"][0] = json!({ "bufferView": 5, "componentType": 5122, "normalized": true, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [32767,32767,0] });
    j["accessors"][1] =
        json!({ "bufferView": 6, "componentType": 5121, "count": 4, "type": "SCALAR" });
    j["accessors"][2] = json!({ "componentType": 5120, "normalized": true, "count": 4, "type": "VEC3",
        "sparse": { "count": 1, "indices": { "bufferView": 7, "componentType": 5121 }, "values": { "bufferView": 8 } } });
    j["meshes"][0]["primitives"][0]["mode"] = json!(5);
    j["nodes"][0]["scale"] = json!([0.5, 0.5, 0.5]);
    j["extensionsUsed"] = json!(["KHR_mesh_quantization"]);
    j["extensionsRequired"] = json!(["KHR_mesh_quantization"]);
    let r = load(
        &write_glb(d.path(), "q.glb", &j, &b),
        &LoadOptions::default(),
    )
    .unwrap();
    let f = r.face();
    assert_eq!(f.positions[2], Vector3::new(0.5, 0.5, 0.0));
    assert_eq!(f.targets[0].positions[2], Vector3::new(0.0, 0.0, -0.5));
    assert_eq!(f.targets[0].positions[1], Vector3::zeros());
    // strip 0 1 3 2 → triangles (0,1,3) and (3,1,2) — both counter-clockwise.
    assert_eq!(f.triangles, vec![[0, 1, 3], [3, 1, 2]]);
}

#[test]
fn gltf_with_external_and_embedded_buffers() {
    use base64::Engine;
    let d = tempfile::tempdir().unwrap();
    let (mut j, b) = common::tiny_rig();
    std::fs::write(d.path().join("tiny data.bin"), &b).unwrap();
    j["buffers"][0]["uri"] = json!("tiny%20data.bin");
    let p = d.path().join("ext.gltf");
    std::fs::write(&p, serde_json::to_vec(&j).unwrap()).unwrap();
    let r = load(&p, &LoadOptions::default()).unwrap();
    assert_eq!(r.face().positions.len(), 4);
    j["buffers"][0]["uri"] = json!(format!(
        "data:application/octet-stream;base64,{}",
        base64::engine::general_purpose::STANDARD.encode(&b)
    ));
    let p2 = d.path().join("emb.gltf");
    std::fs::write(&p2, serde_json::to_vec(&j).unwrap()).unwrap();
    let r2 = load(&p2, &LoadOptions::default()).unwrap();
    assert_eq!(r2.face().positions, r.face().positions);
    let w = r2.frame_weights(4.0);
    assert_eq!(w.len(), 5);
    assert!((w[1][0] - 0.25).abs() < 1e-7);
}

#[test]
fn step_and_cubicspline_weight_channels_sample_per_spec() {
    let d = tempfile::tempdir().unwrap();
    let (mut j, mut b) = common::tiny_rig();
    j["animations"][0]["samplers"][0]["interpolation"] = json!("STEP");
    let r = load(
        &write_glb(d.path(), "step.glb", &j, &b),
        &LoadOptions::default(),
    )
    .unwrap();
    let w = r.frame_weights(4.0);
    assert_eq!(
        w.iter().map(|x| x[0]).collect::<Vec<_>>(),
        vec![0.0, 0.0, 0.0, 0.0, 1.0]
    );
    // CUBICSPLINE: per key [in-tangent, value, out-tangent]; keys (0: v 0, out 3), (1: in 0, v 1).
    let off = b.len();
    b.extend(
        [0.0f32, 0.0, 3.0, 0.0, 1.0, 0.0]
            .iter()
            .flat_map(|v| v.to_le_bytes()),
    );
    j["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "buffer": 0, "byteOffset": off, "byteLength": 24 }));
    j["accessors"]
        .as_array_mut()
        .unwrap()
        .push(json!({ "bufferView": 5, "componentType": 5126, "count": 6, "type": "SCALAR" }));
    j["buffers"][0]["byteLength"] = json!(b.len());
    j["animations"][0]["samplers"][0] =
        json!({ "input": 3, "output": 5, "interpolation": "CUBICSPLINE" });
    let r = load(
        &write_glb(d.path(), "cubic.glb", &j, &b),
        &LoadOptions::default(),
    )
    .unwrap();
    let w = r.frame_weights(4.0);
    for (k, wk) in w.iter().enumerate() {
        let s = k as f64 / 4.0;
        let expect = 3.0 * (s * s * s - 2.0 * s * s + s) + (-2.0 * s * s * s + 3.0 * s * s);
        assert!(
            (wk[0] - expect).abs() < 1e-6,
            "frame {k}: {} vs {expect}",
            wk[0]
        );
    }
}

/// gltfpack output (KHR_mesh_quantization + EXT_meshopt_compression, as capture tools write):
/// the same meshes, triangles, targets, animations and sizes as the original.
#[test]
fn gltfpack_compressed_copies_read_the_same() {
    let Some(files) = common::shared_glbs() else {
        return;
    };
    gltfpack_copies_read_the_same(files);
}

/// The same on the project's own face rig (what a clone without `../shared` still covers).
#[test]
fn gltfpack_copy_of_the_face_rig_reads_the_same() {
    gltfpack_copies_read_the_same(vec![
        Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb")
    ]);
}

fn gltfpack_copies_read_the_same(files: Vec<PathBuf>) {
    let Some(nm) = common::node_modules() else {
        assert!(
            !common::tools_required(),
            "gltfpack is not installed: npm ci --prefix .ci"
        );
        common::note("gltfpack not installed (npm ci --prefix .ci); skipped");
        return;
    };
    let d = tempfile::tempdir().unwrap();
    for src in files {
        let out = d.path().join(src.file_name().unwrap());
        let st = std::process::Command::new("node")
            .arg(nm.join("gltfpack/cli.js"))
            .args(["-cc", "-kn", "-km", "-ke", "-i"])
            .arg(&src)
            .arg("-o")
            .arg(&out)
            .output()
            .unwrap();
        assert!(
            st.status.success(),
            "gltfpack failed on {}: {}",
            src.display(),
            String::from_utf8_lossy(&st.stderr)
        );
        let a = summarize(&src).unwrap();
        let b = summarize(&out).unwrap();
        assert!(
            b.extensions_required
                .iter()
                .any(|e| e == "EXT_meshopt_compression"),
            "{:?}",
            b.extensions_required
        );
        assert!(b
            .extensions_required
            .iter()
            .any(|e| e == "KHR_mesh_quantization"));
        assert_eq!(a.meshes.len(), b.meshes.len(), "{}", src.display());
        // gltfpack renumbers nodes and drops degenerate triangles of ordinary meshes: compare
        // the blend-shape meshes one by one (sorted by triangle count), the rest in total.
        let morph = |s: &furrow::io::inspect::Summary| {
            let mut v: Vec<_> = s
                .meshes
                .iter()
                .filter(|m| !m.targets.is_empty())
                .cloned()
                .collect();
            v.sort_by_key(|m| m.triangles);
            v
        };
        let (ma_all, mb_all) = (morph(&a), morph(&b));
        assert_eq!(ma_all.len(), mb_all.len(), "{}", src.display());
        let total =
            |s: &furrow::io::inspect::Summary| s.meshes.iter().map(|m| m.triangles).sum::<usize>();
        assert!(
            total(&b) <= total(&a) && total(&b) * 100 >= total(&a) * 99,
            "{}",
            src.display()
        );
        for (ma, mb) in ma_all.iter().zip(&mb_all) {
            assert_eq!(ma.triangles, mb.triangles, "{}", src.display());
            assert_eq!(ma.targets, mb.targets);
            // gltfpack may merge duplicate vertices; never adds any.
            assert!(mb.vertices <= ma.vertices && mb.vertices * 10 >= ma.vertices * 9);
            for k in 0..3 {
                assert!(
                    (ma.size_m[k] - mb.size_m[k]).abs()
                        <= 2e-3 * ma.size_m.iter().fold(0.0f64, |x, y| x.max(*y)),
                    "{}: size {:?} vs {:?}",
                    src.display(),
                    ma.size_m,
                    mb.size_m
                );
            }
        }
        assert_eq!(a.animations.len(), b.animations.len());
        for (x, y) in a.animations.iter().zip(&b.animations) {
            // gltfpack resamples animations at 30 Hz: durations agree to one sample.
            assert!((x.duration_s - y.duration_s).abs() <= 1.0 / 30.0 + 1e-6);
        }
        // The base shape and each target at weight 1 agree as point sets (quantisation error
        // ~1e-4 of the size; gltfpack resamples animations, so frames are not compared).
        let ra = load(&src, &LoadOptions::default()).unwrap();
        let rb = load(&out, &LoadOptions::default()).unwrap();
        if ra.face().positions.len() == rb.face().positions.len() {
            let size = a
                .meshes
                .iter()
                .map(|m| m.size_m[0].max(m.size_m[1]).max(m.size_m[2]))
                .fold(0.0, f64::max);
            let nt = ra.face().targets.len();
            for t in 0..=nt {
                let w: Vec<f64> = (0..nt).map(|i| if i == t { 1.0 } else { 0.0 }).collect();
                let pa = ra.blend(&w);
                let pb = rb.blend(&w);
                let worst = pa
                    .iter()
                    .map(|p| {
                        pb.iter()
                            .map(|q| (p - q).norm())
                            .fold(f64::INFINITY, f64::min)
                    })
                    .fold(0.0, f64::max);
                assert!(
                    worst < 1e-3 * size,
                    "{}: shape {t} point sets differ by {worst}",
                    src.display()
                );
            }
        }
    }
}

/// A skinned face (what RobotExpressive carries; here built by hand so a clone without
/// `../shared` covers it): the rest pose is joint world × inverse bind matrix, blended per
/// vertex by the skin weights, and the face's targets move with the same matrices. The
/// animated export keeps the skin, moves the skinned mesh to a root node, and validates.
#[test]
fn skinned_face_loads_in_its_rest_pose_and_exports_valid() {
    let d = tempfile::tempdir().unwrap();
    let (mut j, mut b) = common::tiny_rig();
    // Vertices 0 and 1 follow joint 0 (at +1 m in x); 2 and 3 joint 1 (rotated 90° about z,
    // at +2 m in y); inverse bind matrices are the identity.
    let joints: [u8; 16] = [0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0];
    let wts: [f32; 16] = [
        1., 0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0., 1., 0., 0., 0.,
    ];
    let ibm: Vec<f32> = (0..2)
        .flat_map(|_| {
            [
                1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 0., 0., 1.,
            ]
        })
        .collect();
    let off = b.len();
    b.extend(joints);
    b.extend(wts.iter().flat_map(|v| v.to_le_bytes()));
    b.extend(ibm.iter().flat_map(|v| v.to_le_bytes()));
    let s = std::f64::consts::FRAC_1_SQRT_2;
    j["buffers"][0]["byteLength"] = json!(b.len());
    let views = j["bufferViews"].as_array_mut().unwrap();
    views.push(json!({ "buffer": 0, "byteOffset": off, "byteLength": 16 }));
    views.push(json!({ "buffer": 0, "byteOffset": off + 16, "byteLength": 64 }));
    views.push(json!({ "buffer": 0, "byteOffset": off + 80, "byteLength": 128 }));
    let acc = j["accessors"].as_array_mut().unwrap();
    acc.push(json!({ "bufferView": 5, "componentType": 5121, "count": 4, "type": "VEC4" }));
    acc.push(json!({ "bufferView": 6, "componentType": 5126, "count": 4, "type": "VEC4" }));
    acc.push(json!({ "bufferView": 7, "componentType": 5126, "count": 2, "type": "MAT4" }));
    let attrs = &mut j["meshes"][0]["primitives"][0]["attributes"];
    attrs["JOINTS_0"] = json!(5);
    attrs["WEIGHTS_0"] = json!(6);
    // The skinned mesh sits under a translated parent (which skinning ignores, §3.7.3).
    j["nodes"] = json!([
        { "children": [1, 2, 3], "translation": [0.0, 0.0, 5.0] },
        { "mesh": 0, "skin": 0, "name": "face" },
        { "name": "j0", "translation": [1.0, 0.0, 0.0] },
        { "name": "j1", "translation": [0.0, 2.0, 0.0], "rotation": [0.0, 0.0, s, s] }
    ]);
    j["skins"] = json!([{ "joints": [2, 3], "inverseBindMatrices": 7 }]);
    j["animations"][0]["channels"][0]["target"]["node"] = json!(1);
    let p = write_glb(d.path(), "skinned.glb", &j, &b);
    let r = load(&p, &LoadOptions::default()).unwrap();
    let f = r.face();
    // Joint worlds include the root's +5 m in z. Vertex 1 (1,0,0) → (2,0,5); vertex 2
    // (1,1,0) rotated 90° → (−1,1,0) → (−1,3,5); its target (0,0,0.1) stays along z.
    let expect = [
        (1, Vector3::new(2.0, 0.0, 5.0)),
        (2, Vector3::new(-1.0, 3.0, 5.0)),
    ];
    for (v, e) in expect {
        assert!(
            (f.positions[v] - e).norm() < 1e-6,
            "{v}: {:?}",
            f.positions[v]
        );
    }
    assert!((f.targets[0].positions[2] - Vector3::new(0.0, 0.0, 0.1)).norm() < 1e-6);
    assert!(summarize(&p).unwrap().meshes[0].skinned);
    // The export keeps the skin and validates.
    let frames: Vec<_> = r.frame_weights(4.0).iter().map(|w| r.blend(w)).collect();
    let origin: Vec<_> = (0..f.positions.len())
        .map(furrow::io::origin::VertexOrigin::same)
        .collect();
    let set = furrow::io::export::FrameSet {
        triangles: &f.triangles,
        frames: &frames,
        origin: &origin,
        fps: 4.0,
        weights: &[],
    };
    let out = d.path().join("skinned_out.glb");
    furrow::io::export::write_animated(&r, &set, &out, furrow::io::atomic::Overwrite::Refuse)
        .unwrap();
    let back = summarize(&out).unwrap();
    assert!(back.meshes.iter().any(|m| m.skinned), "{back:?}");
    if let Some(v) = common::validate(&[out]) {
        common::assert_valid(&v);
    }
}
