//! The muscle-driven forward model: quasi-static equilibrium of the lattice interior plus the
//! active muscle energy, with bone nodes pinned and no gravity (the blend shapes are
//! displacements from the neutral face, which is the rest state), and its linearised
//! response to activations.
//!
//! With a [`Coupling`] the model is the interior the pipeline runs, as the muscles' fit sees
//! it: the tracking's stiffness Bᵀ k B (any constant stiffness K_c) is added as
//! ½ (q − q₀)ᵀ K_c (q − q₀), and an equilibrium may carry the tracking's pull Bᵀ k (t − B q₀)
//! towards a target t as a load.
//!
//! Equilibrium q(a) minimises E_int(q; d(a)) + Σ_m E_m(q, a_m) + E_c(q) over the free nodes (modified
//! Newton with a sparse Cholesky on the free DOFs, refactorised when the force residual falls
//! by less than half in an iteration; backtracking on the energy). The Hessian is assembled
//! straight into its pattern by the interior's own [`StiffnessMatrix`], as the pipeline's
//! quasi-static Newton assembles it (faster than sorted triplets, the same fit to the last
//! digit). The linear response is
//! ∂q/∂a_m = K⁻¹ f_m with K the Hessian at (q, a) (interior: frozen-rotation stiffness, exact
//! at rest) and f_m the unit force of muscle m ([`super::model::unit_forces`]): one
//! factorisation and one solve per muscle.

use super::blend::ActuationBlend;
use super::model::{full_forces, unit_forces, ActiveEnergy, Muscle};
use super::MuscleError;
use crate::coupling::embedding::Embedding;
use crate::fem::dynamics::StiffnessMatrix;
use crate::fem::Interior;
use crate::math::sparse::{triplets_mul_add, SpdSolver};
use crate::math::Energy;
use crate::solver::SolveStatus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

const NONE: usize = usize::MAX;

/// What the pipeline's interior carries besides its own elasticity and the muscles, for the
/// muscles' fit to see the same interior: a constant stiffness and the tracking.
#[derive(Debug, Clone, Default)]
pub struct Coupling {
    /// K_c: the tracking's Bᵀ k B (N/m, triplets over node dofs, both triangles).
    pub stiffness: Vec<(usize, usize, f64)>,
    /// Tracking stiffness k_v of each embedded surface vertex (N/m, the lattice's vertex
    /// order; empty: no tracking).
    pub tracking: Vec<f64>,
}

impl Coupling {
    /// The tracking's load Bᵀ k d (N, flat over node dofs) for surface displacements `d`
    /// (flat, 3 per vertex, m) of the vertices `embed` places in the lattice.
    pub fn tracking_load(&self, embed: &Embedding, d: &[f64]) -> Vec<f64> {
        let mut f = vec![0.0; 3 * embed.node_count()];
        if self.tracking.is_empty() {
            return f;
        }
        embed.spread_scaled(&self.tracking, d, &mut f);
        f
    }
}

/// Muscles need bone: a lattice without bone (pinned) nodes would be moved rigidly by them.
/// The error says how to give it bone. `pinned` flags each lattice node.
pub fn check_bone(pinned: &[bool]) -> Result<(), MuscleError> {
    if pinned.iter().any(|&p| p) {
        return Ok(());
    }
    Err(MuscleError::Input(
        "the lattice has no bone (pinned) nodes, so muscles would move it rigidly; give the lattice a flesh depth so bone exists behind the face".into(),
    ))
}

/// What an equilibrium solve did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ForwardReport {
    /// Outcome.
    pub status: SolveStatus,
    /// Newton iterations.
    pub iterations: usize,
    /// Hessian factorisations (modified Newton reuses one while it converges fast).
    pub factorisations: usize,
    /// Final ‖∇E‖ on free DOFs (N).
    pub residual: f64,
    /// `residual` over the reference force (the muscle forces, or a cell-scale floor).
    pub relative_residual: f64,
}

