//! The stiffness K(x) of an interior over its free DOFs, assembled into the same compressed
//! node-block pattern as the stepper's Newton matrix, for Newton loops outside the stepper.

use super::extra::{node_pairs, triplet_layout_key};
use super::system::{MatrixTerms, System};
use super::M3;
use crate::fem::interior::Interior;
use crate::fem::tangent::RotationCorrection;
use crate::fem::FemError;
use faer::sparse::SparseColMat;
use rayon::prelude::*;

/// The stiffness of an interior over its free DOFs, K(x) = Σ_e (R_e K₀ R_eᵀ + C_e) + K_x
/// (N/m: the element rotations R_e of x, their rotation-derivative corrections C_e, and
/// constant extra triplets K_x), assembled straight into the compressed lower triangle of
/// 3 × 3 node blocks that [`super::BackwardEuler`]'s quasi-static Newton factorises: for
/// other Newton loops over the same interior (the muscles' equilibria), which would otherwise
/// sort 27² × 9 triplets per element into a matrix at every factorisation.
pub struct StiffnessMatrix {
    system: System,
}

impl StiffnessMatrix {
    /// The pattern of `interior`'s elements over the nodes not `pinned`, plus the node pairs
    /// of the `extra` triplets (over DOFs) to be added at each assembly.
    pub fn new(
        interior: &Interior,
        pinned: &[bool],
        extra: &[(usize, usize, f64)],
    ) -> Result<Self, FemError> {
        if pinned.len() != interior.nodes {
            return Err(FemError::Input(format!(
                "{} pin flags for {} nodes",
                pinned.len(),
                interior.nodes
            )));
        }
        let mut system = System::new(interior, pinned, &node_pairs(extra))?;
        system.extra_hash = triplet_layout_key(extra);
        system.place_extra(extra);
        Ok(Self { system })
    }

    /// Whether `extra` triplets fit the layout this matrix was built for (else build anew).
    pub fn fits(&self, pinned: &[bool], extra: &[(usize, usize, f64)]) -> bool {
        self.system.pins(pinned) && self.system.extra_hash == triplet_layout_key(extra)
    }

    /// K(x) at node positions `x` (flat, m) of `interior` with its current actuation, the
    /// stress term of C_e projected to positive semi-definite when `project`, plus `extra`
    /// (the layout given at construction) and `diagonal` (N/m) on every free DOF: the lower
    /// triangle, column-compressed over the free DOFs (3 per free node, in node order).
    pub fn assemble(
        &mut self,
        interior: &Interior,
        x: &[f64],
        project: bool,
        extra: &[(usize, usize, f64)],
        diagonal: f64,
    ) -> &SparseColMat<usize, f64> {
        let rotations: Vec<M3> = (0..interior.elements.len())
            .into_par_iter()
            .map(|e| interior.element_rotation(x, e))
            .collect();
        let corrections: Vec<Option<RotationCorrection>> = (0..interior.elements.len())
            .into_par_iter()
            .map(|e| interior.rotation_correction(x, e, project))
            .collect();
        let terms = MatrixTerms {
            mass_coef: 0.0,
            stiff_coef: 1.0,
            lumped: None,
            extra: Some(extra),
            corrections: &corrections,
        };
        let sys = &mut self.system;
        sys.assemble(interior, &rotations, &terms);
        let vals = sys.mat.val_mut();
        for &c in &sys.colptr[..3 * sys.nfree] {
            vals[c] += diagonal;
        }
        &sys.mat
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fem::bench::cube_lattice;
    use crate::fem::dynamics::twisted;
    use crate::fem::Material;
    use crate::math::Energy;

    /// The stiffness assembled straight into its pattern is the interior's Hessian from
    /// triplets (exact and projected rotation corrections) restricted to the free DOFs, with
    /// the extra triplets and the diagonal added, at a twisted, stretched, actuated state.
    #[test]
    fn stiffness_matrix_equals_the_triplet_hessian() {
        let h = 0.02;
        let lat = cube_lattice(3, h).unwrap();
        let mut int = Interior::new(&lat, &Material::default()).unwrap();
        let n3 = 3 * int.nodes_per_element();
        let offsets: Vec<f64> = (0..n3 * int.elements.len())
            .map(|i| 1e-3 * (((i * 31) % 17) as f64 / 17.0 - 0.5))
            .collect();
        int.set_actuation(offsets).unwrap();
        let pinned: Vec<bool> = lat.rest.iter().map(|p| p.z < 0.5 * h).collect();
        let q = twisted(&lat);
        // Extra triplets coupling two far nodes (outside the element pattern) and a diagonal.
        let last = int.nodes - 1;
        let extra = vec![
            (3 * last, 3 * last, 5.0),
            (3 * last + 1, 3 * (last - 40), -2.0),
            (3 * (last - 40), 3 * last + 1, -2.0),
        ];
        let diagonal = 0.25;
        let mut free = vec![usize::MAX; 3 * int.nodes];
        let mut nfree = 0;
        for (n, _) in pinned.iter().enumerate().filter(|(_, p)| !**p) {
            for i in 0..3 {
                free[3 * n + i] = nfree;
                nfree += 1;
            }
        }
        let mut k = StiffnessMatrix::new(&int, &pinned, &extra).unwrap();
        assert!(k.fits(&pinned, &extra));
        for project in [false, true] {
            let mut trip = Vec::new();
            int.eval(&q, None, Some(&mut trip), project);
            trip.extend_from_slice(&extra);
            let mut want = vec![0.0; nfree * nfree];
            for &(r, c, v) in &trip {
                if free[r] != usize::MAX && free[c] != usize::MAX {
                    want[free[r] * nfree + free[c]] += v;
                }
            }
            (0..nfree).for_each(|i| want[i * nfree + i] += diagonal);
            let mat = k.assemble(&int, &q, project, &extra, diagonal);
            let mut got = vec![0.0; nfree * nfree];
            let (cp, ri, val) = (mat.col_ptr(), mat.row_idx(), mat.val());
            for c in 0..nfree {
                for p in cp[c]..cp[c + 1] {
                    assert!(ri[p] >= c, "lower triangle only");
                    got[ri[p] * nfree + c] += val[p];
                }
            }
            let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            for r in 0..nfree {
                for c in 0..=r {
                    let (g, w) = (got[r * nfree + c], want[r * nfree + c]);
                    assert!(
                        (g - w).abs() <= 1e-12 * scale,
                        "({r}, {c}): {g} against {w}"
                    );
                }
            }
        }
    }
}
