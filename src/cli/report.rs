//! `furrow report tradeoff` and `furrow report stability`: measured error against run time,
//! and how the solvers end on stiff and extreme cases.

use super::Output;
use crate::io::atomic::{self, Overwrite};
use crate::io::{LoadOptions, Rig};
use crate::pipeline::frames::FrameRange;
use crate::scene::Scene;
use crate::studies::stability;
use crate::studies::tradeoff::{self, Pick, SheetRig, TradeoffRun};
use anyhow::{bail, Context};
use std::path::{Path, PathBuf};

/// `furrow report …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum ReportCommand {
    /// Sweep the quality knobs (cell size, skin resolution, shell tolerance, time step) on a rig
    /// and on the validation slab; CSV and log-log PNG of error against wall time.
    #[command(
        after_help = "Example:\n  furrow report tradeoff --quick --out out/report\n  furrow report tradeoff rigs/face.glb --frames 0:10 --out out/report"
    )]
    Tradeoff(TradeoffArgs),
    /// Run stiff and extreme cases (stiffness ratio, thickness, compression, weights, time
    /// step, inverted start, degenerate triangle, stiff skin); CSV and markdown table.
    #[command(after_help = "Example:\n  furrow report stability --quick --out out/report")]
    Stability(StabilityArgs),
}

