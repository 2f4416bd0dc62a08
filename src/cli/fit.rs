//! `furrow fit`: muscle activations per frame of a rig's blend-shape animation (CSV).

use super::Output;
use crate::fem::{Interior, Material};
use crate::io::atomic::{self, Overwrite};
use crate::io::mesh::MeshInstance;
use crate::io::{self as fio, LoadOptions, Rig};
use crate::lattice::{Lattice, LatticeSettings};
use crate::mesh::TriMesh;
use crate::muscle::jaw::{Hinge, JawBone};
use crate::muscle::{
    self, fit::Calibration, FitSettings, Fitter, FrameStatus, GenerateSettings, Muscle,
};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `furrow fit`.
#[derive(Debug, clap::Args)]
pub struct FitArgs {
    /// The rig: glTF/GLB with blend shapes (and a weights animation; without one, the
    /// default weights make one frame).
    pub rig: PathBuf,
    /// Frames to fit as A:B (from A inclusive to B exclusive, 0-based; either may be left
    /// out: `10:`, `:50`).
    #[arg(long)]
    pub frames: Option<String>,
    /// Output CSV: one row per frame with the activations and the RMS residual (m).
    #[arg(short, long, default_value = "activations.csv")]
    pub output: PathBuf,
    /// Replace the output if it exists.
    #[arg(long)]
    pub force: bool,
    /// Muscle rig file (TOML); without it, one muscle per blend shape is generated.
    #[arg(long)]
    pub muscles: Option<PathBuf>,
    /// Frames per second at which the animation is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Lattice cell size (m); default: about 500 cells over the face.
    #[arg(long)]
    pub cell_size: Option<f64>,
    /// Gauss–Newton re-linearisations per frame with the nonlinear forward model.
    #[arg(long, default_value_t = 0)]
    pub gauss_newton: usize,
    /// Also write a PNG of the activations over time (and the fit residual).
    #[arg(long)]
    pub plot: Option<PathBuf>,
    /// Metres per unit of the rig file, or `auto` (default; see `animate --scale`); the
    /// residuals and `--cell-size` are in simulated metres.
    #[arg(long, value_parser = crate::io::units::scale_arg)]
    pub scale: Option<crate::io::units::ScaleSetting>,
}

/// Parse `A:B` against `n` frames into a range; the error names `--frames`.
fn frame_range(spec: Option<&str>, n: usize) -> anyhow::Result<std::ops::Range<usize>> {
    let Some(s) = spec else {
        return Ok(0..n);
    };
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| anyhow::anyhow!("--frames must look like A:B (e.g. 0:100), got {s:?}"))?;
    let parse = |x: &str, default: usize| -> anyhow::Result<usize> {
        if x.trim().is_empty() {
            Ok(default)
        } else {
            x.trim().parse::<usize>().map_err(|_| {
                anyhow::anyhow!("--frames: {x:?} is not a frame number (0-based, ≥ 0)")
            })
        }
    };
    let (a, b) = (parse(a, 0)?, parse(b, n)?);
    anyhow::ensure!(
        a <= b && b <= n,
        "--frames {s}: the animation has {n} frames at this fps (valid: 0 ≤ A ≤ B ≤ {n})"
    );
    Ok(a..b)
}

fn csv_field(s: &str) -> String {
    if s.contains([',', '"', '\n']) {
        format!("\"{}\"", s.replace('"', "\"\""))
    } else {
        s.to_string()
    }
}