/// The lattice interior with muscles: equilibrium solves and linear responses.
pub struct Forward {
    /// Interior elasticity.
    pub interior: Interior,
    /// The muscles acting on it ([`Self::muscles`], [`Self::set_muscles`]).
    muscles: Vec<Muscle>,
    /// How the actuation muscles combine ([`ActuationBlend`]), built on first use.
    blend: std::sync::OnceLock<ActuationBlend>,
    /// The activations the interior's rest state is actuated for (none yet: empty).
    actuated_for: Vec<f64>,
    /// Bone nodes (held at rest).
    pub pinned: Vec<bool>,
    /// Rest node positions (flat, m).
    pub rest: Vec<f64>,
    /// Newton iterations at most per equilibrium solve (default 40).
    pub max_newton: usize,
    /// Relative force tolerance of an equilibrium solve (default 10⁻⁷). Under stress the
    /// interior's Hessian omits the derivative of its element rotations, so Newton converges
    /// linearly there (about 0.6 per iteration at 18 % strain).
    pub tolerance: f64,
    /// The pipeline's tracking, when the model stands for that interior.
    pub coupling: Option<Coupling>,
    /// The jaw's bone and the muscle whose activation turns it (by that fraction of the
    /// jaw shape's angle); other bone nodes stay at rest.
    pub bone: Option<(usize, super::jaw::JawBone)>,
    free: Vec<usize>,
    nfree: usize,
    /// The Hessian's assembly into its sparse pattern (built on the first factorisation).
    stiffness: Option<StiffnessMatrix>,
    solver: SpdSolver,
    /// The factorisation at rest with no activation (for [`Self::solve_at_rest`]).
    rest_factor: Option<SpdSolver>,
}

impl Forward {
    /// A forward model of `interior` (rest positions `rest`, flat m) with `muscles` and
    /// `pinned` bone nodes. Muscles are validated against the element count.
    pub fn new(
        interior: Interior,
        muscles: Vec<Muscle>,
        rest: Vec<f64>,
        pinned: Vec<bool>,
    ) -> Result<Self, MuscleError> {
        let n = interior.nodes;
        if rest.len() != 3 * n || pinned.len() != n {
            return Err(MuscleError::Input(format!(
                "expected {} rest coordinates and {n} pin flags, got {} and {}",
                3 * n,
                rest.len(),
                pinned.len()
            )));
        }
        for m in &muscles {
            m.validate(interior.elements.len())
                .map_err(MuscleError::Input)?;
        }
        check_bone(&pinned)?;
        let mut free = vec![NONE; 3 * n];
        let mut nfree = 0;
        for (node, &p) in pinned.iter().enumerate() {
            if !p {
                for i in 0..3 {
                    free[3 * node + i] = nfree;
                    nfree += 1;
                }
            }
        }
        Ok(Self {
            interior,
            muscles,
            blend: std::sync::OnceLock::new(),
            actuated_for: Vec::new(),
            pinned,
            rest,
            max_newton: 40,
            tolerance: 1e-7,
            coupling: None,
            bone: None,
            free,
            nfree,
            stiffness: None,
            solver: SpdSolver::new(),
            rest_factor: None,
        })
    }

    /// The same model with the pipeline's `coupling` (its tracking) added.
    pub fn with_coupling(mut self, coupling: Coupling) -> Self {
        self.coupling = Some(coupling);
        self.stiffness = None;
        self.rest_factor = None;
        self
    }

    /// The muscles acting on the interior.
    pub fn muscles(&self) -> &[Muscle] {
        &self.muscles
    }

    /// Replace the muscles (validated against the interior's elements).
    pub fn set_muscles(&mut self, muscles: Vec<Muscle>) -> Result<(), MuscleError> {
        for m in &muscles {
            m.validate(self.interior.elements.len())
                .map_err(MuscleError::Input)?;
        }
        self.muscles = muscles;
        self.blend = std::sync::OnceLock::new();
        self.actuated_for.clear();
        Ok(())
    }

    /// How the actuation muscles combine ([`ActuationBlend`], built on first use).
    pub fn blend(&self) -> &ActuationBlend {
        self.blend
            .get_or_init(|| ActuationBlend::new(&self.interior, &self.muscles, &self.rest))
    }

    /// Set the interior's rest state to the actuation at activations `a` (kept when it is
    /// already that).
    fn actuate(&mut self, a: &[f64]) -> Result<(), MuscleError> {
        if self.actuated_for.as_slice() != a {
            let d = self.blend().field(&self.interior, &self.muscles, a);
            self.interior.set_actuation(d)?;
            self.actuated_for = a.to_vec();
        }
        Ok(())
    }

