//! What a sweep reports: its runs as a CSV table, the log-log chart of error against wall
//! time with the Pareto front, and the preview and final picks.

use super::TradeoffRun;
use crate::render::plot::{line_chart, Chart, LegendAt, Series, Style};
use anyhow::Context;
use serde::Serialize;
use std::path::Path;

/// The CSV header written by [`to_csv`].
pub const CSV_HEADER: &str = "case,knob,value,default,reference,wall_s,rms_m,max_m,wrinkle_m,measured_wavelength_m,predicted_wavelength_m,wavelength_error,amplitude_error,phase_free_error,frames_not_converged,pareto,status";

/// An optional measurement as a CSV cell: empty when missing.
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
                .to_string()
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
        .filter(|r| r.status.is_ok() && !r.is_reference)
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

/// A run's setting as a pick names it: `default`, `reference` or `key = value`.
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
            .filter(|r| r.status.is_ok() && !r.is_reference && err(r) <= tol)
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

#[cfg(test)]
mod tests {
    use super::super::{blank_row, mark_pareto, Knob, Setting};
    use super::*;
    use crate::scene::Scene;

    #[test]
    fn picks_take_the_fastest_run_within_tolerance() {
        let mk = |knob: Knob, t: f64, e: f64| TradeoffRun {
            rms_m: e,
            ..blank_row(
                "rig",
                &Setting {
                    knob,
                    value: 1.0,
                    scene: Scene::default(),
                },
                t,
            )
        };
        let mut rows = vec![
            mk(Knob::Default, 2.0, 1e-4),
            mk(Knob::Key("a"), 1.0, 5e-4),
            mk(Knob::Key("b"), 0.5, 2e-3),
            mk(Knob::Key("c"), 4.0, 1e-5),
            mk(Knob::Reference, 9.0, 0.0),
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
}
