//! The embedded thin shell: the skin as a thin shell tied to the lattice only at low spatial
//! frequency.
//!
//! The skin state x (flat, 3n, m) is the equilibrium of the shell energy E_x under the
//! frequency-limited constraints H x = H B q (one row per cluster and coordinate, H the
//! truncated-Gaussian cluster weights of [`Clusters`], B the [`Embedding`] of the skin
//! vertices in the lattice, q the lattice node positions). The interior then feels the skin
//! through Bᵀ F_x (F_x = −∇E_x at x, N) and Bᵀ K_x B (K_x the element-projected, positive
//! semi-definite shell Hessian at x, N/m), which enter its backward Euler step
//! ([`crate::fem::dynamics::ExtraTerms`]; the frame's solve is [`super::two_step`]).

use super::clusters::{ClusterStats, Clusters};
use super::embedding::Embedding;
use crate::math::sparse::Pattern;
use crate::math::Energy;
use crate::mesh::TriMesh;
use crate::shell::{Shell, ShellMaterial};
use crate::solver::statics::SolverError;
use crate::solver::{
    LinearConstraints, SolveReport, SolveStatus, StaticProblem, StaticSettings, StaticSolver,
};
use anyhow::{anyhow, bail};
use nalgebra::Vector3;
use std::sync::Mutex;

/// The skin of an embedded-shell simulation: a thin shell tied to the lattice by
/// H x = H B q, with its own quasi-static solver kept across frames.
pub struct EmbeddedShell {
    /// The shell energy (rest mesh, material, membrane and bending parts).
    pub shell: Shell,
    /// The frequency-limited constraint clusters (H).
    pub clusters: Clusters,
    /// The embedding B of the skin vertices (rows sorted by node, weights summing to one).
    embedding: Embedding,
    /// Current skin state (flat, 3n, m).
    x: Vec<f64>,
    solver: StaticSolver,
    problem: StaticProblem,
    /// Pinned skin vertices (they follow B q exactly).
    pinned_vertices: Vec<usize>,
    /// The part of the shell that moves while the pinned vertices are held
    /// ([`Shell::part`]), which the statics solve in place of the whole when the pins hold
    /// more than [`PART_BELOW`] of its elements still.
    part: Option<Shell>,
    /// Pattern of the shell Hessian triplets (built at the first `coupling_terms`).
    hessian_pattern: Mutex<Option<Pattern>>,
    /// Most halvings of the load change when a solve fails (0 = none).
    continuation_levels: usize,
    /// Whether the last solve ended flat (no vertex off B q by [`FLAT_DETAIL`] of the
    /// thinnest skin), and the B q it ended at (flat, m).
    last_flat: bool,
    last_bq: Vec<f64>,
}

/// Largest detail ‖x − B q‖ of a skin counted as flat, as a fraction of its thinnest
/// triangle's thickness (dimensionless): a skin about to buckle stays far below it and a
/// buckled one far above it.
pub const FLAT_DETAIL: f64 = 0.1;

/// The share of the shell's elements (triangles and hinges) below which the statics solve
/// only the part that moves ([`Shell::part`]): a still rig's shape pins most of the face
/// and a part saves most of the assembly and the new layout's analysis, while a clip's few
/// pins leave the whole shell to solve, with its layout kept from frame to frame.
pub const PART_BELOW: f64 = 0.75;

/// The constraints H x = 0 of `clusters` on the skin's dofs: three rows per cluster (x, y, z
/// of its weighted mean position); the right-hand side H B q is filled per frame.
fn cluster_constraints(clusters: &Clusters) -> LinearConstraints {
    let mut entries = Vec::with_capacity(3 * clusters.entries.len());
    for &(c, v, w) in &clusters.entries {
        for a in 0..3 {
            entries.push((3 * c + a, 3 * v + a, w));
        }
    }
    LinearConstraints {
        rows: 3 * clusters.len(),
        entries,
        rhs: vec![0.0; 3 * clusters.len()],
    }
}

