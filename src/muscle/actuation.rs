//! Actuation muscles fitted to blend shapes, with the pipeline's interior in the loop.
//!
//! For blend shape m with surface displacements Δ_m and lattice fit u_m (node displacements,
//! [`super::generate::fit_node_displacements`]), the muscle's actuation must make u_m the
//! equilibrium of the interior the pipeline runs: elasticity K_int, and the tracking's
//! stiffness K_t = Bᵀ k B and pull Bᵀ k Δ_m towards the shape ([`Coupling`]). Linearised at
//! rest that asks for the active force f_m = (K_int + K_t) u_m − Bᵀ k Δ_m, which the rest
//! change δ_m = K_int⁻¹ f_m releases: the actuation is the local displacements of δ_m
//! ([`crate::fem::Interior::local_displacements`]). Without tracking δ_m = u_m: a compatible
//! actuation makes the shape whatever the stiffness. The corotational interior is not linear,
//! so the nonlinear equilibrium q* at activation 1 is solved and δ_m corrected by
//! K_int⁻¹ (K_int + K_t) (u_m − (q* − q₀)) until the surface misses the fit by little against
//! the lattice's own projection residual ([`ActuationSettings::tolerance`]).
//!
//! The skin is left out of this fit unless its force at the shape is given. By default the
//! pipeline's muscles hold the skin's pull at the state the interior reaches
//! ([`crate::scene::SkinHold::Reached`]), so the interior they drive is the flesh and
//! tracking this fit sees: demo frames 0–23, miss 2.6 % of the motion and wrinkles 6.2 % from
//! tracking at κ = 1000 per 2λ region. Given ([`Plant::fit`]'s `skin_load`, the pipeline's
//! `muscles.skin_hold = "shapes"`): the skin at the
//! shape's lattice fit pulls on the nodes with a force the actuation must then hold, so the
//! muscle makes its shape against the skin. Measured on the demo's frames 0–23 (`furrow
//! bench muscles`, three coupling passes): without the skin the muscle-driven interior misses
//! the artist's surface by 46 % of its motion (RMS); holding the solved skin's force by 5.8 %,
//! holding the tension-field skin's ([`crate::shell::tension_field`], no solve) by 10.0 %
//! (tracking at κ = 10: 33 %). The skin's rest stiffness Bᵀ K_x B, or its unrelaxed force
//! at the smooth shape, instead overshot (85 % miss): the muscles fought compressions the
//! skin relieves by wrinkling.

use super::forward::{Coupling, Forward};
use super::jaw::JawBone;
use super::model::{Muscle, DEFAULT_MAX_CONTRACTION};
use super::MuscleError;
use crate::coupling::embedding::Embedding;
use crate::fem::Interior;
use crate::lattice::Lattice;
use crate::math::sparse::triplets_mul_add;
use crate::math::Energy;
use crate::solver::SolveStatus;

/// Relative force tolerance of the equilibria an actuation is checked with: far below the
/// fit's own tolerance on the surface.
const EQUILIBRIUM_TOLERANCE: f64 = 1e-6;

/// How actuations are fitted.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ActuationSettings {
    /// Nonlinear corrections at most per shape (0: the linearised actuation only).
    pub corrections: usize,
    /// Corrections stop when the muscle's surface misses the lattice fit (RMS over the moved
    /// vertices) by less than this fraction of the lattice's own projection residual (or of
    /// 2 % of the shape, when the projection is closer): the miss then adds little to the
    /// shape error, √(projection² + miss²) (dimensionless).
    pub tolerance: f64,
    /// Fraction of the shape's largest element offset an element needs to carry the
    /// actuation (dimensionless): smaller offsets are dropped to keep muscles sparse.
    pub coverage: f64,
}

impl Default for ActuationSettings {
    fn default() -> Self {
        Self {
            corrections: 4,
            tolerance: 0.5,
            coverage: 1e-4,
        }
    }
}

