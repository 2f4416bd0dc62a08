//! Charts and preview images: files exist, decode, have the right size and are not blank; the
//! rasteriser covers, shades and hides what geometry says it should.
//! `REPORT_OUT=/tmp/report cargo test --test pictures` keeps the images for a person to look at.

use furrow::mesh::TriMesh;
use furrow::render::colormap::{diverging, symmetric_range};
use furrow::render::contour::Grid;
use furrow::render::plot::{
    contour_chart, line_chart, series_color, tradeoff_chart, Chart, ContourChart, ContourSet,
    LegendAt, Series, Style, DEFAULT_SIZE,
};
use furrow::render::preview::{
    contact_sheet, render, render_scalar, side_by_side, union_bounds, wrinkle_depth_mm, Camera,
    View,
};
use furrow::render::write_png;
use image::RgbImage;
use nalgebra::Vector3;
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
    let chart = tradeoff_chart(
        "Error against run time",
        "surface distance RMS (mm)",
        &runs,
        Some(3),
    );
    assert_eq!(chart.series[2].points, vec![(2.0, 0.4)]);
    assert!(chart.series[2].highlight);
    // The front: fastest run, then each run more accurate than every faster one.
    assert_eq!(
        chart.series[1].points,
        vec![
            (0.5, 2.0),
            (0.8, 1.1),
            (2.0, 0.4),
            (6.0, 0.12),
            (20.0, 0.03)
        ]
    );
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

// ---------------------------------------------------------------------------------------------
// Preview images

/// A view with one sample per pixel, no margin, fitted to `mesh`'s box.
fn exact_view(mesh: &TriMesh) -> View {
    View {
        supersample: 1,
        margin: 0.0,
        bounds: union_bounds(&[mesh]),
        ..View::default()
    }
}

/// Pixels that differ from the background.
fn covered(img: &RgbImage, bg: [u8; 3]) -> usize {
    img.pixels().filter(|p| p.0 != bg).count()
}

/// Expected 8-bit colour of a flat surface of colour `c` with unit normal `n` (camera space)
/// under `view`'s light: c · (ambient + (1 − ambient) max(0, n·l)).
fn lambert(view: &View, c: [u8; 3], n: Vector3<f64>) -> [u8; 3] {
    let l = view.light.normalize();
    let s = view.ambient + (1.0 - view.ambient) * n.dot(&l).max(0.0);
    c.map(|v| (v as f64 * s).round() as u8)
}

fn close(a: [u8; 3], b: [u8; 3], tol: u8) -> bool {
    a.iter().zip(&b).all(|(x, y)| x.abs_diff(*y) <= tol)
}