impl EmbeddedShell {
    /// A skin at rest in `rest` made of `material`, embedded in a lattice of `nodes` nodes by
    /// the triplets (vertex, node, weight) of B, with constraint clusters of Gaussian width
    /// `sigma` (m; DESIGN.md: σ = λ/π) and quasi-static solver `settings`.
    ///
    /// Fails, naming the problem, on a bad material or mesh, an embedding index out of range,
    /// a vertex without embedding or whose weights do not sum to one, a non-positive σ, or
    /// bad solver settings.
    pub fn new(
        rest: TriMesh,
        material: ShellMaterial,
        embedding: Vec<(usize, usize, f64)>,
        nodes: usize,
        sigma: f64,
        settings: StaticSettings,
    ) -> anyhow::Result<Self> {
        let clusters = |rest: &TriMesh| Clusters::build(rest, sigma);
        Self::build(rest, material, embedding, nodes, clusters, settings)
    }

    /// As [`EmbeddedShell::new`], with the constraint `clusters` given (over this skin's
    /// vertices; e.g. a whole skin's clusters restricted to this part,
    /// [`Clusters::restrict`]). Empty clusters make a shell that is never solved but gives
    /// the interior its stiffness ([`EmbeddedShell::coupling_terms`]).
    pub fn with_clusters(
        rest: TriMesh,
        material: ShellMaterial,
        embedding: Vec<(usize, usize, f64)>,
        nodes: usize,
        clusters: Clusters,
        settings: StaticSettings,
    ) -> anyhow::Result<Self> {
        let given = |rest: &TriMesh| {
            if clusters.vertices == rest.positions.len() {
                Ok(clusters)
            } else {
                Err(format!(
                    "clusters over {} vertices for a skin of {}",
                    clusters.vertices,
                    rest.positions.len()
                ))
            }
        };
        Self::build(rest, material, embedding, nodes, given, settings)
    }

    /// The shell, its embedding checked, with the clusters `clusters` makes for its rest mesh.
    fn build(
        rest: TriMesh,
        material: ShellMaterial,
        embedding: Vec<(usize, usize, f64)>,
        nodes: usize,
        clusters: impl FnOnce(&TriMesh) -> Result<Clusters, String>,
        settings: StaticSettings,
    ) -> anyhow::Result<Self> {
        let n = rest.positions.len();
        if n == 0 {
            bail!("the skin mesh has no vertices");
        }
        if nodes == 0 {
            bail!("the lattice has no nodes to embed the skin in");
        }
        let embedding = Embedding::checked(&embedding, n, nodes)?;
        let solver = StaticSolver::new(settings).map_err(|e| anyhow!("{e}"))?;
        let clusters = clusters(&rest).map_err(|e| anyhow!("clusters: {e}"))?;
        let x: Vec<f64> = rest
            .positions
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect();
        let shell = Shell::new(rest, material)?;
        let problem = StaticProblem {
            pinned: Vec::new(),
            constraints: cluster_constraints(&clusters),
            forces: Vec::new(),
        };
        Ok(Self {
            shell,
            clusters,
            embedding,
            x,
            solver,
            problem,
            pinned_vertices: Vec::new(),
            part: None,
            continuation_levels: 0,
            hessian_pattern: Mutex::new(None),
            last_flat: false,
            last_bq: Vec::new(),
        })
    }

