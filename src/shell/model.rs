//! The thin shell model: rest mesh, material and precomputed rest quantities; its energy is
//! membrane + hinge bending over flat positions (3n, metres), in joules.

use super::bending::BendingEnergy;
use super::material::ShellMaterial;
use super::membrane::MembraneEnergy;
use crate::math::Energy;
use crate::mesh::topology::Topology;
use crate::mesh::TriMesh;

/// A thin elastic shell (the skin): E(x) = membrane(x) + bending(x) in joules.
#[derive(Debug, Clone)]
pub struct Shell {
    /// Rest (stress-free) mesh, positions in metres.
    pub rest: TriMesh,
    /// Material constants.
    pub material: ShellMaterial,
    /// Edges and hinges of the rest mesh.
    pub topology: Topology,
    /// Stretch and shear part.
    pub membrane: MembraneEnergy,
    /// Hinge bending part.
    pub bending: BendingEnergy,
}

impl Shell {
    /// Build a shell at rest in `rest`. Fails with a message naming the bad material field,
    /// a non-manifold / inconsistently wound edge, or a zero-area triangle.
    pub fn new(rest: TriMesh, material: ShellMaterial) -> anyhow::Result<Self> {
        material.validate()?;
        let topology = Topology::new(&rest)?;
        let membrane = MembraneEnergy::new(&rest, &material)?;
        let bending = BendingEnergy::new(&rest, &topology, &material)?;
        Ok(Self {
            rest,
            material,
            topology,
            membrane,
            bending,
        })
    }

    /// Number of Hessian triplets one evaluation emits (fixed order: membrane, then bending).
    pub fn triplet_count(&self) -> usize {
        self.membrane.triplet_count() + self.bending.triplet_count()
    }
}

impl Energy for Shell {
    fn dofs(&self) -> usize {
        3 * self.rest.positions.len()
    }

    fn eval(
        &self,
        x: &[f64],
        mut grad: Option<&mut [f64]>,
        mut hess: Option<&mut Vec<(usize, usize, f64)>>,
        project_psd: bool,
    ) -> f64 {
        let em = self
            .membrane
            .eval(x, grad.as_deref_mut(), hess.as_deref_mut(), project_psd);
        let eb = self.bending.eval(x, grad, hess, project_psd);
        em + eb
    }
}
