//! Bad input: each case gets a message naming the file and the problem, exit status 2, no
//! panic, and no output file.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

struct Outcome {
    code: Option<i32>,
    stderr: String,
}

/// Run `furrow demo --rig FILE --out OUT` (a command that writes files) and `furrow inspect FILE`.
fn run_both(file: &Path) -> (Outcome, Outcome, PathBuf, tempfile::TempDir) {
    let out = tempfile::tempdir().unwrap();
    let dir = out.path().join("demo");
    let bin = env!("CARGO_BIN_EXE_furrow");
    let demo = Command::new(bin)
        .args(["demo", "--rig"])
        .arg(file)
        .arg("--out")
        .arg(&dir)
        .output()
        .unwrap();
    let inspect = Command::new(bin).arg("inspect").arg(file).output().unwrap();
    let o = |x: std::process::Output| Outcome {
        code: x.status.code(),
        stderr: String::from_utf8_lossy(&x.stderr).into_owned(),
    };
    (o(demo), o(inspect), dir, out)
}

fn expect_refused(file: &Path, words: &[&str]) {
    let (demo, inspect, dir, _keep) = run_both(file);
    let name = file.file_name().unwrap().to_string_lossy().into_owned();
    for (what, o) in [("demo", &demo), ("inspect", &inspect)] {
        assert_eq!(
            o.code,
            Some(2),
            "{what} on {name}: exit {:?}, stderr: {}",
            o.code,
            o.stderr
        );
        assert!(
            !o.stderr.contains("panicked"),
            "{what} panicked: {}",
            o.stderr
        );
        assert!(
            o.stderr.contains(&name),
            "{what}: message does not name the file: {}",
            o.stderr
        );
        let lower = o.stderr.to_lowercase();
        for w in words {
            assert!(
                lower.contains(&w.to_lowercase()),
                "{what} on {name}: message lacks {w:?}: {}",
                o.stderr
            );
        }
    }
    assert!(
        !dir.exists() || std::fs::read_dir(&dir).unwrap().next().is_none(),
        "output was written for {name}"
    );
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, bytes).unwrap();
    p
}

fn mutated(
    name: &str,
    f: impl FnOnce(&mut serde_json::Value, &mut Vec<u8>),
) -> (tempfile::TempDir, PathBuf) {
    let d = tempfile::tempdir().unwrap();
    let (mut j, mut b) = common::tiny_rig();
    f(&mut j, &mut b);
    let p = write(d.path(), name, &common::glb_bytes(&j, &b));
    (d, p)
}

#[test]
fn tiny_rig_itself_is_accepted() {
    let (_d, p) = mutated("tiny.glb", |_, _| {});
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .arg("inspect")
        .arg(&p)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // A 1 m square of two triangles cannot carry a 1 mm skin's 2 cm wrinkles: simulated
    // whole (its lift stretches it, so none of it would be selected), it is refused, with
    // the numbers, and nothing written.
    let out = tempfile::tempdir().unwrap();
    let all = out.path().join("all.toml");
    std::fs::write(&all, "[skin]\nsimulate = \"all\"\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["--quiet", "animate"])
        .arg(&p)
        .arg("--scene")
        .arg(&all)
        .arg("-o")
        .arg(out.path().join("face_wrinkled.glb"))
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("tiny.glb") && e.contains("too coarse"), "{e}");
    assert!(!out.path().join("face_wrinkled.glb").exists());
    // With a skin of its scale it is animated.
    let scene = out.path().join("thick.toml");
    std::fs::write(
        &scene,
        "[skin]\nthickness = 0.1\n[interior]\ncell_size = 0.25\n",
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["--quiet", "animate"])
        .arg(&p)
        .arg("--scene")
        .arg(&scene)
        .arg("-o")
        .arg(out.path().join("tiny_out.glb"))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(out.path().join("tiny_out.glb").exists());
}

#[test]
fn missing_file() {
    let d = tempfile::tempdir().unwrap();
    expect_refused(&d.path().join("nowhere.glb"), &["cannot read"]);
}

