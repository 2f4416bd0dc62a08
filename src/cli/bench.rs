//! `furrow bench …`: benchmarks printing their measurements (text or JSON).

use super::Output;

/// `furrow bench …` subcommands.
#[derive(Debug, clap::Subcommand)]
pub enum BenchCommand {
    /// Skin solve: a square sheet of about N triangles under in-plane compression, centre
    /// clamped by constraints, solved to equilibrium from a warm start, with the skin's fast
    /// linear algebra and with the reference (the speed-up in one run).
    #[command(
        after_help = "Example:\n  furrow bench shell --faces 20000\n  furrow bench shell --faces 2000 --json\n  furrow bench shell --faces 20000 --lagged-solves 0"
    )]
    Shell {
        /// Approximate triangle count.
        #[arg(long, default_value_t = 20_000)]
        faces: usize,
        /// Most GMRES solves a Newton direction may spend with a lagged factorisation before
        /// a fresh one (0: factorise every direction); default: the skin's fast solver's (10).
        /// The reference (double precision, 5) runs beside it in any case.
        #[arg(long)]
        lagged_solves: Option<usize>,
    },
    /// Interior step: one backward Euler step of a lattice of about N quadratic elements.
    #[command(after_help = "Example:\n  furrow bench lattice --elements 1000")]
    Lattice {
        /// Approximate element count.
        #[arg(long, default_value_t = 1000)]
        elements: usize,
    },
    /// The rasteriser: a wrinkled patch of about N triangles rendered plain and as a scalar
    /// field, with supersampling 1 and 2 (mean ms of several renders).
    #[command(after_help = "Example:\n  furrow bench render --triangles 20000 --pixels 512")]
    Render {
        /// Approximate triangle count of the patch.
        #[arg(long, default_value_t = 20_000)]
        triangles: usize,
        /// Image side (pixels).
        #[arg(long, default_value_t = 512)]
        pixels: u32,
    },
    /// The skin–interior coupling terms (Bᵀ K_x B and Bᵀ F_x) on the generated face rig over
    /// a lattice of about N cells: the embedded shell's set-up, then the shell Hessian, its
    /// assembly and the coupling terms, four times each (s).
    #[command(after_help = "Example:\n  furrow bench coupling --cells 3000")]
    Coupling {
        /// Approximate lattice cell count over the face's bounding box.
        #[arg(long, default_value_t = 3000)]
        cells: usize,
    },
    /// The benchmark table: shell assembly and warm solve at several face counts (with the
    /// growth exponent), one lattice step, the activation fit per frame and optionally the
    /// whole demo; writes bench_suite.csv and bench_suite.md in DIR (`--out examples/report`
    /// refreshes the table `docs/performance.md` quotes).
    #[command(
        after_help = "Example:\n  furrow bench suite --out out/bench\n  furrow bench suite --faces 2000,8000 --no-demo --out out/bench-quick"
    )]
    Suite {
        /// Output folder (bench_suite.csv, bench_suite.md; the demo's files under demo/).
        #[arg(long, default_value = "out/bench")]
        out: std::path::PathBuf,
        /// Face counts of the shell benchmarks, comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![2_000usize, 20_000, 80_000])]
        faces: Vec<usize>,
        /// Quadratic elements of the lattice benchmark.
        #[arg(long, default_value_t = 1000)]
        elements: usize,
        /// Lattice cells of the activation-fit benchmark.
        #[arg(long, default_value_t = 2000)]
        cells: usize,
        /// Leave out the whole-demo run.
        #[arg(long)]
        no_demo: bool,
        /// Replace existing bench_suite.csv / bench_suite.md.
        #[arg(long)]
        force: bool,
    },
    /// Skin selection: the rig run with only the skin some frame compresses simulated
    /// (`skin.simulate = "compressed"`, the default) against the whole skin, in one process:
    /// skin time, share simulated and the phase-free wrinkle amplitude difference per 2λ.
    #[command(
        after_help = "Example:\n  furrow bench select --rig rigs/face.glb --frames 0:40\n  furrow bench select --rig rigs/head.glb --frames 0:10 --json"
    )]
    Select {
        #[command(flatten)]
        on: RigFrames,
    },
    /// The skin's fast solver (the scene's `solver.skin_solver`: `lagged` by default, or
    /// `patches`) against the global reference on the same skin, in one process: skin time,
    /// factorisations, solves, and how far apart the wrinkles are; then the fast solver's cost
    /// on a held frame (the first frame's weights repeated: `held_frame_skin_ms`).
    #[command(
        after_help = "Example:\n  furrow bench skin --rig rigs/face.glb --frames 0:40\n  furrow bench skin --rig rigs/head.glb --frames 0:10 --json\n  furrow bench skin --rig rigs/face.glb --scene patches.toml   (a scene with [solver] skin_solver = \"patches\")"
    )]
    Skin {
        #[command(flatten)]
        on: RigFrames,
    },
    /// Muscles against tracking: the rig run driven by its generated muscles (activations
    /// fitted per frame) and by tracking, in one process: fit residuals and times, and the
    /// phase-free wrinkle amplitude difference per 2λ.
    #[command(
        after_help = "Example:\n  furrow bench muscles --rig rigs/face.glb --frames 0:40\n  furrow bench muscles --rig rigs/head.glb --frames 0:10 --json\n  furrow bench muscles --rig rigs/face.glb --frames 0:24 --tracking 1000   (the reference tracking at κ = 1000)"
    )]
    Muscles {
        #[command(flatten)]
        on: RigFrames,
        /// Tracking factor κ of the tracking-driven reference run (dimensionless, ≥ 0);
        /// default: the scene's `interior.tracking`, or 10. The muscle run keeps its own.
        #[arg(long)]
        tracking: Option<f64>,
    },
    /// Pre-roll: the rig run unsplit, then from rest at each start (no pre-roll), compared
    /// frame by frame: the error at a chunk's first written frame against its pre-roll, and
    /// the smallest pre-roll within 10 %; writes preroll.csv and preroll.png in DIR.
    #[command(
        after_help = "Example:\n  furrow bench preroll --rig rigs/face.glb --starts 60,120,180 --window 24 --out out/preroll"
    )]
    Preroll {
        /// The rig.
        #[arg(long, default_value = "rigs/face.glb")]
        rig: std::path::PathBuf,
        /// Frames the started runs begin at, from rest, comma-separated.
        #[arg(long, value_delimiter = ',', default_values_t = vec![60usize, 120, 180])]
        starts: Vec<usize>,
        /// Frames each started run simulates (the largest pre-roll measured + 1).
        #[arg(long, default_value_t = 24)]
        window: usize,
        /// Frames per second at which the clip is sampled.
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Output folder (preroll.csv, preroll.png).
        #[arg(long, default_value = "out/preroll")]
        out: std::path::PathBuf,
    },
    /// Correctives: a still rig's shapes and a clip's frames run back to back under the
    /// defaults, set-up included; the time per solved shape over the time per frame (the
    /// goal: at most 3). Writes correctives.json in DIR.
    #[command(
        after_help = "Example:\n  furrow bench correctives --rig rigs/avatar.glb --clip rigs/face.glb --out examples/report/correctives"
    )]
    Correctives {
        /// The still rig (no animation).
        #[arg(long, default_value = "rigs/avatar.glb")]
        rig: std::path::PathBuf,
        /// The animated rig whose frames the shapes are compared with (the demo's).
        #[arg(long, default_value = "rigs/face.glb")]
        clip: std::path::PathBuf,
        /// Frames per second at which the clip is sampled.
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Output folder (correctives.json).
        #[arg(long, default_value = "out/correctives")]
        out: std::path::PathBuf,
    },
    /// The farm's cost model (`furrow chunks`) against a run: each simulated frame's time in
    /// a run's report (`furrow animate RIG --report R.json`) fitted as a + b × the fraction of
    /// the skin it compresses; b / a beside the model's constant. Writes chunk_cost.json in
    /// DIR.
    #[command(
        after_help = "Example:\n  furrow animate rigs/head.glb -o head.glb --report head.json\n  furrow bench chunk-cost --rig rigs/head.glb --report head.json --out examples/report/chunk_cost/head"
    )]
    ChunkCost {
        /// The animated rig the run was of.
        #[arg(long)]
        rig: std::path::PathBuf,
        /// The run's report (REPORT.json of `furrow animate --report`).
        #[arg(long)]
        report: std::path::PathBuf,
        /// Output folder (chunk_cost.json).
        #[arg(long, default_value = "out/chunk_cost")]
        out: std::path::PathBuf,
    },
    /// Activation fit: 52 muscles on a face lattice of about N cells, a 335-frame clip.
    #[command(after_help = "Example:\n  furrow bench fit\n  furrow bench fit --cells 2000 --json")]
    Fit {
        /// Approximate lattice cell count over the face's bounding box.
        #[arg(long, default_value_t = 2000)]
        cells: usize,
        /// Frames timed with one Gauss–Newton re-linearisation.
        #[arg(long, default_value_t = 3)]
        gn_frames: usize,
    },
}

