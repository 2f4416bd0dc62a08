//! Chunks of a clip for a farm: each chunk `A:B` runs on its own machine, simulating from
//! rest at max(0, A − P) with a pre-roll of P frames, so a chunk costs its frames plus its
//! pre-roll (and the set-up every chunk repeats). A frame's cost grows with the skin it
//! compresses: where nothing is compressed the skin only follows the interior and its solve
//! converges at once, where a patch buckles the solve takes many Newton iterations. The ranges
//! are balanced by that expected cost, not by frame count.

use super::frames::FrameRange;
use super::plan::clip_weights;
use super::setup::select::largest_compression;
use crate::io::load::Rig;
use crate::mesh::TriMesh;

/// Frames simulated from rest before a chunk's first written frame by default: on the demo
/// rig the error at a chunk's first written frame against an unsplit run falls below 0.1 % from
/// a pre-roll of 9 frames at every start measured (`furrow bench preroll --rig rigs/face.glb
/// --starts 60,120,180 --window 20`, `examples/report/preroll/face/`). On the capture-shaped
/// head it settles at 12–14 % and stays there (the pre-rolled skin buckles onto another
/// branch; `examples/report/preroll/head/`), so a longer pre-roll does not help there.
pub const DEFAULT_PREROLL: usize = 9;

/// The cost of a frame whose whole skin is compressed, relative to a frame that compresses
/// none (whose cost is 1): a frame costs 1 + `COMPRESSED_FRAME_COST` × (its compressed
/// fraction of the skin's area). Measured frame times hardly follow the compressed fraction
/// (R² 0.02 on the demo's clip, 0.002 on the head's 150 first frames: their slow frames are
/// where the skin changes buckled branch), and replaying those runs' frames split into 8
/// chunks with a pre-roll of 9 puts the longest chunk shortest at a constant of about 1
/// (`furrow bench chunk-cost`, `examples/report/chunk_cost/`).
pub const COMPRESSED_FRAME_COST: f64 = 1.0;

/// Each frame's expected cost (a frame compressing no skin costs 1) for a clip of `rig`
/// sampled at `fps` (Hz): 1 + [`COMPRESSED_FRAME_COST`] × its [`compressed_fractions`].
pub fn frame_costs(rig: &Rig, fps: f64, threshold: f64) -> Vec<f64> {
    compressed_fractions(rig, fps, threshold)
        .iter()
        .map(|f| 1.0 + COMPRESSED_FRAME_COST * f)
        .collect()
}

/// The fraction (0–1) of the skin's area each frame of `rig`'s clip, sampled at `fps` (Hz),
/// compresses by more than `threshold` (1 − the smaller principal stretch; the select
/// stage's threshold).
pub fn compressed_fractions(rig: &Rig, fps: f64, threshold: f64) -> Vec<f64> {
    let face = rig.face();
    let rest = TriMesh::new(face.positions.clone(), face.triangles.clone());
    let areas: Vec<f64> = (0..rest.triangles.len())
        .map(|t| rest.triangle_area(t))
        .collect();
    let total: f64 = areas.iter().sum::<f64>().max(f64::MIN_POSITIVE);
    let (weights, _) = clip_weights(rig, fps);
    let poses = weights.iter().map(|w| (rig.blend(w), None));
    let (_, per_pose) = largest_compression(&rest, poses, threshold);
    per_pose
        .iter()
        .map(|beyond| beyond.iter().map(|&t| areas[t]).sum::<f64>() / total)
        .collect()
}

/// `count` contiguous ranges covering frames 0..costs.len() (fewer when there are fewer
/// frames) that minimise the largest chunk cost Σ costs[max(0, A − preroll)..B].
pub fn balance(costs: &[f64], count: usize, preroll: usize) -> Vec<FrameRange> {
    let n = costs.len();
    let count = count.clamp(1, n.max(1));
    if n == 0 {
        return Vec::new();
    }
    let mut prefix = vec![0.0; n + 1];
    for (k, c) in costs.iter().enumerate() {
        prefix[k + 1] = prefix[k] + c;
    }
    let cost = |a: usize, b: usize| prefix[b] - prefix[a.saturating_sub(preroll)];
    let (mut lo, mut hi) = (0.0, cost(0, n));
    let mut best = greedy(n, hi, &cost);
    for _ in 0..64 {
        let mid = 0.5 * (lo + hi);
        let ranges = greedy(n, mid, &cost);
        if ranges.len() <= count {
            (hi, best) = (mid, ranges);
        } else {
            lo = mid;
        }
    }
    // Fewer chunks than asked for (the bound packs them): halve the longest until there
    // are `count`.
    while best.len() < count {
        let (i, r) = best
            .iter()
            .enumerate()
            .max_by_key(|(_, r)| r.len())
            .map(|(i, r)| (i, *r))
            .expect("a range");
        if r.len() < 2 {
            break;
        }
        let mid = r.start + r.len() / 2;
        best[i] = FrameRange {
            start: r.start,
            end: mid,
        };
        best.insert(
            i + 1,
            FrameRange {
                start: mid,
                end: r.end,
            },
        );
    }
    best
}

/// Ranges from frame 0, each extended while its cost stays within `bound` (each holds at
/// least one frame).
fn greedy(n: usize, bound: f64, cost: &dyn Fn(usize, usize) -> f64) -> Vec<FrameRange> {
    let mut ranges = Vec::new();
    let mut start = 0;
    while start < n {
        let mut end = start + 1;
        while end < n && cost(start, end + 1) <= bound {
            end += 1;
        }
        ranges.push(FrameRange { start, end });
        start = end;
    }
    ranges
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_frames_split_evenly_and_costly_frames_get_short_chunks() {
        let even = balance(&[1.0; 100], 4, 0);
        let lens: Vec<usize> = even.iter().map(FrameRange::len).collect();
        assert_eq!(lens, vec![25, 25, 25, 25]);
        // Frames 0..20 cost 10 each, the rest 1: the costly stretch is cut finer.
        let costs: Vec<f64> = (0..100).map(|k| if k < 20 { 10.0 } else { 1.0 }).collect();
        let r = balance(&costs, 4, 0);
        assert_eq!(r.len(), 4);
        assert_eq!(r[0].start, 0);
        assert_eq!(r.last().unwrap().end, 100);
        assert!(r.windows(2).all(|w| w[0].end == w[1].start));
        let chunk = |r: &FrameRange| costs[r.start..r.end].iter().sum::<f64>();
        let worst = r.iter().map(chunk).fold(0.0, f64::max);
        // The total is 280: the best split of 4 costs at least 70 and here at most 80.
        assert!(worst <= 80.0, "{r:?}");
        assert!(r[0].len() < r[3].len());
    }

    #[test]
    fn the_pre_roll_counts_in_each_chunk_but_the_first() {
        let r = balance(&[1.0; 90], 3, 10);
        let lens: Vec<usize> = r.iter().map(FrameRange::len).collect();
        // Costs 36, 30 + 10, 24 + 10 would be uneven: the first chunk (no pre-roll) is the
        // longest, each of the others carries 10 frames more than it writes.
        let cost = |r: &FrameRange| (r.end - r.start.saturating_sub(10)) as f64;
        let worst = r.iter().map(cost).fold(0.0, f64::max);
        assert!(worst <= 37.0, "{lens:?}");
        assert!(lens[0] > lens[1], "{lens:?}");
        // More chunks than frames: one frame each.
        assert_eq!(balance(&[1.0; 3], 8, 2).len(), 3);
    }
}
