//! Stiff and extreme cases (`furrow report stability`): run the pipeline on a small sheet rig
//! (see [`super::tradeoff::sheet_rig`]) with one thing pushed to an extreme per case, and the
//! interior alone from an inverted start, and record per case how each stage ended
//! (converged, a named non-convergence status, or a refusal with a message), the iterations,
//! residuals and time, and whether any output was non-finite.
//!
//! The goal the table checks: every case converges or stops with a named status and a
//! message saying what to change; no NaN or infinity reaches an output.

use super::tradeoff::{sheet_rig, SheetRig};
use crate::fem::{BackwardEuler, Interior, LinearSolver, SolveStatus, StepSettings};
use crate::lattice::ElementOrder;
use crate::pipeline::{self, record::StageRecord, RunOptions};
use crate::scene::Scene;
use crate::validate::slab::block_lattice;
use nalgebra::Vector3;
use serde::Serialize;
use std::time::Instant;

/// One extreme case: the sheet rig, the scene and the sampling rate to run it with.
#[derive(Debug, Clone)]
pub struct Case {
    /// Short name of what is pushed (`stiffness_ratio`, `thickness`, …).
    pub name: String,
    /// The extreme value, as text with its unit.
    pub parameter: String,
    /// The rig.
    pub rig: CaseRig,
    /// The scene.
    pub scene: Scene,
    /// Frames per second.
    pub fps: f64,
}

/// The rig a case runs.
#[derive(Debug, Clone, Copy)]
pub enum CaseRig {
    /// The sheet rig (see [`SheetRig`]).
    Sheet(SheetRig),
    /// The capture-shaped head of `furrow rig generate --kind head` (52 ARKit shapes), its
    /// performance cut to the first `seconds` (s) and every weight multiplied by
    /// `weight_scale`.
    Head {
        /// Factor on every weight of the performance.
        weight_scale: f64,
        /// Clip length kept (s).
        seconds: f64,
    },
}

impl CaseRig {
    /// The rig, built in memory (the head through the compact writer, as in `rigs/`).
    pub fn build(&self) -> anyhow::Result<crate::io::load::Rig> {
        match *self {
            Self::Sheet(s) => sheet_rig(&s),
            Self::Head {
                weight_scale,
                seconds,
            } => {
                let mut h = crate::rig::head::generate();
                let keep = h
                    .keys
                    .times
                    .iter()
                    .filter(|&&t| t <= seconds)
                    .count()
                    .max(2);
                h.keys.times.truncate(keep);
                h.keys.weights.truncate(keep);
                for w in h.keys.weights.iter_mut().flatten() {
                    *w *= weight_scale;
                }
                let bytes = crate::io::compact::rig_glb("head", &h.mesh, &h.targets, &h.keys)?;
                let path = std::path::Path::new("head.glb");
                Ok(crate::io::load::load_bytes(
                    path,
                    &bytes,
                    &Default::default(),
                )?)
            }
        }
    }
}

/// How one case ended.
#[derive(Debug, Clone, Serialize)]
pub struct StabilityRow {
    /// What is pushed.
    pub case: String,
    /// Its value.
    pub parameter: String,
    /// `converged` (every stage of every frame), `not_converged` (a named solver status in
    /// some frame, outputs finite), `refused` (the run stopped with a message before writing
    /// anything) or `non_finite` (a NaN or infinity in an output: a bug).
    pub outcome: CaseOutcome,
    /// The interior's worst status over the frames, with the count (`converged`,
    /// `iterationlimit (2/5)`, …).
    pub interior_status: String,
    /// Interior Newton iterations summed over frames.
    pub interior_iterations: usize,
    /// Largest final interior residual over frames (N).
    pub interior_residual: f64,
    /// Sub-step halvings the interior needed, summed over frames.
    pub interior_halvings: usize,
    /// The shell's worst status over the frames, with the count.
    pub shell_status: String,
    /// Shell Newton iterations summed over frames.
    pub shell_iterations: usize,
    /// Largest final shell residual over frames (N).
    pub shell_residual: f64,
    /// Load steps of the skin solves that needed load stepping, summed over frames.
    pub shell_load_steps: usize,
    /// Frames simulated.
    pub frames: usize,
    /// Largest wrinkle depth over frames (m).
    pub wrinkle_depth_max_m: f64,
    /// Wall time (s).
    pub wall_s: f64,
    /// Whether any output position was NaN or infinite.
    pub non_finite: bool,
    /// The refusal message, or the run's warnings (joined by " | ").
    pub message: String,
}