/// The interior a shape's actuation is fitted in: the passive lattice (for K_int⁻¹), the
/// pipeline's tracking and the embedding.
pub struct Plant<'a> {
    lattice: &'a Lattice,
    interior: &'a Interior,
    coupling: Coupling,
    passive: Forward,
    /// K_int at rest (triplets over node dofs, N/m).
    k_int: Vec<(usize, usize, f64)>,
    /// The embedding B of the lattice's surface vertices.
    embed: Embedding,
}

/// One shape's fitted actuation and how well it makes the shape.
#[derive(Debug, Clone, PartialEq)]
pub struct FittedActuation {
    /// Elements carrying the actuation (sorted).
    pub elements: Vec<usize>,
    /// Their offsets (3K per element, m).
    pub offsets: Vec<f64>,
    /// The lattice's rest change the offsets are of (node, m), on every node it moves
    /// ([`Muscle::rest_change`]).
    pub rest_change: Vec<(usize, [f64; 3])>,
    /// RMS miss of the muscle's surface at activation 1 against the lattice fit B u_m, over
    /// the moved vertices, relative to the shape's RMS displacement there.
    pub miss: f64,
    /// RMS miss of the muscle's surface at activation 1 against the shape Δ_m itself, over
    /// the moved vertices, relative to the shape's RMS displacement there.
    pub shape_error: f64,
    /// The lattice's own projection residual of the shape, ‖B u_m − Δ_m‖ / ‖Δ_m‖ over the
    /// moved vertices: the floor of `shape_error`.
    pub projection: f64,
    /// The muscle's response at activation 1 (node displacements, flat, m): the equilibrium's
    /// displacement less what the tracking's pull alone makes, K_p⁻¹ Bᵀ k Δ_m. The fit's
    /// J column (a secant: exact at activations 0 and 1).
    pub response: Vec<f64>,
    /// Nonlinear corrections made.
    pub corrections: usize,
    /// Whether the last equilibrium solve converged.
    pub converged: bool,
}

impl<'a> Plant<'a> {
    /// The plant of `interior` on `lattice` (bone nodes pinned) with `coupling` (default: none).
    pub fn new(
        lattice: &'a Lattice,
        interior: &'a Interior,
        coupling: Option<&Coupling>,
    ) -> Result<Self, MuscleError> {
        let rest = lattice.rest_flat();
        let mut passive = Forward::new(
            interior.clone(),
            Vec::new(),
            rest.clone(),
            lattice.pinned.clone(),
        )?;
        passive.solve_at_rest(&vec![0.0; rest.len()])?;
        let mut k_int = Vec::new();
        interior.eval(&rest, None, Some(&mut k_int), false);
        Ok(Self {
            lattice,
            interior,
            coupling: coupling.cloned().unwrap_or_default(),
            passive,
            k_int,
            embed: Embedding::of_lattice(lattice),
        })
    }

    /// K y for the rest stiffness K_int (+ K_c when `coupled`) (N; y in m, flat).
    fn stiffness_times(&self, y: &[f64], coupled: bool) -> Vec<f64> {
        let mut out = vec![0.0; y.len()];
        triplets_mul_add(&self.k_int, y, &mut out);
        if coupled {
            triplets_mul_add(&self.coupling.stiffness, y, &mut out);
        }
        out
    }

    /// Surface displacement B y (flat, 3 per vertex, m) of node displacements `y`.
    fn surface(&self, y: &[f64]) -> Vec<f64> {
        self.embed.positions_flat(y)
    }

