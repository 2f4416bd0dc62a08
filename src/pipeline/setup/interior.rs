//! The `interior` stage of the set-up: the lattice's elastic solid under backward Euler, and
//! the tracking energy ½ Σ_v k_v ‖t_v − (B q)_v‖² that pulls each welded skin vertex towards
//! its blend-shape target (k_v = κ E_q A_v / ℓ: A_v the vertex area, ℓ the cell size).

use crate::coupling::embedding::Embedding;
use crate::fem::{BackwardEuler, Interior, LinearSolver, StepSettings, GRAVITY};
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::pipeline::plan::{Driver, Plan, DEFAULT_DT};
use crate::pipeline::record::{Stage, StagePlan};
use crate::scene::Scene;

/// Tracking stiffness factor κ (dimensionless): each skin vertex is pulled towards its
/// blend-shape position with stiffness κ E_q A_v / ℓ, ten times what the interior's own cell
/// offers, so the lattice follows the artist's shape to about 10 % of its own error.
pub const TRACKING_STIFFNESS: f64 = 10.0;

/// Tracking stiffness factor κ when muscles drive the interior: a tenth of
/// [`TRACKING_STIFFNESS`], enough to carry motion muscles cannot make (a jaw's rotation about
/// bone) without overriding their shape.
pub const MUSCLE_TRACKING: f64 = 1.0;

/// Interior Newton tolerance: ‖∇Φ‖ relative to the larger of the initial gradient and the
/// applied force (the tracking and skin forces). 1e-4 leaves position errors far below the
/// lattice's own discretisation error; the linearised corotational Hessian converges only
/// linearly, so tighter tolerances cost many iterations for no visible change.
pub const INTERIOR_TOLERANCE: f64 = 1e-4;

/// The tracking energy: a stiffness per welded skin vertex and its constant Hessian Bᵀ k B.
#[derive(Debug, Clone)]
pub struct Tracking {
    /// Stiffness k_v per welded vertex (N/m).
    pub k: Vec<f64>,
    /// Bᵀ k B as triplets over node dofs (N/m), node pairs in ascending order.
    pub stiffness: Vec<(usize, usize, f64)>,
}

/// The backward Euler stepper of the lattice at rest, its bone nodes pinned, with the scene's
/// material, gravity, Newton limit and the plan's sub-step (frame interval / sub-steps).
pub fn stepper(lattice: &Lattice, scene: &Scene, plan: &Plan) -> anyhow::Result<BackwardEuler> {
    let material = scene.interior.material()?;
    let interior = Interior::new(lattice, &material)?;
    let gravity = if scene.dynamics.gravity.unwrap_or(false) {
        [0.0, -GRAVITY, 0.0]
    } else {
        [0.0; 3]
    };
    let mut stepper = BackwardEuler::new(
        interior,
        lattice.rest_flat(),
        lattice.pinned.clone(),
        StepSettings {
            dt: scene.dynamics.dt.unwrap_or(DEFAULT_DT),
            max_newton: scene.solver.interior_iterations.unwrap_or(4),
            tolerance: INTERIOR_TOLERANCE,
            lumped_mass: false,
            gravity,
            linear_solver: LinearSolver::Auto,
            tangent: match scene.solver.interior_tangent.unwrap_or_default() {
                crate::scene::InteriorTangent::Frozen => crate::fem::Tangent::Frozen,
                crate::scene::InteriorTangent::Consistent => crate::fem::Tangent::Consistent,
            },
        },
    )?;
    if plan.dynamics() {
        stepper.settings.dt = 1.0 / plan.fps / plan.substeps as f64;
    }
    Ok(stepper)
}

/// The tracking stiffness factor κ: the scene's `interior.tracking`, else
/// [`TRACKING_STIFFNESS`] when tracking drives and [`MUSCLE_TRACKING`] when muscles do.
pub fn tracking_factor(scene: &Scene, driver: &Driver) -> f64 {
    scene.interior.tracking.unwrap_or(match driver {
        Driver::Tracking => TRACKING_STIFFNESS,
        Driver::Muscles { .. } => MUSCLE_TRACKING,
    })
}

