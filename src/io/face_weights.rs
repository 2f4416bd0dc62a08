//! The face's morph-weight animations in a written rig with K more targets: the wrinkle
//! targets' weights join the rig's own weights channel for the face node (in the animation the
//! rig is simulated from), and every other `weights` channel of the face gets K zeros per key,
//! so each still matches the mesh's target count.
//!
//! The rig's channel keeps its key times and interpolation when they are the written frame
//! times (the whole clip, one key per frame at k / fps): the wrinkle weights are added as
//! values at the keys (CUBICSPLINE: with Catmull–Rom tangents). Otherwise the channel is
//! resampled at the written frames, LINEAR, with the rig's weights sampled there, and the
//! returned note says so. A channel whose sampler other channels share gets its own sampler
//! first; the others keep theirs.

use super::accessor::{usize_of, AccessorReader};
use super::compact::CompactDocument;
use super::load::Rig;
use anyhow::bail;
use serde_json::{json, Value};

/// The wrinkle targets' weights at the written frames.
#[derive(Debug, Clone, PartialEq)]
pub struct WrinkleKeys {
    /// Frames per second of the clip (frame k is shown at k / fps seconds).
    pub fps: f64,
    /// First written frame.
    pub first_frame: usize,
    /// Frames in the whole clip.
    pub clip_frames: usize,
    /// The rig's own weights at each written frame (one per rig target).
    pub rig_weights: Vec<Vec<f64>>,
    /// The wrinkle targets' weights at each written frame (one per wrinkle target, as the
    /// file stores them).
    pub weights: Vec<Vec<f64>>,
}

/// Install `keys` (when given) in the rig's weights channel of the face and pad every other
/// weights channel of the face with `k` zeros. Returns, when keys were given, how the rig's
/// channel was treated (kept or resampled), in words.
pub fn install(
    cd: &mut CompactDocument,
    rig: &Rig,
    keys: Option<&WrinkleKeys>,
    k: usize,
) -> anyhow::Result<Option<String>> {
    let node = rig.face().node;
    let reader = AccessorReader::new(&rig.path, &rig.container);
    let anims = cd.doc.json["animations"].as_array().map_or(0, |a| a.len());
    let mut note = None;
    for ai in 0..anims {
        let chans: Vec<usize> = cd.doc.json["animations"][ai]["channels"]
            .as_array()
            .into_iter()
            .flatten()
            .enumerate()
            .filter(|(_, c)| {
                c["target"]["path"] == "weights" && usize_of(&c["target"]["node"]) == Some(node)
            })
            .map(|(i, _)| i)
            .collect();
        for (i, &ci) in chans.iter().enumerate() {
            let s = own_sampler(&mut cd.doc.json, ai, ci);
            match keys.filter(|_| Some(ai) == rig.animation && i == 0) {
                Some(keys) => note = Some(fill(cd, rig, &reader, (ai, s), keys)?),
                None => pad(cd, rig, &reader, (ai, s), k)?,
            }
        }
    }
    Ok(note)
}

/// The sampler of channel `ci` of animation `ai`, made its own (a copy) when another channel
/// uses it too.
fn own_sampler(json: &mut Value, ai: usize, ci: usize) -> usize {
    let a = &mut json["animations"][ai];
    let s = usize_of(&a["channels"][ci]["sampler"]).unwrap_or(0);
    let shared = a["channels"]
        .as_array()
        .into_iter()
        .flatten()
        .enumerate()
        .any(|(j, c)| j != ci && usize_of(&c["sampler"]) == Some(s));
    if !shared {
        return s;
    }
    let copy = a["samplers"][s].clone();
    let samplers = a["samplers"].as_array_mut().expect("samplers exist");
    samplers.push(copy);
    let new = samplers.len() - 1;
    a["channels"][ci]["sampler"] = json!(new);
    new
}

/// A sampler's interpolation, key times and output rows (values per key: one block of
/// targets, three for CUBICSPLINE), checked against `n` targets.
struct Keys {
    cubic: bool,
    times: Vec<f64>,
    output: Vec<f64>,
}

fn read_keys(
    rig: &Rig,
    reader: &AccessorReader,
    json: &Value,
    at: (usize, usize),
) -> anyhow::Result<Keys> {
    let (ai, s) = at;
    let sj = &json["animations"][ai]["samplers"][s];
    let cubic = sj["interpolation"] == "CUBICSPLINE";
    let times = reader
        .read(usize_of(&sj["input"]).unwrap_or(usize::MAX))?
        .data;
    let output = reader
        .read(usize_of(&sj["output"]).unwrap_or(usize::MAX))?
        .data;
    let n = rig.face().targets.len();
    let per = if cubic { 3 * n } else { n };
    if output.len() != times.len() * per {
        bail!(
            "{}: animation {ai} sampler {s}: {} weights for {} keys of the face's {n} targets",
            rig.path.display(),
            output.len(),
            times.len()
        );
    }
    Ok(Keys {
        cubic,
        times,
        output,
    })
}

/// Pad every key of sampler `at` (animation, sampler) with `k` zero weights.
fn pad(
    cd: &mut CompactDocument,
    rig: &Rig,
    reader: &AccessorReader,
    at: (usize, usize),
    k: usize,
) -> anyhow::Result<()> {
    let keys = read_keys(rig, reader, &cd.doc.json, at)?;
    let n = rig.face().targets.len();
    let mut out = Vec::with_capacity(keys.output.len() + keys.times.len() * 3 * k);
    for block in keys.output.chunks_exact(n.max(1)) {
        out.extend_from_slice(block);
        out.extend(std::iter::repeat_n(0.0, k));
    }
    let acc = cd.push_f32(&out, 1, None);
    cd.doc.json["animations"][at.0]["samplers"][at.1]["output"] = json!(acc);
    Ok(())
}