    /// Fit the actuation that makes node displacements `u` (the shape's lattice fit, flat, m)
    /// with the tracking pulling towards surface displacements `delta` (flat, m) and, when
    /// given, the skin's force on the nodes at the shape (`skin_load`, flat, N) held as a
    /// constant load; `moved` lists the vertices the miss is measured on. With the jaw's
    /// `bone` (its shape's), u turns the bone nodes by the shape's angle: the actuation's
    /// rest change turns them too (a rigid change of the bone's elements, which costs no
    /// actuation) and the equilibria hold them there. The response (the fitter's J column)
    /// leaves out what the tracking's pull alone makes, not the skin's.
    pub fn fit(
        &self,
        u: &[f64],
        delta: &[f64],
        moved: &[usize],
        settings: &ActuationSettings,
        skin_load: Option<&[f64]>,
        bone: Option<&JawBone>,
    ) -> Result<FittedActuation, MuscleError> {
        let rest = self.lattice.rest_flat();
        let tracking_load = self.coupling.tracking_load(&self.embed, delta);
        let mut load = tracking_load.clone();
        if let Some(s) = skin_load {
            load.iter_mut().zip(s).for_each(|(a, b)| *a += b);
        }
        // The rest change s that makes u the linearised equilibrium, with s = u on the bone
        // nodes: K_int (u − s) + K_t u = load on the free rows.
        let pinned = &self.lattice.pinned;
        let on_bone = |y: &[f64], keep: bool| -> Vec<f64> {
            (0..y.len())
                .map(|i| if pinned[i / 3] == keep { y[i] } else { 0.0 })
                .collect()
        };
        let mut f = self.stiffness_times(&on_bone(u, false), false);
        triplets_mul_add(&self.coupling.stiffness, u, &mut f);
        f.iter_mut().zip(&load).for_each(|(a, b)| *a -= b);
        let mut shift = self.passive.solve_at_rest_factored(&f);
        shift
            .iter_mut()
            .zip(on_bone(u, true))
            .for_each(|(s, b)| *s += b);
        let bu = self.surface(u);
        let norm = rms_over(delta, None, moved).max(1e-300);
        let mut fitted = FittedActuation {
            elements: Vec::new(),
            offsets: Vec::new(),
            rest_change: Vec::new(),
            miss: f64::INFINITY,
            shape_error: f64::INFINITY,
            projection: rms_over(&bu, Some(delta), moved) / norm,
            response: Vec::new(),
            corrections: 0,
            converged: false,
        };
        let mut one = Forward::new(
            self.interior.clone(),
            Vec::new(),
            rest.clone(),
            self.lattice.pinned.clone(),
        )?
        .with_coupling(self.coupling.clone());
        one.tolerance = EQUILIBRIUM_TOLERANCE;
        one.bone = bone.map(|b| (0, b.clone()));
        // Corrections with backtracking: a step that raises the miss (or whose equilibrium
        // fails) is halved from the best state so far.
        let mut best: Option<(FittedActuation, Vec<f64>, Vec<f64>)> = None;
        let mut step = Vec::new();
        for k in 0..=settings.corrections {
            let mut trial = fitted.clone();
            (trial.elements, trial.offsets) = self.offsets(&rest, &shift, settings.coverage);
            if trial.elements.is_empty() {
                return Ok(trial);
            }
            trial.rest_change = Self::rest_change_of(&shift);
            one.set_muscles(vec![actuation_muscle(
                "fit",
                &trial.elements,
                &trial.offsets,
            )])?;
            // Start where the actuation should put the interior: a good actuation makes the
            // first Newton residual small there (from rest it takes ten iterations more).
            let start = best.as_ref().map_or_else(
                || rest.iter().zip(u).map(|(r, d)| r + d).collect(),
                |b| b.2.clone(),
            );
            let (q, rep) = one.equilibrium_loaded(&[1.0], &start, Some(&load))?;
            trial.converged = rep.status == SolveStatus::Converged;
            let miss: Vec<f64> = (0..q.len()).map(|i| rest[i] + u[i] - q[i]).collect();
            let bmiss = self.surface(&miss);
            trial.miss = rms_over(&bmiss, None, moved) / norm;
            let made: Vec<f64> = bu.iter().zip(&bmiss).map(|(a, b)| a - b).collect();
            trial.shape_error = rms_over(&made, Some(delta), moved) / norm;
            trial.corrections = k;
            trial.response = (0..q.len()).map(|i| q[i] - rest[i]).collect();
            let better = trial.converged && best.as_ref().is_none_or(|b| trial.miss < b.0.miss);
            if better {
                let done = trial.miss <= settings.tolerance * trial.projection.max(0.02);
                step = self
                    .passive
                    .solve_at_rest_factored(&self.stiffness_times(&miss, true));
                best = Some((trial, shift.clone(), q));
                if done {
                    break;
                }
            } else if best.is_none() {
                fitted = trial;
                break;
            } else {
                step.iter_mut().for_each(|s| *s *= 0.5);
            }
            let from = &best.as_ref().expect("set above").1;
            shift = from.iter().zip(&step).map(|(a, b)| a + b).collect();
        }
        if let Some((b, _, _)) = best {
            fitted = b;
        }
        let tracked = one.solve_at_rest(&tracking_load)?;
        fitted
            .response
            .iter_mut()
            .zip(&tracked)
            .for_each(|(r, t)| *r -= t);
        Ok(fitted)
    }

