//! Error against run time (`furrow report tradeoff`): sweep the quality knobs one at a time
//! around the defaults, run each setting, and measure its wall time and its error against the
//! finest setting (all knobs at their fine end at once).
//!
//! Two cases:
//! - a rig (a blend-shape face, or [`sheet_rig`] when none is given): error = distance of each
//!   output vertex to the reference run's output surface (point to nearest triangle), RMS and
//!   max over vertices and frames (m);
//! - the validation slab (a synthetic scene, compressed along x): the same surface distance on
//!   the last frame, and the wavelength error |λ_measured / λ_formula − 1| against
//!   λ = 2π h [(1 − ν_q²) E_x / (3 (1 − ν_x²) E_q)]^(1/3).
//!
//! Wrinkling is a bifurcation: two discretisations may settle on wrinkles of the same
//! wavelength but another phase, so the surface error of a run is bounded by about twice the
//! wrinkle amplitude even when it is "right". The Pareto front and the picks therefore use a
//! phase-free error (the surface distances stay in the CSV):
//! - rig: the wrinkle field w = (wrinkled − blend-shape surface) · n along the blend-shape
//!   surface's normal, its RMS per region (cubes of side 2 λ over the blend-shape surface,
//!   per frame; a region two wavelengths wide holds whole wrinkles, so its RMS does not depend
//!   on where the crests fall), and the relative L2 difference of that amplitude map from the
//!   reference's ([`amplitude_map`], [`amplitude_error`]);
//! - slab: the larger of the relative differences of the last frame's wrinkle amplitude and
//!   measured wavelength from the reference's.

use crate::io::load::{load_bytes, LoadOptions, Rig};
use crate::io::model::{MorphTarget, WeightKeys};
use crate::lattice::geom::closest_point_on_triangle;
use crate::mesh::TriMesh;
use crate::pipeline::frames::FrameRange;
use crate::pipeline::{self, synthetic, RunOptions};
use crate::render::pareto::pareto_front;
use crate::render::plot::{line_chart, Chart, LegendAt, Series, Style};
use crate::scene::Scene;
use anyhow::Context;
use nalgebra::Vector3;
use serde::Serialize;
use std::collections::HashMap;
use std::path::Path;
use std::time::Instant;

/// A flat test sheet rig (see [`sheet_rig`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SheetRig {
    /// Quads per side (the sheet has 2 n² triangles).
    pub n: usize,
    /// Side length (m).
    pub size: f64,
    /// Strain of the blend shape at weight 1: the left half is compressed by it along x, the
    /// right half stretched by it (dimensionless).
    pub strain: f64,
    /// Weight of the blend shape at the end of the clip (1 = the full shape; −0.5 and 2 test
    /// extrapolated weights).
    pub weight: f64,
    /// Clip length (s): the weight ramps linearly from 0 at t = 0 to `weight`.
    pub seconds: f64,
    /// Make two near-zero-area triangles: move vertex (n/2, n/2) along x by (1 − `sliver`)
    /// of an edge, so the triangles it shares with the vertex on its right have area
    /// ½ `sliver` ℓ² (ℓ the edge, m). `None`: a regular sheet.
    pub sliver: Option<f64>,
    /// Seconds the final weight is held after the ramp (the clip then lasts `seconds` +
    /// `hold`).
    pub hold: f64,
}

impl Default for SheetRig {
    /// 24 × 24 quads over 10 cm, 15 % strain reached in 0.3 s.
    fn default() -> Self {
        Self {
            n: 24,
            size: 0.1,
            strain: 0.15,
            weight: 1.0,
            seconds: 0.3,
            sliver: None,
            hold: 0.0,
        }
    }
}

/// A flat sheet rig (x, y in [0, size], z = 0, facing +z) with one blend shape "squeeze"
/// that compresses the left half along x and stretches the right half (see [`SheetRig`]),
/// loaded as a [`Rig`] (its path is `sheet.glb`, only used in messages).
pub fn sheet_rig(s: &SheetRig) -> anyhow::Result<Rig> {
    anyhow::ensure!(s.n >= 2, "the sheet needs at least 2 quads per side");
    let n = s.n;
    let h = s.size / n as f64;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.push(Vector3::new(h * i as f64, h * j as f64, 0.0));
        }
    }
    let id = |i: usize, j: usize| j * (n + 1) + i;
    if let Some(eps) = s.sliver {
        pos[id(n / 2, n / 2)].x += (1.0 - eps) * h;
    }
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let mid = s.size / 2.0;
    let deltas: Vec<Vector3<f64>> = pos
        .iter()
        .map(|p| Vector3::new((p.x - mid).abs() * s.strain, 0.0, 0.0))
        .collect();
    let mesh = TriMesh::new(pos, tris);
    let mut keys = WeightKeys {
        times: vec![0.0, s.seconds],
        weights: vec![vec![0.0], vec![s.weight]],
    };
    if s.hold > 0.0 {
        keys.times.push(s.seconds + s.hold);
        keys.weights.push(vec![s.weight]);
    }
    let target = MorphTarget {
        name: "squeeze".into(),
        positions: deltas,
        normals: None,
    };
    let bytes = crate::io::export::rig_glb("sheet", &mesh, &[target], &keys)?;
    Ok(load_bytes(
        Path::new("sheet.glb"),
        &bytes,
        &LoadOptions::default(),
    )?)
}

