//! The embedded thin shell: the skin as a thin shell tied to the lattice only at low spatial
//! frequency, and the two-step solve of DESIGN.md ("The two-step solve").
//!
//! The skin state x (flat, 3n, m) is the equilibrium of the shell energy E_x under the
//! frequency-limited constraints H x = H B q (one row per cluster and coordinate, H the
//! truncated-Gaussian cluster weights of [`Clusters`], B the embedding of the skin vertices
//! in the lattice, q the lattice node positions). The interior then feels the skin through
//! Bᵀ F_x (F_x = −∇E_x at x, N) and Bᵀ K_x B (K_x the element-projected, positive
//! semi-definite shell Hessian at x, N/m), which enter its backward Euler step
//! ([`crate::fem::dynamics::ExtraTerms`]).
//!
//! Bᵀ K_x B is formed column by column over node dofs: for node m and axis a, the column
//! K_x B e_{3m+a} = Σ_{v ∋ m} w_vm K_x e_{3v+a} is accumulated from the compressed K_x (its
//! sparsity pattern built once), then multiplied by Bᵀ row by row; columns are independent
//! and run in parallel. The emitted triplet layout depends only on the patterns of K_x and
//! B, so the interior's sparse pattern and symbolic factorisation are reused frame to frame.

use super::clusters::{ClusterStats, Clusters};
use crate::fem::dynamics::{BackwardEuler, ExtraTerms, SolveReport as StepReport};
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
use rayon::prelude::*;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap};
use std::sync::Mutex;
use std::time::Instant;

/// Largest |Σ_n B_vn − 1| accepted for an embedding row (the rows of B are partitions of
/// unity: interpolation weights of a point in its element).
const ROW_SUM_TOLERANCE: f64 = 1e-6;