    /// Coupling energy ½ (q − q₀)ᵀ K_c (q − q₀) − (q − q₀)ᵀ f (J), adding its gradient (N)
    /// into `grad` when given; zero without a coupling.
    fn coupling_energy(&self, q: &[f64], load: Option<&[f64]>, grad: Option<&mut [f64]>) -> f64 {
        let du: Vec<f64> = q.iter().zip(&self.rest).map(|(a, b)| a - b).collect();
        let mut kd = vec![0.0; q.len()];
        if let Some(c) = &self.coupling {
            triplets_mul_add(&c.stiffness, &du, &mut kd);
        }
        let mut e = 0.5 * du.iter().zip(&kd).map(|(a, b)| a * b).sum::<f64>();
        if let Some(f) = load {
            e -= du.iter().zip(f).map(|(a, b)| a * b).sum::<f64>();
            kd.iter_mut().zip(f).for_each(|(k, fi)| *k -= fi);
        }
        if let Some(g) = grad {
            g.iter_mut().zip(&kd).for_each(|(gi, k)| *gi += k);
        }
        e
    }

    /// Number of free DOFs.
    pub fn free_dofs(&self) -> usize {
        self.nfree
    }

    fn check_activations(&self, a: &[f64]) -> Result<(), MuscleError> {
        if a.len() != self.muscles.len() {
            return Err(MuscleError::Input(format!(
                "{} activations for {} muscles",
                a.len(),
                self.muscles.len()
            )));
        }
        if a.iter().any(|v| !v.is_finite()) {
            return Err(MuscleError::Input("an activation is not finite".into()));
        }
        Ok(())
    }

    /// Total energy (J) and, when asked, its gradient (N) at node positions `q` (flat, m),
    /// with the interior actuated for `a` and the coupling's `load` (N).
    fn energy(&self, q: &[f64], a: &[f64], load: Option<&[f64]>, grad: Option<&mut [f64]>) -> f64 {
        let act = ActiveEnergy::new(&self.interior, &self.muscles, a);
        match grad {
            Some(g) => {
                g.iter_mut().for_each(|v| *v = 0.0);
                self.interior.eval(q, Some(g), None, false)
                    + act.eval(q, Some(g), None, false)
                    + self.coupling_energy(q, load, Some(g))
            }
            None => {
                self.interior.eval(q, None, None, false)
                    + act.eval(q, None, None, false)
                    + self.coupling_energy(q, load, None)
            }
        }
    }

    fn free_norm(&self, g: &[f64]) -> f64 {
        g.iter()
            .zip(&self.free)
            .filter(|(_, &f)| f != NONE)
            .map(|(v, _)| v * v)
            .sum::<f64>()
            .sqrt()
    }

    /// Assemble and factorise the free-DOF Hessian at (q, a); `project` projects the active
    /// Hessian to positive semi-definite (used when the plain one is not positive definite).
    fn factorise(&mut self, q: &[f64], a: &[f64], project: bool) -> Result<(), MuscleError> {
        self.actuate(a)?;
        let mut active = Vec::new();
        ActiveEnergy::new(&self.interior, &self.muscles, a).eval(
            q,
            None,
            Some(&mut active),
            project,
        );
        let extra: std::borrow::Cow<[(usize, usize, f64)]> = match &self.coupling {
            Some(c) if active.is_empty() => std::borrow::Cow::Borrowed(&c.stiffness),
            Some(c) => {
                active.extend_from_slice(&c.stiffness);
                std::borrow::Cow::Owned(active)
            }
            None => std::borrow::Cow::Owned(active),
        };
        // A tiny diagonal keeps nodes that no element stiffens (none in a valid lattice)
        // from making the matrix singular; it is far below any element stiffness.
        let eps = 1e-12 * self.interior.mu * self.interior.cell_size;
        if !self
            .stiffness
            .as_ref()
            .is_some_and(|k| k.fits(&self.pinned, &extra))
        {
            self.stiffness = Some(StiffnessMatrix::new(&self.interior, &self.pinned, &extra)?);
            self.solver.reset();
        }
        let k = self.stiffness.as_mut().expect("built above");
        let mat = k.assemble(&self.interior, q, project, &extra, eps);
        self.solver.factorize(mat)?;
        Ok(())
    }

    fn factorise_robust(&mut self, q: &[f64], a: &[f64]) -> Result<(), MuscleError> {
        match self.factorise(q, a, false) {
            Ok(()) => Ok(()),
            Err(_) => self.factorise(q, a, true),
        }
    }

