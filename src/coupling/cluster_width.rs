//! The cluster width σ that places the skin's wrinkles at a wavelength: the first zero of
//! the truncated Gaussian cluster kernel's transfer function (the longest wave the
//! constraints H x = H B q cannot see), corrected for distances measured along mesh edges.

use crate::mesh::TriMesh;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};

/// J₀(x), the Bessel function of the first kind of order 0, by the midpoint rule on
/// J₀(x) = (1/π) ∫₀^π cos(x sin θ) dθ (spectrally accurate for a periodic integrand; 1e-12
/// for |x| < 20 with 64 points).
fn bessel_j0(x: f64) -> f64 {
    const N: usize = 64;
    (0..N)
        .map(|i| (x * (std::f64::consts::PI * (i as f64 + 0.5) / N as f64).sin()).cos())
        .sum::<f64>()
        / N as f64
}

/// Transfer function (unnormalised) at wavenumber k (1/σ) of the 2D cluster kernel
/// exp(−r²/2σ²) truncated at r = 2σ, with σ = 1: 2π ∫₀² e^{−r²/2} J₀(k r) r dr (midpoint rule).
fn kernel_transfer(k: f64) -> f64 {
    const N: usize = 400;
    let h = 2.0 / N as f64;
    (0..N)
        .map(|i| {
            let r = (i as f64 + 0.5) * h;
            (-0.5 * r * r).exp() * bessel_j0(k * r) * r * h
        })
        .sum::<f64>()
        * 2.0
        * std::f64::consts::PI
}

/// The wavelength (in units of σ) of the first zero of the cluster kernel's transfer
/// function: a plane wave of this length has zero weighted average over every cluster,
/// wherever its centre lies, so the constraints H x = H B q cannot see it at all. For the
/// Gaussian truncated at 2σ (Euclidean distances) it is 2.279 σ (the untruncated Gaussian has
/// no zero; the truncation makes one, shorter than the design cut-off πσ, where the kernel
/// still transmits 0.19 instead of the untruncated e⁻² = 0.135).
pub fn kernel_zero_wavelength() -> f64 {
    // Bracket the first sign change in k σ, then bisect.
    let (mut a, mut b) = (1.0, 1.0);
    let mut fa = kernel_transfer(a);
    while b < 10.0 {
        b = a + 0.05;
        let fb = kernel_transfer(b);
        if fa * fb <= 0.0 {
            break;
        }
        a = b;
        fa = fb;
    }
    for _ in 0..50 {
        let m = 0.5 * (a + b);
        let fm = kernel_transfer(m);
        if fa * fm <= 0.0 {
            b = m;
        } else {
            a = m;
            fa = fm;
        }
    }
    2.0 * std::f64::consts::PI / (0.5 * (a + b))
}

#[derive(PartialEq)]
struct HeapItem(f64, usize);
impl Eq for HeapItem {}
impl PartialOrd for HeapItem {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for HeapItem {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Mean ratio of edge-path (shortest path along mesh edges) to straight-line distance, over
/// vertex pairs between `radius`/2 and `radius` (m) apart along edges, from up to 16 source
/// vertices spread over the mesh. 1 on a straight line; about 1.05–1.10 on an equilateral
/// triangulation (edge paths zig-zag except along the three edge directions). Curvature
/// of the surface lowers it (chords are shorter than geodesics), which is not corrected.
pub fn edge_path_stretch(mesh: &TriMesh, radius: f64) -> f64 {
    let n = mesh.positions.len();
    if n == 0 || !(radius.is_finite() && radius > 0.0) {
        return 1.0;
    }
    let mut adj: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let l = (mesh.positions[a] - mesh.positions[b]).norm();
            adj[a].push((b, l));
            adj[b].push((a, l));
        }
    }
    let (mut sum, mut count) = (0.0, 0usize);
    let sources = 16.min(n);
    for s in 0..sources {
        let src = s * n / sources;
        let mut dist: HashMap<usize, f64> = HashMap::new();
        let mut heap = BinaryHeap::new();
        dist.insert(src, 0.0);
        heap.push(HeapItem(0.0, src));
        while let Some(HeapItem(d, v)) = heap.pop() {
            if d > dist[&v] {
                continue;
            }
            if d >= 0.5 * radius {
                let e = (mesh.positions[v] - mesh.positions[src]).norm();
                if e > 0.0 {
                    sum += d / e;
                    count += 1;
                }
            }
            for &(w, l) in &adj[v] {
                let nd = d + l;
                if nd < radius && nd < *dist.get(&w).unwrap_or(&f64::INFINITY) {
                    dist.insert(w, nd);
                    heap.push(HeapItem(nd, w));
                }
            }
        }
    }
    if count == 0 {
        1.0
    } else {
        sum / count as f64
    }
}

