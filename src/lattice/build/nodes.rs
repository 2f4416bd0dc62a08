//! Step "merge across faces" of the build, its nodes: every element starts with its own
//! nodes, the overlapping nodes of each graph edge are merged and numbered, and nodes deep
//! behind an open surface are bone.

use super::grid::Grid;
use super::union_find::UnionFind;
use super::V;
use crate::lattice::basis::local_offset;
use crate::lattice::inside::InsideTest;
use crate::lattice::{Element, ElementOrder};
use rayon::prelude::*;
use std::collections::HashMap;

/// Step "merge": every element starts with its own k³ nodes (slot `e·k³ + a` for local node
/// a of element e); for each graph edge the nodes at the same grid position (two layers, 18
/// pairs, for quadratic elements; one layer, 4 pairs, for trilinear) are joined.
pub(super) fn merge_overlapping_nodes(
    order: ElementOrder,
    elements: &[Element],
    graph: &[(usize, usize)],
) -> UnionFind {
    let k = order.per_axis();
    let npe = order.nodes_per_element();
    let mut uf = UnionFind::new(elements.len() * npe);
    for &(e1, e2) in graph {
        let (c1, c2) = (elements[e1].cell, elements[e2].cell);
        for a in 0..npe {
            let off = local_offset(order, a);
            let g: [usize; 3] = [0, 1, 2].map(|d| c1[d] + off[d]);
            if (0..3).all(|d| g[d] >= c2[d] && g[d] < c2[d] + k) {
                let b = (g[0] - c2[0]) + k * (g[1] - c2[1]) + k * k * (g[2] - c2[2]);
                uf.union(e1 * npe + a, e2 * npe + b);
            }
        }
    }
    uf
}

/// The lattice nodes: rest positions and grid coordinates.
pub(super) struct Nodes {
    /// Rest position of each node (m).
    pub(super) rest: Vec<V>,
    /// Grid coordinates of each node.
    pub(super) grid: Vec<[usize; 3]>,
}

/// Number the merged node slots in order of first use and fill each element's node list;
/// node (i, j, k) rests at `lo + h·((i, j, k) + offset)` (offset −½ quadratic, 0 trilinear).
pub(super) fn number_nodes(
    order: ElementOrder,
    grid: &Grid,
    elements: &mut [Element],
    merged: &mut UnionFind,
) -> Nodes {
    let npe = order.nodes_per_element();
    let off0 = order.node_offset();
    let mut node_of_root: HashMap<usize, usize> = HashMap::new();
    let mut rest = Vec::new();
    let mut grid_nodes = Vec::new();
    for (e, el) in elements.iter_mut().enumerate() {
        el.nodes = (0..npe)
            .map(|a| {
                let r = merged.find(e * npe + a);
                *node_of_root.entry(r).or_insert_with(|| {
                    let off = local_offset(order, a);
                    let g = [0, 1, 2].map(|d| el.cell[d] + off[d]);
                    rest.push(grid.node_position(g, off0));
                    grid_nodes.push(g);
                    rest.len() - 1
                })
            })
            .collect();
    }
    Nodes {
        rest,
        grid: grid_nodes,
    }
}

/// Bone nodes (pinned): behind an open surface deeper than the flesh depth. None for closed
/// meshes.
pub(super) fn bone_nodes(rest: &[V], inside: &InsideTest) -> Vec<bool> {
    rest.par_iter().map(|p| inside.is_bone(p)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::test_meshes::*;
    use crate::lattice::inside::InsideTest;
    use crate::lattice::ElementKind;
    use crate::mesh::TriMesh;
    use std::collections::HashSet;

    /// Step "merge": two face neighbours share 18 quadratic (4 trilinear) nodes; without a
    /// graph edge they share none; node positions sit at cell centres (quadratic) or corners.
    #[test]
    fn merging_shares_two_layers_quadratic_one_trilinear() {
        let g = Grid {
            lo: v(1., 2., 3.),
            h: 0.5,
            dims: [2, 1, 1],
            eps: 5e-10,
        };
        let el = |x| Element {
            cell: [x, 0, 0],
            nodes: vec![],
            kind: ElementKind::Surface,
        };
        let q = ElementOrder::Quadratic;
        for (order, edges, nodes, shared) in [
            (q, vec![(0, 1)], 36, 18),
            (ElementOrder::Trilinear, vec![(0, 1)], 12, 4),
            (q, vec![], 54, 0),
        ] {
            let mut els = vec![el(0), el(1)];
            let mut uf = merge_overlapping_nodes(order, &els, &edges);
            let n = number_nodes(order, &g, &mut els, &mut uf);
            assert_eq!((n.rest.len(), n.grid.len()), (nodes, nodes), "{order:?}");
            let a: HashSet<_> = els[0].nodes.iter().collect();
            let b: HashSet<_> = els[1].nodes.iter().collect();
            assert_eq!(a.intersection(&b).count(), shared, "{order:?}");
        }
        let mut els = vec![el(0), el(1)];
        let mut uf = merge_overlapping_nodes(q, &els, &[(0, 1)]);
        let n = number_nodes(q, &g, &mut els, &mut uf);
        assert_eq!(els[0].nodes[..3], [0, 1, 2]);
        assert_eq!(els[1].nodes[..3], [1, 2, 27]);
        assert_eq!(n.rest[0], v(0.75, 1.75, 2.75));
        assert_eq!((n.grid[27], n.rest[27]), ([3, 0, 0], v(2.25, 1.75, 2.75)));
    }

    /// Bone: behind an open 2 m square sheet (facing +z) deeper than the 0.1 m flesh depth.
    #[test]
    fn bone_is_behind_the_sheet_deeper_than_the_depth() {
        let sheet = TriMesh::new(
            vec![
                v(-1., -1., 0.),
                v(1., -1., 0.),
                v(1., 1., 0.),
                v(-1., 1., 0.),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        );
        let s = surface(&sheet, 0.25, 1.0);
        let inside = InsideTest::new(
            &sheet,
            s.grid.lo,
            s.grid.h,
            s.grid.dims,
            &s.tris,
            false,
            0.1,
        );
        let pts = [
            v(0., 0., -0.5),
            v(0.1, 0.2, -0.05),
            v(0., 0., 0.5),
            v(0.3, 0., -0.2),
        ];
        assert_eq!(bone_nodes(&pts, &inside), vec![true, false, false, true]);
    }
}
