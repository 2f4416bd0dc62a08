//! Muscles against tracking: the same rig and frames driven by fitted muscle activations
//! (`muscles.source = "auto"`) and by tracking the blended surface (`"none"`), in one
//! process: how well each generated muscle makes its shape, how well the activations fit the
//! frames, and how far apart the wrinkles are (phase-free amplitude per 2λ region,
//! [`super::tradeoff`]).

use super::tradeoff::{amplitude_error, amplitude_map, region_size, AmplitudeMap};
use crate::io::load::Rig;
use crate::pipeline::record::Stage;
use crate::pipeline::{self, RunOptions, RunOutput};
use crate::scene::MuscleSource;
use serde::Serialize;

/// One run of the comparison.
#[derive(Debug, Clone, Serialize)]
pub struct DriverRun {
    /// `muscles` or `tracking`.
    pub driver: String,
    /// Wall time of the run (s).
    pub wall_s: f64,
    /// Milliseconds in the `muscles` set-up stage (0 for tracking).
    pub muscles_setup_ms: f64,
    /// Mean milliseconds of the per-frame activation fit (QP and tracking relief).
    pub fit_ms_mean: f64,
    /// Largest per-frame fit time (ms).
    pub fit_ms_max: f64,
    /// Mean RMS fit residual over the frames (m; NaN for tracking).
    pub fit_residual_mean_m: f64,
    /// Frames not converged in some stage.
    pub frames_not_converged: usize,
    /// Largest wrinkle depth over the frames (m).
    pub depth_max_m: f64,
    /// Mean over the frames of the interior's RMS miss of the artist's shape (m,
    /// [`crate::pipeline::record::FrameRecord::shape_miss_m`]).
    pub shape_miss_mean_m: f64,
    /// Mean over the frames of the target's RMS displacement from rest (m): the miss's scale.
    pub shape_motion_mean_m: f64,
}

/// The comparison: both runs and the wrinkles' agreement.
#[derive(Debug, Clone, Serialize)]
pub struct DriverComparison {
    /// Tracking factor κ of the reference run when set by `--tracking` (else the scene's).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub reference_tracking: Option<f64>,
    /// Tracking (the reference) and muscles.
    pub runs: Vec<DriverRun>,
    /// Phase-free relative difference of the muscle-driven wrinkle amplitude per region from
    /// the tracking-driven one (dimensionless).
    pub amplitude_error: f64,
    /// Of the regions where tracking wrinkles (amplitude above a tenth of its largest), the
    /// share where the muscles wrinkle too, and the reverse.
    pub shared_regions: [f64; 2],
    /// Region side (m), 2λ.
    pub region_m: f64,
}

fn run_with(
    rig: &Rig,
    opts: &RunOptions,
    source: MuscleSource,
    tracking: Option<f64>,
) -> anyhow::Result<(DriverRun, RunOutput)> {
    let mut o = opts.clone();
    o.scene.muscles.source = Some(source.clone());
    if tracking.is_some() {
        o.scene.interior.tracking = tracking;
    }
    let out = pipeline::run(rig, &o, &|_, _, _| {})?;
    let r = &out.report;
    let fits: Vec<(f64, f64)> = r
        .per_frame
        .iter()
        .filter_map(|f| f.fit.as_ref().map(|s| (s.ms, s.residual)))
        .collect();
    let n = fits.len().max(1) as f64;
    let frames = r.per_frame.len().max(1) as f64;
    let mean = |f: fn(&crate::pipeline::record::FrameRecord) -> f64| {
        r.per_frame.iter().map(f).sum::<f64>() / frames
    };
    let muscles_setup_ms = r
        .stage(Stage::Muscles)
        .filter(|s| s.is_ran())
        .map_or(0.0, |s| s.ms);
    let run = DriverRun {
        driver: if source == MuscleSource::None {
            "tracking"
        } else {
            "muscles"
        }
        .into(),
        wall_s: r.totals.wall_s,
        muscles_setup_ms,
        fit_ms_mean: fits.iter().map(|f| f.0).sum::<f64>() / n,
        fit_ms_max: fits.iter().map(|f| f.0).fold(0.0, f64::max),
        fit_residual_mean_m: if fits.is_empty() {
            f64::NAN
        } else {
            fits.iter().map(|f| f.1).sum::<f64>() / n
        },
        frames_not_converged: r.totals.frames_not_converged,
        depth_max_m: r
            .per_frame
            .iter()
            .map(|f| f.wrinkle_depth_max_m)
            .fold(0.0, f64::max),
        shape_miss_mean_m: mean(|f| f.shape_miss_m),
        shape_motion_mean_m: mean(|f| f.shape_motion_m),
    };
    Ok((run, out))
}

/// Run `opts` on `rig` driven by tracking (at tracking factor `reference_tracking` when
/// given, else the scene's) and by the generated muscles.
pub fn compare_drivers(
    rig: &Rig,
    opts: &RunOptions,
    reference_tracking: Option<f64>,
) -> anyhow::Result<DriverComparison> {
    // The muscles' lattice may be chosen for them (`pipeline::setup::cell`): the reference
    // tracks on that same lattice, so the two differ by their driver alone.
    let (muscles, driven) = run_with(rig, opts, MuscleSource::Auto, None)?;
    let mut same_lattice = opts.clone();
    if same_lattice.scene.interior.target_cells.is_none() {
        same_lattice.scene.interior.cell_size = driven.report.sizes["lattice_cell_m"].as_f64();
    }
    let (tracking, reference) =
        run_with(rig, &same_lattice, MuscleSource::None, reference_tracking)?;
    let region = region_size(&reference);
    let (a_ref, a_run) = (
        amplitude_map(&reference, region),
        amplitude_map(&driven, region),
    );
    Ok(DriverComparison {
        reference_tracking,
        runs: vec![tracking, muscles],
        amplitude_error: amplitude_error(&a_run, &a_ref),
        shared_regions: [shared(&a_ref, &a_run), shared(&a_run, &a_ref)],
        region_m: region,
    })
}

/// Of the (frame, region) pairs where `a` wrinkles (RMS amplitude above a tenth of its
/// largest), the share where `b` also does (above a tenth of its own largest); 1 when `a`
/// has none.
pub fn shared(a: &AmplitudeMap, b: &AmplitudeMap) -> f64 {
    let amp = |(s, area): (f64, f64)| if area > 0.0 { (s / area).sqrt() } else { 0.0 };
    let largest = |m: &AmplitudeMap| {
        m.frames
            .iter()
            .flat_map(|f| f.values().map(|&v| amp(v)))
            .fold(0.0f64, f64::max)
    };
    let (la, lb) = (largest(a), largest(b));
    let (mut hits, mut total) = (0usize, 0usize);
    for (k, fa) in a.frames.iter().enumerate() {
        for (key, &v) in fa {
            if amp(v) > 0.1 * la {
                total += 1;
                let other = b
                    .frames
                    .get(k)
                    .and_then(|fb| fb.get(key))
                    .map_or(0.0, |&w| amp(w));
                hits += usize::from(other > 0.1 * lb);
            }
        }
    }
    if total == 0 {
        1.0
    } else {
        hits as f64 / total as f64
    }
}
