//! Frequency-limited constraints: clusters of skin vertices with truncated Gaussian weights.
//!
//! Centres are chosen by farthest-point sampling with edge-path (shortest path along mesh
//! edges) distances until every vertex lies within σ (= r/2, r = 2σ the cluster radius) of a
//! centre. Cluster C weighs vertex i by α_i ∝ exp(−d_i²/2σ²) for d_i < 2σ (d_i the edge-path
//! distance to the centre), normalised to sum one. The constraint rows H x = H B q then tie
//! the skin to the interior only at spatial frequencies below the Gaussian's cut-off; with
//! σ = λ/π that cut-off sits at the critical wrinkle wavelength λ.

use crate::mesh::TriMesh;
use std::cmp::Ordering;
use std::collections::BinaryHeap;

/// Clusters and the sparse constraint matrix H (one row per cluster, per coordinate).
#[derive(Debug, Clone)]
pub struct Clusters {
    /// Gaussian width σ (m); with widths varying over the skin, the smallest one.
    pub sigma: f64,
    /// Centre vertex of each cluster.
    pub centres: Vec<usize>,
    /// Entries (cluster, vertex, weight) of H; each cluster's weights sum to one.
    pub entries: Vec<(usize, usize, f64)>,
    /// Number of skin vertices.
    pub vertices: usize,
}

/// Coverage statistics of a cluster set (reported to the user).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ClusterStats {
    /// Number of clusters (constraint rows per coordinate).
    pub clusters: usize,
    /// Smallest, mean and largest number of vertices in a cluster.
    pub vertices_per_cluster: [f64; 3],
    /// Smallest, mean and largest number of clusters a vertex belongs to.
    pub clusters_per_vertex: [f64; 3],
}

#[derive(PartialEq)]
struct Item(f64, usize);
impl Eq for Item {}
impl PartialOrd for Item {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Item {
    fn cmp(&self, o: &Self) -> Ordering {
        // Min-heap on distance, ties by vertex index (deterministic).
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Vertex adjacency with edge lengths (m).
fn adjacency(mesh: &TriMesh) -> Vec<Vec<(usize, f64)>> {
    let mut adj: Vec<Vec<(usize, f64)>> = vec![Vec::new(); mesh.positions.len()];
    for t in &mesh.triangles {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let l = (mesh.positions[a] - mesh.positions[b]).norm();
            if !adj[a].iter().any(|&(v, _)| v == b) {
                adj[a].push((b, l));
                adj[b].push((a, l));
            }
        }
    }
    for a in &mut adj {
        a.sort_by_key(|&(v, _)| v);
    }
    adj
}

/// Shortest edge-path distances from `src`, lowering `dist` where the new path is shorter and
/// stopping beyond `limit`; returns the vertices reached (d < limit) with d. With `prune`,
/// paths are not extended through vertices they do not bring closer (valid when `dist` holds
/// shortest-path distances to a set of sources: nothing beyond such a vertex can improve).
fn dijkstra(
    adj: &[Vec<(usize, f64)>],
    src: usize,
    limit: f64,
    dist: &mut [f64],
    prune: bool,
) -> Vec<(usize, f64)> {
    let mut reached = Vec::new();
    let mut local: std::collections::HashMap<usize, f64> = std::collections::HashMap::new();
    let mut heap = BinaryHeap::new();
    local.insert(src, 0.0);
    heap.push(Item(0.0, src));
    while let Some(Item(d, v)) = heap.pop() {
        if d > *local.get(&v).unwrap_or(&f64::INFINITY) {
            continue;
        }
        reached.push((v, d));
        if d < dist[v] {
            dist[v] = d;
        }
        for &(w, l) in &adj[v] {
            let nd = d + l;
            if nd < limit
                && nd < *local.get(&w).unwrap_or(&f64::INFINITY)
                && !(prune && nd >= dist[w])
            {
                local.insert(w, nd);
                heap.push(Item(nd, w));
            }
        }
    }
    reached.sort_by_key(|&(v, _)| v);
    reached
}

impl Clusters {
    /// Build clusters of width `sigma` (m) over `mesh`. Every vertex ends within σ of a centre
    /// (each connected piece gets its own centres).
    pub fn build(mesh: &TriMesh, sigma: f64) -> Result<Self, String> {
        if !(sigma.is_finite() && sigma > 0.0) {
            return Err(format!(
                "cluster width σ must be a positive length in metres, got {sigma}"
            ));
        }
        Self::build_varying(mesh, &vec![sigma; mesh.positions.len()])
    }

