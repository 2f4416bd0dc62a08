//! Real rigs as they come: faces of several primitives whose eyes, lashes, teeth and mouth
//! ride along unchanged, shapes that fold, press and cross the skin (outside the model:
//! that skin follows the blend shape), still rigs whose shapes get correctives. On the
//! generated stand-ins of downloaded avatars (`rigs/avatar*.glb`) and on the scanned ICT face
//! in `../shared/data` (skipped with a note where it is absent; CI requires it).

mod common;

use furrow::io::accessor::AccessorReader;
use furrow::io::load::{load, LoadOptions, Rig};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn rig_path(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("rigs")
        .join(name)
}

/// Run `furrow animate RIG -o DIR/out.glb --report DIR/report.json EXTRA…` bare (no scene);
/// returns the output's path and the report.
fn animate(rig: &Path, dir: &Path, extra: &[&str]) -> (PathBuf, Value) {
    animate_on(rig, dir, extra, None)
}

/// [`animate`] on `threads` threads of the pool (`RAYON_NUM_THREADS`) when given.
fn animate_on(rig: &Path, dir: &Path, extra: &[&str], threads: Option<usize>) -> (PathBuf, Value) {
    let out = dir.join("out.glb");
    let report = dir.join("report.json");
    let mut command = Command::new(env!("CARGO_BIN_EXE_furrow"));
    if let Some(t) = threads {
        command.env("RAYON_NUM_THREADS", t.to_string());
    }
    let o = command
        .arg("animate")
        .arg(rig)
        .arg("-o")
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .args(extra)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "furrow animate {} failed:\n{}",
        rig.display(),
        String::from_utf8_lossy(&o.stderr)
    );
    let r = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    (out, r)
}

