//! Lattice construction, as the steps of the design (DESIGN.md, "The coarse interior lattice"):
//!
//! 1. size the grid over the mesh's bounding box ([`grid::Bounds`], [`grid::Grid::fit`]);
//! 2. **hash**: the triangles overlapping each cell ([`surface::hash_triangles`]);
//! 3. **cut**: the surface is cut by the cell faces; the slits of an open mesh are extruded
//!    into cut walls that flesh may not cross ([`cuts::SlitCuts`]);
//! 4. **one element per connected piece in a cell** ([`surface::connected_pieces`],
//!    [`elements::make_elements`]);
//! 5. **close**: the cell faces close each piece with the volume behind it: cells without
//!    surface that lie in the flesh become volume elements ([`elements::flesh_cells`]) and
//!    are joined to the pieces they lie behind ([`graph::volume_links`]);
//! 6. **merge across faces**: pieces that touch across a cell face form the element graph
//!    ([`graph::shared_triangle_links`], [`graph::volume_links`],
//!    [`graph::keep_surface_parts`]); each element starts with its own nodes and the
//!    overlapping nodes of every graph edge are merged ([`nodes::merge_overlapping_nodes`],
//!    [`nodes::number_nodes`]); deep nodes are bone ([`nodes::bone_nodes`]);
//! 7. **embed**: each surface vertex gets its material point ([`embed::embed_vertices`]).
//!
//! This module runs the steps in order and checks the mesh before them.

mod cuts;
mod elements;
mod embed;
#[cfg(test)]
mod fingerprint;
mod graph;
mod grid;
mod nodes;
mod surface;
#[cfg(test)]
mod test_meshes;
mod union_find;

use super::inside::InsideTest;
use super::{Lattice, LatticeError, LatticeSettings};
use crate::mesh::TriMesh;
use cuts::SlitCuts;
use elements::{flesh_cells, make_elements, ElementTable};
use embed::embed_vertices;
use graph::{keep_surface_parts, shared_triangle_links, volume_links, Kept};
use grid::{Bounds, Grid};
use nodes::{bone_nodes, merge_overlapping_nodes, number_nodes};
use std::collections::HashMap;
use surface::{connected_pieces, hash_triangles, CellSurface};

/// A point or vector in space (m).
type V = nalgebra::Vector3<f64>;

/// Build the lattice over `mesh`: the steps of the module notes, in order.
pub(crate) fn build(mesh: &TriMesh, s: &LatticeSettings) -> Result<Lattice, LatticeError> {
    check_mesh(mesh)?;
    let bounds = Bounds::of(mesh)?;
    let (closed, boundary) = boundary_edges(mesh);
    let depth = s.depth.unwrap_or(0.1 * bounds.diag);
    let grid = Grid::fit(&bounds, if closed { 0.0 } else { depth }, s)?;

    // Hash, cut, and one element per connected piece in a cell.
    let tris = hash_triangles(mesh, &grid);
    let cuts = SlitCuts::extrude(mesh, &boundary, depth, &grid);
    let pieces = connected_pieces(mesh, &grid, &tris);
    let surf = CellSurface {
        mesh,
        grid,
        tris,
        pieces,
    };
    // Close the pieces with the flesh behind them.
    let inside = InsideTest::new(mesh, grid.lo, grid.h, grid.dims, &surf.tris, closed, depth);
    let flesh = flesh_cells(&surf, &inside);
    let ElementTable { elements, first } = make_elements(&surf, &flesh)?;

    // The element graph across cell faces, restricted to the parts that hold skin.
    let mut graph = shared_triangle_links(&surf, &first);
    graph.extend(volume_links(&surf, &cuts, &first, &flesh));
    graph.sort_unstable();
    graph.dedup();
    let Kept {
        mut elements,
        graph,
        renumber,
    } = keep_surface_parts(elements, graph);

    // Merge the overlapping nodes of every graph edge; bone nodes; embedding.
    let mut merged = merge_overlapping_nodes(s.order, &elements, &graph);
    let nodes = number_nodes(s.order, &grid, &mut elements, &mut merged);
    let pinned = bone_nodes(&nodes.rest, &inside);
    let vertex_points = embed_vertices(&surf, &first, &renumber)?;

    Ok(Lattice {
        order: s.order,
        origin: grid.lo,
        cell_size: grid.h,
        dims: grid.dims,
        elements,
        rest: nodes.rest,
        grid: nodes.grid,
        pinned,
        vertex_points,
        closed,
        depth,
        graph,
    })
}

