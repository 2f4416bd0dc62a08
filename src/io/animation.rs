//! Morph-weight animation: `weights` channels with LINEAR, STEP and CUBICSPLINE samplers,
//! sampled at a chosen frame rate.

use super::accessor::{usize_of, AccessorReader};
use super::error::{GltfError, GltfResult};
use std::path::Path;

/// Interpolation of a glTF animation sampler.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum Interpolation {
    /// Linear between keys.
    Linear,
    /// Hold the key's value until the next key.
    Step,
    /// Cubic Hermite with in- and out-tangents per key.
    CubicSpline,
}

/// One keyed channel: key times (s) and, per key, its values: for `weights` one weight per
/// morph target, for a node's `translation` 3 and `rotation` 4 (quaternion x, y, z, w)
/// (for CUBICSPLINE, `tangents_in`/`tangents_out` hold the tangents, in value per second).
#[derive(Debug, Clone, PartialEq)]
pub struct WeightTrack {
    /// Node whose morph weights are animated.
    pub node: usize,
    /// Key times in seconds, non-decreasing.
    pub times: Vec<f64>,
    /// Weights per key.
    pub values: Vec<Vec<f64>>,
    /// In-tangents per key (CUBICSPLINE only).
    pub tangents_in: Vec<Vec<f64>>,
    /// Out-tangents per key (CUBICSPLINE only).
    pub tangents_out: Vec<Vec<f64>>,
    /// Sampler interpolation.
    pub interpolation: Interpolation,
}

/// Summary of one animation in a file.
#[derive(Debug, Clone, serde::Serialize)]
pub struct AnimationInfo {
    /// Animation index in the file.
    pub index: usize,
    /// Animation name (or `animation_N`).
    pub name: String,
    /// Channel count by target path ("weights", "rotation", …).
    pub channels: Vec<(String, usize)>,
    /// Latest key time (s).
    pub duration_s: f64,
}

/// Longest key time accepted (s): one hour of animation.
pub const MAX_KEY_TIME_S: f64 = 3600.0;

/// Check every animation's channels and samplers refer to things that exist, and summarise.
pub fn summarize(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
) -> GltfResult<Vec<AnimationInfo>> {
    let node_count = json["nodes"].as_array().map_or(0, |a| a.len());
    let mut out = Vec::new();
    for (ai, a) in json["animations"]
        .as_array()
        .map(|a| a.as_slice())
        .unwrap_or(&[])
        .iter()
        .enumerate()
    {
        let samplers = a["samplers"]
            .as_array()
            .map(|s| s.as_slice())
            .unwrap_or(&[]);
        let mut counts: Vec<(String, usize)> = Vec::new();
        let mut duration: f64 = 0.0;
        for (ci, c) in a["channels"]
            .as_array()
            .map(|c| c.as_slice())
            .unwrap_or(&[])
            .iter()
            .enumerate()
        {
            let tgt = &c["target"];
            if let Some(n) = tgt.get("node") {
                let n = usize_of(n).filter(|&n| n < node_count).ok_or_else(|| {
                    GltfError::new(
                        path,
                        format!(
                            "animation {ai} channel {ci} targets node {n}, which does not exist"
                        ),
                    )
                })?;
                let _ = n;
            }
            let si = usize_of(&c["sampler"])
                .filter(|&s| s < samplers.len())
                .ok_or_else(|| {
                    GltfError::new(
                        path,
                        format!(
                            "animation {ai} channel {ci} uses sampler {}, which does not exist",
                            c["sampler"]
                        ),
                    )
                })?;
            let input = usize_of(&samplers[si]["input"]).ok_or_else(|| {
                GltfError::new(path, format!("animation {ai} sampler {si} has no input"))
            })?;
            let times = reader.read(input)?;
            if let Some(t) = times
                .data
                .iter()
                .copied()
                .fold(None, |m: Option<f64>, t| Some(m.map_or(t, |m| m.max(t))))
            {
                duration = duration.max(t);
            }
            let p = tgt["path"].as_str().unwrap_or("?").to_string();
            match counts.iter_mut().find(|(k, _)| *k == p) {
                Some(e) => e.1 += 1,
                None => counts.push((p, 1)),
            }
        }
        out.push(AnimationInfo {
            index: ai,
            name: a["name"]
                .as_str()
                .map(String::from)
                .unwrap_or(format!("animation_{ai}")),
            channels: counts,
            duration_s: duration,
        });
    }
    Ok(out)
}

