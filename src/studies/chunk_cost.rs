//! The farm's cost model against a run's measured frames: a frame's time t_k fitted by least
//! squares as a + b f_k, with f_k the fraction of the skin's area the frame compresses
//! ([`crate::pipeline::farm::compressed_fractions`]); b / a is the cost of a wholly
//! compressed frame relative to one that compresses nothing, the model's
//! [`crate::pipeline::farm::COMPRESSED_FRAME_COST`].

use serde::Serialize;

/// The fit of a run's frame times to the cost model.
#[derive(Debug, Clone, Serialize)]
pub struct CostFit {
    /// Frames fitted.
    pub frames: usize,
    /// a: the time of a frame that compresses no skin (s).
    pub plain_frame_s: f64,
    /// b / a: a wholly compressed frame's extra cost over a plain one (dimensionless).
    pub compressed_cost: f64,
    /// R² of the fit (1: the compressed fraction explains every frame's time).
    pub r2: f64,
    /// The mean compressed fraction of the frames (0–1).
    pub mean_fraction: f64,
    /// The constant the model uses now.
    pub model_cost: f64,
    /// The run's frames split into [`REPLAY_CHUNKS`] chunks with the default pre-roll by the
    /// model at each constant of [`REPLAY_COSTS`]: the best constant gives the shortest
    /// longest chunk.
    pub replay: Vec<Replay>,
}

/// One constant of the replay and the longest chunk it makes.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Replay {
    /// The model's constant c (dimensionless).
    pub constant: f64,
    /// The longest chunk's measured time, pre-roll included (s).
    pub longest_chunk_s: f64,
}

/// Chunks the replay splits a run's frames into.
pub const REPLAY_CHUNKS: usize = 8;

/// The model's constants the replay tries.
pub const REPLAY_COSTS: [f64; 7] = [0.0, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0];

/// The longest of `count` chunks' measured times (s, each with `preroll` frames before it)
/// when `times` (s, frames 0..n in order) are split by the model at constant `c` on the
/// frames' compressed `fractions`.
pub fn longest_chunk(
    times: &[f64],
    fractions: &[f64],
    c: f64,
    (count, preroll): (usize, usize),
) -> f64 {
    let costs: Vec<f64> = fractions.iter().map(|f| 1.0 + c * f).collect();
    crate::pipeline::farm::balance(&costs, count, preroll)
        .iter()
        .map(|r| {
            times[r.start.saturating_sub(preroll)..r.end]
                .iter()
                .sum::<f64>()
        })
        .fold(0.0, f64::max)
}

/// Each simulated frame's time (s) from a run's report (`per_frame`: the fit's, the
/// interior's and the skin's milliseconds), by frame index.
pub fn frame_times(report: &serde_json::Value) -> anyhow::Result<Vec<(usize, f64)>> {
    let frames = report["per_frame"]
        .as_array()
        .ok_or_else(|| anyhow::anyhow!("the report has no per_frame list"))?;
    Ok(frames
        .iter()
        .filter(|f| f["not_simulated"].is_null())
        .filter_map(|f| {
            let k = f["frame"].as_u64()? as usize;
            let ms: f64 = ["fit", "interior", "shell"]
                .iter()
                .filter_map(|s| f[s]["ms"].as_f64())
                .sum();
            Some((k, ms / 1e3))
        })
        .collect())
}

