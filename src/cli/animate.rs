//! `furrow animate`, `furrow batch` and `furrow merge`: rig in, wrinkled glTF out.

use super::export::{self as out_file, ExportArgs, Frames};
use super::Output;
use crate::io::atomic::{self, Overwrite};
use crate::io::export;
use crate::io::{self as fio, LoadOptions};
use crate::pipeline::chunk::{self, ChunkHeader};
use crate::pipeline::frames::FrameRange;
use crate::pipeline::layer::Clip;
use crate::pipeline::{self, RunOptions, RunOutput};
use crate::scene::Scene;
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `furrow animate`.
#[derive(Debug, Clone, clap::Args)]
pub struct AnimateArgs {
    /// The rig: a glTF (.glb/.gltf) with a morph-target face and (optionally) an animation.
    pub rig: PathBuf,
    /// The wrinkled animated glTF to write (.glb).
    #[arg(short, long)]
    pub output: PathBuf,
    /// The output's form and storage.
    #[command(flatten)]
    pub export: ExportArgs,
    /// Scene file (TOML): materials, lattice, solver, export; default: the defaults.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Frames to write, `A:B` (end exclusive); also writes OUTPUT's chunk file for `merge`.
    #[arg(long)]
    pub frames: Option<String>,
    /// With --frames A:B, simulate from rest P frames before A (at frame max(0, A − P),
    /// quasi-static there) instead of the clip's whole history from frame 0: chunks of a clip
    /// then run in parallel on a farm, and `furrow merge` cross-fades their overlaps.
    #[arg(long, value_name = "P", requires = "frames")]
    pub preroll: Option<usize>,
    /// Frames per second at which the clip is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Also write one glTF per frame into this folder.
    #[arg(long)]
    pub frames_dir: Option<PathBuf>,
    /// Write the run report (JSON) here.
    #[arg(long)]
    pub report: Option<PathBuf>,
    /// Write preview images into this folder.
    #[arg(long)]
    pub preview: Option<PathBuf>,
    /// The face mesh by name or index (default: the mesh with the most morph targets).
    #[arg(long)]
    pub mesh: Option<String>,
    /// The face mesh's skin primitives, by index or material name, comma-separated (`0,1`
    /// or `M_Face,M_BackHead`; over the scene's `[rig] skin_primitives`); the others ride
    /// along unchanged. Default: decided from the materials and the geometry.
    #[arg(long, value_parser = crate::io::parts::parse_picks)]
    pub skin_primitives: Option<Vec<crate::io::parts::PrimitivePick>>,
    /// Metres per unit of the rig file, or `auto` (default; over the scene's `[rig] scale`):
    /// a face larger or smaller than a human face by a power of ten is simulated at human
    /// size and written back in the file's units.
    #[arg(long, value_parser = crate::io::units::scale_arg)]
    pub scale: Option<crate::io::units::ScaleSetting>,
    /// Replace existing output files.
    #[arg(long)]
    pub force: bool,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// With --frames, do not write the chunk file (`furrow merge` needs it).
    #[arg(long)]
    pub no_chunk: bool,
    /// Cut a --frames range that ends past the clip down to the clip (the demo's default
    /// range on a shorter rig) instead of refusing it.
    #[arg(skip)]
    pub clamp_frames: bool,
}

/// The chunk file written next to an output limited to `--frames`.
pub fn chunk_path(output: &Path) -> PathBuf {
    output.with_extension("furrow-chunk")
}

/// Refuse early (before minutes of simulation) when an output exists and `--force` is absent.
fn preflight(paths: &[&Path], force: bool) -> anyhow::Result<()> {
    atomic::check_free(paths, Overwrite::from_force(force))
}

/// The settings that decide a run's result, hashed to tie chunks to one run.
fn settings_hash(scene: &Scene, fps: f64, a: &AnimateArgs, scale: f64) -> String {
    let mesh = &a.mesh;
    let mut v = serde_json::json!({ "scene": scene, "fps": fps, "mesh": mesh, "scale": scale });
    if let Some(skin) = &a.skin_primitives {
        v["skin_primitives"] = serde_json::json!(skin);
    }
    chunk::fnv64(v.to_string().as_bytes())
}

