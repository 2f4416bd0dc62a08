//! End to end: `furrow animate` and the pipeline on small rigs, `merge`, `batch`, determinism.

mod common;

use common::{furrow, run_ok};
use furrow::pipeline::record::Stage;

use furrow::io::load::{load_bytes, LoadOptions};
use furrow::pipeline::{self, RunOptions};
use furrow::scene::Scene;
use std::path::{Path, PathBuf};

fn write_sheet(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, common::sheet_rig(40, 0.1, 0.15, 0.3)).unwrap();
    p
}

fn write_other_sheet(dir: &Path) -> PathBuf {
    let p = dir.join("other.glb");
    std::fs::write(&p, common::sheet_rig(20, 0.1, 0.1, 0.3)).unwrap();
    p
}

/// RMS over the vertices in `pick` of the wrinkle detail (wrinkled − blend-shape surface).
fn detail_rms(out: &pipeline::RunOutput, frame: usize, pick: impl Fn(f64) -> bool) -> f64 {
    let (mut s, mut n) = (0.0, 0);
    for (p, q) in out.frames[frame].iter().zip(&out.smooth[frame]) {
        if pick(q.x) {
            s += (p - q).norm_squared();
            n += 1;
        }
    }
    (s / n as f64).sqrt()
}

#[test]
fn sheet_tracked_wrinkles_where_compressed_and_not_where_stretched() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_sheet(dir.path(), "sheet.glb");
    let rig = load_bytes(
        &path,
        &std::fs::read(&path).unwrap(),
        &LoadOptions::default(),
    )
    .unwrap();
    // Tracking of the blended surface (the muscle-driven default is tested below).
    let opts = RunOptions::new(Scene::parse("[muscles]\nsource = \"none\"\n", "t.toml").unwrap());
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    let last = out.frames.len() - 1;
    assert_eq!(out.frames.len(), out.report.per_frame.len());
    assert!(out.frames.len() >= 10);
    // Away from the middle line and the borders: compressed (x < 0.05) against stretched.
    let left = detail_rms(&out, last, |x| (0.01..0.035).contains(&x));
    let right = detail_rms(&out, last, |x| (0.065..0.09).contains(&x));
    eprintln!("wrinkle RMS: compressed {left:.3e} m, stretched {right:.3e} m");
    assert!(
        left > 1e-4,
        "no wrinkles where the skin is compressed: {left:.3e} m"
    );
    assert!(
        left > 10.0 * right,
        "compressed {left:.3e} vs stretched {right:.3e}"
    );
    for f in &out.report.per_frame {
        let s = f.shell.as_ref().unwrap();
        assert!(s.status.is_converged(), "frame {}: {s:?}", f.frame);
    }
    let ran: Vec<_> = out
        .report
        .stages
        .iter()
        .filter(|s| s.is_ran())
        .map(|s| s.stage.as_str())
        .collect();
    let skipped: Vec<_> = out
        .report
        .stages
        .iter()
        .filter(|s| !s.is_ran())
        .map(|s| s.stage.as_str())
        .collect();
    for s in ["load", "weld", "lattice", "interior", "shell"] {
        assert!(ran.contains(&s), "{s} should run: {ran:?}");
    }
    for s in ["muscles", "fit"] {
        assert!(skipped.contains(&s), "{s} should be skipped: {skipped:?}");
    }
}

#[test]
fn animate_writes_valid_gltf_and_report_and_refuses_to_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let rig = write_sheet(dir.path(), "sheet.glb");
    let out = dir.path().join("out.glb");
    let report = dir.path().join("report.json");
    let (r, o, rep) = (
        rig.to_str().unwrap(),
        out.to_str().unwrap(),
        report.to_str().unwrap(),
    );
    run_ok(&["animate", r, "-o", o, "--report", rep, "--quiet"]);
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    let frames = j["per_frame"].as_array().unwrap();
    assert!(frames.len() >= 10);
    for key in ["frame", "time_s", "interior", "shell"] {
        assert!(frames[3].get(key).is_some(), "per_frame lacks {key}");
    }
    assert!(j["wavelength_m"].as_f64().unwrap() > 0.0);
    if let Some(v) = common::validate(std::slice::from_ref(&out)) {
        common::assert_valid(&v);
    }
    // A second run without --force must refuse and leave the file as it was.
    let before = std::fs::read(&out).unwrap();
    let o2 = furrow()
        .args(["animate", r, "-o", o, "--quiet"])
        .output()
        .unwrap();
    assert!(!o2.status.success());
    assert!(String::from_utf8_lossy(&o2.stderr).contains("--force"));
    assert_eq!(std::fs::read(&out).unwrap(), before);
}

