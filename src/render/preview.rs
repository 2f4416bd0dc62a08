//! Preview images of meshes without a GPU: an orthographic camera fitted to a bounding box,
//! a depth buffer ([`super::raster`]), per-vertex normals interpolated per pixel with Lambert
//! shading plus a little ambient light, and optionally a per-vertex scalar (such as wrinkle
//! depth in mm) coloured by a symmetric diverging map with a legend bar. Images are composed
//! side by side or as a contact sheet with labels in the shipped font. Output is deterministic
//! (single-threaded, no dependence on thread count or platform fonts).

use super::colormap::{diverging, diverging_f, normalise};
use super::font::{draw_text, text_size};
use super::plot::format_number;
use super::raster::{rasterize, ScreenVertex, NO_TRIANGLE};
use crate::mesh::TriMesh;
use image::{Rgb, RgbImage};
use nalgebra::Vector3;

pub use super::write_png;

/// How to look at a mesh: camera direction and framing, light, colours.
#[derive(Debug, Clone, PartialEq)]
pub struct View {
    /// Direction the camera looks along, in world space (need not be unit). Default −z, i.e.
    /// +z points towards the viewer (a front view of a face modelled facing +z).
    pub direction: Vector3<f64>,
    /// World direction that appears upwards on the image (default +y; if parallel to
    /// `direction`, +z or +x is used instead).
    pub up: Vector3<f64>,
    /// Direction towards the light in camera coordinates (x right, y up, z towards the
    /// viewer); default from the upper left, in front.
    pub light: Vector3<f64>,
    /// Ambient fraction of the light, in [0, 1]: shade = ambient + (1 − ambient)·max(0, n·l).
    pub ambient: f64,
    /// Surface colour (RGB) for plain renders.
    pub color: [u8; 3],
    /// Background colour (RGB).
    pub background: [u8; 3],
    /// Empty border around the fitted box, as a fraction of the image size on each side.
    pub margin: f64,
    /// World-space box (min, max corners, m) to fit in the image; `None` fits each mesh's own
    /// bounding box. Set it (e.g. with [`union_bounds`]) so that several frames share a camera.
    pub bounds: Option<(Vector3<f64>, Vector3<f64>)>,
    /// Samples per pixel along each axis (1 = none; 2 = 4 samples per pixel, smoother edges).
    pub supersample: u32,
    /// Legend title for scalar renders, with its unit.
    pub scalar_label: String,
}

impl Default for View {
    fn default() -> Self {
        Self {
            direction: -Vector3::z(),
            up: Vector3::y(),
            light: Vector3::new(-0.4, 0.5, 1.0),
            ambient: 0.15,
            color: [214, 200, 188],
            background: [236, 236, 236],
            margin: 0.04,
            bounds: None,
            supersample: 2,
            scalar_label: "wrinkle depth (mm)".into(),
        }
    }
}

impl View {
    /// The default front view, looking along `direction` instead (world space).
    pub fn looking_along(direction: Vector3<f64>) -> Self {
        Self {
            direction,
            ..Self::default()
        }
    }
}

/// The smallest axis-aligned box (min, max corners, m) holding every vertex of every mesh, or
/// `None` when there is no vertex. Non-finite positions are ignored.
pub fn union_bounds(meshes: &[&TriMesh]) -> Option<(Vector3<f64>, Vector3<f64>)> {
    let mut it = meshes
        .iter()
        .flat_map(|m| m.positions.iter())
        .filter(|p| p.iter().all(|c| c.is_finite()));
    let first = *it.next()?;
    Some(it.fold((first, first), |(lo, hi), p| (lo.inf(p), hi.sup(p))))
}