/// Read the `weights` channel of animation `anim` that targets `node`, if there is one.
/// `targets` is the node's morph target count (the output layout depends on it).
pub fn weight_track(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    anim: usize,
    node: usize,
    targets: usize,
) -> GltfResult<Option<WeightTrack>> {
    channel_track(path, reader, json, (anim, node), "weights", targets)
}

/// Read the channel of animation `anim` that animates `target_path` (`weights`,
/// `translation`, `rotation` or `scale`) of `node`, if there is one, as a keyed track of
/// `width` values per key (morph targets, 3 or 4).
pub fn channel_track(
    path: &Path,
    reader: &AccessorReader,
    json: &serde_json::Value,
    (anim, node): (usize, usize),
    target_path: &str,
    width: usize,
) -> GltfResult<Option<WeightTrack>> {
    let targets = width;
    let a = &json["animations"][anim];
    let Some(ch) = a["channels"].as_array().and_then(|cs| {
        cs.iter().find(|c| {
            c["target"]["path"] == target_path && usize_of(&c["target"]["node"]) == Some(node)
        })
    }) else {
        return Ok(None);
    };
    let si = usize_of(&ch["sampler"]).unwrap_or(usize::MAX);
    let s = a["samplers"].get(si).ok_or_else(|| {
        GltfError::new(
            path,
            format!("animation {anim}: sampler {si} does not exist"),
        )
    })?;
    let interpolation = match s["interpolation"].as_str().unwrap_or("LINEAR") {
        "LINEAR" => Interpolation::Linear,
        "STEP" => Interpolation::Step,
        "CUBICSPLINE" => Interpolation::CubicSpline,
        o => {
            return Err(GltfError::new(
                path,
                format!("animation {anim} sampler {si}: unknown interpolation {o:?}"),
            ))
        }
    };
    let input = reader.read(usize_of(&s["input"]).unwrap_or(usize::MAX))?;
    let output = reader.read(usize_of(&s["output"]).unwrap_or(usize::MAX))?;
    let times = input.data.clone();
    if let Some(w) = times
        .windows(2)
        .position(|w| w[1].partial_cmp(&w[0]).is_none_or(|o| o.is_lt()))
    {
        return Err(GltfError::new(
            path,
            format!(
                "animation {anim} sampler {si}: key times must increase (key {})",
                w + 1
            ),
        ));
    }
    if let Some(t) = times
        .iter()
        .find(|t| !(t.is_finite() && (0.0..=MAX_KEY_TIME_S).contains(*t)))
    {
        return Err(GltfError::new(
            path,
            format!(
                "animation {anim} sampler {si}: key time {t} s is outside 0 … {MAX_KEY_TIME_S} s"
            ),
        ));
    }
    let per_key = if interpolation == Interpolation::CubicSpline {
        3 * targets
    } else {
        targets
    };
    if targets == 0 || output.data.len() != times.len() * per_key {
        let what = if target_path == "weights" {
            format!("mesh has {targets} morph targets")
        } else {
            format!("{target_path} has {targets} values")
        };
        return Err(GltfError::new(path, format!(
            "animation {anim} sampler {si}: {} output values do not match {} keys × {per_key} ({what})",
            output.data.len(), times.len()
        )));
    }
    if output.data.iter().any(|v| !v.is_finite()) {
        return Err(GltfError::new(
            path,
            format!("animation {anim} sampler {si}: non-finite {target_path} value"),
        ));
    }
    let mut values = Vec::new();
    let mut tin = Vec::new();
    let mut tout = Vec::new();
    for k in 0..times.len() {
        let row = &output.data[k * per_key..(k + 1) * per_key];
        if interpolation == Interpolation::CubicSpline {
            tin.push(row[..targets].to_vec());
            values.push(row[targets..2 * targets].to_vec());
            tout.push(row[2 * targets..].to_vec());
        } else {
            values.push(row.to_vec());
        }
    }
    Ok(Some(WeightTrack {
        node,
        times,
        values,
        tangents_in: tin,
        tangents_out: tout,
        interpolation,
    }))
}

