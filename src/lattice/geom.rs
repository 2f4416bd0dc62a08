//! Small exact geometric predicates used to build the lattice: triangle/box overlap,
//! segment/box and segment/triangle intersection, closest point on a triangle, and the solid
//! angle of a triangle (for generalised winding numbers). Lengths in metres.

use nalgebra::Vector3;

type V = Vector3<f64>;

/// Does the closed axis-aligned box [lo, hi] intersect the triangle (a, b, c)?
/// Separating-axis test (Akenine-Möller 2001): 3 box axes, the triangle normal, 9 edge
/// cross products.
pub fn triangle_box_overlap(a: &V, b: &V, c: &V, lo: &V, hi: &V) -> bool {
    let center = (lo + hi) * 0.5;
    let half = (hi - lo) * 0.5;
    let v = [a - center, b - center, c - center];
    // Box axes.
    for d in 0..3 {
        let mn = v[0][d].min(v[1][d]).min(v[2][d]);
        let mx = v[0][d].max(v[1][d]).max(v[2][d]);
        if mn > half[d] || mx < -half[d] {
            return false;
        }
    }
    let e = [v[1] - v[0], v[2] - v[1], v[0] - v[2]];
    // Triangle normal.
    let n = e[0].cross(&e[1]);
    let r = half.x * n.x.abs() + half.y * n.y.abs() + half.z * n.z.abs();
    if n.dot(&v[0]).abs() > r {
        return false;
    }
    // Edge × box axis.
    for ed in &e {
        for d in 0..3 {
            let mut axis = V::zeros();
            axis[d] = 1.0;
            let ax = ed.cross(&axis);
            let p0 = ax.dot(&v[0]);
            let p1 = ax.dot(&v[1]);
            let p2 = ax.dot(&v[2]);
            let r = half.x * ax.x.abs() + half.y * ax.y.abs() + half.z * ax.z.abs();
            if p0.min(p1).min(p2) > r || p0.max(p1).max(p2) < -r {
                return false;
            }
        }
    }
    true
}

/// Does the closed segment [p, q] intersect the closed box [lo, hi]? (Slab test.)
pub fn segment_box_overlap(p: &V, q: &V, lo: &V, hi: &V) -> bool {
    let d = q - p;
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for k in 0..3 {
        if d[k].abs() < 1e-300 {
            if p[k] < lo[k] || p[k] > hi[k] {
                return false;
            }
        } else {
            let inv = 1.0 / d[k];
            let (mut a, mut b) = ((lo[k] - p[k]) * inv, (hi[k] - p[k]) * inv);
            if a > b {
                std::mem::swap(&mut a, &mut b);
            }
            t0 = t0.max(a);
            t1 = t1.min(b);
            if t0 > t1 {
                return false;
            }
        }
    }
    true
}

/// Does the segment p → q cross the triangle (a, b, c) strictly between its ends
/// (parameter in (tol, 1 − tol))? Möller–Trumbore; edge hits count as crossings.
pub fn segment_crosses_triangle(p: &V, q: &V, a: &V, b: &V, c: &V, tol: f64) -> bool {
    let d = q - p;
    let e1 = b - a;
    let e2 = c - a;
    let h = d.cross(&e2);
    let det = e1.dot(&h);
    let scale = e1.norm() * e2.norm() * d.norm();
    if det.abs() <= 1e-14 * scale {
        return false; // parallel (coplanar segments are treated as not crossing)
    }
    let f = 1.0 / det;
    let s = p - a;
    let u = f * s.dot(&h);
    if !(-1e-12..=1.0 + 1e-12).contains(&u) {
        return false;
    }
    let qv = s.cross(&e1);
    let v = f * d.dot(&qv);
    if v < -1e-12 || u + v > 1.0 + 1e-12 {
        return false;
    }
    let t = f * e2.dot(&qv);
    t > tol && t < 1.0 - tol
}