/// What `animate_one` produced.
pub struct Animated {
    /// The pipeline's output.
    pub run: RunOutput,
    /// Files written.
    pub files: Vec<PathBuf>,
}

/// Load, run and write one rig (shared by `animate`, `batch` and `demo`).
pub fn animate_one(a: &AnimateArgs, out: &Output) -> anyhow::Result<Animated> {
    let t0 = Instant::now();
    let scene = checked_scene(a)?;
    let chunk_file = chunk_path(&a.output);
    let mut outputs: Vec<&Path> = vec![&a.output];
    let write_chunk = a.frames.is_some() && !a.no_chunk;
    if write_chunk {
        outputs.push(&chunk_file);
    }
    if let Some(r) = &a.report {
        outputs.push(r);
    }
    preflight(&outputs, a.force)?;
    let bytes = std::fs::read(&a.rig)
        .with_context(|| format!("{}: cannot read the rig", a.rig.display()))?;
    let mut rig = fio::load::load_bytes(&a.rig, &bytes, &load_options(a, &scene))?;
    out.note(&rig.face_reason);
    if rig.parts.parts.len() > 1 {
        out.note(rig.parts.summary());
    }
    out.note(crate::io::units::apply(&mut rig, a.scale, scene.rig.scale));
    let count = crate::pipeline::plan::clip_weights(&rig, a.fps).0.len();
    let frames = frame_range(a, count)?;
    let opts = RunOptions {
        scene: scene.clone(),
        scene_path: a.scene.as_ref().map(|p| p.display().to_string()),
        fps: a.fps,
        frames,
        preroll: a.preroll,
    };
    let pb = out.progress(count as u64, "simulating");
    let run = pipeline::run(&rig, &opts, &|phase, done, _total| {
        if phase == pipeline::Phase::Frames {
            pb.set_position(done as u64);
        }
    })?;
    pb.finish_and_clear();
    if let Some(o) = &run.report.out_of_model {
        o.summary().iter().for_each(|l| out.note(l));
    }
    for w in &run.report.warnings {
        out.note(format!("warning: {w}"));
    }
    let mut files = Vec::new();
    let t = Instant::now();
    let first = frames.map_or(0, |r| r.start);
    let written = Frames {
        map: &run.face_map,
        frames: &run.frames,
        weights: &run.weights,
        clip: Clip::of(run.animated, a.fps, first, count),
        triangles: &run.triangles,
        origin: &run.origin,
        fps: a.fps,
    };
    let layer_report = out_file::write(
        &rig,
        &written,
        &a.export,
        &a.output,
        Overwrite::from_force(a.force),
    )?;
    files.push(a.output.clone());
    if let Some(range) = frames.filter(|_| write_chunk) {
        write_chunk_file(a, &bytes, &scene, &rig, (range, count), &run, &chunk_file)?;
        files.push(chunk_file.clone());
    }
    if let Some(dir) = &a.frames_dir {
        let set = export::FrameSet {
            triangles: &run.triangles,
            frames: &run.frames,
            origin: &run.origin,
            fps: a.fps,
            weights: &run.weights,
        };
        let pb = out.progress(run.frames.len() as u64, "frames");
        files.extend(export::write_frames_dir(
            &rig,
            &set,
            dir,
            Overwrite::from_force(a.force),
            &|_| pb.inc(1),
        )?);
        pb.finish_and_clear();
    }
    let export_ms = t.elapsed().as_secs_f64() * 1e3;
    let mut run = run;
    run.report.export = layer_report;
    run.report.totals.export_ms = export_ms;
    run.report.totals.wall_s = t0.elapsed().as_secs_f64();
    if let Some(dir) = &a.preview {
        files.extend(crate::pipeline::preview::write_previews(
            &run,
            dir,
            Overwrite::from_force(a.force),
        )?);
    }
    if let Some(r) = &a.report {
        let json = serde_json::to_vec_pretty(&run.report)?;
        atomic::write(r, &json, Overwrite::from_force(a.force))?;
        files.push(r.clone());
    }
    Ok(Animated { run, files })
}

