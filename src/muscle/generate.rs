//! Muscles generated from the blend-shape basis (the procedure is in the [`super`] module
//! notes), and a synthetic 52-shape ARKit-named basis for tests and benchmarks.

use super::model::Muscle;
use super::MuscleError;
use crate::fem::Interior;
use crate::io::model::MorphTarget;
use crate::lattice::Lattice;
use crate::math::rng::Lcg;
use crate::math::sparse::{Pattern, SpdSolver};
use crate::math::Energy;
use crate::mesh::TriMesh;
use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;

/// Settings of muscle generation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GenerateSettings {
    /// β: weight of the elastic regulariser relative to the data term (dimensionless, > 0).
    pub regulariser: f64,
    /// Fraction of a shape's largest element compression an element needs to join its
    /// muscle (dimensionless, in (0, 1]).
    pub threshold: f64,
    /// Smallest principal compression (strain, dimensionless) that makes a muscle at all.
    pub min_compression: f64,
}

impl Default for GenerateSettings {
    fn default() -> Self {
        Self {
            regulariser: 1e-3,
            threshold: 0.25,
            min_compression: 1e-5,
        }
    }
}

impl GenerateSettings {
    /// Check the fields; the error names the one that is wrong.
    pub fn validate(&self) -> Result<(), MuscleError> {
        let bad = |field: &'static str, msg: String| Err(MuscleError::Settings { field, msg });
        if !(self.regulariser.is_finite() && self.regulariser > 0.0) {
            return bad(
                "regulariser",
                format!("must be > 0, got {}", self.regulariser),
            );
        }
        if !(self.threshold > 0.0 && self.threshold <= 1.0) {
            return bad(
                "threshold",
                format!("must be in (0, 1], got {}", self.threshold),
            );
        }
        if !(self.min_compression.is_finite() && self.min_compression >= 0.0) {
            return bad(
                "min_compression",
                format!("must be ≥ 0, got {}", self.min_compression),
            );
        }
        Ok(())
    }
}

/// Generated muscles and the shapes that made none.
#[derive(Debug, Clone, PartialEq)]
pub struct Generated {
    /// One muscle per blend shape with compression.
    pub muscles: Vec<Muscle>,
    /// For each muscle, the index of the blend shape it came from.
    pub source: Vec<usize>,
    /// (shape name, reason) of shapes that made no muscle.
    pub skipped: Vec<(String, String)>,
}