/// Fit `times` ((frame, s)) against `fractions` (per frame of the clip, 0–1). `None` with
/// fewer than three frames or no spread in the fractions.
pub fn fit(times: &[(usize, f64)], fractions: &[f64]) -> Option<CostFit> {
    let points: Vec<(f64, f64)> = times
        .iter()
        .filter_map(|&(k, t)| fractions.get(k).map(|&f| (f, t)))
        .collect();
    let n = points.len() as f64;
    if points.len() < 3 {
        return None;
    }
    let (mf, mt) = points
        .iter()
        .fold((0.0, 0.0), |(a, b), (f, t)| (a + f / n, b + t / n));
    let sff: f64 = points.iter().map(|(f, _)| (f - mf).powi(2)).sum();
    let sft: f64 = points.iter().map(|(f, t)| (f - mf) * (t - mt)).sum();
    let stt: f64 = points.iter().map(|(_, t)| (t - mt).powi(2)).sum();
    if sff <= 0.0 {
        return None;
    }
    let b = sft / sff;
    let a = mt - b * mf;
    let r2 = if stt > 0.0 {
        sft * sft / (sff * stt)
    } else {
        1.0
    };
    // The replay needs every frame from the first on.
    let contiguous: Vec<f64> = times
        .iter()
        .enumerate()
        .map_while(|(i, &(k, t))| (i == k).then_some(t))
        .collect();
    let within = &fractions[..contiguous.len().min(fractions.len())];
    let split = (REPLAY_CHUNKS, crate::pipeline::farm::DEFAULT_PREROLL);
    let replay = if contiguous.len() > REPLAY_CHUNKS {
        REPLAY_COSTS
            .iter()
            .map(|&c| Replay {
                constant: c,
                longest_chunk_s: longest_chunk(&contiguous[..within.len()], within, c, split),
            })
            .collect()
    } else {
        Vec::new()
    };
    Some(CostFit {
        replay,
        frames: points.len(),
        plain_frame_s: a,
        compressed_cost: b / a,
        r2,
        mean_fraction: mf,
        model_cost: crate::pipeline::farm::COMPRESSED_FRAME_COST,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Times made as 0.2 s (1 + 15 f) are fitted back to a = 0.2 s and b / a = 15, R² 1.
    #[test]
    fn a_made_up_linear_cost_is_fitted_back() {
        let fractions: Vec<f64> = (0..20).map(|k| (k % 7) as f64 * 0.03).collect();
        let times: Vec<(usize, f64)> = fractions
            .iter()
            .enumerate()
            .map(|(k, f)| (k, 0.2 * (1.0 + 15.0 * f)))
            .collect();
        let c = fit(&times, &fractions).unwrap();
        assert!((c.plain_frame_s - 0.2).abs() < 1e-12, "{c:?}");
        assert!((c.compressed_cost - 15.0).abs() < 1e-9, "{c:?}");
        assert!((c.r2 - 1.0).abs() < 1e-12);
        assert!(fit(&times[..2], &fractions).is_none());
        assert_eq!(c.replay.len(), REPLAY_COSTS.len());
        assert!(fit(&[(0, 1.0), (1, 2.0), (2, 3.0)], &[0.1; 3]).is_none());
    }

    /// Frames whose time grows with their compressed fraction are split best by a model
    /// that knows it: the longest chunk is shorter with the true constant than with none.
    #[test]
    fn the_replay_favours_the_constant_that_made_the_times() {
        let fractions: Vec<f64> = (0..120).map(|k| if k < 30 { 0.5 } else { 0.0 }).collect();
        let times: Vec<f64> = fractions.iter().map(|f| 0.1 * (1.0 + 10.0 * f)).collect();
        let split = (4, 2);
        let right = longest_chunk(&times, &fractions, 10.0, split);
        let none = longest_chunk(&times, &fractions, 0.0, split);
        assert!(right < 0.8 * none, "{right} vs {none}");
    }

    /// The report's frame times are the sum of its stages' milliseconds, in seconds; a frame
    /// not simulated is left out.
    #[test]
    fn frame_times_sum_the_stages_of_simulated_frames() {
        let report = serde_json::json!({"per_frame": [
            {"frame": 3, "interior": {"ms": 100.0}, "shell": {"ms": 400.0}},
            {"frame": 4, "not_simulated": "compresses_nothing"},
            {"frame": 5, "fit": {"ms": 10.0}, "interior": {"ms": 90.0}},
        ]});
        let t = frame_times(&report).unwrap();
        assert_eq!(t, vec![(3, 0.5), (5, 0.1)]);
        assert!(frame_times(&serde_json::json!({})).is_err());
    }
}
