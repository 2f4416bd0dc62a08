//! Element shape functions on the unit cell: tensor-product quadratic uniform B-splines
//! (27 control points, C¹ across cell faces) and trilinear Lagrange functions (8 corner nodes,
//! C⁰ across faces).
//!
//! Local coordinates ξ ∈ [0, 1]³ are the position inside a cell divided by the cell size.
//! The local node (a, b, c) of an element in cell (i, j, k) is the lattice grid node
//! (i + a, j + b, k + c); its flat local index is `a + k·b + k²·c` with k = 3 (quadratic) or
//! 2 (trilinear).

use serde::{Deserialize, Serialize};

/// The interpolation order of lattice elements.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum ElementOrder {
    /// 27-node tensor-product quadratic uniform B-spline hexahedron (C¹ across faces; the
    /// control points lie at cell centres and do not interpolate).
    #[default]
    Quadratic,
    /// 8-node trilinear hexahedron (nodes at cell corners, C⁰ across faces).
    Trilinear,
}

impl ElementOrder {
    /// Nodes per axis of one element (3 or 2).
    pub fn per_axis(self) -> usize {
        match self {
            ElementOrder::Quadratic => 3,
            ElementOrder::Trilinear => 2,
        }
    }

    /// Nodes per element (27 or 8).
    pub fn nodes_per_element(self) -> usize {
        self.per_axis().pow(3)
    }

    /// Offset (in cell sizes) of grid node 0 from the lattice origin along each axis: control
    /// points of quadratic B-splines sit at cell centres (−½), trilinear nodes at corners (0).
    pub fn node_offset(self) -> f64 {
        match self {
            ElementOrder::Quadratic => -0.5,
            ElementOrder::Trilinear => 0.0,
        }
    }
}

/// Values and local-coordinate gradients of an element's shape functions at one point.
/// Only the first `n` entries are meaningful.
#[derive(Debug, Clone, Copy)]
pub struct Shape {
    /// Number of shape functions (27 or 8).
    pub n: usize,
    /// N_a(ξ), dimensionless.
    pub val: [f64; 27],
    /// ∂N_a/∂ξ (per unit local coordinate; divide by the cell size for ∂/∂x in 1/m).
    pub grad: [[f64; 3]; 27],
}

/// 1D basis values and derivatives at t ∈ [0, 1] (first `k` entries).
fn basis_1d(order: ElementOrder, t: f64) -> ([f64; 3], [f64; 3]) {
    match order {
        ElementOrder::Quadratic => (
            [0.5 * (1.0 - t) * (1.0 - t), 0.5 + t - t * t, 0.5 * t * t],
            [t - 1.0, 1.0 - 2.0 * t, t],
        ),
        ElementOrder::Trilinear => ([1.0 - t, t, 0.0], [-1.0, 1.0, 0.0]),
    }
}

/// Shape functions of `order` at local coordinates `xi` (each component in [0, 1]; values
/// outside extrapolate the polynomial piece of this cell).
pub fn shape(order: ElementOrder, xi: [f64; 3]) -> Shape {
    let k = order.per_axis();
    let (vx, dx) = basis_1d(order, xi[0]);
    let (vy, dy) = basis_1d(order, xi[1]);
    let (vz, dz) = basis_1d(order, xi[2]);
    let mut s = Shape {
        n: k * k * k,
        val: [0.0; 27],
        grad: [[0.0; 3]; 27],
    };
    for c in 0..k {
        for b in 0..k {
            for a in 0..k {
                let i = a + k * b + k * k * c;
                s.val[i] = vx[a] * vy[b] * vz[c];
                s.grad[i] = [
                    dx[a] * vy[b] * vz[c],
                    vx[a] * dy[b] * vz[c],
                    vx[a] * vy[b] * dz[c],
                ];
            }
        }
    }
    s
}

/// The (a, b, c) grid offset of local node `i` of an element of `order`.
pub fn local_offset(order: ElementOrder, i: usize) -> [usize; 3] {
    let k = order.per_axis();
    [i % k, (i / k) % k, i / (k * k)]
}