#[test]
fn chunks_merge_into_the_unsplit_file_and_threads_do_not_change_bytes() {
    let dir = tempfile::tempdir().unwrap();
    let rig = write_sheet(dir.path(), "sheet.glb");
    let r = rig.to_str().unwrap();
    let p = |n: &str| dir.path().join(n).to_str().unwrap().to_string();
    let whole = p("whole.glb");
    let status = furrow()
        .args(["animate", r, "-o", &whole, "--quiet"])
        .env("RAYON_NUM_THREADS", "2")
        .status()
        .unwrap();
    assert!(status.success());
    let one_thread = p("one.glb");
    let status = furrow()
        .args(["animate", r, "-o", &one_thread, "--quiet"])
        .env("RAYON_NUM_THREADS", "1")
        .status()
        .unwrap();
    assert!(status.success());
    assert!(
        std::fs::read(&whole).unwrap() == std::fs::read(&one_thread).unwrap(),
        "1 and 2 threads gave different bytes"
    );
    let (a, b) = (p("part0.glb"), p("part1.glb"));
    run_ok(&["animate", r, "-o", &a, "--frames", ":4", "--quiet"]);
    run_ok(&["animate", r, "-o", &b, "--frames", "4:", "--quiet"]);
    let merged = p("merged.glb");
    run_ok(&["merge", &b, &a, "--rig", r, "-o", &merged, "--quiet"]);
    assert!(
        std::fs::read(&whole).unwrap() == std::fs::read(&merged).unwrap(),
        "merged chunks differ from the unsplit run"
    );
    // A gap is refused, and so is another rig.
    let c = p("part2.glb");
    run_ok(&["animate", r, "-o", &c, "--frames", ":2", "--quiet"]);
    let o = furrow()
        .args(["merge", &c, &b, "--rig", r, "-o", &p("gap.glb")])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("missing"));
    assert!(!dir.path().join("gap.glb").exists());
    let other = write_other_sheet(dir.path());
    let o = furrow()
        .args([
            "merge",
            &a,
            &b,
            "--rig",
            other.to_str().unwrap(),
            "-o",
            &p("x.glb"),
        ])
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("another rig"));
}

#[test]
fn batch_reports_failures_goes_on_and_skips_finished_work() {
    let dir = tempfile::tempdir().unwrap();
    let good = write_sheet(dir.path(), "good.glb");
    let bad = dir.path().join("bad.glb");
    std::fs::write(&bad, b"glTF not really").unwrap();
    let outdir = dir.path().join("out");
    let args = |extra: &[&str]| {
        let mut v = vec![
            "batch".to_string(),
            bad.display().to_string(),
            good.display().to_string(),
            "-o".into(),
            outdir.display().to_string(),
            "--frames".into(),
            ":3".into(),
            "--json".into(),
        ];
        v.extend(extra.iter().map(|s| s.to_string()));
        v
    };
    let o = furrow().args(args(&[])).output().unwrap();
    assert!(!o.status.success(), "a failed input must fail the batch");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let res = j["results"].as_array().unwrap();
    assert_eq!(res[0]["status"], "failed");
    assert!(res[0]["error"].as_str().unwrap().contains("bad.glb"));
    assert_eq!(res[1]["status"], "done");
    assert!(outdir.join("good.glb").exists() && outdir.join("good.report.json").exists());
    assert!(
        !outdir.join("bad.glb").exists(),
        "no partial output for a failed input"
    );
    // Rerun: the finished one is skipped.
    let o = furrow().args(args(&[])).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["results"][1]["status"], "skipped");
    // A killed run leaves an output without its report: it is redone.
    std::fs::remove_file(outdir.join("good.report.json")).unwrap();
    let o = furrow().args(args(&[])).output().unwrap();
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(j["results"][1]["status"], "done");
    let leftovers: Vec<_> = std::fs::read_dir(&outdir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with('.') || n.contains("tmp"))
        .collect();
    assert!(leftovers.is_empty(), "temporary files left: {leftovers:?}");
}

