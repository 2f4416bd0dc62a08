//! Charts as PNG files: line and scatter charts (activations over time, error against run time
//! with the Pareto front, solve time against face count) and contour charts (measured against
//! predicted wavelength isocontours, the paper's Fig. 7). Every file is written atomically.

use super::contour::{contour_segments, polylines, Grid};
use super::font::{ensure_registered, FAMILY};
use super::pareto::pareto_points;
use anyhow::{anyhow, Result};
use image::RgbImage;
use plotters::coord::combinators::{LogCoord, WithKeyPoints};
use plotters::coord::ranged1d::ValueFormatter;
use plotters::prelude::*;
use std::path::Path;

/// Default chart size in pixels (width, height).
pub const DEFAULT_SIZE: (u32, u32) = (960, 640);

/// How a series is drawn.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Style {
    /// A polyline through the points in the given order.
    #[default]
    Line,
    /// A marker at each point.
    Points,
    /// A polyline with a marker at each point.
    LinePoints,
}

/// One named data series of a chart, in the units of the chart's axes.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Series {
    /// Legend text (an empty name gives no legend entry).
    pub name: String,
    /// The data points (x, y). Non-finite points, and non-positive ones on a log axis, are
    /// left out.
    pub points: Vec<(f64, f64)>,
    /// Line, points or both.
    pub style: Style,
    /// Draw prominently (thicker, larger markers with a ring, on top), e.g. the default
    /// settings on an error-against-time chart.
    pub highlight: bool,
}

/// Where the legend box goes inside the plotting area.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LegendAt {
    /// Top right corner (default).
    #[default]
    UpperRight,
    /// Top left corner.
    UpperLeft,
    /// Bottom right corner.
    LowerRight,
    /// Bottom left corner.
    LowerLeft,
    /// The corner whose legend-sized area holds the fewest data points.
    Auto,
}

/// The corner of the plotting area whose box of `box_w × box_h` (fractions of the area) holds
/// the fewest of `points`, given as fractions (0..1) of the axes; ties go to the upper right,
/// then upper left, lower right, lower left.
pub fn least_crowded_corner(points: &[(f64, f64)], box_w: f64, box_h: f64) -> LegendAt {
    let count = |x_right: bool, y_top: bool| {
        points
            .iter()
            .filter(|&&(x, y)| {
                let in_x = if x_right {
                    x >= 1.0 - box_w
                } else {
                    x <= box_w
                };
                let in_y = if y_top { y >= 1.0 - box_h } else { y <= box_h };
                in_x && in_y
            })
            .count()
    };
    [
        (LegendAt::UpperRight, count(true, true)),
        (LegendAt::UpperLeft, count(false, true)),
        (LegendAt::LowerRight, count(true, false)),
        (LegendAt::LowerLeft, count(false, false)),
    ]
    .into_iter()
    .min_by_key(|c| c.1)
    .map(|c| c.0)
    .unwrap_or_default()
}

/// Position of `v` as a fraction of the axis range (log or linear).
fn axis_fraction(v: f64, (lo, hi): (f64, f64), log: bool) -> f64 {
    if log {
        (v / lo).ln() / (hi / lo).ln()
    } else {
        (v - lo) / (hi - lo)
    }
}

/// A line or scatter chart with labelled axes and a legend.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Chart {
    /// Title above the chart.
    pub title: String,
    /// x axis label, with its unit, e.g. "run time (s)".
    pub x_label: String,
    /// y axis label, with its unit.
    pub y_label: String,
    /// Logarithmic x axis.
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The data, drawn in order (highlighted series last).
    pub series: Vec<Series>,
    /// Legend placement.
    pub legend: LegendAt,
}

impl Series {
    /// A series from its name, points and style (not highlighted).
    pub fn new(name: impl Into<String>, points: Vec<(f64, f64)>, style: Style) -> Self {
        Self {
            name: name.into(),
            points,
            style,
            highlight: false,
        }
    }

