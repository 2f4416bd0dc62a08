//! `furrow rig generate` and `furrow demo` end to end: the committed rig is what the code
//! makes, and every file written passes the Khronos glTF Validator.

mod common;

use std::path::Path;
use std::process::Command;

#[test]
fn committed_face_rig_is_what_rig_generate_makes_and_is_valid() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("face.glb");
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["--json", "rig", "generate", "-o"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["targets"].as_array().unwrap().len(), 9);
    assert!(v["duration_s"].as_f64().unwrap() >= 4.0);
    let committed = Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb");
    assert_eq!(
        std::fs::read(&out).unwrap(),
        std::fs::read(&committed).unwrap(),
        "rigs/face.glb is stale: run `furrow rig generate -o rigs/face.glb --force`"
    );
    // The rig reads back with its names, and sampled at 30 fps covers ≥ 4 s.
    let rig = furrow::io::load(&committed, &Default::default()).unwrap();
    let names: Vec<&str> = rig.face().targets.iter().map(|t| t.name.as_str()).collect();
    for want in [
        "brow_raise",
        "brow_frown",
        "squint_left",
        "squint_right",
        "nose_wrinkle",
        "smile_left",
        "smile_right",
        "jaw_open",
        "pucker",
    ] {
        assert!(names.contains(&want), "{want} missing from {names:?}");
    }
    assert!(rig.frame_weights(30.0).len() > 4 * 30);
    if let Some(r) = common::validate(&[committed]) {
        common::assert_valid(&r);
    }
}

#[test]
fn demo_writes_valid_animated_and_per_frame_files() {
    let d = tempfile::tempdir().unwrap();
    let out = d.path().join("demo");
    let args = ["--fps", "10", "--frames", ":5", "--frames-dir", "--out"];
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .arg("--json")
        .arg("demo")
        .args(["--export", "sequence"])
        .args(args)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let frames = v["frames"].as_u64().unwrap() as usize;
    assert_eq!(frames, 5);
    let files: Vec<_> = std::fs::read_dir(out.join("frames"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    assert_eq!(files.len(), frames);
    for f in ["report.json", "preview/contact_sheet.png"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // Frame k of the animated file equals the per-frame file k.
    let anim = furrow::io::load(&out.join("face_wrinkled.glb"), &Default::default()).unwrap();
    assert_eq!(anim.face().targets.len(), frames);
    let w = anim.frame_weights(10.0);
    let k = 3;
    let from_anim = anim.blend(&w[k]);
    let (_, still, _) =
        furrow::io::load::load_instances(&out.join(format!("frames/frame_{k:05}.glb"))).unwrap();
    let still = &still[0].positions;
    let err = from_anim
        .iter()
        .zip(still)
        .map(|(a, b)| (a - b).norm())
        .fold(0.0, f64::max);
    assert!(
        err < 1e-6,
        "frame {k}: animated and still differ by {err} m"
    );
    // A second run replaces its own outputs and says so (here with the default export, the
    // wrinkle layer: the rig's 9 shapes and the wrinkle targets).
    let o2 = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .arg("demo")
        .args(args)
        .arg(&out)
        .output()
        .unwrap();
    assert!(o2.status.success());
    assert!(String::from_utf8_lossy(&o2.stdout).contains("replaced"));
    let layer = furrow::io::load(&out.join("face_wrinkled.glb"), &Default::default()).unwrap();
    let names: Vec<&str> = layer
        .face()
        .targets
        .iter()
        .map(|t| t.name.as_str())
        .collect();
    assert!(names.len() > 9 && names[0] == "brow_raise", "{names:?}");
    assert!(
        names[9..].iter().all(|n| n.starts_with("wrinkle_")),
        "{names:?}"
    );
    let mut check = vec![out.join("face_wrinkled.glb")];
    check.extend(files.into_iter().take(3));
    if let Some(r) = common::validate(&check) {
        common::assert_valid(&r);
    }
}