#[test]
fn not_gltf() {
    let d = tempfile::tempdir().unwrap();
    expect_refused(
        &write(d.path(), "photo.glb", b"\x89PNG\r\n\x1a\n not a gltf"),
        &["not a glTF"],
    );
}

#[test]
fn glb_cut_short() {
    let d = tempfile::tempdir().unwrap();
    let (j, b) = common::tiny_rig();
    let full = common::glb_bytes(&j, &b);
    expect_refused(
        &write(d.path(), "cut.glb", &full[..full.len() - 40]),
        &["GLB"],
    );
}

#[test]
fn broken_json() {
    let d = tempfile::tempdir().unwrap();
    expect_refused(
        &write(
            d.path(),
            "broken.gltf",
            br#"{ "asset": { "version": "2.0" }, "nodes": [ "#,
        ),
        &["JSON"],
    );
}

#[test]
fn accessor_out_of_bounds() {
    let (_d, p) = mutated("oob_accessor.glb", |j, _| {
        j["accessors"][0]["count"] = serde_json::json!(40)
    });
    expect_refused(&p, &["accessor 0", "out of bounds"]);
}

#[test]
fn buffer_view_out_of_bounds() {
    let (_d, p) = mutated("oob_view.glb", |j, _| {
        j["bufferViews"][2]["byteOffset"] = serde_json::json!(4000)
    });
    expect_refused(&p, &["bufferView 2", "outside buffer"]);
}

#[test]
fn morph_target_counts_differ_between_primitives() {
    let (_d, p) = mutated("targets_differ.glb", |j, _| {
        let mut second = j["meshes"][0]["primitives"][0].clone();
        second["targets"] = serde_json::json!([{ "POSITION": 2 }, { "POSITION": 2 }]);
        j["meshes"][0]["primitives"]
            .as_array_mut()
            .unwrap()
            .push(second);
    });
    expect_refused(&p, &["morph target counts differ"]);
}

#[test]
fn nan_positions() {
    let (_d, p) = mutated("nan.glb", |_, b| {
        b[4..8].copy_from_slice(&f32::NAN.to_le_bytes())
    });
    expect_refused(&p, &["POSITION", "non-finite"]);
}

#[test]
fn infinite_positions() {
    let (_d, p) = mutated("inf.glb", |_, b| {
        b[8..12].copy_from_slice(&f32::INFINITY.to_le_bytes())
    });
    expect_refused(&p, &["non-finite"]);
}

#[test]
fn no_mesh_with_morph_targets() {
    let (_d, p) = mutated("no_targets.glb", |j, _| {
        j["meshes"][0]["primitives"][0]
            .as_object_mut()
            .unwrap()
            .remove("targets");
        j.as_object_mut().unwrap().remove("animations");
    });
    // inspect may read this file (it has a mesh); only commands that need a rig refuse it.
    let (demo, inspect, dir, _keep) = run_both(&p);
    assert_eq!(inspect.code, Some(0), "{}", inspect.stderr);
    assert_eq!(demo.code, Some(2));
    assert!(
        demo.stderr.contains("no_targets.glb")
            && demo.stderr.contains("no mesh with morph targets"),
        "{}",
        demo.stderr
    );
    assert!(!dir.exists());
}

#[test]
fn animation_channel_to_missing_node() {
    let (_d, p) = mutated("bad_channel.glb", |j, _| {
        j["animations"][0]["channels"][0]["target"]["node"] = serde_json::json!(7)
    });
    expect_refused(&p, &["node 7", "does not exist"]);
}

/// `inspect` refuses what `animate` refuses in a weight animation, with the same message.
#[test]
fn weights_that_do_not_match_keys_times_targets() {
    // One key's weight dropped: 1 output value for 2 keys × 1 target.
    let (_d, p) = mutated("short_weights.glb", |j, _| {
        j["accessors"][4]["count"] = serde_json::json!(1)
    });
    expect_refused(&p, &["1 output values", "2 keys × 1"]);
}

