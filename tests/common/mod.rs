//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The sample files the tests read from `../shared/data/` (docs/testing.md, "Test data and
/// credits"): Khronos glTF sample models and RobotExpressive. Under CI every one must be
/// present.
pub const SHARED_FILES: [&str; 5] = [
    "AnimatedMorphCube.glb",
    "AnimatedMorphSphere.glb",
    "MorphStressTest.glb",
    "RobotExpressive.glb",
    "SimpleMorph.glb",
];

/// The folder of outside test data, `../shared/data/` beside the project (never copied in).
pub fn shared_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data")
}

/// A one-line note on the terminal, past the test harness' output capture (so a passing
/// test's skip still shows in `cargo test`).
pub fn note(text: &str) {
    use std::io::Write;
    let test = std::thread::current()
        .name()
        .unwrap_or("a test")
        .to_string();
    let _ = writeln!(std::io::stderr(), "note: {test}: {text}");
}

/// `../shared/data/NAME`, when it is there. When it is not: under CI (`CI=true`) the test fails
/// (a broken layout must not pass as a skip); elsewhere it prints one line saying what was
/// skipped and why, and returns None.
pub fn shared_data(name: &str) -> Option<PathBuf> {
    let p = shared_dir().join(name);
    if p.is_file() {
        return Some(p);
    }
    assert!(
        !tools_required(),
        "{} is missing: CI runs every test on the outside sample files (docs/testing.md, \"Test data and credits\")",
        p.display()
    );
    note(&format!(
        "skipped: {} not found (outside sample file; docs/testing.md, \"Test data and credits\", says where it comes from)",
        p.display()
    ));
    None
}

/// All of [`SHARED_FILES`], when every one is there (same rule as [`shared_data`]: a missing
/// file fails under CI, skips with a note elsewhere).
pub fn shared_glbs() -> Option<Vec<PathBuf>> {
    SHARED_FILES.iter().map(|n| shared_data(n)).collect()
}

/// The Node tools folder (`.ci/node_modules`), if installed.
pub fn node_modules() -> Option<PathBuf> {
    let p = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/node_modules");
    p.join("gltf-validator").exists().then_some(p)
}

/// Whether a missing tool must fail the test (in CI) rather than skip it (on a dev machine).
pub fn tools_required() -> bool {
    std::env::var("CI").is_ok_and(|v| v == "true" || v == "1")
}

/// Run the Khronos glTF Validator on `files`; returns each file's JSON report line.
/// Returns None (test skipped, with a note) when the validator is not installed outside CI.
pub fn validate(files: &[PathBuf]) -> Option<Vec<serde_json::Value>> {
    if node_modules().is_none() {
        assert!(
            !tools_required(),
            "gltf-validator is not installed: run `npm ci --prefix .ci`"
        );
        note("gltf-validator not installed (npm ci --prefix .ci); validation skipped");
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/validate.mjs");
    let out = Command::new("node")
        .arg(script)
        .args(files)
        .output()
        .expect("node runs");
    let text = String::from_utf8_lossy(&out.stdout);
    Some(
        text.lines()
            .map(|l| serde_json::from_str(l).expect("validator prints JSON"))
            .collect(),
    )
}

/// Import `file` into Blender (Debian's `blender`, headless, `.ci/blender_import.py`) and
/// return what came in: `{"error", "objects": [{"name", "shape_keys", "slider_min", ...}],
/// "actions": [{"name", "fcurves"}]}`. None (skipped, with a note) when Blender is not
/// installed outside CI; under CI a missing Blender fails the test.
pub fn blender_import(file: &Path) -> Option<serde_json::Value> {
    let found = Command::new("blender")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            !tools_required(),
            "blender is not installed: apt-get install -y blender python3-numpy (.ci/run does)"
        );
        note("blender not installed (apt-get install -y blender); import check skipped");
        return None;
    }
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join(".ci/blender_import.py");
    let out = Command::new("blender")
        .args(["-b", "--factory-startup", "--python"])
        .arg(script)
        .arg("--")
        .arg(file)
        .output()
        .expect("blender runs");
    let text = String::from_utf8_lossy(&out.stdout);
    let line = text
        .lines()
        .find_map(|l| l.strip_prefix("FURROW_JSON "))
        .unwrap_or_else(|| {
            panic!(
                "blender printed no result: {text}{}",
                String::from_utf8_lossy(&out.stderr)
            )
        });
    Some(serde_json::from_str(line).expect("the script prints JSON"))
}

