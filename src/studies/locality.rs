//! Spatial locality of the skin: the pipeline with the `select` stage (only the skin some
//! frame compresses past the wrinkling threshold is simulated) against the reference that
//! simulates all of it, in one process: the skin's time, the share of the skin simulated, and
//! the phase-free difference of the wrinkle amplitude per 2λ region ([`super::tradeoff`]).
//! And temporal locality: the skin's fast solvers (`solver.skin_solver = "lagged"`, a
//! single-precision factor kept across iterations and frames, or `"patches"`, which also
//! refactorises only the patches whose Hessian changed) against the global reference, on the
//! same selected skin, in one process.

use super::tradeoff::{amplitude_error, amplitude_map, region_size};
use crate::io::load::Rig;
use crate::pipeline::{self, RunOptions, RunOutput};
use crate::scene::{SkinSelection, SkinSolver};
use serde::Serialize;

/// One run of the comparison.
#[derive(Debug, Clone, Serialize)]
pub struct SkinRun {
    /// `all` (the reference) or `compressed`.
    pub simulate: String,
    /// Shell vertices simulated.
    pub simulated_vertices: usize,
    /// Skin vertices of the exported face.
    pub skin_vertices: usize,
    /// Milliseconds in the skin's solves over the frames.
    pub shell_ms: f64,
    /// Wall time of the run (s).
    pub wall_s: f64,
    /// Frames not converged in some stage.
    pub frames_not_converged: usize,
}

/// The comparison: both runs, the speed-up of the skin and the amplitude difference.
#[derive(Debug, Clone, Serialize)]
pub struct SelectionComparison {
    /// The reference (whole skin) and the selected run.
    pub runs: Vec<SkinRun>,
    /// Skin time of the reference over the selected run's.
    pub shell_speedup: f64,
    /// Phase-free relative difference of the wrinkle amplitude per region (dimensionless).
    pub amplitude_error: f64,
    /// Region side of the amplitude maps (m), 2λ.
    pub region_m: f64,
}

fn run_with(
    rig: &Rig,
    opts: &RunOptions,
    simulate: SkinSelection,
) -> anyhow::Result<(SkinRun, RunOutput)> {
    let mut o = opts.clone();
    o.scene.skin.simulate = Some(simulate);
    let out = pipeline::run(rig, &o, &|_, _, _| {})?;
    let r = &out.report;
    let count = |k: &str| r.sizes[k].as_u64().unwrap_or(0) as usize;
    let run = SkinRun {
        simulate: simulate.to_string(),
        simulated_vertices: count("simulated_vertices"),
        skin_vertices: count("skin_vertices"),
        shell_ms: r.totals.shell_ms,
        wall_s: r.totals.wall_s,
        frames_not_converged: r.totals.frames_not_converged,
    };
    Ok((run, out))
}

/// Run `opts` on `rig` with the whole skin simulated and with the selected skin.
pub fn compare_selection(rig: &Rig, opts: &RunOptions) -> anyhow::Result<SelectionComparison> {
    let (reference, full) = run_with(rig, opts, SkinSelection::All)?;
    let (selected, local) = run_with(rig, opts, SkinSelection::Compressed)?;
    let region = region_size(&full);
    let error = amplitude_error(
        &amplitude_map(&local, region),
        &amplitude_map(&full, region),
    );
    Ok(SelectionComparison {
        shell_speedup: reference.shell_ms / selected.shell_ms.max(1e-9),
        runs: vec![reference, selected],
        amplitude_error: error,
        region_m: region,
    })
}

/// One run of the solver comparison.
#[derive(Debug, Clone, Serialize)]
pub struct SolverRun {
    /// `global` (the reference), `lagged` or `patches`.
    pub solver: SkinSolver,
    /// Milliseconds in the skin's solves over the frames.
    pub shell_ms: f64,
    /// Skin Newton iterations over the frames.
    pub iterations: usize,
    /// Factorisations of the whole skin's KKT matrix.
    pub factorizations: usize,
    /// Factorisations of patch blocks.
    pub patch_factorizations: usize,
    /// Solves with a factor (GMRES iterations).
    pub linear_solves: usize,
    /// Frames not converged in some stage.
    pub frames_not_converged: usize,
    /// Wall time of the run (s).
    pub wall_s: f64,
}