/// The skin of an embedded-shell simulation: a thin shell tied to the lattice by
/// H x = H B q, with its own quasi-static solver kept across frames.
pub struct EmbeddedShell {
    /// The shell energy (rest mesh, material, membrane and bending parts).
    pub shell: Shell,
    /// The frequency-limited constraint clusters (H).
    pub clusters: Clusters,
    /// Embedding rows: for each skin vertex, its (node, weight) pairs (weights sum to one).
    rows: Vec<Vec<(usize, f64)>>,
    /// Transposed embedding: for each node, its (vertex, weight) pairs.
    cols: Vec<Vec<(usize, f64)>>,
    /// Vertices grouped by identical embedding node lists (one group per lattice element in
    /// practice): the node list of each group, the group of each vertex, and the start of
    /// each group's block in a flat per-group accumulator (3 × group nodes values).
    group_nodes: Vec<Vec<usize>>,
    group_of: Vec<usize>,
    group_offset: Vec<usize>,
    nodes: usize,
    /// Current skin state (flat, 3n, m).
    x: Vec<f64>,
    solver: StaticSolver,
    problem: StaticProblem,
    /// Pinned skin vertices (they follow B q exactly).
    pinned_vertices: Vec<usize>,
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
/// triangle's thickness (dimensionless): the sheet's last frame before it buckles has 0.03 mm
/// on 1 mm skin, its first buckled frame 1.3 mm.
pub const FLAT_DETAIL: f64 = 0.1;

/// What one two-step frame did: the shell statics report, the interior step report and the
/// time (s) of each stage.
#[derive(Debug, Clone, serde::Serialize)]
pub struct TwoStepReport {
    /// Shell statics (step 1): status, iterations, residual (N), constraint violation (m).
    pub shell: SolveReport,
    /// Interior backward Euler (or quasi-static) solve (step 2).
    pub interior: StepReport,
    /// Wall-clock seconds of the shell statics.
    pub shell_s: f64,
    /// Wall-clock seconds forming Bᵀ K_x B and Bᵀ F_x.
    pub coupling_s: f64,
    /// Wall-clock seconds of the interior solve.
    pub interior_s: f64,
}

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
        let mut rows: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
        let mut cols: Vec<Vec<(usize, f64)>> = vec![Vec::new(); nodes];
        for &(v, node, w) in &embedding {
            if v >= n {
                bail!("embedding entry names skin vertex {v}, but the skin has {n} vertices");
            }
            if node >= nodes {
                bail!(
                    "embedding entry names lattice node {node}, but the lattice has {nodes} nodes"
                );
            }
            if !w.is_finite() {
                bail!("embedding weight of vertex {v} on node {node} is not finite ({w})");
            }
            rows[v].push((node, w));
        }
        for (v, r) in rows.iter_mut().enumerate() {
            if r.is_empty() {
                bail!(
                    "skin vertex {v} is not embedded in the lattice (no embedding weights); \
                     the lattice must cover the whole skin"
                );
            }
            r.sort_by_key(|&(node, _)| node);
            // Merge duplicate nodes.
            let mut merged: Vec<(usize, f64)> = Vec::with_capacity(r.len());
            for &(node, w) in r.iter() {
                match merged.last_mut() {
                    Some(last) if last.0 == node => last.1 += w,
                    _ => merged.push((node, w)),
                }
            }
            *r = merged;
            let s: f64 = r.iter().map(|p| p.1).sum();
            if (s - 1.0).abs() > ROW_SUM_TOLERANCE {
                bail!(
                    "embedding weights of skin vertex {v} sum to {s}, not 1 (interpolation \
                     weights must be a partition of unity)"
                );
            }
            for &(node, w) in r.iter() {
                cols[node].push((v, w));
            }
        }
        let mut group_nodes: Vec<Vec<usize>> = Vec::new();
        let mut group_id: HashMap<Vec<usize>, usize> = HashMap::new();
        let group_of: Vec<usize> = rows
            .iter()
            .map(|r| {
                let key: Vec<usize> = r.iter().map(|p| p.0).collect();
                *group_id.entry(key.clone()).or_insert_with(|| {
                    group_nodes.push(key);
                    group_nodes.len() - 1
                })
            })
            .collect();
        let mut group_offset = Vec::with_capacity(group_nodes.len() + 1);
        let mut off = 0;
        for g in &group_nodes {
            group_offset.push(off);
            off += 3 * g.len();
        }
        group_offset.push(off);
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
            rows,
            cols,
            group_nodes,
            group_of,
            group_offset,
            nodes,
            x,
            solver,
            problem,
            pinned_vertices: Vec::new(),
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
        Ok(())
    }

    /// Number of skin vertices.
    pub fn vertex_count(&self) -> usize {
        self.rows.len()
    }

    /// Number of lattice nodes the skin is embedded in.
    pub fn node_count(&self) -> usize {
        self.nodes
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
        Ok(())
    }

    /// The pinned skin vertices (sorted), which follow B q.
    pub fn pinned(&self) -> &[usize] {
        &self.pinned_vertices
    }

    /// The embedded surface B q (m) for node positions `q` (flat, 3 × nodes, m).
    pub fn embedded_positions(&self, q: &[f64]) -> Vec<Vector3<f64>> {
        self.rows
            .iter()
            .map(|r| {
                r.iter().fold(Vector3::zeros(), |acc, &(node, w)| {
                    acc + w * Vector3::new(q[3 * node], q[3 * node + 1], q[3 * node + 2])
                })
            })
            .collect()
    }

    /// B q flat (3n, m).
    pub fn embedded_flat(&self, q: &[f64]) -> Vec<f64> {
        self.embedded_positions(q)
            .iter()
            .flat_map(|p| [p.x, p.y, p.z])
            .collect()
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
        if q.len() != 3 * self.nodes {
            return Err(SolverError::Problem(format!(
                "lattice state has {} values, expected {} (3 per node)",
                q.len(),
                3 * self.nodes
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
        // afresh, so the inertia test finds the negative curvature (the muscle-driven sheet's
        // frame 2: flat 0.07 mm with the lagged factor, 1.34 mm as the global solver finds).
        if self.last_flat && self.last_bq != bq {
            self.solver.factorise_next_solve();
        }
        let backup = self.x.clone();
        let mut rep = match &from {
            Some((rhs_from, pinned_from)) => self.solver.solve_in_increments(
                &self.shell,
                &self.problem,
                &mut self.x,
                rhs_from,
                pinned_from,
                self.continuation_levels,
                accept,
            )?,
            None => self.solver.solve(&self.shell, &self.problem, &mut self.x)?,
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
    /// equal increments (0, the default, turns this off). On the validation slab with a held,
    /// bent quadratic interior it turned load steps whose line search failed from the first
    /// step into converged ones; on the face demo's two hard frames (13 and 14) it did not
    /// help and tripled their time, so the pipeline leaves it off.
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
        let mut force = vec![0.0; 3 * self.nodes];
        for (v, r) in self.rows.iter().enumerate() {
            for &(node, w) in r {
                for a in 0..3 {
                    force[3 * node + a] -= w * grad[3 * v + a];
                }
            }
        }
        force
    }

    /// The skin's terms for the interior step: (Bᵀ K_x B as triplets over node dofs, both
    /// triangles, N/m; Bᵀ F_x flat over node dofs, N), with K_x the element-projected PSD
    /// shell Hessian and F_x = −∇E_x, both at the current x. The triplet layout is the same
    /// on every call (entries that happen to vanish are kept).
    pub fn coupling_terms(&self) -> (Vec<(usize, usize, f64)>, Vec<f64>) {
        let nd = 3 * self.nodes;
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
        let kr = k.as_ref();
        let nv = self.rows.len();
        // Column (3m + a) of Bᵀ K B, for every node m and axis a, in parallel over m.
        let ng = self.group_nodes.len();
        let gsize = *self.group_offset.last().expect("offsets");
        // Column (3m + a) of Bᵀ K B, for every node m and axis a, in parallel over m:
        // acc = K (B e_{3m+a}) over skin dofs, then Bᵀ acc gathered per vertex group (dense
        // loops over the group's nodes) and scattered once per group.
        let columns: Vec<Vec<(usize, usize, f64)>> = (0..self.nodes)
            .into_par_iter()
            .map_init(
                || {
                    (
                        vec![0.0; 3 * nv],
                        vec![false; 3 * nv],
                        vec![0.0; gsize],
                        vec![false; ng],
                        vec![0.0; nd],
                        vec![false; nd],
                    )
                },
                |(acc, seen, gacc, gseen, out, oseen), m| {
                    let mut col_trip = Vec::new();
                    for a in 0..3 {
                        let mut touched = Vec::new();
                        for &(v, w) in &self.cols[m] {
                            let j = 3 * v + a;
                            for (i, kv) in kr.row_idx_of_col(j).zip(kr.val_of_col(j)) {
                                if !seen[i] {
                                    seen[i] = true;
                                    touched.push(i);
                                }
                                acc[i] += w * kv;
                            }
                        }
                        let mut gtouched = Vec::new();
                        for &i in &touched {
                            let (u, b) = (i / 3, i % 3);
                            let g = self.group_of[u];
                            if !gseen[g] {
                                gseen[g] = true;
                                gtouched.push(g);
                            }
                            let row = &self.rows[u];
                            let base = self.group_offset[g] + b * row.len();
                            let val = acc[i];
                            for (slot, &(_, w)) in gacc[base..base + row.len()].iter_mut().zip(row)
                            {
                                *slot += w * val;
                            }
                            acc[i] = 0.0;
                            seen[i] = false;
                        }
                        let mut otouched = Vec::new();
                        for &g in &gtouched {
                            let gn = &self.group_nodes[g];
                            let base = self.group_offset[g];
                            for b in 0..3 {
                                for (k, &node) in gn.iter().enumerate() {
                                    let r = 3 * node + b;
                                    if !oseen[r] {
                                        oseen[r] = true;
                                        otouched.push(r);
                                    }
                                    let slot = &mut gacc[base + b * gn.len() + k];
                                    out[r] += *slot;
                                    *slot = 0.0;
                                }
                            }
                            gseen[g] = false;
                        }
                        otouched.sort_unstable();
                        for &r in &otouched {
                            col_trip.push((r, 3 * m + a, out[r]));
                            out[r] = 0.0;
                            oseen[r] = false;
                        }
                    }
                    col_trip
                },
            )
            .collect();
        let stiffness = columns.into_iter().flatten().collect();
        (stiffness, force)
    }

    /// The force (flat over node dofs, N) the skin puts on the lattice at node positions `q`
    /// (flat, m) without solving for its wrinkles: Bᵀ F of the membrane relaxed over
    /// wrinkles ([`crate::shell::tension_field`]) at x = B q, each triangle wrinkling at
    /// `wavelength` (m, the thinnest skin's) scaled by its thickness (λ ∝ h, as the
    /// clusters are: [`EmbeddedShell::set_thickness`]). A triangle whose corners are all
    /// pinned sits at B q and cannot wrinkle, so it is not relaxed (N_c = ∞): it carries its
    /// whole compression, as in the solved skin (the lips' pinned ring: the demo's pucker
    /// force 27.2 % from the solved skin's with it relaxed, see the test). Bending is left
    /// out: at B q it is the smooth face's, a small part of the skin's pull.
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

/// How the interior solve of [`two_step_with`] treats time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum InteriorMode {
    /// One backward Euler step of `interior.settings.dt`.
    Dynamic,
    /// Quasi-static equilibrium of the interior with the skin terms (velocities zeroed).
    QuasiStatic,
}

/// One frame of the two-step scheme: shell statics at the interior's current q, then one
/// backward Euler step of the interior with the external node forces `f_ext` (flat, N) and
/// the skin's Bᵀ F_x and Bᵀ K_x B (held fixed within the step).
pub fn two_step(
    interior: &mut BackwardEuler,
    skin: &mut EmbeddedShell,
    f_ext: &[f64],
) -> anyhow::Result<TwoStepReport> {
    two_step_with(interior, skin, f_ext, InteriorMode::Dynamic)
}

/// [`two_step`] with the interior solve chosen by `mode` (quasi-static for validation scenes).
pub fn two_step_with(
    interior: &mut BackwardEuler,
    skin: &mut EmbeddedShell,
    f_ext: &[f64],
    mode: InteriorMode,
) -> anyhow::Result<TwoStepReport> {
    if interior.interior.nodes != skin.nodes {
        bail!(
            "the skin is embedded in {} nodes but the interior has {}",
            skin.nodes,
            interior.interior.nodes
        );
    }
    let t = Instant::now();
    let shell = skin.solve(&interior.q)?;
    let shell_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let (stiffness, force) = skin.coupling_terms();
    let coupling_s = t.elapsed().as_secs_f64();
    let extra = ExtraTerms::new(&stiffness, &force);
    let t = Instant::now();
    let rep = match mode {
        InteriorMode::Dynamic => interior.step(f_ext, Some(&extra))?,
        InteriorMode::QuasiStatic => interior.quasi_static(f_ext, Some(&extra))?,
    };
    let interior_s = t.elapsed().as_secs_f64();
    Ok(TwoStepReport {
        shell,
        interior: rep,
        shell_s,
        coupling_s,
        interior_s,
    })
}

/// J₀(x), the Bessel function of the first kind of order 0, by the midpoint rule on
/// J₀(x) = (1/π) ∫₀^π cos(x sin θ) dθ (spectrally accurate for a periodic integrand; 1e-12
/// for |x| < 20 with 64 points).
fn bessel_j0(x: f64) -> f64 {
    const N: usize = 64;
    (0..N)
        .map(|i| (x * (std::f64::consts::PI * (i as f64 + 0.5) / N as f64).sin()).cos())
        .sum::<f64>()
        / N as f64
}

/// Transfer function (unnormalised) at wavenumber k (1/σ) of the 2D cluster kernel
/// exp(−r²/2σ²) truncated at r = 2σ, with σ = 1: 2π ∫₀² e^{−r²/2} J₀(k r) r dr (midpoint rule).
fn kernel_transfer(k: f64) -> f64 {
    const N: usize = 400;
    let h = 2.0 / N as f64;
    (0..N)
        .map(|i| {
            let r = (i as f64 + 0.5) * h;
            (-0.5 * r * r).exp() * bessel_j0(k * r) * r * h
        })
        .sum::<f64>()
        * 2.0
        * std::f64::consts::PI
}

/// The wavelength (in units of σ) of the first zero of the cluster kernel's transfer
/// function: a plane wave of this length has zero weighted average over every cluster,
/// wherever its centre lies, so the constraints H x = H B q cannot see it at all. For the
/// Gaussian truncated at 2σ (Euclidean distances) it is 2.279 σ (the untruncated Gaussian has
/// no zero; the truncation makes one, shorter than the design cut-off πσ, where the kernel
/// still transmits 0.19 instead of the untruncated e⁻² = 0.135).
pub fn kernel_zero_wavelength() -> f64 {
    // Bracket the first sign change in k σ, then bisect.
    let (mut a, mut b) = (1.0, 1.0);
    let mut fa = kernel_transfer(a);
    while b < 10.0 {
        b = a + 0.05;
        let fb = kernel_transfer(b);
        if fa * fb <= 0.0 {
            break;
        }
        a = b;
        fa = fb;
    }
    for _ in 0..50 {
        let m = 0.5 * (a + b);
        let fm = kernel_transfer(m);
        if fa * fm <= 0.0 {
            b = m;
        } else {
            a = m;
            fa = fm;
        }
    }
    2.0 * std::f64::consts::PI / (0.5 * (a + b))
}

#[derive(PartialEq)]
struct HeapItem(f64, usize);
impl Eq for HeapItem {}
impl PartialOrd for HeapItem {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for HeapItem {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Mean ratio of edge-path (shortest path along mesh edges) to straight-line distance, over
/// vertex pairs between `radius`/2 and `radius` (m) apart along edges, from up to 16 source
/// vertices spread over the mesh. 1 on a straight line; about 1.05–1.10 on an equilateral
/// triangulation (edge paths zig-zag except along the three edge directions). Curvature
/// of the surface lowers it (chords are shorter than geodesics), which is not corrected.
pub fn edge_path_stretch(mesh: &TriMesh, radius: f64) -> f64 {
    let n = mesh.positions.len();
    if n == 0 || !(radius.is_finite() && radius > 0.0) {
        return 1.0;
    }
    let mut adj: Vec<Vec<(usize, f64)>> = vec![Vec::new(); n];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let l = (mesh.positions[a] - mesh.positions[b]).norm();
            adj[a].push((b, l));
            adj[b].push((a, l));
        }
    }
    let (mut sum, mut count) = (0.0, 0usize);
    let sources = 16.min(n);
    for s in 0..sources {
        let src = s * n / sources;
        let mut dist: HashMap<usize, f64> = HashMap::new();
        let mut heap = BinaryHeap::new();
        dist.insert(src, 0.0);
        heap.push(HeapItem(0.0, src));
        while let Some(HeapItem(d, v)) = heap.pop() {
            if d > dist[&v] {
                continue;
            }
            if d >= 0.5 * radius {
                let e = (mesh.positions[v] - mesh.positions[src]).norm();
                if e > 0.0 {
                    sum += d / e;
                    count += 1;
                }
            }
            for &(w, l) in &adj[v] {
                let nd = d + l;
                if nd < radius && nd < *dist.get(&w).unwrap_or(&f64::INFINITY) {
                    dist.insert(w, nd);
                    heap.push(HeapItem(nd, w));
                }
            }
        }
    }
    if count == 0 {
        1.0
    } else {
        sum / count as f64
    }
}

/// The cluster width σ (m) that puts the skin's wrinkles at wavelength `lambda` (m) on
/// `mesh`: σ = s λ / z, z = [`kernel_zero_wavelength`] (2.279) and s the mesh's
/// [`edge_path_stretch`] at the kernel radius 2σ.
///
/// Why not DESIGN.md's σ = λ/π: the shell wrinkles at the longest wave the constraints do
/// not see, and with the truncated kernel that is the first zero of its transfer function,
/// z σ / s, not the Gaussian's nominal cut-off π σ. Measured on the compressed slab with
/// σ = λ/π, λ/π × 1.5 and λ/2 the wrinkles came out at 2.13 σ, 2.01 σ and 2.04 σ, against
/// z/s = 2.279/1.08 = 2.11 σ; with σ = λ/π they were 0.68 λ, a third too short.
pub fn sigma_for_wavelength(mesh: &TriMesh, lambda: f64) -> f64 {
    let z = kernel_zero_wavelength();
    // σ ≈ λ/2, so the kernel radius 2σ ≈ λ.
    let s = edge_path_stretch(mesh, lambda);
    s * lambda / z
}

#[cfg(test)]
mod tests {
    use super::*;

    /// J₀ at known values; the kernel zero is a zero (sign change) and the truncated kernel
    /// transmits ≈ 0.19 at πσ (numbers from an independent quadrature in the notes).
    #[test]
    fn kernel_zero_and_transmission() {
        assert!((bessel_j0(0.0) - 1.0).abs() < 1e-14);
        assert!((bessel_j0(2.404_825_557_695_773)).abs() < 1e-12);
        assert!((bessel_j0(1.0) - 0.765_197_686_557_966_6).abs() < 1e-12);
        let z = kernel_zero_wavelength();
        assert!((z - 2.279).abs() < 2e-3, "{z}");
        let k0 = 2.0 * std::f64::consts::PI / z;
        let t0 = kernel_transfer(0.0);
        assert!(kernel_transfer(0.99 * k0) > 0.0 && kernel_transfer(1.01 * k0) < 0.0);
        let t_pi = kernel_transfer(2.0) / t0;
        assert!((t_pi - 0.1895).abs() < 2e-3, "{t_pi}");
        // Normalisation: 2π ∫₀² e^{−r²/2} r dr = 2π (1 − e⁻²).
        assert!((t0 - 2.0 * std::f64::consts::PI * (1.0 - (-2.0f64).exp())).abs() < 1e-5);
    }

    /// The edge-path stretch lies between 1 and 2/√3 (the worst direction, 30° off the
    /// edges) on an equilateral sheet, and is lower on a one-triangle strip, whose paths run
    /// along the edge direction (only the step between its two rows zig-zags).
    #[test]
    fn edge_path_stretch_of_sheets() {
        let sheet = crate::shell::sheet::equilateral_sheet(60, 60, 1e-3);
        let s = edge_path_stretch(&sheet.mesh, 10e-3);
        assert!(s > 1.0 && s < 2.0 / 3f64.sqrt(), "{s}");
        let strip = crate::shell::sheet::equilateral_sheet(60, 1, 1e-3);
        let s1 = edge_path_stretch(&strip.mesh, 10e-3);
        println!("stretch: sheet {s:.4}, strip {s1:.4}");
        assert!(s1 < 1.05 && s1 < s, "{s1} vs {s}");
    }
}