/// Assert that every report has no errors and no warnings.
pub fn assert_valid(reports: &[serde_json::Value]) {
    for r in reports {
        assert_eq!(r["errors"], 0, "validator errors: {r}");
        assert_eq!(r["warnings"], 0, "validator warnings: {r}");
    }
}

/// A small valid rig for tests: one quad (4 vertices, 2 triangles, u16 indices) with one
/// morph target (+0.1 m in z on vertex 2) and a LINEAR weights animation 0 → 1 over 1 s.
/// Returns the JSON and the binary buffer, to be mutated by bad-input tests.
pub fn tiny_rig() -> (serde_json::Value, Vec<u8>) {
    let pos: [f32; 12] = [0., 0., 0., 1., 0., 0., 1., 1., 0., 0., 1., 0.];
    let idx: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let dpos: [f32; 12] = [0., 0., 0., 0., 0., 0., 0., 0., 0.1, 0., 0., 0.];
    let times: [f32; 2] = [0.0, 1.0];
    let weights: [f32; 2] = [0.0, 1.0];
    let mut bin = Vec::new();
    bin.extend(pos.iter().flat_map(|v| v.to_le_bytes())); // 0..48
    bin.extend(idx.iter().flat_map(|v| v.to_le_bytes())); // 48..60
    bin.extend(dpos.iter().flat_map(|v| v.to_le_bytes())); // 60..108
    bin.extend(times.iter().flat_map(|v| v.to_le_bytes())); // 108..116
    bin.extend(weights.iter().flat_map(|v| v.to_le_bytes())); // 116..124
    let json = serde_json::json!({
        "asset": { "version": "2.0" },
        "scene": 0,
        "scenes": [{ "nodes": [0] }],
        "nodes": [{ "mesh": 0, "name": "face" }],
        "meshes": [{ "name": "face", "primitives": [{ "attributes": { "POSITION": 0 }, "indices": 1, "targets": [{ "POSITION": 2 }] }],
                     "extras": { "targetNames": ["lift"] } }],
        "buffers": [{ "byteLength": bin.len() }],
        "bufferViews": [
            { "buffer": 0, "byteOffset": 0, "byteLength": 48 },
            { "buffer": 0, "byteOffset": 48, "byteLength": 12 },
            { "buffer": 0, "byteOffset": 60, "byteLength": 48 },
            { "buffer": 0, "byteOffset": 108, "byteLength": 8 },
            { "buffer": 0, "byteOffset": 116, "byteLength": 8 }
        ],
        "accessors": [
            { "bufferView": 0, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [1,1,0] },
            { "bufferView": 1, "componentType": 5123, "count": 6, "type": "SCALAR" },
            { "bufferView": 2, "componentType": 5126, "count": 4, "type": "VEC3", "min": [0,0,0], "max": [0,0,0.1] },
            { "bufferView": 3, "componentType": 5126, "count": 2, "type": "SCALAR", "min": [0], "max": [1] },
            { "bufferView": 4, "componentType": 5126, "count": 2, "type": "SCALAR" }
        ],
        "animations": [{ "name": "lift", "samplers": [{ "input": 3, "output": 4 }],
                         "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }] }]
    });
    (json, bin)
}

/// Pack JSON and a binary chunk into GLB bytes.
pub fn glb_bytes(json: &serde_json::Value, bin: &[u8]) -> Vec<u8> {
    let mut js = serde_json::to_vec(json).unwrap();
    while js.len() % 4 != 0 {
        js.push(b' ');
    }
    let mut b = bin.to_vec();
    while b.len() % 4 != 0 {
        b.push(0);
    }
    let total = 12 + 8 + js.len() + 8 + b.len();
    let mut out = Vec::new();
    out.extend(b"glTF");
    out.extend(2u32.to_le_bytes());
    out.extend((total as u32).to_le_bytes());
    out.extend((js.len() as u32).to_le_bytes());
    out.extend(b"JSON");
    out.extend(js);
    out.extend((b.len() as u32).to_le_bytes());
    out.extend(b"BIN\0");
    out.extend(b);
    out
}

/// Compress `src` with gltfpack (quantization + meshopt, as capture tools ship rigs) into `out`.
/// Returns false (skip, with a note) when gltfpack is not installed outside CI.
pub fn gltfpack(src: &Path, out: &Path) -> bool {
    let Some(nm) = node_modules() else {
        assert!(
            !tools_required(),
            "gltfpack is not installed: npm ci --prefix .ci"
        );
        note("gltfpack not installed (npm ci --prefix .ci); skipped");
        return false;
    };
    let st = Command::new("node")
        .arg(nm.join("gltfpack/cli.js"))
        .args(["-cc", "-kn", "-km", "-ke", "-i"])
        .arg(src)
        .arg("-o")
        .arg(out)
        .output()
        .expect("node runs");
    assert!(
        st.status.success(),
        "gltfpack failed on {}: {}",
        src.display(),
        String::from_utf8_lossy(&st.stderr)
    );
    true
}

/// A flat rectangle `[0, lx] × [0, ly]` (z = 0, facing +z) of `nx × ny` squares, each split
/// in two triangles.
#[allow(dead_code)]
pub fn grid_mesh(lx: f64, ly: f64, nx: usize, ny: usize) -> furrow::mesh::TriMesh {
    let mut pos = Vec::new();
    for j in 0..=ny {
        for i in 0..=nx {
            pos.push(nalgebra::Vector3::new(
                lx * i as f64 / nx as f64,
                ly * j as f64 / ny as f64,
                0.0,
            ));
        }
    }
    let id = |i: usize, j: usize| j * (nx + 1) + i;
    let mut tris = Vec::new();
    for j in 0..ny {
        for i in 0..nx {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    furrow::mesh::TriMesh::new(pos, tris)
}

/// A rig of `mesh` with one blend shape "squeeze" of per-vertex offsets `deltas` (m),
/// animated linearly from weight 0 at t = 0 to 1 at t = `seconds`. Returns GLB bytes.
#[allow(dead_code)]
pub fn squeeze_rig(
    name: &str,
    mesh: &furrow::mesh::TriMesh,
    deltas: Vec<nalgebra::Vector3<f64>>,
    seconds: f64,
) -> Vec<u8> {
    use furrow::io::model::{MorphTarget, WeightKeys};
    let keys = WeightKeys {
        times: vec![0.0, seconds],
        weights: vec![vec![0.0], vec![1.0]],
    };
    let target = MorphTarget {
        name: "squeeze".into(),
        positions: deltas,
        normals: None,
    };
    furrow::io::export::rig_glb(name, mesh, &[target], &keys).unwrap()
}

/// A flat sheet rig (x, y in [0, size], z = 0, facing +z) of about `2·n²` triangles with one
/// blend shape "squeeze" that compresses the left half along x by `strain` and stretches the
/// right half by the same amount (the middle line stays), animated linearly from weight 0 at
/// t = 0 to 1 at t = `seconds`. Returns GLB bytes.
#[allow(dead_code)]
pub fn sheet_rig(n: usize, size: f64, strain: f64, seconds: f64) -> Vec<u8> {
    let mesh = grid_mesh(size, size, n, n);
    let mid = size / 2.0;
    // Left half: x ↦ mid − (mid − x)(1 − strain); right half: x ↦ mid + (x − mid)(1 + strain).
    let deltas = mesh
        .positions
        .iter()
        .map(|p| {
            let d = if p.x < mid {
                (mid - p.x) * strain
            } else {
                (p.x - mid) * strain
            };
            nalgebra::Vector3::new(d, 0.0, 0.0)
        })
        .collect();
    squeeze_rig("sheet", &mesh, deltas, seconds)
}

/// The `furrow` binary this test build made, as a command.
pub fn furrow() -> std::process::Command {
    std::process::Command::new(env!("CARGO_BIN_EXE_furrow"))
}

/// Run `furrow ARGS…`, asserting it succeeds (else printing its output); its stdout.
pub fn run_ok(args: &[&str]) -> String {
    let o = furrow().args(args).output().unwrap();
    assert!(
        o.status.success(),
        "furrow {args:?} failed:\n{}\n{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}
