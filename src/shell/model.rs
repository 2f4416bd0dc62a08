//! The thin shell model: rest mesh, material and precomputed rest quantities; its energy is
//! membrane + hinge bending over flat positions (3n, metres), in joules.

use super::bending::BendingEnergy;
use super::material::ShellMaterial;
use super::membrane::MembraneEnergy;
use super::scatter::pack_symmetric_slots;
use crate::math::Energy;
use crate::mesh::topology::Topology;
use crate::mesh::TriMesh;

/// A thin elastic shell (the skin): E(x) = membrane(x) + bending(x) in joules.
#[derive(Debug, Clone)]
pub struct Shell {
    /// Rest (stress-free) mesh, positions in metres.
    pub rest: TriMesh,
    /// Material constants (its `thickness` is the reference; see `thickness`).
    pub material: ShellMaterial,
    /// Thickness of each rest triangle h_t (m); all equal to `material.thickness` for a
    /// uniform skin.
    pub thickness: Vec<f64>,
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
        let h = vec![material.thickness; rest.triangles.len()];
        Self::with_thickness(rest, material, h)
    }

    /// Build a shell whose triangle t has thickness `per_face_h[t]` (m): membrane stiffness
    /// ∝ h_t per triangle, hinge rigidity the area-weighted mean of h³ of its two triangles
    /// (see [`crate::shell::bending`]). With every value equal to `material.thickness` this is
    /// [`Shell::new`], bit for bit. Fails as `new`, or on a thickness list of the wrong
    /// length or with a value that is not a positive number of metres.
    pub fn with_thickness(
        rest: TriMesh,
        material: ShellMaterial,
        per_face_h: Vec<f64>,
    ) -> anyhow::Result<Self> {
        material.validate()?;
        let topology = Topology::new(&rest)?;
        let membrane = MembraneEnergy::with_thickness(&rest, &material, &per_face_h)?;
        let bending = BendingEnergy::with_thickness(&rest, &topology, &material, &per_face_h)?;
        Ok(Self {
            rest,
            material,
            thickness: per_face_h,
            topology,
            membrane,
            bending,
        })
    }

    /// Thinnest and thickest triangle (m).
    pub fn thickness_range(&self) -> (f64, f64) {
        self.thickness
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &h| {
                (lo.min(h), hi.max(h))
            })
    }

    /// The part of the shell that moves when the vertices `held` marks stay where they are:
    /// its triangles and hinges that touch a vertex not held, over the same dofs, rest mesh
    /// and thickness. Its energy differs from the whole shell's by the elements of held
    /// vertices only, a constant while they are held, so over the free dofs its gradient
    /// and Hessian are the whole shell's: a solve with those vertices pinned needs only the
    /// part (a still rig's shape moves a fraction of the face).
    pub fn part(&self, held: &[bool]) -> Shell {
        let moves = |v: &[usize]| moves(held, v);
        Shell {
            rest: self.rest.clone(),
            material: self.material,
            thickness: self.thickness.clone(),
            topology: self.topology.clone(),
            membrane: self.membrane.part(moves),
            bending: self.bending.part(moves),
        }
    }

    /// The triangles and hinges [`Shell::part`] keeps for `held`, counted without building
    /// the part, and all of them: (moving, all).
    pub fn moving_elements(&self, held: &[bool]) -> (usize, usize) {
        let triangles = self.membrane.elements.iter().filter(|e| moves(held, &e.v));
        let hinges = self.bending.hinges.iter().filter(|h| moves(held, &h.v));
        let all = self.membrane.elements.len() + self.bending.hinges.len();
        (triangles.count() + hinges.count(), all)
    }

    /// Number of Hessian triplets one evaluation emits (fixed order: membrane, then bending).
    pub fn triplet_count(&self) -> usize {
        self.membrane.triplet_count() + self.bending.triplet_count()
    }
}

