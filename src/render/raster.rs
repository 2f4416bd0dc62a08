//! Triangle rasterisation with a depth buffer: which triangle is nearest the viewer at each
//! pixel, and where inside it (barycentric coordinates). Shading happens afterwards, once per
//! visible pixel (see [`super::preview`]). Single-threaded and deterministic: the same input
//! gives the same pixels on every machine and thread count.

/// A vertex already projected to the screen: pixel coordinates (x to the right, y downwards,
/// pixel (i, j) covers [i, i+1) × [j, j+1)) and depth along the view axis in metres, larger
/// meaning nearer to the viewer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScreenVertex {
    /// Horizontal pixel coordinate.
    pub x: f64,
    /// Vertical pixel coordinate (downwards).
    pub y: f64,
    /// Depth (m), larger is nearer.
    pub depth: f64,
}

/// Marker for a pixel that no triangle covers.
pub const NO_TRIANGLE: u32 = u32::MAX;

/// The visible surface at every pixel: nearest triangle, its depth and the barycentric
/// coordinates of the pixel centre in it. Row-major, `width * height` entries.
#[derive(Debug, Clone, PartialEq)]
pub struct Fragments {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Depth (m) of the nearest surface, `-inf` where nothing was drawn.
    pub depth: Vec<f64>,
    /// Index of the nearest triangle, [`NO_TRIANGLE`] where nothing was drawn.
    pub triangle: Vec<u32>,
    /// Barycentric weights of the triangle's three corners at the pixel centre.
    pub bary: Vec<[f64; 3]>,
}

impl Fragments {
    /// An empty buffer of `width × height` pixels.
    pub fn new(width: u32, height: u32) -> Self {
        let n = width as usize * height as usize;
        Self {
            width,
            height,
            depth: vec![f64::NEG_INFINITY; n],
            triangle: vec![NO_TRIANGLE; n],
            bary: vec![[0.0; 3]; n],
        }
    }

    /// Number of pixels covered by some triangle.
    pub fn covered(&self) -> usize {
        self.triangle.iter().filter(|&&t| t != NO_TRIANGLE).count()
    }

    /// Draw triangle number `id` with corners `v`: every pixel whose centre lies inside it
    /// (edges included) and whose current depth is farther takes it. Both windings are drawn
    /// (no back-face culling); triangles with a non-finite corner or zero screen area are
    /// skipped. On equal depth the earlier triangle stays, so the result does not depend on
    /// anything but the input order.
    pub fn draw_triangle(&mut self, id: u32, v: [ScreenVertex; 3]) {
        if v.iter()
            .any(|p| !(p.x.is_finite() && p.y.is_finite() && p.depth.is_finite()))
        {
            return;
        }
        let [a, b, c] = v;
        let area = (b.x - a.x) * (c.y - a.y) - (c.x - a.x) * (b.y - a.y);
        if area.abs() < 1e-12 {
            return;
        }
        let (w, h) = (self.width as f64, self.height as f64);
        // Pixel centres (i + 0.5) inside the box [min, max].
        let lo_x = (a.x.min(b.x).min(c.x) - 0.5).ceil().max(0.0);
        let hi_x = (a.x.max(b.x).max(c.x) - 0.5).floor().min(w - 1.0);
        let lo_y = (a.y.min(b.y).min(c.y) - 0.5).ceil().max(0.0);
        let hi_y = (a.y.max(b.y).max(c.y) - 0.5).floor().min(h - 1.0);
        if lo_x > hi_x || lo_y > hi_y {
            return;
        }
        let inv = 1.0 / area;
        // Barycentric weights are affine in (x, y): w_k = c_k + dx_k x + dy_k y.
        let edge = |p: ScreenVertex, q: ScreenVertex| {
            // Signed area of (p, q, r) as a function of r, divided by the triangle's area.
            let dx = -(q.y - p.y) * inv;
            let dy = (q.x - p.x) * inv;
            let c0 = ((q.y - p.y) * p.x - (q.x - p.x) * p.y) * inv;
            (c0, dx, dy)
        };
        let e = [edge(b, c), edge(c, a), edge(a, b)];
        let (x0, x1, y0, y1) = (lo_x as usize, hi_x as usize, lo_y as usize, hi_y as usize);
        let width = self.width as usize;
        for j in y0..=y1 {
            let py = j as f64 + 0.5;
            for i in x0..=x1 {
                let px = i as f64 + 0.5;
                let wa = e[0].0 + e[0].1 * px + e[0].2 * py;
                let wb = e[1].0 + e[1].1 * px + e[1].2 * py;
                let wc = e[2].0 + e[2].1 * px + e[2].2 * py;
                // Inside with a little slack so shared edges leave no cracks.
                const EPS: f64 = -1e-9;
                if wa < EPS || wb < EPS || wc < EPS {
                    continue;
                }
                let z = wa * a.depth + wb * b.depth + wc * c.depth;
                let k = j * width + i;
                if z > self.depth[k] {
                    self.depth[k] = z;
                    self.triangle[k] = id;
                    self.bary[k] = [wa, wb, wc];
                }
            }
        }
    }
}