/// An orthographic camera: an orthonormal frame (right, up, towards the viewer) and the
/// mapping of camera coordinates (m) to pixels.
#[derive(Debug, Clone, PartialEq)]
pub struct Camera {
    /// World direction of the image's +x axis.
    pub right: Vector3<f64>,
    /// World direction of the image's upward axis.
    pub up: Vector3<f64>,
    /// World direction towards the viewer (depth grows along it).
    pub back: Vector3<f64>,
    /// Camera-space point (m) at the image centre.
    pub centre: (f64, f64),
    /// Pixels per metre.
    pub scale: f64,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
}

impl Camera {
    /// The camera of `view` that fits the box `bounds` (min, max corners, m) into a
    /// `width × height` image with the view's margin, keeping the aspect ratio.
    pub fn fit(view: &View, bounds: (Vector3<f64>, Vector3<f64>), width: u32, height: u32) -> Self {
        let f = {
            let n = view.direction.norm();
            if n > 0.0 && n.is_finite() {
                view.direction / n
            } else {
                -Vector3::z()
            }
        };
        let mut up_hint = view.up;
        for alt in [Vector3::z(), Vector3::x()] {
            if f.cross(&up_hint).norm() > 1e-9 * up_hint.norm().max(1e-300) {
                break;
            }
            up_hint = alt;
        }
        let right = f.cross(&up_hint).normalize();
        let up = right.cross(&f);
        let back = -f;
        let (lo, hi) = bounds;
        let (mut x0, mut x1, mut y0, mut y1) = (f64::MAX, f64::MIN, f64::MAX, f64::MIN);
        for k in 0..8 {
            let p = Vector3::new(
                if k & 1 == 0 { lo.x } else { hi.x },
                if k & 2 == 0 { lo.y } else { hi.y },
                if k & 4 == 0 { lo.z } else { hi.z },
            );
            let (cx, cy) = (p.dot(&right), p.dot(&up));
            x0 = x0.min(cx);
            x1 = x1.max(cx);
            y0 = y0.min(cy);
            y1 = y1.max(cy);
        }
        let m = view.margin.clamp(0.0, 0.45);
        let (w, h) = (width as f64, height as f64);
        let sx = w * (1.0 - 2.0 * m) / (x1 - x0);
        let sy = h * (1.0 - 2.0 * m) / (y1 - y0);
        let mut scale = sx.min(sy);
        if !(scale.is_finite() && scale > 0.0) {
            scale = sx.max(sy);
        }
        if !(scale.is_finite() && scale > 0.0) {
            scale = 1.0;
        }
        Self {
            right,
            up,
            back,
            centre: (0.5 * (x0 + x1), 0.5 * (y0 + y1)),
            scale,
            width,
            height,
        }
    }

    /// Camera coordinates (m) of a world point: x right, y up, z towards the viewer.
    pub fn to_camera(&self, p: &Vector3<f64>) -> Vector3<f64> {
        Vector3::new(p.dot(&self.right), p.dot(&self.up), p.dot(&self.back))
    }

    /// Screen position (pixels, y down) and depth (m, larger is nearer) of a world point.
    pub fn project(&self, p: &Vector3<f64>) -> ScreenVertex {
        let c = self.to_camera(p);
        ScreenVertex {
            x: self.width as f64 / 2.0 + (c.x - self.centre.0) * self.scale,
            y: self.height as f64 / 2.0 - (c.y - self.centre.1) * self.scale,
            depth: c.z,
        }
    }
}