    /// Rest change `shift` (flat, m) on every node it moves (sorted by node): the whole
    /// field, so that where muscles' elements meet, each element's rest shape comes from a
    /// smooth change (cut at a muscle's last element, a change that moves nodes far from the
    /// shape rigidly would step there).
    fn rest_change_of(shift: &[f64]) -> Vec<(usize, [f64; 3])> {
        shift
            .chunks_exact(3)
            .enumerate()
            .filter(|(_, s)| s.iter().any(|&v| v != 0.0))
            .map(|(n, s)| (n, [s[0], s[1], s[2]]))
            .collect()
    }

    /// The element offsets of rest change `shift` (flat, m): the elements whose largest
    /// offset reaches `coverage` of the largest, and their offsets.
    fn offsets(&self, rest: &[f64], shift: &[f64], coverage: f64) -> (Vec<usize>, Vec<f64>) {
        let x: Vec<f64> = rest.iter().zip(shift).map(|(a, b)| a + b).collect();
        let all = self.interior.local_displacements(&x);
        let n3 = 3 * self.interior.nodes_per_element();
        let size: Vec<f64> = all
            .chunks_exact(n3)
            .map(|d| d.iter().fold(0.0f64, |m, v| m.max(v.abs())))
            .collect();
        let largest = size.iter().copied().fold(0.0f64, f64::max);
        if !(largest > 0.0 && largest.is_finite()) {
            return (Vec::new(), Vec::new());
        }
        let elements: Vec<usize> = (0..size.len())
            .filter(|&e| size[e] >= coverage * largest)
            .collect();
        let offsets = elements
            .iter()
            .flat_map(|&e| all[e * n3..(e + 1) * n3].iter().copied())
            .collect();
        (elements, offsets)
    }
}

/// An actuation muscle named `name` with `offsets` (3K per element of `elements`, m).
pub fn actuation_muscle(name: &str, elements: &[usize], offsets: &[f64]) -> Muscle {
    Muscle {
        name: name.to_string(),
        elements: elements.to_vec(),
        fibres: Vec::new(),
        max_contraction: DEFAULT_MAX_CONTRACTION,
        bounds: [0.0, 1.0],
        actuation: offsets.to_vec(),
        rest_change: Vec::new(),
    }
}

/// RMS over the vertices `moved` of the difference `a − b` (flat, 3 per vertex; `b` zero when
/// `None`), m.
pub fn rms_over(a: &[f64], b: Option<&[f64]>, moved: &[usize]) -> f64 {
    if moved.is_empty() {
        return 0.0;
    }
    let s: f64 = moved
        .iter()
        .flat_map(|&v| (0..3).map(move |i| 3 * v + i))
        .map(|i| {
            let d = a[i] - b.map_or(0.0, |b| b[i]);
            d * d
        })
        .sum();
    (s / moved.len() as f64).sqrt()
}

/// The vertices surface displacements `delta` (flat, 3 per vertex, m) move by more than
/// `fraction` of the largest.
pub fn moved_vertices(delta: &[f64], fraction: f64) -> Vec<usize> {
    let len: Vec<f64> = delta
        .chunks_exact(3)
        .map(|d| (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt())
        .collect();
    let max = len.iter().copied().fold(0.0f64, f64::max);
    (0..len.len())
        .filter(|&v| max > 0.0 && len[v] > fraction * max)
        .collect()
}