/// One setting of the sweep: a scene and what it changes.
#[derive(Debug, Clone)]
pub struct Setting {
    /// The knob changed (`default`, `reference`, or a scene key such as
    /// `interior.cell_size`).
    pub knob: String,
    /// Its value (in the key's unit; NaN for `default` and `reference`).
    pub value: f64,
    /// The scene of this run.
    pub scene: Scene,
}

/// One run of the sweep and its measurements.
#[derive(Debug, Clone, Serialize)]
pub struct TradeoffRun {
    /// `rig` or `slab`.
    pub case: String,
    /// The knob changed (see [`Setting::knob`]).
    pub knob: String,
    /// Its value (scene units, SI).
    pub value: f64,
    /// The defaults.
    pub is_default: bool,
    /// The finest run the others are measured against.
    pub is_reference: bool,
    /// Wall time of the run (s).
    pub wall_s: f64,
    /// RMS distance of the output vertices to the reference surface, over vertices and
    /// frames (m).
    pub rms_m: f64,
    /// Largest such distance (m).
    pub max_m: f64,
    /// Size of the wrinkles themselves: rig, RMS over vertices and frames of the wrinkled
    /// minus the blend-shape surface; slab, the sine-fit amplitude on the last frame (m).
    pub wrinkle_m: f64,
    /// Slab: wavelength measured on the last frame (m).
    pub measured_wavelength_m: Option<f64>,
    /// Slab: λ from the formula (m).
    pub predicted_wavelength_m: Option<f64>,
    /// Slab: |measured / predicted − 1| (dimensionless; 1 when no wrinkles were found).
    pub wavelength_error: Option<f64>,
    /// Phase-free amplitude error against the reference (dimensionless): rig, the relative
    /// L2 difference of the per-region wrinkle RMS maps ([`amplitude_error`]); slab,
    /// |A / A_ref − 1| of the last frame's sine-fit amplitude (1 when either has no wrinkle).
    pub amplitude_error: f64,
    /// The phase-free error the Pareto front and the picks use (dimensionless): rig, the
    /// amplitude error; slab, max(amplitude error, |λ / λ_ref − 1|) with λ the measured
    /// wavelengths (1 when either has no wrinkle).
    pub phase_free_error: f64,
    /// Frames (or slab frames) in which a solver did not converge.
    pub frames_not_converged: usize,
    /// On the Pareto front of (wall time, error) among the non-reference runs of its case.
    pub pareto: bool,
    /// `ok`, or the error message when the run failed.
    pub status: String,
}

impl TradeoffRun {
    /// The knob's value as written in tables: empty for the reference run's missing value.
    pub fn value_text(&self) -> String {
        if self.value.is_finite() {
            format!("{}", self.value)
        } else {
            String::new()
        }
    }
}

/// The CSV header written by [`to_csv`].
pub const CSV_HEADER: &str = "case,knob,value,default,reference,wall_s,rms_m,max_m,wrinkle_m,measured_wavelength_m,predicted_wavelength_m,wavelength_error,amplitude_error,phase_free_error,frames_not_converged,pareto,status";

/// How big a sweep to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SweepSize {
    /// Fewer values per knob and a cheaper reference (for tests and a quick look).
    pub quick: bool,
}

/// Knob values for a rig, around the defaults: (scene key, values), the defaults excluded.
/// The reference takes the finest value of every knob.
fn rig_knobs(quick: bool) -> Vec<(&'static str, Vec<f64>)> {
    if quick {
        vec![
            ("interior.target_cells", vec![100.0, 1000.0]),
            ("skin.vertices_per_wavelength", vec![3.0, 12.0]),
            ("solver.shell_tolerance", vec![1e-3, 1e-8]),
            ("dynamics.dt", vec![0.0334, 0.01]),
        ]
    } else {
        vec![
            ("interior.target_cells", vec![60.0, 200.0, 1000.0, 2000.0]),
            ("skin.vertices_per_wavelength", vec![3.0, 4.5, 9.0, 12.0]),
            ("solver.shell_tolerance", vec![1e-2, 1e-3, 1e-4, 1e-8]),
            ("dynamics.dt", vec![0.0334, 0.01, 0.005]),
        ]
    }
}

/// Knob values for the slab (the skin resolution is `geometry.skin_edge` there).
fn slab_knobs(quick: bool) -> Vec<(&'static str, Vec<f64>)> {
    if quick {
        vec![
            ("interior.cell_size", vec![0.02, 0.005]),
            ("geometry.skin_edge", vec![0.0015, 0.0007]),
            ("solver.shell_tolerance", vec![1e-3, 1e-8]),
        ]
    } else {
        vec![
            ("interior.cell_size", vec![0.02, 0.0067, 0.005]),
            ("geometry.skin_edge", vec![0.002, 0.0015, 0.0007, 0.0005]),
            ("solver.shell_tolerance", vec![1e-2, 1e-3, 1e-4, 1e-8]),
        ]
    }
}