    /// Solve K x = b on the free DOFs for a full-length `b` (pinned entries ignored; the
    /// result is zero there). Needs a factorisation.
    fn solve_full(&self, b: &[f64]) -> Vec<f64> {
        self.solve_with(&self.solver, b)
    }

    /// Solve on the free DOFs with `solver`'s factorisation (see [`Self::solve_full`]).
    fn solve_with(&self, solver: &SpdSolver, b: &[f64]) -> Vec<f64> {
        let mut r = vec![0.0; self.nfree];
        for (i, &f) in self.free.iter().enumerate() {
            if f != NONE {
                r[f] = b[i];
            }
        }
        solver.solve_in_place(&mut r);
        let mut out = vec![0.0; b.len()];
        for (i, &f) in self.free.iter().enumerate() {
            if f != NONE {
                out[i] = r[f];
            }
        }
        out
    }

    /// Put the bone nodes of `q` (flat, m) where activations `a` hold them: at rest, the
    /// jaw's turned by its muscle's activation.
    fn place_bone(&self, a: &[f64], q: &mut [f64]) {
        for (n, &p) in self.pinned.iter().enumerate() {
            if p {
                q[3 * n..3 * n + 3].copy_from_slice(&self.rest[3 * n..3 * n + 3]);
            }
        }
        if let Some((m, bone)) = &self.bone {
            bone.place(a.get(*m).copied().unwrap_or(0.0), q);
        }
    }

    /// Equilibrium node positions (flat, m) at activations `a`, by Newton from `q0` (bone
    /// nodes are put where `a` holds them: [`Self::bone`]). Returns the positions and what
    /// the solve did.
    pub fn equilibrium(
        &mut self,
        a: &[f64],
        q0: &[f64],
    ) -> Result<(Vec<f64>, ForwardReport), MuscleError> {
        self.equilibrium_loaded(a, q0, None)
    }

    /// [`Self::equilibrium`] under a constant `load` (N, flat over node dofs): with a
    /// [`Coupling`], the tracking's pull towards the frame's target.
    pub fn equilibrium_loaded(
        &mut self,
        a: &[f64],
        q0: &[f64],
        load: Option<&[f64]>,
    ) -> Result<(Vec<f64>, ForwardReport), MuscleError> {
        self.check_activations(a)?;
        if load.is_some_and(|f| f.len() != self.rest.len()) {
            return Err(MuscleError::Input("the load has the wrong length".into()));
        }
        self.actuate(a)?;
        if q0.len() != self.rest.len() || q0.iter().any(|v| !v.is_finite()) {
            return Err(MuscleError::Input(
                "start positions have the wrong length or a non-finite value".into(),
            ));
        }
        let mut q = q0.to_vec();
        self.place_bone(a, &mut q);
        let forces = full_forces(&self.interior, &self.muscles, &q);
        let mut applied = load.map_or_else(|| vec![0.0; q.len()], <[f64]>::to_vec);
        for (f, &am) in forces.iter().zip(a) {
            applied.iter_mut().zip(f).for_each(|(s, v)| *s += am * v);
        }
        let cell_force = 1e-6 * self.interior.mu * self.interior.cell_size.powi(2);
        let reference = self.free_norm(&applied).max(cell_force);
        let mut g = vec![0.0; q.len()];
        let mut e = self.energy(&q, a, load, Some(&mut g));
        let mut res = self.free_norm(&g);
        let mut report = ForwardReport {
            status: SolveStatus::IterationLimit,
            iterations: 0,
            factorisations: 0,
            residual: res,
            relative_residual: res / reference,
        };
        // Modified Newton: the Hessian (approximate anyway, see `tolerance`) is refactorised
        // only when the residual fell by less than half over the last iteration.
        let mut refactor = true;
        for _ in 0..self.max_newton {
            if res <= self.tolerance * reference {
                report.status = SolveStatus::Converged;
                break;
            }
            if refactor {
                self.factorise_robust(&q, a)?;
                report.factorisations += 1;
            }
            report.iterations += 1;
            let mut dir = self.solve_full(&g);
            dir.iter_mut().for_each(|v| *v = -*v);
            let slope: f64 = dir.iter().zip(&g).map(|(d, gi)| d * gi).sum();
            let mut alpha = 1.0;
            let mut accepted = None;
            let mut trial = q.clone();
            let mut gt = vec![0.0; q.len()];
            for _ in 0..30 {
                for i in 0..q.len() {
                    trial[i] = q[i] + alpha * dir[i];
                }
                let et = self.energy(&trial, a, load, Some(&mut gt));
                let ok = et.is_finite()
                    && (et <= e + 1e-4 * alpha * slope.min(0.0)
                        || (et - e <= 1e-12 * e.abs().max(1e-300) && self.free_norm(&gt) < res));
                if ok {
                    accepted = Some(et);
                    break;
                }
                alpha *= 0.5;
            }
            let Some(et) = accepted else {
                if !refactor {
                    // A stale Hessian gave no descent: refactorise and try again.
                    refactor = true;
                    continue;
                }
                report.status = SolveStatus::Stalled;
                break;
            };
            q.copy_from_slice(&trial);
            g.copy_from_slice(&gt);
            e = et;
            let previous = res;
            res = self.free_norm(&g);
            refactor = res > 0.5 * previous;
            report.residual = res;
            report.relative_residual = res / reference;
        }
        if report.status == SolveStatus::IterationLimit && res <= self.tolerance * reference {
            report.status = SolveStatus::Converged;
        }
        Ok((q, report))
    }

