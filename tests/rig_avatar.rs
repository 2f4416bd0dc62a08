//! The avatar stand-ins (`furrow rig generate --kind avatar | avatar-parts | avatar-clip`,
//! `rigs/avatar.glb`, `rigs/avatar_parts.glb`, `rigs/avatar_clip.glb`): the committed files
//! are what the generator makes; they pass the Khronos validator; they load with the head as
//! the face; the lip press, lip roll, blink and viseme_PP fold the skin past 150° along a few
//! edges and no other shape folds it; the eyes, teeth and every primitive carry the head's
//! targets; every primitive has texture coordinates. Run with `-- --nocapture` to see the
//! measured folds; `AVATAR_PREVIEW_DIR=DIR cargo test --release --test rig_avatar --
//! --ignored` writes pictures of the folding shapes.

mod common;

use furrow::io::accessor::AccessorReader;
use furrow::io::load::Rig;
use furrow::mesh::fold::{Folds, WeldedSurface, FOLD_DEG};
use furrow::rig::avatar::{CLIP_DURATION, FACE_NAME, HEAD_NAME};
use furrow::rig::avatar_shapes::{target_names, FOLDING};
use nalgebra::Vector3;
use std::path::{Path, PathBuf};
use std::process::Command;

/// The three kinds, their committed files and the name of their face mesh.
const KINDS: [(&str, &str, &str); 3] = [
    ("avatar", "rigs/avatar.glb", HEAD_NAME),
    ("avatar-parts", "rigs/avatar_parts.glb", FACE_NAME),
    ("avatar-clip", "rigs/avatar_clip.glb", HEAD_NAME),
];

fn committed(file: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(file)
}

fn load(file: &str) -> Rig {
    furrow::io::load(&committed(file), &Default::default()).unwrap()
}

#[test]
fn generator_is_deterministic_and_the_committed_files_are_what_it_makes() {
    let d = tempfile::tempdir().unwrap();
    for (kind, file, _) in KINDS {
        let mut bytes = Vec::new();
        for k in 0..2 {
            let out = d.path().join(format!("{kind}{k}.glb"));
            let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
                .args(["--json", "rig", "generate", "--kind", kind, "-o"])
                .arg(&out)
                .output()
                .unwrap();
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
            let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(v["targets"].as_array().unwrap().len(), 67, "{kind}");
            bytes.push(std::fs::read(&out).unwrap());
        }
        assert_eq!(bytes[0], bytes[1], "{kind}: two runs differ");
        assert_eq!(
            bytes[0],
            std::fs::read(committed(file)).unwrap(),
            "{file} is stale: run `furrow rig generate --kind {kind} -o {file} --force`"
        );
        println!("{file}: {} bytes", bytes[0].len());
        assert!(bytes[0].len() < 700_000, "{file}: {} bytes", bytes[0].len());
    }
}

/// The validator does not decode meshopt, so the compact face is also checked decoded.
#[test]
fn the_files_pass_the_validator() {
    let d = tempfile::tempdir().unwrap();
    let decoded = d.path().join("avatar_parts_decoded.glb");
    let parts = load("rigs/avatar_parts.glb");
    std::fs::write(&decoded, furrow::io::export::decoded_glb(&parts).unwrap()).unwrap();
    let mut files: Vec<PathBuf> = KINDS.iter().map(|k| committed(k.1)).collect();
    files.push(decoded);
    if let Some(r) = common::validate(&files) {
        for report in &r {
            println!("{report}");
        }
        common::assert_valid(&r);
    }
}

#[test]
fn each_file_loads_with_the_head_as_its_face_and_inspect_reads_it() {
    let names = target_names();
    for (_, file, face) in KINDS {
        let rig = load(file);
        let f = rig.face();
        assert_eq!(f.name, face, "{file}: {}", rig.face_reason);
        let got: Vec<&str> = f.targets.iter().map(|t| t.name.as_str()).collect();
        assert_eq!(got, names, "{file}");
        let skin = f.primitives[0].count;
        assert!(
            (1800..=2400).contains(&skin),
            "{file}: {skin} skin vertices"
        );
        let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
            .arg("inspect")
            .arg(committed(file))
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains(face) && text.contains("67 morph targets"),
            "{text}"
        );
        println!("{file}: {}", rig.face_reason);
    }
}

