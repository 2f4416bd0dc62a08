//! A hash of every bit of a lattice, printed for a set of meshes and settings: equal hashes
//! before and after a change to the build show the change kept its result bit for bit.

use super::{build, V};
use crate::lattice::{ElementKind, ElementOrder, Lattice, LatticeSettings};
use crate::mesh::TriMesh;

/// FNV-1a over 64-bit words.
struct Fnv(u64);
impl Fnv {
    fn word(&mut self, w: u64) {
        for b in w.to_le_bytes() {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x100_0000_01b3);
        }
    }
    fn f(&mut self, x: f64) {
        self.word(x.to_bits());
    }
    fn u(&mut self, x: usize) {
        self.word(x as u64);
    }
}

/// Hash of every float bit pattern and index of a lattice (and its embedding weights).
pub(super) fn lattice_hash(l: &Lattice) -> u64 {
    let mut h = Fnv(0xcbf2_9ce4_8422_2325);
    h.u(l.order.nodes_per_element());
    (0..3).for_each(|d| h.f(l.origin[d]));
    h.f(l.cell_size);
    l.dims.iter().for_each(|&d| h.u(d));
    h.u(l.elements.len());
    for e in &l.elements {
        e.cell.iter().for_each(|&c| h.u(c));
        h.u(usize::from(e.kind == ElementKind::Surface));
        h.u(e.nodes.len());
        e.nodes.iter().for_each(|&n| h.u(n));
    }
    h.u(l.rest.len());
    for p in &l.rest {
        (0..3).for_each(|d| h.f(p[d]));
    }
    for g in &l.grid {
        g.iter().for_each(|&c| h.u(c));
    }
    l.pinned.iter().for_each(|&p| h.u(usize::from(p)));
    h.u(l.vertex_points.len());
    for mp in &l.vertex_points {
        h.u(mp.element);
        mp.xi.iter().for_each(|&x| h.f(x));
    }
    h.u(usize::from(l.closed));
    h.f(l.depth);
    h.u(l.graph.len());
    for &(a, b) in &l.graph {
        h.u(a);
        h.u(b);
    }
    for (v, n, w) in l.embedding_triplets() {
        h.u(v);
        h.u(n);
        h.f(w);
    }
    h.0
}

/// Open square sheet [−w, w]² at z = 0 (spacing s) with a slit on y = 0 for |x| < half.
pub(super) fn slit_sheet(w: f64, s: f64, half: f64) -> TriMesh {
    let n = (2.0 * w / s).round() as usize;
    let coord = |i: usize| -w + i as f64 * s;
    let mut pos = Vec::new();
    let mut id = vec![vec![0usize; n + 1]; n + 1];
    for (i, row) in id.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = pos.len();
            pos.push(V::new(coord(i), coord(j), 0.0));
        }
    }
    let j0 = n / 2;
    let mut lower = id.clone();
    for i in 0..=n {
        if coord(i).abs() < half - 1e-12 {
            lower[i][j0] = pos.len();
            pos.push(pos[id[i][j0]]);
        }
    }
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let g = if j < j0 { &lower } else { &id };
            let (a, b, c, d) = (g[i][j], g[i + 1][j], g[i + 1][j + 1], g[i][j + 1]);
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    TriMesh::new(pos, tris)
}

/// Fingerprint of the lattices of the face rig and small synthetic meshes; run with
/// `cargo test --release --lib fingerprint -- --ignored --nocapture` before and after a
/// change to the build that must not change its result (the current build prints
/// `ALL d48a593624ecfb23` on x86-64 Linux).
#[test]
#[ignore = "prints a hash for refactoring checks; slow-ish"]
fn print_lattice_fingerprints() {
    let face = crate::rig::face::generate().mesh;
    let cube = crate::mesh::cube_mesh(0.4, 4);
    let two = {
        let a = crate::mesh::cube_mesh(0.25, 5);
        let mut b = crate::mesh::cube_mesh(0.24, 5);
        b.positions.iter_mut().for_each(|p| p.x += 0.26);
        let n = a.positions.len();
        let mut m = a.clone();
        m.positions.extend(&b.positions);
        m.triangles
            .extend(b.triangles.iter().map(|t| t.map(|i| i + n)));
        m
    };
    let sheet = slit_sheet(0.05, 0.005, 0.025);
    let q = ElementOrder::Quadratic;
    let t = ElementOrder::Trilinear;
    let set = |cell_size: Option<f64>, target: Option<usize>, order, depth| LatticeSettings {
        cell_size,
        target_cells: target,
        order,
        depth,
    };
    let cases: Vec<(&str, &TriMesh, LatticeSettings)> = vec![
        ("face default", &face, LatticeSettings::default()),
        ("face 1 cm", &face, set(Some(0.01), None, q, None)),
        ("face trilinear 300", &face, set(None, Some(300), t, None)),
        (
            "face 2 cm depth 3 cm",
            &face,
            set(Some(0.02), None, q, Some(0.03)),
        ),
        ("cube 4", &cube, set(Some(0.1), None, q, None)),
        ("cube 4 trilinear", &cube, set(Some(0.1), None, t, None)),
        ("two cubes", &two, set(Some(0.1), None, q, None)),
        ("slit sheet", &sheet, set(Some(0.0125), None, q, Some(0.02))),
        ("slit sheet default", &sheet, LatticeSettings::default()),
    ];
    let mut all = Fnv(0xcbf2_9ce4_8422_2325);
    for (name, mesh, s) in cases {
        let l = build(mesh, &s).unwrap();
        let hash = lattice_hash(&l);
        all.word(hash);
        println!(
            "{name}: {} elements, {} nodes, {} pinned, {} graph edges, hash {hash:016x}",
            l.elements.len(),
            l.node_count(),
            l.pinned_count(),
            l.graph.len()
        );
    }
    println!("ALL {:016x}", all.0);
}
