//! Spatial locality of the skin: the pipeline with the `select` stage (only the skin some
//! frame compresses past the wrinkling threshold is simulated) against the reference that
//! simulates all of it, in one process: the skin's time, the share of the skin simulated, and
//! the phase-free difference of the wrinkle amplitude per 2λ region ([`super::tradeoff`]).

use super::tradeoff::{amplitude_error, amplitude_map, region_size};
use crate::io::load::Rig;
use crate::pipeline::{self, RunOptions, RunOutput};
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

fn run_with(rig: &Rig, opts: &RunOptions, simulate: &str) -> anyhow::Result<(SkinRun, RunOutput)> {
    let mut o = opts.clone();
    o.scene.skin.simulate = Some(simulate.to_string());
    let out = pipeline::run(rig, &o, &|_, _, _| {})?;
    let r = &out.report;
    let count = |k: &str| r.sizes[k].as_u64().unwrap_or(0) as usize;
    let run = SkinRun {
        simulate: simulate.into(),
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
    let (reference, full) = run_with(rig, opts, "all")?;
    let (selected, local) = run_with(rig, opts, "compressed")?;
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
