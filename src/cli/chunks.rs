//! `furrow chunks`: the frame ranges of a clip for a farm, balanced by expected cost.

use super::Output;
use crate::io as fio;
use crate::pipeline::farm::{self, DEFAULT_PREROLL};
use crate::pipeline::frames::FrameRange;
use crate::pipeline::setup::select::default_threshold;
use crate::scene::Scene;
use std::path::PathBuf;

/// Arguments of `furrow chunks`.
#[derive(Debug, clap::Args)]
pub struct ChunksArgs {
    /// The rig: a glTF with a morph-target face and an animation.
    pub rig: PathBuf,
    /// How many chunks (machines).
    #[arg(long)]
    pub count: usize,
    /// Frames each chunk simulates from rest before its first written frame (give the same
    /// to `animate --preroll`).
    #[arg(long, default_value_t = DEFAULT_PREROLL)]
    pub preroll: usize,
    /// Only these frames of the clip, `A:B` (end exclusive); default: the whole clip.
    #[arg(long)]
    pub frames: Option<String>,
    /// Frames per second at which the clip is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Scene file (TOML), as given to `animate` (its materials set the compression that
    /// counts).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// The face mesh by name or index, as given to `animate --mesh`.
    #[arg(long)]
    pub mesh: Option<String>,
    /// The face's skin primitives, as given to `animate --skin-primitives`.
    #[arg(long, value_parser = crate::io::parts::parse_picks)]
    pub skin_primitives: Option<Vec<crate::io::parts::PrimitivePick>>,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
}

/// Run `furrow chunks`: print one `A:B` range per line (with `--json`, the ranges with
/// their expected costs and each frame's cost).
pub fn run(a: ChunksArgs, out: &Output) -> anyhow::Result<()> {
    if a.count == 0 {
        anyhow::bail!("--count must be at least 1");
    }
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0) {
        anyhow::bail!("--fps must lie in (0, 1000], got {}", a.fps);
    }
    let scene = match &a.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default(),
    };
    scene.validate()?;
    let load = super::animate::rig_load_options(&a.mesh, &a.skin_primitives, &scene, a.paths);
    let rig = fio::load::load(&a.rig, &load)?;
    if rig.track.is_none() {
        anyhow::bail!(
            "{}: the rig has no animation; a still rig's shapes are solved each alone (run \
             `furrow animate` on it whole)",
            a.rig.display()
        );
    }
    let threshold = default_threshold(&scene.materials()?);
    let costs = farm::frame_costs(&rig, a.fps, threshold);
    let within = match &a.frames {
        Some(t) => FrameRange::parse(t, costs.len())?,
        None => FrameRange::all(costs.len()),
    };
    let ranges: Vec<FrameRange> =
        farm::balance(&costs[within.start..within.end], a.count, a.preroll)
            .into_iter()
            .map(|r| FrameRange {
                start: r.start + within.start,
                end: r.end + within.start,
            })
            .collect();
    let chunk_cost =
        |r: &FrameRange| -> f64 { costs[r.start.saturating_sub(a.preroll)..r.end].iter().sum() };
    out.json_result(&serde_json::json!({
        "ok": true,
        "preroll": a.preroll,
        "chunks": ranges.iter().map(|r| serde_json::json!({
            "frames": [r.start, r.end], "expected_cost": chunk_cost(r),
        })).collect::<Vec<_>>(),
        "frame_costs": costs,
    }));
    for r in &ranges {
        out.say(format!("{}:{}", r.start, r.end));
    }
    if ranges.len() < a.count {
        out.note(format!(
            "note: {} frames make only {} chunks of one frame or more",
            within.len(),
            ranges.len()
        ));
    }
    Ok(())
}
