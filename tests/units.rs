//! A rig's units: the face rig with its coordinates multiplied by 10 and by 0.01 is simulated
//! at human size (`auto`), wrinkles as the 1× rig does (scaled), and is written back in its
//! own units; `scale = 1` on the 10× rig is refused as too coarse, saying the face's size.

use furrow::io::load::{load_bytes, LoadOptions, Rig};
use furrow::io::units::{self, ScaleSetting};
use furrow::pipeline::{self, frames::FrameRange, RunOptions, RunOutput};
use furrow::scene::Scene;
use nalgebra::Vector3;
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;

/// Frames 0..11 of the face rig: the brow raise's forehead lines grow to about 0.7 mm.
const FRAMES: usize = 11;

/// `rigs/face.glb`'s rig with every coordinate and delta multiplied by `factor`, as GLB.
fn face_rig_times(factor: f64) -> Vec<u8> {
    let mut rig = furrow::rig::face::generate();
    rig.mesh.positions.iter_mut().for_each(|p| *p *= factor);
    for t in &mut rig.targets {
        t.positions.iter_mut().for_each(|d| *d *= factor);
    }
    furrow::io::export::rig_glb("face", &rig.mesh, &rig.targets, &rig.keys).unwrap()
}

fn load_scaled(bytes: &[u8]) -> Rig {
    let mut rig = load_bytes(Path::new("face.glb"), bytes, &LoadOptions::default()).unwrap();
    units::apply(&mut rig, None, None);
    rig
}

fn run(rig: &Rig) -> RunOutput {
    let opts = RunOptions::new(Scene::default()).frames(FrameRange {
        start: FRAMES - 1,
        end: FRAMES,
    });
    pipeline::run(rig, &opts, &|_, _, _| {}).unwrap()
}

/// The largest wrinkle depth |wrinkled − blend-shape surface| (m) in each cell of side 2λ
/// (by the blend-shape position), of the last frame: a measure that round-off shifting the
/// wrinkles' phase within a cell leaves alone.
fn depth_per_region(out: &RunOutput) -> HashMap<[i64; 3], f64> {
    let cell = 2.0 * out.report.wavelength_m;
    let (wrinkled, smooth) = (out.frames.last().unwrap(), out.smooth.last().unwrap());
    let mut depth = HashMap::new();
    for (p, q) in wrinkled.iter().zip(smooth) {
        let key = (q / cell).map(|c| c.floor() as i64);
        let d = depth.entry([key.x, key.y, key.z]).or_insert(0.0f64);
        *d = d.max((p - q).norm());
    }
    depth
}

#[test]
fn a_face_ten_times_or_a_hundredth_of_human_size_wrinkles_as_at_human_size() {
    let reference = load_scaled(&face_rig_times(1.0));
    assert_eq!(reference.scale.metres_per_unit, 1.0);
    let base = run(&reference);
    let base_depth = depth_per_region(&base);
    let deepest = base_depth.values().copied().fold(0.0, f64::max);
    assert!(deepest > 3e-4, "the 1× run has wrinkles: {deepest} m");
    for (factor, expected) in [(10.0, 0.1), (0.01, 100.0)] {
        let rig = load_scaled(&face_rig_times(factor));
        assert_eq!(rig.scale.metres_per_unit, expected, "{}", rig.scale.why);
        assert!(rig.scale.why.contains("simulated at"), "{}", rig.scale.why);
        let out = run(&rig);
        assert_eq!(out.report.rig_scale.metres_per_unit, expected);
        let depth = depth_per_region(&out);
        let worst = base_depth
            .iter()
            .map(|(k, d)| (d - depth.get(k).copied().unwrap_or(0.0)).abs())
            .fold(0.0, f64::max);
        eprintln!(
            "×{factor}: largest difference of depth per 2λ region {:.3e} m of {deepest:.3e} m ({:.2e})",
            worst,
            worst / deepest
        );
        assert!(
            worst <= 0.01 * deepest,
            "×{factor}: depth per region differs by {worst} m (deepest {deepest} m)"
        );
        check_written_in_file_units(&rig, &out, factor);
    }
}