/// The skin of a loaded face: its first primitive's positions (m) and triangles.
fn skin(rig: &Rig) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>, usize) {
    let f = rig.face();
    let (start, count) = (f.primitives[0].first, f.primitives[0].count);
    let pos = f.positions[start..start + count].to_vec();
    let tris = f
        .triangles
        .iter()
        .filter(|t| t.iter().all(|&v| v >= start && v < start + count))
        .map(|t| t.map(|v| v - start))
        .collect();
    (pos, tris, start)
}

/// Each target's folds on the welded skin at weight 1.
fn folds(rig: &Rig) -> Vec<(String, Folds)> {
    let (pos, tris, start) = skin(rig);
    let s = WeldedSurface::new(&pos, &tris, 1e-7);
    rig.face()
        .targets
        .iter()
        .map(|t| {
            let d = &t.positions[start..start + pos.len()];
            (t.name.clone(), s.folds(&pos, d, 1.0, FOLD_DEG))
        })
        .collect()
}

#[test]
fn the_folding_shapes_fold_along_a_few_edges_and_no_other_shape_folds() {
    for file in ["rigs/avatar.glb", "rigs/avatar_parts.glb"] {
        let rig = load(file);
        let (pos, tris, _) = skin(&rig);
        let welded = WeldedSurface::new(&pos, &tris, 1e-7);
        let joined = welded
            .representative
            .iter()
            .enumerate()
            .filter(|(i, r)| i != *r)
            .count();
        assert!(joined > 20, "{file}: the seam welds {joined} vertices");
        println!("{file}: the weld joins {joined} seam vertices");
        for (name, f) in folds(&rig) {
            let folding = FOLDING.contains(&name.as_str());
            if folding || f.max_turn_deg > 100.0 {
                println!(
                    "  {name:16} max turn {:6.1}° (grown {:5.1}°; rest {:5.1}° at most), {:2} edges past {FOLD_DEG}°",
                    f.max_turn_deg, f.max_gain_deg, f.rest_max_turn_deg, f.edges_past
                );
            }
            assert!(f.rest_max_turn_deg < 120.0, "{file}: {f:?}");
            if folding {
                assert!(f.max_turn_deg > FOLD_DEG, "{file}: {name} {f:?}");
                assert!((1..=60).contains(&f.edges_past), "{file}: {name} {f:?}");
            } else {
                assert_eq!(f.edges_past, 0, "{file}: {name} folds: {f:?}");
            }
        }
    }
}

#[test]
fn the_shapes_that_should_not_fold_stay_smooth() {
    let rig = load("rigs/avatar.glb");
    let all = folds(&rig);
    for name in [
        "browInnerUp",
        "cheekPuff",
        "jawOpen",
        "mouthSmileLeft",
        "viseme_aa",
    ] {
        let f = all.iter().find(|(n, _)| n == name).unwrap().1;
        assert!(f.max_turn_deg < 120.0, "{name}: {f:?}");
    }
}