fn print(out: &Output, title: &str, v: &serde_json::Value) {
    out.json_result(v);
    out.say(title);
    if let Some(o) = v.as_object() {
        for (k, x) in o {
            out.say(format!("  {k:<22} {x}"));
        }
    }
}

/// Run a benchmark.
pub fn run(c: BenchCommand, out: &Output) -> anyhow::Result<()> {
    match c {
        BenchCommand::Shell {
            faces,
            lagged_solves,
        } => {
            anyhow::ensure!(
                (2..=5_000_000).contains(&faces),
                "--faces must be between 2 and 5,000,000, got {faces}"
            );
            let fast = crate::solver::LinearAlgebra::FAST;
            let lagged = lagged_solves.unwrap_or(fast.lagged_solves);
            anyhow::ensure!(
                lagged <= 1000,
                "--lagged-solves must be between 0 and 1000, got {lagged}"
            );
            print(
                out,
                "bench shell",
                &crate::shell::bench::bench_shell_with(
                    faces,
                    crate::solver::LinearAlgebra {
                        lagged_solves: lagged,
                        ..fast
                    },
                )?,
            );
        }
        BenchCommand::Lattice { elements } => {
            anyhow::ensure!(
                (1..=1_000_000).contains(&elements),
                "--elements must be between 1 and 1,000,000, got {elements}"
            );
            print(
                out,
                "bench lattice",
                &crate::fem::bench::bench_lattice(elements)?,
            );
        }
        BenchCommand::Render { triangles, pixels } => {
            anyhow::ensure!(
                (2..=10_000_000).contains(&triangles) && (8..=8192).contains(&pixels),
                "--triangles must lie in [2, 10,000,000] and --pixels in [8, 8192]"
            );
            let v = crate::render::bench::bench_render(triangles, pixels, 10)?;
            print(out, "bench render", &v);
        }
        BenchCommand::Coupling { cells } => {
            anyhow::ensure!(
                (1..=crate::lattice::MAX_CELLS).contains(&cells),
                "--cells must lie in [1, {}], got {cells}",
                crate::lattice::MAX_CELLS
            );
            let v = crate::coupling::bench::bench_coupling(cells, 4)?;
            print(out, "bench coupling", &v);
        }
        BenchCommand::Suite {
            out: dir,
            faces,
            elements,
            cells,
            no_demo,
            force,
        } => suite(&dir, faces, elements, cells, !no_demo, force, out)?,
        BenchCommand::Select { on } => select(&on, out)?,
        BenchCommand::Skin { on } => skin(&on, out)?,
        BenchCommand::Muscles { on, tracking } => {
            if let Some(k) = tracking {
                anyhow::ensure!(
                    k.is_finite() && k >= 0.0,
                    "--tracking must be a finite number ≥ 0, got {k}"
                );
            }
            let (loaded, opts) = bench_rig(&on)?;
            let c = crate::studies::muscles::compare_drivers(&loaded, &opts, tracking)?;
            print(out, "bench muscles", &serde_json::to_value(&c)?);
        }
        BenchCommand::Preroll {
            rig,
            starts,
            window,
            fps,
            out: dir,
        } => preroll(&rig, &starts, window, fps, &dir, out)?,
        BenchCommand::Correctives {
            rig,
            clip,
            fps,
            out: dir,
        } => correctives(&rig, &clip, fps, &dir, out)?,
        BenchCommand::ChunkCost {
            rig,
            report,
            out: dir,
        } => chunk_cost(&rig, &report, &dir, out)?,
        BenchCommand::Fit { cells, gn_frames } => {
            anyhow::ensure!(
                (1..=1_000_000).contains(&cells),
                "--cells must be between 1 and 1,000,000, got {cells}"
            );
            anyhow::ensure!(
                gn_frames <= 335,
                "--gn-frames must be at most 335, got {gn_frames}"
            );
            print(
                out,
                "bench fit",
                &crate::muscle::bench::bench_fit(cells, gn_frames)?,
            );
        }
    }
    Ok(())
}

