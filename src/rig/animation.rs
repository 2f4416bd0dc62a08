//! The demonstration weights animation: every shape in turn, then a few combinations.

use crate::io::model::WeightKeys;

/// Key rate of the animation, frames per second.
pub const FPS: f64 = 30.0;

/// One event: the listed targets rise to `peak`, hold, and fall back to 0.
struct Event {
    /// Start time, s.
    start: f64,
    /// Duration, s.
    duration: f64,
    /// (target index, peak weight).
    targets: Vec<(usize, f64)>,
}

/// Envelope of an event at normalised time `u ∈ [0, 1]`: smooth rise over 40 %, hold 20 %,
/// smooth fall over 40 %; 0 outside.
fn envelope(u: f64) -> f64 {
    if !(0.0..=1.0).contains(&u) {
        return 0.0;
    }
    let rise = |t: f64| t * t * (3.0 - 2.0 * t);
    if u < 0.4 {
        rise(u / 0.4)
    } else if u <= 0.6 {
        1.0
    } else {
        rise((1.0 - u) / 0.4)
    }
}

/// Keys sampled at [`FPS`] for `n_targets` targets whose names are `names` (used to build the
/// combinations): each target alone for 0.6 s, then both smiles, brow raise with jaw open, both
/// squints with the nose wrinkle, and pucker with a frown (0.7 s each). Total 8 s.
pub fn demo_keys(names: &[&str]) -> WeightKeys {
    let n = names.len();
    let id = |name: &str| names.iter().position(|&m| m == name);
    let mut events = Vec::new();
    let mut t = 0.25;
    for k in 0..n {
        events.push(Event {
            start: t,
            duration: 0.6,
            targets: vec![(k, 1.0)],
        });
        t += 0.6;
    }
    let combos: [&[&str]; 4] = [
        &["smile_left", "smile_right"],
        &["brow_raise", "jaw_open"],
        &["squint_left", "squint_right", "nose_wrinkle"],
        &["pucker", "brow_frown"],
    ];
    for combo in combos {
        let targets: Vec<(usize, f64)> = combo
            .iter()
            .filter_map(|&c| id(c))
            .map(|k| (k, 0.8))
            .collect();
        events.push(Event {
            start: t,
            duration: 0.7,
            targets,
        });
        t += 0.7;
    }
    let end = (t + 0.25).max(4.0);
    let frames = (end * FPS).round() as usize;
    let mut times = Vec::with_capacity(frames + 1);
    let mut weights = Vec::with_capacity(frames + 1);
    for f in 0..=frames {
        let time = f as f64 / FPS;
        let mut w = vec![0.0; n];
        for e in &events {
            let a = envelope((time - e.start) / e.duration);
            for &(k, peak) in &e.targets {
                w[k] += peak * a;
            }
        }
        times.push(time);
        weights.push(w.into_iter().map(|x| x.clamp(0.0, 1.0)).collect());
    }
    WeightKeys { times, weights }
}
