//! Mesh connectivity: unique edges and the bending hinges (interior edges with their two
//! opposite vertices) that the thin shell's bending energy lives on.

use super::TriMesh;
use std::collections::HashMap;

/// An interior edge shared by exactly two triangles, oriented so that triangle `tris[0]`
/// is `(v[0], v[1], v[2])` in its counter-clockwise order and triangle `tris[1]` is
/// `(v[1], v[0], v[3])`: `v[0]`, `v[1]` are the edge, `v[2]`, `v[3]` the opposite vertices.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Hinge {
    /// Vertex indices `[edge start, edge end, opposite in tris[0], opposite in tris[1]]`.
    pub v: [usize; 4],
    /// The two triangles sharing the edge.
    pub tris: [usize; 2],
}

/// Edges and hinges of a triangle mesh.
#[derive(Debug, Clone, Default)]
pub struct Topology {
    /// Unique undirected edges `(a, b)` with `a < b`.
    pub edges: Vec<[usize; 2]>,
    /// Edges on the boundary (one incident triangle), as indices into `edges`.
    pub boundary_edges: Vec<usize>,
    /// Interior edges with their opposite vertices (consistently oriented pairs only).
    pub hinges: Vec<Hinge>,
}

/// Connectivity errors a user must fix in the mesh.
#[derive(Debug, thiserror::Error, PartialEq, Eq)]
pub enum TopologyError {
    /// A triangle references a vertex that does not exist.
    #[error("triangle {tri} references vertex {vertex}, but the mesh has {count} vertices")]
    BadIndex {
        /// Triangle index.
        tri: usize,
        /// Offending vertex index.
        vertex: usize,
        /// Number of vertices.
        count: usize,
    },
    /// A triangle repeats a vertex (zero area by construction).
    #[error("triangle {tri} repeats a vertex: {verts:?}")]
    DegenerateTriangle {
        /// Triangle index.
        tri: usize,
        /// Its vertex indices.
        verts: [usize; 3],
    },
    /// More than two triangles share one edge: a thin shell needs a manifold surface.
    #[error("edge ({a}, {b}) is shared by {count} triangles; the skin must be a manifold surface (split or remesh it)")]
    NonManifoldEdge {
        /// Edge start vertex.
        a: usize,
        /// Edge end vertex.
        b: usize,
        /// Number of incident triangles.
        count: usize,
    },
    /// Two triangles share an edge with the same direction: their windings disagree.
    #[error("triangles {t0} and {t1} share edge ({a}, {b}) with inconsistent winding; orient the mesh consistently")]
    InconsistentWinding {
        /// First triangle.
        t0: usize,
        /// Second triangle.
        t1: usize,
        /// Edge start vertex.
        a: usize,
        /// Edge end vertex.
        b: usize,
    },
}

impl Topology {
    /// Build edges and hinges of `mesh`, or say why the mesh cannot carry a thin shell.
    pub fn new(mesh: &TriMesh) -> Result<Self, TopologyError> {
        let n = mesh.positions.len();
        // For each undirected edge: list of (triangle, local corner of the edge start).
        let mut map: HashMap<(usize, usize), Vec<(usize, usize)>> = HashMap::new();
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for &v in tri {
                if v >= n {
                    return Err(TopologyError::BadIndex {
                        tri: t,
                        vertex: v,
                        count: n,
                    });
                }
            }
            if tri[0] == tri[1] || tri[1] == tri[2] || tri[0] == tri[2] {
                return Err(TopologyError::DegenerateTriangle {
                    tri: t,
                    verts: *tri,
                });
            }
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                map.entry((a.min(b), a.max(b))).or_default().push((t, k));
            }
        }
        let mut keys: Vec<(usize, usize)> = map.keys().copied().collect();
        keys.sort_unstable();
        let mut topo = Topology::default();
        for (a, b) in keys {
            let inc = &map[&(a, b)];
            let ei = topo.edges.len();
            topo.edges.push([a, b]);
            match inc.len() {
                1 => topo.boundary_edges.push(ei),
                2 => {
                    let (t0, k0) = inc[0];
                    let (t1, k1) = inc[1];
                    let tri0 = mesh.triangles[t0];
                    let tri1 = mesh.triangles[t1];
                    let (s0, e0) = (tri0[k0], tri0[(k0 + 1) % 3]);
                    let (s1, e1) = (tri1[k1], tri1[(k1 + 1) % 3]);
                    if s0 == s1 || e0 == e1 {
                        return Err(TopologyError::InconsistentWinding { t0, t1, a, b });
                    }
                    let o0 = tri0[(k0 + 2) % 3];
                    let o1 = tri1[(k1 + 2) % 3];
                    topo.hinges.push(Hinge {
                        v: [s0, e0, o0, o1],
                        tris: [t0, t1],
                    });
                    let _ = e1;
                }
                c => return Err(TopologyError::NonManifoldEdge { a, b, count: c }),
            }
        }
        Ok(topo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    fn square() -> TriMesh {
        TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(1.0, 0.0, 0.0),
                Vector3::new(1.0, 1.0, 0.0),
                Vector3::new(0.0, 1.0, 0.0),
            ],
            vec![[0, 1, 2], [0, 2, 3]],
        )
    }

    #[test]
    fn two_triangles_have_five_edges_one_oriented_hinge() {
        let t = Topology::new(&square()).unwrap();
        assert_eq!(t.edges.len(), 5);
        assert_eq!(t.boundary_edges.len(), 4);
        assert_eq!(t.hinges.len(), 1);
        let h = t.hinges[0];
        // tris[0] = (v0, v1, v2) and tris[1] = (v1, v0, v3) as cyclic orders.
        let cyc = |tri: [usize; 3], a: usize, b: usize, c: usize| {
            (0..3).any(|k| tri[k] == a && tri[(k + 1) % 3] == b && tri[(k + 2) % 3] == c)
        };
        let m = square();
        assert!(cyc(m.triangles[h.tris[0]], h.v[0], h.v[1], h.v[2]));
        assert!(cyc(m.triangles[h.tris[1]], h.v[1], h.v[0], h.v[3]));
    }

    #[test]
    fn bad_meshes_are_refused_with_the_reason() {
        let mut m = square();
        m.triangles[1] = [0, 3, 2];
        assert!(matches!(
            Topology::new(&m),
            Err(TopologyError::InconsistentWinding { .. })
        ));
        let mut m = square();
        m.triangles.push([2, 0, 1]);
        m.triangles[2] = [0, 2, 1];
        m.positions.push(Vector3::new(0.5, 0.5, 1.0));
        m.triangles.push([0, 4, 2]);
        assert!(Topology::new(&m).is_err());
        let mut m = square();
        m.triangles[0] = [0, 1, 9];
        assert!(matches!(
            Topology::new(&m),
            Err(TopologyError::BadIndex { .. })
        ));
    }
}