/// Run `furrow fit`.
pub fn run(a: FitArgs, out: &Output) -> anyhow::Result<()> {
    check_args(&a)?;
    let outputs: Vec<&PathBuf> = std::iter::once(&a.output).chain(a.plot.as_ref()).collect();
    atomic::check_free(&outputs, Overwrite::from_force(a.force))?;
    let t0 = Instant::now();
    let mut rig = fio::load(&a.rig, &LoadOptions::default())?;
    out.note(&rig.face_reason);
    out.note(crate::io::units::apply(&mut rig, a.scale, None));
    let face = rig.face();
    let mesh = TriMesh::new(face.positions.clone(), face.triangles.clone());
    let lattice = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: a.cell_size,
            ..Default::default()
        },
    )?;
    let material = Material::default();
    let MuscleRig {
        muscles,
        origin,
        bone,
        hinge,
        calibration,
    } = muscle_rig(a.muscles.as_deref(), &lattice, &mesh, &material, face, out)?;
    anyhow::ensure!(
        !muscles.is_empty(),
        "{}: no muscles (every blend shape is empty); give a muscle file with --muscles",
        a.rig.display()
    );
    let settings = FitSettings {
        gauss_newton: a.gauss_newton,
        ..Default::default()
    };
    let mut fitter = Fitter::coupled(
        &lattice,
        &material,
        muscles,
        settings,
        None,
        calibration,
        bone,
    )?;
    let weights = rig.frame_weights(a.fps);
    let range = frame_range(a.frames.as_deref(), weights.len())?;
    let names: Vec<String> = fitter.muscles().iter().map(|m| m.name.clone()).collect();
    let pb = out.progress(range.len() as u64, "fitting");
    let fits = fit_frames(
        &mut fitter,
        &rig,
        &weights,
        range.clone(),
        a.fps,
        &names,
        &|| pb.inc(1),
    )?;
    pb.finish_and_clear();
    atomic::write(
        &a.output,
        fits.csv.as_bytes(),
        if a.force {
            Overwrite::Replace
        } else {
            Overwrite::Refuse
        },
    )?;
    if let Some(p) = &a.plot {
        plot_activations(p, &a.rig, &names, fits.curves)?;
    }
    let nf = range.len();
    let mean = if nf > 0 {
        fits.rms_sum / nf as f64
    } else {
        0.0
    };
    let secs = t0.elapsed().as_secs_f64();
    out.json_result(&serde_json::json!({
        "ok": true, "rig": a.rig, "output": a.output, "frames": nf,
        "first_frame": range.start, "fps": a.fps,
        "elements": lattice.elements.len(), "muscles": names, "muscle_origin": origin,
        "gauss_newton": a.gauss_newton,
        "rms_residual_mean_m": mean, "rms_residual_max_m": fits.rms_max,
        "frames_not_fitted": fits.not_fitted.iter().map(|(k, s)| serde_json::json!({"frame": k, "status": format!("{s:?}")})).collect::<Vec<_>>(),
        "jacobian_s": fitter.jacobian_s, "qp_s": fits.qp_s, "seconds": secs,
        "jaw": jaw_json(&fitter, &names, hinge.as_ref()),
    }));
    out.say(format!(
        "{nf} frames of '{}' fitted with {} muscles ({origin}) on {} lattice elements in {secs:.2} s",
        face.name,
        names.len(),
        lattice.elements.len()
    ));
    out.say(format!(
        "  RMS residual mean {:.3} mm, max {:.3} mm; wrote {}",
        mean * 1e3,
        fits.rms_max * 1e3,
        a.output.display()
    ));
    for (k, s) in &fits.not_fitted {
        out.note(format!("frame {k}: {s:?}"));
    }
    Ok(())
}

/// Refuse out-of-range `--fps`, `--cell-size` and `--gauss-newton`.
fn check_args(a: &FitArgs) -> anyhow::Result<()> {
    anyhow::ensure!(
        a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0,
        "--fps must be in (0, 1000], got {}",
        a.fps
    );
    if let Some(h) = a.cell_size {
        anyhow::ensure!(
            h.is_finite() && h > 0.0,
            "--cell-size must be a positive length in metres, got {h}"
        );
    }
    anyhow::ensure!(
        a.gauss_newton <= 50,
        "--gauss-newton must be at most 50, got {}",
        a.gauss_newton
    );
    Ok(())
}