    /// Give the skin a thickness per triangle (`per_face_h`, m; the shell's membrane and
    /// bending stiffness follow it) and widen the clusters where it is thicker: the critical
    /// wavelength grows in proportion to the thickness (λ ∝ h), and so does the cluster width
    /// that places wrinkles at λ, so σ(v) = σ_thin · h(v) / h_min, with σ_thin the width
    /// for the thinnest skin (the one given to [`EmbeddedShell::new`]) and h(v) the mean
    /// thickness of the triangles around vertex v. Call before the first solve.
    pub fn set_thickness(&mut self, per_face_h: Vec<f64>) -> anyhow::Result<()> {
        let rest = self.shell.rest.clone();
        let shell = Shell::with_thickness(rest, self.shell.material, per_face_h)?;
        let h_min = shell.thickness_range().0;
        let n = shell.rest.positions.len();
        let (mut sum, mut count) = (vec![0.0; n], vec![0usize; n]);
        for (t, tri) in shell.rest.triangles.iter().enumerate() {
            for &v in tri {
                sum[v] += shell.thickness[t];
                count[v] += 1;
            }
        }
        let sigma_thin = self.clusters.sigma;
        let widths: Vec<f64> = sum
            .iter()
            .zip(&count)
            .map(|(&h, &c)| {
                if c == 0 {
                    sigma_thin
                } else {
                    sigma_thin * h / (c as f64 * h_min)
                }
            })
            .collect();
        let clusters =
            Clusters::build_varying(&shell.rest, &widths).map_err(|e| anyhow!("clusters: {e}"))?;
        self.problem.constraints = cluster_constraints(&clusters);
        self.clusters = clusters;
        self.shell = shell;
        self.solver.forget_gradient();
        self.update_part();
        Ok(())
    }

    /// Number of skin vertices.
    pub fn vertex_count(&self) -> usize {
        self.embedding.point_count()
    }

    /// Number of lattice nodes the skin is embedded in.
    pub fn node_count(&self) -> usize {
        self.embedding.node_count()
    }

    /// The embedding B of the skin vertices in the lattice.
    pub fn embedding(&self) -> &Embedding {
        &self.embedding
    }

    /// Cluster coverage statistics (clusters, vertices per cluster, clusters per vertex).
    pub fn cluster_stats(&self) -> ClusterStats {
        self.clusters.stats()
    }

    /// The current skin state x (flat, 3n, m).
    pub fn x(&self) -> &[f64] {
        &self.x
    }

    /// Replace the skin state (flat, 3n, m), e.g. to start from a perturbed state.
    pub fn set_x(&mut self, x: &[f64]) -> anyhow::Result<()> {
        if x.len() != self.x.len() {
            bail!(
                "skin state has {} values, expected {} (3 per vertex)",
                x.len(),
                self.x.len()
            );
        }
        if x.iter().any(|v| !v.is_finite()) {
            bail!("skin state contains NaN or infinity");
        }
        self.x.copy_from_slice(x);
        Ok(())
    }

    /// A second skin in the same state (positions, pins, thickness, clusters, settings)
    /// with a solver that has solved nothing yet: from rest, it solves as this one does
    /// after [`Self::reset_to_rest`], to the same bits. A still rig's shapes are solved on
    /// such copies side by side.
    pub fn duplicate(&self) -> anyhow::Result<Self> {
        let solver = StaticSolver::new(self.solver.settings).map_err(|e| anyhow!("{e}"))?;
        Ok(Self {
            shell: self.shell.clone(),
            clusters: self.clusters.clone(),
            embedding: self.embedding.clone(),
            x: self.x.clone(),
            solver,
            problem: self.problem.clone(),
            pinned_vertices: self.pinned_vertices.clone(),
            part: self.part.clone(),
            continuation_levels: self.continuation_levels,
            hessian_pattern: Mutex::new(None),
            last_flat: self.last_flat,
            last_bq: self.last_bq.clone(),
        })
    }

    /// Put the skin back at its rest shape and its solver back to a new one's history (the
    /// sparsity analysis is kept): the next solve is the first from rest.
    pub fn reset_to_rest(&mut self) {
        for (x, p) in self.x.chunks_exact_mut(3).zip(&self.shell.rest.positions) {
            x.copy_from_slice(&[p.x, p.y, p.z]);
        }
        self.solver.forget_solves();
        self.last_flat = false;
        self.last_bq.clear();
    }

    /// Pin skin vertices: they then follow the embedded surface B q exactly (all three
    /// coordinates), e.g. where the skin is glued to bone.
    pub fn set_pinned(&mut self, vertices: &[usize]) -> anyhow::Result<()> {
        if let Some(&v) = vertices.iter().find(|&&v| v >= self.vertex_count()) {
            bail!(
                "pinned skin vertex {v} out of range ({} vertices)",
                self.vertex_count()
            );
        }
        let mut p = vertices.to_vec();
        p.sort_unstable();
        p.dedup();
        self.problem.pinned = p
            .iter()
            .flat_map(|&v| [3 * v, 3 * v + 1, 3 * v + 2])
            .collect();
        self.pinned_vertices = p;
        self.update_part();
        Ok(())
    }

