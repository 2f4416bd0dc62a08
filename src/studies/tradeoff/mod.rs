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

mod amplitude;
mod distance;
mod report;
mod sheet;

pub use amplitude::{
    amplitude_error, amplitude_map, region_size, relative_change, wrinkle_rms, AmplitudeMap,
};
pub use distance::SurfaceDistance;
pub use report::{chart, picks, to_csv, write_chart, Pick, CSV_HEADER};
pub use sheet::{sheet_rig, SheetRig};

use crate::io::load::Rig;
use crate::pipeline::frames::FrameRange;
use crate::pipeline::{self, synthetic, RunOptions};
use crate::render::pareto::pareto_front;
use crate::scene::Scene;
use distance::ErrorSum;
use serde::Serialize;
use std::time::Instant;

/// What a setting of the sweep changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Knob {
    /// Nothing: the scene's defaults.
    Default,
    /// Every knob at its finest value: the run the others are measured against.
    Reference,
    /// One scene key (such as `interior.cell_size`), the others at their defaults.
    Key(&'static str),
}

impl Knob {
    /// The knob's name as tables write it: `default`, `reference` or the scene key.
    pub fn name(self) -> &'static str {
        match self {
            Knob::Default => "default",
            Knob::Reference => "reference",
            Knob::Key(key) => key,
        }
    }
}

/// How a run of the sweep ended.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RunStatus {
    /// The run finished and was measured.
    Ok,
    /// The run failed (its measurements stay NaN).
    Failed {
        /// The run's error message.
        error: String,
    },
}

impl RunStatus {
    /// Whether the run finished and was measured.
    pub fn is_ok(&self) -> bool {
        matches!(self, RunStatus::Ok)
    }
}

impl std::fmt::Display for RunStatus {
    /// `ok`, or the error message.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunStatus::Ok => f.write_str("ok"),
            RunStatus::Failed { error } => f.write_str(error),
        }
    }
}

impl Serialize for RunStatus {
    /// As its text ([`std::fmt::Display`]): `"ok"` or the error message.
    fn serialize<S: serde::Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

/// One setting of the sweep: a scene and what it changes.
#[derive(Debug, Clone)]
pub struct Setting {
    /// The knob changed.
    pub knob: Knob,
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
    /// The knob changed, by name ([`Knob::name`]).
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
    /// Whether the run finished, or its error.
    pub status: RunStatus,
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
        knob: Knob::Default,
        value: f64::NAN,
        scene: base.clone(),
    }];
    let mut reference = base.clone();
    for (k, vals) in knobs {
        for &v in vals {
            let mut s = base.clone();
            set_knob(&mut s, k, v);
            out.push(Setting {
                knob: Knob::Key(k),
                value: v,
                scene: s,
            });
        }
        set_knob(&mut reference, k, *vals.last().expect("values"));
    }
    out.push(Setting {
        knob: Knob::Reference,
        value: f64::NAN,
        scene: reference,
    });
    out
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
            Err(e) => row.status = failed(e),
        }
        rows.push(row);
    }
    mark_pareto(&mut rows, |r| r.phase_free_error);
    Ok(rows)
}

/// The status of a run that failed with `e`.
fn failed(e: &anyhow::Error) -> RunStatus {
    RunStatus::Failed {
        error: format!("{e:#}"),
    }
}

/// The row of setting `s` of `case` that took `wall` seconds, before its measurements.
fn blank_row(case: &str, s: &Setting, wall: f64) -> TradeoffRun {
    TradeoffRun {
        case: case.into(),
        knob: s.knob.name().into(),
        value: s.value,
        is_default: s.knob == Knob::Default,
        is_reference: s.knob == Knob::Reference,
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
        status: RunStatus::Ok,
    }
}

/// Mark the Pareto front of (wall time, `err`) among the non-reference successful runs.
fn mark_pareto(rows: &mut [TradeoffRun], err: impl Fn(&TradeoffRun) -> f64) {
    let pts: Vec<(f64, f64)> = rows
        .iter()
        .map(|r| {
            if r.is_reference || !r.status.is_ok() {
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
            Err(e) => row.status = failed(e),
        }
        rows.push(row);
    }
    mark_pareto(&mut rows, |r| r.phase_free_error);
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn settings_change_one_knob_and_the_reference_takes_the_finest() {
        let base = Scene::default();
        let knobs = rig_knobs(true);
        let s = settings(&base, &knobs);
        assert_eq!(s.len(), 2 + knobs.iter().map(|k| k.1.len()).sum::<usize>());
        assert_eq!(s[0].knob, Knob::Default);
        let r = &s.last().unwrap().scene;
        assert_eq!(r.interior.target_cells, Some(1000));
        assert_eq!(r.skin.vertices_per_wavelength, Some(12.0));
        assert_eq!(r.solver.shell_tolerance, Some(1e-8));
        assert_eq!(r.dynamics.dt, Some(0.01));
        let dt = s
            .iter()
            .find(|x| x.knob == Knob::Key("dynamics.dt"))
            .unwrap();
        assert_eq!(dt.scene.solver.shell_tolerance, None);
        for x in &s {
            x.scene.validate().unwrap();
        }
    }
}
