//! Muscles generated from the blend-shape basis (the procedure is in the [`super`] module
//! notes), and a synthetic 52-shape ARKit-named basis for tests and benchmarks.

use super::actuation::{
    actuation_muscle, moved_vertices, ActuationSettings, FittedActuation, Plant,
};
use super::fit::Calibration;
use super::forward::Coupling;
use super::jaw::JawBone;
use super::model::Muscle;
use super::samples::ShapeSamples;
use super::MuscleError;
use crate::fem::Interior;
use crate::io::model::MorphTarget;
use crate::lattice::Lattice;
use crate::math::rng::Lcg;
use crate::math::sparse::{triplets_mul_add, Pattern, SpdSolver};
use crate::math::Energy;
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

type V3 = Vector3<f64>;

/// Settings of muscle generation.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GenerateSettings {
    /// β: weight of the elastic regulariser relative to the data term (dimensionless, > 0).
    pub regulariser: f64,
    /// Smallest element strain (largest offset over the cell size, dimensionless) that makes
    /// a muscle at all.
    pub min_strain: f64,
    /// Nonlinear corrections of each actuation at most.
    pub corrections: usize,
    /// Nonlinear corrections at most of an actuation that holds the skin's force: the load
    /// slows the corrections (the demo's brow raise against the tension-field skin: 5.2 %
    /// from its shape after 4, 4.5 % after 10).
    pub corrections_with_skin: usize,
}