/// The rig and frames a rig benchmark runs on.
#[derive(clap::Args, Debug)]
pub struct RigFrames {
    /// The rig.
    #[arg(long, default_value = "rigs/face.glb")]
    rig: std::path::PathBuf,
    /// Frames to run, `A:B` (end exclusive).
    #[arg(long, default_value = "0:40")]
    frames: String,
    /// Frames per second at which the clip is sampled.
    #[arg(long, default_value_t = 30.0)]
    fps: f64,
    /// Scene file (TOML) both runs start from; default: the defaults.
    #[arg(long)]
    scene: Option<std::path::PathBuf>,
    /// Whether the rig's buffer and image files may lie outside its folder.
    #[command(flatten)]
    paths: super::RigPathsArgs,
}

/// The rig of `on` (units decided as `animate` does) and the run options for its frames.
fn bench_rig(
    on: &RigFrames,
) -> anyhow::Result<(crate::io::load::Rig, crate::pipeline::RunOptions)> {
    let RigFrames {
        rig,
        frames,
        fps,
        scene,
        paths,
    } = on;
    let fps = *fps;
    let load = crate::io::LoadOptions {
        allow_outside_paths: paths.allow_outside_paths,
        ..Default::default()
    };
    let loaded = load_rig(rig, &load)?;
    let count = crate::pipeline::plan::clip_weights(&loaded, fps).0.len();
    let opts = crate::pipeline::RunOptions {
        preroll: None,
        scene: match scene {
            Some(p) => crate::scene::Scene::load(p)?,
            None => crate::scene::Scene::default(),
        },
        scene_path: scene.as_ref().map(|p| p.display().to_string()),
        fps,
        frames: Some(crate::pipeline::frames::FrameRange::parse(frames, count)?),
    };
    Ok((loaded, opts))
}