impl WeightTrack {
    /// Duration in seconds (last key time; 0 for one key).
    pub fn duration(&self) -> f64 {
        self.times.last().copied().unwrap_or(0.0)
    }

    /// Weights at time `t` (s), clamped to the first and last keys.
    pub fn sample(&self, t: f64) -> Vec<f64> {
        let n = self.times.len();
        if n == 0 {
            return Vec::new();
        }
        if t <= self.times[0] {
            return self.values[0].clone();
        }
        if t >= self.times[n - 1] {
            return self.values[n - 1].clone();
        }
        let k = self.times.partition_point(|&x| x <= t) - 1;
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let dt = t1 - t0;
        let s = if dt > 0.0 { (t - t0) / dt } else { 0.0 };
        let (v0, v1) = (&self.values[k], &self.values[k + 1]);
        match self.interpolation {
            Interpolation::Step => v0.clone(),
            Interpolation::Linear => v0.iter().zip(v1).map(|(a, b)| a + s * (b - a)).collect(),
            Interpolation::CubicSpline => {
                let (s2, s3) = (s * s, s * s * s);
                let h00 = 2.0 * s3 - 3.0 * s2 + 1.0;
                let h10 = s3 - 2.0 * s2 + s;
                let h01 = -2.0 * s3 + 3.0 * s2;
                let h11 = s3 - s2;
                let (b0, a1) = (&self.tangents_out[k], &self.tangents_in[k + 1]);
                (0..v0.len())
                    .map(|i| h00 * v0[i] + h10 * dt * b0[i] + h01 * v1[i] + h11 * dt * a1[i])
                    .collect()
            }
        }
    }

    /// Sample at `fps` frames per second from t = 0 to the last key inclusive:
    /// frame k is at k / fps seconds.
    pub fn sample_frames(&self, fps: f64) -> Vec<Vec<f64>> {
        frame_times(self.duration(), fps)
            .into_iter()
            .map(|t| self.sample(t))
            .collect()
    }
}

/// Frame times k / fps for k = 0 … ⌊duration · fps⌋ (s). Key times stored as f32 carry a
/// relative error of ~6e-8, so a duration within 1e-6 (relative) of a whole frame counts as it.
pub fn frame_times(duration: f64, fps: f64) -> Vec<f64> {
    let n = (duration * fps * (1.0 + 1e-6) + 1e-6).floor().max(0.0) as usize + 1;
    (0..n).map(|k| k as f64 / fps).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn track(interp: Interpolation) -> WeightTrack {
        WeightTrack {
            node: 0,
            times: vec![0.0, 1.0, 2.0],
            values: vec![vec![0.0], vec![1.0], vec![0.5]],
            tangents_in: vec![vec![0.0], vec![0.0], vec![0.0]],
            tangents_out: vec![vec![2.0], vec![0.0], vec![0.0]],
            interpolation: interp,
        }
    }

    #[test]
    fn linear_step_and_cubic_sampling_match_formulas() {
        let l = track(Interpolation::Linear);
        assert_eq!(l.sample(0.25), vec![0.25]);
        assert_eq!(l.sample(1.5), vec![0.75]);
        assert_eq!(l.sample(-1.0), vec![0.0]);
        assert_eq!(l.sample(9.0), vec![0.5]);
        let s = track(Interpolation::Step);
        assert_eq!(s.sample(0.99), vec![0.0]);
        assert_eq!(s.sample(1.0), vec![1.0]);
        // Hermite on [0,1]: p(s) = h10·2 + h01·1 with h10 = s³−2s²+s, h01 = −2s³+3s².
        let c = track(Interpolation::CubicSpline);
        let sv = 0.5;
        let expect =
            2.0 * (sv * sv * sv - 2.0 * sv * sv + sv) + (-2.0 * sv * sv * sv + 3.0 * sv * sv);
        assert!((c.sample(0.5)[0] - expect).abs() < 1e-15);
        assert_eq!(c.sample(1.0), vec![1.0]);
        assert_eq!(frame_times(2.0, 30.0).len(), 61);
        assert_eq!(l.sample_frames(2.0).len(), 5);
    }
}