/// Every decoded value of every attribute and morph target of primitive `p` of `rig`'s face
/// mesh, by attribute (targets as `target{i}.NAME`); the first `targets` targets only.
fn primitive_values(rig: &Rig, p: usize, targets: usize) -> Vec<(String, Vec<f64>)> {
    let reader = AccessorReader::new(&rig.path, &rig.container);
    let prim = &rig.container.json["meshes"][rig.face_mesh().mesh]["primitives"][p];
    let read = |a: &Value| reader.read(a.as_u64().unwrap() as usize).unwrap().data;
    let mut out: Vec<(String, Vec<f64>)> = prim["attributes"]
        .as_object()
        .unwrap()
        .iter()
        .map(|(k, a)| (k.clone(), read(a)))
        .collect();
    for (i, t) in prim["targets"].as_array().unwrap()[..targets]
        .iter()
        .enumerate()
    {
        for (k, a) in t.as_object().unwrap() {
            out.push((format!("target{i}.{k}"), read(a)));
        }
    }
    if let Some(ix) = prim["indices"].as_u64() {
        let idx = reader.read_indices(ix as usize).unwrap();
        out.push(("indices".into(), idx.iter().map(|&i| i as f64).collect()));
    }
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// The riding primitives of the input's face read back from the output equal the input's,
/// bit for bit (attributes, indices and the rig's own targets).
fn assert_riding_unchanged(input: &Path, output: &Path) {
    let a = load(input, &LoadOptions::default()).unwrap();
    let b = load(output, &LoadOptions::default()).unwrap();
    let n = a.face().targets.len();
    let riding: Vec<usize> = a.parts.riding().map(|p| p.primitive).collect();
    assert!(!riding.is_empty());
    for p in riding {
        let (va, vb) = (primitive_values(&a, p, n), primitive_values(&b, p, n));
        assert_eq!(va.len(), vb.len(), "primitive {p}'s attributes");
        for ((ka, xa), (kb, xb)) in va.iter().zip(&vb) {
            assert_eq!(ka, kb);
            let same =
                xa.len() == xb.len() && xa.iter().zip(xb).all(|(x, y)| x.to_bits() == y.to_bits());
            assert!(same, "primitive {p}: {ka} changed");
        }
    }
}

/// The largest area fraction of any pose outside the model (0 when none is).
fn worst_outside(report: &Value) -> f64 {
    report["out_of_model"]["regions"]
        .as_array()
        .map_or(0.0, |r| {
            r.iter()
                .map(|x| x["area_fraction"].as_f64().unwrap())
                .fold(0.0, f64::max)
        })
}

fn check_file(out: &Path) {
    if let Some(r) = common::validate(&[out.to_path_buf()]) {
        common::assert_valid(&r);
    }
}

/// The shape keys of the first object Blender imported with any.
fn blender_keys(out: &Path) -> Option<Vec<String>> {
    let r = common::blender_import(out)?;
    assert!(r["error"].is_null(), "{r}");
    let keys = r["objects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["shape_keys"].as_array().is_some_and(|k| !k.is_empty()))
        .expect("an object with shape keys")["shape_keys"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap().to_string())
        .collect();
    Some(keys)
}

/// A face of several primitives (skin, eyeballs, lash cards, mouth pocket), compact
/// (quantized, meshopt): the skin is told from the rest, the rest rides along bit for bit, and
/// the lip roll and press shapes, which fold the lips past 150°, are handled, not refused.
#[test]
fn a_face_of_several_primitives_keeps_its_eyes_lashes_and_mouth() {
    let dir = tempfile::tempdir().unwrap();
    let rig = rig_path("avatar_parts.glb");
    // mouthRollLower … mouthPressRight.
    let (out, report) = animate(&rig, dir.path(), &["--frames", "31:37"]);
    check_file(&out);
    let parts = report["face_parts"]["parts"].as_array().unwrap();
    let skin: Vec<u64> = parts
        .iter()
        .filter(|p| p["skin"] == true)
        .map(|p| p["primitive"].as_u64().unwrap())
        .collect();
    assert_eq!(skin, vec![0], "{parts:?}");
    let reasons: Vec<&str> = parts
        .iter()
        .map(|p| p["reason"].as_str().unwrap())
        .collect();
    assert!(
        reasons.contains(&"closed_apart") && reasons.contains(&"alpha_mask"),
        "{reasons:?}"
    );
    assert_riding_unchanged(&rig, &out);
    let regions = report["out_of_model"]["regions"].as_array().unwrap();
    let folded: Vec<u64> = regions
        .iter()
        .filter(|r| r["folded_edges"].as_u64().unwrap() > 0)
        .map(|r| r["pose"].as_u64().unwrap())
        .collect();
    for shape in [31, 32, 35, 36] {
        assert!(folded.contains(&shape), "shape {shape} folds: {folded:?}");
    }
    let worst = worst_outside(&report);
    assert!(worst > 0.0 && worst < 0.05, "out of model: {worst}");
}

/// A still avatar (a skinned body, a head with ARKit shapes and visemes, eyes and teeth as
/// meshes of their own carrying the same targets): its folding shapes solve, each shape that
/// compresses skin gets a corrective and one that does not is said, and Blender imports the
/// rig's shape keys with the correctives. Its shapes solved by two workers side by side
/// give the file one worker writes, byte for byte.
#[test]
fn a_still_avatar_gets_a_corrective_per_wrinkling_shape() {
    let dir = tempfile::tempdir().unwrap();
    let rig = rig_path("avatar.glb");
    // eyeBlinkLeft … eyeWideLeft: a blink that closes the lids, and shapes that barely move.
    let (out, report) = animate_on(&rig, dir.path(), &["--frames", "0:7"], Some(2));
    check_file(&out);
    let one = tempfile::tempdir().unwrap();
    let (alone, _) = animate_on(&rig, one.path(), &["--frames", "0:7"], Some(1));
    assert!(
        std::fs::read(&out).unwrap() == std::fs::read(&alone).unwrap(),
        "two workers and one write different files"
    );
    let frames = report["per_frame"].as_array().unwrap();
    assert_eq!(frames.len(), 7);
    let solved = frames.iter().filter(|f| f["shell"].is_object()).count();
    let skipped = frames
        .iter()
        .filter(|f| f["not_simulated"] == "compresses_nothing")
        .count();
    assert_eq!(solved + skipped, 7);
    assert!(
        solved >= 2 && skipped >= 1,
        "solved {solved}, skipped {skipped}"
    );
    for f in frames.iter().filter(|f| f["shell"].is_object()) {
        assert_eq!(f["shell"]["status"], "converged", "{f}");
    }
    assert!(
        report["out_of_model"]["regions"][0]["pose"] == 0,
        "the blink folds"
    );
    assert!(worst_outside(&report) < 0.05);
    let correctives = report["export"]["wrinkle_targets"].as_u64().unwrap();
    assert!(correctives >= 1 && correctives as usize <= solved);
    if let Some(keys) = blender_keys(&out) {
        assert!(keys.iter().any(|k| k == "eyeBlinkLeft"), "{keys:?}");
        assert!(keys.iter().any(|k| k.ends_with("_wrinkle")), "{keys:?}");
    }
}

/// An animated avatar through a blink, a lip press, a lip roll and a viseme: the folds'
/// skin follows the blend shape, switching on and off without a jolt (where a region's fade
/// changes between two frames, the exported wrinkles move by at most the clip's 99th
/// percentile elsewhere), and the exported surface passes through itself nowhere the blend
/// shape does not.
#[test]
fn an_animated_avatar_folds_without_a_jolt() {
    let dir = tempfile::tempdir().unwrap();
    let rig = rig_path("avatar_clip.glb");
    let (out, report) = animate(&rig, dir.path(), &[]);
    check_file(&out);
    let worst = worst_outside(&report);
    assert!(worst > 0.0 && worst < 0.05, "out of model: {worst}");
    let jolt = &report["out_of_model"]["jolt"];
    let (band, switching, p99) = (
        jolt["band_p99_m"].as_f64().unwrap(),
        jolt["switching_p99_m"].as_f64().unwrap(),
        jolt["elsewhere_p99_m"].as_f64().unwrap(),
    );
    eprintln!("jolt: {jolt}");
    // Where a region switches on or off, no more than the skin moves elsewhere.
    assert!(switching <= p99, "{jolt}");
    // The bands lie by the lips and lids, where the wrinkles move most, switching or not;
    // within 3× of the skin elsewhere.
    assert!(band <= 3.0 * p99, "{jolt}");
    assert_eq!(report["totals"]["frames_not_converged"], 0);
    assert!(report["export"]["wrinkle_targets"].as_u64().unwrap() >= 1);
    if let Some(keys) = blender_keys(&out) {
        assert!(keys.iter().any(|k| k.starts_with("wrinkle_")), "{keys:?}");
    }
}

/// The ICT face's twelve primitives: its face and the back of its head are skin; gums and
/// tongue, teeth, scleras, irises ride along as surfaces apart, the lacrimal fluid, eye
/// blend, eye occlusion and lashes as alpha-blended cards.
#[test]
fn the_ict_face_is_told_from_its_eyes_teeth_and_cards() {
    let Some(p) = common::shared_data("ICTFaceKit.glb") else {
        return;
    };
    let rig = load(&p, &LoadOptions::default()).unwrap();
    let skin: Vec<usize> = rig
        .parts
        .parts
        .iter()
        .filter(|p| p.skin)
        .map(|p| p.primitive)
        .collect();
    assert_eq!(skin, vec![0, 1]);
    use furrow::io::parts::PartReason::*;
    let reasons: Vec<_> = rig.parts.parts.iter().map(|p| p.reason).collect();
    assert_eq!(
        &reasons[2..8],
        &[
            OpenApart,
            ClosedApart,
            ClosedApart,
            ClosedApart,
            ClosedApart,
            ClosedApart
        ]
    );
    assert!(reasons[8..].iter().all(|&r| r == AlphaBlend));
    assert_eq!(rig.face().primitives.len(), 2);
}

/// The still ICT face, bare, on a few shapes (a brow raise, a blink that closes the lids
/// onto each other, the lips pressed shut): exit 0, a valid file, riding primitives
/// unchanged, at most 5 % of the skin outside the model in any shape.
#[test]
fn the_still_ict_face_runs_bare_on_a_few_shapes() {
    let Some(p) = common::shared_data("ICTFaceKit.glb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (out, report) = animate(&p, dir.path(), &["--frames", "14:16"]);
    check_file(&out);
    assert_riding_unchanged(&p, &out);
    assert!(worst_outside(&report) < 0.05);
}

/// The animated ICT face, bare, through its blink (frame 51 closes the lids onto each other)
/// as a pre-rolled chunk: exit 0, a valid file with the wrinkle layer, riding primitives
/// unchanged, at most 5 % of the skin outside the model in any frame.
/// The frames 40:60 simulate 20 frames of a 140k-triangle skin (minutes): this
/// chunk covers the blink's frames 50:53 with one frame of pre-roll.
#[test]
#[ignore = "the ICT skin refines to 140k triangles: set-up and 4 frames take about 10 minutes on two cores, too long for CI; run with --ignored"]
fn the_animated_ict_face_blinks_bare_as_a_pre_rolled_chunk() {
    let Some(p) = common::shared_data("ICTFaceKit-performance.glb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let (out, report) = animate(&p, dir.path(), &["--frames", "50:53", "--preroll", "1"]);
    check_file(&out);
    assert_riding_unchanged(&p, &out);
    assert_eq!(report["preroll"], 1);
    assert_eq!(report["per_frame"].as_array().unwrap().len(), 3);
    let worst = worst_outside(&report);
    assert!(worst < 0.05, "out of model: {worst}");
    let simulated = report["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .all(|f| f["shell"].is_object());
    assert!(simulated, "a frame of the blink was not simulated");
    assert!(report["export"]["wrinkle_targets"].as_u64().unwrap() >= 1);
}