/// The CSV header written by [`to_csv`].
pub const CSV_HEADER: &str = "case,parameter,outcome,interior_status,interior_iterations,interior_residual,interior_halvings,shell_status,shell_iterations,shell_residual,shell_load_steps,frames,wrinkle_depth_max_m,wall_s,non_finite,message";

/// The cases. `quick` keeps each end of every range (a reduced set for tests); the full set
/// adds intermediate values. The sheet is `n` quads per side over `size` (m, the model size),
/// 15 % strain over `seconds`, flesh interior (E_q = 10 kPa) and the `skin` preset
/// (λ ≈ 2 cm: the skin is refined to about 3 mm edges whatever `n`, so `size` sets the cost).
pub fn cases(quick: bool, n: usize, size: f64, seconds: f64) -> Vec<Case> {
    let base = SheetRig {
        n,
        size,
        strain: 0.15,
        weight: 1.0,
        seconds,
        sliver: None,
        hold: 0.0,
    };
    let mut set = CaseSet {
        quick,
        base,
        scene: Scene::default(),
        out: Vec::new(),
    };
    set.push("baseline", "defaults".into(), base, set.scene.clone(), 30.0);
    // The defaults drive the interior by muscles; the tracking driver once at the baseline.
    let mut tracked = set.scene.clone();
    tracked.muscles.source = Some(crate::scene::MuscleSource::None);
    set.push(
        "driver",
        "tracking (muscles.source = none)".into(),
        base,
        tracked,
        30.0,
    );
    set.materials();
    set.loads();
    set.time_steps();
    set.meshes();
    if !quick {
        // The capture-shaped head at twice its performance's weights: its first second.
        set.out.push(Case {
            name: "capture_rig".into(),
            parameter: "rigs/head.glb, weights × 2, first 1 s".into(),
            rig: CaseRig::Head {
                weight_scale: 2.0,
                seconds: 1.0,
            },
            scene: Scene::default(),
            fps: 30.0,
        });
    }
    set.out
}

/// The cases being built: the sweep's size, the base sheet and scene, and the list.
struct CaseSet {
    quick: bool,
    base: SheetRig,
    scene: Scene,
    out: Vec<Case>,
}

impl CaseSet {
    fn push(&mut self, name: &str, parameter: String, rig: SheetRig, scene: Scene, fps: f64) {
        self.out.push(Case {
            name: name.into(),
            parameter,
            rig: CaseRig::Sheet(rig),
            scene,
            fps,
        })
    }

    /// The full range, or its ends when quick.
    fn range<'a>(&self, quick: &'a [f64], full: &'a [f64]) -> &'a [f64] {
        if self.quick {
            quick
        } else {
            full
        }
    }

    /// Stiffness ratios, skin thickness, and a skin far stiffer than the lattice.
    fn materials(&mut self) {
        let (base, scene) = (self.base, self.scene.clone());
        let e_q = scene
            .interior
            .material()
            .expect("default interior is valid")
            .young;
        for &r in self.range(&[10.0, 1e6], &[10.0, 1e2, 1e3, 1e4, 1e5, 1e6]) {
            let mut s = scene.clone();
            s.skin.young = Some(r * e_q);
            self.push("stiffness_ratio", format!("E_x/E_q = {r:e}"), base, s, 30.0);
        }
        for &t in self.range(&[1e-4, 1e-1], &[1e-4, 1e-3, 1e-2, 1e-1]) {
            let mut s = scene.clone();
            s.skin.thickness = Some(t * base.size);
            let what = format!("h = {t:e} × size = {:.1e} m", t * base.size);
            self.push("thickness", what, base, s, 30.0);
        }
        // A skin far stiffer than the lattice: membrane stiffness E_x h ≈ 10⁶ × E_q ℓ; then
        // the same ratio on a thin skin (λ ∝ h (E_x/E_q)^⅓ stays near the sheet's).
        for t in [0.1, 1e-3] {
            let mut s = scene.clone();
            s.skin.young = Some(1e6 * e_q);
            s.skin.thickness = Some(t * base.size);
            let what = format!("E_x/E_q = 1e6, h = {t:e} × size");
            self.push("stiff_skin", what, base, s, 30.0);
        }
    }

