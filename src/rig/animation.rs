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
/// combinations): a quarter second of neutral, each target alone for 0.6 s, then both smiles, brow
/// raise with jaw open, both squints with the nose wrinkle, and pucker with a frown (0.7 s each,
/// each at 0.8), and a quarter second of neutral: 8.7 s for nine targets, never under 4 s.
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
        if targets.len() < 2 {
            continue;
        }
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn envelope_rises_holds_and_falls_continuously() {
        assert_eq!(envelope(-0.1), 0.0);
        assert_eq!(envelope(0.0), 0.0);
        assert_eq!(envelope(0.5), 1.0);
        assert_eq!(envelope(1.0), 0.0);
        assert_eq!(envelope(1.1), 0.0);
        // Continuous (no jump above the slope bound 1.5 / 0.4 per unit time) and within [0, 1].
        let n = 10_000;
        for k in 0..n {
            let (a, b) = (
                envelope(k as f64 / n as f64),
                envelope((k + 1) as f64 / n as f64),
            );
            assert!((0.0..=1.0).contains(&a));
            assert!((b - a).abs() <= 3.75 / n as f64 + 1e-12);
        }
    }

    #[test]
    fn keys_cover_each_target_and_the_combinations() {
        let names = ["smile_left", "smile_right", "other"];
        let k = demo_keys(&names);
        assert_eq!(k.times.len(), k.weights.len());
        let end = k.times.last().copied().unwrap_or(0.0);
        // 0.25 + 3 × 0.6 + one matching combination (the smiles) × 0.7 + 0.25, at least 4 s.
        assert!((end - 4.0).abs() < 1e-9, "end {end}");
        let both = k
            .weights
            .iter()
            .any(|w| w[0] >= 0.79 && w[1] >= 0.79 && w[2] == 0.0);
        assert!(both);
    }
}
