//! `furrow demo`: the main job (`furrow animate`) on `rigs/face.glb`, with its report and
//! previews, printing where the files went.

use super::animate::{self, AnimateArgs};
use super::Output;
use std::path::{Path, PathBuf};

/// Arguments of `furrow demo`.
#[derive(Debug, clap::Args)]
pub struct DemoArgs {
    /// Folder for the outputs (files of an earlier demo run there are replaced, and said so).
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// Frames per second at which the animation is sampled.
    #[arg(long, default_value_t = DEMO_FPS)]
    pub fps: f64,
    /// Frames to simulate, `A:B` (end exclusive; default `:`, the whole clip).
    #[arg(long, default_value = DEMO_FRAMES)]
    pub frames: String,
    /// The rig (default: rigs/face.glb of this checkout).
    #[arg(long)]
    pub rig: Option<PathBuf>,
    /// Also write one glTF per frame into OUT/frames.
    #[arg(long)]
    pub frames_dir: bool,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// Metres per unit of the rig file, or `auto` (default; see `animate --scale`).
    #[arg(long, value_parser = crate::io::units::scale_arg)]
    pub scale: Option<crate::io::units::ScaleSetting>,
    /// The output's form and storage.
    #[command(flatten)]
    pub export: super::export::ExportArgs,
}

impl DemoArgs {
    /// The demo's default arguments with outputs in `out` (for `furrow bench suite`).
    pub fn for_benchmark(out: PathBuf) -> Self {
        Self {
            out,
            fps: DEMO_FPS,
            frames: DEMO_FRAMES.into(),
            rig: None,
            frames_dir: false,
            paths: Default::default(),
            scale: None,
            export: Default::default(),
        }
    }
}

/// The demo's frame rate (frames per second). Frames 1/30 s apart keep every skin solve a
/// small step from its warm start; sparser sampling makes each solve cross wrinkle
/// bifurcations and costs far more per frame than it saves in frames.
pub const DEMO_FPS: f64 = 30.0;

/// The demo's frames: the whole clip (262 frames, 8.7 s at 30 fps: each of the rig's nine
/// shapes alone, then four combinations).
pub const DEMO_FRAMES: &str = ":";

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
    run_demo(a, out).map(|_| ())
}

/// Run the demo and return its run's totals (frames written, wall time, per-stage time).
pub fn run_demo(a: DemoArgs, out: &Output) -> anyhow::Result<crate::pipeline::record::Totals> {
    let rig = a.rig.clone().unwrap_or_else(default_rig);
    if a.rig.is_none() && !rig.exists() {
        anyhow::bail!(
            "{}: the demo rig is missing; make it with `furrow rig generate -o {}`",
            rig.display(),
            rig.display()
        );
    }
    let output = a.out.join("face_wrinkled.glb");
    let replaced = output.exists();
    let args = AnimateArgs {
        rig: rig.clone(),
        output: output.clone(),
        export: a.export.clone(),
        scene: None,
        frames: Some(a.frames.clone()).filter(|f| f != ":"),
        preroll: None,
        fps: a.fps,
        frames_dir: a.frames_dir.then(|| a.out.join("frames")),
        report: Some(a.out.join("report.json")),
        preview: Some(a.out.join("preview")),
        mesh: None,
        skin_primitives: None,
        scale: a.scale,
        // The demo's folder is its own: an earlier demo's files are replaced (and said so).
        force: true,
        paths: a.paths,
        no_chunk: true,
        clamp_frames: true,
    };
    let done = animate::animate_one(&args, out)?;
    if replaced {
        out.say(format!(
            "replaced the earlier demo outputs in {}",
            a.out.display()
        ));
    }
    let rep = &done.run.report;
    out.json_result(&serde_json::json!({
        "ok": true, "rig": rig, "output": output, "files": done.files,
        "frames": rep.totals.frames_written, "fps": a.fps, "seconds": rep.totals.wall_s,
        "wavelength_m": rep.wavelength_m,
    }));
    animate::say_summary(out, &done);
    Ok(done.run.report.totals.clone())
}