/// Lattice node displacements (flat, m) fitted to each target (see the module notes, step
/// 1): least squares through the embedding with an elastic regulariser, bone nodes fixed.
pub fn fit_node_displacements(
    lattice: &Lattice,
    interior: &Interior,
    targets: &[MorphTarget],
    regulariser: f64,
) -> Result<Vec<Vec<f64>>, MuscleError> {
    let nn = lattice.node_count();
    let nv = lattice.vertex_points.len();
    if let Some(t) = targets.iter().find(|t| t.positions.len() != nv) {
        return Err(MuscleError::Input(format!(
            "blend shape '{}' has {} vertices, the face {nv}",
            t.name,
            t.positions.len()
        )));
    }
    let mut free = vec![usize::MAX; nn];
    let mut nfree = 0;
    for (n, &p) in lattice.pinned.iter().enumerate() {
        if !p {
            free[n] = nfree;
            nfree += 1;
        }
    }
    // BᵀB per element (vertices grouped by their element), node level.
    let k = lattice.order.nodes_per_element();
    let mut by_elem: Vec<Vec<usize>> = vec![Vec::new(); lattice.elements.len()];
    for (v, mp) in lattice.vertex_points.iter().enumerate() {
        by_elem[mp.element].push(v);
    }
    let mut btb: Vec<(usize, usize, f64)> = Vec::new();
    let mut trace_btb = 0.0;
    for (e, verts) in by_elem.iter().enumerate() {
        if verts.is_empty() {
            continue;
        }
        let mut loc = vec![0.0; k * k];
        for &v in verts {
            let s = crate::lattice::shape(lattice.order, lattice.vertex_points[v].xi);
            for a in 0..k {
                for b in 0..k {
                    loc[a * k + b] += s.val[a] * s.val[b];
                }
            }
        }
        let nodes = &lattice.elements[e].nodes;
        for a in 0..k {
            trace_btb += 3.0 * loc[a * k + a];
            for b in 0..k {
                btb.push((nodes[a], nodes[b], loc[a * k + b]));
            }
        }
    }
    let rest = lattice.rest_flat();
    let mut kt = Vec::new();
    interior.eval(&rest, None, Some(&mut kt), false);
    let trace_k: f64 = kt.iter().filter(|t| t.0 == t.1).map(|t| t.2).sum();
    let alpha = regulariser * trace_btb / trace_k.max(1e-300);
    let mut trip: Vec<(usize, usize, f64)> = Vec::with_capacity(kt.len() + 3 * btb.len());
    for (r, c, v) in kt {
        let (fr, fc) = (free[r / 3], free[c / 3]);
        if fr != usize::MAX && fc != usize::MAX {
            trip.push((3 * fr + r % 3, 3 * fc + c % 3, alpha * v));
        }
    }
    for &(a, b, v) in &btb {
        let (fa, fb) = (free[a], free[b]);
        if fa != usize::MAX && fb != usize::MAX {
            for i in 0..3 {
                trip.push((3 * fa + i, 3 * fb + i, v));
            }
        }
    }
    let n3 = 3 * nfree;
    let eps = 1e-12 * trace_btb.max(1e-300) / n3.max(1) as f64;
    trip.extend((0..n3).map(|i| (i, i, eps)));
    let pat = Pattern::new(n3, &trip)?;
    let mut solver = SpdSolver::new();
    solver.factorize(&pat.assemble(&trip)?)?;
    let embed = lattice.embedding_triplets();
    Ok(targets
        .iter()
        .map(|t| {
            let mut rhs = vec![0.0; n3];
            for &(v, n, w) in &embed {
                let f = free[n];
                if f != usize::MAX {
                    for i in 0..3 {
                        rhs[3 * f + i] += w * t.positions[v][i];
                    }
                }
            }
            solver.solve_in_place(&mut rhs);
            let mut u = vec![0.0; 3 * nn];
            for n in 0..nn {
                if free[n] != usize::MAX {
                    u[3 * n..3 * n + 3].copy_from_slice(&rhs[3 * free[n]..3 * free[n] + 3]);
                }
            }
            u
        })
        .collect())
}

/// Principal compression (positive strain, dimensionless) and its unit direction of each
/// element for node displacements `u`: the most negative eigenvalue (negated) and its
/// eigenvector of the deviatoric part of the Gauss-point average of ε = sym(F) − I.
pub fn element_compression(interior: &Interior, rest: &[f64], u: &[f64]) -> Vec<(f64, V3)> {
    let x: Vec<f64> = rest.iter().zip(u).map(|(a, b)| a + b).collect();
    (0..interior.elements.len())
        .into_par_iter()
        .map(|e| {
            let fs = interior.deformation_gradients(&x, e);
            let mut eps = Matrix3::zeros();
            let mut wsum = 0.0;
            for (q, f) in interior.qp.iter().zip(&fs) {
                eps += ((f + f.transpose()) * 0.5 - Matrix3::identity()) * q.w;
                wsum += q.w;
            }
            let eps = eps / wsum;
            // Deviatoric part: the active stress is deviatoric, so it can only produce the
            // shape-changing part of the strain.
            let eps = eps - Matrix3::identity() * (eps.trace() / 3.0);
            let eig = SymmetricEigen::new(eps);
            let (i, &l) = eig
                .eigenvalues
                .iter()
                .enumerate()
                .min_by(|a, b| a.1.total_cmp(b.1))
                .expect("three eigenvalues");
            let dir = eig.eigenvectors.column(i).into_owned();
            (-l, dir)
        })
        .collect()
}