/// The scene of `--scene` (or the default), after the arguments that need no rig are checked.
fn checked_scene(a: &AnimateArgs) -> anyhow::Result<Scene> {
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0) {
        bail!("--fps must lie in (0, 1000], got {}", a.fps);
    }
    let scene = match &a.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default(),
    };
    scene.validate()?;
    a.export.check()?;
    if a.output.extension().and_then(|e| e.to_str()) != Some("glb") {
        bail!("{}: the output must be a .glb file", a.output.display());
    }
    Ok(scene)
}

/// How the rig of `a` loads: the flags first, then the scene's `[rig]` keys.
fn load_options(a: &AnimateArgs, scene: &Scene) -> LoadOptions {
    rig_load_options(&a.mesh, &a.skin_primitives, scene, a.paths)
}

/// How a rig loads for a subcommand: its `--mesh`, its `--skin-primitives` (else the scene's
/// `[rig] skin_primitives`) and its `--allow-outside-paths`.
pub fn rig_load_options(
    mesh: &Option<String>,
    skin_primitives: &Option<Vec<crate::io::parts::PrimitivePick>>,
    scene: &Scene,
    paths: super::RigPathsArgs,
) -> LoadOptions {
    LoadOptions {
        mesh: mesh.clone(),
        animation: None,
        skin_primitives: skin_primitives
            .clone()
            .or_else(|| scene.rig.skin_primitives.clone()),
        allow_outside_paths: paths.allow_outside_paths,
    }
}

/// The `--frames` range of a clip of `count` frames (clamped to the clip with
/// `--clamp-frames`).
fn frame_range(a: &AnimateArgs, count: usize) -> anyhow::Result<Option<FrameRange>> {
    Ok(match &a.frames {
        Some(t) if a.clamp_frames => {
            let (start, end) = t.split_once(':').unwrap_or((t, ""));
            let end = end.trim().parse::<usize>().map_or(count, |e| e.min(count));
            Some(FrameRange::parse(&format!("{start}:{end}"), count)?)
        }
        Some(t) => Some(FrameRange::parse(t, count)?),
        None => None,
    })
}

/// Write the chunk file of a `--frames` run: the frames of `range` in a clip of `count`,
/// with what `merge` needs to join chunks and check they belong together.
fn write_chunk_file(
    a: &AnimateArgs,
    bytes: &[u8],
    scene: &Scene,
    rig: &fio::load::Rig,
    (range, count): (FrameRange, usize),
    run: &pipeline::RunOutput,
    chunk_file: &Path,
) -> anyhow::Result<()> {
    let header = ChunkHeader {
        rig_hash: chunk::fnv64(bytes),
        settings_hash: settings_hash(scene, a.fps, a, rig.scale.metres_per_unit),
        fps: a.fps,
        range,
        clip_frames: count,
        vertices: run.origin.len(),
        triangles: run.triangles.clone(),
        origin: chunk::origin_to_plain(&run.origin),
        metres_per_unit: rig.scale.metres_per_unit,
        face_map: run.face_map.clone(),
        preroll: a.preroll,
        wavelength_m: run.report.wavelength_m,
        offsets: true,
    };
    let offsets: Vec<Vec<_>> = run
        .frames
        .iter()
        .zip(&run.smooth)
        .map(|(f, s)| f.iter().zip(s).map(|(p, q)| p - q).collect())
        .collect();
    chunk::write(
        chunk_file,
        &header,
        &run.frames,
        &offsets,
        Overwrite::from_force(a.force),
    )?;
    Ok(())
}

/// Run `furrow animate`.
pub fn run(a: AnimateArgs, out: &Output) -> anyhow::Result<()> {
    let done = animate_one(&a, out)?;
    let rep = &done.run.report;
    out.json_result(&serde_json::json!({
        "ok": true, "output": a.output, "files": done.files, "frames": rep.frames,
        "wavelength_m": rep.wavelength_m, "totals": rep.totals, "stages": rep.stages,
    }));
    say_summary(out, &done);
    Ok(())
}