/// Whether an element of vertices `v` has a vertex `held` does not hold.
fn moves(held: &[bool], v: &[usize]) -> bool {
    v.iter().any(|&i| !held[i])
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

    fn hessian_values(&self, x: &[f64], values: &mut Vec<f64>, project_psd: bool) {
        values.resize(self.triplet_count(), 0.0);
        let (vm, vb) = values.split_at_mut(self.membrane.triplet_count());
        self.membrane.hessian_values_into(x, vm, project_psd);
        self.bending.hessian_values_into(x, vb, project_psd);
    }

    fn triplet_count(&self) -> Option<usize> {
        Some(Shell::triplet_count(self))
    }

    /// The membrane's and the hinges' slots packed to one per pair of an element's dofs
    /// ([`pack_symmetric_slots`]): 45 of 81 per triangle, 78 of 144 per hinge.
    fn pack_slot_map(&self, slot: &[u32]) -> Option<Vec<u32>> {
        let (sm, sb) = slot.split_at_checked(self.membrane.triplet_count())?;
        let mut packed = pack_symmetric_slots(sm, 9)?;
        packed.extend(pack_symmetric_slots(sb, 12)?);
        Some(packed)
    }

    fn hessian_scatter(&self, x: &[f64], slot: &[u32], out: &mut [f64], project_psd: bool) {
        let membrane = if slot.len() == Shell::triplet_count(self) {
            self.membrane.triplet_count()
        } else {
            self.membrane.triplet_count() / 81 * 45
        };
        let (sm, sb) = slot.split_at(membrane);
        self.membrane.hessian_scatter_into(x, sm, out, project_psd);
        self.bending.hessian_scatter_into(x, sb, out, project_psd);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::rng::Lcg;
    use crate::shell::sheet::equilateral_sheet;

    /// A skin of `nx` × `ny` equilateral cells of 1 cm (1 MPa, ν = 0.3, 0.5 mm thick).
    fn sheet_shell(nx: usize, ny: usize) -> Shell {
        let mat = ShellMaterial {
            young: 1e6,
            poisson: 0.3,
            thickness: 5e-4,
        };
        Shell::new(equilateral_sheet(nx, ny, 0.01).mesh, mat).unwrap()
    }

    /// The values-only Hessian must be the values of `eval`'s triplets, in their order,
    /// bit for bit, with and without the PSD projection, on a randomly deformed sheet.
    #[test]
    fn hessian_values_are_the_triplet_values_in_order() {
        let shell = sheet_shell(5, 4);
        let mut rng = Lcg::new(17);
        let x: Vec<f64> = shell
            .rest
            .flat_positions()
            .iter()
            .map(|p| p + 2e-3 * rng.next_signed())
            .collect();
        for project in [false, true] {
            let mut t = Vec::new();
            shell.eval(&x, None, Some(&mut t), project);
            let mut v = vec![1.0; 7];
            shell.hessian_values(&x, &mut v, project);
            assert_eq!(v.len(), t.len());
            assert_eq!(v.len(), shell.triplet_count());
            for (i, (a, b)) in v.iter().zip(&t).enumerate() {
                assert_eq!(a.to_bits(), b.2.to_bits(), "entry {i} (project {project})");
            }
        }
    }

    /// The part of a sheet that moves with a third of its vertices held has the whole
    /// sheet's gradient and Hessian over the free dofs, fewer elements, and an energy that
    /// differs from the whole one's by a constant (the same for two states that differ at
    /// free dofs only).
    #[test]
    fn the_moving_part_has_the_whole_shells_derivatives_at_free_dofs() {
        let shell = sheet_shell(6, 5);
        let n = shell.rest.positions.len();
        let held: Vec<bool> = (0..n).map(|v| v < n / 3).collect();
        let part = shell.part(&held);
        assert!(part.membrane.elements.len() < shell.membrane.elements.len());
        assert!(part.bending.hinges.len() < shell.bending.hinges.len());
        let all = shell.membrane.elements.len() + shell.bending.hinges.len();
        let kept = part.membrane.elements.len() + part.bending.hinges.len();
        assert_eq!(shell.moving_elements(&held), (kept, all));
        let mut rng = Lcg::new(5);
        let deform = |rng: &mut Lcg, free_only: bool, x: &[f64]| -> Vec<f64> {
            x.iter()
                .enumerate()
                .map(|(d, p)| {
                    let moves = !free_only || !held[d / 3];
                    p + if moves { 1e-3 * rng.next_signed() } else { 0.0 }
                })
                .collect()
        };
        let x = deform(&mut rng, false, &shell.rest.flat_positions());
        let y = deform(&mut rng, true, &x);
        let whole = |z: &[f64]| {
            let (mut g, mut h) = (vec![0.0; z.len()], Vec::new());
            (shell.eval(z, Some(&mut g), Some(&mut h), false), g, h)
        };
        let parted = |z: &[f64]| {
            let (mut g, mut h) = (vec![0.0; z.len()], Vec::new());
            (part.eval(z, Some(&mut g), Some(&mut h), false), g, h)
        };
        let ((ex, gx, hx), (px, pgx, phx)) = (whole(&x), parted(&x));
        let ((ey, ..), (py, ..)) = (whole(&y), parted(&y));
        let scale = ex.abs().max(1e-30);
        assert!(
            ((ex - px) - (ey - py)).abs() <= 1e-9 * scale,
            "constant gap"
        );
        let free = |d: usize| !held[d / 3];
        let gmax = gx.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for d in (0..3 * n).filter(|&d| free(d)) {
            assert!((gx[d] - pgx[d]).abs() <= 1e-9 * gmax, "gradient at dof {d}");
        }
        let dense = |t: &[(usize, usize, f64)]| {
            let mut m = std::collections::HashMap::new();
            for &(r, c, v) in t.iter().filter(|e| free(e.0) && free(e.1)) {
                *m.entry((r, c)).or_insert(0.0) += v;
            }
            m
        };
        let (hw, hp) = (dense(&hx), dense(&phx));
        let hmax = hw.values().fold(0.0f64, |m, v| m.max(v.abs()));
        assert_eq!(hw.len(), hp.len());
        for (k, v) in &hw {
            assert!((v - hp[k]).abs() <= 1e-9 * hmax, "Hessian at {k:?}");
        }
    }
}