#[test]
fn key_times_that_do_not_increase() {
    let (_d, p) = mutated("backwards_keys.glb", |j, b| {
        b[108..112].copy_from_slice(&1.0f32.to_le_bytes());
        b[112..116].copy_from_slice(&0.5f32.to_le_bytes());
        j["accessors"][3]["min"] = serde_json::json!([0.5]);
    });
    expect_refused(&p, &["key times must increase"]);
}

#[test]
fn unknown_required_extension() {
    let (_d, p) = mutated("draco.glb", |j, _| {
        j["extensionsUsed"] = serde_json::json!(["KHR_draco_mesh_compression"]);
        j["extensionsRequired"] = serde_json::json!(["KHR_draco_mesh_compression"]);
    });
    expect_refused(&p, &["KHR_draco_mesh_compression", "does not support"]);
}

#[test]
fn existing_output_is_not_overwritten_without_force() {
    let d = tempfile::tempdir().unwrap();
    let target = d.path().join("face.glb");
    std::fs::write(&target, b"precious").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["rig", "generate", "-o"])
        .arg(&target)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--force"));
    assert_eq!(std::fs::read(&target).unwrap(), b"precious");
}

#[test]
fn every_subcommand_has_help_with_an_example() {
    let bin = env!("CARGO_BIN_EXE_furrow");
    for args in [
        vec![],
        vec!["inspect"],
        vec!["rig"],
        vec!["rig", "generate"],
        vec!["demo"],
        vec!["bench"],
        vec!["bench", "shell"],
        vec!["bench", "lattice"],
        vec!["bench", "fit"],
        vec!["bench", "select"],
        vec!["fit"],
        vec!["animate"],
        vec!["batch"],
        vec!["merge"],
        vec!["scene"],
        vec!["validate"],
        vec!["validate", "wavelength"],
        vec!["validate", "dense"],
    ] {
        let o = Command::new(bin)
            .args(&args)
            .arg("--help")
            .output()
            .unwrap();
        assert!(o.status.success(), "{args:?} --help failed");
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(
            text.contains("Example:\n  furrow "),
            "{args:?} --help has no example:\n{text}"
        );
    }
}

#[test]
fn absurd_settings_are_refused_with_the_flag_named() {
    let bin = env!("CARGO_BIN_EXE_furrow");
    let d = tempfile::tempdir().unwrap();
    for (args, flag) in [
        (vec!["demo", "--fps", "0"], "--fps"),
        (vec!["demo", "--fps", "NaN"], "--fps"),
        (vec!["bench", "shell", "--faces", "0"], "--faces"),
        (vec!["bench", "muscles", "--tracking=-1"], "--tracking"),
        (vec!["bench", "muscles", "--tracking", "NaN"], "--tracking"),
    ] {
        let o = Command::new(bin)
            .args(&args)
            .arg("--out")
            .arg(d.path().join("x"))
            .output();
        let o = match o {
            Ok(o) if args[0] == "demo" => o,
            _ => Command::new(bin).args(&args).output().unwrap(),
        };
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(flag),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    assert!(!d.path().join("x").exists());
}

#[test]
fn wavelength_command_gives_the_papers_value_and_names_bad_fields() {
    let bin = env!("CARGO_BIN_EXE_furrow");
    let o = Command::new(bin)
        .args([
            "--json",
            "wavelength",
            "--thickness",
            "0.0002",
            "--skin-modulus",
            "1e6",
            "--interior-modulus",
            "1e4",
        ])
        .output()
        .unwrap();
    assert!(o.status.success());
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(
        (v["wavelength_m"].as_f64().unwrap() - 4.04e-3).abs() < 0.005e-3,
        "{v}"
    );
    let o = Command::new(bin)
        .args([
            "wavelength",
            "--thickness",
            "0.0002",
            "--skin-modulus",
            "1e6",
            "--interior-modulus",
            "-1",
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("interior modulus"));
}