    /// The Pareto front of `(time, error)` points (see [`super::pareto::pareto_front`]) as a
    /// line-and-points series, ordered by time.
    pub fn pareto_front(name: impl Into<String>, points: &[(f64, f64)]) -> Self {
        Self::new(name, pareto_points(points), Style::LinePoints)
    }
}

/// An error-against-run-time chart on log–log axes: every run as a point, the Pareto front of
/// `runs = [(time s, error), …]` as a line, and the run `default` (an index into `runs`, if
/// any) highlighted as the default settings. Write it with [`line_chart`].
pub fn tradeoff_chart(
    title: impl Into<String>,
    error_label: impl Into<String>,
    runs: &[(f64, f64)],
    default: Option<usize>,
) -> Chart {
    let mut series = vec![
        Series::new("runs", runs.to_vec(), Style::Points),
        Series::pareto_front("Pareto front", runs),
    ];
    if let Some(&p) = default.and_then(|d| runs.get(d)) {
        series.push(Series {
            name: "default settings".into(),
            points: vec![p],
            style: Style::Points,
            highlight: true,
        });
    }
    Chart {
        title: title.into(),
        x_label: "run time (s)".into(),
        y_label: error_label.into(),
        log_x: true,
        log_y: true,
        series,
        legend: LegendAt::Auto,
    }
}

/// Tableau 10: distinct colours for successive series.
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Colour of series number `k`.
pub fn series_color(k: usize) -> [u8; 3] {
    let c = PALETTE[k % PALETTE.len()];
    [c.0, c.1, c.2]
}

/// A compact tick label: "0", "0.25", "120", "1e-4", "3e6".
pub fn format_number(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    let a = v.abs();
    if !(1e-3..1e5).contains(&a) {
        let s = format!("{v:.1e}");
        // "1.0e-4" -> "1e-4"
        return s.replace(".0e", "e");
    }
    let s = format!("{v:.4}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_string()
}

pub use super::write_png;

/// Axis range covering `values` (finite, and positive on a log axis), padded by 5% (a factor
/// on a log axis). Errors name the axis when nothing can be drawn.
fn axis_range(
    values: impl Iterator<Item = f64>,
    log: bool,
    pad: bool,
    axis: &str,
) -> Result<(f64, f64)> {
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for v in values.filter(|v| v.is_finite() && (!log || *v > 0.0)) {
        lo = lo.min(v);
        hi = hi.max(v);
    }
    if lo > hi {
        anyhow::bail!(
            "chart: no {}data to draw on the {axis} axis",
            if log { "positive " } else { "finite " }
        );
    }
    if log {
        if hi / lo < 1.0 + 1e-9 {
            return Ok((lo / 2.0, hi * 2.0));
        }
        let (lo, hi) = if pad {
            let f = (hi / lo).powf(0.05);
            (lo / f, hi * f)
        } else {
            (lo, hi)
        };
        Ok((lo, hi))
    } else {
        let span = hi - lo;
        if span <= 1e-12 * lo.abs().max(hi.abs()) || span == 0.0 {
            let d = (lo.abs() * 0.1).max(1.0);
            return Ok((lo - d, hi + d));
        }
        if !pad {
            return Ok((lo, hi));
        }
        Ok((lo - 0.05 * span, hi + 0.05 * span))
    }
}

/// Tick values of a logarithmic axis over `[lo, hi]` (lo > 0): the labelled (bold) ticks and
/// the unlabelled grid lines (light). Labels go at 1, 2 and 5 times the powers of ten; when the
/// range holds fewer than three of those, at every integer multiple 1…9 of them, and when
/// still fewer than three at the half steps as well (1.5, 2.5, 3.5, 4.5); a range too narrow
/// for two of those is labelled at its two ends. Grid lines go at every integer multiple in
/// the range.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo > 0.0 && hi > lo && hi.is_finite()) {
        return (Vec::new(), Vec::new());
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-12) && v <= hi * (1.0 + 1e-12);
    let (k0, k1) = (lo.log10().floor() as i32 - 1, hi.log10().ceil() as i32 + 1);
    let multiples = |set: &[f64]| -> Vec<f64> {
        (k0..=k1)
            .flat_map(|k| set.iter().map(move |m| m * 10f64.powi(k)))
            .filter(|&v| inside(v))
            .collect()
    };
    let all: Vec<f64> = multiples(&[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0]);
    let mut bold = multiples(&[1.0, 2.0, 5.0]);
    if bold.len() < 3 {
        bold = all.clone();
    }
    if bold.len() < 3 {
        bold = multiples(&[
            1.0, 1.5, 2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 6.0, 7.0, 8.0, 9.0,
        ]);
    }
    if bold.len() < 2 {
        bold = vec![lo, hi];
    }
    (bold, all)
}

