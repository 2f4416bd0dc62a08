//! The structured mesh of 9-node quadratic quadrilaterals (Q2) on a rectangle that the dense
//! strip is made of.

/// A structured mesh of 9-node quadratic quadrilaterals on a rectangle.
///
/// Nodes form a grid of `columns` × `rows` (row-major from the bottom-left, node index =
/// row × columns + column); element `e` lists its nodes as `[i + 3 j]` with i along x and j
/// along y, i, j ∈ {0, 1, 2}.
#[derive(Debug, Clone)]
pub struct QuadMesh {
    /// Reference node positions (x along the strip, y up), m.
    pub nodes: Vec<[f64; 2]>,
    /// Nodes of each element (9 per element).
    pub elements: Vec<[usize; 9]>,
    /// Element layer index from the bottom (0-based) of each element.
    pub element_row: Vec<usize>,
    /// Number of node columns (2 × elements along x + 1).
    pub columns: usize,
    /// Number of node rows (2 × element layers + 1).
    pub rows: usize,
}

impl QuadMesh {
    /// A grid of `nx` elements of equal width over [0, `length`] (m) and element layers with
    /// boundaries `ys` (m, increasing, `ys.len()` − 1 layers). Mid-side nodes sit halfway.
    pub fn rectangle(length: f64, nx: usize, ys: &[f64]) -> Self {
        let ny = ys.len() - 1;
        let columns = 2 * nx + 1;
        let rows = 2 * ny + 1;
        let mut nodes = Vec::with_capacity(columns * rows);
        for r in 0..rows {
            let y = if r % 2 == 0 {
                ys[r / 2]
            } else {
                0.5 * (ys[r / 2] + ys[r / 2 + 1])
            };
            for c in 0..columns {
                nodes.push([length * c as f64 / (columns - 1) as f64, y]);
            }
        }
        let mut elements = Vec::with_capacity(nx * ny);
        let mut element_row = Vec::with_capacity(nx * ny);
        for ey in 0..ny {
            for ex in 0..nx {
                let mut e = [0usize; 9];
                for j in 0..3 {
                    for i in 0..3 {
                        e[i + 3 * j] = (2 * ey + j) * columns + 2 * ex + i;
                    }
                }
                elements.push(e);
                element_row.push(ey);
            }
        }
        Self {
            nodes,
            elements,
            element_row,
            columns,
            rows,
        }
    }

    /// Node index of grid column `c` and row `r`.
    pub fn node(&self, c: usize, r: usize) -> usize {
        r * self.columns + c
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::validate::dense::PlaneStrainSvk;

    /// The structured mesh: node and element counts, corner positions, element orientation.
    #[test]
    fn rectangle_mesh_layout() {
        let m = QuadMesh::rectangle(3.0, 3, &[0.0, 1.0, 1.5]);
        assert_eq!((m.columns, m.rows), (7, 5));
        assert_eq!(m.nodes.len(), 35);
        assert_eq!(m.elements.len(), 6);
        assert_eq!(m.nodes[m.node(6, 4)], [3.0, 1.5]);
        assert_eq!(m.nodes[m.node(3, 3)], [1.5, 1.25]);
        // Element 4 (second layer, middle column): node 0 bottom-left, node 8 top-right.
        let e = m.elements[4];
        assert_eq!(m.nodes[e[0]], [1.0, 1.0]);
        assert_eq!(m.nodes[e[8]], [2.0, 1.5]);
        assert_eq!(m.element_row[4], 1);
        // Total area from the quadrature weights equals the rectangle's (4.5 m²).
        let svk = PlaneStrainSvk::new(&m, &[(1.0, 0.3); 6]).unwrap();
        let area: f64 = svk.quad.iter().flatten().map(|q| q.1).sum();
        assert!((area - 4.5).abs() < 1e-12, "{area}");
    }
}