#[test]
fn triangle_covers_its_area_with_the_lambert_shade() {
    // Right triangle with legs 2 m (x) and 1 m (y) facing +z, fitted into 200 × 100 pixels
    // with no margin: 100 px/m, so it covers half the image, 10 000 px. Pixel centres along
    // the hypotenuse are in or out, so the count may differ from the area by at most half a
    // pixel per column the hypotenuse crosses (200 columns → ±100).
    let mesh = TriMesh::new(
        vec![
            Vector3::zeros(),
            Vector3::new(2.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ],
        vec![[0, 1, 2]],
    );
    let view = exact_view(&mesh);
    let img = render(&mesh, &view, (200, 100));
    let n = covered(&img, view.background) as f64;
    eprintln!("triangle: covered {n} px, area 10 000 px");
    assert!(
        (n - 10_000.0).abs() <= 100.0,
        "covered {n} px, area 10 000 px"
    );
    // Lower-left quarter is inside, upper-right corner outside (y grows downwards).
    assert_ne!(img.get_pixel(20, 90).0, view.background);
    assert_eq!(img.get_pixel(190, 5).0, view.background);
    // Every covered pixel has the flat Lambert shade of normal +z.
    let want = lambert(&view, view.color, Vector3::z());
    for p in img.pixels().filter(|p| p.0 != view.background) {
        assert!(close(p.0, want, 1), "{:?} vs {want:?}", p.0);
    }
}

/// A triangle of size `s` centred at `c` with unit normal `n` (counter-clockwise seen from n).
fn facing_triangle(c: Vector3<f64>, n: Vector3<f64>, s: f64) -> [Vector3<f64>; 3] {
    let n = n.normalize();
    let a = if n.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let u = (a - n * n.dot(&a)).normalize();
    let v = n.cross(&u);
    [0.0f64, 2.0944, 4.1888].map(|t| c + (u * t.cos() + v * t.sin()) * s)
}

#[test]
fn the_normal_facing_the_light_is_brightest() {
    // Separate triangles (no shared vertices, so vertex normals are the face normals) in a
    // row, each turned a different way; the one whose normal points at the light is the
    // brightest and every one matches c·(ambient + (1 − ambient) max(0, n·l)) to one level.
    let view = View {
        supersample: 1,
        ..View::default()
    };
    let l = view.light.normalize();
    let normals = [
        Vector3::z(),
        l,
        Vector3::new(0.5, 0.0, 1.0).normalize(),
        Vector3::new(0.0, -0.6, 1.0).normalize(),
        Vector3::new(0.9, -0.5, 0.3).normalize(), // faces away from the light: ambient only
    ];
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for (k, n) in normals.iter().enumerate() {
        let c = Vector3::new(k as f64 * 1.2, 0.0, 0.0);
        let t = facing_triangle(c, *n, 0.5);
        tris.push([pos.len(), pos.len() + 1, pos.len() + 2]);
        pos.extend(t);
    }
    let mesh = TriMesh::new(pos, tris);
    let size = (600, 160);
    let img = render(&mesh, &view, size);
    let cam = Camera::fit(&view, union_bounds(&[&mesh]).unwrap(), size.0, size.1);
    let mut shades = Vec::new();
    for (k, n) in normals.iter().enumerate() {
        let p = cam.project(&Vector3::new(k as f64 * 1.2, 0.0, 0.0));
        let got = img.get_pixel(p.x as u32, p.y as u32).0;
        let want = lambert(&view, view.color, *n);
        assert!(close(got, want, 1), "triangle {k}: {got:?} vs {want:?}");
        shades.push(got[0]);
    }
    eprintln!("shades (red channel) per triangle: {shades:?}");
    let brightest = (0..normals.len()).max_by_key(|&k| shades[k]).unwrap();
    assert_eq!(brightest, 1, "shades {shades:?}");
    let ambient_only = (view.color[0] as f64 * view.ambient).round() as u8;
    assert!(shades[4].abs_diff(ambient_only) <= 1);
}

/// Axis-aligned square in the plane z = `z`, corners (x0, y0)–(x1, y1), facing +z.
fn square(
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
    z: f64,
    base: usize,
) -> (Vec<Vector3<f64>>, Vec<[usize; 3]>) {
    (
        vec![
            Vector3::new(x0, y0, z),
            Vector3::new(x1, y0, z),
            Vector3::new(x1, y1, z),
            Vector3::new(x0, y1, z),
        ],
        vec![[base, base + 1, base + 2], [base, base + 2, base + 3]],
    )
}

#[test]
fn depth_buffer_keeps_the_nearer_surface_in_either_order() {
    // A far square (z = 0, value −1 → blue end) and a nearer one (z = 0.1, value +1 → red
    // end) overlapping in x ∈ [1, 2]. With the light along the view the shade is 1, so the
    // pixels are the colour map's end colours exactly.
    let (mut p, mut t) = square(0.0, 0.0, 2.0, 1.0, 0.0, 0);
    let (p2, t2) = square(1.0, 0.0, 3.0, 1.0, 0.1, 4);
    p.extend(p2);
    t.extend(t2);
    let values = vec![-1.0, -1.0, -1.0, -1.0, 1.0, 1.0, 1.0, 1.0];
    let view = View {
        light: Vector3::z(),
        ..exact_view(&TriMesh::new(p.clone(), t.clone()))
    };
    for order in [t.clone(), vec![t[2], t[3], t[0], t[1]]] {
        let mesh = TriMesh::new(p.clone(), order);
        // 300 px wide body + legend: render at a width without legend (< 240 px).
        let img = render_scalar(&mesh, &values, (-1.0, 1.0), &view, (210, 70)).unwrap();
        // 70 px per metre: x = 0.5 m → column 35 (far only), x = 1.5 m → 105 (both), 2.5 → 175.
        assert_eq!(img.get_pixel(35, 35).0, diverging(0.0));
        assert_eq!(
            img.get_pixel(105, 35).0,
            diverging(1.0),
            "the nearer square must win"
        );
        assert_eq!(img.get_pixel(175, 35).0, diverging(1.0));
    }
}

#[test]
fn scalar_field_reaches_both_ends_of_the_colour_map() {
    // A strip with values from −2 at x = 0 to +2 at x = 4 (linear), range (−1, 1): the left
    // quarter clamps to the blue end, the right quarter to the red end, the middle is the
    // map's centre; the legend bar shows both ends.
    let (p, t) = square(0.0, 0.0, 4.0, 1.0, 0.0, 0);
    let values: Vec<f64> = p.iter().map(|q| q.x - 2.0).collect();
    let mesh = TriMesh::new(p, t);
    let view = View {
        light: Vector3::z(),
        margin: 0.0,
        supersample: 1,
        ..View::default()
    };
    let img = render_scalar(&mesh, &values, (-1.0, 1.0), &view, (500, 300)).unwrap();
    assert_eq!(img.dimensions(), (500, 300));
    // Body is 500 − 83 = 417 px wide (legend 500/6); the strip is centred vertically.
    let body_w = 500 - (500 / 6);
    let y = 150;
    assert_eq!(img.get_pixel(5, y).0, diverging(0.0));
    assert_eq!(img.get_pixel(body_w - 5, y).0, diverging(1.0));
    assert!(close(img.get_pixel(body_w / 2, y).0, diverging(0.5), 3));
    let legend: Vec<[u8; 3]> = (0..300)
        .flat_map(|y| (body_w..500).map(move |x| (x, y)))
        .map(|(x, y)| img.get_pixel(x, y).0)
        .collect();
    assert!(legend.contains(&diverging(0.0)) && legend.contains(&diverging(1.0)));
    // Wrong sizes and ranges are errors that say what is wrong.
    let e = render_scalar(&mesh, &values[..3], (-1.0, 1.0), &view, (100, 100)).unwrap_err();
    assert!(e.to_string().contains("one per vertex"), "{e}");
    assert!(render_scalar(&mesh, &values, (1.0, 1.0), &view, (100, 100)).is_err());
}

/// The benchmark's wrinkled dome patch (`furrow bench render`): 2 (n − 1)² triangles.
fn patch(n: usize, amp: f64) -> TriMesh {
    furrow::render::bench::wrinkled_patch(n, amp)
}

#[test]
fn wrinkle_depth_preview_side_by_side_and_contact_sheet() {
    let (dir, _keep) = out_dir();
    let base = patch(121, 0.0);
    let wrinkled = patch(121, 0.0005);
    let depth = wrinkle_depth_mm(&base, &wrinkled.positions).unwrap();
    // The dome is flat-ish at the centre: depth there is the wrinkle height (0.5 mm · sin),
    // and its extremes are close to ±0.5 mm (the normal tilts a little off the centre).
    let (lo, hi) = symmetric_range(&depth, 1e-3);
    assert!(
        hi > 0.45 && hi <= 0.5 + 1e-9 && lo == -hi,
        "range ({lo}, {hi})"
    );
    let view = View {
        bounds: union_bounds(&[&base, &wrinkled]),
        ..View::default()
    };
    let a = render(&base, &view, (320, 320));
    let b = render(&wrinkled, &view, (320, 320));
    let c = render_scalar(&wrinkled, &depth, (lo, hi), &view, (400, 320)).unwrap();
    // Same input, same pixels.
    assert_eq!(render(&wrinkled, &view, (320, 320)), b);
    assert_ne!(a, b, "wrinkles must change the shading");
    let sbs = side_by_side(
        &[a.clone(), b.clone(), c.clone()],
        &["blend shapes", "wrinkled", "depth"],
    );
    // Three cells of the widest image (400 px) with 6 px gaps, plus a label strip.
    assert_eq!(sbs.width(), 3 * 400 + 4 * 6);
    assert!(sbs.height() > 320 + 12);
    // The label strip above the first image holds dark text.
    let dark = (0..400)
        .flat_map(|x| (6..26).map(move |y| (x, y)))
        .filter(|&(x, y)| sbs.get_pixel(x, y).0[0] < 100)
        .count();
    assert!(dark > 30, "label pixels {dark}");
    let frames: Vec<RgbImage> = (0..5)
        .map(|k| render(&patch(61, 0.0002 * k as f64), &view, (160, 160)))
        .collect();
    let labels = ["frame 0", "frame 1", "frame 2", "frame 3", "frame 4"];
    let sheet = contact_sheet(&frames, &labels, 3);
    assert_eq!(sheet.width(), 3 * 160 + 4 * 6);
    // Two rows of (label + frame) with gaps.
    assert!(sheet.height() > 2 * 160 && sheet.height() < 2 * 160 + 3 * 6 + 2 * 40);
    for (name, img) in [("side_by_side.png", &sbs), ("contact_sheet.png", &sheet)] {
        let path = dir.join(name);
        write_png(&path, img).unwrap();
        assert_eq!(&load(&path), img, "{name}: PNG round trip");
    }
}

#[test]
fn large_mesh_renders_at_512() {
    // 20 000 triangles at 512 × 512 (the benchmark below times the same call).
    let (dir, _keep) = out_dir();
    let mesh = patch(101, 0.0005);
    assert_eq!(mesh.triangle_count(), 20_000);
    let view = View::default();
    let img = render(&mesh, &view, (512, 512));
    let frac = covered(&img, view.background) as f64 / (512.0 * 512.0);
    // A square patch seen from the front with a 4% margin fills ≈ 0.92² ≈ 85% of the image.
    eprintln!("20k patch: coverage {frac:.4}, expected {:.4}", 0.92 * 0.92);
    assert!((frac - 0.92 * 0.92).abs() < 0.02, "coverage {frac}");
    write_png(&dir.join("patch_20k.png"), &img).unwrap();
}

/// UV sphere of radius `r` m centred at the origin (`n` segments around, `n/2` rings).
fn sphere(r: f64, n: usize) -> TriMesh {
    let rings = n / 2;
    let mut pos = vec![Vector3::new(0.0, 0.0, r)];
    for i in 1..rings {
        let th = std::f64::consts::PI * i as f64 / rings as f64;
        for j in 0..n {
            let ph = 2.0 * std::f64::consts::PI * j as f64 / n as f64;
            pos.push(Vector3::new(th.sin() * ph.cos(), th.sin() * ph.sin(), th.cos()) * r);
        }
    }
    pos.push(Vector3::new(0.0, 0.0, -r));
    let south = pos.len() - 1;
    let ring = |i: usize, j: usize| 1 + (i - 1) * n + j % n;
    let mut tris = Vec::new();
    for j in 0..n {
        tris.push([0, ring(1, j), ring(1, j + 1)]);
        for i in 1..rings - 1 {
            tris.push([ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)]);
            tris.push([ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)]);
        }
        tris.push([ring(rings - 1, j), south, ring(rings - 1, j + 1)]);
    }
    TriMesh::new(pos, tris)
}