/// Generate one muscle per blend shape (see the module notes of [`super`]).
pub fn generate_muscles(
    lattice: &Lattice,
    interior: &Interior,
    targets: &[MorphTarget],
    settings: &GenerateSettings,
) -> Result<Generated, MuscleError> {
    settings.validate()?;
    let u = fit_node_displacements(lattice, interior, targets, settings.regulariser)?;
    let rest = lattice.rest_flat();
    let mut out = Generated {
        muscles: Vec::new(),
        source: Vec::new(),
        skipped: Vec::new(),
    };
    let mut used: Vec<String> = Vec::new();
    for (ti, (t, ut)) in targets.iter().zip(&u).enumerate() {
        let comp = element_compression(interior, &rest, ut);
        let max = comp.iter().map(|c| c.0).fold(0.0f64, f64::max);
        if max.is_nan() || max <= settings.min_compression {
            out.skipped.push((
                t.name.clone(),
                format!(
                    "largest element compression {max:.2e} is below {:.0e}",
                    settings.min_compression
                ),
            ));
            continue;
        }
        let chosen: Vec<usize> = (0..comp.len())
            .filter(|&e| comp[e].0 >= settings.threshold * max)
            .collect();
        let mean = chosen.iter().map(|&e| comp[e].0).sum::<f64>() / chosen.len() as f64;
        let base = if t.name.trim().is_empty() {
            format!("shape{}", out.source.len())
        } else {
            t.name.clone()
        };
        let mut name = base.clone();
        let mut k = 2;
        while used.contains(&name) {
            name = format!("{base}#{k}");
            k += 1;
        }
        used.push(name.clone());
        out.muscles.push(Muscle {
            name,
            fibres: chosen
                .iter()
                .map(|&e| {
                    let d = comp[e].1;
                    [d.x, d.y, d.z]
                })
                .collect(),
            elements: chosen,
            max_contraction: (2.0 * mean).clamp(0.02, 0.6),
            bounds: [0.0, 1.0],
        });
        out.source.push(ti);
    }
    Ok(out)
}

/// The 52 ARKit blend-shape names (one list, kept with the head rig that uses them).
pub use crate::rig::head_shapes::ARKIT_NAMES;

/// 52 synthetic ARKit-named blend shapes on `mesh` (for tests and `furrow bench fit`): each
/// is a smooth Gaussian bump of displacement, `amplitude` metres at its centre, radius
/// `radius` metres, in a random direction, centred at a random vertex: on the +X half of the
/// face for `…Left` names (the subject's left when the face looks along +Z), on the −X half
/// for `…Right`, near the middle otherwise. Deterministic for a given `seed`.
pub fn synthetic_arkit_targets(
    mesh: &TriMesh,
    amplitude: f64,
    radius: f64,
    seed: u64,
) -> Vec<MorphTarget> {
    let mut rng = Lcg::new(seed);
    let (lo, hi) = mesh.bounding_box().unwrap_or((V3::zeros(), V3::zeros()));
    let mid = 0.5 * (lo.x + hi.x);
    let margin = 0.1 * (hi.x - lo.x);
    ARKIT_NAMES
        .iter()
        .map(|&name| {
            let side: Box<dyn Fn(f64) -> bool> = if name.ends_with("Left") {
                Box::new(move |x| x > mid + margin)
            } else if name.ends_with("Right") {
                Box::new(move |x| x < mid - margin)
            } else {
                Box::new(move |x| (x - mid).abs() < margin)
            };
            let cands: Vec<usize> = (0..mesh.vertex_count())
                .filter(|&v| side(mesh.positions[v].x))
                .collect();
            let pick = if cands.is_empty() {
                0
            } else {
                cands[((rng.next_f64() * cands.len() as f64) as usize).min(cands.len() - 1)]
            };
            let c = mesh.positions.get(pick).copied().unwrap_or_default();
            let dir = loop {
                let d = V3::new(
                    2.0 * rng.next_f64() - 1.0,
                    2.0 * rng.next_f64() - 1.0,
                    2.0 * rng.next_f64() - 1.0,
                );
                let n = d.norm();
                if n > 0.1 && n <= 1.0 {
                    break d / n;
                }
            };
            let positions = mesh
                .positions
                .iter()
                .map(|p| {
                    let r2 = (p - c).norm_squared();
                    dir * (amplitude * (-r2 / (2.0 * radius * radius)).exp())
                })
                .collect();
            MorphTarget {
                name: name.to_string(),
                positions,
                normals: None,
            }
        })
        .collect()
}