    /// Strong compression and extrapolated weights.
    fn loads(&mut self) {
        let (base, scene) = (self.base, self.scene.clone());
        for &c in self.range(&[0.5, 0.7], &[0.3, 0.5, 0.7]) {
            let rig = SheetRig { strain: c, ..base };
            self.push(
                "compression",
                format!("{:.0} %", c * 100.0),
                rig,
                scene.clone(),
                30.0,
            );
        }
        for &w in self.range(&[-1.0, 3.0], &[-1.0, -0.5, 2.0, 3.0]) {
            let rig = SheetRig { weight: w, ..base };
            self.push(
                "weight",
                format!("blend weight → {w}"),
                rig,
                scene.clone(),
                30.0,
            );
        }
    }

    /// Time steps. The pipeline sub-steps a frame by at most dt: steps shorter than a frame
    /// (1/30 s) are sub-steps; for longer ones the sampling rate is 1/dt so that the step
    /// really is dt, on a clip at least two steps long so the strain is really applied.
    fn time_steps(&mut self) {
        let base = self.base;
        for &dt in self.range(&[0.005, 0.2], &[0.005, 0.02, 0.05, 0.1, 0.2]) {
            let mut s = self.scene.clone();
            s.dynamics.dt = Some(dt);
            let rig = SheetRig {
                seconds: base.seconds.max(2.0 * dt),
                ..base
            };
            let fps = if dt < 1.0 / 30.0 { 30.0 } else { 1.0 / dt };
            self.push("time_step", format!("dt = {dt} s"), rig, s, fps);
        }
    }

    /// Degenerate triangles, and a shape that folds the skin over itself (the fold followed
    /// as an out-of-model region).
    fn meshes(&mut self) {
        let base = self.base;
        for &e in self.range(&[1e-4], &[1e-2, 1e-4]) {
            let rig = SheetRig {
                sliver: Some(e),
                ..base
            };
            let what = format!("2 triangles of area {e:e} × ½ℓ²");
            self.push("degenerate_triangle", what, rig, self.scene.clone(), 30.0);
        }
        // Strain 1.5 maps x ↦ x + 1.5 (mid − x) on the left half: it turns over there.
        let rig = SheetRig {
            strain: 1.5,
            ..base
        };
        let what = "left half turned over (strain 150 %)".into();
        self.push("folding_shape", what, rig, self.scene.clone(), 30.0);
    }
}

/// Worst status over frames: the first non-`converged` status and how many frames had a
/// non-converged status, or `converged`.
fn worst<'a>(recs: impl Iterator<Item = &'a StageRecord>) -> (String, usize, f64, usize) {
    let (mut bad, mut first, mut it, mut res, mut n) = (0, None, 0, 0.0f64, 0);
    for r in recs {
        n += 1;
        it += r.iterations;
        res = res.max(r.residual);
        if !r.status.is_converged() {
            bad += 1;
            first.get_or_insert(r.status);
        }
    }
    let s = match (n, first) {
        (0, _) => "skipped".to_string(),
        (_, None) => "converged".to_string(),
        (_, Some(f)) => format!("{f} ({bad}/{n})"),
    };
    (s, it, res, bad)
}

/// How a stability case ended, over all its frames and stages.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum CaseOutcome {
    /// Every stage of every frame converged.
    Converged,
    /// A solver ended with another status in some frame; the outputs are finite.
    NotConverged,
    /// The run stopped with a message before writing anything.
    Refused,
    /// A NaN or infinity in an output: a bug.
    NonFinite,
}

impl std::fmt::Display for CaseOutcome {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            CaseOutcome::Converged => "converged",
            CaseOutcome::NotConverged => "not_converged",
            CaseOutcome::Refused => "refused",
            CaseOutcome::NonFinite => "non_finite",
        })
    }
}