/// A logarithmic axis over `[lo, hi]` ticked by [`log_ticks`] (plotters' own ticks skip
/// ranges that hold no power of ten, and round-off in its decade arithmetic can drop every
/// label).
fn log_axis(lo: f64, hi: f64) -> WithKeyPoints<LogCoord<f64>> {
    let (bold, light) = log_ticks(lo, hi);
    (lo..hi)
        .log_scale()
        .with_key_points(bold)
        .with_light_points(light)
}

/// Keep a point if it can be placed on the chart's axes.
fn drawable(p: (f64, f64), log_x: bool, log_y: bool) -> bool {
    p.0.is_finite() && p.1.is_finite() && (!log_x || p.0 > 0.0) && (!log_y || p.1 > 0.0)
}

/// Draw a chart into a new in-memory image of `size` pixels; `body` draws the data on the
/// built coordinate system. Dispatches over the four linear/log axis combinations.
struct Frame<'c> {
    title: &'c str,
    x_label: &'c str,
    y_label: &'c str,
    log_x: bool,
    log_y: bool,
    x: (f64, f64),
    y: (f64, f64),
}

/// What a chart draws on its axes, for any coordinate types with f64 values.
trait Body {
    fn draw<'a, X, Y>(
        &self,
        ctx: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>,
    ) -> Result<()>
    where
        X: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>;
}

fn render_frame(frame: &Frame<'_>, size: (u32, u32), body: &impl Body) -> Result<RgbImage> {
    ensure_registered();
    let (w, h) = size;
    if w < 200 || h < 150 {
        anyhow::bail!("chart: {w}×{h} pixels is too small (need at least 200×150)");
    }
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        root.fill(&WHITE).map_err(|e| anyhow!("chart: {e}"))?;
        let mut builder = ChartBuilder::on(&root);
        builder
            .caption(frame.title, (FAMILY, 26.0))
            .margin(16)
            .margin_right(40)
            .x_label_area_size(56)
            .y_label_area_size(84);
        let (x0, x1) = frame.x;
        let (y0, y1) = frame.y;
        let (log_x, log_y) = (|| log_axis(x0, x1), || log_axis(y0, y1));
        match (frame.log_x, frame.log_y) {
            (false, false) => draw_axes(builder.build_cartesian_2d(x0..x1, y0..y1), frame, body)?,
            (true, false) => draw_axes(builder.build_cartesian_2d(log_x(), y0..y1), frame, body)?,
            (false, true) => draw_axes(builder.build_cartesian_2d(x0..x1, log_y()), frame, body)?,
            (true, true) => draw_axes(builder.build_cartesian_2d(log_x(), log_y()), frame, body)?,
        }
        root.present().map_err(|e| anyhow!("chart: {e}"))?;
    }
    RgbImage::from_raw(w, h, buf).ok_or_else(|| anyhow!("chart: image buffer has the wrong size"))
}

