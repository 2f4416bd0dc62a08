//! `furrow fit`: muscle activations per frame of a rig's blend-shape animation (CSV).

use super::Output;
use crate::io::atomic::{self, Overwrite};
use crate::io::{self as fio, LoadOptions, Rig};
use crate::muscle::jaw::Hinge;
use crate::muscle::{Fitter, FrameStatus};
use crate::pipeline::{self, MuscleSetUp, RunOptions};
use crate::scene::Scene;
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
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// Muscle rig file (TOML); without it, one muscle per blend shape is generated (in place
    /// of the scene's `muscles.source`).
    #[arg(long)]
    pub muscles: Option<PathBuf>,
    /// Scene TOML (materials, lattice, muscles) whose set-up the fit runs in, as `furrow
    /// animate --scene` runs it; default: the built-in defaults.
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Frames per second at which the animation is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// Lattice cell size (m), in place of the scene's `interior.cell_size`; default: about
    /// 500 cells over the face.
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

/// Run `furrow fit`: the pipeline's set-up up to its muscles (the interior the pipeline
/// runs: welded skin, lattice, tracking, the skin's force in the muscles' fit), then the QP
/// on each frame.
pub fn run(a: FitArgs, out: &Output) -> anyhow::Result<()> {
    check_args(&a)?;
    let outputs: Vec<&PathBuf> = std::iter::once(&a.output).chain(a.plot.as_ref()).collect();
    atomic::check_free(&outputs, Overwrite::from_force(a.force))?;
    let t0 = Instant::now();
    let scene = fit_scene(&a)?;
    let load = LoadOptions {
        allow_outside_paths: a.paths.allow_outside_paths,
        ..Default::default()
    };
    let mut rig = fio::load(&a.rig, &load)?;
    out.note(&rig.face_reason);
    out.note(crate::io::units::apply(&mut rig, a.scale, scene.rig.scale));
    // A bad range is refused before the set-up's seconds.
    let count = pipeline::plan::clip_weights(&rig, a.fps).0.len();
    let range = frame_range(a.frames.as_deref(), count)?;
    let opts = RunOptions {
        preroll: None,
        scene,
        scene_path: a.scene.as_ref().map(|p| p.display().to_string()),
        fps: a.fps,
        frames: None,
    };
    let pb = out.progress(4, "setting up");
    let mut set = pipeline::set_up_muscles(&rig, &opts, &|phase, done, _| {
        if phase == pipeline::Phase::Setup {
            pb.set_position(done as u64)
        }
    })?;
    pb.finish_and_clear();
    for w in &set.log.warnings {
        out.note(format!("warning: {w}"));
    }
    let setup_s = t0.elapsed().as_secs_f64();
    set.muscles.fitter.settings.gauss_newton = a.gauss_newton;
    let names: Vec<String> = set
        .muscles
        .fitter
        .muscles()
        .iter()
        .map(|m| m.name.clone())
        .collect();
    let pb = out.progress(range.len() as u64, "fitting");
    let mut fits = fit_frames(&mut set, &rig, range.clone(), &names, &|| pb.inc(1))?;
    pb.finish_and_clear();
    atomic::write(
        &a.output,
        fits.csv.as_bytes(),
        Overwrite::from_force(a.force),
    )?;
    if let Some(p) = &a.plot {
        plot_activations(p, &a.rig, &names, std::mem::take(&mut fits.curves))?;
    }
    say_fit(
        out,
        (&a, &rig),
        &set,
        &fits,
        (range, setup_s, t0.elapsed().as_secs_f64()),
    );
    Ok(())
}

/// The scene `furrow fit` sets up: `--scene` (or the defaults) with `--cell-size` and
/// `--muscles` in place of its lattice cell and muscle source; muscles generated from the
/// blend shapes unless it names a muscle file.
fn fit_scene(a: &FitArgs) -> anyhow::Result<Scene> {
    let mut scene = match &a.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default(),
    };
    if let Some(h) = a.cell_size {
        scene.interior.cell_size = Some(h);
        scene.interior.target_cells = None;
    }
    if let Some(m) = &a.muscles {
        scene.muscles.source = Some(crate::scene::MuscleSource::File(m.display().to_string()));
    }
    scene.validate()?;
    Ok(scene)
}