/// The skin solvers compared: both runs, the speed-up of the skin and how far apart the
/// wrinkles are.
#[derive(Debug, Clone, Serialize)]
pub struct SolverComparison {
    /// Shell vertices simulated (the same in both runs).
    pub simulated_vertices: usize,
    /// The reference (global) and the compared run.
    pub runs: Vec<SolverRun>,
    /// Skin time of the global run over the compared run's.
    pub shell_speedup: f64,
    /// Phase-free relative difference of the wrinkle amplitude per region (dimensionless).
    pub amplitude_error: f64,
    /// Largest distance between the two runs' exported vertices over every frame (m).
    pub max_difference_m: f64,
    /// Largest wrinkle depth of the reference over every frame (m).
    pub max_depth_m: f64,
    /// Region side of the amplitude maps (m), 2λ.
    pub region_m: f64,
}

fn run_solver(
    rig: &Rig,
    opts: &RunOptions,
    solver: SkinSolver,
) -> anyhow::Result<(SolverRun, RunOutput)> {
    let mut o = opts.clone();
    o.scene.solver.skin_solver = Some(solver);
    let out = pipeline::run(rig, &o, &|_, _, _| {})?;
    let t = &out.report.totals;
    let solves = out
        .report
        .per_frame
        .iter()
        .filter_map(|f| f.shell.as_ref())
        .map(|s| s.linear_solves)
        .sum();
    let run = SolverRun {
        solver,
        shell_ms: t.shell_ms,
        iterations: t.skin_iterations,
        factorizations: t.skin_factorizations,
        patch_factorizations: t.skin_patch_factorizations,
        linear_solves: solves,
        frames_not_converged: t.frames_not_converged,
        wall_s: t.wall_s,
    };
    Ok((run, out))
}

/// Run `opts` on `rig` with the global skin solver (the reference) and with the solver the
/// scene names (`lagged`, the default, when it names none or the reference itself).
pub fn compare_solvers(rig: &Rig, opts: &RunOptions) -> anyhow::Result<SolverComparison> {
    let candidate = match opts.scene.solver.skin_solver.unwrap_or_default() {
        SkinSolver::Global => SkinSolver::Lagged,
        s => s,
    };
    let (reference, global) = run_solver(rig, opts, SkinSolver::Global)?;
    let (local_run, local) = run_solver(rig, opts, candidate)?;
    let region = region_size(&global);
    let error = amplitude_error(
        &amplitude_map(&local, region),
        &amplitude_map(&global, region),
    );
    let mut max_difference_m: f64 = 0.0;
    let mut max_depth_m: f64 = 0.0;
    for ((a, b), s) in local.frames.iter().zip(&global.frames).zip(&global.smooth) {
        for ((p, q), r) in a.iter().zip(b).zip(s) {
            max_difference_m = max_difference_m.max((p - q).norm());
            max_depth_m = max_depth_m.max((q - r).norm());
        }
    }
    Ok(SolverComparison {
        simulated_vertices: global.report.sizes["simulated_vertices"]
            .as_u64()
            .unwrap_or(0) as usize,
        shell_speedup: reference.shell_ms / local_run.shell_ms.max(1e-9),
        runs: vec![reference, local_run],
        amplitude_error: error,
        max_difference_m,
        max_depth_m,
        region_m: region,
    })
}

/// The reference's residual test applied to every frame of a run: how many frames were
/// checked, how many failed, the worst residual (N) and the tolerance (N).
#[derive(Debug, Clone, Serialize)]
pub struct ResidualCheck {
    /// Frames stepped.
    pub frames: usize,
    /// Frames whose final skin state fails the test.
    pub failed: usize,
    /// Largest residual norm over the frames (N).
    pub worst_residual: f64,
    /// The test's tolerance (N).
    pub tolerance: f64,
}

