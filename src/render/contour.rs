//! Isocontours of a scalar field sampled on a rectangular grid, by marching squares: the lines
//! along which, for example, the critical wavelength λ takes chosen values over (log E_x/E_q, h).

/// A scalar field sampled on a rectangular grid: `values[j * xs.len() + i]` is the value at
/// `(xs[i], ys[j])`. Units are those of the caller (for the wavelength plot: x = E_x/E_q
/// (dimensionless) or its log10, y = skin thickness h, values = λ). Non-finite values mark
/// missing samples; cells touching them produce no contour.
#[derive(Debug, Clone, PartialEq)]
pub struct Grid {
    /// Sample positions along x, strictly increasing.
    pub xs: Vec<f64>,
    /// Sample positions along y, strictly increasing.
    pub ys: Vec<f64>,
    /// Row-major samples, `xs.len() * ys.len()` of them (x varies fastest).
    pub values: Vec<f64>,
}

impl Grid {
    /// A grid from its axes and row-major values; checks sizes and that the axes increase.
    pub fn new(xs: Vec<f64>, ys: Vec<f64>, values: Vec<f64>) -> anyhow::Result<Self> {
        if xs.len() < 2 || ys.len() < 2 {
            anyhow::bail!(
                "contour grid: need at least 2 samples along each axis, got {} × {}",
                xs.len(),
                ys.len()
            );
        }
        if values.len() != xs.len() * ys.len() {
            anyhow::bail!(
                "contour grid: {} values for a {} × {} grid (need {})",
                values.len(),
                xs.len(),
                ys.len(),
                xs.len() * ys.len()
            );
        }
        for (name, axis) in [("x", &xs), ("y", &ys)] {
            if axis.iter().any(|v| !v.is_finite()) || axis.windows(2).any(|w| w[1] <= w[0]) {
                anyhow::bail!(
                    "contour grid: the {name} samples must be finite and strictly increasing"
                );
            }
        }
        Ok(Self { xs, ys, values })
    }

    /// Sample `f(x, y)` at every grid point (the axes must increase; see [`Grid::new`]).
    pub fn from_fn(
        xs: Vec<f64>,
        ys: Vec<f64>,
        f: impl Fn(f64, f64) -> f64,
    ) -> anyhow::Result<Self> {
        let values = ys
            .iter()
            .flat_map(|&y| xs.iter().map(move |&x| (x, y)))
            .map(|(x, y)| f(x, y))
            .collect();
        Self::new(xs, ys, values)
    }

    /// Value at grid point `(i, j)`.
    pub fn at(&self, i: usize, j: usize) -> f64 {
        self.values[j * self.xs.len() + i]
    }
}

/// A straight piece of a contour line: two end points.
pub type Segment = [(f64, f64); 2];

/// Marching squares on an `nx × ny` row-major field (`values[j * nx + i]`): the pieces of the
/// isoline `value = level`, with end points in fractional grid-index coordinates `(i, j)`
/// (linear interpolation along cell edges, so a field linear in i and j gives its exact
/// isoline). Saddle cells are resolved with the cell-centre average. Cells with a non-finite
/// corner are skipped.
pub fn marching_squares(nx: usize, ny: usize, values: &[f64], level: f64) -> Vec<Segment> {
    let mut out = Vec::new();
    if nx < 2 || ny < 2 || values.len() < nx * ny || !level.is_finite() {
        return out;
    }
    let v = |i: usize, j: usize| values[j * nx + i];
    for j in 0..ny - 1 {
        for i in 0..nx - 1 {
            let (v00, v10, v11, v01) = (v(i, j), v(i + 1, j), v(i + 1, j + 1), v(i, j + 1));
            if ![v00, v10, v11, v01].iter().all(|x| x.is_finite()) {
                continue;
            }
            let (fi, fj) = (i as f64, j as f64);
            // Crossing on the edge from a to b (a, b corner values at points pa, pb).
            let cross = |va: f64, vb: f64, pa: (f64, f64), pb: (f64, f64)| {
                if (va >= level) == (vb >= level) {
                    return None;
                }
                let t = (level - va) / (vb - va);
                Some((pa.0 + t * (pb.0 - pa.0), pa.1 + t * (pb.1 - pa.1)))
            };
            let bottom = cross(v00, v10, (fi, fj), (fi + 1.0, fj));
            let right = cross(v10, v11, (fi + 1.0, fj), (fi + 1.0, fj + 1.0));
            let top = cross(v01, v11, (fi, fj + 1.0), (fi + 1.0, fj + 1.0));
            let left = cross(v00, v01, (fi, fj), (fi, fj + 1.0));
            let mut push = |a: Option<(f64, f64)>, b: Option<(f64, f64)>| {
                if let (Some(a), Some(b)) = (a, b) {
                    if (a.0 - b.0).hypot(a.1 - b.1) > 1e-12 {
                        out.push([a, b]);
                    }
                }
            };
            let n = [bottom, right, top, left].iter().flatten().count();
            if n == 4 {
                let diagonal = v00 >= level;
                let centre = 0.25 * (v00 + v10 + v11 + v01) >= level;
                if diagonal == centre {
                    // v00 and v11 are joined through the centre: cut off v10 and v01.
                    push(bottom, right);
                    push(top, left);
                } else {
                    push(left, bottom);
                    push(right, top);
                }
            } else if n == 2 {
                let mut it = [bottom, right, top, left].into_iter().flatten();
                let (a, b) = (it.next(), it.next());
                push(a, b);
            }
        }
    }
    out
}