#[test]
fn oblique_view_of_a_sphere_is_a_disc_lit_where_the_normal_meets_the_light() {
    // Looking along (1, 1, 1): the camera fits the sphere's bounding cube, so the sphere is a
    // disc of radius `scale · r` pixels at the image centre; its area matches π (scale r)²
    // to within the polygon's shortfall (< 1% at 96 segments) plus one pixel ring; the
    // brightest pixel is where the surface normal points at the light.
    let (dir, _keep) = out_dir();
    let mesh = sphere(1.0, 96);
    let view = View {
        supersample: 1,
        ..View::looking_along(Vector3::new(1.0, 1.0, 1.0))
    };
    let size = (300, 300);
    let img = render(&mesh, &view, size);
    let cam = Camera::fit(&view, union_bounds(&[&mesh]).unwrap(), size.0, size.1);
    let rpx = cam.scale;
    let want = std::f64::consts::PI * rpx * rpx;
    let got = covered(&img, view.background) as f64;
    eprintln!("sphere: covered {got} px, disc π (scale r)² = {want:.0} px");
    assert!(
        got < want + 2.0 * std::f64::consts::PI * rpx
            && got > 0.99 * want - 2.0 * std::f64::consts::PI * rpx,
        "{got} vs {want}"
    );
    // The point of the sphere whose camera-space normal is the light direction.
    let l = view.light.normalize();
    let world_n = cam.right * l.x + cam.up * l.y + cam.back * l.z;
    let p = cam.project(&world_n);
    let peak = img.get_pixel(p.x as u32, p.y as u32).0[0];
    let max = img
        .pixels()
        .filter(|q| q.0 != view.background)
        .map(|q| q.0[0])
        .max()
        .unwrap();
    assert!(peak + 1 >= max, "peak {peak}, max {max}");
    assert_eq!(peak, view.color[0], "full light: albedo · 1");
    write_png(&dir.join("sphere_oblique.png"), &img).unwrap();
}