/// The cluster width σ (m) that puts the skin's wrinkles at wavelength `lambda` (m) on
/// `mesh`: σ = s λ / z, z = [`kernel_zero_wavelength`] (2.279) and s the mesh's
/// [`edge_path_stretch`] at the kernel radius 2σ.
///
/// Why not DESIGN.md's σ = λ/π: the shell wrinkles at the longest wave the constraints do
/// not see, and with the truncated kernel that is the first zero of its transfer function,
/// z σ / s, not the Gaussian's nominal cut-off π σ: on the compressed slab the wrinkles come
/// out at about z/s = 2.11 σ whatever σ is, so σ = λ/π makes them a third too short.
pub fn sigma_for_wavelength(mesh: &TriMesh, lambda: f64) -> f64 {
    let z = kernel_zero_wavelength();
    // σ ≈ λ/2, so the kernel radius 2σ ≈ λ.
    let s = edge_path_stretch(mesh, lambda);
    s * lambda / z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// J₀ at known values; the kernel zero is a zero (sign change) and the truncated kernel
    /// transmits ≈ 0.19 at πσ (values of an independent quadrature).
    #[test]
    fn kernel_zero_and_transmission() {
        assert!((bessel_j0(0.0) - 1.0).abs() < 1e-14);
        assert!((bessel_j0(2.404_825_557_695_773)).abs() < 1e-12);
        assert!((bessel_j0(1.0) - 0.765_197_686_557_966_6).abs() < 1e-12);
        let z = kernel_zero_wavelength();
        assert!((z - 2.279).abs() < 2e-3, "{z}");
        let k0 = 2.0 * std::f64::consts::PI / z;
        let t0 = kernel_transfer(0.0);
        assert!(kernel_transfer(0.99 * k0) > 0.0 && kernel_transfer(1.01 * k0) < 0.0);
        let t_pi = kernel_transfer(2.0) / t0;
        assert!((t_pi - 0.1895).abs() < 2e-3, "{t_pi}");
        // Normalisation: 2π ∫₀² e^{−r²/2} r dr = 2π (1 − e⁻²).
        assert!((t0 - 2.0 * std::f64::consts::PI * (1.0 - (-2.0f64).exp())).abs() < 1e-5);
    }

    /// The edge-path stretch lies between 1 and 2/√3 (the worst direction, 30° off the
    /// edges) on an equilateral sheet, and is lower on a one-triangle strip, whose paths run
    /// along the edge direction (only the step between its two rows zig-zags).
    #[test]
    fn edge_path_stretch_of_sheets() {
        let sheet = crate::shell::sheet::equilateral_sheet(60, 60, 1e-3);
        let s = edge_path_stretch(&sheet.mesh, 10e-3);
        assert!(s > 1.0 && s < 2.0 / 3f64.sqrt(), "{s}");
        let strip = crate::shell::sheet::equilateral_sheet(60, 1, 1e-3);
        let s1 = edge_path_stretch(&strip.mesh, 10e-3);
        println!("stretch: sheet {s:.4}, strip {s1:.4}");
        assert!(s1 < 1.05 && s1 < s, "{s1} vs {s}");
    }
}
