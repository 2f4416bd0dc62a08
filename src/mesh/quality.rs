//! Triangle quality: find sliver triangles, which make the thin shell's membrane stiff and
//! ill-conditioned and its hinge angles meaningless, and say where they are and how bad.

use super::TriMesh;
use nalgebra::Vector3;

/// One triangle whose quality is below the threshold.
#[derive(Debug, Clone, PartialEq)]
pub struct Sliver {
    /// Triangle index.
    pub triangle: usize,
    /// Its vertex indices.
    pub vertices: [usize; 3],
    /// Its vertex positions (m).
    pub positions: [Vector3<f64>; 3],
    /// Quality q = 2 r_in / r_circ (1 for equilateral, 0 for degenerate; dimensionless).
    pub quality: f64,
    /// Smallest interior angle (degrees).
    pub min_angle_deg: f64,
}

/// Result of a mesh quality check.
#[derive(Debug, Clone, PartialEq)]
pub struct QualityReport {
    /// Threshold on q = 2 r_in / r_circ below which a triangle counts as a sliver.
    pub threshold: f64,
    /// Number of triangles checked.
    pub triangles: usize,
    /// Worst quality found (1 for an empty mesh).
    pub worst_quality: f64,
    /// Mean quality.
    pub mean_quality: f64,
    /// Slivers, worst first.
    pub slivers: Vec<Sliver>,
}

impl QualityReport {
    /// True when no triangle is below the threshold.
    pub fn is_ok(&self) -> bool {
        self.slivers.is_empty()
    }

    /// A message a user can act on: how many slivers, the worst few with their location.
    pub fn message(&self) -> String {
        if self.slivers.is_empty() {
            return format!(
                "mesh quality ok: {} triangles, worst quality {:.3} (threshold {:.3}, 1 = equilateral)",
                self.triangles, self.worst_quality, self.threshold
            );
        }
        let mut s = format!(
            "{} of {} triangles are slivers (quality 2·r_in/r_circ below {:.3}; 1 = equilateral); \
             they make the skin stiff and ill-conditioned, remesh these regions. Worst:",
            self.slivers.len(),
            self.triangles,
            self.threshold
        );
        for sl in self.slivers.iter().take(5) {
            let c = (sl.positions[0] + sl.positions[1] + sl.positions[2]) / 3.0;
            s.push_str(&format!(
                "\n  triangle {} (vertices {:?}) near ({:.4}, {:.4}, {:.4}) m: quality {:.2e}, smallest angle {:.2}°",
                sl.triangle, sl.vertices, c.x, c.y, c.z, sl.quality, sl.min_angle_deg
            ));
        }
        s
    }
}

/// Quality q = 2 r_in / r_circ of a triangle (1 equilateral, 0 degenerate) and its smallest
/// angle in degrees.
pub fn triangle_quality(p: [Vector3<f64>; 3]) -> (f64, f64) {
    let a = (p[1] - p[2]).norm();
    let b = (p[2] - p[0]).norm();
    let c = (p[0] - p[1]).norm();
    let area = 0.5 * (p[1] - p[0]).cross(&(p[2] - p[0])).norm();
    let s = 0.5 * (a + b + c);
    // r_in = A / s, r_circ = abc / (4A): q = 8 A² / (s a b c).
    let denom = s * a * b * c;
    let q = if denom > 0.0 && denom.is_finite() {
        (8.0 * area * area / denom).min(1.0)
    } else {
        0.0
    };
    let ang = |opp: f64, x: f64, y: f64| {
        if x * y <= 0.0 {
            0.0
        } else {
            ((x * x + y * y - opp * opp) / (2.0 * x * y))
                .clamp(-1.0, 1.0)
                .acos()
                .to_degrees()
        }
    };
    let min_angle = ang(a, b, c).min(ang(b, c, a)).min(ang(c, a, b));
    (if q.is_finite() { q } else { 0.0 }, min_angle)
}

/// Check every triangle of `mesh`; triangles with quality below `threshold` (a good default
/// is 0.1, roughly a smallest angle under 6°) are reported as slivers, worst first.
pub fn check(mesh: &TriMesh, threshold: f64) -> QualityReport {
    let mut slivers = Vec::new();
    let mut worst = 1.0f64;
    let mut sum = 0.0;
    for (t, &tri) in mesh.triangles.iter().enumerate() {
        let pos = tri.map(|v| {
            mesh.positions
                .get(v)
                .copied()
                .unwrap_or_else(Vector3::zeros)
        });
        let (q, min_angle_deg) = triangle_quality(pos);
        worst = worst.min(q);
        sum += q;
        if q < threshold {
            slivers.push(Sliver {
                triangle: t,
                vertices: tri,
                positions: pos,
                quality: q,
                min_angle_deg,
            });
        }
    }
    slivers.sort_by(|a, b| a.quality.total_cmp(&b.quality));
    let n = mesh.triangles.len();
    QualityReport {
        threshold,
        triangles: n,
        worst_quality: worst,
        mean_quality: if n > 0 { sum / n as f64 } else { 1.0 },
        slivers,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn equilateral_is_one_right_isoceles_known_and_sliver_found() {
        let eq = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.5, 3f64.sqrt() / 2.0, 0.0),
        ];
        let (q, a) = triangle_quality(eq);
        assert!((q - 1.0).abs() < 1e-12 && (a - 60.0).abs() < 1e-9);
        // Right isoceles legs 1: r_in = (2 − √2)/2, r_circ = √2/2, q = 2√2 − 2 ≈ 0.828.
        let ri = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
        ];
        assert!((triangle_quality(ri).0 - (2.0 * 2f64.sqrt() - 2.0)).abs() < 1e-12);
        let m = TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(0.5, 0.8, 0.0),
                Vector3::new(0.5, -0.001, 0.0),
            ],
            vec![[0, 1, 2], [0, 3, 1]],
        );
        let r = check(&m, 0.1);
        assert_eq!(r.slivers.len(), 1);
        assert_eq!(r.slivers[0].triangle, 1);
        assert!(r.slivers[0].min_angle_deg < 0.3);
        let msg = r.message();
        assert!(
            msg.contains("triangle 1") && msg.contains("1 of 2"),
            "{msg}"
        );
        assert!(check(&m, 0.01).is_ok() || r.slivers[0].quality < 0.01);
    }
}