    /// Take the part of the shell the pins leave moving as the statics' energy when it has
    /// fewer than [`PART_BELOW`] of the shell's elements, else the whole shell. The solver
    /// forgets its Hessian layout whenever the energy it solves changes.
    fn update_part(&mut self) {
        let had_part = self.part.is_some();
        self.part = None;
        if !self.pinned_vertices.is_empty() {
            let mut held = vec![false; self.vertex_count()];
            for &v in &self.pinned_vertices {
                held[v] = true;
            }
            let (moving, all) = self.shell.moving_elements(&held);
            if (moving as f64) < PART_BELOW * all as f64 {
                self.part = Some(self.shell.part(&held));
            }
        }
        if had_part || self.part.is_some() {
            self.solver.forget_layout();
        }
    }

    /// The pinned skin vertices (sorted), which follow B q.
    pub fn pinned(&self) -> &[usize] {
        &self.pinned_vertices
    }

    /// The embedded surface B q (m) for node positions `q` (flat, 3 × nodes, m).
    pub fn embedded_positions(&self, q: &[f64]) -> Vec<Vector3<f64>> {
        self.embedding.positions(q)
    }

    /// B q flat (3n, m).
    pub fn embedded_flat(&self, q: &[f64]) -> Vec<f64> {
        self.embedding.positions_flat(q)
    }

    /// Constraint residual max |H x − H B q| (m) of the current state against `q`.
    pub fn constraint_violation(&self, q: &[f64]) -> f64 {
        let bq = self.embedded_flat(q);
        let hx = self.problem.constraints.apply(&self.x);
        let hb = self.problem.constraints.apply(&bq);
        hx.iter()
            .zip(&hb)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }

    fn check_q(&self, q: &[f64]) -> Result<(), SolverError> {
        if q.len() != 3 * self.node_count() {
            return Err(SolverError::Problem(format!(
                "lattice state has {} values, expected {} (3 per node)",
                q.len(),
                3 * self.node_count()
            )));
        }
        if q.iter().any(|v| !v.is_finite()) {
            return Err(SolverError::Problem(
                "lattice state contains NaN or infinity".into(),
            ));
        }
        Ok(())
    }

    /// Shell statics (step 1): from the last x, find the equilibrium of E_x subject to
    /// H x = H B q (3 rows per cluster, one per coordinate; pinned vertices sit at B q).
    /// With [`EmbeddedShell::set_continuation_levels`] above 0, a solve that does not get
    /// there directly is redone with the move from the current cluster means to H B q split
    /// into up to 2^levels equal increments ([`StaticSolver::solve_in_increments`]).
    /// Returns the solver's report; the state is kept only if it stayed finite (otherwise
    /// the previous state is restored and the report's status says `NotFinite`).
    pub fn solve(&mut self, q: &[f64]) -> Result<SolveReport, SolverError> {
        self.solve_accepting(q, &mut |_| true)
    }