fn draw_axes<'a, X, Y, E: std::fmt::Display>(
    ctx: std::result::Result<ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>, E>,
    frame: &Frame<'_>,
    body: &impl Body,
) -> Result<()>
where
    X: Ranged<ValueType = f64> + ValueFormatter<f64>,
    Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
{
    let mut ctx = ctx.map_err(|e| anyhow!("chart: {e}"))?;
    let fmt = |v: &f64| format_number(*v);
    ctx.configure_mesh()
        .x_desc(frame.x_label)
        .y_desc(frame.y_label)
        .label_style((FAMILY, 15.0))
        .axis_desc_style((FAMILY, 19.0))
        .x_label_formatter(&fmt)
        .y_label_formatter(&fmt)
        .draw()
        .map_err(|e| anyhow!("chart: {e}"))?;
    body.draw(&mut ctx)
}

struct LineBody<'c> {
    chart: &'c Chart,
    /// The legend corner, resolved ([`LegendAt::Auto`] replaced by a corner).
    legend: LegendAt,
}

/// plotters' position for a legend corner ([`LegendAt::Auto`] unresolved: upper right).
fn label_position(at: LegendAt) -> SeriesLabelPosition {
    match at {
        LegendAt::UpperRight | LegendAt::Auto => SeriesLabelPosition::UpperRight,
        LegendAt::UpperLeft => SeriesLabelPosition::UpperLeft,
        LegendAt::LowerRight => SeriesLabelPosition::LowerRight,
        LegendAt::LowerLeft => SeriesLabelPosition::LowerLeft,
    }
}

impl Body for LineBody<'_> {
    fn draw<'a, X, Y>(
        &self,
        ctx: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>,
    ) -> Result<()>
    where
        X: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let chart = self.chart;
        let mut order: Vec<usize> = (0..chart.series.len()).collect();
        order.sort_by_key(|&k| chart.series[k].highlight);
        let mut any_legend = false;
        for k in order {
            let s = &chart.series[k];
            let c = series_color(k);
            let color = RGBColor(c[0], c[1], c[2]);
            let pts: Vec<(f64, f64)> = s
                .points
                .iter()
                .copied()
                .filter(|&p| drawable(p, chart.log_x, chart.log_y))
                .collect();
            let width = if s.highlight { 4 } else { 2 };
            let radius = if s.highlight { 8 } else { 4 };
            let line_style = color.stroke_width(width);
            let lines = matches!(s.style, Style::Line | Style::LinePoints);
            let marks = matches!(s.style, Style::Points | Style::LinePoints);
            let err = |e| anyhow!("chart: {e}");
            let mut anno = None;
            if lines {
                anno = Some(
                    ctx.draw_series(LineSeries::new(pts.iter().copied(), line_style))
                        .map_err(err)?,
                );
            }
            if marks {
                if s.highlight {
                    ctx.draw_series(
                        pts.iter()
                            .map(|&p| Circle::new(p, radius + 3, BLACK.stroke_width(2))),
                    )
                    .map_err(err)?;
                }
                anno = Some(
                    ctx.draw_series(pts.iter().map(|&p| Circle::new(p, radius, color.filled())))
                        .map_err(err)?,
                );
            }
            if let (Some(a), false) = (anno, s.name.is_empty()) {
                any_legend = true;
                let style = s.style;
                let hl = s.highlight;
                let show_line = matches!(style, Style::Line | Style::LinePoints);
                let show_mark = matches!(style, Style::Points | Style::LinePoints);
                let path_style = if show_line {
                    color.stroke_width(width)
                } else {
                    TRANSPARENT.stroke_width(1)
                };
                let ring_style = if show_mark && hl {
                    BLACK.stroke_width(2)
                } else {
                    TRANSPARENT.stroke_width(1)
                };
                let dot_style = if show_mark {
                    color.filled()
                } else {
                    TRANSPARENT.filled()
                };
                a.label(s.name.clone()).legend(move |(x, y)| {
                    EmptyElement::at((x + 12, y))
                        + PathElement::new(vec![(-12, 0), (12, 0)], path_style)
                        + Circle::new((0, 0), radius + 3, ring_style)
                        + Circle::new((0, 0), radius, dot_style)
                });
            }
        }
        if any_legend {
            ctx.configure_series_labels()
                .position(label_position(self.legend))
                .label_font((FAMILY, 16.0))
                .background_style(WHITE.mix(0.85))
                .border_style(BLACK)
                .draw()
                .map_err(|e| anyhow!("chart: {e}"))?;
        }
        Ok(())
    }
}