/// Render `mesh` into a `width × height` image (supersampled), each visible pixel coloured by
/// `albedo(corner vertex indices, barycentric weights)` (channels in 0..=1) times the Lambert
/// shade. Triangles with an out-of-range vertex index are left out.
fn render_with(
    mesh: &TriMesh,
    view: &View,
    (width, height): (u32, u32),
    albedo: &dyn Fn([usize; 3], [f64; 3]) -> [f64; 3],
) -> RgbImage {
    let mut img = RgbImage::from_pixel(width, height, Rgb(view.background));
    if width == 0 || height == 0 {
        return img;
    }
    let Some(bounds) = view.bounds.or_else(|| union_bounds(&[mesh])) else {
        return img;
    };
    let nv = mesh.vertex_count();
    let valid_mesh;
    let mesh = if mesh.triangles.iter().flatten().all(|&v| v < nv) {
        mesh
    } else {
        valid_mesh = TriMesh::new(
            mesh.positions.clone(),
            mesh.triangles
                .iter()
                .copied()
                .filter(|t| t.iter().all(|&v| v < nv))
                .collect(),
        );
        &valid_mesh
    };
    let ss = view.supersample.clamp(1, 8);
    let (sw, sh) = (width * ss, height * ss);
    let cam = Camera::fit(view, bounds, sw, sh);
    let screen: Vec<ScreenVertex> = mesh.positions.iter().map(|p| cam.project(p)).collect();
    let frags = rasterize(sw, sh, &screen, &mesh.triangles);
    let normals: Vec<Vector3<f64>> = mesh
        .vertex_normals()
        .iter()
        .map(|n| cam.to_camera(n))
        .collect();
    // Which side of each triangle the viewer sees (+1 front, −1 back) and its unit normal.
    let faces: Vec<(f64, Vector3<f64>)> = mesh
        .triangles
        .iter()
        .map(|&[a, b, c]| {
            let p = &mesh.positions;
            let n = cam.to_camera(&(p[b] - p[a]).cross(&(p[c] - p[a])));
            let side = if n.z >= 0.0 { 1.0 } else { -1.0 };
            let l = n.norm();
            (side, if l > 0.0 { n / l } else { Vector3::z() })
        })
        .collect();
    let light = {
        let l = view.light.norm();
        if l > 0.0 && l.is_finite() {
            view.light / l
        } else {
            Vector3::z()
        }
    };
    let ambient = view.ambient.clamp(0.0, 1.0);
    let bg = view.background.map(|c| c as f64 / 255.0);
    let inv = 1.0 / (ss * ss) as f64;
    for y in 0..height {
        for x in 0..width {
            let mut acc = [0.0; 3];
            for sy in 0..ss {
                for sx in 0..ss {
                    let k = (y * ss + sy) as usize * sw as usize + (x * ss + sx) as usize;
                    let t = frags.triangle[k];
                    let c = if t == NO_TRIANGLE {
                        bg
                    } else {
                        let t = t as usize;
                        let w = frags.bary[k];
                        let [a, b, c] = mesh.triangles[t];
                        let (side, face_n) = faces[t];
                        let mut n =
                            (normals[a] * w[0] + normals[b] * w[1] + normals[c] * w[2]) * side;
                        let l = n.norm();
                        n = if l > 1e-12 && l.is_finite() {
                            n / l
                        } else {
                            face_n * side
                        };
                        let shade = ambient + (1.0 - ambient) * n.dot(&light).max(0.0);
                        albedo([a, b, c], w).map(|v| v * shade)
                    };
                    for i in 0..3 {
                        acc[i] += c[i];
                    }
                }
            }
            let px = acc.map(|v| (v * inv * 255.0).round().clamp(0.0, 255.0) as u8);
            img.put_pixel(x, y, Rgb(px));
        }
    }
    img
}

/// A shaded render of `mesh` (front view by default) of `size = (width, height)` pixels.
pub fn render(mesh: &TriMesh, view: &View, size: (u32, u32)) -> RgbImage {
    let base = view.color.map(|c| c as f64 / 255.0);
    render_with(mesh, view, size, &|_, _| base)
}