/// Set scene key `knob` to `v`.
fn set_knob(scene: &mut Scene, knob: &str, v: f64) {
    match knob {
        "interior.target_cells" => {
            scene.interior.cell_size = None;
            scene.interior.target_cells = Some(v.round() as usize);
        }
        "interior.cell_size" => {
            scene.interior.target_cells = None;
            scene.interior.cell_size = Some(v);
        }
        "skin.vertices_per_wavelength" => {
            scene.skin.vertices_per_wavelength = Some(v);
            // Enough levels to reach it.
            scene.skin.refine_limit = Some(scene.skin.refine_limit.unwrap_or(2).max(3));
        }
        "solver.shell_tolerance" => scene.solver.shell_tolerance = Some(v),
        "dynamics.dt" => scene.dynamics.dt = Some(v),
        "geometry.skin_edge" => {
            if let Some(g) = scene.geometry.as_mut() {
                g.skin_edge = v;
            }
        }
        _ => unreachable!("unknown knob {knob}"),
    }
}

/// The settings of a sweep: `default`, one per knob value, and `reference` (every knob at
/// its finest value, which is the last value of each list).
fn settings(base: &Scene, knobs: &[(&'static str, Vec<f64>)]) -> Vec<Setting> {
    let mut out = vec![Setting {
        knob: "default".into(),
        value: f64::NAN,
        scene: base.clone(),
    }];
    let mut reference = base.clone();
    for (k, vals) in knobs {
        for &v in vals {
            let mut s = base.clone();
            set_knob(&mut s, k, v);
            out.push(Setting {
                knob: k.to_string(),
                value: v,
                scene: s,
            });
        }
        set_knob(&mut reference, k, *vals.last().expect("values"));
    }
    out.push(Setting {
        knob: "reference".into(),
        value: f64::NAN,
        scene: reference,
    });
    out
}

/// Distance from points to a triangle surface, with a uniform grid over triangle centroids.
pub struct SurfaceDistance<'a> {
    positions: &'a [Vector3<f64>],
    triangles: &'a [[usize; 3]],
    cell: f64,
    grid: HashMap<[i64; 3], Vec<usize>>,
}

impl<'a> SurfaceDistance<'a> {
    /// Index the surface (positions in m).
    pub fn new(positions: &'a [Vector3<f64>], triangles: &'a [[usize; 3]]) -> Self {
        let mut longest = 0.0f64;
        for t in triangles {
            for e in 0..3 {
                longest = longest.max((positions[t[e]] - positions[t[(e + 1) % 3]]).norm());
            }
        }
        let cell = longest.max(1e-12);
        let mut grid: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
        for (i, t) in triangles.iter().enumerate() {
            let c = (positions[t[0]] + positions[t[1]] + positions[t[2]]) / 3.0;
            grid.entry(key(&c, cell)).or_default().push(i);
        }
        Self {
            positions,
            triangles,
            cell,
            grid,
        }
    }

    /// Distance from `p` to the nearest point of the surface (m); infinite for an empty
    /// surface.
    pub fn distance(&self, p: &Vector3<f64>) -> f64 {
        if self.triangles.is_empty() {
            return f64::INFINITY;
        }
        let k = key(p, self.cell);
        let mut best = f64::INFINITY;
        // A triangle within distance d has its centroid within d + cell of p: ring r covers
        // centroids up to r·cell away.
        for r in 0i64.. {
            for dx in -r..=r {
                for dy in -r..=r {
                    for dz in -r..=r {
                        if dx.abs().max(dy.abs()).max(dz.abs()) != r {
                            continue;
                        }
                        if let Some(ts) = self.grid.get(&[k[0] + dx, k[1] + dy, k[2] + dz]) {
                            for &t in ts {
                                let [a, b, c] = self.triangles[t].map(|v| self.positions[v]);
                                let q = closest_point_on_triangle(p, &a, &b, &c);
                                best = best.min((q - p).norm());
                            }
                        }
                    }
                }
            }
            if (r as f64 - 1.0) * self.cell >= best || r > 1_000_000 {
                break;
            }
        }
        best
    }
}

fn key(p: &Vector3<f64>, cell: f64) -> [i64; 3] {
    [0, 1, 2].map(|d| (p[d] / cell).floor() as i64)
}

/// Accumulates distances to a reference surface: (sum of squares, count, max).
#[derive(Debug, Clone, Copy, Default)]
struct ErrorSum {
    sq: f64,
    n: usize,
    max: f64,
}

impl ErrorSum {
    fn add_frame(&mut self, pts: &[Vector3<f64>], ref_pts: &[Vector3<f64>], tris: &[[usize; 3]]) {
        let sd = SurfaceDistance::new(ref_pts, tris);
        for p in pts {
            let d = sd.distance(p);
            self.sq += d * d;
            self.n += 1;
            self.max = self.max.max(d);
        }
    }
    fn rms(&self) -> f64 {
        if self.n == 0 {
            f64::NAN
        } else {
            (self.sq / self.n as f64).sqrt()
        }
    }
}

/// Sweep the quality knobs on a rig, sampled at `fps` and limited to `frames` (the pipeline
/// simulates from frame 0 up to the range's end). `progress(done, total)` is called before
/// each run.
pub fn rig_sweep(
    rig: &Rig,
    base: &Scene,
    fps: f64,
    frames: Option<FrameRange>,
    quick: bool,
    progress: &dyn Fn(usize, usize),
) -> anyhow::Result<Vec<TradeoffRun>> {
    let set = settings(base, &rig_knobs(quick));
    let total = set.len();
    let mut outputs = Vec::new();
    for (i, s) in set.iter().enumerate() {
        progress(i, total);
        let opts = RunOptions {
            preroll: None,
            scene: s.scene.clone(),
            scene_path: None,
            fps,
            frames,
        };
        let t = Instant::now();
        let r = pipeline::run(rig, &opts, &|_, _, _| {});
        outputs.push((t.elapsed().as_secs_f64(), r));
    }
    progress(total, total);
    let (_, reference) = outputs.last().expect("reference run");
    let reference = match reference {
        Ok(r) => r,
        Err(e) => {
            anyhow::bail!("the reference (finest) run failed, nothing to measure against: {e:#}")
        }
    };
    let region = region_size(reference);
    let ref_map = amplitude_map(reference, region);
    let mut rows = Vec::new();
    for (s, (wall, r)) in set.iter().zip(&outputs) {
        let mut row = blank_row("rig", s, *wall);
        match r {
            Ok(out) => {
                let mut e = ErrorSum::default();
                for (f, rf) in out.frames.iter().zip(&reference.frames) {
                    e.add_frame(f, rf, &reference.triangles);
                }
                row.rms_m = e.rms();
                row.max_m = e.max;
                row.wrinkle_m = wrinkle_rms(out);
                row.amplitude_error = amplitude_error(&amplitude_map(out, region), &ref_map);
                row.phase_free_error = row.amplitude_error;
                row.frames_not_converged = out.report.totals.frames_not_converged;
            }
            Err(e) => row.status = format!("{e:#}"),
        }
        rows.push(row);
    }
    mark_pareto(&mut rows, |r| r.phase_free_error);
    Ok(rows)
}

fn blank_row(case: &str, s: &Setting, wall: f64) -> TradeoffRun {
    TradeoffRun {
        case: case.into(),
        knob: s.knob.clone(),
        value: s.value,
        is_default: s.knob == "default",
        is_reference: s.knob == "reference",
        wall_s: wall,
        rms_m: f64::NAN,
        max_m: f64::NAN,
        wrinkle_m: f64::NAN,
        measured_wavelength_m: None,
        predicted_wavelength_m: None,
        wavelength_error: None,
        amplitude_error: f64::NAN,
        phase_free_error: f64::NAN,
        frames_not_converged: 0,
        pareto: false,
        status: "ok".into(),
    }
}

/// Mark the Pareto front of (wall time, `err`) among the non-reference successful runs.
fn mark_pareto(rows: &mut [TradeoffRun], err: impl Fn(&TradeoffRun) -> f64) {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| {
            if r.is_reference || r.status != "ok" {
                (f64::NAN, f64::NAN)
            } else {
                (r.wall_s, err(r))
            }
        })
        .collect();
    for i in pareto_front(&pts) {
        rows[i].pareto = true;
    }
}

