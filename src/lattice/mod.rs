//! The coarse interior lattice: hexahedral cells, B-spline bases, superimposed elements, embedding.
//!
//! A regular grid of cubic cells (edge `cell_size`, metres) covers the mesh. In each cell, the
//! surface is cut by the cell's faces; every connected piece of the cut surface becomes one
//! element (with the volume it bounds), so two parts of the mesh that share a cell but are not
//! connected inside it (upper and lower lip) get superimposed elements with their own nodes.
//! Cells with no surface that lie in the flesh become one volume element each. Elements whose
//! pieces touch across a cell face share their overlapping nodes (18 for quadratic B-splines,
//! 4 for trilinear); everything else stays separate. See [`Lattice::build`].

// Numerical kernels index small fixed-size arrays by axis; iterator forms obscure them.
#![allow(clippy::needless_range_loop)]

pub mod basis;
mod build;
pub(crate) mod geom;
mod inside;

pub use basis::{shape, ElementOrder, Shape};

use crate::math::sparse::{assemble, SparseError};
use crate::mesh::TriMesh;
use faer::sparse::SparseColMat;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Default number of lattice cells over the (padded) bounding box when neither
/// `cell_size` nor `target_cells` is given.
pub const DEFAULT_TARGET_CELLS: usize = 500;

/// Largest number of grid cells a lattice may have (a guard against a mistyped cell size).
pub const MAX_CELLS: usize = 4_000_000;

/// How to build a lattice over a mesh.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatticeSettings {
    /// Cell edge length (m). Takes the place of `target_cells` when set.
    pub cell_size: Option<f64>,
    /// Approximate number of cells over the (padded) bounding box, used when `cell_size` is
    /// not given (default [`DEFAULT_TARGET_CELLS`]).
    pub target_cells: Option<usize>,
    /// Quadratic B-spline (default) or trilinear elements.
    pub order: ElementOrder,
    /// Flesh depth behind an open surface (m): lattice material reaches this far behind the
    /// skin, and nodes behind the skin deeper than this are bone (pinned). Default: 10 % of the
    /// mesh's bounding-box diagonal. Unused for closed meshes (their inside is the flesh).
    pub depth: Option<f64>,
}

impl Default for LatticeSettings {
    fn default() -> Self {
        Self {
            cell_size: None,
            target_cells: None,
            order: ElementOrder::Quadratic,
            depth: None,
        }
    }
}

impl LatticeSettings {
    /// Check the settings; the error names the field that is wrong.
    pub fn validate(&self) -> Result<(), LatticeError> {
        let bad = |field: &'static str, msg: String| Err(LatticeError::Settings { field, msg });
        if let Some(h) = self.cell_size {
            if !(h.is_finite() && h > 0.0) {
                return bad(
                    "cell_size",
                    format!("must be a positive length in metres, got {h}"),
                );
            }
            if self.target_cells.is_some() {
                return bad(
                    "target_cells",
                    "give either cell_size or target_cells, not both".into(),
                );
            }
        }
        if let Some(n) = self.target_cells {
            if n == 0 || n > MAX_CELLS {
                return bad(
                    "target_cells",
                    format!("must be between 1 and {MAX_CELLS}, got {n}"),
                );
            }
        }
        if let Some(d) = self.depth {
            if !(d.is_finite() && d > 0.0) {
                return bad(
                    "depth",
                    format!("must be a positive length in metres, got {d}"),
                );
            }
        }
        Ok(())
    }
}

/// Why a lattice could not be built.
#[derive(Debug, thiserror::Error)]
pub enum LatticeError {
    /// A settings field is out of range.
    #[error("lattice setting `{field}`: {msg}")]
    Settings {
        /// The offending field.
        field: &'static str,
        /// What is wrong and what is expected.
        msg: String,
    },
    /// The mesh cannot carry a lattice.
    #[error("mesh: {0}")]
    Mesh(String),
    /// The cell size is too small for the mesh.
    #[error("the lattice would have {cells} cells (limit {MAX_CELLS}); increase cell_size or lower target_cells")]
    TooManyCells {
        /// Cells the grid would have.
        cells: usize,
    },
    /// Sparse assembly failed.
    #[error(transparent)]
    Sparse(#[from] SparseError),
}

/// What an element stands for.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub enum ElementKind {
    /// A connected piece of the surface in its cell, with the volume it bounds.
    Surface,
    /// A cell with no surface that lies in the flesh.
    Volume,
}

/// One hexahedral element: a cell of the grid and its own control nodes.
#[derive(Debug, Clone, PartialEq)]
pub struct Element {
    /// Integer cell coordinates (i, j, k); the cell spans origin + cell_size·[i, i+1] × ….
    pub cell: [usize; 3],
    /// Global node indices, local order `a + k·b + k²·c` (k = 3 quadratic, 2 trilinear).
    pub nodes: Vec<usize>,
    /// Surface piece or volume cell.
    pub kind: ElementKind,
}

/// A material point: an element and local coordinates ξ ∈ [0, 1]³ in its cell.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MaterialPoint {
    /// Element index.
    pub element: usize,
    /// Local coordinates (position in the cell / cell size).
    pub xi: [f64; 3],
}