/// Map a fractional grid index along `axis` to a coordinate: linear between samples, or
/// geometric (straight on a log axis) when `log` is set and the samples are positive.
pub fn index_to_coord(axis: &[f64], f: f64, log: bool) -> f64 {
    let n = axis.len();
    if n == 1 {
        return axis[0];
    }
    let i0 = (f.floor().max(0.0) as usize).min(n - 2);
    let t = f - i0 as f64;
    let (a, b) = (axis[i0], axis[i0 + 1]);
    if log && a > 0.0 && b > 0.0 {
        (a.ln() + t * (b.ln() - a.ln())).exp()
    } else {
        a + t * (b - a)
    }
}

/// The isoline `value = level` of `grid` as segments in the grid's own coordinates. `log_x` /
/// `log_y` interpolate geometrically along that axis (use them when the axis is drawn
/// logarithmically, so the pieces are straight on the plot).
pub fn contour_segments(grid: &Grid, level: f64, log_x: bool, log_y: bool) -> Vec<Segment> {
    marching_squares(grid.xs.len(), grid.ys.len(), &grid.values, level)
        .into_iter()
        .map(|s| {
            s.map(|(fi, fj)| {
                (
                    index_to_coord(&grid.xs, fi, log_x),
                    index_to_coord(&grid.ys, fj, log_y),
                )
            })
        })
        .collect()
}

