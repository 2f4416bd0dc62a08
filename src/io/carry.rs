//! Vertex data of the loaded face carried to exported vertices by their origin (up to three
//! loaded vertices and weights): texture coordinates and colours interpolate, skin influences
//! blend (each joint's weight summed over the origins, the strongest kept, renormalised).

use super::export::VertexOrigin;

/// `components` values per loaded vertex (`values`), interpolated at each origin.
pub fn interpolate(values: &[f64], components: usize, origin: &[VertexOrigin]) -> Vec<f64> {
    let mut out = Vec::with_capacity(origin.len() * components);
    for o in origin {
        for k in 0..components {
            out.push(
                (0..3)
                    .map(|j| o.weights[j] * values[o.vertices[j] * components + k])
                    .sum(),
            );
        }
    }
    out
}

/// Skin influences at each origin: `joints[s]` and `weights[s]` are the loaded vertices'
/// `JOINTS_s` / `WEIGHTS_s` (4 per vertex). Each joint's weight is summed over the origin's
/// vertices (times their weights), the 4 × sets strongest are kept (ties by joint index) and
/// renormalised to sum to one. Returns the new sets, in the same layout.
pub fn blend_influences(
    joints: &[Vec<f64>],
    weights: &[Vec<f64>],
    origin: &[VertexOrigin],
) -> (Vec<Vec<f64>>, Vec<Vec<f64>>) {
    let sets = joints.len().min(weights.len());
    let keep = 4 * sets;
    let mut oj = vec![Vec::with_capacity(origin.len() * 4); sets];
    let mut ow = vec![Vec::with_capacity(origin.len() * 4); sets];
    let mut acc: Vec<(u32, f64)> = Vec::new();
    for o in origin {
        acc.clear();
        for j in 0..3 {
            if o.weights[j] == 0.0 {
                continue;
            }
            let v = o.vertices[j];
            for s in 0..sets {
                for k in 0..4 {
                    let (jt, wt) = (joints[s][4 * v + k] as u32, weights[s][4 * v + k]);
                    if wt == 0.0 {
                        continue;
                    }
                    match acc.iter_mut().find(|e| e.0 == jt) {
                        Some(e) => e.1 += wt * o.weights[j],
                        None => acc.push((jt, wt * o.weights[j])),
                    }
                }
            }
        }
        acc.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        acc.truncate(keep);
        let total: f64 = acc.iter().map(|e| e.1).sum();
        for s in 0..sets {
            for k in 0..4 {
                let (jt, wt) = acc.get(4 * s + k).copied().unwrap_or((0, 0.0));
                oj[s].push(jt as f64);
                ow[s].push(if total > 0.0 { wt / total } else { 0.0 });
            }
        }
    }
    (oj, ow)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uvs_interpolate_and_influences_blend() {
        let uv = [0.0, 0.0, 1.0, 0.0, 0.0, 1.0];
        let o = VertexOrigin {
            vertices: [0, 1, 2],
            weights: [0.5, 0.25, 0.25],
        };
        assert_eq!(interpolate(&uv, 2, &[o]), vec![0.25, 0.25]);
        // Vertex 0: joint 3 only; vertex 1: joints 3 and 5 half each; vertex 2 unused.
        let joints = vec![vec![3., 0., 0., 0., 3., 5., 0., 0., 9., 0., 0., 0.]];
        let weights = vec![vec![1., 0., 0., 0., 0.5, 0.5, 0., 0., 1., 0., 0., 0.]];
        let mid = VertexOrigin {
            vertices: [0, 1, 2],
            weights: [0.5, 0.5, 0.0],
        };
        let (j, w) = blend_influences(&joints, &weights, &[mid]);
        assert_eq!(j[0][..2], [3.0, 5.0]);
        assert!((w[0][0] - 0.75).abs() < 1e-15 && (w[0][1] - 0.25).abs() < 1e-15);
        assert_eq!(w[0][2..], [0.0, 0.0]);
    }
}