/// Target names of mesh `m` of a loaded file's JSON.
fn mesh_names(j: &serde_json::Value, m: usize) -> Vec<String> {
    j["meshes"][m]["extras"]["targetNames"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| n.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn eyes_teeth_and_every_primitive_carry_the_heads_targets() {
    let names: Vec<String> = target_names().iter().map(|s| s.to_string()).collect();
    for file in ["rigs/avatar.glb", "rigs/avatar_clip.glb"] {
        let rig = load(file);
        let j = &rig.container.json;
        let meshes = j["meshes"].as_array().unwrap();
        let find = |n: &str| meshes.iter().position(|m| m["name"] == n).unwrap();
        for m in [HEAD_NAME, "EyeLeft", "EyeRight", "Teeth"] {
            assert_eq!(mesh_names(j, find(m)), names, "{file}: {m}");
            let p = &meshes[find(m)]["primitives"][0];
            assert_eq!(p["targets"].as_array().unwrap().len(), 67, "{file}: {m}");
        }
        assert!(meshes[find("Body")]["primitives"][0]["targets"].is_null());
        // The eyes move only with their side's look shapes; the teeth only with the jaw.
        for inst in &rig.instances {
            let moving: Vec<&str> = inst
                .targets
                .iter()
                .filter(|t| t.positions.iter().any(|d| d.norm() > 0.0))
                .map(|t| t.name.as_str())
                .collect();
            match inst.name.as_str() {
                "EyeLeft" => assert_eq!(
                    moving,
                    [
                        "eyeLookDownLeft",
                        "eyeLookInLeft",
                        "eyeLookOutLeft",
                        "eyeLookUpLeft"
                    ]
                ),
                "Teeth" => {
                    assert!(moving.contains(&"jawOpen") && moving.contains(&"viseme_aa"));
                    assert!(!moving
                        .iter()
                        .any(|n| n.starts_with("eye") || n.contains("Press")));
                }
                _ => {}
            }
        }
    }
    let rig = load("rigs/avatar_parts.glb");
    let j = &rig.container.json;
    assert_eq!(j["meshes"].as_array().unwrap().len(), 1);
    assert_eq!(mesh_names(j, 0), names);
    let prims = j["meshes"][0]["primitives"].as_array().unwrap();
    assert_eq!(prims.len(), 5);
    let mut materials: Vec<u64> = prims
        .iter()
        .map(|p| p["material"].as_u64().unwrap())
        .collect();
    for p in prims {
        assert_eq!(p["targets"].as_array().unwrap().len(), 67);
    }
    materials.dedup();
    assert_eq!(materials.len(), 5, "a material per primitive");
    let lashes = &j["materials"][prims[3]["material"].as_u64().unwrap() as usize];
    assert!(lashes["alphaMode"] == "MASK" || lashes["alphaMode"] == "BLEND");
    assert_eq!(lashes["doubleSided"], true);
}

#[test]
fn every_primitive_has_texture_coordinates() {
    for (_, file, _) in KINDS {
        let rig = load(file);
        let reader = AccessorReader::new(&rig.path, &rig.container);
        let j = &rig.container.json;
        for m in j["meshes"].as_array().unwrap() {
            for p in m["primitives"].as_array().unwrap() {
                let a = &p["attributes"];
                let uv = reader
                    .read(a["TEXCOORD_0"].as_u64().unwrap() as usize)
                    .unwrap();
                let n = reader
                    .read(a["POSITION"].as_u64().unwrap() as usize)
                    .unwrap();
                assert_eq!(
                    (uv.components, uv.count),
                    (2, n.count),
                    "{file}: {}",
                    m["name"]
                );
                assert!(uv.data.iter().all(|u| (0.0..=1.0).contains(u)));
                let spread = uv.data.iter().fold(0.0f64, |a, &b| a.max(b))
                    - uv.data.iter().fold(1.0f64, |a, &b| a.min(b));
                assert!(spread > 0.5, "{file}: {} uv spread {spread}", m["name"]);
            }
        }
    }
}

/// Every edge of the triangles `tris` is shared by exactly two of them.
fn closed(tris: &[[usize; 3]]) -> bool {
    let mut count = std::collections::HashMap::new();
    for t in tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    count.values().all(|&c| c == 2)
}

#[test]
fn the_avatar_is_skinned_and_its_eyes_are_closed_spheres_in_front_of_the_lids() {
    let rig = load("rigs/avatar.glb");
    let j = &rig.container.json;
    let joint_names: Vec<&str> = j["skins"][0]["joints"]
        .as_array()
        .unwrap()
        .iter()
        .map(|n| {
            j["nodes"][n.as_u64().unwrap() as usize]["name"]
                .as_str()
                .unwrap()
        })
        .collect();
    assert_eq!(joint_names, ["Hips", "Spine", "Neck", "Head"]);
    assert!(j["skins"][0]["inverseBindMatrices"].is_u64());
    for inst in &rig.instances {
        assert_eq!(j["nodes"][inst.node]["skin"], 0, "{}", inst.name);
        let a = &j["meshes"][inst.mesh]["primitives"][0]["attributes"];
        assert!(a["JOINTS_0"].is_u64() && a["WEIGHTS_0"].is_u64() && a["NORMAL"].is_u64());
    }
    let body = rig.instances.iter().find(|i| i.name == "Body").unwrap();
    assert!((200..=600).contains(&body.positions.len()));
    let head = rig.face();
    let top = head.positions.iter().map(|p| p.y).fold(f64::MIN, f64::max);
    let bottom = head.positions.iter().map(|p| p.y).fold(f64::MAX, f64::min);
    assert!(
        (top - bottom - 0.23).abs() < 0.005 && top > 1.7,
        "{bottom}..{top}"
    );
    for name in ["EyeLeft", "EyeRight"] {
        let eye = rig.instances.iter().find(|i| i.name == name).unwrap();
        assert!(closed(&eye.triangles), "{name} is not closed");
        let c = eye.positions.iter().sum::<Vector3<f64>>() / eye.positions.len() as f64;
        let r = eye
            .positions
            .iter()
            .map(|p| (p - c).norm())
            .fold(0.0, f64::max);
        // No skin vertex inside the eyeball.
        let inside = head
            .positions
            .iter()
            .filter(|p| (*p - c).norm() < r)
            .count();
        assert_eq!(inside, 0, "{name}: {inside} skin vertices inside the eye");
        assert!(
            c.z > 0.05 && (c.x > 0.0) == (name == "EyeLeft"),
            "{name} at {c}"
        );
    }
    // The teeth sit behind the lips: the skin in front of each tooth vertex is ahead of it.
    let teeth = rig.instances.iter().find(|i| i.name == "Teeth").unwrap();
    let depth = teeth
        .positions
        .iter()
        .map(|p| {
            let front = head
                .positions
                .iter()
                .filter(|q| (q.x - p.x).abs() < 0.004 && (q.y - p.y).abs() < 0.004 && q.z > 0.03)
                .map(|q| q.z)
                .fold(f64::MIN, f64::max);
            front - p.z
        })
        .fold(f64::MAX, f64::min);
    println!(
        "the teeth sit {:.1} mm or more behind the skin",
        depth * 1e3
    );
    assert!(depth > 0.002, "{depth}");
}

#[test]
fn the_clip_passes_through_every_folding_shape() {
    let rig = load("rigs/avatar_clip.glb");
    let track = rig.track.as_ref().expect("a weights animation on the head");
    assert!((track.duration() - CLIP_DURATION).abs() < 1e-6);
    let frames = rig.frame_weights(30.0);
    assert_eq!(frames.len(), 76);
    let names = target_names();
    for shape in FOLDING {
        let i = names.iter().position(|n| *n == shape).unwrap();
        let peak = frames.iter().map(|w| w[i]).fold(0.0, f64::max);
        assert!((peak - 1.0).abs() < 1e-6, "{shape} peaks at {peak}");
        // Smooth ramps: no weight jumps by more than 0.3 in a frame.
        for w in frames.windows(2) {
            assert!((w[1][i] - w[0][i]).abs() < 0.3, "{shape} jumps");
        }
    }
    assert_eq!(frames[0].iter().sum::<f64>(), 0.0);
    let j = &rig.container.json;
    let animated: Vec<&str> = j["animations"][0]["channels"]
        .as_array()
        .unwrap()
        .iter()
        .map(|c| {
            assert_eq!(c["target"]["path"], "weights");
            j["nodes"][c["target"]["node"].as_u64().unwrap() as usize]["name"]
                .as_str()
                .unwrap()
        })
        .collect();
    assert_eq!(animated, [HEAD_NAME, "EyeLeft", "EyeRight", "Teeth"]);
}

#[test]
fn the_parts_face_is_compact_and_its_mouth_pocket_is_apart_from_the_skin() {
    let rig = load("rigs/avatar_parts.glb");
    for e in ["EXT_meshopt_compression", "KHR_mesh_quantization"] {
        assert!(rig.extensions_used.iter().any(|u| u == e), "{e}");
    }
    assert!(rig.animations.is_empty());
    let f = rig.face_mesh();
    let span = |k: usize| (f.primitives[k].first, f.primitives[k].count);
    let (s0, sn) = span(0);
    let (m0, mn) = span(4);
    let gap = f.positions[m0..m0 + mn]
        .iter()
        .map(|p| {
            f.positions[s0..s0 + sn]
                .iter()
                .map(|q| (p - q).norm())
                .fold(f64::MAX, f64::min)
        })
        .fold(f64::MAX, f64::min);
    assert!(
        gap > 1e-3,
        "the mouth interior comes within {gap} m of the skin"
    );
    for k in [1, 2] {
        let (e0, en) = span(k);
        let tris: Vec<[usize; 3]> = f
            .triangles
            .iter()
            .filter(|t| t.iter().all(|&v| v >= e0 && v < e0 + en))
            .copied()
            .collect();
        assert!(closed(&tris), "eyeball {k} is not closed");
    }
}

/// Pictures of the skin at rest and at each folding shape (front and from below-side), for a
/// person to look at.
#[test]
#[ignore = "writes pictures of the folding shapes for a person to look at"]
fn preview_the_folding_shapes() {
    use furrow::render::preview::{render, side_by_side, write_png, View};
    let Ok(dir) = std::env::var("AVATAR_PREVIEW_DIR") else {
        common::note("set AVATAR_PREVIEW_DIR to write the pictures");
        return;
    };
    let dir = PathBuf::from(dir);
    std::fs::create_dir_all(&dir).unwrap();
    for (_, file, _) in KINDS.iter().take(2) {
        let rig = load(file);
        let (pos, tris, start) = skin(&rig);
        let stem = Path::new(file)
            .file_stem()
            .unwrap()
            .to_string_lossy()
            .to_string();
        let c = pos.iter().sum::<Vector3<f64>>() / pos.len() as f64;
        let mut shots = vec![("rest".to_string(), pos.clone())];
        for t in &rig.face().targets {
            if FOLDING.contains(&t.name.as_str()) || t.name == "jawOpen" {
                let moved = pos
                    .iter()
                    .zip(&t.positions[start..])
                    .map(|(p, d)| p + d)
                    .collect();
                shots.push((t.name.clone(), moved));
            }
        }
        for (name, p) in shots {
            let mesh = furrow::mesh::TriMesh::new(p, tris.clone());
            // Close up on the eye or the mouth the shape acts on (the head's origin is `c`).
            let (focus, half) = if name.starts_with("eye") {
                let x = if name.ends_with("Right") {
                    -0.032
                } else {
                    0.032
                };
                (c + Vector3::new(x, 0.024, 0.08), 0.016)
            } else {
                (c + Vector3::new(0.0, -0.045, 0.095), 0.028)
            };
            let mut images = Vec::new();
            for dir_v in [
                Vector3::new(0.0, 0.0, -1.0),
                Vector3::new(-1.0, 0.15, -0.35),
            ] {
                let view = View {
                    bounds: Some((focus - Vector3::repeat(half), focus + Vector3::repeat(half))),
                    ..View::looking_along(dir_v)
                };
                images.push(render(&mesh, &view, (500, 500)));
            }
            let img = side_by_side(&images, &[&name, &format!("{name} (side)")]);
            write_png(&dir.join(format!("{stem}_{name}.png")), &img).unwrap();
        }
    }
}
