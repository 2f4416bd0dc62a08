//! The cost of the skin–interior coupling terms (`furrow bench coupling`): the interior's
//! view of the skin, its stiffness Bᵀ K_x B and force Bᵀ F_x, on the face rig.

use super::embedded::EmbeddedShell;
use crate::lattice::{Lattice, LatticeSettings};
use crate::math::Energy;
use crate::shell::ShellMaterial;
use crate::solver::StaticSettings;
use std::time::Instant;

/// Wall times (s) on the generated face rig over a lattice of about `cells` cells: building
/// the embedded shell, then `reps` times the projected shell Hessian and gradient, their
/// compressed assembly and the coupling terms (the first builds the Hessian pattern).
pub fn bench_coupling(cells: usize, reps: usize) -> anyhow::Result<serde_json::Value> {
    let rig = crate::rig::face::generate();
    let settings = LatticeSettings {
        target_cells: Some(cells),
        ..Default::default()
    };
    let lattice = Lattice::build(&rig.mesh, &settings)?;
    let material = ShellMaterial {
        young: 1e6,
        poisson: 0.3,
        thickness: 2e-4,
    };
    let t = Instant::now();
    let skin = EmbeddedShell::new(
        rig.mesh.clone(),
        material,
        lattice.embedding_triplets(),
        lattice.node_count(),
        0.004,
        StaticSettings::default(),
    )?;
    let build_s = t.elapsed().as_secs_f64();
    let (mut eval_s, mut assembly_s, mut coupling_s, mut triplets) = (vec![], vec![], vec![], 0);
    for _ in 0..reps {
        let t = Instant::now();
        let mut g = vec![0.0; skin.x().len()];
        let mut h = Vec::new();
        skin.shell.eval(skin.x(), Some(&mut g), Some(&mut h), true);
        eval_s.push(t.elapsed().as_secs_f64());
        let pattern = crate::math::sparse::Pattern::new(g.len(), &h)?;
        let t = Instant::now();
        std::hint::black_box(pattern.assemble(&h)?);
        assembly_s.push(t.elapsed().as_secs_f64());
        let t = Instant::now();
        let (k, _) = skin.coupling_terms();
        coupling_s.push(t.elapsed().as_secs_f64());
        triplets = k.len();
    }
    Ok(serde_json::json!({
        "vertices": rig.mesh.positions.len(), "triangles": rig.mesh.triangles.len(),
        "nodes": lattice.node_count(), "build_s": build_s, "shell_hessian_s": eval_s,
        "assembly_s": assembly_s, "coupling_terms_s": coupling_s, "triplets": triplets,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The benchmark runs on a coarse lattice and its coupling terms are not empty.
    #[test]
    fn bench_coupling_runs_on_a_coarse_lattice() {
        let v = bench_coupling(100, 1).unwrap();
        assert!(v["triplets"].as_u64().unwrap() > 0);
        assert!(v["coupling_terms_s"][0].as_f64().unwrap().is_finite());
    }
}
