//! Step "merge across faces" of the build, its graph: which elements touch across a cell
//! face (shared triangles, flesh behind a piece, flesh to flesh), and the connected parts of
//! that graph that hold skin.

use super::cuts::SlitCuts;
use super::surface::CellSurface;
use super::union_find::UnionFind;
use super::V;
use crate::lattice::geom::{closest_point_on_triangle, segment_crosses_triangle};
use crate::lattice::{Element, ElementKind};

/// Step "merge across faces", surface part: element pairs (low, high) whose pieces share a
/// triangle across a cell face (the piece continues into the neighbouring cell).
pub(super) fn shared_triangle_links(surf: &CellSurface, first: &[usize]) -> Vec<(usize, usize)> {
    let g = &surf.grid;
    let face_adjacent =
        |a: [usize; 3], b: [usize; 3]| (0..3).map(|d| a[d].abs_diff(b[d])).sum::<usize>() == 1;
    let mut tri_elems: Vec<Vec<(usize, usize)>> = vec![Vec::new(); surf.mesh.triangles.len()];
    for ci in 0..g.cell_count() {
        for (l, &t) in surf.tris[ci].iter().enumerate() {
            tri_elems[t].push((ci, first[ci] + surf.pieces[ci].of[l]));
        }
    }
    let mut links = Vec::new();
    for te in &tri_elems {
        for i in 0..te.len() {
            for j in i + 1..te.len() {
                if face_adjacent(g.coord(te[i].0), g.coord(te[j].0)) {
                    links.push((te[i].1.min(te[j].1), te[i].1.max(te[j].1)));
                }
            }
        }
    }
    links
}

/// Step "close", part 2: element pairs (low, high) joining each flesh volume cell to its face
/// neighbours: other volume cells unless a slit cut separates the centres; surface pieces
/// when the volume cell lies behind the piece and no other piece or cut screens it.
pub(super) fn volume_links(
    surf: &CellSurface,
    cuts: &SlitCuts,
    first: &[usize],
    flesh: &[bool],
) -> Vec<(usize, usize)> {
    let g = &surf.grid;
    let mut links = Vec::new();
    for ci in (0..g.cell_count()).filter(|&ci| flesh[ci]) {
        let c = g.coord(ci);
        let ev = first[ci];
        for cn in g.face_neighbours(c) {
            let ni = g.index(cn);
            if flesh[ni] {
                if !cuts.between(&g.center(c), &g.center(cn), [ci, ni]) {
                    links.push((ev.min(first[ni]), ev.max(first[ni])));
                }
                continue;
            }
            for piece in 0..surf.pieces[ni].count {
                if volume_reaches_piece(surf, cuts, [ci, ni], piece) {
                    let ep = first[ni] + piece;
                    links.push((ev.min(ep), ev.max(ep)));
                }
            }
        }
    }
    links
}

/// Does the flesh of volume cell `cells[0]` reach piece `piece` of its neighbour `cells[1]`?
/// Yes when the cell centre is behind the piece's nearest triangle and the segment from the
/// centre to that triangle's centroid crosses neither another piece of the neighbour nor a
/// slit cut. (The centroid, not the nearest point: the nearest point may lie on a slit edge,
/// exactly on the cut that should separate this piece.)
pub(super) fn volume_reaches_piece(
    surf: &CellSurface,
    cuts: &SlitCuts,
    [ci, ni]: [usize; 2],
    piece: usize,
) -> bool {
    let pos = &surf.mesh.positions;
    let cv = surf.grid.center(surf.grid.coord(ci));
    let (q0, n, centroid) = nearest_triangle_of_piece(surf, &cv, ni, piece);
    let behind = (cv - q0).dot(&n) <= 0.0;
    let q = centroid;
    let screened = surf.tris[ni].iter().enumerate().any(|(l, &t)| {
        let [a, b, cc] = surf.mesh.triangles[t];
        surf.pieces[ni].of[l] != piece
            && segment_crosses_triangle(&cv, &q, &pos[a], &pos[b], &pos[cc], 1e-9)
    });
    behind && !screened && !cuts.between(&cv, &q, [ci, ni])
}

/// The triangle of piece `piece` of cell `ni` nearest to `p` (m): the nearest point on it,
/// its (unnormalised, area-weighted) normal and its centroid. The first triangle wins ties.
pub(super) fn nearest_triangle_of_piece(
    surf: &CellSurface,
    p: &V,
    ni: usize,
    piece: usize,
) -> (V, V, V) {
    let pos = &surf.mesh.positions;
    let mut best = (f64::INFINITY, V::zeros(), V::zeros(), V::zeros());
    for (l, &t) in surf.tris[ni].iter().enumerate() {
        if surf.pieces[ni].of[l] != piece {
            continue;
        }
        let [a, b, cc] = surf.mesh.triangles[t];
        let q = closest_point_on_triangle(p, &pos[a], &pos[b], &pos[cc]);
        let dist = (q - p).norm();
        if dist < best.0 {
            let n = (pos[b] - pos[a]).cross(&(pos[cc] - pos[a]));
            let centroid = (pos[a] + pos[b] + pos[cc]) / 3.0;
            best = (dist, q, n, centroid);
        }
    }
    (best.1, best.2, best.3)
}