impl Default for GenerateSettings {
    fn default() -> Self {
        Self {
            regulariser: 1e-3,
            min_strain: 1e-5,
            corrections: ActuationSettings::default().corrections,
            corrections_with_skin: 10,
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
        if !(self.min_strain.is_finite() && self.min_strain >= 0.0) {
            return bad(
                "min_strain",
                format!("must be ≥ 0, got {}", self.min_strain),
            );
        }
        if self.corrections > 20 {
            return bad(
                "corrections",
                format!("at most 20, got {}", self.corrections),
            );
        }
        if self.corrections_with_skin > 20 {
            return bad(
                "corrections_with_skin",
                format!("at most 20, got {}", self.corrections_with_skin),
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
    /// For each muscle, how well its actuation makes its shape, and its measured response.
    pub fits: Vec<FittedActuation>,
    /// (shape name, why) of the shapes fitted without the skin's force although it was
    /// given: their fit holding it did not converge or missed the shape beyond the goal.
    pub without_skin: Vec<(String, String)>,
    /// The muscle that turns the jaw's bone (index into `muscles`), when a bone was given
    /// and its shape made a muscle.
    pub bone_muscle: Option<usize>,
}

impl Generated {
    /// Each muscle's measured response at activation 1: the activation fit's J columns.
    pub fn calibration(&self) -> Calibration {
        Calibration {
            responses: self.fits.iter().map(|f| f.response.clone()).collect(),
        }
    }

    /// The jaw's bone `found` for these muscles (with its hinge) and the muscle that turns
    /// it, when its shape made one.
    pub fn jaw<H>(&self, found: Option<(JawBone, H)>) -> Option<((usize, JawBone), H)> {
        self.bone_muscle
            .zip(found)
            .map(|(m, (bone, hinge))| ((m, bone), hinge))
    }
}

/// The shape error a generated muscle is held to (dimensionless): 5 % of the shape's RMS
/// displacement, or 1.2× the lattice's own projection residual when that is larger.
pub fn shape_goal(projection: f64) -> f64 {
    0.05f64.max(1.2 * projection)
}

/// Lattice node displacements (flat, m) fitted to each target (see the module notes, step
/// 1): least squares through the embedding of the `samples` (the vertices, and the
/// subdivided surface between them) with an elastic regulariser, bone nodes fixed (the
/// jaw's `bone`, when given, turned by its shape's full angle for that shape).
pub fn fit_node_displacements(
    lattice: &Lattice,
    interior: &Interior,
    targets: &[MorphTarget],
    samples: &ShapeSamples,
    regulariser: f64,
    bone: Option<&JawBone>,
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
    if samples.of.iter().flatten().any(|&(v, _)| v >= nv) {
        return Err(MuscleError::Input(format!(
            "the shapes' samples are not of this face's {nv} vertices"
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
    let (btb, trace_btb) = samples_gram(lattice, samples);
    let rest = lattice.rest_flat();
    let mut kt = Vec::new();
    interior.eval(&rest, None, Some(&mut kt), false);
    let trace_k: f64 = kt.iter().filter(|t| t.0 == t.1).map(|t| t.2).sum();
    let alpha = regulariser * trace_btb / trace_k.max(1e-300);
    let mut trip: Vec<(usize, usize, f64)> = Vec::with_capacity(kt.len() + 3 * btb.len());
    for &(r, c, v) in &kt {
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
    let embed = samples.embedding(lattice);
    // (α K + BᵀB) y over all dofs: what bone displacements y put on the free rows.
    let system_times = |y: &[f64]| {
        let mut out = vec![0.0; 3 * nn];
        triplets_mul_add(&kt, y, &mut out);
        out.iter_mut().for_each(|v| *v *= alpha);
        for &(a, b, v) in &btb {
            for i in 0..3 {
                out[3 * a + i] += v * y[3 * b + i];
            }
        }
        out
    };
    // One solve per shape, the shapes side by side (each its own right-hand side).
    Ok(targets
        .par_iter()
        .enumerate()
        .map(|(ti, t)| {
            let turned = bone
                .filter(|b| b.shape == ti)
                .map(|b| b.displacement(1.0, nn));
            // Bᵀ Δ over all node dofs, then its free rows.
            let mut pulled = vec![0.0; 3 * nn];
            embed.spread(&samples.displacement(&t.positions), &mut pulled);
            let mut rhs = vec![0.0; n3];
            for (n, &f) in free.iter().enumerate().filter(|(_, &f)| f != usize::MAX) {
                rhs[3 * f..3 * f + 3].copy_from_slice(&pulled[3 * n..3 * n + 3]);
            }
            if let Some(up) = &turned {
                let pull = system_times(up);
                for n in (0..nn).filter(|&n| free[n] != usize::MAX) {
                    for i in 0..3 {
                        rhs[3 * free[n] + i] -= pull[3 * n + i];
                    }
                }
            }
            solver.solve_in_place(&mut rhs);
            let mut u = turned.unwrap_or_else(|| vec![0.0; 3 * nn]);
            for n in 0..nn {
                if free[n] != usize::MAX {
                    u[3 * n..3 * n + 3].copy_from_slice(&rhs[3 * free[n]..3 * free[n] + 3]);
                }
            }
            u
        })
        .collect())
}

/// BᵀB of the `samples`' embedding at node level (node, node, Σ w w), assembled per element,
/// and its trace over the three coordinates (dimensionless).
fn samples_gram(lattice: &Lattice, samples: &ShapeSamples) -> (Vec<(usize, usize, f64)>, f64) {
    let k = lattice.order.nodes_per_element();
    let mut by_elem: Vec<Vec<usize>> = vec![Vec::new(); lattice.elements.len()];
    for (s, mp) in samples.points.iter().enumerate() {
        by_elem[mp.element].push(s);
    }
    let mut btb: Vec<(usize, usize, f64)> = Vec::new();
    let mut trace = 0.0;
    for (e, on) in by_elem.iter().enumerate().filter(|(_, on)| !on.is_empty()) {
        let mut loc = vec![0.0; k * k];
        for &s in on {
            let n = crate::lattice::shape(lattice.order, samples.points[s].xi);
            for a in 0..k {
                for b in 0..k {
                    loc[a * k + b] += n.val[a] * n.val[b];
                }
            }
        }
        let nodes = &lattice.elements[e].nodes;
        for a in 0..k {
            trace += 3.0 * loc[a * k + a];
            for b in 0..k {
                btb.push((nodes[a], nodes[b], loc[a * k + b]));
            }
        }
    }
    (btb, trace)
}

/// The blend shapes muscles are generated from, and where their lattice fit is held.
#[derive(Debug, Clone, Copy)]
pub struct BlendShapes<'a> {
    /// Each shape's vertex displacements (m) on the lattice's embedded surface.
    pub targets: &'a [MorphTarget],
    /// The points each shape's lattice fit is held at ([`ShapeSamples::subdivided`]).
    pub samples: &'a ShapeSamples,
}

/// Generate one actuation muscle per blend shape (see the module notes of [`super`]), fitted
/// in the interior with the pipeline's `coupling` (its tracking) when given.
pub fn generate_muscles(
    lattice: &Lattice,
    interior: &Interior,
    shapes: BlendShapes,
    coupling: Option<&Coupling>,
    settings: &GenerateSettings,
) -> Result<Generated, MuscleError> {
    generate_muscles_with_skin(lattice, interior, shapes, coupling, settings, None, None)
}

/// The skin's force on the lattice nodes (flat, N) when the interior stands at node
/// displacements `u` (flat, m) from rest.
pub type SkinForce<'s> = &'s mut dyn FnMut(&[f64]) -> Result<Vec<f64>, MuscleError>;

/// [`generate_muscles`], with the skin's force at each shape held by the actuation and the
/// jaw's `bone` turned by the muscle of the shape that opens it.
pub fn generate_muscles_with_skin(
    lattice: &Lattice,
    interior: &Interior,
    shapes: BlendShapes,
    coupling: Option<&Coupling>,
    settings: &GenerateSettings,
    skin_force: Option<SkinForce>,
    bone: Option<&JawBone>,
) -> Result<Generated, MuscleError> {
    settings.validate()?;
    let BlendShapes { targets, samples } = shapes;
    let u = fit_node_displacements(
        lattice,
        interior,
        targets,
        samples,
        settings.regulariser,
        bone,
    )?;
    // Only shapes strained enough to make a muscle get a (costly) skin solve.
    let strained = |ut: &[f64]| {
        let strain = ut.iter().fold(0.0f64, |m, v| m.max(v.abs())) / lattice.cell_size;
        !strain.is_nan() && strain > settings.min_strain
    };
    let skin_loads: Vec<Option<Vec<f64>>> = match skin_force {
        Some(f) => u
            .iter()
            .map(|ut| {
                if strained(ut) {
                    f(ut).map(Some)
                } else {
                    Ok(None)
                }
            })
            .collect::<Result<_, _>>()?,
        None => vec![None; u.len()],
    };
    let plant = Plant::new(lattice, interior, coupling)?;
    let fit_settings = ActuationSettings {
        corrections: settings.corrections,
        ..Default::default()
    };
    let mut out = Generated {
        muscles: Vec::new(),
        source: Vec::new(),
        skipped: Vec::new(),
        fits: Vec::new(),
        without_skin: Vec::new(),
        bone_muscle: None,
    };
    // Shapes are fitted in parallel, each with its own equilibrium solver; the results are
    // taken in shape order, so the muscles do not depend on the thread count.
    type Fit = (FittedActuation, Option<String>);
    let fits: Vec<Result<Option<Fit>, MuscleError>> = targets
        .par_iter()
        .zip(&u)
        .zip(&skin_loads)
        .enumerate()
        .map(|(ti, ((t, ut), skin))| {
            if !strained(ut) {
                return Ok(None);
            }
            let delta: Vec<f64> = t.positions.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
            let moved = moved_vertices(&delta, 0.1);
            let turns = bone.filter(|b| b.shape == ti);
            let free = |why: Option<String>| {
                plant
                    .fit(ut, &delta, &moved, &fit_settings, None, turns)
                    .map(|f| Some((f, why)))
            };
            let Some(load) = skin else {
                return free(None);
            };
            let held_settings = ActuationSettings {
                corrections: settings.corrections_with_skin,
                ..fit_settings
            };
            let held = match plant.fit(ut, &delta, &moved, &held_settings, Some(load), turns) {
                Ok(held) => held,
                Err(e) => {
                    return free(Some(format!(
                        "its equilibrium holding the skin's force failed: {e}"
                    )))
                }
            };
            if !held.converged {
                free(Some(
                    "its equilibrium holding the skin's force did not converge".into(),
                ))
            } else if held.shape_error > shape_goal(held.projection) {
                free(Some(format!(
                    "holding the skin's force it missed the shape by {:.1} %",
                    100.0 * held.shape_error
                )))
            } else {
                Ok(Some((held, None)))
            }
        })
        .collect();
    let mut used: Vec<String> = Vec::new();
    for (ti, (t, fit)) in targets.iter().zip(fits).enumerate() {
        match fit? {
            None => out.skipped.push((
                t.name.clone(),
                format!(
                    "its largest lattice displacement is below {:.0e} cells",
                    settings.min_strain
                ),
            )),
            Some((f, _)) if f.elements.is_empty() => out
                .skipped
                .push((t.name.clone(), "no element deforms".into())),
            Some((f, why)) => {
                if let Some(why) = why {
                    out.without_skin.push((t.name.clone(), why));
                }
                let name = unique_name(&t.name, out.source.len(), &mut used);
                out.muscles.push(Muscle {
                    rest_change: f.rest_change.clone(),
                    ..actuation_muscle(&name, &f.elements, &f.offsets)
                });
                if bone.is_some_and(|b| b.shape == ti) {
                    out.bone_muscle = Some(out.muscles.len() - 1);
                }
                out.source.push(ti);
                out.fits.push(f);
            }
        }
    }
    Ok(out)
}

/// The shape's name (or `shape<i>` when blank), with a `#2`, `#3` suffix when already `used`.
fn unique_name(name: &str, i: usize, used: &mut Vec<String>) -> String {
    let base = if name.trim().is_empty() {
        format!("shape{i}")
    } else {
        name.to_string()
    };
    let mut out = base.clone();
    let mut k = 2;
    while used.contains(&out) {
        out = format!("{base}#{k}");
        k += 1;
    }
    used.push(out.clone());
    out
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