    /// Clusters whose width varies over the skin: `sigma_of[v]` (m) is the width wanted at
    /// vertex v — proportional to the local critical wavelength, which grows with the local
    /// skin thickness (λ ∝ h). Farthest-point sampling runs on the distance measured in local
    /// widths, d(v)/σ(v), and stops when every vertex is within its own σ of a centre; each
    /// cluster takes the σ of its centre for its Gaussian weights and its 2σ reach. With a
    /// constant σ this is [`Clusters::build`].
    pub fn build_varying(mesh: &TriMesh, sigma_of: &[f64]) -> Result<Self, String> {
        let n = mesh.positions.len();
        if n == 0 {
            return Err("the skin mesh has no vertices".into());
        }
        if sigma_of.len() != n {
            return Err(format!(
                "cluster widths: {} values for {n} vertices",
                sigma_of.len()
            ));
        }
        if let Some((v, s)) = sigma_of
            .iter()
            .enumerate()
            .find(|(_, s)| !(s.is_finite() && **s > 0.0))
        {
            return Err(format!(
                "cluster width σ must be a positive length in metres, got {s} at vertex {v}"
            ));
        }
        let sigma = sigma_of.iter().copied().fold(f64::INFINITY, f64::min);
        let adj = adjacency(mesh);
        // Farthest-point sampling: `near[v]` is the edge-path distance to the nearest centre.
        let mut near = vec![f64::INFINITY; n];
        let mut centres = Vec::new();
        let mut next = 0;
        loop {
            centres.push(next);
            // Only distances below the current value can change; bound by the largest one.
            let bound = near.iter().copied().fold(0.0, f64::max);
            let bound = if bound.is_finite() {
                bound
            } else {
                f64::INFINITY
            };
            dijkstra(&adj, next, bound, &mut near, true);
            let (far, d) =
                near.iter()
                    .zip(sigma_of)
                    .enumerate()
                    .fold((0, -1.0), |(bi, bd), (i, (&d, &s))| {
                        let d = d / s;
                        if d > bd {
                            (i, d)
                        } else {
                            (bi, bd)
                        }
                    });
            if d <= 1.0 {
                break;
            }
            next = far;
        }
        let mut entries = Vec::new();
        let mut scratch = vec![f64::INFINITY; n];
        for (c, &centre) in centres.iter().enumerate() {
            let sigma = sigma_of[centre];
            let reached = dijkstra(&adj, centre, 2.0 * sigma, &mut scratch, false);
            let w: Vec<f64> = reached
                .iter()
                .map(|&(_, d)| (-d * d / (2.0 * sigma * sigma)).exp())
                .collect();
            let sum: f64 = w.iter().sum();
            for (&(v, _), wi) in reached.iter().zip(&w) {
                entries.push((c, v, wi / sum));
            }
        }
        Ok(Self {
            sigma,
            centres,
            entries,
            vertices: n,
        })
    }

