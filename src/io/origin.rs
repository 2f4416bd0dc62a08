//! Where an exported vertex comes from in the loaded face (up to three loaded vertices and
//! weights), and the local frame its world-space results (m, as simulated) are written back
//! in (the face's local coordinates, the file's units).

use super::load::Rig;
use super::mesh::VertexTransform;
use anyhow::Context;
use nalgebra::{Matrix3, Matrix4, Vector3};

/// Where an output vertex came from: a convex combination of up to three vertices of the
/// loaded face (indices into its merged vertex arrays). Used to carry texture coordinates,
/// skin weights and the local frame to refined meshes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VertexOrigin {
    /// Source vertices.
    pub vertices: [usize; 3],
    /// Their weights (sum to one).
    pub weights: [f64; 3],
}

impl VertexOrigin {
    /// The vertex itself.
    pub fn same(i: usize) -> Self {
        Self {
            vertices: [i, i, i],
            weights: [1.0, 0.0, 0.0],
        }
    }
    /// The source vertex with the largest weight.
    pub fn dominant(&self) -> usize {
        let k = (0..3)
            .max_by(|&a, &b| self.weights[a].total_cmp(&self.weights[b]))
            .unwrap_or(0);
        self.vertices[k]
    }
}

/// Local-to-world affine map of an exported vertex (blended for skinned faces).
fn vertex_matrix(t: &VertexTransform, o: &VertexOrigin) -> Matrix4<f64> {
    match t {
        VertexTransform::Node(m) => *m,
        VertexTransform::PerVertex(_) => (0..3).map(|k| t.of(o.vertices[k]) * o.weights[k]).sum(),
    }
}

/// Per exported vertex: world→local point map (inverse affine) and its linear part, for
/// writing world-space results (m, as simulated) back in the face's local coordinates (the
/// file's units).
pub(crate) struct LocalFrames {
    inv: Vec<Matrix4<f64>>,
    lin: Vec<Matrix3<f64>>,
}

impl LocalFrames {
    /// The frames of vertices with origins `origin` in `rig`'s face.
    pub(crate) fn new(rig: &Rig, origin: &[VertexOrigin]) -> anyhow::Result<Self> {
        let t = &rig.face().to_world;
        let mut inv = Vec::with_capacity(origin.len());
        let mut lin = Vec::with_capacity(origin.len());
        for (i, o) in origin.iter().enumerate() {
            let m = vertex_matrix(t, o);
            let mi = m.try_inverse().with_context(|| {
                format!(
                    "{}: the face's transform at vertex {i} is singular (zero scale?)",
                    rig.path.display()
                )
            })?;
            lin.push(mi.fixed_view::<3, 3>(0, 0).into_owned());
            inv.push(mi);
        }
        Ok(Self { inv, lin })
    }
    /// Vertex `i`'s world point `p` in local coordinates.
    pub(crate) fn point(&self, i: usize, p: &Vector3<f64>) -> Vector3<f64> {
        (self.inv[i] * p.push(1.0)).xyz()
    }

    /// A world displacement `d` at vertex `i` in local coordinates (morph position deltas).
    pub(crate) fn vector(&self, i: usize, d: &Vector3<f64>) -> Vector3<f64> {
        self.lin[i] * d
    }

    /// A world normal change `d` at vertex `i` in local coordinates (morph normal deltas): the
    /// normal map's linear part over its mean scale, which is exact for rotations with uniform
    /// scale and linear, so weighted sums of deltas map as the deltas do.
    pub(crate) fn normal_delta(&self, i: usize, d: &Vector3<f64>) -> Vector3<f64> {
        let m = self.lin[i]
            .try_inverse()
            .map(|m| m.transpose())
            .unwrap_or(self.lin[i]);
        let s = m.determinant().abs().cbrt();
        if s > 0.0 {
            m * d / s
        } else {
            *d
        }
    }

    /// Vertex `i`'s world unit normal `n` in local coordinates (unit).
    pub(crate) fn normal(&self, i: usize, n: &Vector3<f64>) -> Vector3<f64> {
        // Normals map by the inverse transpose of the (world→local) linear part.
        let r = self.lin[i]
            .try_inverse()
            .map(|m| m.transpose())
            .unwrap_or(self.lin[i])
            * n;
        let l = r.norm();
        if l > 0.0 {
            r / l
        } else {
            Vector3::z()
        }
    }
}
