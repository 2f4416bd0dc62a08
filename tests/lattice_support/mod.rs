//! Synthetic meshes for the lattice tests.
#![allow(clippy::needless_range_loop)]
#![allow(dead_code)]

use furrow::fem::{Interior, Material};
use furrow::lattice::{ElementOrder, Lattice, LatticeSettings};
use furrow::mesh::TriMesh;
use nalgebra::{Matrix3, Vector3};

type V = Vector3<f64>;

pub use furrow::mesh::box_mesh;

/// Two meshes in one.
pub fn merge(a: &TriMesh, b: &TriMesh) -> TriMesh {
    let n = a.positions.len();
    let mut p = a.positions.clone();
    p.extend(&b.positions);
    let mut t = a.triangles.clone();
    t.extend(b.triangles.iter().map(|t| t.map(|i| i + n)));
    TriMesh::new(p, t)
}

/// An open "mask": the square sheet [−w, w]² in the plane z = 0 facing +z (flesh behind it,
/// at z < 0), grid spacing `s`, cut along a mouth slit on y = 0 for |x| < `half_slit`: the
/// upper lip (y ≥ 0) and lower lip (y ≤ 0) coincide there but share no vertex; the sheet is
/// one connected surface around the slit corners. Returns the mesh and the vertex sets of
/// the upper and lower slit edges.
pub fn slit_sheet(w: f64, s: f64, half_slit: f64) -> (TriMesh, Vec<usize>, Vec<usize>) {
    let n = (2.0 * w / s).round() as usize;
    let mut pos = Vec::new();
    let mut id = vec![vec![0usize; n + 1]; n + 1];
    let coord = |i: usize| -w + i as f64 * s;
    for (i, row) in id.iter_mut().enumerate() {
        for (j, v) in row.iter_mut().enumerate() {
            *v = pos.len();
            pos.push(V::new(coord(i), coord(j), 0.0));
        }
    }
    let j0 = n / 2; // y = 0 row
    let mut lower_id = id.clone();
    let mut upper = Vec::new();
    let mut lower = Vec::new();
    for i in 0..=n {
        if coord(i).abs() < half_slit - 1e-12 {
            let p = pos[id[i][j0]];
            lower_id[i][j0] = pos.len();
            pos.push(p);
            upper.push(id[i][j0]);
            lower.push(lower_id[i][j0]);
        }
    }
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let g = if j < j0 { &lower_id } else { &id };
            let (a, b, c, d) = (g[i][j], g[i + 1][j], g[i + 1][j + 1], g[i][j + 1]);
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    (TriMesh::new(pos, tris), upper, lower)
}

/// Deterministic pseudo-random numbers in [−1, 1].
pub fn noise(i: usize) -> f64 {
    let x = ((i as f64 + 1.0) * 12.9898).sin() * 43758.5453;
    2.0 * (x - x.floor()) - 1.0
}

/// Two 10 cm cells side by side along x (a 20 × 10 × 10 cm box) of `order`, and their
/// interior of Young's modulus `young` (Pa), ν = 0.3, ρ = 1000 kg/m³.
pub fn two_cells(order: ElementOrder, young: f64) -> (Lattice, Interior) {
    let mesh = box_mesh(V::zeros(), V::new(0.2, 0.1, 0.1), 2);
    let lat = Lattice::build(
        &mesh,
        &LatticeSettings {
            cell_size: Some(0.1),
            order,
            ..Default::default()
        },
    )
    .unwrap();
    let mat = Material {
        young,
        poisson: 0.3,
        density: 1000.0,
    };
    let int = Interior::new(&lat, &mat).unwrap();
    (lat, int)
}

/// Flat positions `q` (m) mapped by x ↦ m x + t.
pub fn transform(q: &[f64], m: &Matrix3<f64>, t: V) -> Vec<f64> {
    q.chunks(3)
        .flat_map(|c| {
            let p = m * V::new(c[0], c[1], c[2]) + t;
            [p.x, p.y, p.z]
        })
        .collect()
}