/// Rasterise all `triangles` (indices into `vertices`) into a `width × height` buffer, in order.
pub fn rasterize(
    width: u32,
    height: u32,
    vertices: &[ScreenVertex],
    triangles: &[[usize; 3]],
) -> Fragments {
    let mut f = Fragments::new(width, height);
    for (t, &[a, b, c]) in triangles.iter().enumerate() {
        if a < vertices.len() && b < vertices.len() && c < vertices.len() {
            f.draw_triangle(t as u32, [vertices[a], vertices[b], vertices[c]]);
        }
    }
    f
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sv(x: f64, y: f64, depth: f64) -> ScreenVertex {
        ScreenVertex { x, y, depth }
    }

    #[test]
    fn square_of_two_triangles_covers_exactly_its_pixels() {
        // A square from (2, 3) to (12, 9) in pixels: pixel centres inside are i = 2..=11,
        // j = 3..=8, i.e. 10 × 6 = 60 pixels, each covered once and none outside (the
        // shared diagonal leaves no crack).
        let v = [
            sv(2.0, 3.0, 0.0),
            sv(12.0, 3.0, 0.0),
            sv(12.0, 9.0, 0.0),
            sv(2.0, 9.0, 0.0),
        ];
        let f = rasterize(16, 12, &v, &[[0, 1, 2], [0, 2, 3]]);
        assert_eq!(f.covered(), 60);
        for j in 0..12 {
            for i in 0..16 {
                let inside = (2..12).contains(&i) && (3..9).contains(&j);
                assert_eq!(f.triangle[j * 16 + i] != NO_TRIANGLE, inside, "{i} {j}");
            }
        }
    }

    #[test]
    fn barycentrics_reproduce_the_pixel_centre_and_depth() {
        let v = [sv(1.0, 1.0, 1.0), sv(30.0, 4.0, 2.0), sv(8.0, 25.0, 3.0)];
        let f = rasterize(32, 32, &v, &[[0, 1, 2]]);
        assert!(f.covered() > 200);
        for j in 0..32 {
            for i in 0..32 {
                let k = j * 32 + i;
                if f.triangle[k] == NO_TRIANGLE {
                    continue;
                }
                let b = f.bary[k];
                assert!((b[0] + b[1] + b[2] - 1.0).abs() < 1e-12);
                let x = b[0] * v[0].x + b[1] * v[1].x + b[2] * v[2].x;
                let y = b[0] * v[0].y + b[1] * v[1].y + b[2] * v[2].y;
                assert!((x - (i as f64 + 0.5)).abs() < 1e-9 && (y - (j as f64 + 0.5)).abs() < 1e-9);
                let z = b[0] + 2.0 * b[1] + 3.0 * b[2];
                assert!((f.depth[k] - z).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn nearer_triangle_wins_in_either_order() {
        let far = [sv(0.0, 0.0, -1.0), sv(20.0, 0.0, -1.0), sv(0.0, 20.0, -1.0)];
        let near = [sv(0.0, 0.0, 1.0), sv(20.0, 0.0, 1.0), sv(0.0, 20.0, 1.0)];
        let verts: Vec<ScreenVertex> = far.iter().chain(near.iter()).copied().collect();
        let f1 = rasterize(20, 20, &verts, &[[0, 1, 2], [3, 4, 5]]);
        let f2 = rasterize(20, 20, &verts, &[[3, 4, 5], [0, 1, 2]]);
        let k = 5 * 20 + 5;
        assert_eq!(f1.triangle[k], 1);
        assert_eq!(f2.triangle[k], 0);
        assert_eq!(f1.depth[k], 1.0);
        assert_eq!(f2.depth[k], 1.0);
    }

    #[test]
    fn degenerate_and_non_finite_triangles_are_skipped() {
        let v = [
            sv(0.0, 0.0, 0.0),
            sv(10.0, 10.0, 0.0),
            sv(20.0, 20.0, 0.0),
            sv(f64::NAN, 3.0, 0.0),
        ];
        let f = rasterize(32, 32, &v, &[[0, 1, 2], [0, 1, 3], [0, 1, 9]]);
        assert_eq!(f.covered(), 0);
    }
}
