//! How `animate`, `demo`, `batch` and `merge` write their frames: the wrinkle layer (the
//! default: the rig kept, plus wrinkle targets) or the frame sequence (one morph target per
//! frame), quantized or float, compressed or not.

use super::Output;
use crate::io::atomic::{self, Overwrite};
use crate::io::export::{self, FrameSet};
use crate::io::layer::{self, LayerOptions, Precision};
use crate::io::load::Rig;
use crate::io::origin::VertexOrigin;
use crate::io::split::FaceMap;
use crate::pipeline::layer::{self as wl, Clip, LayerInput, LayerReport};
use anyhow::bail;
use nalgebra::Vector3;
use std::path::Path;

/// What the output file holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, clap::ValueEnum)]
pub enum ExportForm {
    /// The rig as its artist made it (primitives, materials, UV seams, blend shapes and their
    /// animation) on the refined skin, plus wrinkle targets: modes of the clip's wrinkles in
    /// the rig's weights channel, or for a still rig one corrective per shape.
    #[default]
    Layer,
    /// One morph target per frame and a weights animation showing frame k at k / fps (the
    /// face welded into one primitive).
    Sequence,
}

/// The export flags.
#[derive(Debug, Clone, Default, clap::Args)]
pub struct ExportArgs {
    /// What the file holds: `layer` (the rig kept plus wrinkle targets) or `sequence` (one
    /// morph target per frame).
    #[arg(long, value_enum, default_value_t = ExportForm::Layer)]
    pub export: ExportForm,
    /// Compress the layer with EXT_meshopt_compression (web viewers decode it; Blender 3.4
    /// does not).
    #[arg(long)]
    pub compress: bool,
    /// Write the layer with float accessors only (no KHR_mesh_quantization): exact, larger,
    /// for engines without the extension.
    #[arg(long)]
    pub float: bool,
}

impl ExportArgs {
    /// Refuse flags that do not apply to the chosen form.
    pub fn check(&self) -> anyhow::Result<()> {
        if self.export == ExportForm::Sequence && (self.compress || self.float) {
            bail!("--compress and --float apply to the wrinkle layer; `--export sequence` is written as float glTF");
        }
        Ok(())
    }
}

/// The written frames and what they came from.
pub struct Frames<'a> {
    /// How the refined skin maps onto the loaded face.
    pub map: &'a FaceMap,
    /// The wrinkled surface per written frame (world, m as simulated).
    pub frames: &'a [Vec<Vector3<f64>>],
    /// The rig's weights per written frame.
    pub weights: &'a [Vec<f64>],
    /// The clip (animated, or a still rig's shapes).
    pub clip: Clip,
    /// The sequence form's triangles and vertex origins (the welded, refined skin).
    pub triangles: &'a [[usize; 3]],
    /// Origin of each vertex of the sequence form.
    pub origin: &'a [VertexOrigin],
    /// Frames per second.
    pub fps: f64,
}

/// Write `frames` of `rig` to `output` in the form `args` asks for; returns the layer's
/// report (none for the sequence form).
pub fn write(
    rig: &Rig,
    frames: &Frames,
    args: &ExportArgs,
    output: &Path,
    overwrite: Overwrite,
) -> anyhow::Result<Option<LayerReport>> {
    args.check()?;
    if args.export == ExportForm::Sequence {
        let set = FrameSet {
            triangles: frames.triangles,
            frames: frames.frames,
            origin: frames.origin,
            fps: frames.fps,
            weights: frames.weights,
        };
        export::write_animated(rig, &set, output, overwrite)?;
        return Ok(None);
    }
    if frames.map.triangles.is_empty() {
        bail!("these frames carry no skin map (chunks from an older furrow): use `--export sequence`, or run the chunks again");
    }
    let input = LayerInput {
        rig,
        map: frames.map,
        frames: frames.frames,
        weights: frames.weights,
        clip: frames.clip,
    };
    let mut built = wl::build(&input)?;
    let opts = LayerOptions {
        precision: if args.float {
            Precision::Float
        } else {
            Precision::Quantized
        },
        compress: args.compress,
    };
    let written = layer::layer_glb(rig, frames.map, &built.layer, opts)?;
    wl::check_file(rig, &mut built, &written, frames.frames)?;
    let mut report = built.report;
    if let Some(f) = report.file.as_mut() {
        f.precision = if args.float { "float" } else { "quantized" }.into();
        f.compressed = args.compress;
    }
    let (weights_notes, other): (Vec<String>, Vec<String>) = written
        .notes
        .into_iter()
        .partition(|n| n.contains("weights channel"));
    report.weights = weights_notes.into_iter().next();
    report.notes.extend(other);
    atomic::write(output, &written.bytes, overwrite)?;
    Ok(Some(report))
}

/// Say what the layer holds and how well it reproduces the frames.
pub fn say(out: &Output, r: &LayerReport) {
    let pct = |x: f64| 100.0 * x;
    let bound = match r.bound.as_str() {
        "error" => format!("the {:.0} % error bound", pct(wl::LAYER_TOLERANCE)),
        "target_cap" => format!("the {}-target cap", wl::MAX_TARGETS),
        "rank" => "every mode the clip has".into(),
        "one_per_shape" => "one per wrinkling shape".into(),
        _ => "no wrinkles".into(),
    };
    out.say(format!(
        "  {}: {} rig targets + {} wrinkle targets (decided by {bound}); wrinkle depth {:.3} mm, basis error {:.4} mm ({:.2} %), normals {:.2}° RMS, {:.1}° max",
        r.form,
        r.rig_targets,
        r.wrinkle_targets,
        r.wrinkle_depth_m * 1e3,
        r.basis_error_m * 1e3,
        pct(r.basis_error_of_depth),
        r.normal_error.rms_deg,
        r.normal_error.max_deg
    ));
    if let Some(f) = &r.file {
        out.say(format!(
            "  file {:.2} MB ({}{}): read back, {:.4} mm from the layer ({:.3} % of the depth), {:.4} mm from the frame sequence ({:.2} %)",
            f.bytes as f64 / 1e6,
            f.precision,
            if f.compressed { ", meshopt" } else { "" },
            f.decoded_error_m * 1e3,
            pct(f.decoded_error_of_depth),
            f.total_error_m * 1e3,
            pct(f.total_error_of_depth)
        ));
    }
    for n in r.weights.iter().chain(&r.notes) {
        out.note(format!("note: {n}"));
    }
}
