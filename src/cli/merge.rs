//! `furrow merge`: chunks of `furrow animate --frames A:B` joined into the file an unsplit
//! run writes, with a report of each seam: exact chunks join byte-identically, pre-rolled
//! ones cross-fade over their overlap and the report measures how far the neighbours
//! disagree there (and, given an unsplit run's chunk, how far the merge is from it).

use super::animate::{chunk_path, rig_load_options};
use super::export::{self as out_file, ExportArgs, Frames};
use super::Output;
use crate::io as fio;
use crate::io::atomic::{self, Overwrite};
use crate::io::units::ScaleSetting;
use crate::pipeline::chunk::{self, Chunk, Joined, Seam};
use crate::pipeline::frames::FrameRange;
use crate::pipeline::layer::Clip;
use crate::scene::Scene;
use crate::studies::tradeoff::{amplitude_error, AmplitudeMap};
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Arguments of `furrow merge`.
#[derive(Debug, clap::Args)]
pub struct MergeArgs {
    /// Chunk outputs of `furrow animate --frames A:B` (their .glb or .furrow-chunk files).
    #[arg(required = true)]
    pub chunks: Vec<PathBuf>,
    /// The rig the chunks were made from.
    #[arg(long)]
    pub rig: PathBuf,
    /// The merged glTF.
    #[arg(short, long)]
    pub output: PathBuf,
    /// The face mesh, as given to `animate --mesh`.
    #[arg(long)]
    pub mesh: Option<String>,
    /// The face's skin primitives, as given to `animate --skin-primitives`.
    #[arg(long, value_parser = crate::io::parts::parse_picks)]
    pub skin_primitives: Option<Vec<crate::io::parts::PrimitivePick>>,
    /// An unsplit run's chunk (`furrow animate RIG --frames 0:N`) to measure the merge
    /// against: the report gives each seam's and the whole merge's amplitude error.
    #[arg(long)]
    pub reference: Option<PathBuf>,
    /// Replace an existing output.
    #[arg(long)]
    pub force: bool,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// The output's form and storage (the layer's basis is built over the joined frames).
    #[command(flatten)]
    pub export: ExportArgs,
    /// Write the merge's report (JSON: the seams, the export's wrinkle targets, errors and
    /// file size) here.
    #[arg(long)]
    pub report: Option<PathBuf>,
}

/// One seam of a merge in the report.
#[derive(Debug, Clone, Serialize)]
pub struct SeamReport {
    /// The earlier chunk's file.
    pub before: String,
    /// The later chunk's file.
    pub after: String,
    /// The frames both wrote, [start, end) (empty: they only touch).
    pub overlap: [usize; 2],
    /// The phase-free amplitude error (`studies::tradeoff::amplitude_error`, 2λ regions) of
    /// the later chunk's frames against the earlier's over the overlap; absent without one.
    pub neighbours_error: Option<f64>,
    /// The same of the merged frames around the seam (the overlap, or the later chunk's
    /// first frame) against the reference run; absent without `--reference`.
    pub reference_error: Option<f64>,
}

/// What `furrow merge --report` writes.
#[derive(Debug, Clone, Serialize)]
pub struct MergeReport {
    /// The frames merged, [start, end).
    pub frames: [usize; 2],
    /// Each chunk's pre-roll (frames simulated from rest before its first), or absent for
    /// exact chunks.
    pub preroll: Option<usize>,
    /// Each pair of neighbouring chunks, in order.
    pub seams: Vec<SeamReport>,
    /// The amplitude error of every merged frame against the reference run.
    pub reference_error: Option<f64>,
    /// The export's report (the wrinkle layer's targets, errors and size).
    pub export: Option<crate::pipeline::layer::LayerReport>,
}

/// Run `furrow merge`.
pub fn merge(a: MergeArgs, out: &Output) -> anyhow::Result<()> {
    a.export.check()?;
    let mut outputs: Vec<&Path> = vec![&a.output];
    if let Some(r) = &a.report {
        outputs.push(r);
    }
    atomic::check_free(&outputs, Overwrite::from_force(a.force))?;
    let mut chunks = Vec::new();
    for p in &a.chunks {
        let cp = chunk_file(p);
        chunks.push((cp.display().to_string(), chunk::read(&cp)?));
    }
    let joined = chunk::join(chunks)?;
    let reference = match &a.reference {
        Some(p) => Some(reference_chunk(&chunk_file(p), &joined.chunk)?),
        None => None,
    };
    let bytes = std::fs::read(&a.rig)
        .with_context(|| format!("{}: cannot read the rig", a.rig.display()))?;
    let whole = &joined.chunk;
    if chunk::fnv64(&bytes) != whole.header.rig_hash {
        bail!(
            "{}: the chunks were made from another rig file",
            a.rig.display()
        );
    }
    let load = rig_load_options(&a.mesh, &a.skin_primitives, &Scene::default(), a.paths);
    let mut rig = fio::load::load_bytes(&a.rig, &bytes, &load)?;
    // The frames are in the metres they were simulated in: write them back in file units.
    let m = whole.header.metres_per_unit;
    crate::io::units::apply(
        &mut rig,
        Some(ScaleSetting::metres(m, "the chunks' scale")?),
        None,
    );
    let origin = chunk::origin_from_plain(&whole.header.origin);
    if origin
        .iter()
        .any(|o| o.vertices.iter().any(|&v| v >= rig.face().positions.len()))
    {
        bail!(
            "{}: the chunks' face does not match this rig's face (pass the same --mesh)",
            a.rig.display()
        );
    }
    let h = &whole.header;
    let r = h.range;
    let (weights, animated) = crate::pipeline::plan::clip_weights(&rig, h.fps);
    if weights.len() != h.clip_frames {
        bail!(
            "{}: the chunks' clip has {} frames at {} fps, this rig's {}",
            a.rig.display(),
            h.clip_frames,
            h.fps,
            weights.len()
        );
    }
    let written = Frames {
        map: &h.face_map,
        frames: &whole.frames,
        weights: &weights[r.start..r.end],
        clip: Clip::of(animated, h.fps, r.start, h.clip_frames),
        triangles: &h.triangles,
        origin: &origin,
        fps: h.fps,
    };
    let export = out_file::write(
        &rig,
        &written,
        &a.export,
        &a.output,
        Overwrite::from_force(a.force),
    )?;
    let report = merge_report(&joined, reference.as_ref(), export);
    if let Some(path) = &a.report {
        let json = serde_json::to_vec_pretty(&report)?;
        atomic::write(path, &json, Overwrite::from_force(a.force))?;
    }
    say(out, &a, &report, h.clip_frames);
    Ok(())
}