/// Render `chart` into an image of `size` pixels (width, height).
pub fn render_line_chart(chart: &Chart, size: (u32, u32)) -> Result<RgbImage> {
    let pts = || {
        chart
            .series
            .iter()
            .flat_map(|s| s.points.iter().copied())
            .filter(|&p| drawable(p, chart.log_x, chart.log_y))
    };
    if pts().next().is_none() {
        anyhow::bail!(
            "{}: no point to draw (every point is non-finite, or not positive on a logarithmic axis)",
            chart.title
        );
    }
    let x = axis_range(pts().map(|p| p.0), chart.log_x, true, "x")
        .map_err(|e| anyhow!("{}: {e}", chart.title))?;
    let y = axis_range(pts().map(|p| p.1), chart.log_y, true, "y")
        .map_err(|e| anyhow!("{}: {e}", chart.title))?;
    let frame = Frame {
        title: &chart.title,
        x_label: &chart.x_label,
        y_label: &chart.y_label,
        log_x: chart.log_x,
        log_y: chart.log_y,
        x,
        y,
    };
    let legend = if chart.legend == LegendAt::Auto {
        let frac: Vec<(f64, f64)> = pts()
            .map(|p| {
                (
                    axis_fraction(p.0, x, chart.log_x),
                    axis_fraction(p.1, y, chart.log_y),
                )
            })
            .collect();
        let entries = chart.series.iter().filter(|s| !s.name.is_empty()).count();
        least_crowded_corner(&frac, 0.4, (0.06 * entries as f64 + 0.04).min(0.9))
    } else {
        chart.legend
    };
    render_frame(&frame, size, &LineBody { chart, legend })
}

/// Write `chart` as a PNG of [`DEFAULT_SIZE`] at `path` (atomically, replacing).
pub fn line_chart(path: &Path, chart: &Chart) -> Result<()> {
    let img = render_line_chart(chart, DEFAULT_SIZE)?;
    write_png(path, &img)
}

/// One field drawn as isocontours on a [`ContourChart`], e.g. measured λ on the sample grid or
/// predicted λ from the formula on a fine grid.
#[derive(Debug, Clone, PartialEq)]
pub struct ContourSet {
    /// Legend text.
    pub name: String,
    /// The sampled field (values in the unit of [`ContourChart::level_unit`]).
    pub grid: Grid,
    /// Draw this set's lines dashed.
    pub dashed: bool,
    /// Mark the grid points that hold a finite sample (for measured data).
    pub mark_samples: bool,
}

/// Isocontours of one or more fields at the same levels over the same axes, each field in its
/// own colour (the paper's Fig. 7: measured against predicted wavelength).
#[derive(Debug, Clone, PartialEq)]
pub struct ContourChart {
    /// Title above the chart.
    pub title: String,
    /// x axis label with unit.
    pub x_label: String,
    /// y axis label with unit.
    pub y_label: String,
    /// Logarithmic x axis (contours are then interpolated geometrically along x).
    pub log_x: bool,
    /// Logarithmic y axis.
    pub log_y: bool,
    /// The contour levels, in the unit of the grid values.
    pub levels: Vec<f64>,
    /// Unit text appended to level labels, e.g. "mm".
    pub level_unit: String,
    /// The fields; the first one's contours carry the level labels.
    pub sets: Vec<ContourSet>,
    /// Legend placement.
    pub legend: LegendAt,
}