    /// [`EmbeddedShell::solve`], with an equilibrium `accept` refuses (given the skin's
    /// positions, flat, m) redone in increments as one that does not converge is
    /// ([`StaticSolver::solve_in_increments`]; only with continuation levels above 0).
    pub fn solve_accepting(
        &mut self,
        q: &[f64],
        accept: &mut dyn FnMut(&[f64]) -> bool,
    ) -> Result<SolveReport, SolverError> {
        self.check_q(q)?;
        let bq = self.embedded_flat(q);
        // Where a continuation would start (only when one may run): the current state's own
        // cluster means and pinned positions.
        let from = (self.continuation_levels > 0).then(|| {
            let rhs: Vec<f64> = self.problem.constraints.apply(&self.x);
            let pinned: Vec<f64> = self.problem.pinned.iter().map(|&d| self.x[d]).collect();
            (rhs, pinned)
        });
        self.problem.constraints.rhs = self.problem.constraints.apply(&bq);
        for &v in &self.pinned_vertices {
            self.x[3 * v..3 * v + 3].copy_from_slice(&bq[3 * v..3 * v + 3]);
        }
        // A flat skin the interior moves may be at its buckling onset, a saddle a lagged
        // factor from the last (stable) frame cannot see: its directions are factorised
        // afresh, so the inertia test finds the negative curvature (a lagged factor would
        // leave such a skin flat where the global solver finds it buckled).
        if self.last_flat && self.last_bq != bq {
            self.solver.factorise_next_solve();
        }
        let backup = self.x.clone();
        let mut rep = match &from {
            Some((rhs_from, pinned_from)) => self.solver.solve_in_increments(
                self.part.as_ref().unwrap_or(&self.shell),
                &self.problem,
                &mut self.x,
                rhs_from,
                pinned_from,
                self.continuation_levels,
                accept,
            )?,
            None => self.solver.solve(
                self.part.as_ref().unwrap_or(&self.shell),
                &self.problem,
                &mut self.x,
            )?,
        };
        if self.x.iter().any(|v| !v.is_finite()) {
            self.x = backup;
            rep.status = SolveStatus::NotFinite;
        }
        let flat = FLAT_DETAIL * self.shell.thickness_range().0;
        self.last_flat = self
            .x
            .chunks_exact(3)
            .zip(bq.chunks_exact(3))
            .all(|(a, b)| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>() <= flat * flat);
        self.last_bq = bq;
        Ok(rep)
    }

    /// [`EmbeddedShell::solve`] with the statics' tolerance `loosening` times its own for
    /// this solve only (an intermediate solve whose force feeds a later, exact one).
    pub fn solve_loosened(
        &mut self,
        q: &[f64],
        loosening: f64,
    ) -> Result<SolveReport, SolverError> {
        self.solve_loosened_accepting(q, loosening, &mut |_| true)
    }

    /// [`EmbeddedShell::solve_loosened`] with an `accept` test of the equilibrium, as
    /// [`EmbeddedShell::solve_accepting`].
    pub fn solve_loosened_accepting(
        &mut self,
        q: &[f64],
        loosening: f64,
        accept: &mut dyn FnMut(&[f64]) -> bool,
    ) -> Result<SolveReport, SolverError> {
        let tolerance = self.tolerance();
        self.set_tolerance(tolerance * loosening);
        let report = self.solve_accepting(q, accept);
        self.set_tolerance(tolerance);
        report
    }

    /// The residual norm of the current state against node positions `q` (N), as the
    /// statics' convergence test sees it, and that test's tolerance (N): the state is an
    /// equilibrium when the first is at most the second.
    pub fn residual(&mut self, q: &[f64]) -> Result<(f64, f64), SolverError> {
        self.check_q(q)?;
        let bq = self.embedded_flat(q);
        let mut p = self.problem.clone();
        p.constraints.rhs = p.constraints.apply(&bq);
        let r = self.solver.residual_norm(&self.shell, &p, &self.x)?;
        Ok((r, self.solver.settings.tolerance))
    }

    /// Let a failed skin solve be redone with its load change split into up to 2^`levels`
    /// equal increments (0, the default, turns this off). The pipeline leaves it off: it
    /// rescues load steps on a held, bent slab but not the face's hard frames, whose time it
    /// triples.
    pub fn set_continuation_levels(&mut self, levels: usize) {
        self.continuation_levels = levels;
    }

    /// The skin's force on the lattice nodes, Bᵀ F_x (flat over node dofs, N), with
    /// F_x = −∇E_x at the current x: the force part of [`Self::coupling_terms`] alone.
    pub fn coupling_force(&self) -> Vec<f64> {
        self.node_force(&self.elastic_gradient())
    }