/// Arguments of `furrow report tradeoff`.
#[derive(Debug, clap::Args)]
pub struct TradeoffArgs {
    /// The rig (glTF with a blend-shape face); default: a 24 × 24 sheet rig built in code
    /// (10 cm, 15 % compression on its left half over 0.3 s).
    pub rig: Option<PathBuf>,
    /// Output folder: tradeoff.csv, tradeoff_rig.png, tradeoff_slab.png, tradeoff.json.
    #[arg(long, default_value = "out/report")]
    pub out: PathBuf,
    /// Fewer knob values and a smaller slab (a few minutes instead of tens).
    #[arg(long)]
    pub quick: bool,
    /// Scene file for the rig runs (the base the knobs are changed around).
    #[arg(long)]
    pub scene: Option<PathBuf>,
    /// Frames of the rig's clip, `A:B` (end exclusive; frames 0..B are simulated).
    #[arg(long)]
    pub frames: Option<String>,
    /// Frames per second at which the rig's clip is sampled.
    #[arg(long, default_value_t = 30.0)]
    pub fps: f64,
    /// The face mesh by name or index (default: the mesh with the most morph targets).
    #[arg(long)]
    pub mesh: Option<String>,
    /// Leave out the slab sweep.
    #[arg(long)]
    pub no_slab: bool,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    pub paths: super::RigPathsArgs,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// Arguments of `furrow report stability`.
#[derive(Debug, clap::Args)]
pub struct StabilityArgs {
    /// Output folder: stability.csv and stability.md.
    #[arg(long, default_value = "out/report")]
    pub out: PathBuf,
    /// One value at each end of every range instead of the full sweep.
    #[arg(long)]
    pub quick: bool,
    /// Quads per side of the sheet rig (2 n² triangles before refinement).
    #[arg(long, default_value_t = 12)]
    pub n: usize,
    /// Side of the sheet rig (m); the skin is refined to hold its wrinkles (λ ≈ 2 cm), so the
    /// cost grows with size².
    #[arg(long, default_value_t = 0.1)]
    pub size: f64,
    /// Clip length (s) of the sheet rig.
    #[arg(long, default_value_t = 0.1)]
    pub seconds: f64,
    /// Replace existing outputs.
    #[arg(long)]
    pub force: bool,
}

/// Run `furrow report …`.
pub fn run(c: ReportCommand, out: &Output) -> anyhow::Result<()> {
    match c {
        ReportCommand::Tradeoff(a) => run_tradeoff(a, out),
        ReportCommand::Stability(a) => run_stability(a, out),
    }
}

fn check_free(paths: &[&Path], force: bool) -> anyhow::Result<Overwrite> {
    let ow = Overwrite::from_force(force);
    crate::io::atomic::check_free(paths, ow)?;
    Ok(ow)
}

/// The error the Pareto front and the picks use: phase-free (see [`tradeoff`]).
fn phase_free(r: &TradeoffRun) -> f64 {
    r.phase_free_error
}

/// Preview pick: the fastest run whose phase-free error is at most this (relative): the
/// wrinkles are there, at a size within a third of the finest run's.
const PREVIEW_TOL: f64 = 0.3;
/// Final pick: the fastest run within this phase-free error (relative).
const FINAL_TOL: f64 = 0.1;

fn run_tradeoff(a: TradeoffArgs, out: &Output) -> anyhow::Result<()> {
    if !(a.fps.is_finite() && a.fps > 0.0 && a.fps <= 1000.0) {
        bail!("--fps must lie in (0, 1000], got {}", a.fps);
    }
    let csv = a.out.join("tradeoff.csv");
    let rig_png = a.out.join("tradeoff_rig.png");
    let slab_png = a.out.join("tradeoff_slab.png");
    let json = a.out.join("tradeoff.json");
    let ow = check_free(&[&csv, &rig_png, &slab_png, &json], a.force)?;
    let scene = match &a.scene {
        Some(p) => Scene::load(p)?,
        None => Scene::default(),
    };
    let (rig, rig_name) = tradeoff_rig(&a)?;
    let frames = match &a.frames {
        Some(t) => Some(FrameRange::parse(
            t,
            crate::pipeline::plan::clip_weights(&rig, a.fps).0.len(),
        )?),
        None => None,
    };
    let pb = out.progress(1, "rig sweep");
    let mut rows = tradeoff::rig_sweep(&rig, &scene, a.fps, frames, a.quick, &|k, n| {
        pb.set_length(n as u64);
        pb.set_position(k as u64);
    })
    .with_context(|| format!("{rig_name}: the tradeoff sweep"))?;
    pb.finish_and_clear();
    let amp = rows
        .iter()
        .find(|r| r.is_default)
        .map_or(f64::NAN, |r| r.wrinkle_m);
    let rig_rows = rows.clone();
    let mut picks_rig =
        tradeoff::picks(&rig_rows, phase_free, PREVIEW_TOL, FINAL_TOL, "(relative)");
    let mut picks_slab: Vec<Pick> = Vec::new();
    if !a.no_slab {
        let slab = slab_sweep(a.quick, &slab_png, out)?;
        picks_slab = tradeoff::picks(&slab, phase_free, PREVIEW_TOL, FINAL_TOL, "(relative)");
        rows.extend(slab);
    }
    tradeoff::write_chart(
        &rig_png,
        &rig_rows,
        &format!("{rig_name}: wrinkle amplitude error against wall time"),
        "relative error of the per-region wrinkle RMS",
        phase_free,
    )?;
    atomic::write(&csv, tradeoff::to_csv(&rows).as_bytes(), ow)?;
    for p in &mut picks_rig {
        p.purpose = format!("rig {}", p.purpose);
    }
    for p in &mut picks_slab {
        p.purpose = format!("slab {}", p.purpose);
    }
    let all_picks: Vec<Pick> = picks_rig.into_iter().chain(picks_slab).collect();
    let doc = serde_json::json!({
        "ok": true,
        "rig": rig_name,
        "wrinkle_rms_m": amp,
        "csv": csv,
        "charts": [rig_png, slab_png],
        "picks": all_picks,
        "runs": rows,
    });
    atomic::write(&json, &serde_json::to_vec_pretty(&doc)?, ow)?;
    out.json_result(&doc);
    say_runs(out, &rows);
    say_picks(out, amp, &all_picks);
    out.say(format!(
        "wrote {}, {}, {}{}",
        csv.display(),
        json.display(),
        rig_png.display(),
        if a.no_slab {
            String::new()
        } else {
            format!(", {}", slab_png.display())
        }
    ));
    Ok(())
}

/// The rig the tradeoff sweeps (the file given, or the built-in sheet rig) and its name for
/// messages.
fn tradeoff_rig(a: &TradeoffArgs) -> anyhow::Result<(Rig, String)> {
    let rig = match &a.rig {
        Some(p) => crate::io::load(
            p,
            &LoadOptions {
                mesh: a.mesh.clone(),
                animation: None,
                skin_primitives: None,
                allow_outside_paths: a.paths.allow_outside_paths,
            },
        )?,
        None => tradeoff::sheet_rig(&SheetRig::default())?,
    };
    let rig_name = a
        .rig
        .as_ref()
        .map_or("built-in sheet rig".to_string(), |p| {
            p.display().to_string()
        });
    Ok((rig, rig_name))
}

/// The sweep on the validation slab (smaller when `quick`), with its chart written to `png`.
fn slab_sweep(quick: bool, png: &Path, out: &Output) -> anyhow::Result<Vec<TradeoffRun>> {
    let pb = out.progress(1, "slab sweep");
    let slab = tradeoff::slab_sweep(&tradeoff::slab_scene(quick), quick, &|k, n| {
        pb.set_length(n as u64);
        pb.set_position(k as u64);
    })
    .context("the slab sweep")?;
    pb.finish_and_clear();
    tradeoff::write_chart(
        png,
        &slab,
        "validation slab: phase-free error against wall time",
        "max(|A/A_ref − 1|, |λ/λ_ref − 1|)",
        phase_free,
    )?;
    Ok(slab)
}

/// Say the table of runs: knob, wall time, wrinkle sizes and errors, Pareto mark, status.
fn say_runs(out: &Output, rows: &[TradeoffRun]) {
    out.say(format!(
        "{:<6} {:<30} {:>10} {:>9} {:>11} {:>11} {:>9} {:>9} {:>9}  status",
        "case", "setting", "value", "wall s", "RMS m", "max m", "λ err", "amp err", "pf err"
    ));
    for r in rows {
        out.say(format!(
            "{:<6} {:<30} {:>10} {:>9.2} {:>11.3e} {:>11.3e} {:>9} {:>8.1}% {:>8.1}%  {}{}",
            r.case,
            r.knob,
            r.value_text(),
            r.wall_s,
            r.rms_m,
            r.max_m,
            r.wavelength_error
                .map_or(String::new(), |e| format!("{:.1} %", e * 100.0)),
            100.0 * r.amplitude_error,
            100.0 * r.phase_free_error,
            if r.pareto { "pareto " } else { "" },
            r.status
        ));
    }
}

/// Say the default rig run's wrinkle RMS `amp` (m), the pick rules and each pick.
fn say_picks(out: &Output, amp: f64, picks: &[Pick]) {
    out.say(format!(
        "wrinkle RMS of the default rig run: {amp:.3e} m; picks by the phase-free error (pf: rig, \
         per-region wrinkle amplitude; slab, amplitude and wavelength) against the finest run: \
         preview ≤ {:.0} %, final ≤ {:.0} %",
        100.0 * PREVIEW_TOL,
        100.0 * FINAL_TOL
    ));
    for p in picks {
        out.say(format!(
            "pick for {}: {} ({:.2} s, error {:.3e}; {})",
            p.purpose, p.setting, p.wall_s, p.error, p.rule
        ));
    }
}

fn run_stability(a: StabilityArgs, out: &Output) -> anyhow::Result<()> {
    if !(2..=64).contains(&a.n) {
        bail!("--n must lie in [2, 64], got {}", a.n);
    }
    if !(a.seconds.is_finite() && a.seconds > 0.0 && a.seconds <= 10.0) {
        bail!("--seconds must lie in (0, 10], got {}", a.seconds);
    }
    if !(a.size.is_finite() && a.size > 0.0 && a.size <= 10.0) {
        bail!("--size must lie in (0, 10] m, got {}", a.size);
    }
    let csv = a.out.join("stability.csv");
    let md = a.out.join("stability.md");
    let ow = check_free(&[&csv, &md], a.force)?;
    let pb = out.progress(1, "cases");
    let rows = stability::run_all(a.quick, a.n, a.size, a.seconds, &|k, n| {
        pb.set_length(n as u64);
        pb.set_position(k as u64);
    });
    pb.finish_and_clear();
    let table = stability::to_markdown(&rows);
    atomic::write(&csv, stability::to_csv(&rows).as_bytes(), ow)?;
    atomic::write(&md, table.as_bytes(), ow)?;
    let bad: Vec<&stability::StabilityRow> = rows.iter().filter(|r| r.non_finite).collect();
    out.json_result(&serde_json::json!({
        "ok": bad.is_empty(), "csv": csv, "markdown": md, "cases": rows,
    }));
    out.say(table);
    out.say(format!("wrote {} and {}", csv.display(), md.display()));
    if !bad.is_empty() {
        bail!(
            "{} case(s) produced a non-finite output: {}",
            bad.len(),
            bad.iter()
                .map(|r| format!("{} ({})", r.case, r.parameter))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    Ok(())
}