/// The validation slab of the tradeoff: latex (h = 0.3 mm) on gel, compressed 8 % along x,
/// λ ≈ 7.8 mm. `quick`: 6 × 1.2 × 2 cm and 4 frames; else 12 × 4 × 2 cm and 8 frames.
pub fn slab_scene(quick: bool) -> Scene {
    let (size, frames) = if quick {
        ("[0.06, 0.012, 0.02]", 4)
    } else {
        ("[0.12, 0.04, 0.02]", 8)
    };
    let text = format!(
        "name = \"slab\"\n[skin]\npreset = \"latex\"\nthickness = 0.0003\n[interior]\npreset = \"gel\"\n\
         cell_size = 0.01\n[geometry]\nkind = \"slab\"\nsize = {size}\nskin_edge = 0.001\n\
         [load]\ncompression = 0.08\nframes = {frames}\n"
    );
    Scene::parse(&text, "built-in slab").expect("the built-in slab scene is valid")
}

/// Sweep the quality knobs on the slab scene (see [`slab_scene`]).
pub fn slab_sweep(
    base: &Scene,
    quick: bool,
    progress: &dyn Fn(usize, usize),
) -> anyhow::Result<Vec<TradeoffRun>> {
    let set = settings(base, &slab_knobs(quick));
    let total = set.len();
    let mut outputs = Vec::new();
    for (i, s) in set.iter().enumerate() {
        progress(i, total);
        let t = Instant::now();
        let r = synthetic::run_scene(&s.scene, &|_, _| {});
        outputs.push((t.elapsed().as_secs_f64(), r));
    }
    progress(total, total);
    let reference = match &outputs.last().expect("reference run").1 {
        Ok(r) => r,
        Err(e) => anyhow::bail!(
            "the reference (finest) slab run failed, nothing to measure against: {e:#}"
        ),
    };
    let ref_copy = &reference.copies[0];
    let mut rows = Vec::new();
    for (s, (wall, r)) in set.iter().zip(&outputs) {
        let mut row = blank_row("slab", s, *wall);
        match r {
            Ok(out) => {
                let mut e = ErrorSum::default();
                if let (Some(f), Some(rf)) = (out.frames.last(), reference.frames.last()) {
                    e.add_frame(f, rf, &reference.mesh.triangles);
                }
                row.rms_m = e.rms();
                row.max_m = e.max;
                let c = &out.copies[0];
                row.wrinkle_m = c.amplitude_m.unwrap_or(0.0);
                row.measured_wavelength_m = c.measured_wavelength_m;
                row.predicted_wavelength_m = Some(c.predicted_wavelength_m);
                row.wavelength_error = Some(
                    c.measured_wavelength_m
                        .map_or(1.0, |m| (m / c.predicted_wavelength_m - 1.0).abs()),
                );
                row.frames_not_converged = c.frames_not_converged;
                row.amplitude_error = relative_change(c.amplitude_m, ref_copy.amplitude_m);
                row.phase_free_error = row.amplitude_error.max(relative_change(
                    c.measured_wavelength_m,
                    ref_copy.measured_wavelength_m,
                ));
            }
            Err(e) => row.status = format!("{e:#}"),
        }
        rows.push(row);
    }
    mark_pareto(&mut rows, |r| r.phase_free_error);
    Ok(rows)
}

