//! `furrow scene FILE`: run a synthetic scene (slab, cushions, cubes) and write its frames.

use super::Output;
use crate::io::atomic::{self, Overwrite};
use crate::io::model::{MorphTarget, WeightKeys};
use crate::pipeline::synthetic;
use crate::scene::Scene;
use anyhow::bail;
use std::path::PathBuf;

/// Arguments of `furrow scene`.
#[derive(Debug, clap::Args)]
pub struct SceneArgs {
    /// The scene file (TOML with `[geometry]` and `[load]`; see examples/).
    pub file: PathBuf,
    /// Output folder: NAME.glb (one morph target per frame, played at --fps) and NAME.json.
    #[arg(long, default_value = "out/scenes")]
    pub out: PathBuf,
    /// Frames per second of the exported animation.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// Run `furrow scene`.
pub fn run(a: SceneArgs, out: &Output) -> anyhow::Result<()> {
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0) {
        bail!("--fps must lie in (0, 1000], got {}", a.fps);
    }
    let scene = Scene::load(&a.file)?;
    let name = scene.name.clone().unwrap_or_else(|| {
        a.file
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("scene")
            .to_string()
    });
    let glb = a.out.join(format!("{name}.glb"));
    let json = a.out.join(format!("{name}.json"));
    let ow = Overwrite::from_force(a.force);
    atomic::check_free(&[&glb, &json], ow)?;
    let frames = scene.load.as_ref().map_or(0, |l| l.frames);
    let pb = out.progress(frames as u64, "simulating");
    let res = synthetic::run_scene(&scene, &|k, total| {
        pb.set_length(total as u64);
        pb.set_position(k as u64);
    })
    .map_err(|e| e.context(format!("{}", a.file.display())))?;
    pb.finish_and_clear();
    let targets: Vec<MorphTarget> = res
        .frames
        .iter()
        .enumerate()
        .map(|(k, f)| MorphTarget {
            name: format!("frame_{k:05}"),
            positions: f
                .iter()
                .zip(&res.mesh.positions)
                .map(|(p, r)| p - r)
                .collect(),
            normals: None,
        })
        .collect();
    let n = targets.len();
    let keys = WeightKeys {
        times: (0..n).map(|k| k as f64 / a.fps).collect(),
        weights: (0..n)
            .map(|k| (0..n).map(|j| if j == k { 1.0 } else { 0.0 }).collect())
            .collect(),
    };
    let bytes = crate::io::export::rig_glb(&name, &res.mesh, &targets, &keys)?;
    atomic::write(&glb, &bytes, ow)?;
    let report = serde_json::json!({
        "scene": a.file, "name": name, "frames": n, "fps": a.fps, "copies": res.copies,
    });
    atomic::write(&json, &serde_json::to_vec_pretty(&report)?, ow)?;
    out.json_result(
        &serde_json::json!({ "ok": true, "glb": glb, "report": json, "copies": res.copies }),
    );
    out.say(format!("{name}: {n} frames → {}", glb.display()));
    for c in &res.copies {
        out.say(format!(
            "  copy {}: E_x = {:.3e} Pa, h = {:.2} mm: λ predicted {:.2} mm, measured {}, sag {:.2} mm{}",
            c.copy,
            c.skin.young,
            c.skin.thickness * 1e3,
            c.predicted_wavelength_m * 1e3,
            c.measured_wavelength_m
                .map_or("no wrinkles".to_string(), |m| format!("{:.2} mm", m * 1e3)),
            c.sag_m * 1e3,
            if c.frames_not_converged > 0 {
                format!(" ({} frames not converged)", c.frames_not_converged)
            } else {
                String::new()
            }
        ));
    }
    out.say(format!("  report: {}", json.display()));
    Ok(())
}