/// The pipeline set up on one rig, stepped frame by frame by the studies below.
struct Stepper {
    plan: pipeline::plan::Plan,
    model: pipeline::setup::Model,
    state: pipeline::setup::State,
    scratch: pipeline::step::Scratch,
    options: pipeline::step::StepOptions,
}

impl Stepper {
    /// Plan and set up `opts` on `rig`.
    fn new(rig: &Rig, opts: &RunOptions) -> anyhow::Result<Self> {
        let plan = pipeline::plan::Plan::new(rig, opts)?;
        let mut log = pipeline::setup::Log::default();
        let (model, state) =
            pipeline::setup::set_up(rig, &opts.scene, &plan, &mut log, &|_, _, _| {})?;
        let options = pipeline::step::StepOptions::of(&opts.scene, &plan, &model.driver);
        let scratch = pipeline::step::Scratch::new(model.lattice.node_count());
        Ok(Self {
            plan,
            model,
            state,
            scratch,
            options,
        })
    }

    /// Step the clip's frame `k` (its weights at clip time k / fps).
    fn step(&mut self, rig: &Rig, k: usize) -> anyhow::Result<pipeline::record::FrameRecord> {
        let (record, _) = pipeline::step::step_frame(
            rig,
            &self.plan.weights[k],
            k,
            &self.model,
            &mut self.state,
            &mut self.scratch,
            self.options,
        )?;
        Ok(record)
    }
}

/// Step every frame of `opts` on `rig` and, after each, evaluate the skin's residual at its
/// final state the way the global reference tests convergence.
pub fn check_with_global(rig: &Rig, opts: &RunOptions) -> anyhow::Result<ResidualCheck> {
    let mut run = Stepper::new(rig, opts)?;
    let mut check = ResidualCheck {
        frames: 0,
        failed: 0,
        worst_residual: 0.0,
        tolerance: 0.0,
    };
    for k in 0..run.plan.range.end {
        run.step(rig, k)?;
        let q = run.state.interior.q.clone();
        let skin = run
            .state
            .skin
            .as_mut()
            .ok_or_else(|| anyhow::anyhow!("no skin is simulated"))?;
        let (r, tol) = skin.residual(&q)?;
        check.frames += 1;
        check.tolerance = tol;
        check.worst_residual = check.worst_residual.max(r);
        if r > tol {
            check.failed += 1;
        }
    }
    Ok(check)
}

/// One repeat of a held frame: the skin stage's cost when the rig's weights do not change.
#[derive(Debug, Clone, Serialize)]
pub struct HeldFrame {
    /// Skin stage wall time (ms).
    pub skin_ms: f64,
    /// Skin Newton iterations (0 when the constraint targets moved less than the tolerance
    /// allows and the solve was skipped).
    pub iterations: usize,
    /// Factorisations of the whole skin.
    pub factorizations: usize,
}

/// The skin's cost on frames where nothing moves: step the clip up to the first frame of
/// `opts`' range (its history), then step that frame's weights `repeats` more times with the
/// scene's skin solver. Backward Euler damps the interior's velocity within a few repeats,
/// but after an expression the coupled interior still creeps by about 0.1 µm per frame for
/// over a second (measured on the face at frame 30; the same with the interior's Newton
/// tolerance at 1e-6, so not its stopping test), enough to move the skin's targets past the
/// skin's tolerance: such a frame costs one Newton iteration, not none.
pub fn held_frames(rig: &Rig, opts: &RunOptions, repeats: usize) -> anyhow::Result<Vec<HeldFrame>> {
    let mut run = Stepper::new(rig, opts)?;
    let first = run.plan.range.start;
    let mut held = Vec::with_capacity(repeats);
    for (i, k) in (0..=first)
        .chain(std::iter::repeat_n(first, repeats))
        .enumerate()
    {
        let record = run.step(rig, k)?;
        if i > first {
            let shell = record.shell.unwrap_or_default();
            held.push(HeldFrame {
                skin_ms: shell.ms,
                iterations: shell.iterations,
                factorizations: shell.factorizations,
            });
        }
    }
    Ok(held)
}