/// Run one case.
pub fn run_case(c: &Case) -> StabilityRow {
    let t = Instant::now();
    let mut row = StabilityRow {
        case: c.name.clone(),
        parameter: c.parameter.clone(),
        outcome: CaseOutcome::Refused,
        interior_status: "-".into(),
        interior_iterations: 0,
        interior_residual: 0.0,
        interior_halvings: 0,
        shell_status: "-".into(),
        shell_iterations: 0,
        shell_residual: 0.0,
        shell_load_steps: 0,
        frames: 0,
        wrinkle_depth_max_m: 0.0,
        wall_s: 0.0,
        non_finite: false,
        message: String::new(),
    };
    let result = c.rig.build().and_then(|rig| {
        pipeline::run(
            &rig,
            &RunOptions::new(c.scene.clone()).fps(c.fps),
            &|_, _, _| {},
        )
    });
    row.wall_s = t.elapsed().as_secs_f64();
    match result {
        Err(e) => row.message = format!("{e:#}"),
        Ok(out) => {
            let pf = &out.report.per_frame;
            let (is, ii, ir, ib) = worst(pf.iter().filter_map(|f| f.interior.as_ref()));
            let (ss, si, sr, sb) = worst(pf.iter().filter_map(|f| f.shell.as_ref()));
            row.interior_status = is;
            row.interior_iterations = ii;
            row.interior_residual = ir;
            row.shell_status = ss;
            row.shell_iterations = si;
            row.shell_residual = sr;
            row.interior_halvings = pf
                .iter()
                .filter_map(|f| f.interior.as_ref())
                .map(|r| r.halvings)
                .sum();
            row.shell_load_steps = pf
                .iter()
                .filter_map(|f| f.shell.as_ref())
                .map(|r| r.load_steps)
                .sum();
            row.frames = pf.len();
            row.wrinkle_depth_max_m = pf.iter().map(|f| f.wrinkle_depth_max_m).fold(0.0, f64::max);
            row.non_finite = out
                .frames
                .iter()
                .chain(&out.smooth)
                .flatten()
                .any(|p| !p.iter().all(|v| v.is_finite()))
                || !row.wrinkle_depth_max_m.is_finite();
            row.outcome = if row.non_finite {
                CaseOutcome::NonFinite
            } else if ib + sb > 0 {
                CaseOutcome::NotConverged
            } else {
                CaseOutcome::Converged
            };
            let outside = out.report.out_of_model.iter().flat_map(|o| o.summary());
            row.message = out
                .report
                .warnings
                .iter()
                .cloned()
                .chain(outside)
                .collect::<Vec<_>>()
                .join(" | ");
        }
    }
    row
}

/// The interior alone (no skin) from an inverted start: a 3 × 3 × 2 block of flesh (2 cm
/// cells, quadratic elements, two bottom node layers pinned) whose free nodes start
/// squeezed through the plane z₀ of the top pinned layer, z ↦ z₀ − ½ (z − z₀) (the upper
/// elements inverted with stretch ½ across their thickness), then `steps` quasi-static
/// solves. Outcome `converged` when the last solve converged and the
/// block came back to its rest shape (largest node distance from rest below 1 % of a cell).
pub fn inverted_interior(steps: usize) -> StabilityRow {
    let t = Instant::now();
    let cell = 0.02;
    let (lattice, pinned, q0) = squeezed_block(cell);
    let rest = lattice.rest_flat();
    let mut row = StabilityRow {
        case: "inverted_start".into(),
        parameter: "interior alone, squeezed to −½ through the pinned layer".into(),
        outcome: CaseOutcome::Refused,
        interior_status: "-".into(),
        interior_iterations: 0,
        interior_residual: 0.0,
        interior_halvings: 0,
        shell_status: "skipped".into(),
        shell_iterations: 0,
        shell_residual: 0.0,
        shell_load_steps: 0,
        frames: 0,
        wrinkle_depth_max_m: 0.0,
        wall_s: 0.0,
        non_finite: false,
        message: String::new(),
    };
    let material = Scene::default()
        .interior
        .material()
        .expect("default interior is valid");
    let result = Interior::new(&lattice, &material).and_then(|interior| {
        BackwardEuler::new(
            interior,
            q0,
            pinned,
            StepSettings {
                dt: 0.02,
                max_newton: 30,
                tolerance: 1e-6,
                lumped_mass: false,
                gravity: [0.0; 3],
                linear_solver: LinearSolver::Auto,
                tangent: crate::fem::Tangent::Consistent,
            },
        )
    });
    let mut be = match result {
        Ok(be) => be,
        Err(e) => {
            row.message = e.to_string();
            row.wall_s = t.elapsed().as_secs_f64();
            return row;
        }
    };
    let (last, bad) = relax(&mut be, steps, &mut row);
    row.non_finite = be.q.iter().any(|v| !v.is_finite());
    let dist = largest_distance(&be.q, &rest);
    row.wrinkle_depth_max_m = 0.0;
    judge_recovery(&mut row, last, bad, dist < 0.01 * cell, dist);
    row.wall_s = t.elapsed().as_secs_f64();
    row
}

