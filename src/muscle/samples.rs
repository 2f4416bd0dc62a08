//! Where each blend shape's lattice fit is measured: the face's vertices and, between them,
//! the vertices of its subdivided surface.
//!
//! The lattice fit ‖B u − Δ‖² + α uᵀ K u ([`super::generate::fit_node_displacements`]) held
//! only at the rig's vertices lets a coarse lattice swing between them: on the capture head
//! (17.2 mm cells) the blink's fit moved an outer control node by 18 cm for a 2 cm lid, and
//! the refined skin between the vertices creased the forehead the shape leaves still. The
//! skin the pipeline renders is the subdivided surface, so the fit is held there too: a
//! subdivided vertex's displacement is its subdivision row over the rig's vertices (S Δ,
//! the same operator the refined skin's targets go through).

use crate::coupling::embedding::Embedding;
use crate::coupling::refine::embed_refined;
use crate::lattice::{Lattice, MaterialPoint};
use crate::mesh::redgreen::{self, Smoothing};
use crate::mesh::TriMesh;
use nalgebra::Vector3;

/// Levels of 1-to-4 subdivision the shapes' lattice fit is held on by default: one puts a
/// sample at every edge's (smoothed) midpoint, where a coarse lattice's fit swings most.
pub const SAMPLE_LEVELS: usize = 1;

/// Points on the face where the lattice fit of each shape is held, with their displacement
/// as a blend of the rig vertices' displacements.
#[derive(Debug, Clone)]
pub struct ShapeSamples {
    /// Each sample's material point in the lattice (rest state).
    pub points: Vec<MaterialPoint>,
    /// Each sample's displacement as weights over the rig's (welded) vertices: Σ w Δ_v
    /// (dimensionless, summing to one).
    pub of: Vec<Vec<(usize, f64)>>,
}

impl ShapeSamples {
    /// The rig's vertices alone (the lattice's embedded surface).
    pub fn vertices(lattice: &Lattice) -> Self {
        Self {
            points: lattice.vertex_points.clone(),
            of: (0..lattice.vertex_points.len())
                .map(|v| vec![(v, 1.0)])
                .collect(),
        }
    }

    /// The vertices of `mesh` (the surface the lattice was built over) subdivided `levels`
    /// times everywhere with the skin's smoothing rule (modified butterfly), embedded in
    /// `lattice`. A mesh without triangles or `levels` = 0 gives [`Self::vertices`].
    pub fn subdivided(lattice: &Lattice, mesh: &TriMesh, levels: usize) -> anyhow::Result<Self> {
        if levels == 0 || mesh.triangles.is_empty() {
            return Ok(Self::vertices(lattice));
        }
        let all = vec![true; mesh.triangles.len()];
        let rg = redgreen::refine(mesh, &all, levels, Smoothing::Butterfly);
        let points = embed_refined(lattice, mesh, &rg)?;
        Ok(Self {
            points,
            of: rg.weights,
        })
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.points.len()
    }

    /// Whether there are none.
    pub fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The samples' displacements (flat, m) for vertex displacements `delta` (m).
    pub fn displacement(&self, delta: &[Vector3<f64>]) -> Vec<f64> {
        self.of
            .iter()
            .flat_map(|row| {
                let d: Vector3<f64> = row.iter().map(|&(v, w)| w * delta[v]).sum();
                [d.x, d.y, d.z]
            })
            .collect()
    }

    /// The embedding B of the samples in `lattice`.
    pub fn embedding(&self, lattice: &Lattice) -> Embedding {
        let triplets = crate::coupling::refine::embedding_triplets(lattice, &self.points);
        Embedding::from_triplets(&triplets, self.points.len(), lattice.node_count())
    }
}