/// The export of a scaled run is in the file's units: its one frame (the mesh's base) read
/// back is the simulated frame divided by the scale.
fn check_written_in_file_units(rig: &Rig, out: &RunOutput, factor: f64) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("out.glb");
    let set = furrow::io::export::FrameSet {
        triangles: &out.triangles,
        frames: &out.frames,
        origin: &out.origin,
        fps: 30.0,
        weights: &[],
    };
    furrow::io::export::write_animated(rig, &set, &path, furrow::io::atomic::Overwrite::Refuse)
        .unwrap();
    let (_, back, _) = furrow::io::load::load_instances(&path).unwrap();
    let f = &back[0];
    assert_eq!(out.frames.len(), 1);
    let m = rig.scale.metres_per_unit;
    let (mut worst, mut size) = (0.0f64, 0.0f64);
    for (v, p) in out.frames[0].iter().enumerate() {
        let q: Vector3<f64> = f.positions[v];
        worst = worst.max((q - p / m).norm());
        size = size.max((p / m).norm());
    }
    assert!(
        worst <= 1e-5 * size,
        "×{factor}: the written frame is not in file units ({worst} of {size})"
    );
}

/// The capture-shaped head (`rigs/head.glb`, 2.7k vertices) ten times human size, as GLB.
fn head_rig_times_ten() -> Vec<u8> {
    let mut rig = furrow::rig::head::generate();
    rig.mesh.positions.iter_mut().for_each(|p| *p *= 10.0);
    for t in &mut rig.targets {
        t.positions.iter_mut().for_each(|d| *d *= 10.0);
    }
    furrow::io::export::rig_glb("head", &rig.mesh, &rig.targets, &rig.keys).unwrap()
}

/// A capture head 2 m tall in its file: at `scale = 1` its skin is far too coarse for the
/// human skin's wrinkles, and the refusal says how tall the face is and the scale used.
#[test]
fn scale_one_on_a_ten_times_head_is_refused_naming_its_size() {
    let dir = tempfile::tempdir().unwrap();
    let rig = dir.path().join("big.glb");
    std::fs::write(&rig, head_rig_times_ten()).unwrap();
    let out = dir.path().join("out.glb");
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args([
            "animate",
            "--scale",
            "1",
            "--frames",
            "0:1",
            "--no-chunk",
            "-o",
        ])
        .arg(&out)
        .arg(&rig)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    for words in [
        "big.glb",
        "too coarse",
        "m tall",
        "1 m per file unit",
        "--scale",
    ] {
        assert!(err.contains(words), "lacks {words:?}: {err}");
    }
    assert!(!out.exists());
    // The same through the scene file.
    let scene = dir.path().join("s.toml");
    std::fs::write(&scene, "[rig]\nscale = 1\n").unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["animate", "--frames", "0:1", "--no-chunk", "--scene"])
        .arg(&scene)
        .arg("-o")
        .arg(&out)
        .arg(&rig)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("too coarse"));
    // Bare, it is simulated at human size and says so.
    let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
        .args(["animate", "--frames", "0:1", "--no-chunk", "-o"])
        .arg(&out)
        .arg(&rig)
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("simulated at 0.1 m per file unit"), "{said}");
    eprintln!("{said}");
}

#[test]
fn scale_settings_parse_from_the_scene_and_refuse_nonsense() {
    let s: Scene = toml::from_str("[rig]\nscale = \"auto\"\n").unwrap();
    assert_eq!(s.rig.scale, Some(ScaleSetting::Auto));
    let s: Scene = toml::from_str("[rig]\nscale = 0.01\n").unwrap();
    assert_eq!(s.rig.scale, Some(ScaleSetting::MetresPerUnit(0.01)));
    let e = toml::from_str::<Scene>("[rig]\nscale = \"cm\"\n")
        .unwrap_err()
        .to_string();
    assert!(e.contains("rig.scale") && e.contains("auto"), "{e}");
    assert!(toml::from_str::<Scene>("[rig]\nscale = -2\n").is_err());
}