/// The block of [`inverted_interior`] with cells of `cell` (m): its lattice, pinned nodes
/// (the two bottom layers) and start positions (m, flat) with the free nodes mirrored to
/// half their height through the top pinned layer.
fn squeezed_block(cell: f64) -> (crate::lattice::Lattice, Vec<bool>, Vec<f64>) {
    let lattice = block_lattice(Vector3::zeros(), cell, [3, 3, 2], ElementOrder::Quadratic);
    let rest = lattice.rest_flat();
    let layers = ElementOrder::Quadratic.per_axis() - 1;
    let pinned: Vec<bool> = lattice.grid.iter().map(|g| g[2] < layers).collect();
    let z0 = lattice
        .grid
        .iter()
        .zip(lattice.rest.iter())
        .filter(|(g, _)| g[2] == layers - 1)
        .map(|(_, p)| p.z)
        .fold(f64::NEG_INFINITY, f64::max);
    let mut q0 = rest.clone();
    for (n, &p) in pinned.iter().enumerate() {
        if !p {
            q0[3 * n + 2] = z0 - 0.5 * (rest[3 * n + 2] - z0);
        }
    }
    (lattice, pinned, q0)
}

/// Up to `steps` quasi-static solves without load, counted in `row` (frames, iterations,
/// last residual; the message on an error, which stops them). Returns the last status and
/// how many solves did not converge.
fn relax(
    be: &mut BackwardEuler,
    steps: usize,
    row: &mut StabilityRow,
) -> (Option<SolveStatus>, usize) {
    let zero = vec![0.0; be.q.len()];
    let mut last = None;
    let mut bad = 0;
    for _ in 0..steps {
        match be.quasi_static(&zero, None) {
            Ok(rep) => {
                row.frames += 1;
                row.interior_iterations += rep.iterations;
                row.interior_residual = rep.residual;
                if rep.status != SolveStatus::Converged {
                    bad += 1;
                }
                last = Some(rep.status);
            }
            Err(e) => {
                row.message = e.to_string();
                break;
            }
        }
    }
    (last, bad)
}

/// Largest distance (m) of a node of `q` from its rest position in `rest` (both flat, m).
fn largest_distance(q: &[f64], rest: &[f64]) -> f64 {
    (0..q.len() / 3)
        .map(|n| {
            Vector3::new(
                q[3 * n] - rest[3 * n],
                q[3 * n + 1] - rest[3 * n + 1],
                q[3 * n + 2] - rest[3 * n + 2],
            )
            .norm()
        })
        .fold(0.0, f64::max)
}

/// Fill in `row`'s interior status, outcome and (unless an error message is there) the
/// distance message, from the last solve status `last`, the `bad` solves, whether the block
/// came `back` to rest and its largest node distance `dist` (m).
fn judge_recovery(
    row: &mut StabilityRow,
    last: Option<SolveStatus>,
    bad: usize,
    back: bool,
    dist: f64,
) {
    row.interior_status = match last {
        None => "-".into(),
        Some(SolveStatus::Converged) => "converged".into(),
        Some(s) => format!("{s} ({bad}/{})", row.frames),
    };
    row.outcome = if row.non_finite {
        CaseOutcome::NonFinite
    } else if last.is_none() {
        CaseOutcome::Refused
    } else if last == Some(SolveStatus::Converged) && back {
        CaseOutcome::Converged
    } else {
        CaseOutcome::NotConverged
    };
    if row.message.is_empty() {
        row.message = format!(
            "largest node distance from rest after {} solve(s): {:.3e} m ({})",
            row.frames,
            dist,
            if back {
                "recovered"
            } else {
                "not recovered: more solves or a smaller load step"
            }
        );
    }
}