    /// ∇E_x at the current x (flat, N): the last solve's own evaluation when x is where it
    /// ended (no second pass over the skin), else evaluated.
    pub fn elastic_gradient(&self) -> std::borrow::Cow<'_, [f64]> {
        match self.solver.gradient_at(&self.shell, &self.x) {
            Some(g) => std::borrow::Cow::Borrowed(g),
            None => {
                let mut grad = vec![0.0; self.x.len()];
                self.shell.eval(&self.x, Some(&mut grad), None, false);
                std::borrow::Cow::Owned(grad)
            }
        }
    }

    /// −Bᵀ g over the node dofs (N) of a skin gradient `g` (flat per vertex, N).
    fn node_force(&self, grad: &[f64]) -> Vec<f64> {
        let mut force = vec![0.0; 3 * self.node_count()];
        self.embedding.spread_gradient(grad, &mut force);
        force
    }

    /// The skin's terms for the interior step: (Bᵀ K_x B as triplets over node dofs, both
    /// triangles, N/m; Bᵀ F_x flat over node dofs, N), with K_x the element-projected PSD
    /// shell Hessian and F_x = −∇E_x, both at the current x. The triplet layout is the same
    /// on every call (entries that happen to vanish are kept).
    pub fn coupling_terms(&self) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
        // F_x projected: Bᵀ F_x.
        let mut grad = vec![0.0; self.x.len()];
        let mut trip = Vec::with_capacity(self.shell.triplet_count());
        self.shell
            .eval(&self.x, Some(&mut grad), Some(&mut trip), true);
        let force = self.node_force(&grad);
        // K_x compressed (pattern reused).
        let k = {
            let mut guard = self.hessian_pattern.lock().expect("pattern lock");
            match guard.as_ref().map(|p| p.assemble(&trip)) {
                Some(Ok(k)) => k,
                _ => {
                    let p = Pattern::new(self.x.len(), &trip).expect("shell Hessian pattern");
                    let k = p.assemble(&trip).expect("shell Hessian assembly");
                    *guard = Some(p);
                    k
                }
            }
        };
        let stiffness = self.embedding.project_stiffness(k.as_ref());
        (stiffness, force)
    }

    /// The force (flat over node dofs, N) the skin puts on the lattice at node positions `q`
    /// (flat, m) without solving for its wrinkles: Bᵀ F of the membrane relaxed over
    /// wrinkles ([`crate::shell::tension_field`]) at x = B q, each triangle wrinkling at
    /// `wavelength` (m, the thinnest skin's) scaled by its thickness (λ ∝ h, as the
    /// clusters are: [`EmbeddedShell::set_thickness`]). A triangle whose corners are all
    /// pinned sits at B q and cannot wrinkle, so it is not relaxed (N_c = ∞): it carries its
    /// whole compression, as in the solved skin (relaxing the lips' pinned ring would take
    /// a large share of the pucker force away). Bending is left out: at B q it is the smooth
    /// face's, a small part of the skin's pull.
    pub fn tension_field_force(&self, q: &[f64], wavelength: f64) -> Vec<f64> {
        let material = &self.shell.material;
        let h_min = self.shell.thickness_range().0;
        let pinned = |v: &usize| self.pinned_vertices.binary_search(v).is_ok();
        let critical: Vec<f64> = self
            .shell
            .thickness
            .iter()
            .zip(&self.shell.membrane.elements)
            .map(|(&h, el)| {
                if el.v.iter().all(pinned) {
                    return f64::INFINITY;
                }
                let lambda = wavelength * h / h_min;
                crate::shell::tension_field::critical_force(
                    material.young,
                    material.poisson,
                    h,
                    lambda,
                )
            })
            .collect();
        let x = self.embedded_flat(q);
        let mut grad = vec![0.0; x.len()];
        crate::shell::tension_field::relaxed_energy(
            &self.shell.membrane,
            &critical,
            &x,
            Some(&mut grad),
        );
        self.node_force(&grad)
    }

    /// The statics' convergence tolerance on the residual norm (N).
    pub fn tolerance(&self) -> f64 {
        self.solver.settings.tolerance
    }

    /// Set the statics' convergence tolerance on the residual norm (N).
    pub fn set_tolerance(&mut self, tolerance: f64) {
        self.solver.settings.tolerance = tolerance;
    }

    /// Shell energy E_x (J) at the current state.
    pub fn energy(&self) -> f64 {
        self.shell.eval(&self.x, None, None, false)
    }
}