/// The jaw's bone in the JSON result: the muscle that turns it, its nodes and the hinge's
/// angle at activation 1 (degrees) and fit residual; null without one.
fn jaw_json(fitter: &Fitter, names: &[String], hinge: Option<&Hinge>) -> serde_json::Value {
    match (&fitter.forward.bone, hinge) {
        (Some((m, bone)), Some(h)) => serde_json::json!({
            "muscle": names[*m], "bone_nodes": bone.nodes.len(),
            "angle_deg": h.angle_deg, "hinge_residual": h.residual,
        }),
        _ => serde_json::Value::Null,
    }
}

/// The muscles `furrow fit` fits.
struct MuscleRig {
    muscles: Vec<Muscle>,
    /// Where they came from, for the summary.
    origin: String,
    /// The jaw's bone and the muscle that turns it.
    bone: Option<(usize, JawBone)>,
    /// The hinge the bone turns about.
    hinge: Option<Hinge>,
    /// Generated muscles' responses at activation 1 (the bone's turn included): the rest
    /// J's columns, as `animate` uses them.
    calibration: Option<Calibration>,
}

/// The muscles to fit: read from the rig file `file` (no bone), or one generated per blend
/// shape of `face` (saying which make none), the jaw-opening shape's turning the bone about
/// its fitted hinge as `animate`'s generated muscles do.
fn muscle_rig(
    file: Option<&Path>,
    lattice: &Lattice,
    mesh: &TriMesh,
    material: &Material,
    face: &MeshInstance,
    out: &Output,
) -> anyhow::Result<MuscleRig> {
    Ok(match file {
        Some(p) => MuscleRig {
            muscles: muscle::rigfile::load(p, lattice, mesh)?,
            origin: format!("from {}", p.display()),
            bone: None,
            hinge: None,
            calibration: None,
        },
        None => {
            let interior = Interior::new(lattice, material)?;
            let jaw = JawBone::find(lattice, &face.positions, &face.targets);
            let g = muscle::generate::generate_muscles_with_skin(
                lattice,
                &interior,
                &face.targets,
                None,
                &GenerateSettings::default(),
                None,
                jaw.as_ref().map(|j| &j.0),
            )?;
            for (name, why) in &g.skipped {
                out.note(format!("blend shape '{name}' makes no muscle: {why}"));
            }
            let (bone, hinge) = g.jaw(jaw).map(|((m, bone), hinge)| {
                out.note(format!(
                    "jaw: muscle '{}' turns {} bone nodes by {:.2}° about the hinge fitted to its shape (residual {:.1} %)",
                    g.muscles[m].name,
                    bone.nodes.len(),
                    hinge.angle_deg,
                    100.0 * hinge.residual
                ));
                ((m, bone), hinge)
            }).unzip();
            MuscleRig {
                calibration: Some(g.calibration()),
                muscles: g.muscles,
                origin: "generated from the blend shapes".to_string(),
                bone,
                hinge,
            }
        }
    })
}

/// The fitted frames: the CSV (header included), the activation curves and residual totals.
struct FittedFrames {
    /// The CSV text: one row per frame with the activations and the RMS residual (m).
    csv: String,
    /// Per muscle, (time in s, activation) per frame.
    curves: Vec<Vec<(f64, f64)>>,
    /// Largest finite RMS residual (m).
    rms_max: f64,
    /// Sum of the finite RMS residuals (m).
    rms_sum: f64,
    /// Seconds spent in the QP solves.
    qp_s: f64,
    /// Frames whose fit did not end `Fitted`, with their status.
    not_fitted: Vec<(usize, FrameStatus)>,
}