/// The chunk file of `p` (a chunk's .glb names the chunk beside it).
fn chunk_file(p: &Path) -> PathBuf {
    if p.extension().and_then(|e| e.to_str()) == Some("furrow-chunk") {
        p.to_path_buf()
    } else {
        chunk_path(p)
    }
}

/// The reference run's chunk at `path`, refused unless it is of the same run as `whole` and
/// covers its frames.
fn reference_chunk(path: &Path, whole: &Chunk) -> anyhow::Result<Chunk> {
    let c = chunk::read(path)?;
    let (h, w) = (&c.header, &whole.header);
    chunk::same_run(
        w,
        "the chunks",
        h,
        &format!("{} (the reference)", path.display()),
    )?;
    if h.range.start > w.range.start || h.range.end < w.range.end {
        bail!(
            "{}: the reference covers frames {}:{}, the chunks {}:{}",
            path.display(),
            h.range.start,
            h.range.end,
            w.range.start,
            w.range.end
        );
    }
    if !h.offsets || !w.offsets {
        bail!(
            "{}: the reference and the chunks must carry their wrinkle offsets",
            path.display()
        );
    }
    Ok(c)
}

/// The merge's report: each seam's and the whole merge's amplitude errors.
fn merge_report(
    joined: &Joined,
    reference: Option<&Chunk>,
    export: Option<crate::pipeline::layer::LayerReport>,
) -> MergeReport {
    let whole = &joined.chunk;
    let smooth = whole.smooth();
    let region = 2.0 * whole.header.wavelength_m;
    let map = |frames: &[Vec<Vector3<f64>>], at: FrameRange| {
        let s = smooth.as_ref()?;
        let from = at.start - whole.header.range.start;
        let s = &s[from..from + frames.len()];
        (region > 0.0).then(|| AmplitudeMap::new(frames, s, &whole.header.triangles, region))
    };
    let merged = |at: FrameRange| {
        let from = at.start - whole.header.range.start;
        &whole.frames[from..from + at.len()]
    };
    let against_reference = |at: FrameRange| {
        let c = reference?;
        let from = at.start - c.header.range.start;
        let run = map(merged(at), at)?;
        let truth = map(&c.frames[from..from + at.len()], at)?;
        Some(amplitude_error(&run, &truth))
    };
    let seams = joined
        .seams
        .iter()
        .map(|s: &Seam| {
            let window = if s.overlap.is_empty() {
                FrameRange {
                    start: s.overlap.start,
                    end: s.overlap.start + 1,
                }
            } else {
                s.overlap
            };
            let neighbours = (!s.overlap.is_empty())
                .then(|| {
                    Some(amplitude_error(
                        &map(&s.after_frames, s.overlap)?,
                        &map(&s.before_frames, s.overlap)?,
                    ))
                })
                .flatten();
            SeamReport {
                before: s.before.clone(),
                after: s.after.clone(),
                overlap: [s.overlap.start, s.overlap.end],
                neighbours_error: neighbours,
                reference_error: against_reference(window),
            }
        })
        .collect();
    MergeReport {
        frames: [whole.header.range.start, whole.header.range.end],
        preroll: whole.header.preroll,
        seams,
        reference_error: against_reference(whole.header.range),
        export,
    }
}

/// Tell what the merge did.
fn say(out: &Output, a: &MergeArgs, report: &MergeReport, clip_frames: usize) {
    let [start, end] = report.frames;
    out.json_result(&serde_json::json!({ "ok": true, "output": a.output, "report": report }));
    out.say(format!(
        "merged frames {start}:{end} of {} chunks into {}",
        a.chunks.len(),
        a.output.display()
    ));
    for s in &report.seams {
        let pct = |e: Option<f64>| e.map_or("–".to_string(), |e| format!("{:.1} %", 100.0 * e));
        if s.neighbours_error.is_some() || s.reference_error.is_some() {
            out.say(format!(
                "  seam at frames {}:{}: neighbours differ by {}, the merge from the reference by {}",
                s.overlap[0],
                s.overlap[1],
                pct(s.neighbours_error),
                pct(s.reference_error)
            ));
        }
    }
    if let Some(e) = report.reference_error {
        out.say(format!(
            "  the merge differs from the reference by {:.1} % (amplitude error)",
            100.0 * e
        ));
    }
    if let Some(rep) = &report.export {
        out_file::say(out, rep);
    }
    if start != 0 || end != clip_frames {
        out.note(format!(
            "note: the chunks cover frames {start}:{end} of a {clip_frames}-frame clip"
        ));
    }
}