/// Print what a run did and where its files went.
pub fn say_summary(out: &Output, done: &Animated) {
    let rep = &done.run.report;
    out.say(format!(
        "{} frames of '{}' in {:.1} s (λ = {:.1} mm; shell {:.1} s, interior {:.1} s)",
        rep.totals.frames_written,
        rep.face,
        rep.totals.wall_s,
        rep.wavelength_m * 1e3,
        rep.totals.shell_ms / 1e3,
        rep.totals.interior_ms / 1e3
    ));
    for s in &rep.stages {
        out.say(format!("  {:<10} {:<8} {}", s.stage, s.status, s.why));
    }
    if let Some(e) = &rep.export {
        out_file::say(out, e);
    }
    for f in &done.files {
        out.say(format!("  wrote {}", f.display()));
    }
}

/// Arguments of `furrow batch`.
#[derive(Debug, clap::Args)]
pub struct BatchArgs {
    /// Rigs to process.
    #[arg(required = true)]
    pub inputs: Vec<PathBuf>,
    /// Output folder: NAME.glb and NAME.report.json per input (the report marks it finished).
    #[arg(short, long)]
    pub output: PathBuf,
    /// Scene file for every input.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Frames to write, `A:B`.
    #[arg(long)]
    pub frames: Option<String>,
    /// Frames per second.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Metres per unit of every rig file, or `auto` (default; see `animate --scale`).
    #[arg(long, value_parser = crate::io::units::scale_arg)]
    pub scale: Option<crate::io::units::ScaleSetting>,
    /// Redo inputs whose outputs are finished.
    #[arg(long)]
    pub force: bool,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// The outputs' form and storage.
    #[command(flatten)]
    pub export: ExportArgs,
}

/// Run `furrow batch`: every input in turn; a failure is reported and the rest go on; finished
/// outputs (their report exists) are skipped on a rerun.
pub fn batch(a: BatchArgs, out: &Output) -> anyhow::Result<()> {
    let mut results = Vec::new();
    let mut failed = 0;
    let mut seen = std::collections::HashSet::new();
    for input in &a.inputs {
        let stem = input
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or("rig")
            .to_string();
        if !seen.insert(stem.clone()) {
            failed += 1;
            out.note(format!(
                "{}: skipped: another input has the same name {stem}",
                input.display()
            ));
            results.push(serde_json::json!({ "input": input, "status": "failed", "error": format!("duplicate output name {stem}") }));
            continue;
        }
        let glb = a.output.join(format!("{stem}.glb"));
        let report = a.output.join(format!("{stem}.report.json"));
        if !a.force && report.exists() && glb.exists() {
            out.say(format!("{}: finished earlier, skipped", input.display()));
            results.push(serde_json::json!({ "input": input, "status": "skipped", "output": glb }));
            continue;
        }
        let args = AnimateArgs {
            rig: input.clone(),
            output: glb.clone(),
            export: a.export.clone(),
            scene: a.scene.clone(),
            frames: a.frames.clone(),
            preroll: None,
            fps: a.fps,
            frames_dir: None,
            report: Some(report.clone()),
            preview: None,
            mesh: None,
            skin_primitives: None,
            scale: a.scale,
            // An output without its report is an unfinished earlier attempt: redo it.
            force: true,
            paths: a.paths,
            no_chunk: false,
            clamp_frames: false,
        };
        match animate_one(&args, out) {
            Ok(done) => {
                out.say(format!(
                    "{}: {} frames → {}",
                    input.display(),
                    done.run.report.totals.frames_written,
                    glb.display()
                ));
                results
                    .push(serde_json::json!({ "input": input, "status": "done", "output": glb }));
            }
            Err(e) => {
                failed += 1;
                out.note(format!("furrow: {}: failed: {e:#}", input.display()));
                results.push(serde_json::json!({ "input": input, "status": "failed", "error": format!("{e:#}") }));
            }
        }
    }
    out.json_result(&serde_json::json!({ "ok": failed == 0, "results": results }));
    if failed > 0 {
        return Err(super::AlreadyReported(format!(
            "{failed} of {} inputs failed (the others are done)",
            a.inputs.len()
        ))
        .into());
    }
    Ok(())
}