#[test]
fn bad_geometry_is_skipped_and_missing_values_are_grey() {
    // A good square, a triangle with an out-of-range index and one with a NaN corner: the
    // square is drawn, the others are left out, nothing panics. A NaN scalar on a vertex of
    // the square makes the pixels of its triangles the "missing" grey, never a map colour.
    let (mut p, mut t) = square(0.0, 0.0, 1.0, 1.0, 0.0, 0);
    p.push(Vector3::new(f64::NAN, 0.5, 0.0));
    t.push([0, 1, 99]);
    t.push([0, 1, 4]);
    let mesh = TriMesh::new(p, t);
    let view = View {
        light: Vector3::z(),
        supersample: 1,
        margin: 0.0,
        bounds: Some((Vector3::zeros(), Vector3::new(1.0, 1.0, 0.0))),
        ..View::default()
    };
    let img = render(&mesh, &view, (50, 50));
    assert_eq!(covered(&img, view.background), 2500);
    let values = vec![0.0, 0.0, 0.0, f64::NAN, 0.0];
    let img = render_scalar(&mesh, &values, (-1.0, 1.0), &view, (50, 50)).unwrap();
    // Triangle [0, 2, 3] (upper left in the image) touches the NaN vertex; [0, 1, 2] does not.
    assert_eq!(img.get_pixel(5, 25).0, furrow::render::colormap::MISSING);
    assert_eq!(img.get_pixel(45, 25).0, diverging(0.5));
}
