//! A clip on a farm: `furrow chunks` balances ranges, `animate --frames A:B --preroll P`
//! starts each chunk from rest P frames early, and `merge` cross-fades pre-rolled chunks
//! over their overlap, reporting each seam against its neighbour and an unsplit run.

mod common;

use common::{furrow, run_ok};

use serde_json::Value;
use std::path::Path;

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

#[test]
fn pre_rolled_chunks_overlap_merge_and_report_their_seams() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("sheet.glb");
    // A 0.6 s compression of a sheet: 19 frames at 30 fps.
    std::fs::write(&rig, common::sheet_rig(40, 0.1, 0.15, 0.6)).unwrap();
    let r = rig.to_str().unwrap();
    let ranges = run_ok(&["chunks", r, "--count", "2", "--preroll", "2"]);
    let lines: Vec<&str> = ranges.lines().collect();
    assert_eq!(lines.len(), 2, "{ranges}");
    assert!(
        lines[0].starts_with("0:") && lines[1].ends_with(":19"),
        "{ranges}"
    );
    let p = |n: &str| path(dir.path(), n);
    // The reference: the clip unsplit, with its chunk file.
    run_ok(&[
        "animate",
        r,
        "-o",
        &p("whole.glb"),
        "--frames",
        "0:19",
        "--quiet",
    ]);
    // Two pre-rolled chunks sharing frames 8 and 9.
    run_ok(&[
        "animate",
        r,
        "-o",
        &p("a.glb"),
        "--frames",
        "0:10",
        "--preroll",
        "2",
        "--quiet",
    ]);
    let rep_b = p("b.json");
    run_ok(&[
        "animate",
        r,
        "-o",
        &p("b.glb"),
        "--frames",
        "8:19",
        "--preroll",
        "3",
        "--report",
        &rep_b,
        "--quiet",
    ]);
    let b: Value = serde_json::from_slice(&std::fs::read(&rep_b).unwrap()).unwrap();
    assert_eq!(b["preroll"], 3);
    let deepest = b["per_frame"]
        .as_array()
        .unwrap()
        .iter()
        .map(|f| f["wrinkle_depth_max_m"].as_f64().unwrap())
        .fold(0.0, f64::max);
    eprintln!("deepest wrinkle of chunk b: {deepest:.3e} m");
    assert!(
        b["warnings"]
            .to_string()
            .contains("frames 5..8 were simulated"),
        "{}",
        b["warnings"]
    );
    let report = p("merge.json");
    run_ok(&[
        "merge",
        &p("b.glb"),
        &p("a.glb"),
        "--rig",
        r,
        "-o",
        &p("merged.glb"),
        "--reference",
        &p("whole.furrow-chunk"),
        "--report",
        &report,
        "--quiet",
    ]);
    let m: Value = serde_json::from_slice(&std::fs::read(&report).unwrap()).unwrap();
    assert_eq!(m["frames"], serde_json::json!([0, 19]));
    let seams = m["seams"].as_array().unwrap();
    assert_eq!(seams.len(), 1);
    assert_eq!(seams[0]["overlap"], serde_json::json!([8, 10]));
    let neighbours = seams[0]["neighbours_error"].as_f64().unwrap();
    let against = seams[0]["reference_error"].as_f64().unwrap();
    let whole = m["reference_error"].as_f64().unwrap();
    eprintln!("seam: neighbours {neighbours:.4}, reference {against:.4}; whole {whole:.4}");
    assert!(neighbours.is_finite() && against.is_finite() && whole.is_finite());
    assert!(
        whole < 0.5,
        "the merge is far from the unsplit run: {whole}"
    );
    let o = furrow()
        .args(["inspect", &p("merged.glb")])
        .output()
        .unwrap();
    assert!(o.status.success());
    refusals(dir.path(), r);
}

/// An exact chunk beside a pre-rolled one is refused, with nothing written, and a pre-roll
/// without frames by the command line.
fn refusals(dir: &Path, r: &str) {
    let p = |n: &str| path(dir, n);
    run_ok(&[
        "animate",
        r,
        "-o",
        &p("c.glb"),
        "--frames",
        "10:19",
        "--quiet",
    ]);
    let o = furrow()
        .args([
            "merge",
            &p("a.glb"),
            &p("c.glb"),
            "--rig",
            r,
            "-o",
            &p("mix.glb"),
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("exact and pre-rolled"));
    assert!(!dir.join("mix.glb").exists());
    let o = furrow()
        .args(["animate", r, "-o", &p("x.glb"), "--preroll", "2"])
        .output()
        .unwrap();
    assert!(!o.status.success());
}