/// Whether `times` (s) are the frames 0..count at `fps`, as f32 key times hold them.
fn frame_times(times: &[f64], fps: f64, count: usize) -> bool {
    times.len() == count
        && times
            .iter()
            .enumerate()
            .all(|(i, &t)| (t - i as f64 / fps).abs() <= 1e-6 * t.abs().max(1.0))
}

/// Catmull–Rom tangents (weight per second) of `values[key][m]` at `times`.
fn tangents(times: &[f64], values: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = times.len();
    (0..n)
        .map(|i| {
            let (a, b) = (i.saturating_sub(1), (i + 1).min(n - 1));
            let dt = times[b] - times[a];
            (0..values[i].len())
                .map(|m| {
                    if dt > 0.0 {
                        (values[b][m] - values[a][m]) / dt
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// Put `keys` in sampler `at`: kept keys with the wrinkle weights added, or resampled at the
/// written frames. Returns the note.
fn fill(
    cd: &mut CompactDocument,
    rig: &Rig,
    reader: &AccessorReader,
    at: (usize, usize),
    keys: &WrinkleKeys,
) -> anyhow::Result<String> {
    let old = read_keys(rig, reader, &cd.doc.json, at)?;
    let n = rig.face().targets.len();
    let written = keys.weights.len();
    let whole = keys.first_frame == 0 && written == keys.clip_frames;
    let sj = &mut cd.doc.json["animations"][at.0]["samplers"][at.1];
    let interpolation = sj["interpolation"].as_str().unwrap_or("LINEAR").to_string();
    if whole && frame_times(&old.times, keys.fps, written) {
        let mut out = Vec::new();
        if old.cubic {
            let tan = tangents(&old.times, &keys.weights);
            for (i, row) in old.output.chunks_exact(3 * n.max(1)).enumerate() {
                for (b, extra) in [&tan[i], &keys.weights[i], &tan[i]].into_iter().enumerate() {
                    out.extend_from_slice(&row[b * n..(b + 1) * n]);
                    out.extend_from_slice(extra);
                }
            }
        } else {
            for (row, w) in old.output.chunks_exact(n.max(1)).zip(&keys.weights) {
                out.extend_from_slice(row);
                out.extend_from_slice(w);
            }
        }
        let acc = cd.push_f32(&out, 1, None);
        cd.doc.json["animations"][at.0]["samplers"][at.1]["output"] = json!(acc);
        return Ok(format!(
            "the wrinkle weights joined the rig's weights channel (its {} keys at the frame times, {interpolation}, kept)",
            old.times.len()
        ));
    }
    let times: Vec<f64> = (0..written)
        .map(|j| (keys.first_frame + j) as f64 / keys.fps)
        .collect();
    let out: Vec<f64> = keys
        .rig_weights
        .iter()
        .zip(&keys.weights)
        .flat_map(|(r, w)| r.iter().chain(w).copied())
        .collect();
    let input = cd.push_f32(&times, 1, None);
    let output = cd.push_f32(&out, 1, None);
    let sj = &mut cd.doc.json["animations"][at.0]["samplers"][at.1];
    sj["input"] = json!(input);
    sj["output"] = json!(output);
    sj["interpolation"] = json!("LINEAR");
    let why = if whole {
        format!(
            "its {} {interpolation} keys are not the {written} frame times",
            old.times.len()
        )
    } else {
        format!(
            "only frames {}..{} of {} were written",
            keys.first_frame,
            keys.first_frame + written,
            keys.clip_frames
        )
    };
    Ok(format!(
        "the rig's weights channel was resampled at the {written} written frames (LINEAR, {} fps) to carry the wrinkle weights: {why}",
        keys.fps
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn frame_times_tolerate_f32_and_tangents_are_central() {
        let t: Vec<f64> = (0..4).map(|i| (i as f32 / 30.0) as f64).collect();
        assert!(frame_times(&t, 30.0, 4));
        assert!(!frame_times(&t, 60.0, 4));
        assert!(!frame_times(&t[..3], 30.0, 4));
        let tan = tangents(&[0.0, 1.0, 3.0], &[vec![0.0], vec![1.0], vec![5.0]]);
        assert_eq!(tan, vec![vec![1.0], vec![5.0 / 3.0], vec![2.0]]);
    }

    #[test]
    fn a_shared_sampler_is_split_for_the_face_channel_only() {
        let mut j = json!({ "animations": [{ "samplers": [{ "input": 0, "output": 1 }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } },
                         { "sampler": 0, "target": { "node": 1, "path": "weights" } }] }] });
        assert_eq!(own_sampler(&mut j, 0, 0), 1);
        assert_eq!(j["animations"][0]["channels"][0]["sampler"], 1);
        assert_eq!(j["animations"][0]["channels"][1]["sampler"], 0);
        assert_eq!(
            j["animations"][0]["samplers"][1],
            json!({ "input": 0, "output": 1 })
        );
        // Now each has its own: no further copy.
        assert_eq!(own_sampler(&mut j, 0, 1), 0);
    }
}