fn opt(v: Option<f64>) -> String {
    v.map_or(String::new(), |x| format!("{x:.6e}"))
}

/// The runs as CSV (header [`CSV_HEADER`]); the status is quoted.
pub fn to_csv(rows: &[TradeoffRun]) -> String {
    let mut s = String::from(CSV_HEADER);
    s.push('\n');
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{:.4},{:.6e},{:.6e},{:.6e},{},{},{},{:.6e},{:.6e},{},{},\"{}\"\n",
            r.case,
            r.knob,
            r.value_text(),
            r.is_default,
            r.is_reference,
            r.wall_s,
            r.rms_m,
            r.max_m,
            r.wrinkle_m,
            opt(r.measured_wavelength_m),
            opt(r.predicted_wavelength_m),
            opt(r.wavelength_error),
            r.amplitude_error,
            r.phase_free_error,
            r.frames_not_converged,
            r.pareto,
            r.status
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" ")
                .replace('"', "'")
        ));
    }
    s
}

/// The log-log chart of error against wall time for one case: every run per knob, the
/// Pareto front, the default highlighted. `err` picks the error (and `y_label` names it).
pub fn chart(
    rows: &[TradeoffRun],
    title: &str,
    y_label: &str,
    err: fn(&TradeoffRun) -> f64,
) -> Chart {
    let ok: Vec<&TradeoffRun> = rows
        .iter()
        .filter(|r| r.status == "ok" && !r.is_reference)
        .collect();
    let mut knobs: Vec<&str> = Vec::new();
    for r in &ok {
        if !r.is_default && !knobs.contains(&r.knob.as_str()) {
            knobs.push(&r.knob);
        }
    }
    let mut series: Vec<Series> = knobs
        .iter()
        .map(|k| {
            let mut pts: Vec<(f64, f64)> = ok
                .iter()
                .filter(|r| r.knob == *k)
                .map(|r| (r.wall_s, err(r)))
                .collect();
            pts.sort_by(|a, b| a.0.total_cmp(&b.0));
            Series::new(*k, pts, Style::Points)
        })
        .collect();
    let all: Vec<(f64, f64)> = ok.iter().map(|r| (r.wall_s, err(r))).collect();
    series.push(Series::pareto_front("Pareto front", &all));
    if let Some(d) = ok.iter().find(|r| r.is_default) {
        let mut s = Series::new("default", vec![(d.wall_s, err(d))], Style::Points);
        s.highlight = true;
        series.push(s);
    }
    Chart {
        title: title.into(),
        x_label: "wall time (s)".into(),
        y_label: y_label.into(),
        log_x: true,
        log_y: true,
        series,
        legend: LegendAt::Auto,
    }
}

/// Write the chart of `rows` to `path` (PNG).
pub fn write_chart(
    path: &Path,
    rows: &[TradeoffRun],
    title: &str,
    y_label: &str,
    err: fn(&TradeoffRun) -> f64,
) -> anyhow::Result<()> {
    line_chart(path, &chart(rows, title, y_label, err))
        .with_context(|| format!("{}: writing the chart", path.display()))
}

/// A recommended setting and why.
#[derive(Debug, Clone, Serialize)]
pub struct Pick {
    /// `preview` or `final`.
    pub purpose: String,
    /// The knob and value (`default`, `reference`, or `key = value`).
    pub setting: String,
    /// Its wall time (s) and error (the case's error measure).
    pub wall_s: f64,
    /// Its error (m for the rig, relative for the slab's wavelength).
    pub error: f64,
    /// The rule that picked it.
    pub rule: String,
}