/// A shaded render of `mesh` coloured by the per-vertex scalar `values` (interpolated across
/// triangles) with the diverging colour map over `range = (lo, hi)` (lo blue, middle
/// near-white, hi red; values outside are clamped, non-finite values grey), plus a legend bar
/// on the right with the range and [`View::scalar_label`]. For a signed quantity such as
/// wrinkle depth use a symmetric range ([`super::colormap::symmetric_range`]).
pub fn render_scalar(
    mesh: &TriMesh,
    values: &[f64],
    range: (f64, f64),
    view: &View,
    size: (u32, u32),
) -> anyhow::Result<RgbImage> {
    if values.len() != mesh.vertex_count() {
        anyhow::bail!(
            "scalar render: {} values for a mesh of {} vertices (need one per vertex)",
            values.len(),
            mesh.vertex_count()
        );
    }
    if !(range.0.is_finite() && range.1.is_finite() && range.0 < range.1) {
        anyhow::bail!(
            "scalar render: colour range ({}, {}) must be finite with low < high",
            range.0,
            range.1
        );
    }
    let (width, height) = size;
    let legend_w = if width >= 240 {
        (width / 6).clamp(80, 170)
    } else {
        0
    };
    let albedo = |[a, b, c]: [usize; 3], w: [f64; 3]| {
        let (va, vb, vc) = (values[a], values[b], values[c]);
        if !(va.is_finite() && vb.is_finite() && vc.is_finite()) {
            return diverging_f(f64::NAN);
        }
        diverging_f(normalise(w[0] * va + w[1] * vb + w[2] * vc, range))
    };
    let body = render_with(mesh, view, (width - legend_w, height), &albedo);
    let mut img = RgbImage::from_pixel(width, height, Rgb(view.background));
    image::imageops::replace(&mut img, &body, 0, 0);
    if legend_w > 0 {
        draw_legend(
            &mut img,
            width - legend_w,
            legend_w,
            range,
            &view.scalar_label,
        );
    }
    Ok(img)
}

/// Draw a vertical colour bar with its range and title into the strip starting at column
/// `x0`, `w` pixels wide.
fn draw_legend(img: &mut RgbImage, x0: u32, w: u32, range: (f64, f64), label: &str) {
    let h = img.height();
    let fs = (h as f64 / 24.0).clamp(11.0, 20.0);
    let ink = [20, 20, 20];
    // The title, wrapped at spaces to fit the strip (a word longer than the strip is clipped).
    let mut lines: Vec<String> = Vec::new();
    for word in label.split_whitespace() {
        match lines.last_mut() {
            Some(line) if text_size(&format!("{line} {word}"), fs).0 + 8 <= w => {
                line.push(' ');
                line.push_str(word);
            }
            _ => lines.push(word.to_string()),
        }
    }
    let line_h = (fs * 1.2).ceil() as u32;
    for (k, line) in lines.iter().enumerate() {
        draw_text(
            img,
            line,
            x0 as i32 + 4,
            6 + (k as u32 * line_h) as i32,
            fs,
            ink,
        );
    }
    let top = 6 + lines.len() as u32 * line_h + (fs * 0.8) as u32;
    let bottom = h.saturating_sub(fs as u32 + 12);
    if bottom <= top + 10 {
        return;
    }
    let bar_x = x0 + 8;
    let bar_w = (w / 6).clamp(10, 24);
    for y in top..=bottom {
        let t = 1.0 - (y - top) as f64 / (bottom - top) as f64;
        let c = diverging(t);
        for x in bar_x..bar_x + bar_w {
            img.put_pixel(x, y, Rgb(c));
        }
    }
    for (t, v) in [
        (1.0, range.1),
        (0.5, 0.5 * (range.0 + range.1)),
        (0.0, range.0),
    ] {
        let y = top as f64 + (1.0 - t) * (bottom - top) as f64;
        for x in bar_x + bar_w..bar_x + bar_w + 5 {
            img.put_pixel(x, y.round() as u32, Rgb(ink));
        }
        let x = bar_x + bar_w + 8;
        let room = img.width().saturating_sub(x + 2);
        draw_text(
            img,
            &tick_label(v, fs, room),
            x as i32,
            (y - fs * 0.5) as i32,
            fs,
            ink,
        );
    }
}