/// Refuse meshes that cannot carry a lattice: no triangles, non-finite positions, triangle
/// indices out of range.
fn check_mesh(mesh: &TriMesh) -> Result<(), LatticeError> {
    if mesh.triangles.is_empty() {
        return Err(LatticeError::Mesh("the mesh has no triangles".into()));
    }
    if let Some(i) = mesh
        .positions
        .iter()
        .position(|p| !p.iter().all(|c| c.is_finite()))
    {
        return Err(LatticeError::Mesh(format!(
            "vertex {i} has a non-finite position"
        )));
    }
    let n = mesh.positions.len();
    if let Some(t) = mesh
        .triangles
        .iter()
        .position(|t| t.iter().any(|&v| v >= n))
    {
        return Err(LatticeError::Mesh(format!(
            "triangle {t} indexes a vertex ≥ {n}"
        )));
    }
    Ok(())
}

/// Edges used by exactly one triangle (the boundary of an open mesh), as (a, b) vertex
/// pairs; the mesh is closed when there are none and every edge has two triangles.
fn boundary_edges(mesh: &TriMesh) -> (bool, Vec<(usize, usize)>) {
    let mut count: HashMap<(usize, usize), u32> = HashMap::new();
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            *count.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    let closed = !count.is_empty() && count.values().all(|&c| c == 2);
    let mut edges: Vec<(usize, usize)> = count
        .iter()
        .filter(|(_, &c)| c == 1)
        .map(|(&e, _)| e)
        .collect();
    edges.sort_unstable();
    (closed, edges)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::fingerprint;
    use crate::lattice::build::test_meshes::*;

    #[test]
    fn check_mesh_refuses_empty_non_finite_and_out_of_range() {
        assert!(check_mesh(&triangle()).is_ok());
        assert!(check_mesh(&TriMesh::new(vec![v(0., 0., 0.)], vec![])).is_err());
        let mut m = triangle();
        m.positions[1].y = f64::NAN;
        assert!(matches!(check_mesh(&m), Err(LatticeError::Mesh(s)) if s.contains("vertex 1")));
        let mut m = triangle();
        m.triangles[0][2] = 3;
        assert!(matches!(check_mesh(&m), Err(LatticeError::Mesh(s)) if s.contains("≥ 3")));
    }

    #[test]
    fn boundary_edges_of_a_triangle_and_a_tetrahedron() {
        assert_eq!(
            boundary_edges(&triangle()),
            (false, vec![(0, 1), (0, 2), (1, 2)])
        );
        assert_eq!(boundary_edges(&tetra()), (true, vec![]));
    }

    /// The whole build on small inputs, exact counts: a slit sheet (open, superimposed lip
    /// elements, 13 grid positions with a node of each lip) and two boxes 1 cm apart in
    /// 5 × 2 × 2 cells of 0.1 m: 20 cells + 4 superimposed = 24 elements, two bodies of
    /// (3+2)(2+2)(2+2) = 80 nodes whose grids overlap in 3 × 4 × 4 = 48 positions, and
    /// 20 face adjacencies per body.
    #[test]
    fn build_counts_on_small_meshes() {
        let sheet = fingerprint::slit_sheet(0.05, 0.005, 0.025);
        let s = LatticeSettings {
            depth: Some(0.02),
            ..cell(0.0125)
        };
        let two = {
            let mut m = box_mesh(V::zeros(), v(0.25, 0.2, 0.2), 5);
            let b = box_mesh(v(0.26, 0.0, 0.0), v(0.5, 0.2, 0.2), 5);
            let n = m.positions.len();
            m.positions.extend(&b.positions);
            m.triangles
                .extend(b.triangles.iter().map(|t| t.map(|i| i + n)));
            m
        };
        // (elements, nodes, graph edges, grid positions holding duplicated nodes, pinned)
        for (mesh, s, expect) in [
            (&sheet, s, (148, 476, 320, 13, 108)),
            (&two, cell(0.1), (24, 160, 40, 48, 0)),
        ] {
            let l = build(mesh, &s).unwrap();
            let mut at: HashMap<[usize; 3], usize> = HashMap::new();
            l.grid.iter().for_each(|g| *at.entry(*g).or_default() += 1);
            let dup = at.values().filter(|&&c| c > 1).count();
            let got = (
                l.elements.len(),
                l.node_count(),
                l.graph.len(),
                dup,
                l.pinned_count(),
            );
            assert_eq!(got, expect);
        }
    }
}