fn describe(r: &TradeoffRun) -> String {
    if r.is_default || r.is_reference {
        r.knob.clone()
    } else {
        format!("{} = {}", r.knob, r.value)
    }
}

/// Preview and final picks: the fastest successful non-reference run whose error is at most
/// `preview_tol` (resp. `final_tol`); the reference when none is. `err` is the case's error.
pub fn picks(
    rows: &[TradeoffRun],
    err: fn(&TradeoffRun) -> f64,
    preview_tol: f64,
    final_tol: f64,
    unit: &str,
) -> Vec<Pick> {
    let mut out = Vec::new();
    for (purpose, tol) in [("preview", preview_tol), ("final", final_tol)] {
        let best = rows
            .iter()
            .filter(|r| r.status == "ok" && !r.is_reference && err(r) <= tol)
            .min_by(|a, b| a.wall_s.total_cmp(&b.wall_s))
            .or_else(|| rows.iter().find(|r| r.is_reference));
        if let Some(r) = best {
            out.push(Pick {
                purpose: purpose.into(),
                setting: describe(r),
                wall_s: r.wall_s,
                error: if r.is_reference { 0.0 } else { err(r) },
                rule: format!("fastest run with error ≤ {tol:.3e} {unit}"),
            });
        }
    }
    out
}

/// Wrinkle amplitude scale of a rig run: RMS over vertices and frames of the wrinkled minus
/// the blend-shape-only surface (m). Used to set the rig's error tolerances.
pub fn wrinkle_rms(out: &pipeline::RunOutput) -> f64 {
    let (mut s, mut n) = (0.0, 0usize);
    for (f, g) in out.frames.iter().zip(&out.smooth) {
        for (p, q) in f.iter().zip(g) {
            s += (p - q).norm_squared();
            n += 1;
        }
    }
    if n == 0 {
        0.0
    } else {
        (s / n as f64).sqrt()
    }
}

/// |a / b − 1| of two optional positive measurements (a wrinkle amplitude or wavelength, m);
/// 1 when either is missing or not positive (no wrinkle counts as entirely wrong), 0 when
/// both are missing (neither run wrinkled).
pub fn relative_change(a: Option<f64>, b: Option<f64>) -> f64 {
    match (a, b) {
        (Some(a), Some(b)) if a > 0.0 && b > 0.0 => (a / b - 1.0).abs(),
        (None, None) => 0.0,
        _ => 1.0,
    }
}

