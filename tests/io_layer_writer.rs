//! The wrinkle layer writer on real files (the shared samples, their gltfpack copies, the
//! face rig): frames made of each rig's own blend shapes plus a synthetic wrinkle field, no
//! simulation. Every uncompressed file passes the Khronos validator with no error and no
//! warning its input did not have; every compressed file reads back to the same accessors as
//! the uncompressed one and its decoded copy validates; Blender imports a skinned and a
//! multi-primitive face with their shape keys.

mod common;

use furrow::io::accessor::AccessorReader;
use furrow::io::layer::{layer_glb, LayerOptions, Precision};
use furrow::io::load::{load, load_bytes, LoadOptions, Rig};
use furrow::io::split::{FaceMap, LoadedCorners};
use furrow::mesh::TriMesh;
use furrow::pipeline::layer::{self, Clip, LayerInput};
use furrow::pipeline::plan::clip_weights;
use furrow::pipeline::setup::weld::weld;
use furrow::pipeline::step::blend::weld_positions;
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The face's map without refinement: welded as the pipeline welds it, each welded triangle
/// its loaded triangle with its own corners.
fn unrefined_map(rig: &Rig) -> FaceMap {
    let f = rig.face();
    let m = TriMesh::new(f.positions.clone(), f.triangles.clone());
    let (lo, hi) = m.bounding_box().unwrap();
    let w = weld(
        &f.positions,
        &f.targets,
        &f.triangles,
        1e-7 * (hi - lo).norm(),
    );
    let n = w.mesh.positions.len();
    let id = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    FaceMap {
        triangles: w.mesh.triangles.clone(),
        subdivision: (0..n).map(|v| vec![(v, 1.0)]).collect(),
        welded_of_loaded: w.of_loaded,
        welded_count: n,
        corners: w
            .loaded_triangle
            .iter()
            .map(|&triangle| LoadedCorners { triangle, bary: id })
            .collect(),
    }
}

/// Positions of every vertex per frame (m), weights per frame, and the clip they make.
type Synthetic = (Vec<Vec<nalgebra::Vector3<f64>>>, Vec<Vec<f64>>, Clip);

/// Frames of the rig's blend shapes (at most 40) plus ripples along the normals, 1 % of the
/// face's size deep, growing over the clip; the clip they make.
fn frames(rig: &Rig, map: &FaceMap, fps: f64) -> Synthetic {
    let (all, animated) = clip_weights(rig, fps);
    let count = all.len().min(40);
    let weights = all[..count].to_vec();
    let f = rig.face();
    let size = TriMesh::new(f.positions.clone(), f.triangles.clone())
        .bounding_box()
        .map_or(1.0, |(lo, hi)| (hi - lo).norm());
    let frames = weights
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let p = weld_positions(&rig.blend(w), &map.welded_of_loaded, map.welded_count);
            let normals = TriMesh::new(p.clone(), map.triangles.clone()).vertex_normals();
            let s = (k + 1) as f64 / count as f64;
            p.iter()
                .zip(&normals)
                .map(|(x, n)| {
                    x + n
                        * (0.01 * size * s * (40.0 * x.x / size).sin() * (31.0 * x.y / size).cos())
                })
                .collect()
        })
        .collect();
    let clip = if animated {
        Clip::Animated {
            fps,
            first_frame: 0,
            clip_frames: all.len(),
        }
    } else {
        Clip::Still { first_shape: 0 }
    };
    (frames, weights, clip)
}

/// The rig at `path`, its unrefined map, its synthetic frames and their layer.
fn synthetic_layer(path: &Path) -> (Rig, FaceMap, Vec<Vec<nalgebra::Vector3<f64>>>, layer::Built) {
    let rig = load(path, &LoadOptions::default()).unwrap();
    let map = unrefined_map(&rig);
    let (frames, weights, clip) = frames(&rig, &map, 10.0);
    let input = LayerInput {
        rig: &rig,
        map: &map,
        frames: &frames,
        weights: &weights,
        clip,
    };
    let built = layer::build(&input).unwrap();
    (rig, map, frames, built)
}

/// Warning and error codes of a validator report.
fn codes(report: &serde_json::Value) -> BTreeSet<String> {
    report["messages"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            m.as_str()
                .unwrap()
                .split_whitespace()
                .take(2)
                .collect::<Vec<_>>()
                .join(" ")
        })
        .collect()
}

