//! The `record` step's geometry: the exported surface of a frame. It is the blend-shape target
//! plus the skin's high-frequency part, t + (x − B q): H (x − B q) = 0, so this adds exactly
//! the wrinkles (what the constraints leave free) to the artist's shape; with
//! `export.surface = "simulated"` it is x itself (B q where no skin is simulated).

use crate::coupling::embedding::Embedding;
use anyhow::bail;
use nalgebra::Vector3;

/// One frame's exported surfaces.
#[derive(Debug, Clone)]
pub struct Composed {
    /// The wrinkled surface per export vertex (m).
    pub wrinkled: Vec<Vector3<f64>>,
    /// The blend-shape target per export vertex (m).
    pub target: Vec<Vector3<f64>>,
    /// Largest wrinkle displacement ‖x − B q‖ over the skin (m).
    pub depth_max: f64,
    /// RMS of the embedded surface B q from the target over the export vertices (m).
    pub shape_miss: f64,
}

/// How the export vertices follow the lattice, the target and the skin.
#[derive(Debug, Clone, Copy)]
pub struct SurfaceMaps<'a> {
    /// The embedding B of every export vertex in the lattice.
    pub embedding: &'a Embedding,
    /// For each export vertex, (welded vertex, weight) pairs whose blend is its target.
    pub target_of: &'a [Vec<(usize, f64)>],
    /// Export vertex of each shell vertex.
    pub sim_vertices: &'a [usize],
}

/// The state a frame's surfaces are composed from: node positions `q` (flat, m), the skin's
/// positions `x` (flat per shell vertex, m; `None` without a simulated skin) and the
/// wrinkles' weight per export vertex (0–1; `None`: one everywhere), below one about skin
/// outside the model ([`crate::pipeline::setup::outside`]).
pub type ComposeState<'a> = (&'a [f64], Option<&'a [f64]>, Option<&'a [f64]>);

/// The frame's surfaces from the welded target (m) and the state `(q, x, fade)`: the target
/// plus the wrinkles x − B q weighted by the fade.
pub fn compose(
    maps: SurfaceMaps,
    welded_target: &[Vector3<f64>],
    (q, x, fade): ComposeState,
    simulated_surface: bool,
    k: usize,
) -> anyhow::Result<Composed> {
    let embedded = maps.embedding.positions(q);
    let target = carry(maps.target_of, welded_target);
    let shape_miss = rms_distance(&embedded, &target);
    let mut out = if simulated_surface {
        embedded.clone()
    } else {
        target.clone()
    };
    let mut depth_max = 0.0f64;
    if let Some(x) = x {
        for (i, &v) in maps.sim_vertices.iter().enumerate() {
            let xv = Vector3::new(x[3 * i], x[3 * i + 1], x[3 * i + 2]);
            let detail = xv - embedded[v];
            let (shown, kept) = match fade {
                None => (xv, detail),
                Some(f) => (embedded[v] + detail * f[v], detail * f[v]),
            };
            depth_max = depth_max.max(kept.norm());
            out[v] = if simulated_surface {
                shown
            } else {
                target[v] + kept
            };
        }
    }
    if out.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        bail!("frame {k}: a non-finite position reached the output; nothing was written");
    }
    Ok(Composed {
        wrinkled: out,
        target,
        depth_max,
        shape_miss,
    })
}

/// RMS distance between two point lists of the same length (m); 0 for empty lists.
pub fn rms_distance(a: &[Vector3<f64>], b: &[Vector3<f64>]) -> f64 {
    let sum: f64 = a.iter().zip(b).map(|(p, q)| (p - q).norm_squared()).sum();
    (sum / a.len().max(1) as f64).sqrt()
}

/// Welded-skin values (positions or deltas, m) carried to the refined skin by the
/// subdivision S (`target_of`: per refined vertex, (welded vertex, weight) pairs).
pub fn carry(target_of: &[Vec<(usize, f64)>], welded: &[Vector3<f64>]) -> Vec<Vector3<f64>> {
    target_of
        .iter()
        .map(|o| o.iter().map(|&(w, a)| welded[w] * a).sum())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wrinkle_is_added_to_the_target_or_the_skin_is_taken_as_is() {
        // Two export vertices (the welded vertex 0, and a midpoint of welded 0 and 1) on one
        // node; only the second is simulated.
        let rows = Embedding::from_rows(vec![vec![(0, 1.0)], vec![(0, 1.0)]], 1);
        let target_of = vec![vec![(0, 1.0)], vec![(0, 0.5), (1, 0.5)]];
        let maps = SurfaceMaps {
            embedding: &rows,
            target_of: &target_of,
            sim_vertices: &[1],
        };
        let welded = [Vector3::new(0.0, 0.0, 0.0), Vector3::new(2.0, 0.0, 0.0)];
        let q = [0.5, 0.0, 0.0];
        let x = [0.5, 0.0, 0.003];
        let c = compose(maps, &welded, (&q, Some(&x), None), false, 0).unwrap();
        assert_eq!(c.target, vec![welded[0], Vector3::new(1.0, 0.0, 0.0)]);
        assert_eq!(c.wrinkled, vec![welded[0], Vector3::new(1.0, 0.0, 0.003)]);
        assert!((c.depth_max - 0.003).abs() < 1e-15);
        // B q stands at x = 0.5 for both: 0.5 m from the first target, 0.5 m from the second.
        assert!((c.shape_miss - 0.5).abs() < 1e-15, "{}", c.shape_miss);
        let s = compose(maps, &welded, (&q, Some(&x), None), true, 0).unwrap();
        assert_eq!(
            s.wrinkled,
            vec![Vector3::new(0.5, 0.0, 0.0), Vector3::new(0.5, 0.0, 0.003)]
        );
        let bad = compose(maps, &welded, (&[f64::NAN, 0.0, 0.0], None, None), true, 7);
        assert!(bad
            .unwrap_err()
            .to_string()
            .starts_with("frame 7: a non-finite"));
    }
}
