//! `furrow fit`: muscle activations per frame of a rig's blend-shape animation (CSV).

use super::Output;
use crate::fem::{Interior, Material};
use crate::io::atomic::{self, Overwrite};
use crate::io::{self as fio, LoadOptions};
use crate::lattice::{Lattice, LatticeSettings};
use crate::mesh::TriMesh;
use crate::muscle::{self, FitSettings, Fitter, FrameStatus, GenerateSettings};
use std::fmt::Write as _;
use std::path::PathBuf;
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
    let outputs: Vec<&PathBuf> = std::iter::once(&a.output).chain(a.plot.as_ref()).collect();
    atomic::check_free(&outputs, Overwrite::from_force(a.force))?;
    let t0 = Instant::now();
    let rig = fio::load(&a.rig, &LoadOptions::default())?;
    out.note(&rig.face_reason);
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
    let (muscles, origin) = match &a.muscles {
        Some(p) => (
            muscle::rigfile::load(p, &lattice, &mesh)?,
            format!("from {}", p.display()),
        ),
        None => {
            let interior = Interior::new(&lattice, &material)?;
            let g = muscle::generate_muscles(
                &lattice,
                &interior,
                &face.targets,
                &GenerateSettings::default(),
            )?;
            for (name, why) in &g.skipped {
                out.note(format!("blend shape '{name}' makes no muscle: {why}"));
            }
            (g.muscles, "generated from the blend shapes".to_string())
        }
    };
    anyhow::ensure!(
        !muscles.is_empty(),
        "{}: no muscles (every blend shape is empty); give a muscle file with --muscles",
        a.rig.display()
    );
    let settings = FitSettings {
        gauss_newton: a.gauss_newton,
        ..Default::default()
    };
    let mut fitter = Fitter::new(&lattice, &material, muscles, settings)?;
    let weights = rig.frame_weights(a.fps);
    let range = frame_range(a.frames.as_deref(), weights.len())?;
    let names: Vec<String> = fitter.muscles().iter().map(|m| m.name.clone()).collect();
    let mut csv = String::from("frame,time_s");
    for n in &names {
        csv.push(',');
        csv.push_str(&csv_field(n));
    }
    csv.push_str(",rms_residual_m,status,clarabel_status\n");
    let pb = out.progress(range.len() as u64, "fitting");
    let (mut rms_max, mut rms_sum, mut qp_s) = (0.0f64, 0.0, 0.0);
    let mut not_fitted: Vec<(usize, FrameStatus)> = Vec::new();
    let mut curves: Vec<Vec<(f64, f64)>> = vec![Vec::new(); names.len()];
    for k in range.clone() {
        let target = rig.blend(&weights[k]);
        let f = fitter.fit_frame(&target)?;
        let _ = write!(csv, "{k},{:.6}", k as f64 / a.fps);
        for (c, v) in curves.iter_mut().zip(&f.activations) {
            let _ = write!(csv, ",{v:.9}");
            c.push((k as f64 / a.fps, *v));
        }
        let _ = writeln!(
            csv,
            ",{:.9e},{:?},{}",
            f.rms_residual, f.status, f.clarabel_status
        );
        if f.status != FrameStatus::Fitted {
            not_fitted.push((k, f.status));
        }
        if f.rms_residual.is_finite() {
            rms_max = rms_max.max(f.rms_residual);
            rms_sum += f.rms_residual;
        }
        qp_s += f.qp_s;
        pb.inc(1);
    }
    pb.finish_and_clear();
    atomic::write(
        &a.output,
        csv.as_bytes(),
        if a.force {
            Overwrite::Replace
        } else {
            Overwrite::Refuse
        },
    )?;
    if let Some(p) = &a.plot {
        use crate::render::plot::{line_chart, Chart, Series, Style};
        let chart = Chart {
            title: format!("muscle activations of {}", a.rig.display()),
            x_label: "time (s)".into(),
            y_label: "activation (0 = relaxed, 1 = fully contracted)".into(),
            series: names
                .iter()
                .zip(curves)
                .map(|(n, pts)| Series::new(n.clone(), pts, Style::Line))
                .collect(),
            ..Default::default()
        };
        line_chart(p, &chart)?;
    }
    let nf = range.len();
    let mean = if nf > 0 { rms_sum / nf as f64 } else { 0.0 };
    let secs = t0.elapsed().as_secs_f64();
    out.json_result(&serde_json::json!({
        "ok": true, "rig": a.rig, "output": a.output, "frames": nf,
        "first_frame": range.start, "fps": a.fps,
        "elements": lattice.elements.len(), "muscles": names, "muscle_origin": origin,
        "gauss_newton": a.gauss_newton,
        "rms_residual_mean_m": mean, "rms_residual_max_m": rms_max,
        "frames_not_fitted": not_fitted.iter().map(|(k, s)| serde_json::json!({"frame": k, "status": format!("{s:?}")})).collect::<Vec<_>>(),
        "jacobian_s": fitter.jacobian_s, "qp_s": qp_s, "seconds": secs,
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
        rms_max * 1e3,
        a.output.display()
    ));
    for (k, s) in &not_fitted {
        out.note(format!("frame {k}: {s:?}"));
    }
    Ok(())
}
