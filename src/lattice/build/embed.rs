//! Step "embed" of the build: the material point (element and local coordinates) of each
//! surface vertex.

use super::surface::CellSurface;
use crate::lattice::{LatticeError, MaterialPoint};
use crate::mesh::TriMesh;

/// The first triangle of each vertex (`usize::MAX` for a vertex on no triangle).
pub(super) fn first_triangle_of_vertex(mesh: &TriMesh) -> Vec<usize> {
    let mut vert_tri: Vec<usize> = vec![usize::MAX; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &v in tri {
            if vert_tri[v] == usize::MAX {
                vert_tri[v] = t;
            }
        }
    }
    vert_tri
}

/// Step "embed": the material point of each surface vertex, in the element of the piece that
/// holds its first triangle in its cell, with ξ its position in the cell over the cell size
/// (clamped to [0, 1]). `first` and `renumber` come from
/// [`super::elements::make_elements`] and [`super::graph::keep_surface_parts`].
pub(super) fn embed_vertices(
    surf: &CellSurface,
    first: &[usize],
    renumber: &[usize],
) -> Result<Vec<MaterialPoint>, LatticeError> {
    let g = &surf.grid;
    let pos = &surf.mesh.positions;
    let vert_tri = first_triangle_of_vertex(surf.mesh);
    let mut vertex_points = Vec::with_capacity(pos.len());
    for (v, p) in pos.iter().enumerate() {
        let t = vert_tri[v];
        let c = g.clamp_cell(p);
        let ci = g.index(c);
        let e = if t == usize::MAX {
            // A vertex on no triangle: any element of its cell (the first) carries it.
            let f = first[ci];
            if f == usize::MAX || renumber[f] == usize::MAX {
                return Err(LatticeError::Mesh(format!(
                    "vertex {v} belongs to no triangle and lies in no lattice element; remove unreferenced vertices"
                )));
            }
            renumber[f]
        } else {
            let Some(l) = surf.tris[ci].iter().position(|&u| u == t) else {
                return Err(LatticeError::Mesh(format!(
                    "vertex {v} at {p:?} could not be placed in a lattice cell (degenerate triangle {t}?)"
                )));
            };
            renumber[first[ci] + surf.pieces[ci].of[l]]
        };
        let r = (p - g.corner(c)) / g.h;
        vertex_points.push(MaterialPoint {
            element: e,
            xi: [0, 1, 2].map(|d| r[d].clamp(0.0, 1.0)),
        });
    }
    Ok(vertex_points)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::elements::make_elements;
    use crate::lattice::build::test_meshes::*;

    /// Step "embed": each vertex of the triangle lies in the element of its cell, ξ = its
    /// position in the cell over 0.1 m; a vertex on no triangle outside every element is an
    /// error.
    #[test]
    fn vertices_embed_in_their_cells_element() {
        let m = triangle();
        let s = surface(&m, 0.1, 0.0);
        let vp = embed_vertices(&s, &[0, 1], &[0, 1]).unwrap();
        let expect = [
            (0, [0.0, 0.0, 0.0]),
            (1, [0.6, 0.0, 0.0]),
            (0, [0.0, 1.0, 0.0]),
        ];
        for (mp, (e, xi)) in vp.iter().zip(expect) {
            assert_eq!(mp.element, e);
            assert!((0..3).all(|d| (mp.xi[d] - xi[d]).abs() < 1e-12), "{mp:?}");
        }
        assert_eq!(first_triangle_of_vertex(&m), vec![0, 0, 0]);
        // A vertex on no triangle, in cell (2, 1, 0) where the triangle does not reach: an
        // error unless that cell holds a (volume) element.
        let mut lone = m.clone();
        lone.positions.push(v(0.25, 0.15, 0.1));
        let s = surface(&lone, 0.1, 0.0);
        assert_eq!(s.grid.dims, [3, 2, 1]);
        let mut flesh = vec![false; 6];
        let t = make_elements(&s, &flesh).unwrap();
        assert_eq!(t.elements.len(), 3);
        let renumber: Vec<usize> = (0..4).collect();
        assert!(embed_vertices(&s, &t.first, &renumber).is_err());
        flesh[s.grid.index([2, 1, 0])] = true;
        let t = make_elements(&s, &flesh).unwrap();
        let vp = embed_vertices(&s, &t.first, &renumber).unwrap();
        assert_eq!(vp[3].element, 3);
        assert!((0..3).all(|d| (vp[3].xi[d] - [0.3, 0.3, 0.5][d]).abs() < 1e-12));
    }
}