/// Side (m) of the regions of [`amplitude_map`] for a run: two critical wavelengths of its
/// report, so each region holds whole wrinkles; when no skin was simulated (λ not finite),
/// an eighth of the largest extent of the first blend-shape frame.
pub fn region_size(out: &pipeline::RunOutput) -> f64 {
    let lambda = out.report.wavelength_m;
    if lambda.is_finite() && lambda > 0.0 {
        return 2.0 * lambda;
    }
    let Some(first) = out.smooth.first() else {
        return 1.0;
    };
    let (mut lo, mut hi) = (
        Vector3::repeat(f64::INFINITY),
        Vector3::repeat(f64::NEG_INFINITY),
    );
    for p in first {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let extent = (hi - lo).max();
    if extent.is_finite() && extent > 0.0 {
        extent / 8.0
    } else {
        1.0
    }
}

/// Wrinkle amplitude per region and frame: for each written frame, a map from a region
/// (cube of side `region` m, indexed by the floor of the blend-shape position / `region`) to
/// (Σ A w² (m⁴), Σ A (m²)), with w = (wrinkled − blend-shape position) · n the wrinkle
/// height along the blend-shape surface's unit vertex normal n and A the vertex's share of
/// that surface's area (a third of its triangles'): an RMS over the surface, so meshes of
/// different resolution (a skin refined only where it is simulated) weigh alike.
#[derive(Debug, Clone)]
pub struct AmplitudeMap {
    /// Region side (m).
    pub region: f64,
    /// Per frame: region → (Σ A w² in m⁴, Σ A in m²).
    pub frames: Vec<HashMap<[i64; 3], (f64, f64)>>,
}

impl AmplitudeMap {
    /// Build from per-frame wrinkled and blend-shape positions (m) of the same vertices and
    /// the triangles that give the normals.
    pub fn new(
        frames: &[Vec<Vector3<f64>>],
        smooth: &[Vec<Vector3<f64>>],
        triangles: &[[usize; 3]],
        region: f64,
    ) -> Self {
        let topo = TriMesh {
            positions: Vec::new(),
            triangles: triangles.to_vec(),
        };
        let maps = frames
            .iter()
            .zip(smooth)
            .map(|(f, g)| {
                let normals = topo.vertex_normals_of(g);
                let area = topo.vertex_areas_of(g);
                let mut m: HashMap<[i64; 3], (f64, f64)> = HashMap::new();
                for (((p, q), n), a) in f.iter().zip(g).zip(&normals).zip(&area) {
                    let w = (p - q).dot(n);
                    let e = m.entry(key(q, region)).or_insert((0.0, 0.0));
                    e.0 += a * w * w;
                    e.1 += a;
                }
                m
            })
            .collect();
        Self {
            region,
            frames: maps,
        }
    }
}

/// The [`AmplitudeMap`] of a rig run with regions of side `region` (m).
pub fn amplitude_map(out: &pipeline::RunOutput, region: f64) -> AmplitudeMap {
    AmplitudeMap::new(&out.frames, &out.smooth, &out.triangles, region)
}

/// Phase-free relative error of a run's wrinkle amplitude map against the reference's:
/// √(Σ A_ref (a − a_ref)² / Σ A_ref a_ref²) over frames and the reference's regions, with a
/// the region's area-weighted RMS wrinkle height (m) and A_ref the reference's surface area
/// there (so regions weigh by their size whatever either run's resolution). A region the run lacks counts
/// as a = 0. Dimensionless: 0 for the same amplitudes wherever the crests are, 1 for no
/// wrinkles; 0 when the reference has no wrinkles and neither has the run.
pub fn amplitude_error(run: &AmplitudeMap, reference: &AmplitudeMap) -> f64 {
    let (mut num, mut den) = (0.0, 0.0);
    for (k, rf) in reference.frames.iter().enumerate() {
        let empty = HashMap::new();
        let rn = run.frames.get(k).unwrap_or(&empty);
        // In key order: the sums do not depend on the hash map's iteration order.
        let mut keys: Vec<&[i64; 3]> = rf.keys().collect();
        keys.sort_unstable();
        for key in keys {
            let (sq, area) = rf[key];
            if area <= 0.0 {
                continue;
            }
            let a_ref = (sq / area).sqrt();
            let a = rn
                .get(key)
                .filter(|&&(_, m)| m > 0.0)
                .map_or(0.0, |&(s, m)| (s / m).sqrt());
            num += area * (a - a_ref).powi(2);
            den += area * a_ref * a_ref;
        }
    }
    if den > 0.0 {
        (num / den).sqrt()
    } else if num > 0.0 {
        1.0
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn surface_distance_matches_a_plane() {
        // A 10 × 10 grid in z = 0 over [0, 1]²; points above it at height d: distance d.
        let n = 10;
        let mut pos = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                pos.push(Vector3::new(i as f64 / n as f64, j as f64 / n as f64, 0.0));
            }
        }
        let mut tris = Vec::new();
        for j in 0..n {
            for i in 0..n {
                let id = |i: usize, j: usize| j * (n + 1) + i;
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let sd = SurfaceDistance::new(&pos, &tris);
        for (p, want) in [
            (Vector3::new(0.33, 0.71, 0.02), 0.02),
            (Vector3::new(0.5, 0.5, -0.3), 0.3),
            (Vector3::new(0.05, 0.95, 2.0), 2.0),
            // Outside the square: distance to the edge x = 1.
            (Vector3::new(1.4, 0.5, 0.3), 0.5),
        ] {
            let d = sd.distance(&p);
            assert!((d - want).abs() < 1e-12, "{p:?}: {d} vs {want}");
        }
    }

    #[test]
    fn settings_change_one_knob_and_the_reference_takes_the_finest() {
        let base = Scene::default();
        let knobs = rig_knobs(true);
        let s = settings(&base, &knobs);
        assert_eq!(s.len(), 2 + knobs.iter().map(|k| k.1.len()).sum::<usize>());
        assert_eq!(s[0].knob, "default");
        let r = &s.last().unwrap().scene;
        assert_eq!(r.interior.target_cells, Some(1000));
        assert_eq!(r.skin.vertices_per_wavelength, Some(12.0));
        assert_eq!(r.solver.shell_tolerance, Some(1e-8));
        assert_eq!(r.dynamics.dt, Some(0.01));
        let dt = s.iter().find(|x| x.knob == "dynamics.dt").unwrap();
        assert_eq!(dt.scene.solver.shell_tolerance, None);
        for x in &s {
            x.scene.validate().unwrap();
        }
    }

    #[test]
    fn picks_take_the_fastest_run_within_tolerance() {
        let mk = |knob: &str, t: f64, e: f64| TradeoffRun {
            rms_m: e,
            ..blank_row(
                "rig",
                &Setting {
                    knob: knob.into(),
                    value: 1.0,
                    scene: Scene::default(),
                },
                t,
            )
        };
        let mut rows = vec![
            mk("default", 2.0, 1e-4),
            mk("a", 1.0, 5e-4),
            mk("b", 0.5, 2e-3),
            mk("c", 4.0, 1e-5),
            mk("reference", 9.0, 0.0),
        ];
        mark_pareto(&mut rows, |r| r.rms_m);
        let front: Vec<bool> = rows.iter().map(|r| r.pareto).collect();
        assert_eq!(front, vec![true, true, true, true, false]);
        let p = picks(&rows, |r| r.rms_m, 1e-3, 5e-5, "m");
        assert_eq!(p[0].setting, "a = 1");
        assert_eq!(p[1].setting, "c = 1");
        let p = picks(&rows, |r| r.rms_m, 1e-3, 1e-9, "m");
        assert_eq!(p[1].setting, "reference");
    }

    /// Wrinkled positions, smooth positions and triangles of a test surface.
    type Wrinkled = (Vec<Vector3<f64>>, Vec<Vector3<f64>>, Vec<[usize; 3]>);

    /// A flat grid (z = 0, x in [0, 4), y in [0, 2)) with a wrinkle w = A sin(2π x / λ + φ)
    /// along its normal: (wrinkled, smooth, triangles).
    fn wrinkled_grid(a: f64, lambda: f64, phi: f64) -> Wrinkled {
        let xs: Vec<f64> = (0..80).map(|i| i as f64 * 0.05).collect();
        wrinkled_grid_at(&xs, |x| {
            a * (2.0 * std::f64::consts::PI * x / lambda + phi).sin()
        })
    }

    /// A flat grid with columns at `xs` and rows 0.05 apart (y in [0, 2)), displaced along
    /// its normal by w(x): (wrinkled, smooth, triangles).
    fn wrinkled_grid_at(xs: &[f64], w: impl Fn(f64) -> f64) -> Wrinkled {
        let (nx, ny, h) = (xs.len(), 40, 0.05);
        let mut smooth = Vec::new();
        for j in 0..ny {
            for &x in xs {
                smooth.push(Vector3::new(x, j as f64 * h, 0.0));
            }
        }
        let id = |i: usize, j: usize| j * nx + i;
        let mut tris = Vec::new();
        for j in 0..ny - 1 {
            for i in 0..nx - 1 {
                tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
                tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
            }
        }
        let wrinkled = smooth.iter().map(|p| p + Vector3::z() * w(p.x)).collect();
        (wrinkled, smooth, tris)
    }

    /// A region half wrinkled and half flat scores the same whether its wrinkled half is
    /// sampled as densely as the rest or four times as densely (a skin refined only where it
    /// is simulated): the RMS is over area, not over vertices (counting vertices gave 0.26).
    #[test]
    fn amplitude_error_does_not_depend_on_the_resolution() {
        let w = |x: f64| {
            if x < 2.0 {
                0.01 * (2.0 * std::f64::consts::PI * x / 0.5).sin()
            } else {
                0.0
            }
        };
        let uniform: Vec<f64> = (0..80).map(|i| i as f64 * 0.05).collect();
        let refined: Vec<f64> = (0..160)
            .map(|i| i as f64 * 0.0125)
            .chain((40..80).map(|i| i as f64 * 0.05))
            .collect();
        let map = |xs: &[f64]| {
            let (wr, s, t) = wrinkled_grid_at(xs, w);
            AmplitudeMap::new(&[wr], &[s], &t, 4.0)
        };
        let e = amplitude_error(&map(&refined), &map(&uniform));
        assert!(e < 0.02, "{e}");
    }

    /// The amplitude error is phase-free: wrinkles shifted by a quarter wavelength (whose
    /// surface distance is as large as the wrinkles) score ~0; regions of 2.5 wavelengths
    /// bound the phase dependence of a region's mean square by 1/(4π · 2.5) ≈ 3 %; a 20 %
    /// larger amplitude scores 0.2; no wrinkles score 1.
    #[test]
    fn amplitude_error_ignores_the_phase_and_sees_the_size() {
        let map = |a: f64, lambda: f64, phi: f64| {
            let (w, s, t) = wrinkled_grid(a, lambda, phi);
            AmplitudeMap::new(&[w], &[s], &t, 2.0)
        };
        let a = 0.01;
        for lambda in [1.0, 0.8] {
            let reference = map(a, lambda, 0.0);
            let shifted = amplitude_error(&map(a, lambda, 0.5 * std::f64::consts::PI), &reference);
            assert!(shifted < 0.05, "λ = {lambda}: shifted error {shifted}");
            let bigger = amplitude_error(&map(1.2 * a, lambda, 0.3), &reference);
            assert!(
                (bigger - 0.2).abs() < 0.03,
                "λ = {lambda}: 1.2 A gives {bigger}"
            );
            let none = amplitude_error(&map(0.0, lambda, 0.0), &reference);
            assert!((none - 1.0).abs() < 1e-12, "no wrinkles give {none}");
            assert!(amplitude_error(&reference, &reference) < 1e-12);
        }
        // Regions of whole periods with whole sample counts: phase-free but for the grid's
        // border columns, which hold half a column's area (0.7 %).
        let e = amplitude_error(&map(a, 1.0, 1.0), &map(a, 1.0, 0.0));
        assert!(e < 0.01, "{e}");
        assert_eq!(relative_change(Some(2.0), Some(1.0)), 1.0);
        assert_eq!(relative_change(None, Some(1.0)), 1.0);
        assert_eq!(relative_change(None, None), 0.0);
        assert!((relative_change(Some(0.9), Some(1.0)) - 0.1).abs() < 1e-12);
    }
}