/// Run every case of [`cases`] and [`inverted_interior`]; `progress(done, total)` before each.
pub fn run_all(
    quick: bool,
    n: usize,
    size: f64,
    seconds: f64,
    progress: &dyn Fn(usize, usize),
) -> Vec<StabilityRow> {
    let cs = cases(quick, n, size, seconds);
    let total = cs.len() + 1;
    let mut rows = Vec::new();
    for (i, c) in cs.iter().enumerate() {
        progress(i, total);
        rows.push(run_case(c));
    }
    progress(cs.len(), total);
    rows.push(inverted_interior(if quick { 3 } else { 6 }));
    progress(total, total);
    rows
}

/// `s` on one line (line breaks become spaces).
fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// The rows as CSV (header [`CSV_HEADER`]); text fields quoted, on one line.
pub fn to_csv(rows: &[StabilityRow]) -> String {
    let q = |s: &str| format!("\"{}\"", one_line(s).replace('"', "'"));
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{:.3e},{},{},{},{:.3e},{},{},{:.3e},{:.3},{},{}\n",
            r.case,
            q(&r.parameter),
            r.outcome,
            q(&r.interior_status),
            r.interior_iterations,
            r.interior_residual,
            r.interior_halvings,
            q(&r.shell_status),
            r.shell_iterations,
            r.shell_residual,
            r.shell_load_steps,
            r.frames,
            r.wrinkle_depth_max_m,
            r.wall_s,
            r.non_finite,
            q(&r.message)
        ));
    }
    s
}

/// The rows as a markdown table (the message cut to 120 characters).
pub fn to_markdown(rows: &[StabilityRow]) -> String {
    let mut s = String::from(
        "| case | parameter | outcome | interior (it, residual N) | halvings | shell (it, residual N) | load steps | frames | max depth (mm) | time (s) | non-finite | message |\n|---|---|---|---|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let full = one_line(&r.message);
        let mut msg: String = full.chars().take(120).collect();
        if full.chars().count() > 120 {
            msg.push('…');
        }
        s.push_str(&format!(
            "| {} | {} | {} | {} ({}, {:.1e}) | {} | {} ({}, {:.1e}) | {} | {} | {:.3} | {:.2} | {} | {} |\n",
            r.case,
            r.parameter,
            r.outcome,
            r.interior_status,
            r.interior_iterations,
            r.interior_residual,
            r.interior_halvings,
            r.shell_status,
            r.shell_iterations,
            r.shell_residual,
            r.shell_load_steps,
            r.frames,
            r.wrinkle_depth_max_m * 1e3,
            r.wall_s,
            r.non_finite,
            msg.replace('|', "/")
        ));
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_case_has_a_valid_scene_and_the_ranges_reach_their_ends() {
        let cs = cases(true, 8, 0.1, 0.1);
        for c in &cs {
            c.scene.validate().unwrap();
        }
        let names: Vec<&str> = cs.iter().map(|c| c.name.as_str()).collect();
        for n in [
            "stiffness_ratio",
            "thickness",
            "compression",
            "weight",
            "time_step",
            "degenerate_triangle",
            "stiff_skin",
        ] {
            assert!(names.contains(&n), "{n} missing");
        }
        let ratios: Vec<String> = cs
            .iter()
            .filter(|c| c.name == "stiffness_ratio")
            .map(|c| c.parameter.clone())
            .collect();
        assert_eq!(ratios, vec!["E_x/E_q = 1e1", "E_x/E_q = 1e6"]);
    }

    #[test]
    fn worst_status_names_the_first_failure_and_counts() {
        let rec = |s: SolveStatus, it: usize, r: f64| StageRecord {
            status: s,
            iterations: it,
            residual: r,
            ms: 0.0,
            halvings: 0,
            load_steps: 0,
            ..Default::default()
        };
        let v = [
            rec(SolveStatus::Converged, 2, 1e-9),
            rec(SolveStatus::IterationLimit, 60, 1e-3),
            rec(SolveStatus::Stalled, 5, 1e-5),
        ];
        let (s, it, res, bad) = worst(v.iter());
        assert_eq!(s, "iteration_limit (2/3)");
        assert_eq!((it, bad), (67, 2));
        assert_eq!(res, 1e-3);
        assert_eq!(worst([].iter()).0, "skipped");
    }
}
