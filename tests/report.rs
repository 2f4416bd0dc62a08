//! Charts and preview images: files exist, decode, have the right size and are not blank; the
//! rasteriser covers, shades and hides what geometry says it should.
//! `REPORT_OUT=/tmp/report cargo test --test report` keeps the images for a person to look at.

use furrow::report::contour::Grid;
use furrow::report::plot::{
    contour_chart, line_chart, series_color, Chart, ContourChart, ContourSet, LegendAt, Series,
    Style, DEFAULT_SIZE,
};
use image::RgbImage;
use std::path::PathBuf;

/// Output folder: `$REPORT_OUT` when set (kept), else a temporary folder (removed).
fn out_dir() -> (PathBuf, Option<tempfile::TempDir>) {
    match std::env::var_os("REPORT_OUT") {
        Some(d) => {
            let p = PathBuf::from(d);
            std::fs::create_dir_all(&p).unwrap();
            (p, None)
        }
        None => {
            let t = tempfile::tempdir().unwrap();
            (t.path().to_path_buf(), Some(t))
        }
    }
}

/// Decode a PNG file with the image crate.
fn load(path: &std::path::Path) -> RgbImage {
    image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8()
}

/// Number of pixels exactly of colour `c`.
fn count_color(img: &RgbImage, c: [u8; 3]) -> usize {
    img.pixels().filter(|p| p.0 == c).count()
}

/// Fraction of pixels that are not pure white.
fn ink(img: &RgbImage) -> f64 {
    img.pixels().filter(|p| p.0 != [255, 255, 255]).count() as f64
        / (img.width() * img.height()) as f64
}

/// The critical wavelength (DESIGN.md), mm, for thickness h (mm) and ratio E_x/E_q, equal ν.
fn lambda_mm(h: f64, ratio: f64) -> f64 {
    2.0 * std::f64::consts::PI * h * (ratio / 3.0).cbrt()
}

#[test]
fn tradeoff_chart_log_log_with_front_and_default() {
    let (dir, _keep) = out_dir();
    // (time s, error mm): a cloud of runs; the front is marked and one run highlighted.
    let runs: Vec<(f64, f64)> = vec![
        (0.5, 2.0),
        (0.8, 1.1),
        (1.0, 1.5),
        (2.0, 0.4),
        (3.0, 0.6),
        (6.0, 0.12),
        (9.0, 0.2),
        (20.0, 0.03),
        (40.0, 0.05),
    ];
    let mut default = Series::new("default settings", vec![(2.0, 0.4)], Style::Points);
    default.highlight = true;
    let chart = Chart {
        title: "Error against run time".into(),
        x_label: "run time (s)".into(),
        y_label: "surface distance RMS (mm)".into(),
        log_x: true,
        log_y: true,
        series: vec![
            Series::new("runs", runs.clone(), Style::Points),
            Series::pareto_front("Pareto front", &runs),
            default,
        ],
        legend: LegendAt::UpperRight,
    };
    let path = dir.join("tradeoff.png");
    line_chart(&path, &chart).unwrap();
    let img = load(&path);
    assert_eq!(img.dimensions(), DEFAULT_SIZE);
    let f = ink(&img);
    assert!(f > 0.02 && f < 0.5, "ink fraction {f}");
    // Each series' colour appears (markers are filled with it).
    for k in 0..3 {
        let n = count_color(&img, series_color(k));
        assert!(n > 50, "series {k}: {n} pixels of its colour");
    }
    // No temporary file left behind.
    let stray: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(stray.is_empty());
}

#[test]
fn activation_chart_linear_axes() {
    let (dir, _keep) = out_dir();
    let series: Vec<Series> = (0..4)
        .map(|k| {
            let pts = (0..=120)
                .map(|f| {
                    let t = f as f64 / 60.0;
                    (t, (0.5 + 0.5 * (3.0 * t + k as f64).sin()).clamp(0.0, 1.0))
                })
                .collect();
            Series::new(format!("muscle {k}"), pts, Style::Line)
        })
        .collect();
    let chart = Chart {
        title: "Muscle activations".into(),
        x_label: "time (s)".into(),
        y_label: "activation".into(),
        series,
        legend: LegendAt::LowerRight,
        ..Default::default()
    };
    let path = dir.join("activations.png");
    line_chart(&path, &chart).unwrap();
    let img = load(&path);
    assert_eq!(img.dimensions(), DEFAULT_SIZE);
    for k in 0..4 {
        assert!(count_color(&img, series_color(k)) > 300, "series {k}");
    }
}

#[test]
fn chart_errors_name_the_problem() {
    let (dir, _keep) = out_dir();
    let chart = Chart {
        title: "empty".into(),
        log_y: true,
        series: vec![Series::new(
            "neg",
            vec![(1.0, -1.0), (2.0, 0.0)],
            Style::Line,
        )],
        ..Default::default()
    };
    let e = line_chart(&dir.join("empty.png"), &chart)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("no point to draw") && e.contains("logarithmic"),
        "{e}"
    );
    assert!(!dir.join("empty.png").exists());
}

#[test]
fn wavelength_contours_measured_against_predicted() {
    let (dir, _keep) = out_dir();
    // x: E_x/E_q on a log axis, y: h (mm). Predicted on a fine grid, "measured" on the
    // validation grid with a 3% bias and one failed sample.
    let fine_x: Vec<f64> = (0..=40)
        .map(|k| 10f64.powf(2.0 + 2.0 * k as f64 / 40.0))
        .collect();
    let fine_y: Vec<f64> = (0..=30).map(|k| 0.1 + 0.6 * k as f64 / 30.0).collect();
    let predicted = Grid::from_fn(fine_x, fine_y, |r, h| lambda_mm(h, r)).unwrap();
    let xs = vec![1e2, 3e2, 1e3, 3e3, 1e4];
    let ys = vec![0.1, 0.3, 0.5, 0.7];
    let mut measured = Grid::from_fn(xs, ys, |r, h| 1.03 * lambda_mm(h, r)).unwrap();
    measured.values[7] = f64::NAN;
    let chart = ContourChart {
        title: "Critical wavelength: measured against predicted".into(),
        x_label: "E_x / E_q".into(),
        y_label: "skin thickness h (mm)".into(),
        log_x: true,
        log_y: false,
        levels: vec![2.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0],
        level_unit: "mm".into(),
        sets: vec![
            ContourSet {
                name: "predicted λ".into(),
                grid: predicted,
                dashed: false,
                mark_samples: false,
            },
            ContourSet {
                name: "measured λ".into(),
                grid: measured,
                dashed: true,
                mark_samples: true,
            },
        ],
        legend: LegendAt::UpperLeft,
    };
    let path = dir.join("wavelength_contours.png");
    contour_chart(&path, &chart).unwrap();
    let img = load(&path);
    assert_eq!(img.dimensions(), DEFAULT_SIZE);
    assert!(count_color(&img, series_color(0)) > 500);
    assert!(count_color(&img, series_color(1)) > 300);
}
