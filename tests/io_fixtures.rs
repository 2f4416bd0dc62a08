//! Byte fixtures written by hand from the specifications (glTF 2.0, KHR_mesh_quantization,
//! EXT_meshopt_compression's bitstream), with the values they must decode to computed by
//! hand, so the loader is not tested only against furrow's own writer.

mod common;

use furrow::io::accessor::AccessorReader;
use furrow::io::load::{load_bytes, LoadOptions};
use nalgebra::Vector3;
use serde_json::json;
use std::path::Path;

/// Little-endian bytes of i16s.
fn i16s(v: &[i16]) -> Vec<u8> {
    v.iter().flat_map(|x| x.to_le_bytes()).collect()
}

/// Pad to a multiple of 4 bytes.
fn pad4(mut b: Vec<u8>) -> Vec<u8> {
    while b.len() % 4 != 0 {
        b.push(0);
    }
    b
}

/// Quantized positions (normalized SHORT, 8-byte stride) dequantized by the node's
/// translation (1, 2, 3) and scale 2; a sparse morph target (one SHORT normalized value at
/// vertex 2, UNSIGNED_BYTE index); BYTE normalized normal deltas (−128 clamps to −1); a
/// weights animation of UNSIGNED_BYTE normalized values.
#[test]
fn quantized_and_sparse_accessors_decode_as_the_specification_says() {
    let views: Vec<Vec<u8>> = vec![
        i16s(&[32767, 0, 0, 0, 0, 16384, 0, 0, 0, 0, -32767, 0]), // positions, stride 8
        vec![0, 1, 2],                                            // indices (u8)
        vec![2],                                                  // sparse index
        i16s(&[-16384, 0, 32767]),                                // sparse value
        vec![127, 0, 0, 0, 0, 128, 0, 0, 0, 0, 64, 0],            // normal deltas (i8), stride 4
        [0.0f32, 1.0].iter().flat_map(|x| x.to_le_bytes()).collect(), // times
        vec![0, 255],                                             // weights (u8 normalized)
    ];
    let mut bin = Vec::new();
    let mut vj = Vec::new();
    for (i, v) in views.iter().enumerate() {
        let mut view = json!({ "buffer": 0, "byteOffset": bin.len(), "byteLength": v.len() });
        if i == 0 {
            view["byteStride"] = json!(8);
        }
        if i == 4 {
            view["byteStride"] = json!(4);
        }
        vj.push(view);
        bin.extend(pad4(v.clone()));
    }
    let j = json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["KHR_mesh_quantization"], "extensionsRequired": ["KHR_mesh_quantization"],
        "scene": 0, "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "translation": [1.0, 2.0, 3.0], "scale": [2.0, 2.0, 2.0] }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1,
            "targets": [{ "POSITION": 2, "NORMAL": 3 }] }] }],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": vj,
        "accessors": [
            { "bufferView": 0, "componentType": 5122, "normalized": true, "count": 3, "type": "VEC3", "min": [0, 0, -32767], "max": [32767, 16384, 0] },
            { "bufferView": 1, "componentType": 5121, "count": 3, "type": "SCALAR" },
            { "componentType": 5122, "normalized": true, "count": 3, "type": "VEC3", "min": [-16384, 0, 0], "max": [0, 0, 32767],
              "sparse": { "count": 1, "indices": { "bufferView": 2, "componentType": 5121 }, "values": { "bufferView": 3 } } },
            { "bufferView": 4, "componentType": 5120, "normalized": true, "count": 3, "type": "VEC3" },
            { "bufferView": 5, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0.0], "max": [1.0] },
            { "bufferView": 6, "componentType": 5121, "normalized": true, "count": 2, "type": "SCALAR" }
        ],
        "animations": [{ "samplers": [{ "input": 4, "output": 5 }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }] }]
    });
    let bytes = common::glb_bytes(&j, &bin);
    let rig = load_bytes(Path::new("fixture.glb"), &bytes, &LoadOptions::default()).unwrap();
    let f = rig.face();
    // world = t + s q / 32767 (glTF: SHORT normalized decodes as max(q / 32767, −1)).
    let expect = [
        Vector3::new(3.0, 2.0, 3.0),
        Vector3::new(1.0, 2.0 + 32768.0 / 32767.0, 3.0),
        Vector3::new(1.0, 2.0, 1.0),
    ];
    for (p, e) in f.positions.iter().zip(&expect) {
        assert!((p - e).norm() < 1e-6, "{p} vs {e}");
    }
    assert_eq!(f.triangles, vec![[0, 1, 2]]);
    // The sparse target: zero but at vertex 2, scaled by the node (the linear part, 2).
    let d = &f.targets[0].positions;
    assert_eq!((d[0], d[1]), (Vector3::zeros(), Vector3::zeros()));
    assert!(
        (d[2] - Vector3::new(-32768.0 / 32767.0, 0.0, 2.0)).norm() < 1e-6,
        "{}",
        d[2]
    );
    // BYTE normalized: max(c / 127, −1).
    let reader = AccessorReader::new(&rig.path, &rig.container);
    let n = reader.read(3).unwrap();
    assert_eq!(
        n.data,
        vec![1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 64.0 / 127.0]
    );
    // UNSIGNED_BYTE normalized weights: 255 → 1; linear between keys.
    let t = rig.track.as_ref().unwrap();
    assert_eq!(t.values, vec![vec![0.0], vec![1.0]]);
    assert_eq!(t.sample(0.5), vec![0.5]);
}

