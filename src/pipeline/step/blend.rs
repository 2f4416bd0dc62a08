//! The `blend` step: the frame's blend-shape target on the welded skin (the artist's shape).

use crate::io::load::Rig;
use anyhow::bail;
use nalgebra::Vector3;

/// The blended face of frame `k` under morph `weights`, as positions of the welded skin (m):
/// welded vertex `welded_of_loaded[i]` takes loaded vertex i's position (the last one wins;
/// they coincide). A non-finite position is an error naming the rig and the frame.
pub fn blend_frame(
    rig: &Rig,
    weights: &[f64],
    welded_of_loaded: &[usize],
    welded_count: usize,
    k: usize,
) -> anyhow::Result<Vec<Vector3<f64>>> {
    let loaded = rig.blend(weights);
    if loaded.iter().any(|p| !p.iter().all(|c| c.is_finite())) {
        bail!(
            "{}: frame {k}: the blended face has a non-finite position (check the morph weights)",
            rig.path.display()
        );
    }
    Ok(weld_positions(&loaded, welded_of_loaded, welded_count))
}

/// Loaded positions carried to the welded vertices (m).
pub fn weld_positions(
    loaded: &[Vector3<f64>],
    welded_of_loaded: &[usize],
    welded_count: usize,
) -> Vec<Vector3<f64>> {
    let mut welded = vec![Vector3::zeros(); welded_count];
    for (i, p) in loaded.iter().enumerate() {
        welded[welded_of_loaded[i]] = *p;
    }
    welded
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seam_copies_land_on_their_welded_vertex() {
        let loaded = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 2.0, 0.0),
        ];
        let w = weld_positions(&loaded, &[0, 1, 1, 2], 3);
        assert_eq!(w, vec![loaded[0], loaded[1], loaded[3]]);
    }
}