fn layer_files(inputs: Vec<PathBuf>) {
    let dir = tempfile::tempdir().unwrap();
    let mut pairs = Vec::new();
    for (i, path) in inputs.iter().enumerate() {
        let (rig, map, frames, mut built) = synthetic_layer(path);
        let name = path.file_stem().unwrap().to_string_lossy();
        let mut written = Vec::new();
        for compress in [false, true] {
            let opts = LayerOptions {
                precision: Precision::Quantized,
                compress,
            };
            let w = layer_glb(&rig, &map, &built.layer, opts).unwrap();
            layer::check_file(&rig, &mut built, &w, &frames).unwrap();
            let f = built.report.file.as_ref().unwrap();
            assert!(f.decoded_error_of_depth < 0.01, "{name}: {f:?}");
            let out = dir.path().join(format!("{i}_{name}_{compress}.glb"));
            std::fs::write(&out, &w.bytes).unwrap();
            // `fuzz/seeds.sh` collects these as seeds for the loader's fuzz target.
            if let Some(seeds) = std::env::var_os("FURROW_SEEDS_DIR") {
                std::fs::copy(&out, Path::new(&seeds).join(out.file_name().unwrap())).unwrap();
            }
            written.push(out);
        }
        eprintln!(
            "{name}: {} + {} targets ({}), basis {:.2} %",
            built.report.rig_targets,
            built.report.wrinkle_targets,
            built.report.form,
            100.0 * built.report.basis_error_of_depth
        );
        let plain = load(&written[0], &LoadOptions::default()).unwrap();
        let packed = load(&written[1], &LoadOptions::default()).unwrap();
        same_accessors(&plain, &packed);
        let decoded = dir.path().join(format!("{i}_{name}_decoded.glb"));
        std::fs::write(&decoded, furrow::io::export::decoded_glb(&packed).unwrap()).unwrap();
        let back = load_bytes(
            &decoded,
            &std::fs::read(&decoded).unwrap(),
            &LoadOptions::default(),
        )
        .unwrap();
        same_accessors(&plain, &back);
        pairs.push((path.clone(), written[0].clone(), decoded));
    }
    let Some(reports) = common::validate(
        &pairs
            .iter()
            .flat_map(|(a, b, c)| [a.clone(), b.clone(), c.clone()])
            .collect::<Vec<_>>(),
    ) else {
        return;
    };
    for (r, (input, ..)) in reports.chunks(3).zip(&pairs) {
        let before = codes(&r[0]);
        for out in &r[1..] {
            assert_eq!(out["errors"], 0, "{}: {out}", input.display());
            let new: Vec<_> = codes(out).difference(&before).cloned().collect();
            assert!(
                new.is_empty(),
                "{}: new warnings {new:?}: {out}",
                input.display()
            );
        }
    }
}

/// Every accessor of `a` and `b` decodes to the same values (a compressed file and its
/// uncompressed twin, or its decoded copy).
fn same_accessors(a: &Rig, b: &Rig) {
    let n = a.container.json["accessors"].as_array().unwrap().len();
    assert_eq!(n, b.container.json["accessors"].as_array().unwrap().len());
    let (ra, rb) = (
        AccessorReader::new(&a.path, &a.container),
        AccessorReader::new(&b.path, &b.container),
    );
    for i in 0..n {
        assert_eq!(
            ra.read(i).unwrap(),
            rb.read(i).unwrap(),
            "{}: accessor {i}",
            b.path.display()
        );
    }
}

#[test]
fn layers_of_the_shared_files_and_their_gltfpack_copies_validate() {
    let Some(mut inputs) = common::shared_glbs() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for src in inputs.clone() {
        let out = dir.path().join(src.file_name().unwrap());
        if common::gltfpack(&src, &out) {
            inputs.push(out);
        }
    }
    layer_files(inputs);
}

#[test]
fn layers_of_the_project_rigs_validate() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    layer_files(vec![root.join("rigs/face.glb"), root.join("rigs/head.glb")]);
}

/// Blender imports a skinned face (RobotExpressive's head) and a face of two primitives
/// (MorphStressTest) with every shape key and the wrinkle targets.
#[test]
fn blender_imports_skinned_and_multi_primitive_layers() {
    let (Some(robot), Some(stress)) = (
        common::shared_data("RobotExpressive.glb"),
        common::shared_data("MorphStressTest.glb"),
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    for path in [robot, stress] {
        let (rig, map, _, built) = synthetic_layer(&path);
        let opts = LayerOptions {
            precision: Precision::Quantized,
            compress: false,
        };
        let w = layer_glb(&rig, &map, &built.layer, opts).unwrap();
        let out = dir.path().join(path.file_name().unwrap());
        std::fs::write(&out, &w.bytes).unwrap();
        let Some(r) = common::blender_import(&out) else {
            return;
        };
        assert!(r["error"].is_null(), "{}: {r}", path.display());
        let names: Vec<&str> = built
            .layer
            .shapes
            .iter()
            .chain(&built.layer.wrinkles)
            .map(|t| t.name.as_str())
            .collect();
        let found = r["objects"].as_array().unwrap().iter().any(|o| {
            let keys: Vec<&str> = o["shape_keys"]
                .as_array()
                .unwrap()
                .iter()
                .skip(1)
                .map(|k| k.as_str().unwrap())
                .collect();
            keys == names
        });
        assert!(
            found,
            "{}: no object with shape keys {names:?}: {r}",
            path.display()
        );
    }
}