/// Join segments that share end points into polylines (marching squares computes a crossing
/// shared by two cells identically in both, so shared points match exactly). A closed contour
/// comes back with its first point repeated at the end. Order is deterministic.
pub fn polylines(segments: &[Segment]) -> Vec<Vec<(f64, f64)>> {
    use std::collections::HashMap;
    let key = |p: (f64, f64)| (p.0.to_bits(), p.1.to_bits());
    let mut at: HashMap<(u64, u64), Vec<usize>> = HashMap::new();
    for (k, s) in segments.iter().enumerate() {
        at.entry(key(s[0])).or_default().push(k);
        at.entry(key(s[1])).or_default().push(k);
    }
    let mut used = vec![false; segments.len()];
    // Continue from point `p` along unused segments, appending points to `line`.
    let walk = |p: (f64, f64), line: &mut Vec<(f64, f64)>, used: &mut Vec<bool>| {
        let mut p = p;
        loop {
            let next = at
                .get(&key(p))
                .and_then(|v| v.iter().copied().find(|&k| !used[k]));
            let Some(k) = next else { break };
            used[k] = true;
            let s = segments[k];
            p = if key(s[0]) == key(p) { s[1] } else { s[0] };
            line.push(p);
        }
    };
    let mut out = Vec::new();
    for k in 0..segments.len() {
        if used[k] {
            continue;
        }
        used[k] = true;
        let mut fwd = vec![segments[k][0], segments[k][1]];
        walk(segments[k][1], &mut fwd, &mut used);
        let mut back = Vec::new();
        walk(segments[k][0], &mut back, &mut used);
        back.reverse();
        back.extend(fwd);
        out.push(back);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Length of the line a·x + b·y = c clipped to the rectangle [x0, x1] × [y0, y1].
    fn clipped_length(a: f64, b: f64, c: f64, x0: f64, x1: f64, y0: f64, y1: f64) -> f64 {
        // Parametrise by x (b ≠ 0): y = (c − a x)/b; clip x so that y is inside.
        let ya = (c - a * x0) / b;
        let yb = (c - a * x1) / b;
        let (mut lo, mut hi) = (x0, x1);
        let xs_at = |y: f64| (c - b * y) / a;
        let (ylo, yhi) = (ya.min(yb), ya.max(yb));
        if ylo < y0 {
            let x = xs_at(y0);
            if ya < yb {
                lo = lo.max(x)
            } else {
                hi = hi.min(x)
            }
        }
        if yhi > y1 {
            let x = xs_at(y1);
            if ya < yb {
                hi = hi.min(x)
            } else {
                lo = lo.max(x)
            }
        }
        if hi <= lo {
            return 0.0;
        }
        let dy = (a / b) * (hi - lo);
        (hi - lo).hypot(dy)
    }

    #[test]
    fn plane_gives_its_straight_isoline() {
        // Non-uniform axes; the field is linear in (x, y), so linear interpolation along
        // edges is exact: every end point lies on a·x + b·y = level, and the pieces add up to
        // the length of that line inside the grid.
        let xs = vec![0.0, 0.4, 1.0, 1.5, 2.5, 3.0];
        let ys = vec![-1.0, -0.2, 0.3, 1.0, 2.0];
        let (a, b) = (0.8, -1.3);
        let g = Grid::from_fn(xs.clone(), ys.clone(), |x, y| a * x + b * y).unwrap();
        for level in [-1.7, 0.0, 0.55, 2.1] {
            let segs = contour_segments(&g, level, false, false);
            assert!(!segs.is_empty(), "level {level}");
            let mut total = 0.0;
            for s in &segs {
                for &(x, y) in s {
                    assert!(
                        (a * x + b * y - level).abs() < 1e-12,
                        "off the line: {x} {y}"
                    );
                    assert!((0.0..=3.0).contains(&x) && (-1.0..=2.0).contains(&y));
                }
                total += (s[1].0 - s[0].0).hypot(s[1].1 - s[0].1);
            }
            let want = clipped_length(a, b, level, 0.0, 3.0, -1.0, 2.0);
            assert!(
                (total - want).abs() < 1e-9,
                "level {level}: {total} vs {want}"
            );
        }
        // One open polyline from boundary to boundary.
        let lines = polylines(&contour_segments(&g, 0.55, false, false));
        assert_eq!(lines.len(), 1);
        // A level outside the field's range has no contour.
        assert!(contour_segments(&g, 100.0, false, false).is_empty());
    }

    #[test]
    fn circle_contour_has_the_right_radius() {
        // f = x² + y² on a fine grid: the isoline at r² lies within the interpolation error
        // (≤ h²/4 in f, so ≤ h²/(8 r) in radius) of the circle of radius r.
        let n = 81;
        let h = 2.0 / (n - 1) as f64;
        let axis: Vec<f64> = (0..n).map(|k| -1.0 + k as f64 * h).collect();
        let g = Grid::from_fn(axis.clone(), axis, |x, y| x * x + y * y).unwrap();
        let r = 0.7;
        let segs = contour_segments(&g, r * r, false, false);
        let mut len = 0.0;
        for s in &segs {
            for &(x, y) in s {
                assert!((x.hypot(y) - r).abs() <= h * h / (8.0 * r) + 1e-12);
            }
            len += (s[1].0 - s[0].0).hypot(s[1].1 - s[0].1);
        }
        // Inscribed polygon: perimeter slightly under 2πr.
        let c = 2.0 * std::f64::consts::PI * r;
        assert!(len < c && len > c * 0.995, "{len} vs {c}");
        // The pieces join into one closed polyline.
        let lines = polylines(&segs);
        assert_eq!(lines.len(), 1);
        assert_eq!(lines[0].len(), segs.len() + 1);
        assert_eq!(lines[0].first(), lines[0].last());
    }

    #[test]
    fn saddle_and_missing_samples() {
        // Saddle cell: corners 1, 0, 1, 0 at level 0.5: two pieces, never crossing.
        let segs = marching_squares(2, 2, &[1.0, 0.0, 0.0, 1.0], 0.5);
        assert_eq!(segs.len(), 2);
        // A NaN corner removes the cell, not the whole contour.
        let mut v: Vec<f64> = (0..9).map(|k| (k % 3) as f64).collect();
        let full = marching_squares(3, 3, &v, 0.5).len();
        v[8] = f64::NAN;
        let part = marching_squares(3, 3, &v, 0.5).len();
        assert_eq!(full, 2);
        assert_eq!(
            part, 2,
            "the NaN is in the cell that the 0.5 line does not cross"
        );
        assert!(Grid::new(vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0; 3]).is_err());
        assert!(Grid::new(vec![1.0, 0.0], vec![0.0, 1.0], vec![0.0; 4]).is_err());
    }

    #[test]
    fn log_axis_interpolates_geometrically() {
        let axis = [1.0, 100.0];
        assert!((index_to_coord(&axis, 0.5, true) - 10.0).abs() < 1e-12);
        assert!((index_to_coord(&axis, 0.5, false) - 50.5).abs() < 1e-12);
    }
}