/// The tracking energy of the welded skin `welded` (m) whose vertices are the first points of
/// `embedding`, with factor `kappa` ([`tracking_factor`]), for an interior of Young's modulus
/// `young` (Pa) and cell size `cell` (m).
pub fn tracking(
    welded: &TriMesh,
    embedding: &Embedding,
    kappa: f64,
    young: f64,
    cell: f64,
) -> Tracking {
    let k: Vec<f64> = vertex_areas(welded)
        .iter()
        .map(|a| kappa * young * a / cell)
        .collect();
    // Bᵀ k B summed per node pair once (the same on every step): 27² pairs per vertex would
    // otherwise be re-assembled every step.
    let stiffness = embedding.scalar_stiffness(&k);
    Tracking { k, stiffness }
}

/// The `interior` stage's record: backward Euler and its sub-steps, or quasi-static and why.
pub fn record(plan: &Plan, driver: &Driver, stepper: &BackwardEuler) -> StagePlan {
    let why = if plan.dynamics() {
        let head = match &plan.head_motion {
            Some(m) => {
                let (turn, accel) = m.extent(plan.weights.len(), plan.fps, &stepper.q);
                format!(
                    "; the head's motion ({}: up to {:.1}° from the displayed pose, frame \
                     acceleration up to {accel:.2} m/s² in the flesh) felt as inertial forces",
                    m.motion.animated.join(", "),
                    turn.to_degrees()
                )
            }
            None => String::new(),
        };
        format!(
            "backward Euler, {} step(s) of {:.4} s per frame, driven by {}{head}",
            plan.substeps,
            stepper.settings.dt,
            driver.name()
        )
    } else {
        format!(
            "quasi-static ({}), driven by {}",
            if plan.animated {
                "dynamics disabled by the scene"
            } else {
                "the rig has no animation: no dynamics"
            },
            driver.name()
        )
    };
    StagePlan::ran(Stage::Interior, why, 0.0)
}

/// Lumped vertex areas (one third of each adjacent triangle), m².
pub fn vertex_areas(mesh: &TriMesh) -> Vec<f64> {
    let mut a = vec![0.0; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        let at = mesh.triangle_area(t) / 3.0;
        for &v in tri {
            a[v] += at;
        }
    }
    a
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    #[test]
    fn vertex_areas_share_each_triangle_in_thirds() {
        let m = TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(2.0, 0.0, 0.0),
                Vector3::new(0.0, 3.0, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        assert_eq!(vertex_areas(&m), vec![1.0, 1.0, 1.0]);
    }

    #[test]
    fn tracking_hessian_is_bt_k_b_summed_per_node_pair() {
        let m = TriMesh::new(
            vec![
                Vector3::new(0.0, 0.0, 0.0),
                Vector3::new(2.0, 0.0, 0.0),
                Vector3::new(0.0, 3.0, 0.0),
            ],
            vec![[0, 1, 2]],
        );
        // Vertices 0 and 1 share node 7; vertex 2 sits on node 9.
        let rows = vec![vec![(7, 0.5), (8, 0.5)], vec![(7, 1.0)], vec![(9, 1.0)]];
        let rows = Embedding::from_rows(rows, 10);
        let kappa = tracking_factor(&Scene::default(), &Driver::Tracking);
        let t = tracking(&m, &rows, kappa, 2.0, 4.0);
        // k_v = κ E A / ℓ = 10 · 2 · 1 / 4 = 5 N/m.
        assert_eq!(t.k, vec![5.0; 3]);
        let get = |a: usize, b: usize| {
            t.stiffness
                .iter()
                .filter(|s| s.0 == a && s.1 == b)
                .map(|s| s.2)
                .sum::<f64>()
        };
        // (7,7): 5·0.25 + 5·1 = 6.25; (7,8): 1.25; (9,9): 5; every dof of x, y, z alike.
        assert_eq!(get(21, 21), 6.25);
        assert_eq!(get(23, 23), 6.25);
        assert_eq!(get(21, 24), 1.25);
        assert_eq!(get(27, 27), 5.0);
        assert_eq!(get(21, 27), 0.0);
        let muscles = Driver::Muscles {
            source: crate::scene::MuscleSource::Auto,
        };
        let weak = tracking(
            &m,
            &rows,
            tracking_factor(&Scene::default(), &muscles),
            2.0,
            4.0,
        );
        assert_eq!(weak.k, vec![0.5; 3]);
        let mut scene = Scene::default();
        scene.interior.tracking = Some(0.0);
        assert_eq!(tracking_factor(&scene, &muscles), 0.0);
    }
}