    /// Linear response of the equilibrium at (q, a) to each activation: columns ∂q/∂a_m
    /// (flat over node DOFs, m per unit activation, zero on bone nodes but the jaw's, which
    /// turn with its muscle). One factorisation of the Hessian at (q, a) and one solve per
    /// muscle.
    pub fn response(&mut self, q: &[f64], a: &[f64]) -> Result<Vec<Vec<f64>>, MuscleError> {
        self.check_activations(a)?;
        self.factorise_robust(q, a)?;
        let mut forces = unit_forces(&self.interior, &self.muscles, self.blend(), a, q);
        let turn = self.bone.as_ref().map(|(m, bone)| {
            let dp = bone.velocity(a.get(*m).copied().unwrap_or(0.0), self.interior.nodes);
            (*m, dp)
        });
        if let Some((m, dp)) = &turn {
            // The bone's turn pulls the free nodes by −K dp (a directional difference of the
            // gradient: K is the Hessian the factorisation is of).
            let scale = dp.iter().fold(0.0f64, |s, v| s.max(v.abs())).max(1e-300);
            let h = 1e-6 * self.interior.cell_size / scale;
            let (mut g0, mut g1) = (vec![0.0; q.len()], vec![0.0; q.len()]);
            let moved: Vec<f64> = q.iter().zip(dp).map(|(x, d)| x + h * d).collect();
            self.energy(q, a, None, Some(&mut g0));
            self.energy(&moved, a, None, Some(&mut g1));
            for ((f, a1), a0) in forces[*m].iter_mut().zip(&g1).zip(&g0) {
                *f -= (a1 - a0) / h;
            }
        }
        let mut cols: Vec<Vec<f64>> = forces.par_iter().map(|f| self.solve_full(f)).collect();
        if let Some((m, dp)) = turn {
            cols[m].iter_mut().zip(&dp).for_each(|(c, d)| *c += d);
        }
        Ok(cols)
    }

    /// K⁻¹ b with K the Hessian at rest with no activation (coupling included), for a
    /// full-length `b` (N; pinned entries ignored, the result is zero there; m). The
    /// factorisation is made on the first call and kept.
    pub fn solve_at_rest(&mut self, b: &[f64]) -> Result<Vec<f64>, MuscleError> {
        if self.rest_factor.is_none() {
            let rest = self.rest.clone();
            let zero = vec![0.0; self.muscles.len()];
            self.factorise_robust(&rest, &zero)?;
            self.rest_factor = Some(std::mem::take(&mut self.solver));
        }
        Ok(self.solve_at_rest_factored(b))
    }

    /// [`Self::solve_at_rest`] once the rest factorisation exists (shared, read-only).
    /// Panics before the first [`Self::solve_at_rest`].
    pub fn solve_at_rest_factored(&self, b: &[f64]) -> Vec<f64> {
        let solver = self
            .rest_factor
            .as_ref()
            .expect("solve_at_rest_factored before solve_at_rest");
        self.solve_with(solver, b)
    }
}