    /// The clusters on a part of the mesh, over a skin of `vertices` vertices: `local[v]` is
    /// vertex v's index in that skin (`None` outside the part). A cluster is kept when its
    /// centre lies in the part and at least `min_share` of its weight does; its weights are
    /// restricted to the part and renormalised. Inside the part, away from its border, the
    /// clusters are exactly the whole mesh's, so the constraint layout does not depend on
    /// where the part was cut.
    pub fn restrict(&self, local: &[Option<usize>], vertices: usize, min_share: f64) -> Self {
        let mut kept_weight = vec![0.0; self.len()];
        for &(c, v, w) in &self.entries {
            if local[v].is_some() {
                kept_weight[c] += w;
            }
        }
        let mut renumber = vec![None; self.len()];
        let mut centres = Vec::new();
        for (c, &centre) in self.centres.iter().enumerate() {
            if let Some(lc) = local[centre] {
                if kept_weight[c] >= min_share {
                    renumber[c] = Some(centres.len());
                    centres.push(lc);
                }
            }
        }
        let entries = self
            .entries
            .iter()
            .filter_map(|&(c, v, w)| Some((renumber[c]?, local[v]?, w / kept_weight[c])))
            .collect();
        Self {
            sigma: self.sigma,
            centres,
            entries,
            vertices,
        }
    }

    /// Number of clusters.
    pub fn len(&self) -> usize {
        self.centres.len()
    }

    /// True when there are no clusters.
    pub fn is_empty(&self) -> bool {
        self.centres.is_empty()
    }

    /// Apply H to one coordinate field (one value per vertex): the cluster averages.
    pub fn apply(&self, field: &[f64]) -> Vec<f64> {
        let mut out = vec![0.0; self.len()];
        for &(c, v, w) in &self.entries {
            out[c] += w * field[v];
        }
        out
    }