/// Fit the blend of each frame of `range` (morph weights per frame `weights`, sampled at
/// `fps`) with muscles `names`; `progress()` after each frame.
fn fit_frames(
    fitter: &mut Fitter,
    rig: &Rig,
    weights: &[Vec<f64>],
    range: std::ops::Range<usize>,
    fps: f64,
    names: &[String],
    progress: &dyn Fn(),
) -> anyhow::Result<FittedFrames> {
    let mut csv = String::from("frame,time_s");
    for n in names {
        csv.push(',');
        csv.push_str(&csv_field(n));
    }
    csv.push_str(",rms_residual_m,rms_displacement_m,status,clarabel_status\n");
    let mut done = FittedFrames {
        csv,
        curves: vec![Vec::new(); names.len()],
        rms_max: 0.0,
        rms_sum: 0.0,
        qp_s: 0.0,
        not_fitted: Vec::new(),
    };
    for k in range {
        let target = rig.blend(&weights[k]);
        let f = fitter.fit_frame(&target)?;
        let _ = write!(done.csv, "{k},{:.6}", k as f64 / fps);
        for (c, v) in done.curves.iter_mut().zip(&f.activations) {
            let _ = write!(done.csv, ",{v:.9}");
            c.push((k as f64 / fps, *v));
        }
        let _ = writeln!(
            done.csv,
            ",{:.9e},{:.9e},{:?},{}",
            f.rms_residual, f.rms_displacement, f.status, f.clarabel_status
        );
        if f.status != FrameStatus::Fitted {
            done.not_fitted.push((k, f.status));
        }
        if f.rms_residual.is_finite() {
            done.rms_max = done.rms_max.max(f.rms_residual);
            done.rms_sum += f.rms_residual;
        }
        done.qp_s += f.qp_s;
        progress();
    }
    Ok(done)
}

/// Muscles named in the activation plot at most; the others are drawn as one envelope.
const PLOT_NAMED: usize = 8;

/// An activation curve: (time in s, activation) per frame.
type Curve = Vec<(f64, f64)>;

/// The muscles a plot names, (name, curve) each, and the envelope of the others: their count
/// and pointwise largest activation.
type Strongest = (Vec<(String, Curve)>, Option<(usize, Curve)>);

/// The `k` muscles of largest peak activation, in their order, and when there are more, the
/// envelope of the others.
fn strongest(names: &[String], curves: Vec<Curve>, k: usize) -> Strongest {
    let peak = |c: &Curve| c.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
    let mut order: Vec<usize> = (0..curves.len()).collect();
    order.sort_by(|&a, &b| {
        peak(&curves[b])
            .total_cmp(&peak(&curves[a]))
            .then(a.cmp(&b))
    });
    let keep: Vec<bool> = (0..curves.len())
        .map(|i| order[..k.min(order.len())].contains(&i))
        .collect();
    let mut named = Vec::new();
    let mut envelope: Option<Curve> = None;
    let mut others = 0;
    for ((name, c), kept) in names.iter().zip(curves).zip(keep) {
        if kept {
            named.push((name.clone(), c));
        } else {
            others += 1;
            envelope = Some(match envelope {
                None => c,
                Some(e) => e.iter().zip(&c).map(|(a, b)| (a.0, a.1.max(b.1))).collect(),
            });
        }
    }
    (named, envelope.map(|e| (others, e)))
}

/// Write the PNG of the activation `curves` of muscles `names` over time to `png`: the
/// strongest few by name, the others as one envelope, so the legend stays readable.
fn plot_activations(
    png: &Path,
    rig: &Path,
    names: &[String],
    curves: Vec<Vec<(f64, f64)>>,
) -> anyhow::Result<()> {
    use crate::render::plot::{line_chart, Chart, Series, Style};
    let (named, rest) = strongest(names, curves, PLOT_NAMED);
    let mut series: Vec<Series> = named
        .into_iter()
        .map(|(n, pts)| Series::new(n, pts, Style::Line))
        .collect();
    let title = if let Some((n, envelope)) = rest {
        series.push(Series::new(
            format!("largest of the other {n}"),
            envelope,
            Style::Line,
        ));
        format!(
            "muscle activations of {} ({} strongest of {} named)",
            rig.display(),
            PLOT_NAMED,
            names.len()
        )
    } else {
        format!("muscle activations of {}", rig.display())
    };
    let chart = Chart {
        title,
        x_label: "time (s)".into(),
        y_label: "activation (0 = relaxed, 1 = fully contracted)".into(),
        series,
        ..Default::default()
    };
    line_chart(png, &chart)?;
    Ok(())
}
