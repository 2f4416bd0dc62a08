//! Steps "close" (which empty cells lie in the flesh) and "one element per connected piece
//! in a cell" of the build: the elements before their nodes are assigned.

use super::surface::CellSurface;
use crate::lattice::inside::InsideTest;
use crate::lattice::{Element, ElementKind, LatticeError};
use rayon::prelude::*;

/// Step "close", part 1: which cells without surface lie in the flesh (inside a closed mesh,
/// or behind an open one within the flesh depth), judged at the cell centre.
pub(super) fn flesh_cells(surf: &CellSurface, inside: &InsideTest) -> Vec<bool> {
    let g = &surf.grid;
    (0..g.cell_count())
        .into_par_iter()
        .map(|ci| surf.tris[ci].is_empty() && inside.is_flesh(&g.center(g.coord(ci))))
        .collect()
}

/// The elements before node merging, grouped by cell.
pub(super) struct ElementTable {
    /// Elements in cell order, the pieces of a cell in piece order; nodes not yet assigned.
    pub(super) elements: Vec<Element>,
    /// Index of the first element of each cell (`usize::MAX` for cells without elements); the
    /// element of piece p of cell c is `first[c] + p`.
    pub(super) first: Vec<usize>,
}

/// Step "one element per connected piece in a cell": one surface element per piece, one
/// volume element per flesh cell without surface. An error when there would be none.
pub(super) fn make_elements(
    surf: &CellSurface,
    flesh: &[bool],
) -> Result<ElementTable, LatticeError> {
    let g = &surf.grid;
    let mut elements: Vec<Element> = Vec::new();
    let mut first = vec![usize::MAX; g.cell_count()];
    for ci in 0..g.cell_count() {
        let cell = g.coord(ci);
        let (count, kind) = if surf.tris[ci].is_empty() {
            (usize::from(flesh[ci]), ElementKind::Volume)
        } else {
            (surf.pieces[ci].count, ElementKind::Surface)
        };
        if count > 0 {
            first[ci] = elements.len();
        }
        for _ in 0..count {
            elements.push(Element {
                cell,
                nodes: Vec::new(),
                kind,
            });
        }
    }
    if elements.is_empty() {
        return Err(LatticeError::Mesh(
            "no lattice element could be made".into(),
        ));
    }
    Ok(ElementTable { elements, first })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::surface::CellPieces;
    use crate::lattice::build::test_meshes::*;
    use crate::lattice::build::V;
    use crate::lattice::inside::InsideTest;

    /// Steps "close" (flesh cells) and "one element per piece": a closed 0.4 m box in 0.1 m
    /// cells has 56 surface cells with one piece each and 8 inner flesh cells.
    #[test]
    fn closed_box_elements_one_per_piece_plus_inner_volume() {
        let b = box_mesh(V::zeros(), V::repeat(0.4), 4);
        let s = surface(&b, 0.1, 0.0);
        let inside = InsideTest::new(&b, s.grid.lo, 0.1, s.grid.dims, &s.tris, true, 0.0);
        let flesh = flesh_cells(&s, &inside);
        let inner: Vec<usize> = (0..64).filter(|&i| flesh[i]).collect();
        assert_eq!(inner, vec![21, 22, 25, 26, 37, 38, 41, 42]);
        let t = make_elements(&s, &flesh).unwrap();
        assert_eq!(t.elements.len(), 64);
        assert_eq!(t.first[..4], [0, 1, 2, 3]);
        assert_eq!(t.elements[21].kind, ElementKind::Volume);
        assert_eq!(t.elements[20].kind, ElementKind::Surface);
        assert_eq!(t.elements[21].cell, [1, 1, 1]);
        // Nothing in the flesh and no surface: an error.
        let none = CellSurface {
            tris: vec![vec![]; 64],
            pieces: vec![CellPieces::default(); 64],
            ..s
        };
        assert!(make_elements(&none, &[false; 64]).is_err());
    }
}