/// The elements and element graph kept by [`keep_surface_parts`].
pub(super) struct Kept {
    /// The kept elements, in their former order.
    pub(super) elements: Vec<Element>,
    /// The graph edges between kept elements, renumbered.
    pub(super) graph: Vec<(usize, usize)>,
    /// New index of each former element (`usize::MAX` when dropped).
    pub(super) renumber: Vec<usize>,
}

/// Keep only the connected parts of the element graph that hold surface: flesh cells joined
/// to no skin cannot move the skin and would only float.
pub(super) fn keep_surface_parts(elements: Vec<Element>, graph: Vec<(usize, usize)>) -> Kept {
    let ne = elements.len();
    let mut comp = UnionFind::new(ne);
    for &(a, b) in &graph {
        comp.union(a, b);
    }
    let mut has_surface = vec![false; ne];
    for (e, el) in elements.iter().enumerate() {
        if el.kind == ElementKind::Surface {
            let r = comp.find(e);
            has_surface[r] = true;
        }
    }
    let mut renumber = vec![usize::MAX; ne];
    let mut kept = Vec::new();
    for (e, el) in elements.into_iter().enumerate() {
        if has_surface[comp.find(e)] {
            renumber[e] = kept.len();
            kept.push(el);
        }
    }
    let graph = graph
        .into_iter()
        .filter(|&(a, b)| renumber[a] != usize::MAX && renumber[b] != usize::MAX)
        .map(|(a, b)| (renumber[a], renumber[b]))
        .collect();
    Kept {
        elements: kept,
        graph,
        renumber,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::build::elements::{flesh_cells, make_elements};
    use crate::lattice::build::test_meshes::*;
    use crate::lattice::inside::InsideTest;
    use crate::lattice::ElementKind;
    use std::collections::HashSet;

    /// Step "merge across faces", surface part: the two cells of a 0.2 × 0.1 × 0.1 m box
    /// share 32 triangles, all joining element 0 to element 1.
    #[test]
    fn shared_triangles_link_neighbouring_pieces() {
        let b = box_mesh(V::zeros(), v(0.2, 0.1, 0.1), 2);
        let s = surface(&b, 0.1, 0.0);
        let links = shared_triangle_links(&s, &[0, 1]);
        assert_eq!(links.len(), 32);
        assert!(links.iter().all(|&l| l == (0, 1)));
    }

    /// Step "close", links: in the closed 0.4 m box, the 8 inner volume cells link to each
    /// other (12 faces, each seen from both sides) and to the 24 surface cells they face; a cell outside the box is in
    /// front of the surface and reaches no piece.
    #[test]
    fn volume_cells_link_to_volume_and_to_pieces_they_lie_behind() {
        let b = box_mesh(V::zeros(), V::repeat(0.4), 4);
        let s = surface(&b, 0.1, 0.0);
        let inside = InsideTest::new(&b, s.grid.lo, 0.1, s.grid.dims, &s.tris, true, 0.0);
        let flesh = flesh_cells(&s, &inside);
        let t = make_elements(&s, &flesh).unwrap();
        let links = volume_links(&s, &no_cuts(&s), &t.first, &flesh);
        let both = |(a, b): &(usize, usize)| flesh[*a] && flesh[*b];
        // Each volume–volume face is found from both sides.
        assert_eq!(links.len(), 48);
        assert_eq!(links.iter().filter(|l| both(l)).count(), 24);
        let unique: HashSet<_> = links.iter().collect();
        assert_eq!(unique.len(), 36);
        assert!(links.contains(&(17, 21)) && links.contains(&(21, 22)));
        // Padded by one cell: cell (0,1,1) is outside, (2,1,1) inside, (1,1,1) on the x = 0 face.
        let p = surface(&b, 0.1, 0.1);
        let (out, face, inner) = ([0, 1, 1], [1, 1, 1], [2, 1, 1]);
        let [o, f, i] = [out, face, inner].map(|c| p.grid.index(c));
        assert_eq!(p.pieces[f].count, 1);
        assert!(!volume_reaches_piece(&p, &no_cuts(&p), [o, f], 0));
        assert!(volume_reaches_piece(&p, &no_cuts(&p), [i, f], 0));
    }

    /// Keep the graph parts holding surface: an isolated volume element is dropped, an
    /// isolated surface element kept.
    #[test]
    fn parts_without_surface_are_dropped() {
        let el = |kind| Element {
            cell: [0, 0, 0],
            nodes: vec![],
            kind,
        };
        use ElementKind::{Surface, Volume};
        let k = keep_surface_parts(
            vec![el(Volume), el(Surface), el(Volume), el(Surface), el(Volume)],
            vec![(0, 1), (2, 4)],
        );
        assert_eq!(k.renumber, vec![0, 1, usize::MAX, 2, usize::MAX]);
        assert_eq!(k.graph, vec![(0, 1)]);
        let kinds: Vec<_> = k.elements.iter().map(|e| e.kind).collect();
        assert_eq!(kinds, vec![Volume, Surface, Surface]);
    }
}