#[test]
fn masked_skin_simulates_only_the_mask_and_the_rest_keeps_the_blend_shapes() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_sheet(dir.path(), "sheet.glb");
    let rig = load_bytes(
        &path,
        &std::fs::read(&path).unwrap(),
        &LoadOptions::default(),
    )
    .unwrap();
    let scene = Scene::parse(
        "[skin]\nmask = [{ min = [-1.0, -1.0, -1.0], max = [0.045, 1.0, 1.0] }]\n",
        "mask.toml",
    )
    .unwrap();
    let opts = RunOptions::new(scene);
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    let sizes = &out.report.sizes;
    let sim = sizes["simulated_vertices"].as_u64().unwrap();
    let all = sizes["skin_vertices"].as_u64().unwrap();
    assert!(sim > 0 && sim < all * 6 / 10, "{sim} of {all} simulated");
    let last = out.frames.len() - 1;
    // Outside the mask: exactly the blend shapes.
    for (p, q) in out.frames[last].iter().zip(&out.smooth[last]) {
        if q.x > 0.06 {
            assert_eq!(p, q);
        }
    }
    assert!(detail_rms(&out, last, |x| (0.01..0.035).contains(&x)) > 1e-4);
}

#[test]
fn a_rig_without_animation_is_solved_once_without_dynamics() {
    let dir = tempfile::tempdir().unwrap();
    let (mut json, bin) = common::tiny_rig();
    json.as_object_mut().unwrap().remove("animations");
    let p = dir.path().join("still.glb");
    std::fs::write(&p, common::glb_bytes(&json, &bin)).unwrap();
    let out = dir.path().join("still_out.glb");
    let report = dir.path().join("r.json");
    let o = furrow()
        .args([
            "animate",
            p.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
            "--report",
        ])
        .arg(&report)
        .args(["--scene"])
        .arg(write_scene(
            dir.path(),
            "big.toml",
            "[skin]\nthickness = 0.1\n[interior]\ncell_size = 0.25\n",
        ))
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(j["per_frame"].as_array().unwrap().len(), 1);
    let interior = j["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "interior")
        .unwrap();
    assert!(
        interior["why"].as_str().unwrap().contains("no dynamics"),
        "{interior}"
    );
}

fn write_scene(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn robot_expressive_head_is_animated_to_a_valid_file() {
    let Some(robot) = common::shared_data("RobotExpressive.glb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("robot.glb");
    let report = dir.path().join("robot.json");
    // No frame of the robot's clip compresses its skin enough to wrinkle, so by default its
    // skin is neither simulated nor refined; simulating all of it refines the coarse head,
    // whose export (skinned, beside 18 other meshes) must stay valid.
    let text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/robot.toml"))
            .unwrap()
            .replace("[skin]\n", "[skin]\nsimulate = \"all\"\n");
    let scene = write_scene(dir.path(), "robot.toml", &text);
    let o = furrow()
        .arg("animate")
        .arg(&robot)
        .args(["--scene"])
        .arg(&scene)
        .args(["--frames", ":12", "-o"])
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    // Head_4 is the one of the three heads with the same targets whose targets move.
    assert_eq!(j["face"], "Head_4");
    assert_eq!(j["rig_scale"]["metres_per_unit"], 1.0);
    assert_eq!(j["per_frame"].as_array().unwrap().len(), 12);
    let refine = j["stages"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["stage"] == "refine")
        .unwrap();
    assert_eq!(
        refine["status"], "ran",
        "the robot's coarse head needs refining: {refine}"
    );
    // The other 18 meshes, the skins and the 14 animations pass through; the head keeps its
    // three shapes and gains the wrinkle layer's targets.
    let anim = furrow::io::load(&out, &Default::default()).unwrap();
    assert_eq!(anim.instances.len(), 19);
    assert!(anim.animations.len() >= 14);
    let k = j["export"]["wrinkle_targets"].as_u64().unwrap() as usize;
    let names: Vec<&str> = anim
        .face()
        .targets
        .iter()
        .map(|t| t.name.as_str())
        .collect();
    assert_eq!(names[..3], ["Angry", "Surprised", "Sad"]);
    assert_eq!(names.len(), 3 + k, "{names:?}");
    if let Some(v) = common::validate(&[out]) {
        common::assert_valid(&v);
    }
}

/// RobotExpressive's face is 2.3 m tall in its file: a bare `animate` simulates it at human
/// size (0.1 m per unit) and says so; `--scale 1` keeps its size, where the default skin is
/// far too coarse to simulate (its whole skin, as no frame compresses it enough to be
/// selected), and the refusal names the face's size and the scale.
#[test]
fn a_ten_times_human_face_is_scaled_and_scale_one_is_refused_with_the_numbers() {
    let Some(robot) = common::shared_data("RobotExpressive.glb") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r.glb");
    let report = dir.path().join("r.json");
    let o = furrow()
        .arg("animate")
        .arg(&robot)
        .args(["--frames", ":3", "--no-chunk", "-o"])
        .arg(&out)
        .arg("--report")
        .arg(&report)
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{e}");
    assert!(e.contains("simulated at 0.1 m per file unit"), "{e}");
    let j: serde_json::Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(j["rig_scale"]["metres_per_unit"], 0.1);
    let out1 = dir.path().join("r1.glb");
    let all = write_scene(dir.path(), "all.toml", "[skin]\nsimulate = \"all\"\n");
    let o = furrow()
        .arg("animate")
        .arg(&robot)
        .arg("--scene")
        .arg(&all)
        .args(["--scale", "1", "-o"])
        .arg(&out1)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    let e = String::from_utf8_lossy(&o.stderr);
    for words in [
        "RobotExpressive.glb",
        "too coarse",
        "λ",
        "2.255 m tall",
        "1 m per file unit",
    ] {
        assert!(e.contains(words), "lacks {words:?}: {e}");
    }
    assert!(!out1.exists());
}

#[test]
fn muscles_fitted_per_frame_drive_the_interior_and_the_skin_wrinkles_by_default() {
    let dir = tempfile::tempdir().unwrap();
    let path = write_sheet(dir.path(), "sheet.glb");
    let rig = load_bytes(
        &path,
        &std::fs::read(&path).unwrap(),
        &LoadOptions::default(),
    )
    .unwrap();
    let opts = RunOptions::new(Scene::default());
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    assert_eq!(
        out.report.sizes["muscles"], 1,
        "one muscle for the one blend shape"
    );
    for s in [Stage::Muscles, Stage::Fit] {
        let st = out.report.stage(s).unwrap();
        assert!(st.is_ran(), "{s}: {st:?}");
    }
    let last = out.report.per_frame.last().unwrap();
    let fit = last.fit.as_ref().expect("the fit ran in every frame");
    assert!(fit.status.is_converged());
    assert!(fit.residual.is_finite() && fit.residual < 5e-3, "{fit:?}");
    let n = out.frames.len() - 1;
    let left = detail_rms(&out, n, |x| (0.01..0.035).contains(&x));
    let right = detail_rms(&out, n, |x| (0.065..0.09).contains(&x));
    eprintln!("muscle-driven wrinkle RMS: compressed {left:.3e} m, stretched {right:.3e} m");
    assert!(
        left > 1e-4 && left > 5.0 * right,
        "{left:.3e} vs {right:.3e}"
    );
}
