//! `furrow demo`: the main job on `rigs/face.glb`.
//!
//! Today it loads the rig, samples its blend-shape animation and exports the frames (the
//! wrinkle stages land in later versions).

use super::Output;
use crate::io::atomic::Overwrite;
use crate::io::export::{self, FrameSet, VertexOrigin};
use crate::io::{self as fio, LoadOptions};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `furrow demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Folder for the outputs (files of an earlier demo run there are replaced, and said so).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Frames per second at which the animation is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// The rig (default: rigs/face.glb of this checkout).
    #[arg(long)]
    pub rig: Option<PathBuf>,
}

/// The project's face rig: `rigs/face.glb` here, else in the source checkout.
pub fn default_rig() -> PathBuf {
    let local = PathBuf::from("rigs/face.glb");
    if local.exists() {
        return local;
    }
    Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb")
}

/// Run the demo.
pub fn run(a: DemoArgs, out: &Output) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0,
        "--fps must be in (0, 1000], got {}",
        a.fps
    );
    let t0 = Instant::now();
    let rig_path = a.rig.clone().unwrap_or_else(default_rig);
    if a.rig.is_none() && !rig_path.exists() {
        anyhow::bail!(
            "{}: the demo rig is missing; make it with `furrow rig generate -o {}`",
            rig_path.display(),
            rig_path.display()
        );
    }
    let rig = fio::load(&rig_path, &LoadOptions::default())?;
    out.note(&rig.face_reason);
    let weights = rig.frame_weights(a.fps);
    let pb = out.progress(weights.len() as u64, "blending");
    let frames: Vec<_> = weights
        .iter()
        .map(|w| {
            pb.inc(1);
            rig.blend(w)
        })
        .collect();
    pb.finish_and_clear();
    let face = rig.face();
    let origin: Vec<VertexOrigin> = (0..face.positions.len()).map(VertexOrigin::same).collect();
    let set = FrameSet {
        triangles: &face.triangles,
        frames: &frames,
        origin: &origin,
        fps: a.fps,
    };
    let animated = a.out.join("face_frames.glb");
    let replaced = animated.exists();
    export::write_animated(&rig, &set, &animated, Overwrite::Replace)?;
    let dir = a.out.join("frames");
    let pb = out.progress(frames.len() as u64, "frames");
    let paths = export::write_frames_dir(&rig, &set, &dir, Overwrite::Replace, &|_| pb.inc(1))?;
    pb.finish_and_clear();
    let secs = t0.elapsed().as_secs_f64();
    out.json_result(&serde_json::json!({
        "ok": true, "rig": rig_path, "face": face.name, "frames": frames.len(), "fps": a.fps,
        "animated_glb": animated, "frames_dir": dir, "seconds": secs,
    }));
    if replaced {
        out.say(format!(
            "replaced the earlier demo outputs in {}",
            a.out.display()
        ));
    }
    out.say(format!(
        "{} frames at {} fps of '{}' ({} vertices) in {:.2} s",
        frames.len(),
        a.fps,
        face.name,
        face.positions.len(),
        secs
    ));
    out.say(format!(
        "  animated glTF (one morph target per frame): {}",
        animated.display()
    ));
    out.say(format!(
        "  one glTF per frame:                          {}/ ({} files)",
        dir.display(),
        paths.len()
    ));
    Ok(())
}