/// The point of triangle (a, b, c) closest to p (Ericson, Real-Time Collision Detection 5.1.5).
pub fn closest_point_on_triangle(p: &V, a: &V, b: &V, c: &V) -> V {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(&ap);
    let d2 = ac.dot(&ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return *a;
    }
    let bp = p - b;
    let d3 = ab.dot(&bp);
    let d4 = ac.dot(&bp);
    if d3 >= 0.0 && d4 <= d3 {
        return *b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return a + ab * v;
    }
    let cp = p - c;
    let d5 = ab.dot(&cp);
    let d6 = ac.dot(&cp);
    if d6 >= 0.0 && d5 <= d6 {
        return *c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return a + ac * w;
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return b + (c - b) * w;
    }
    let denom = 1.0 / (va + vb + vc);
    let v = vb * denom;
    let w = vc * denom;
    a + ab * v + ac * w
}

/// Signed solid angle (steradians) of triangle (a, b, c) seen from p (Van Oosterom and
/// Strackee 1983): positive when p is behind the triangle (on the side opposite its
/// counter-clockwise normal). A closed outward-oriented surface subtends 4π at inside points.
pub fn solid_angle(p: &V, a: &V, b: &V, c: &V) -> f64 {
    let (x, y, z) = (a - p, b - p, c - p);
    let (lx, ly, lz) = (x.norm(), y.norm(), z.norm());
    let num = x.dot(&y.cross(&z));
    let den = lx * ly * lz + x.dot(&y) * lz + x.dot(&z) * ly + y.dot(&z) * lx;
    2.0 * num.atan2(den)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn v(x: f64, y: f64, z: f64) -> V {
        V::new(x, y, z)
    }

    #[test]
    fn predicates_on_known_cases() {
        let (lo, hi) = (v(0., 0., 0.), v(1., 1., 1.));
        // Triangle slicing through the box, one far away, one whose plane misses the box.
        assert!(triangle_box_overlap(
            &v(-1., 0.5, -1.),
            &v(3., 0.5, -1.),
            &v(-1., 0.5, 3.),
            &lo,
            &hi
        ));
        assert!(!triangle_box_overlap(
            &v(2., 2., 2.),
            &v(3., 2., 2.),
            &v(2., 3., 2.),
            &lo,
            &hi
        ));
        // Big triangle near a corner: bounding boxes overlap but the triangle misses.
        assert!(!triangle_box_overlap(
            &v(1.2, 2., 0.),
            &v(2., 1.2, 0.),
            &v(2., 2., 2.),
            &lo,
            &hi
        ));
        assert!(segment_box_overlap(
            &v(-1., 0.5, 0.5),
            &v(2., 0.5, 0.5),
            &lo,
            &hi
        ));
        assert!(!segment_box_overlap(
            &v(-1., 2., 0.5),
            &v(2., 2., 0.5),
            &lo,
            &hi
        ));
        let (a, b, c) = (v(0., 0., 0.), v(1., 0., 0.), v(0., 1., 0.));
        assert!(segment_crosses_triangle(
            &v(0.2, 0.2, -1.),
            &v(0.2, 0.2, 1.),
            &a,
            &b,
            &c,
            1e-9
        ));
        assert!(!segment_crosses_triangle(
            &v(0.8, 0.8, -1.),
            &v(0.8, 0.8, 1.),
            &a,
            &b,
            &c,
            1e-9
        ));
        assert!(
            (closest_point_on_triangle(&v(0.2, 0.3, 5.), &a, &b, &c) - v(0.2, 0.3, 0.)).norm()
                < 1e-15
        );
        assert!(
            (closest_point_on_triangle(&v(2., 2., 0.), &a, &b, &c) - v(0.5, 0.5, 0.)).norm()
                < 1e-15
        );
        // An octant triangle subtends 4π/8 from the origin... seen from the origin the
        // triangle (1,0,0),(0,1,0),(0,0,1) covers one octant of the sphere: π/2.
        let o = solid_angle(
            &v(0., 0., 0.),
            &v(1., 0., 0.),
            &v(0., 1., 0.),
            &v(0., 0., 1.),
        );
        assert!((o - std::f64::consts::FRAC_PI_2).abs() < 1e-12, "{o}");
    }
}