/// `furrow bench preroll`: how fast the clip's history fades on a rig.
fn preroll(
    rig: &std::path::Path,
    starts: &[usize],
    window: usize,
    fps: f64,
    dir: &std::path::Path,
    out: &Output,
) -> anyhow::Result<()> {
    anyhow::ensure!(window >= 1, "--window must be at least 1");
    anyhow::ensure!(!starts.is_empty(), "--starts needs at least one frame");
    let end = starts.iter().max().copied().unwrap_or(0) + window;
    let on = RigFrames {
        rig: rig.to_path_buf(),
        frames: format!("0:{end}"),
        fps,
        scene: None,
        paths: super::RigPathsArgs::default(),
    };
    let (loaded, opts) = bench_rig(&on)?;
    let curve = crate::studies::preroll::measure(&loaded, &opts, starts, window)?;
    let files = crate::studies::preroll::write(&curve, dir)?;
    out.json_result(&serde_json::json!({ "ok": true, "files": files, "curve": curve }));
    out.say("bench preroll: worst amplitude error over the starts at a chunk's first frame");
    for (p, e) in &curve.worst {
        out.say(format!("  pre-roll {p:>3}  {:6.2} %", 100.0 * e));
    }
    match curve.preroll {
        Some(p) => out.say(format!("  within 10 % from a pre-roll of {p} frames")),
        None => out.say("  no measured pre-roll stays within 10 %"),
    }
    files
        .iter()
        .for_each(|f| out.say(format!("  wrote {}", f.display())));
    Ok(())
}

