//! Lattice construction: grid, cell hashing, connected pieces per cell, element graph, node
//! merging, bone nodes and the embedding of the surface vertices.

use super::geom::{
    closest_point_on_triangle, segment_box_overlap, segment_crosses_triangle, triangle_box_overlap,
};
use super::inside::InsideTest;
use super::{
    basis::local_offset, Element, ElementKind, Lattice, LatticeError, LatticeSettings,
    MaterialPoint, DEFAULT_TARGET_CELLS, MAX_CELLS,
};
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
use std::collections::HashMap;

type V = Vector3<f64>;

/// Disjoint-set forest with path halving.
pub(crate) struct UnionFind(Vec<usize>);

impl UnionFind {
    pub fn new(n: usize) -> Self {
        Self((0..n).collect())
    }
    pub fn find(&mut self, mut i: usize) -> usize {
        while self.0[i] != i {
            self.0[i] = self.0[self.0[i]];
            i = self.0[i];
        }
        i
    }
    pub fn union(&mut self, a: usize, b: usize) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb)] = ra.min(rb);
        }
    }
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

pub(crate) fn build(mesh: &TriMesh, s: &LatticeSettings) -> Result<Lattice, LatticeError> {
    check_mesh(mesh)?;
    let order = s.order;
    let k = order.per_axis();
    let (lo0, hi0) = mesh.bounding_box().expect("non-empty");
    let diag = (hi0 - lo0).norm();
    if diag <= 0.0 {
        return Err(LatticeError::Mesh("all vertices coincide".into()));
    }
    let (closed, boundary) = boundary_edges(mesh);
    let depth = s.depth.unwrap_or(0.1 * diag);
    let pad = if closed { 0.0 } else { depth };
    let lo = lo0 - V::repeat(pad);
    let ext = (hi0 - lo0) + V::repeat(2.0 * pad);
    let h = match s.cell_size {
        Some(h) => h,
        None => {
            let target = s.target_cells.unwrap_or(DEFAULT_TARGET_CELLS) as f64;
            let e = ext.map(|c| c.max(1e-3 * diag));
            (e.x * e.y * e.z / target).cbrt()
        }
    };
    let dims = [0, 1, 2].map(|d| ((ext[d] / h - 1e-9).ceil() as usize).max(1));
    let ncell = dims[0] as f64 * dims[1] as f64 * dims[2] as f64;
    if ncell > MAX_CELLS as f64 {
        return Err(LatticeError::TooManyCells {
            cells: ncell as usize,
        });
    }
    let ncell = ncell as usize;
    let cidx = |c: [usize; 3]| c[0] + dims[0] * (c[1] + dims[1] * c[2]);
    let ccoord = |i: usize| {
        [
            i % dims[0],
            (i / dims[0]) % dims[1],
            i / (dims[0] * dims[1]),
        ]
    };
    let eps = 1e-9 * h;
    let cell_box = |c: [usize; 3]| {
        let l = lo + V::new(c[0] as f64, c[1] as f64, c[2] as f64) * h;
        (l - V::repeat(eps), l + V::repeat(h + eps))
    };
    let clamp_cell = |p: &V| -> [usize; 3] {
        let r = (p - lo) / h;
        [0, 1, 2].map(|d| (r[d].floor().max(0.0) as usize).min(dims[d] - 1))
    };
    let pos = &mesh.positions;

    // 1. Spatial hash: triangles overlapping each (closed) cell.
    let per_tri: Vec<Vec<usize>> = mesh
        .triangles
        .par_iter()
        .map(|&[a, b, c]| {
            let tlo = pos[a].inf(&pos[b]).inf(&pos[c]);
            let thi = pos[a].sup(&pos[b]).sup(&pos[c]);
            let (c0, c1) = (
                clamp_cell(&(tlo - V::repeat(eps))),
                clamp_cell(&(thi + V::repeat(eps))),
            );
            let mut out = Vec::new();
            for kz in c0[2]..=c1[2] {
                for ky in c0[1]..=c1[1] {
                    for kx in c0[0]..=c1[0] {
                        let (bl, bh) = cell_box([kx, ky, kz]);
                        if triangle_box_overlap(&pos[a], &pos[b], &pos[c], &bl, &bh) {
                            out.push(cidx([kx, ky, kz]));
                        }
                    }
                }
            }
            out
        })
        .collect();
    let mut cell_tris: Vec<Vec<usize>> = vec![Vec::new(); ncell];
    for (t, cells) in per_tri.iter().enumerate() {
        for &c in cells {
            cell_tris[c].push(t);
        }
    }

    // 1b. Cuts: each boundary edge of an open mesh extruded backwards (against the vertex
    //     normals) by the flesh depth. Flesh may not connect across a cut, so the two sides of
    //     a slit (mouth, eyelids) get separate flesh down to the bone.
    let normals = mesh.vertex_normals();
    let mut cuts: Vec<[V; 3]> = Vec::new();
    for &(a, b) in &boundary {
        let (pa, pb) = (pos[a], pos[b]);
        let (qa, qb) = (pa - normals[a] * depth, pb - normals[b] * depth);
        cuts.push([pa, pb, qb]);
        cuts.push([pa, qb, qa]);
    }
    let mut cell_cuts: Vec<Vec<usize>> = vec![Vec::new(); ncell];
    for (t, [a, b, c]) in cuts.iter().enumerate() {
        let (tlo, thi) = (a.inf(b).inf(c), a.sup(b).sup(c));
        let (c0, c1) = (
            clamp_cell(&(tlo - V::repeat(eps))),
            clamp_cell(&(thi + V::repeat(eps))),
        );
        for kz in c0[2]..=c1[2] {
            for ky in c0[1]..=c1[1] {
                for kx in c0[0]..=c1[0] {
                    let (bl, bh) = cell_box([kx, ky, kz]);
                    if triangle_box_overlap(a, b, c, &bl, &bh) {
                        cell_cuts[cidx([kx, ky, kz])].push(t);
                    }
                }
            }
        }
    }
    let cut_between = |p: &V, q: &V, cells: [usize; 2]| {
        cells.iter().any(|&ci| {
            cell_cuts[ci].iter().any(|&t| {
                let [a, b, c] = &cuts[t];
                segment_crosses_triangle(p, q, a, b, c, 1e-9)
            })
        })
    };

    // 2. Connected pieces of the cut surface in each cell: triangles joined by a shared edge
    //    that passes through the cell, or a shared vertex inside it.
    let pieces: Vec<(usize, Vec<usize>)> = cell_tris
        .par_iter()
        .enumerate()
        .map(|(ci, tris)| {
            if tris.is_empty() {
                return (0, Vec::new());
            }
            let (bl, bh) = cell_box(ccoord(ci));
            let mut uf = UnionFind::new(tris.len());
            let mut edge_first: HashMap<(usize, usize), usize> = HashMap::new();
            let mut vert_first: HashMap<usize, usize> = HashMap::new();
            for (l, &t) in tris.iter().enumerate() {
                let tri = mesh.triangles[t];
                for m in 0..3 {
                    let v = tri[m];
                    let p = pos[v];
                    if (0..3).all(|d| p[d] >= bl[d] && p[d] <= bh[d]) {
                        match vert_first.get(&v) {
                            Some(&o) => uf.union(o, l),
                            None => {
                                vert_first.insert(v, l);
                            }
                        }
                    }
                    let (a, b) = (tri[m], tri[(m + 1) % 3]);
                    let key = (a.min(b), a.max(b));
                    match edge_first.get(&key) {
                        Some(&o) => {
                            if segment_box_overlap(&pos[a], &pos[b], &bl, &bh) {
                                uf.union(o, l);
                            }
                        }
                        None => {
                            edge_first.insert(key, l);
                        }
                    }
                }
            }
            let mut label = HashMap::new();
            let ids: Vec<usize> = (0..tris.len())
                .map(|l| {
                    let r = uf.find(l);
                    let n = label.len();
                    *label.entry(r).or_insert(n)
                })
                .collect();
            (label.len(), ids)
        })
        .collect();

    // 3. Elements: one per piece; cells without surface in the flesh get a volume element.
    let inside = InsideTest::new(mesh, lo, h, dims, &cell_tris, closed, depth);
    let center =
        |c: [usize; 3]| lo + V::new(c[0] as f64 + 0.5, c[1] as f64 + 0.5, c[2] as f64 + 0.5) * h;
    let empty_flesh: Vec<bool> = (0..ncell)
        .into_par_iter()
        .map(|ci| cell_tris[ci].is_empty() && inside.is_flesh(&center(ccoord(ci))))
        .collect();
    let mut elements: Vec<Element> = Vec::new();
    let mut cell_first = vec![usize::MAX; ncell]; // first element of each cell
    for ci in 0..ncell {
        let cell = ccoord(ci);
        let count = if cell_tris[ci].is_empty() {
            usize::from(empty_flesh[ci])
        } else {
            pieces[ci].0
        };
        if count > 0 {
            cell_first[ci] = elements.len();
        }
        let kind = if cell_tris[ci].is_empty() {
            ElementKind::Volume
        } else {
            ElementKind::Surface
        };
        for _ in 0..count {
            elements.push(Element {
                cell,
                nodes: Vec::new(),
                kind,
            });
        }
    }
    let ne = elements.len();
    if ne == 0 {
        return Err(LatticeError::Mesh(
            "no lattice element could be made".into(),
        ));
    }
    let elem_of = |ci: usize, local: usize| cell_first[ci] + pieces[ci].1[local];

    // 4. Element graph across cell faces.
    let face_adjacent =
        |a: [usize; 3], b: [usize; 3]| (0..3).map(|d| a[d].abs_diff(b[d])).sum::<usize>() == 1;
    let mut graph: Vec<(usize, usize)> = Vec::new();
    // 4a. Pieces sharing a triangle.
    let mut tri_elems: Vec<Vec<(usize, usize)>> = vec![Vec::new(); mesh.triangles.len()];
    for ci in 0..ncell {
        for (l, &t) in cell_tris[ci].iter().enumerate() {
            tri_elems[t].push((ci, elem_of(ci, l)));
        }
    }
    for te in &tri_elems {
        for i in 0..te.len() {
            for j in i + 1..te.len() {
                if face_adjacent(ccoord(te[i].0), ccoord(te[j].0)) {
                    graph.push((te[i].1.min(te[j].1), te[i].1.max(te[j].1)));
                }
            }
        }
    }
    // 4b. Volume cells with their face neighbours: other volume cells always; surface pieces
    //     when the volume cell is behind the piece and not screened by another piece.
    for ci in 0..ncell {
        if !empty_flesh[ci] {
            continue;
        }
        let c = ccoord(ci);
        let ev = cell_first[ci];
        let cv = center(c);
        for d in 0..3 {
            for s in [-1i64, 1] {
                let nb = c[d] as i64 + s;
                if nb < 0 || nb >= dims[d] as i64 {
                    continue;
                }
                let mut cn = c;
                cn[d] = nb as usize;
                let ni = cidx(cn);
                if empty_flesh[ni] {
                    if !cut_between(&cv, &center(cn), [ci, ni]) {
                        graph.push((ev.min(cell_first[ni]), ev.max(cell_first[ni])));
                    }
                    continue;
                }
                if cell_tris[ni].is_empty() {
                    continue;
                }
                let tris = &cell_tris[ni];
                for piece in 0..pieces[ni].0 {
                    let mut best = (f64::INFINITY, V::zeros(), V::zeros(), V::zeros());
                    for (l, &t) in tris.iter().enumerate() {
                        if pieces[ni].1[l] != piece {
                            continue;
                        }
                        let [a, b, cc] = mesh.triangles[t];
                        let q = closest_point_on_triangle(&cv, &pos[a], &pos[b], &pos[cc]);
                        let dist = (q - cv).norm();
                        if dist < best.0 {
                            let n = (pos[b] - pos[a]).cross(&(pos[cc] - pos[a]));
                            let centroid = (pos[a] + pos[b] + pos[cc]) / 3.0;
                            best = (dist, q, n, centroid);
                        }
                    }
                    let (_, q0, n, centroid) = best;
                    let behind = (cv - q0).dot(&n) <= 0.0;
                    // Screening and cuts are tested on the segment to the centroid of the
                    // nearest triangle: the nearest point itself may lie on a slit edge,
                    // exactly on the cut that should separate this piece.
                    let q = centroid;
                    let screened = tris.iter().enumerate().any(|(l, &t)| {
                        let [a, b, cc] = mesh.triangles[t];
                        pieces[ni].1[l] != piece
                            && segment_crosses_triangle(&cv, &q, &pos[a], &pos[b], &pos[cc], 1e-9)
                    });
                    if behind && !screened && !cut_between(&cv, &q, [ci, ni]) {
                        let ep = cell_first[ni] + piece;
                        graph.push((ev.min(ep), ev.max(ep)));
                    }
                }
            }
        }
    }
    graph.sort_unstable();
    graph.dedup();

    // 4c. Keep only the parts of the element graph that hold surface: flesh cells connected to
    //     no skin cannot move the skin and would only float.
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
    let mut elements = kept;
    let ne = elements.len();
    let graph: Vec<(usize, usize)> = graph
        .into_iter()
        .filter(|&(a, b)| renumber[a] != usize::MAX && renumber[b] != usize::MAX)
        .map(|(a, b)| (renumber[a], renumber[b]))
        .collect();

    // 5. Node merging: every element starts with its own k³ nodes; for each graph edge the
    //    nodes at the same grid position (two layers for quadratic, one for trilinear) merge.
    let npe = order.nodes_per_element();
    let mut uf = UnionFind::new(ne * npe);
    for &(e1, e2) in &graph {
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
    let mut node_of_root: HashMap<usize, usize> = HashMap::new();
    let mut rest = Vec::new();
    let mut grid = Vec::new();
    let off0 = order.node_offset();
    for (e, el) in elements.iter_mut().enumerate() {
        el.nodes = (0..npe)
            .map(|a| {
                let r = uf.find(e * npe + a);
                *node_of_root.entry(r).or_insert_with(|| {
                    let off = local_offset(order, a);
                    let g = [0, 1, 2].map(|d| el.cell[d] + off[d]);
                    rest.push(
                        lo + V::new(g[0] as f64 + off0, g[1] as f64 + off0, g[2] as f64 + off0) * h,
                    );
                    grid.push(g);
                    rest.len() - 1
                })
            })
            .collect();
    }

    // 6. Bone nodes (open meshes): behind the surface, deeper than the flesh depth.
    let pinned: Vec<bool> = rest.par_iter().map(|p| inside.is_bone(p)).collect();

    // 7. Embedding: each vertex lies in the element of the piece holding its triangles.
    let mut vert_tri: Vec<usize> = vec![usize::MAX; pos.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for &v in tri {
            if vert_tri[v] == usize::MAX {
                vert_tri[v] = t;
            }
        }
    }
    let mut vertex_points = Vec::with_capacity(pos.len());
    for (v, p) in pos.iter().enumerate() {
        let t = vert_tri[v];
        let c = clamp_cell(p);
        let ci = cidx(c);
        let e = if t == usize::MAX {
            // A vertex on no triangle: any element of its cell (the first) carries it.
            let first = cell_first[ci];
            if first == usize::MAX || renumber[first] == usize::MAX {
                return Err(LatticeError::Mesh(format!(
                    "vertex {v} belongs to no triangle and lies in no lattice element; remove unreferenced vertices"
                )));
            }
            renumber[first]
        } else {
            let Some(l) = cell_tris[ci].iter().position(|&u| u == t) else {
                return Err(LatticeError::Mesh(format!(
                    "vertex {v} at {p:?} could not be placed in a lattice cell (degenerate triangle {t}?)"
                )));
            };
            renumber[elem_of(ci, l)]
        };
        let r = (p - (lo + V::new(c[0] as f64, c[1] as f64, c[2] as f64) * h)) / h;
        vertex_points.push(MaterialPoint {
            element: e,
            xi: [0, 1, 2].map(|d| r[d].clamp(0.0, 1.0)),
        });
    }

    Ok(Lattice {
        order,
        origin: lo,
        cell_size: h,
        dims,
        elements,
        rest,
        grid,
        pinned,
        vertex_points,
        closed,
        depth,
        graph,
    })
}