struct ContourBody<'c>(&'c ContourChart);

impl Body for ContourBody<'_> {
    fn draw<'a, X, Y>(
        &self,
        ctx: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<X, Y>>,
    ) -> Result<()>
    where
        X: Ranged<ValueType = f64> + ValueFormatter<f64>,
        Y: Ranged<ValueType = f64> + ValueFormatter<f64>,
    {
        let chart = self.0;
        let err = |e| anyhow!("chart: {e}");
        let mut labelled = vec![false; chart.levels.len()];
        for (k, set) in chart.sets.iter().enumerate() {
            let c = series_color(k);
            let color = RGBColor(c[0], c[1], c[2]);
            let style = color.stroke_width(2);
            for (li, &level) in chart.levels.iter().enumerate() {
                let lines = polylines(&contour_segments(
                    &set.grid,
                    level,
                    chart.log_x,
                    chart.log_y,
                ));
                for line in &lines {
                    if set.dashed {
                        ctx.draw_series(DashedLineSeries::new(line.iter().copied(), 10, 6, style))
                            .map_err(err)?;
                    } else {
                        ctx.draw_series(LineSeries::new(line.iter().copied(), style))
                            .map_err(err)?;
                    }
                }
                // Label the level once, on the longest line, at its middle point.
                if !labelled[li] {
                    if let Some(line) = lines.iter().max_by_key(|l| l.len()) {
                        labelled[li] = true;
                        let p = line[line.len() / 2];
                        let text = if chart.level_unit.is_empty() {
                            format_number(level)
                        } else {
                            format!("{} {}", format_number(level), chart.level_unit)
                        };
                        let ts = TextStyle::from((FAMILY, 15.0)).color(&BLACK);
                        ctx.draw_series(std::iter::once(
                            EmptyElement::at(p)
                                + Circle::new((0, 0), 3, BLACK.filled())
                                + Text::new(text, (5, -18), ts),
                        ))
                        .map_err(err)?;
                    }
                }
            }
            if set.mark_samples {
                let g = &set.grid;
                let nodes: Vec<(f64, f64)> = (0..g.ys.len())
                    .flat_map(|j| (0..g.xs.len()).map(move |i| (i, j)))
                    .filter(|&(i, j)| g.at(i, j).is_finite())
                    .map(|(i, j)| (g.xs[i], g.ys[j]))
                    .filter(|&p| drawable(p, chart.log_x, chart.log_y))
                    .collect();
                ctx.draw_series(
                    nodes
                        .into_iter()
                        .map(|p| Cross::new(p, 4, color.stroke_width(1))),
                )
                .map_err(err)?;
            }
            // Legend entry (an empty series carries it).
            let dashed = set.dashed;
            ctx.draw_series(LineSeries::new(std::iter::empty::<(f64, f64)>(), style))
                .map_err(err)?
                .label(set.name.clone())
                .legend(move |(x, y)| {
                    let gap = if dashed {
                        TRANSPARENT.stroke_width(2)
                    } else {
                        style
                    };
                    EmptyElement::at((x, y))
                        + PathElement::new(vec![(0, 0), (9, 0)], style)
                        + PathElement::new(vec![(9, 0), (15, 0)], gap)
                        + PathElement::new(vec![(15, 0), (24, 0)], style)
                });
        }
        ctx.configure_series_labels()
            .position(label_position(chart.legend))
            .label_font((FAMILY, 16.0))
            .background_style(WHITE.mix(0.85))
            .border_style(BLACK)
            .draw()
            .map_err(err)?;
        Ok(())
    }
}