/// `v` as [`format_number`] writes it, with fewer decimals when that is wider than `room`
/// pixels at font size `fs` (a label is rounded rather than clipped at the image's edge).
fn tick_label(v: f64, fs: f64, room: u32) -> String {
    let full = format_number(v);
    if text_size(&full, fs).0 <= room || !(1e-3..1e5).contains(&v.abs()) {
        return full;
    }
    (0..4)
        .rev()
        .map(|d| {
            let s = format!("{v:.d$}");
            if s.contains('.') {
                s.trim_end_matches('0').trim_end_matches('.').to_string()
            } else {
                s
            }
        })
        .find(|s| text_size(s, fs).0 <= room)
        .unwrap_or(full)
}

/// Signed distance (mm) of each wrinkled vertex from the blend-shape-only surface `base`
/// along the base's vertex normal: positive where the skin rises out of the surface (ridges),
/// negative in furrows. Both meshes share `base`'s topology (same vertex order); positions in
/// metres.
pub fn wrinkle_depth_mm(base: &TriMesh, wrinkled: &[Vector3<f64>]) -> anyhow::Result<Vec<f64>> {
    if wrinkled.len() != base.vertex_count() {
        anyhow::bail!(
            "wrinkle depth: wrinkled mesh has {} vertices, the blend-shape surface {} (they must share topology)",
            wrinkled.len(),
            base.vertex_count()
        );
    }
    let n = base.vertex_normals();
    Ok(wrinkled
        .iter()
        .zip(&base.positions)
        .zip(&n)
        .map(|((w, b), n)| (w - b).dot(n) * 1000.0)
        .collect())
}

/// Label text height (pixels) for composing images of height `h`.
fn label_px(h: u32) -> f64 {
    (h as f64 / 22.0).clamp(12.0, 28.0)
}

/// Images placed left to right (top-aligned, 6 px apart) on white, each with its label
/// centred above it (`labels` may be shorter than `images`; missing labels are blank).
pub fn side_by_side(images: &[RgbImage], labels: &[&str]) -> RgbImage {
    contact_sheet(images, labels, images.len().max(1))
}

/// Frames in a grid of `columns` columns (row by row), each cell as large as the largest frame,
/// with the frame's label centred above it, on white, 6 px apart.
pub fn contact_sheet(frames: &[RgbImage], labels: &[&str], columns: usize) -> RgbImage {
    let gap = 6u32;
    let cols = columns.clamp(1, frames.len().max(1)) as u32;
    let rows = (frames.len() as u32).div_ceil(cols).max(1);
    let cw = frames.iter().map(|f| f.width()).max().unwrap_or(0);
    let ch = frames.iter().map(|f| f.height()).max().unwrap_or(0);
    let fs = label_px(ch);
    let has_labels = labels.iter().any(|l| !l.is_empty());
    let lh = if has_labels { fs as u32 + 10 } else { 0 };
    let width = cols * cw + (cols + 1) * gap;
    let height = rows * (ch + lh) + (rows + 1) * gap;
    let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
    for (k, f) in frames.iter().enumerate() {
        let (c, r) = (k as u32 % cols, k as u32 / cols);
        let x = gap + c * (cw + gap);
        let y = gap + r * (ch + lh + gap);
        image::imageops::replace(
            &mut img,
            f,
            (x + (cw - f.width()) / 2) as i64,
            (y + lh) as i64,
        );
        if let Some(label) = labels.get(k).filter(|l| !l.is_empty()) {
            let tw = text_size(label, fs).0.min(cw);
            draw_text(
                &mut img,
                label,
                (x + (cw - tw) / 2) as i32,
                y as i32 + 3,
                fs,
                [0, 0, 0],
            );
        }
    }
    img
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tick_labels_round_to_fit_instead_of_clipping() {
        assert_eq!(tick_label(1.7819, 14.0, 500), "1.7819");
        let narrow = text_size("1.78", 14.0).0;
        assert_eq!(tick_label(1.7819, 14.0, narrow), "1.78");
        assert_eq!(tick_label(-1.7819, 14.0, text_size("-1.8", 14.0).0), "-1.8");
        assert_eq!(tick_label(0.0, 14.0, 1), "0");
    }
}