/// `furrow bench correctives`: a still rig's shapes against a clip's frames.
fn correctives(
    rig: &std::path::Path,
    clip: &std::path::Path,
    fps: f64,
    dir: &std::path::Path,
    out: &Output,
) -> anyhow::Result<()> {
    let load = crate::io::LoadOptions::default();
    let (still, animated) = (load_rig(rig, &load)?, load_rig(clip, &load)?);
    let cost = crate::studies::correctives::measure(&still, &animated, fps)?;
    let v = serde_json::to_value(&cost)?;
    write_result(out, "bench correctives", &v, &dir.join("correctives.json"))
}

/// A rig loaded with `load`, its units decided as `animate` decides them.
fn load_rig(
    path: &std::path::Path,
    load: &crate::io::LoadOptions,
) -> anyhow::Result<crate::io::load::Rig> {
    let mut loaded = crate::io::load::load(path, load)?;
    crate::io::units::apply(&mut loaded, None, None);
    Ok(loaded)
}

/// Print a benchmark's result `v` under `title` and write it to `file` as JSON (replacing
/// an earlier one).
fn write_result(
    out: &Output,
    title: &str,
    v: &serde_json::Value,
    file: &std::path::Path,
) -> anyhow::Result<()> {
    let text = serde_json::to_string_pretty(v)?;
    crate::io::atomic::write(file, text.as_bytes(), crate::io::atomic::Overwrite::Replace)?;
    print(out, title, v);
    out.say(format!("  wrote {}", file.display()));
    Ok(())
}

/// `furrow bench chunk-cost`: the farm's cost model against a run's frame times.
fn chunk_cost(
    rig: &std::path::Path,
    report: &std::path::Path,
    dir: &std::path::Path,
    out: &Output,
) -> anyhow::Result<()> {
    use crate::studies::chunk_cost;
    let text = std::fs::read(report)
        .map_err(|e| anyhow::anyhow!("{}: cannot read the report: {e}", report.display()))?;
    let run: serde_json::Value = serde_json::from_slice(&text)
        .map_err(|e| anyhow::anyhow!("{}: not a run's report: {e}", report.display()))?;
    let times =
        chunk_cost::frame_times(&run).map_err(|e| anyhow::anyhow!("{}: {e}", report.display()))?;
    let fps = run["fps"].as_f64().unwrap_or(30.0);
    let loaded = load_rig(rig, &crate::io::LoadOptions::default())?;
    let materials = crate::scene::Scene::default().materials()?;
    let threshold = crate::pipeline::setup::select::default_threshold(&materials);
    let fractions = crate::pipeline::farm::compressed_fractions(&loaded, fps, threshold);
    let fit = chunk_cost::fit(&times, &fractions).ok_or_else(|| {
        anyhow::anyhow!(
            "{}: too few frames, or frames that all compress the same, to fit",
            report.display()
        )
    })?;
    let v = serde_json::to_value(&fit)?;
    write_result(out, "bench chunk-cost", &v, &dir.join("chunk_cost.json"))
}

/// `furrow bench select`: the selected skin against the whole skin on a rig.
fn select(on: &RigFrames, out: &Output) -> anyhow::Result<()> {
    let (loaded, opts) = bench_rig(on)?;
    let c = crate::studies::locality::compare_selection(&loaded, &opts)?;
    print(out, "bench select", &serde_json::to_value(&c)?);
    Ok(())
}