/// Render a contour chart into an image of `size` pixels. The axes span the union of the sets'
/// grids.
pub fn render_contour_chart(chart: &ContourChart, size: (u32, u32)) -> Result<RgbImage> {
    if chart.sets.is_empty() {
        anyhow::bail!("{}: a contour chart needs at least one field", chart.title);
    }
    let xs = || {
        chart
            .sets
            .iter()
            .flat_map(|s| [s.grid.xs[0], *s.grid.xs.last().unwrap()])
    };
    let ys = || {
        chart
            .sets
            .iter()
            .flat_map(|s| [s.grid.ys[0], *s.grid.ys.last().unwrap()])
    };
    let x =
        axis_range(xs(), chart.log_x, false, "x").map_err(|e| anyhow!("{}: {e}", chart.title))?;
    let y =
        axis_range(ys(), chart.log_y, false, "y").map_err(|e| anyhow!("{}: {e}", chart.title))?;
    let frame = Frame {
        title: &chart.title,
        x_label: &chart.x_label,
        y_label: &chart.y_label,
        log_x: chart.log_x,
        log_y: chart.log_y,
        x,
        y,
    };
    render_frame(&frame, size, &ContourBody(chart))
}

/// Write a contour chart as a PNG of [`DEFAULT_SIZE`] at `path` (atomically, replacing).
pub fn contour_chart(path: &Path, chart: &ContourChart) -> Result<()> {
    let img = render_contour_chart(chart, DEFAULT_SIZE)?;
    write_png(path, &img)
}

#[cfg(test)]
mod tests {
    use super::{axis_range, least_crowded_corner, log_ticks, LegendAt};

    /// The legend goes to the corner without points: points in the upper right and lower
    /// left send it to the upper left; an empty chart keeps the upper right.
    #[test]
    fn legend_avoids_the_points() {
        let pts = [(0.95, 0.9), (0.8, 0.95), (0.1, 0.1), (0.5, 0.5)];
        assert_eq!(least_crowded_corner(&pts, 0.4, 0.3), LegendAt::UpperLeft);
        let pts = [(0.95, 0.9), (0.1, 0.9), (0.1, 0.1)];
        assert_eq!(least_crowded_corner(&pts, 0.4, 0.3), LegendAt::LowerRight);
        assert_eq!(least_crowded_corner(&[], 0.4, 0.3), LegendAt::UpperRight);
    }

    /// Every log axis gets at least two labelled ticks inside its range, whatever the range
    /// (within one decade, across many, or narrower than one multiple): the charts of
    /// `report tradeoff` once came out with no labels at all on an error axis of 0.11–0.37.
    #[test]
    fn log_axes_always_have_labels_inside_the_range() {
        for (a, b) in [
            (0.11, 0.37),
            (0.1, 0.35),
            (3.9, 33.0),
            (1.2, 4.5),
            (1e-7, 3e2),
            (0.0101, 0.0102),
            (7.0, 7.5),
            (950.0, 1050.0),
        ] {
            let (lo, hi) = axis_range([a, b].into_iter(), true, true, "y").unwrap();
            let (bold, light) = log_ticks(lo, hi);
            assert!(bold.len() >= 2, "{a}..{b}: {bold:?}");
            for v in bold.iter().chain(&light) {
                assert!(
                    *v >= lo * (1.0 - 1e-9) && *v <= hi * (1.0 + 1e-9),
                    "{a}..{b}: tick {v} outside {lo}..{hi}"
                );
            }
        }
        // 0.11–0.37 holds only 0.2 and 0.3 of the integer multiples: the half steps join.
        let (bold, _) = log_ticks(0.11, 0.37);
        let want = [0.15, 0.2, 0.25, 0.3, 0.35];
        assert_eq!(bold.len(), want.len(), "{bold:?}");
        for (b, w) in bold.iter().zip(want) {
            assert!((b - w).abs() < 1e-15, "{bold:?}");
        }
        // Three decades: 1, 2, 5 times each power of ten.
        let (bold, light) = log_ticks(1.0, 1000.0);
        assert_eq!(bold.len(), 10);
        assert_eq!(light.len(), 28);
    }
}