/// One meshopt ATTRIBUTES stream (version 0): the header 0xa0, one block of `stride` data
/// blocks (one per byte of the element) of one group of 16 deltas each, here either all zero
/// (mode 0) or 16 raw zigzag deltas (mode 3), and the 32-byte tail whose last `stride` bytes
/// are the baseline element (zero).
fn meshopt_stream(byte_deltas: &[Option<[u8; 4]>]) -> Vec<u8> {
    let mut s = vec![0xa0];
    for d in byte_deltas {
        match d {
            None => s.push(0b00),
            Some(d) => {
                s.push(0b11);
                s.extend(d);
                s.extend([0; 12]);
            }
        }
    }
    s.extend([0; 32]);
    s
}

/// Key times compressed with EXT_meshopt_compression (ATTRIBUTES), and weights compressed with
/// the EXPONENTIAL filter (8-bit exponent, 24-bit mantissa: m · 2^e), both encoded by hand.
#[test]
fn meshopt_views_and_the_exponential_filter_decode_as_the_bitstream_says() {
    // Times 0, 0.25, 0.5, 1 as f32: bytes 2 are 00 80 00 80 (zigzag deltas 00 ff ff ff),
    // bytes 3 are 00 3e 3f 3f (deltas 00 7c 02 00); bytes 0 and 1 are all zero.
    let times = meshopt_stream(&[
        None,
        None,
        Some([0x00, 0xff, 0xff, 0xff]),
        Some([0x00, 0x7c, 0x02, 0x00]),
    ]);
    // Weights 0.75 = 3·2⁻² (fe000003), −1.5 = −3·2⁻¹ (fffffffd), 0, 2 = 1·2¹ (01000001).
    let weights = meshopt_stream(&[
        Some([0x06, 0x0b, 0x06, 0x02]),
        Some([0x00, 0x01, 0x02, 0x00]),
        Some([0x00, 0x01, 0x02, 0x00]),
        Some([0x03, 0x02, 0x02, 0x02]),
    ]);
    let pos: Vec<u8> = [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let delta: Vec<u8> = [0.0f32, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.5]
        .iter()
        .flat_map(|x| x.to_le_bytes())
        .collect();
    let mut bin = pos.clone();
    bin.extend(&delta);
    let t_off = bin.len();
    bin.extend(pad4(times.clone()));
    let w_off = bin.len();
    bin.extend(pad4(weights.clone()));
    let ext = |off: usize, len: usize, filter: Option<&str>| {
        let mut e = json!({ "buffer": 0, "byteOffset": off, "byteLength": len, "byteStride": 4, "count": 4, "mode": "ATTRIBUTES" });
        if let Some(f) = filter {
            e["filter"] = json!(f);
        }
        json!({ "EXT_meshopt_compression": e })
    };
    let j = json!({
        "asset": { "version": "2.0" },
        "extensionsUsed": ["EXT_meshopt_compression"], "extensionsRequired": ["EXT_meshopt_compression"],
        "scene": 0, "scenes": [{ "nodes": [0] }], "nodes": [{ "mesh": 0 }],
        "meshes": [{ "primitives": [{ "attributes": { "POSITION": 0 }, "targets": [{ "POSITION": 1 }] }] }],
        "buffers": [{ "byteLength": bin.len() },
                    { "byteLength": 32, "extensions": { "EXT_meshopt_compression": { "fallback": true } } }],
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": 36 },
            { "buffer": 0, "byteOffset": 36, "byteLength": 36 },
            { "buffer": 1, "byteOffset": 0, "byteLength": 16, "extensions": ext(t_off, times.len(), None) },
            { "buffer": 1, "byteOffset": 16, "byteLength": 16, "extensions": ext(w_off, weights.len(), Some("EXPONENTIAL")) }
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0] },
            { "bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [0, 0, 0.5] },
            { "bufferView": 2, "componentType": 5126, "count": 4, "type": "SCALAR", "min": [0.0], "max": [1.0] },
            { "bufferView": 3, "componentType": 5126, "count": 4, "type": "SCALAR" }
        ],
        "animations": [{ "samplers": [{ "input": 2, "output": 3 }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }] }]
    });
    let bytes = common::glb_bytes(&j, &bin);
    let rig = load_bytes(Path::new("meshopt.glb"), &bytes, &LoadOptions::default()).unwrap();
    let t = rig.track.as_ref().unwrap();
    assert_eq!(t.times, vec![0.0, 0.25, 0.5, 1.0]);
    assert_eq!(t.values, vec![vec![0.75], vec![-1.5], vec![0.0], vec![2.0]]);
    assert_eq!(t.sample(0.125), vec![-0.375]);
    // A corrupt stream (its tail cut) is an error naming the view, not a crash.
    let mut j2 = j.clone();
    j2["bufferViews"][2]["extensions"]["EXT_meshopt_compression"]["byteLength"] =
        json!(times.len() - 8);
    let e = load_bytes(
        Path::new("meshopt.glb"),
        &common::glb_bytes(&j2, &bin),
        &LoadOptions::default(),
    );
    let msg = format!("{:#}", e.err().expect("refused"));
    assert!(
        msg.contains("bufferView 2") && msg.contains("meshopt.glb"),
        "{msg}"
    );
}
