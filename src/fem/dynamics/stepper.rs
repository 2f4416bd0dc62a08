//! The backward Euler stepper of the lattice interior: its state (positions, velocities,
//! pins), its mass, and its public steps (a time step, a quasi-static solve, the linear
//! response of the last factorised step), each of which minimises Φ (`newton`).

use super::extra::{extra_signature, triplet_layout_key};
use super::settings::StepSettings;
use super::system::{System, NONE};
use super::{ExtraTerms, M3};
use crate::fem::interior::Interior;
use crate::fem::matfree::ElementOperator;
use crate::fem::FemError;
use crate::math::sparse::SpdSolver;
use crate::solver::SolveStatus;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

/// What a solve did.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct SolveReport {
    /// Outcome.
    pub status: SolveStatus,
    /// Newton iterations (factorisations) performed.
    pub iterations: usize,
    /// Final ‖∇Φ‖ on free DOFs (N).
    pub residual: f64,
    /// `residual` divided by the reference force norm the tolerance applies to.
    pub relative_residual: f64,
    /// Time spent assembling matrices (s).
    pub assembly_s: f64,
    /// Time spent factorising and solving (s).
    pub solve_s: f64,
    /// Conjugate-gradient iterations summed over the Newton iterations (0 for Cholesky).
    pub cg_iterations: usize,
    /// Time spent evaluating the potential and its gradient (s).
    pub energy_s: f64,
    /// Potential evaluations (with or without gradient).
    pub evaluations: usize,
}

/// Node triplets (a, b, value) summed into CSR form (row pointers, columns, values).
fn node_csr(n: usize, mut t: Vec<(usize, usize, f64)>) -> (Vec<usize>, Vec<usize>, Vec<f64>) {
    t.sort_unstable_by_key(|&(a, b, _)| (a, b));
    let mut ptr = vec![0usize; n + 1];
    let mut col: Vec<usize> = Vec::new();
    let mut val: Vec<f64> = Vec::new();
    let mut last = (usize::MAX, usize::MAX);
    for (a, b, v) in t {
        if (a, b) == last {
            *val.last_mut().expect("entry") += v;
        } else {
            col.push(b);
            val.push(v);
            ptr[a + 1] += 1;
            last = (a, b);
        }
    }
    for i in 0..n {
        ptr[i + 1] += ptr[i];
    }
    (ptr, col, val)
}

/// Backward Euler time stepping of the lattice interior (state q, v; see
/// [`crate::fem::dynamics`]).
pub struct BackwardEuler {
    /// The elastic energy and element data.
    pub interior: Interior,
    /// Node positions (flat, m).
    pub q: Vec<f64>,
    /// Node velocities (flat, m/s).
    pub v: Vec<f64>,
    /// Pinned nodes: they keep their position in `q` through a step (velocity zero). To drive
    /// bone (e.g. a jaw), write the pinned nodes' new positions into `q` before `step`.
    /// Changing which nodes are pinned rebuilds the sparse pattern on the next solve.
    pub pinned: Vec<bool>,
    /// Time step, Newton and mass settings.
    pub settings: StepSettings,
    /// Simulated time (s).
    pub time: f64,
    /// Consistent node mass matrix, CSR over nodes (row pointers, columns, kg).
    pub(super) node_mass: (Vec<usize>, Vec<usize>, Vec<f64>),
    pub(super) lumped: Vec<f64>,
    pub(super) system: Option<System>,
    pub(super) solver: SpdSolver,
    /// The (mass, stiffness) coefficients of the Newton matrix `solver` last factorised
    /// (time steps only; `None` when it holds no factor of one).
    pub(super) factor_coefs: Option<(f64, f64)>,
    pub(super) eval_clock: std::cell::Cell<(f64, usize)>,
    /// First Newton direction of the last time step (free DOFs, m), CG's warm start.
    pub(super) last_direction: Option<Vec<f64>>,
    /// CG's matrix-free Newton operator (built on the first CG solve without K_x).
    pub(super) operator: Option<ElementOperator>,
    /// Positions of the last potential evaluation with gradient and its element rotations.
    pub(super) rot_cache: std::cell::RefCell<(Vec<f64>, Vec<M3>)>,
}

impl BackwardEuler {
    /// Put the interior back at rest at positions `q0` (flat, m), with zero velocity at time
    /// zero and no warm start or factor from earlier steps.
    pub fn reset_to_rest(&mut self, q0: &[f64]) {
        self.q.copy_from_slice(q0);
        self.v.iter_mut().for_each(|v| *v = 0.0);
        self.time = 0.0;
        self.last_direction = None;
        self.factor_coefs = None;
    }

