//! How fast a clip's history fades: runs started at rest at frame A (a chunk with no
//! pre-roll before it) against an unsplit run, frame by frame. The run's frame A + P has had
//! P frames of pre-roll, so one run per start gives the whole curve of the error at a chunk's
//! first written frame against its pre-roll P; the default pre-roll is where that error
//! stays within [`PREROLL_TOLERANCE`] at every start.

use super::tradeoff::{amplitude_error, region_size, AmplitudeMap};
use crate::io::load::Rig;
use crate::pipeline::frames::FrameRange;
use crate::pipeline::{self, RunOptions, RunOutput};
use crate::render::plot::{line_chart, Chart, LegendAt, Series, Style};
use serde::Serialize;
use std::path::Path;

/// The amplitude error at a chunk's first written frame that the default pre-roll keeps to
/// (dimensionless, relative to the unsplit run's wrinkle amplitude).
pub const PREROLL_TOLERANCE: f64 = 0.10;

/// One frame of a run started at rest.
#[derive(Debug, Clone, Serialize)]
pub struct PrerollRow {
    /// The frame the run started at, from rest.
    pub start: usize,
    /// Frames simulated before this one (its pre-roll).
    pub preroll: usize,
    /// The clip frame.
    pub frame: usize,
    /// Phase-free amplitude error of the frame against the unsplit run's (2λ regions).
    pub amplitude_error: f64,
    /// The unsplit run's RMS wrinkle height over the face in that frame (m).
    pub reference_rms_m: f64,
}

/// The curve and the pre-roll it asks for.
#[derive(Debug, Clone, Serialize)]
pub struct PrerollCurve {
    /// Every measured frame.
    pub rows: Vec<PrerollRow>,
    /// Per pre-roll P, the largest error over the starts.
    pub worst: Vec<(usize, f64)>,
    /// The smallest P from which the worst error stays within [`PREROLL_TOLERANCE`];
    /// absent when no measured P does.
    pub preroll: Option<usize>,
    /// Region side of the amplitude maps (m), 2λ.
    pub region_m: f64,
    /// Wall time of the unsplit run (s) and of the started runs (s, each).
    pub reference_wall_s: f64,
    /// Wall time of each started run (s).
    pub started_wall_s: Vec<f64>,
}

/// Run `opts` on `rig` unsplit over frames 0..max(starts) + window, then from rest at each
/// start over `window` frames, and compare frame by frame.
pub fn measure(
    rig: &Rig,
    opts: &RunOptions,
    starts: &[usize],
    window: usize,
) -> anyhow::Result<PrerollCurve> {
    let end = starts.iter().max().copied().unwrap_or(0) + window;
    let run = |frames: FrameRange, preroll: Option<usize>| -> anyhow::Result<RunOutput> {
        let o = RunOptions {
            frames: Some(frames),
            preroll,
            ..opts.clone()
        };
        pipeline::run(rig, &o, &|_, _, _| {})
    };
    let reference = run(FrameRange { start: 0, end }, None)?;
    let region = region_size(&reference);
    let tris = &reference.triangles;
    let map = |out: &RunOutput, j: usize| {
        AmplitudeMap::new(&out.frames[j..=j], &out.smooth[j..=j], tris, region)
    };
    let mut rows = Vec::new();
    let mut started_wall_s = Vec::new();
    for &start in starts {
        let out = run(
            FrameRange {
                start,
                end: start + window,
            },
            Some(0),
        )?;
        started_wall_s.push(out.report.totals.wall_s);
        for j in 0..window {
            let truth = map(&reference, start + j);
            rows.push(PrerollRow {
                start,
                preroll: j,
                frame: start + j,
                amplitude_error: amplitude_error(&map(&out, j), &truth),
                reference_rms_m: rms_height(&truth),
            });
        }
    }
    let worst: Vec<(usize, f64)> = (0..window)
        .map(|p| {
            let e = rows
                .iter()
                .filter(|r| r.preroll == p)
                .map(|r| r.amplitude_error)
                .fold(0.0, f64::max);
            (p, e)
        })
        .collect();
    let preroll = (0..window).find(|&p| worst[p..].iter().all(|&(_, e)| e <= PREROLL_TOLERANCE));
    Ok(PrerollCurve {
        rows,
        worst,
        preroll,
        region_m: region,
        reference_wall_s: reference.report.totals.wall_s,
        started_wall_s,
    })
}

/// The RMS wrinkle height over the face of a one-frame amplitude map (m).
fn rms_height(map: &AmplitudeMap) -> f64 {
    let (sq, area) = map.frames[0]
        .values()
        .fold((0.0, 0.0), |(s, a), &(q, m)| (s + q, a + m));
    if area > 0.0 {
        (sq / area).sqrt()
    } else {
        0.0
    }
}

/// Write `preroll.csv` and `preroll.png` (error at the first written frame against the
/// pre-roll, one line per start) into `dir`; returns the files.
pub fn write(curve: &PrerollCurve, dir: &Path) -> anyhow::Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir)?;
    let mut csv = String::from("start,preroll,frame,amplitude_error,reference_rms_m\n");
    for r in &curve.rows {
        csv += &format!(
            "{},{},{},{:.6},{:.6e}\n",
            r.start, r.preroll, r.frame, r.amplitude_error, r.reference_rms_m
        );
    }
    let csv_path = dir.join("preroll.csv");
    std::fs::write(&csv_path, csv)?;
    let mut starts: Vec<usize> = curve.rows.iter().map(|r| r.start).collect();
    starts.dedup();
    let mut series: Vec<Series> = starts
        .iter()
        .map(|&s| {
            let points = curve
                .rows
                .iter()
                .filter(|r| r.start == s)
                .map(|r| (r.preroll as f64, 100.0 * r.amplitude_error))
                .collect();
            Series::new(format!("from rest at frame {s}"), points, Style::LinePoints)
        })
        .collect();
    let limit = curve.worst.len().saturating_sub(1) as f64;
    series.push(Series::new(
        format!("{:.0} %", 100.0 * PREROLL_TOLERANCE),
        vec![
            (0.0, 100.0 * PREROLL_TOLERANCE),
            (limit, 100.0 * PREROLL_TOLERANCE),
        ],
        Style::Line,
    ));
    let png = dir.join("preroll.png");
    line_chart(
        &png,
        &Chart {
            title: "error at a chunk's first written frame against its pre-roll".into(),
            x_label: "pre-roll P (frames)".into(),
            y_label: "amplitude error against the unsplit run (%)".into(),
            series,
            legend: LegendAt::Auto,
            ..Chart::default()
        },
    )?;
    Ok(vec![csv_path, png])
}