    /// Coverage statistics.
    pub fn stats(&self) -> ClusterStats {
        let mut per_cluster = vec![0usize; self.len()];
        let mut per_vertex = vec![0usize; self.vertices];
        for &(c, v, _) in &self.entries {
            per_cluster[c] += 1;
            per_vertex[v] += 1;
        }
        let mmm = |v: &[usize]| {
            let min = v.iter().copied().min().unwrap_or(0) as f64;
            let max = v.iter().copied().max().unwrap_or(0) as f64;
            let mean = v.iter().sum::<usize>() as f64 / v.len().max(1) as f64;
            [min, mean, max]
        };
        ClusterStats {
            clusters: self.len(),
            vertices_per_cluster: mmm(&per_cluster),
            clusters_per_vertex: mmm(&per_vertex),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::Vector3;

    /// A flat square grid sheet, `n × n` vertices, spacing `a` (m), in the z = 0 plane.
    fn grid(n: usize, a: f64) -> TriMesh {
        let mut p = Vec::new();
        for j in 0..n {
            for i in 0..n {
                p.push(Vector3::new(i as f64 * a, j as f64 * a, 0.0));
            }
        }
        TriMesh::new(p, crate::mesh::grid_triangles(n, n))
    }

    #[test]
    fn clusters_cover_every_vertex_with_normalised_truncated_gaussians() {
        let (n, a, sigma) = (61, 1e-3, 4e-3);
        let m = grid(n, a);
        let c = Clusters::build(&m, sigma).unwrap();
        let s = c.stats();
        // Every vertex lies in at least one cluster; rows sum to one; weights positive.
        assert!(s.clusters_per_vertex[0] >= 1.0, "{s:?}");
        let mut sums = vec![0.0; c.len()];
        for &(k, _, w) in &c.entries {
            assert!(w > 0.0);
            sums[k] += w;
        }
        assert!(sums.iter().all(|x| (x - 1.0).abs() < 1e-12));
        // Farthest-point sampling: centres are more than σ apart along edges (they were
        // picked > σ from all earlier ones), so no two are closer than σ in the plane... up to
        // the grid's edge-path metric, which is ≥ the Euclidean one: check Euclidean ≥ σ/√2.
        for (i, &p) in c.centres.iter().enumerate() {
            for &q in &c.centres[..i] {
                assert!((m.positions[p] - m.positions[q]).norm() > sigma / 2f64.sqrt());
            }
        }
        // Disc of radius 2σ on a grid of spacing a holds about π(2σ/a)² ≈ 200 vertices; the
        // edge-path metric on this triangulation is longer than Euclidean, so fewer.
        assert!(
            s.vertices_per_cluster[2] <= std::f64::consts::PI * (2.0 * sigma / a + 1.0).powi(2),
            "{s:?}"
        );
        assert!(s.vertices_per_cluster[1] > 20.0, "{s:?}");
        // DESIGN.md: each vertex typically lies in 3 to 10 constraints.
        assert!(
            s.clusters_per_vertex[1] >= 2.0 && s.clusters_per_vertex[1] <= 12.0,
            "{s:?}"
        );
    }

    /// H passes long waves and damps waves at the critical wavelength λ = πσ: a Gaussian of
    /// width σ transmits a wave of length L with factor exp(−(2πσ/L)²/2): 0.98 at L = 10λ and
    /// exp(−2) = 0.135 at L = λ (the truncation at 2σ changes these slightly).
    #[test]
    fn constraints_pass_long_waves_and_damp_the_critical_wavelength() {
        let (n, a, sigma) = (121, 1e-3, 3e-3);
        let m = grid(n, a);
        let c = Clusters::build(&m, sigma).unwrap();
        let lambda = std::f64::consts::PI * sigma;
        let transmitted = |len: f64| {
            // Interior clusters only (away from the sheet's edges).
            let field: Vec<f64> = m
                .positions
                .iter()
                .map(|p| (2.0 * std::f64::consts::PI * p.x / len).sin())
                .collect();
            let cos: Vec<f64> = m
                .positions
                .iter()
                .map(|p| (2.0 * std::f64::consts::PI * p.x / len).cos())
                .collect();
            let hs = c.apply(&field);
            let hc = c.apply(&cos);
            let side = (n - 1) as f64 * a;
            let mut amp: f64 = 0.0;
            let mut count = 0;
            for (k, &centre) in c.centres.iter().enumerate() {
                let p = m.positions[centre];
                if p.x > 3.0 * sigma
                    && p.x < side - 3.0 * sigma
                    && p.y > 3.0 * sigma
                    && p.y < side - 3.0 * sigma
                {
                    amp += (hs[k] * hs[k] + hc[k] * hc[k]).sqrt();
                    count += 1;
                }
            }
            amp / count as f64
        };
        let long = transmitted(10.0 * lambda);
        let crit = transmitted(lambda);
        println!(
            "transmitted: {long:.3} at 10λ, {crit:.3} at λ; stats {:?}",
            c.stats()
        );
        assert!(long > 0.9, "long waves pass: {long}");
        assert!(crit < 0.35, "critical wavelength damped: {crit}");
        assert!(
            crit > 0.02,
            "… but not erased (the edge-path metric widens the kernel): {crit}"
        );
    }

    #[test]
    fn bad_width_and_disconnected_pieces() {
        let m = grid(5, 1e-3);
        assert!(Clusters::build(&m, 0.0).unwrap_err().contains("σ"));
        assert!(Clusters::build(&m, f64::NAN).is_err());
        // Two separate sheets each get centres.
        let mut two = grid(5, 1e-3);
        let off = two.positions.len();
        let other = grid(5, 1e-3);
        two.positions.extend(
            other
                .positions
                .iter()
                .map(|p| p + Vector3::new(1.0, 0.0, 0.0)),
        );
        two.triangles.extend(
            other
                .triangles
                .iter()
                .map(|t| [t[0] + off, t[1] + off, t[2] + off]),
        );
        let c = Clusters::build(&two, 1e-3).unwrap();
        assert!(c.stats().clusters_per_vertex[0] >= 1.0);
        assert!(c.centres.iter().any(|&v| v < off) && c.centres.iter().any(|&v| v >= off));
    }
}