/// Say what was fitted to `rig` as `a` asked: the summary line, the residual against the
/// motion, and the JSON result; `(range, setup_s, seconds)` are the frames fitted and the times (s).
fn say_fit(
    out: &Output,
    (a, rig): (&FitArgs, &Rig),
    set: &MuscleSetUp,
    fits: &FittedFrames,
    (range, setup_s, secs): (std::ops::Range<usize>, f64, f64),
) {
    let fitter = &set.muscles.fitter;
    let names: Vec<&str> = fitter.muscles().iter().map(|m| m.name.as_str()).collect();
    let nf = range.len().max(1) as f64;
    let (mean, motion) = (fits.rms_sum / nf, fits.displacement_sum / nf);
    let of_motion = mean / motion.max(1e-300);
    let lattice = &set.model.lattice;
    let made: Vec<serde_json::Value> = set
        .muscles
        .made
        .iter()
        .map(|m| serde_json::json!({"name": m.name, "shape_error": m.shape_error, "projection": m.projection}))
        .collect();
    out.json_result(&serde_json::json!({
        "ok": true, "rig": a.rig, "output": a.output, "frames": range.len(),
        "first_frame": range.start, "fps": a.fps,
        "elements": lattice.elements.len(), "cell_size_m": lattice.cell_size,
        "muscles": names, "muscle_origin": set.muscles.origin, "made": made,
        "gauss_newton": a.gauss_newton,
        "rms_residual_mean_m": mean, "rms_residual_max_m": fits.rms_max,
        "rms_displacement_mean_m": motion, "residual_of_motion": of_motion,
        "frames_not_fitted": fits.not_fitted.iter().map(|(k, s)| serde_json::json!({"frame": k, "status": format!("{s:?}")})).collect::<Vec<_>>(),
        "setup_s": setup_s, "jacobian_s": fitter.jacobian_s, "qp_s": fits.qp_s, "seconds": secs,
        "jaw": jaw_json(fitter, set.muscles.jaw.as_ref()),
        "stages": set.log.stages,
    }));
    out.say(format!(
        "{} frames of '{}' fitted with {} muscles ({}) on {} lattice elements (cell {:.1} mm) in {secs:.2} s (set-up {setup_s:.2} s)",
        range.len(),
        rig.face().name,
        names.len(),
        set.muscles.origin,
        lattice.elements.len(),
        lattice.cell_size * 1e3
    ));
    out.say(format!(
        "  RMS residual mean {:.3} mm ({:.1} % of the mean blend displacement, {:.3} mm), max {:.3} mm; wrote {}",
        mean * 1e3,
        100.0 * of_motion,
        motion * 1e3,
        fits.rms_max * 1e3,
        a.output.display()
    ));
    for (k, s) in &fits.not_fitted {
        out.note(format!("frame {k}: {s:?}"));
    }
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
fn jaw_json(fitter: &Fitter, hinge: Option<&Hinge>) -> serde_json::Value {
    match (&fitter.forward.bone, hinge) {
        (Some((m, bone)), Some(h)) => serde_json::json!({
            "muscle": fitter.muscles()[*m].name, "bone_nodes": bone.nodes.len(),
            "angle_deg": h.angle_deg, "hinge_residual": h.residual,
        }),
        _ => serde_json::Value::Null,
    }
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
    /// Sum of the frames' RMS blend displacements from the neutral face (m).
    displacement_sum: f64,
    /// Seconds spent in the QP solves.
    qp_s: f64,
    /// Frames whose fit did not end `Fitted`, with their status.
    not_fitted: Vec<(usize, FrameStatus)>,
}

/// Fit the blended face of each frame of `range` with the set-up's muscles `names`, each
/// shape of a still rig from rest; `progress()` after each frame.
fn fit_frames(
    set: &mut MuscleSetUp,
    rig: &Rig,
    range: std::ops::Range<usize>,
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
        displacement_sum: 0.0,
        qp_s: 0.0,
        not_fitted: Vec::new(),
    };
    let fps = set.plan.fps;
    for k in range {
        let target = set.target(rig, k)?;
        if !set.plan.animated {
            set.muscles.fitter.reset();
        }
        let f = set.muscles.fitter.fit_frame(&target)?;
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
        if f.rms_displacement.is_finite() {
            done.displacement_sum += f.rms_displacement;
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