/// A hexahedral lattice with superimposed elements over a triangle mesh.
#[derive(Debug, Clone)]
pub struct Lattice {
    /// Element order.
    pub order: ElementOrder,
    /// Corner of cell (0, 0, 0) (m).
    pub origin: Vector3<f64>,
    /// Cell edge length (m).
    pub cell_size: f64,
    /// Number of cells along x, y, z.
    pub dims: [usize; 3],
    /// Elements (one per connected surface piece per cell, plus flesh volume cells).
    pub elements: Vec<Element>,
    /// Rest positions of the nodes (control points), m.
    pub rest: Vec<Vector3<f64>>,
    /// Grid coordinates of each node (node (i,j,k) sits at origin + h·((i,j,k) + offset),
    /// offset −½ for quadratic, 0 for trilinear).
    pub grid: Vec<[usize; 3]>,
    /// Bone nodes: behind an open surface deeper than the flesh depth (pinned in dynamics).
    pub pinned: Vec<bool>,
    /// The material point of each surface vertex (rest state).
    pub vertex_points: Vec<MaterialPoint>,
    /// Whether the mesh was closed (inside = flesh) or open (flesh = behind, to `depth`).
    pub closed: bool,
    /// Flesh depth used for an open mesh (m).
    pub depth: f64,
    /// Element adjacency used to merge nodes (pairs of elements whose pieces touch across a
    /// cell face), for inspection and tests.
    pub graph: Vec<(usize, usize)>,
}

impl Lattice {
    /// Build the lattice over `mesh` (see the module notes for the rules).
    pub fn build(mesh: &TriMesh, settings: &LatticeSettings) -> Result<Lattice, LatticeError> {
        settings.validate()?;
        build::build(mesh, settings)
    }

    /// Number of nodes (control points).
    pub fn node_count(&self) -> usize {
        self.rest.len()
    }

    /// Rest node positions as a flat `[x0, y0, z0, …]` vector (m).
    pub fn rest_flat(&self) -> Vec<f64> {
        self.rest.iter().flat_map(|p| [p.x, p.y, p.z]).collect()
    }

    /// Corner (m) of the cell of element `e`.
    pub fn cell_origin(&self, e: usize) -> Vector3<f64> {
        let c = self.elements[e].cell;
        self.origin + Vector3::new(c[0] as f64, c[1] as f64, c[2] as f64) * self.cell_size
    }

    /// The material point of element `e` at rest position `p` (m); ξ may leave [0, 1] when
    /// `p` is outside the element's cell.
    pub fn locate_in_element(&self, e: usize, p: &Vector3<f64>) -> MaterialPoint {
        let r = (p - self.cell_origin(e)) / self.cell_size;
        MaterialPoint {
            element: e,
            xi: [r.x, r.y, r.z],
        }
    }

    /// Elements whose cell contains rest position `p` (several where elements are
    /// superimposed, none outside the lattice).
    pub fn elements_at(&self, p: &Vector3<f64>) -> Vec<usize> {
        let r = (p - self.origin) / self.cell_size;
        let c: Vec<i64> = (0..3).map(|d| r[d].floor() as i64).collect();
        self.elements
            .iter()
            .enumerate()
            .filter(|(_, el)| (0..3).all(|d| el.cell[d] as i64 == c[d]))
            .map(|(i, _)| i)
            .collect()
    }

    /// Interpolation weights (node, weight) of a material point; they sum to one.
    pub fn weights(&self, mp: &MaterialPoint) -> Vec<(usize, f64)> {
        let s = shape(self.order, mp.xi);
        let el = &self.elements[mp.element];
        (0..s.n).map(|a| (el.nodes[a], s.val[a])).collect()
    }

    /// Position (m) of a material point when the nodes are at `q` (flat, m).
    pub fn position(&self, q: &[f64], mp: &MaterialPoint) -> Vector3<f64> {
        let mut x = Vector3::zeros();
        for (n, w) in self.weights(mp) {
            x += Vector3::new(q[3 * n], q[3 * n + 1], q[3 * n + 2]) * w;
        }
        x
    }

    /// Positions (m) of all embedded surface vertices for node positions `q` (x = B q).
    pub fn embed(&self, q: &[f64]) -> Vec<Vector3<f64>> {
        self.vertex_points
            .iter()
            .map(|mp| self.position(q, mp))
            .collect()
    }

    /// Triplets (vertex, node, weight) of the embedding matrix B.
    pub fn embedding_triplets(&self) -> Vec<(usize, usize, f64)> {
        let mut t = Vec::with_capacity(self.vertex_points.len() * self.order.nodes_per_element());
        for (v, mp) in self.vertex_points.iter().enumerate() {
            for (n, w) in self.weights(mp) {
                if w != 0.0 {
                    t.push((v, n, w));
                }
            }
        }
        t
    }

    /// The embedding B (vertices × nodes, rows sum to one): x_v = Σ_n B_vn q_n per coordinate.
    pub fn embedding(&self) -> Result<SparseColMat<usize, f64>, LatticeError> {
        Ok(assemble(
            self.vertex_points.len(),
            self.node_count(),
            &self.embedding_triplets(),
        )?)
    }

    /// Number of pinned (bone) nodes.
    pub fn pinned_count(&self) -> usize {
        self.pinned.iter().filter(|&&p| p).count()
    }
}