/// Repeats of the held frame in `bench skin`.
const HELD_REPEATS: usize = 6;
/// The first repeats of the held frame, left out of its figure while the interior comes to
/// rest.
const HELD_SETTLE: usize = 2;

/// `furrow bench skin`: the local skin solver against the global one on a rig, then the
/// skin's cost on a held frame (the first frame's weights repeated).
fn skin(on: &RigFrames, out: &Output) -> anyhow::Result<()> {
    let (loaded, opts) = bench_rig(on)?;
    let c = crate::studies::locality::compare_solvers(&loaded, &opts)?;
    let held = crate::studies::locality::held_frames(&loaded, &opts, HELD_REPEATS)?;
    // The first repeats still see the interior settle; the rest hold still.
    let settled = held[HELD_SETTLE..]
        .iter()
        .map(|h| h.skin_ms)
        .fold(0.0, f64::max);
    let mut v = serde_json::to_value(&c)?;
    v["held_frames"] = serde_json::to_value(&held)?;
    v["held_frame_skin_ms"] = settled.into();
    print(out, "bench skin", &v);
    Ok(())
}

/// `furrow bench suite`: run every benchmark in one process and write the table.
fn suite(
    dir: &std::path::Path,
    faces: Vec<usize>,
    elements: usize,
    cells: usize,
    demo: bool,
    force: bool,
    out: &Output,
) -> anyhow::Result<()> {
    use crate::io::atomic::{self, Overwrite};
    use crate::studies::benchmarks::{self, BenchRow, SuiteSettings};
    anyhow::ensure!(!faces.is_empty(), "--faces needs at least one face count");
    for &f in &faces {
        anyhow::ensure!(
            (50..=5_000_000).contains(&f),
            "--faces values must be between 50 and 5,000,000, got {f}"
        );
    }
    anyhow::ensure!(
        (1..=1_000_000).contains(&elements),
        "--elements must be between 1 and 1,000,000, got {elements}"
    );
    anyhow::ensure!(
        (1..=1_000_000).contains(&cells),
        "--cells must be between 1 and 1,000,000, got {cells}"
    );
    let (csv, md) = (dir.join("bench_suite.csv"), dir.join("bench_suite.md"));
    let overwrite = Overwrite::from_force(force);
    atomic::check_free(&[&csv, &md], overwrite)?;
    let settings = SuiteSettings {
        faces,
        elements,
        cells,
    };
    let total = settings.faces.len() as u64 * 2 + 2 + u64::from(demo);
    let bar = out.progress(total, "benchmarks");
    let mut rows = benchmarks::run_suite(&settings, |what| {
        bar.set_message(what.to_string());
        bar.inc(1);
    })?;
    if demo {
        bar.set_message("whole demo");
        bar.inc(1);
        let demo_dir = dir.join("demo");
        let args = super::demo::DemoArgs::for_benchmark(demo_dir);
        let t = std::time::Instant::now();
        let totals = super::demo::run_demo(args, &Output::new(true, false))?;
        rows.push(BenchRow {
            benchmark: "demo".into(),
            size: totals.frames_written,
            size_unit: "frames".into(),
            metric: "wall_s".into(),
            value: t.elapsed().as_secs_f64(),
        });
    }
    bar.finish_and_clear();
    let table = benchmarks::to_markdown(&rows);
    atomic::write(&csv, benchmarks::to_csv(&rows).as_bytes(), overwrite)?;
    atomic::write(&md, table.as_bytes(), overwrite)?;
    out.json_result(&serde_json::json!({
        "csv": csv, "markdown": md,
        "rows": rows.iter().map(|r| serde_json::json!({
            "benchmark": r.benchmark, "size": r.size, "size_unit": r.size_unit,
            "metric": r.metric, "value": r.value,
        })).collect::<Vec<_>>(),
        "shell_solve_exponent": benchmarks::growth(&rows, "shell_solve", "total_s").map(|p| p.exponent),
    }));
    out.say(table);
    out.say(format!("wrote {} and {}", csv.display(), md.display()));
    Ok(())
}