    /// A stepper starting at rest at positions `q0` (flat, m) with `pinned` nodes.
    pub fn new(
        interior: Interior,
        q0: Vec<f64>,
        pinned: Vec<bool>,
        settings: StepSettings,
    ) -> Result<Self, FemError> {
        settings.validate()?;
        let n = interior.nodes;
        if q0.len() != 3 * n || pinned.len() != n {
            return Err(FemError::Input(format!(
                "expected {} positions and {n} pin flags, got {} and {}",
                3 * n,
                q0.len(),
                pinned.len()
            )));
        }
        if q0.iter().any(|x| !x.is_finite()) {
            return Err(FemError::Input(
                "initial positions contain a non-finite value".into(),
            ));
        }
        let node_mass = node_csr(n, interior.node_mass(false));
        let lumped = interior.node_masses();
        Ok(Self {
            interior,
            v: vec![0.0; q0.len()],
            q: q0,
            pinned,
            settings,
            time: 0.0,
            node_mass,
            lumped,
            system: None,
            solver: SpdSolver::new(),
            factor_coefs: None,
            eval_clock: std::cell::Cell::new((0.0, 0)),
            last_direction: None,
            operator: None,
            rot_cache: Default::default(),
        })
    }

    /// y ↦ M y (flat node vectors; the consistent mass matrix, or the lumped one when the
    /// settings ask; kg · the unit of y).
    pub fn mass_times(&self, y: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; y.len()];
        if self.settings.lumped_mass {
            for (n, m) in self.lumped.iter().enumerate() {
                for i in 0..3 {
                    out[3 * n + i] = m * y[3 * n + i];
                }
            }
        } else {
            let (ptr, col, val) = &self.node_mass;
            out.par_chunks_mut(3).enumerate().for_each(|(a, o)| {
                for k in ptr[a]..ptr[a + 1] {
                    let (b, m) = (col[k], val[k]);
                    for i in 0..3 {
                        o[i] += m * y[3 * b + i];
                    }
                }
            });
        }
        out
    }

    /// The linear response of `steps` backward Euler steps of the current dt, taken from
    /// the current state, to a constant extra force `df` (flat over node dofs, N) held over
    /// them: the change of the end positions and velocities (flat, m and m/s; zero at pinned
    /// nodes), with the last factorised Newton matrix M + h²(K + K_x) as every step's
    /// tangent: δy_k = A⁻¹ (M (δy_{k−1} + h δv_{k−1}) + h² δf), δv_k = (δy_k − δy_{k−1}) / h.
    /// Exact for a quadratic energy whose matrix the steps share; to first order in `df`
    /// otherwise. K_x is taken about fixed positions: a caller whose [`ExtraTerms`] force
    /// carries the stiffness from each step's start to its anchor (as the pipeline's
    /// coupling does) gets its steps' response. `None` when no Cholesky factor of a time step of this dt is at hand
    /// (conjugate gradients, a quasi-static solve, or no step yet).
    pub fn linear_response(&self, df: &[f64], steps: usize) -> Option<(Vec<f64>, Vec<f64>)> {
        let h = self.settings.dt;
        let (mass_coef, stiff_coef) = self.factor_coefs?;
        let same_dt = mass_coef == 1.0 && (stiff_coef - h * h).abs() <= 1e-12 * h * h;
        let sys = self.system.as_ref()?;
        if !same_dt || df.len() != self.q.len() {
            return None;
        }
        let n = df.len();
        let (mut y, mut v) = (vec![0.0; n], vec![0.0; n]);
        for _ in 0..steps {
            let predicted: Vec<f64> = (0..n).map(|i| y[i] + h * v[i]).collect();
            let m = self.mass_times(&predicted);
            let mut rhs = vec![0.0; 3 * sys.nfree];
            for (node, &f) in sys.free.iter().enumerate() {
                if f != NONE {
                    for i in 0..3 {
                        let d = 3 * node + i;
                        rhs[3 * f + i] = m[d] + h * h * df[d];
                    }
                }
            }
            self.solver.solve_in_place(&mut rhs);
            let mut next = vec![0.0; n];
            for (node, &f) in sys.free.iter().enumerate() {
                if f != NONE {
                    next[3 * node..3 * node + 3].copy_from_slice(&rhs[3 * f..3 * f + 3]);
                }
            }
            for i in 0..n {
                v[i] = (next[i] - y[i]) / h;
            }
            y = next;
        }
        Some((y, v))
    }

    fn ensure_system(&mut self, extra: Option<&ExtraTerms>) -> Result<(), FemError> {
        // The sorted pattern signature costs a sort of every extra triplet; the caller's
        // layout key, or a hash of the triplet layout (O(n), no allocation), tells first
        // whether anything could differ.
        let hash = match extra {
            Some(x) => x.layout.unwrap_or_else(|| triplet_layout_key(x.stiffness)),
            None => triplet_layout_key(&[]),
        };
        if let Some(s) = &self.system {
            if s.extra_hash == hash && s.pins(&self.pinned) {
                return Ok(());
            }
        }
        let sig = extra_signature(extra);
        let rebuild = match &self.system {
            Some(s) => s.extra_sig != sig || !s.pins(&self.pinned),
            None => true,
        };
        if rebuild {
            self.system = Some(System::new(&self.interior, &self.pinned, &sig)?);
            self.solver.reset();
            self.factor_coefs = None;
            self.last_direction = None;
            self.operator = None;
        }
        if let Some(s) = self.system.as_mut() {
            s.extra_hash = hash;
            s.place_extra(extra.map_or(&[], |x| x.stiffness));
        }
        Ok(())
    }

    fn check_inputs(&self, f_ext: &[f64], extra: Option<&ExtraTerms>) -> Result<(), FemError> {
        let n = self.q.len();
        if f_ext.len() != n {
            return Err(FemError::Input(format!(
                "external force has {} entries, expected {n}",
                f_ext.len()
            )));
        }
        if let Some(x) = extra {
            if x.force.len() != n {
                return Err(FemError::Input(format!(
                    "extra force has {} entries, expected {n}",
                    x.force.len()
                )));
            }
            // A caller's layout key vouches for the triplets it has shown before.
            let known =
                x.layout.is_some() && x.layout == self.system.as_ref().map(|s| s.extra_hash);
            if !known
                && x.stiffness
                    .iter()
                    .any(|&(r, c, v)| r >= n || c >= n || !v.is_finite())
            {
                return Err(FemError::Input(
                    "extra stiffness has an index out of range or a non-finite value".into(),
                ));
            }
        }
        if f_ext.iter().any(|f| !f.is_finite()) {
            return Err(FemError::Input(
                "external force contains a non-finite value".into(),
            ));
        }
        Ok(())
    }

    /// One backward Euler step with external node forces `f_ext` (flat, N; surface forces
    /// enter as Bᵀ f) and optional coupling terms. Advances q, v and time even when the
    /// Newton solve did not converge (the report says so).
    pub fn step(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.step_from(f_ext, extra, None)
    }

    /// [`Self::step`] with Newton started at `start` (node positions, flat, m; pinned nodes
    /// keep theirs) instead of the inertial predictor q + h v: a step taken again under a
    /// slightly changed load (a later interior–skin coupling pass) starts where the last
    /// attempt ended. The step's answer is the same; only the iterations to it change.
    pub fn step_from(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
        start: Option<&[f64]>,
    ) -> Result<SolveReport, FemError> {
        self.check_inputs(f_ext, extra)?;
        if let Some(s) = start {
            if s.len() != self.q.len() || s.iter().any(|v| !v.is_finite()) {
                return Err(FemError::Input(
                    "a step's start has the wrong length or a non-finite value".into(),
                ));
            }
        }
        self.ensure_system(extra)?;
        let h = self.settings.dt;
        let x0 = self.q.clone();
        let mut y: Vec<f64> = x0.clone();
        for n in 0..self.interior.nodes {
            if !self.pinned[n] {
                for i in 0..3 {
                    y[3 * n + i] += h * self.v[3 * n + i];
                }
            }
        }
        let target: Vec<f64> = y.clone();
        if let Some(s) = start {
            for n in (0..self.interior.nodes).filter(|&n| !self.pinned[n]) {
                y[3 * n..3 * n + 3].copy_from_slice(&s[3 * n..3 * n + 3]);
            }
        }
        let report = self.minimise(&mut y, &x0, Some((&target, h)), f_ext, extra)?;
        for i in 0..y.len() {
            self.v[i] = (y[i] - x0[i]) / h;
        }
        for n in 0..self.interior.nodes {
            if self.pinned[n] {
                for i in 0..3 {
                    self.v[3 * n + i] = 0.0;
                }
            }
        }
        self.q = y;
        self.time += h;
        Ok(report)
    }

    /// Quasi-static equilibrium from the current q: minimise E(y) − (f_ext + f_g)ᵀ y (+ E_x)
    /// over the free nodes; sets q to the result and v to zero. Needs pinned nodes (or a
    /// positive definite K_x) to remove rigid motions.
    pub fn quasi_static(
        &mut self,
        f_ext: &[f64],
        extra: Option<&ExtraTerms>,
    ) -> Result<SolveReport, FemError> {
        self.check_inputs(f_ext, extra)?;
        self.ensure_system(extra)?;
        let x0 = self.q.clone();
        let mut y = x0.clone();
        let report = self.minimise(&mut y, &x0, None, f_ext, extra)?;
        self.q = y;
        self.v.iter_mut().for_each(|v| *v = 0.0);
        Ok(report)
    }
}