/// 3-point Gauss–Legendre rule on [0, 1]: (points, weights summing to 1). Exact for
/// polynomials of degree ≤ 5 per axis, so the 27-point tensor rule integrates products of
/// quadratic B-spline gradients and values exactly on an undeformed cell.
pub fn gauss3() -> ([f64; 3], [f64; 3]) {
    let r = (0.6f64).sqrt() / 2.0;
    (
        [0.5 - r, 0.5, 0.5 + r],
        [5.0 / 18.0, 8.0 / 18.0, 5.0 / 18.0],
    )
}

/// The 27-point tensor Gauss rule on the unit cube: (ξ, weight), weights sum to 1.
pub fn gauss27() -> Vec<([f64; 3], f64)> {
    let (p, w) = gauss3();
    let mut out = Vec::with_capacity(27);
    for k in 0..3 {
        for j in 0..3 {
            for i in 0..3 {
                out.push(([p[i], p[j], p[k]], w[i] * w[j] * w[k]));
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pts() -> Vec<[f64; 3]> {
        let mut v = Vec::new();
        for i in 0..5 {
            for j in 0..5 {
                for k in 0..5 {
                    v.push([
                        i as f64 / 4.0,
                        0.13 + j as f64 * 0.19,
                        (k as f64 / 4.0).powi(2),
                    ]);
                }
            }
        }
        v
    }

    /// Σ N_a = 1 and Σ ∇N_a = 0 everywhere in the cell, for both orders.
    #[test]
    fn partition_of_unity_and_gradients_sum_to_zero() {
        for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
            for xi in pts() {
                let s = shape(order, xi);
                let sum: f64 = s.val[..s.n].iter().sum();
                assert!((sum - 1.0).abs() < 1e-14, "{order:?} sum {sum}");
                for d in 0..3 {
                    let g: f64 = s.grad[..s.n].iter().map(|g| g[d]).sum();
                    assert!(g.abs() < 1e-14, "{order:?} grad sum {g}");
                }
                assert!(
                    s.val[..s.n].iter().all(|&v| v >= -1e-15),
                    "B-splines are non-negative"
                );
            }
        }
    }

    /// Control points at the grid node positions reproduce the identity map (linear
    /// precision): Σ N_a(ξ) (offset_a + node_offset) = ξ, and the gradient of that map is I.
    #[test]
    fn linear_precision() {
        for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
            for xi in pts() {
                let s = shape(order, xi);
                for d in 0..3 {
                    let mut x = 0.0;
                    let mut dx = [0.0; 3];
                    for a in 0..s.n {
                        let p = local_offset(order, a)[d] as f64 + order.node_offset();
                        x += s.val[a] * p;
                        for e in 0..3 {
                            dx[e] += s.grad[a][e] * p;
                        }
                    }
                    assert!((x - xi[d]).abs() < 1e-14);
                    for (e, v) in dx.iter().enumerate() {
                        let want = if e == d { 1.0 } else { 0.0 };
                        assert!((v - want).abs() < 1e-14);
                    }
                }
            }
        }
    }

    /// The analytic ∂N/∂ξ agree with central differences of N.
    #[test]
    fn gradients_match_finite_differences() {
        let eps = 1e-6;
        for order in [ElementOrder::Quadratic, ElementOrder::Trilinear] {
            for xi in pts() {
                let s = shape(order, xi);
                for d in 0..3 {
                    let mut p = xi;
                    let mut m = xi;
                    p[d] += eps;
                    m[d] -= eps;
                    let (sp, sm) = (shape(order, p), shape(order, m));
                    for a in 0..s.n {
                        let fd = (sp.val[a] - sm.val[a]) / (2.0 * eps);
                        assert!((fd - s.grad[a][d]).abs() < 1e-8);
                    }
                }
            }
        }
    }

    #[test]
    fn gauss_rule_integrates_quintics_exactly() {
        let q = gauss27();
        let w: f64 = q.iter().map(|p| p.1).sum();
        assert!((w - 1.0).abs() < 1e-15);
        // ∫₀¹ x⁵ y⁴ z dx dy dz = 1/6 · 1/5 · 1/2.
        let i: f64 = q
            .iter()
            .map(|(p, w)| w * p[0].powi(5) * p[1].powi(4) * p[2])
            .sum();
        assert!((i - 1.0 / 60.0).abs() < 1e-15);
    }
}
