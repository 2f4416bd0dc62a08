//! A skinned face (capture rigs often are): the loader applies the rest-pose skin, the export
//! writes local coordinates back so that the round trip is exact, and the file validates.

mod common;

use furrow::io::atomic::Overwrite;
use furrow::io::export::{self, FrameSet};
use furrow::io::origin::VertexOrigin;
use furrow::io::{load, LoadOptions};
use nalgebra::Vector3;
use serde_json::json;

#[test]
fn skinned_face_round_trips_in_world_space() {
    let d = tempfile::tempdir().unwrap();
    let (mut j, mut b) = common::tiny_rig();
    // Two joints: joint A translated by (0, 0, 1), joint B by (2, 0, 0); inverse bind = identity.
    // Vertices 0 and 1 follow A fully, 2 and 3 are split 50/50 between A and B.
    let joints: [u8; 16] = [0, 0, 0, 0, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1, 0, 0];
    let weights: [f32; 16] = [
        1., 0., 0., 0., 1., 0., 0., 0., 0.5, 0.5, 0., 0., 0.5, 0.5, 0., 0.,
    ];
    let jo = b.len();
    b.extend(joints);
    let wo = b.len();
    b.extend(weights.iter().flat_map(|v| v.to_le_bytes()));
    j["bufferViews"].as_array_mut().unwrap().extend([
        json!({ "buffer": 0, "byteOffset": jo, "byteLength": 16 }),
        json!({ "buffer": 0, "byteOffset": wo, "byteLength": 64 }),
    ]);
    j["buffers"][0]["byteLength"] = json!(b.len());
    j["accessors"].as_array_mut().unwrap().extend([
        json!({ "bufferView": 5, "componentType": 5121, "count": 4, "type": "VEC4" }),
        json!({ "bufferView": 6, "componentType": 5126, "count": 4, "type": "VEC4" }),
    ]);
    j["meshes"][0]["primitives"][0]["attributes"]["JOINTS_0"] = json!(5);
    j["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = json!(6);
    j["nodes"] = json!([
        { "mesh": 0, "skin": 0, "name": "face" },
        { "name": "root", "children": [2, 3] },
        { "name": "A", "translation": [0.0, 0.0, 1.0] },
        { "name": "B", "translation": [2.0, 0.0, 0.0] }
    ]);
    j["scenes"] = json!([{ "nodes": [0, 1] }]);
    j["skins"] = json!([{ "joints": [2, 3] }]);
    let p = d.path().join("skinned.glb");
    std::fs::write(&p, common::glb_bytes(&j, &b)).unwrap();
    let rig = load(&p, &LoadOptions::default()).unwrap();
    let f = rig.face();
    // Rest-pose linear blend skinning: v0 = (0,0,0)+(0,0,1); v2 = (1,1,0) + ½(0,0,1) + ½(2,0,0).
    assert!((f.positions[0] - Vector3::new(0.0, 0.0, 1.0)).norm() < 1e-7);
    assert!(
        (f.positions[2] - Vector3::new(2.0, 1.0, 0.5)).norm() < 1e-7,
        "{:?}",
        f.positions[2]
    );
    let frames: Vec<_> = rig
        .frame_weights(4.0)
        .iter()
        .map(|w| rig.blend(w))
        .collect();
    let origin: Vec<_> = (0..4).map(VertexOrigin::same).collect();
    let set = FrameSet {
        triangles: &f.triangles,
        frames: &frames,
        origin: &origin,
        fps: 4.0,
        weights: &[],
    };
    let out = d.path().join("out.glb");
    export::write_animated(&rig, &set, &out, Overwrite::Refuse).unwrap();
    let back = load(
        &out,
        &LoadOptions {
            mesh: None,
            animation: Some("furrow_wrinkles".into()),
            ..Default::default()
        },
    )
    .unwrap();
    let w = back.frame_weights(4.0);
    for k in 0..frames.len() {
        let got = back.blend(&w[k]);
        for (a, e) in got.iter().zip(&frames[k]) {
            assert!((a - e).norm() < 1e-6, "frame {k}: {a:?} vs {e:?}");
        }
    }
    if let Some(r) = common::validate(&[out]) {
        common::assert_valid(&r);
    }
}
