//! The head rig's performance: 11 s keyed at 30 fps, shaped like facial-capture data. Several
//! shapes are active at once at partial weights (expressions overlap and blend into each
//! other, speech moves the jaw and lips continuously, blinks come every few seconds), every
//! weight rests slightly above zero, and every weight of every frame carries a small jitter.

use crate::io::model::WeightKeys;
use crate::math::rng::Lcg;

/// Key rate of the performance, frames per second.
pub const FPS: f64 = 30.0;
/// Length of the performance, s (330 frame intervals, 331 keys).
pub const DURATION: f64 = 11.0;
/// Resting weight of every shape (capture solvers rarely output exact zeros).
pub const REST: f64 = 0.02;
/// Amplitude of the uniform frame-to-frame jitter added to every weight.
pub const JITTER: f64 = 0.015;
/// Seed of the jitter.
const SEED: u64 = 0x6865_6164;

/// One expression: the listed shapes rise to their peaks, hold, and fall back.
struct Event {
    /// Start time, s.
    start: f64,
    /// Duration, s.
    duration: f64,
    /// (shape name, peak weight).
    shapes: &'static [(&'static str, f64)],
}

/// The expressions, in time order (overlapping).
const EVENTS: &[Event] = &[
    Event {
        start: 0.3,
        duration: 2.0,
        shapes: &[
            ("mouthSmileLeft", 0.7),
            ("mouthSmileRight", 0.65),
            ("cheekSquintLeft", 0.4),
            ("cheekSquintRight", 0.35),
            ("eyeSquintLeft", 0.3),
            ("eyeSquintRight", 0.3),
        ],
    },
    Event {
        start: 0.7,
        duration: 0.25,
        shapes: &[("eyeBlinkLeft", 0.95), ("eyeBlinkRight", 0.95)],
    },
    Event {
        start: 2.2,
        duration: 1.4,
        shapes: &[
            ("eyeLookOutLeft", 0.5),
            ("eyeLookInRight", 0.5),
            ("mouthRight", 0.3),
            ("mouthDimpleRight", 0.3),
            ("jawRight", 0.2),
        ],
    },
    Event {
        start: 3.4,
        duration: 2.1,
        shapes: &[
            ("browInnerUp", 0.8),
            ("browOuterUpLeft", 0.7),
            ("browOuterUpRight", 0.65),
            ("eyeWideLeft", 0.6),
            ("eyeWideRight", 0.6),
            ("jawOpen", 0.35),
        ],
    },
    Event {
        start: 3.6,
        duration: 0.22,
        shapes: &[("eyeBlinkLeft", 0.9), ("eyeBlinkRight", 0.9)],
    },
    Event {
        start: 5.2,
        duration: 2.0,
        shapes: &[
            ("browDownLeft", 0.7),
            ("browDownRight", 0.7),
            ("noseSneerLeft", 0.5),
            ("noseSneerRight", 0.45),
            ("mouthFrownLeft", 0.5),
            ("mouthFrownRight", 0.5),
            ("mouthUpperUpLeft", 0.3),
            ("mouthUpperUpRight", 0.3),
            ("mouthShrugUpper", 0.3),
            ("mouthStretchLeft", 0.25),
        ],
    },
    Event {
        start: 6.2,
        duration: 0.25,
        shapes: &[("eyeBlinkLeft", 0.95), ("eyeBlinkRight", 0.9)],
    },
    Event {
        start: 7.0,
        duration: 1.6,
        shapes: &[
            ("mouthPucker", 0.8),
            ("mouthFunnel", 0.3),
            ("eyeLookUpLeft", 0.5),
            ("eyeLookUpRight", 0.5),
            ("mouthLeft", 0.3),
            ("mouthRollUpper", 0.2),
        ],
    },
    Event {
        start: 8.2,
        duration: 2.2,
        shapes: &[
            ("mouthSmileLeft", 0.6),
            ("mouthDimpleLeft", 0.4),
            ("mouthStretchRight", 0.3),
            ("jawLeft", 0.2),
            ("browOuterUpLeft", 0.4),
            ("eyeLookDownLeft", 0.4),
            ("eyeLookDownRight", 0.4),
            ("eyeLookInLeft", 0.2),
            ("eyeLookOutRight", 0.2),
        ],
    },
    Event {
        start: 8.9,
        duration: 1.1,
        shapes: &[
            ("cheekPuff", 0.5),
            ("mouthPressLeft", 0.3),
            ("mouthPressRight", 0.3),
            ("mouthClose", 0.2),
        ],
    },
    Event {
        start: 9.4,
        duration: 0.22,
        shapes: &[("eyeBlinkLeft", 0.9), ("eyeBlinkRight", 0.95)],
    },
    Event {
        start: 9.8,
        duration: 1.0,
        shapes: &[
            ("mouthRollLower", 0.4),
            ("mouthShrugLower", 0.5),
            ("tongueOut", 0.3),
            ("jawForward", 0.2),
            ("mouthLowerDownLeft", 0.3),
            ("mouthLowerDownRight", 0.25),
        ],
    },
];

/// Speech: the jaw and lips move continuously while talking, (start, end) in s.
const SPEECH: &[(f64, f64)] = &[(1.6, 4.4), (7.6, 10.2)];

/// Smooth rise over 30 %, hold 40 %, smooth fall over 30 % of `u` ∈ [0, 1]; 0 outside.
fn envelope(u: f64) -> f64 {
    if !(0.0..=1.0).contains(&u) {
        return 0.0;
    }
    let rise = |t: f64| t * t * (3.0 - 2.0 * t);
    if u < 0.3 {
        rise(u / 0.3)
    } else if u <= 0.7 {
        1.0
    } else {
        rise((1.0 - u) / 0.3)
    }
}

/// Speech weights at time `t` for (jawOpen, mouthClose, mouthFunnel, mouthPucker,
/// mouthLowerDownLeft, mouthLowerDownRight, mouthUpperUpLeft, mouthUpperUpRight): syllables at
/// about 4 Hz with incommensurate lip motions.
fn speech(t: f64) -> [(&'static str, f64); 8] {
    let on: f64 = SPEECH
        .iter()
        .map(|&(a, b)| envelope((t - a) / (b - a)))
        .sum();
    let tau = std::f64::consts::TAU;
    let syl = 0.5 + 0.5 * (tau * 4.1 * t).sin();
    let round = (0.5 + 0.5 * (tau * 1.3 * t + 1.0).sin()).powi(2);
    let open = on * (0.1 + 0.3 * syl);
    [
        ("jawOpen", open),
        ("mouthClose", on * 0.15 * (1.0 - syl)),
        ("mouthFunnel", on * 0.35 * round * syl),
        ("mouthPucker", on * 0.3 * round * (1.0 - syl)),
        ("mouthLowerDownLeft", on * 0.25 * syl),
        ("mouthLowerDownRight", on * 0.22 * syl),
        (
            "mouthUpperUpLeft",
            on * 0.12 * (0.5 + 0.5 * (tau * 2.7 * t).sin()),
        ),
        (
            "mouthUpperUpRight",
            on * 0.1 * (0.5 + 0.5 * (tau * 2.7 * t + 0.4).sin()),
        ),
    ]
}

/// The performance for the shapes `names` (names it does not know stay at rest): keys every
/// 1/[`FPS`] s from 0 to [`DURATION`], each weight the sum of the expressions and speech using
/// it plus [`REST`] plus a uniform jitter of ±[`JITTER`], clamped to [0, 1]. Deterministic.
pub fn performance(names: &[&str]) -> WeightKeys {
    let n = names.len();
    let id = |name: &str| names.iter().position(|&m| m == name);
    let frames = (DURATION * FPS).round() as usize;
    let mut rng = Lcg::new(SEED);
    let mut times = Vec::with_capacity(frames + 1);
    let mut weights = Vec::with_capacity(frames + 1);
    for f in 0..=frames {
        let t = f as f64 / FPS;
        let mut w = vec![REST; n];
        for e in EVENTS {
            let a = envelope((t - e.start) / e.duration);
            if a > 0.0 {
                for &(name, peak) in e.shapes {
                    if let Some(k) = id(name) {
                        w[k] += peak * a;
                    }
                }
            }
        }
        for (name, x) in speech(t) {
            if let Some(k) = id(name) {
                w[k] += x;
            }
        }
        for x in &mut w {
            *x = (*x + JITTER * rng.next_signed()).clamp(0.0, 1.0);
        }
        times.push(t);
        weights.push(w);
    }
    WeightKeys { times, weights }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rig::head_shapes::ARKIT_NAMES;

    #[test]
    fn performance_is_capture_like() {
        let k = performance(&ARKIT_NAMES);
        assert_eq!(k.times.len(), 331);
        assert!((k.times[330] - 11.0).abs() < 1e-12);
        // Every shape is used above 0.15 somewhere, and several at once at partial weights.
        for (s, name) in ARKIT_NAMES.iter().enumerate() {
            let peak = k.weights.iter().map(|w| w[s]).fold(0.0, f64::max);
            assert!(peak > 0.15, "{name} peaks at {peak}");
        }
        let busy = k
            .weights
            .iter()
            .filter(|w| w.iter().filter(|&&x| (0.15..0.9).contains(&x)).count() >= 3)
            .count();
        assert!(busy > 150, "{busy} frames with three partial shapes");
        // Jitter: a weight at rest moves by up to 2 × JITTER between frames, never more.
        let rest = k.weights.iter().map(|w| w[ARKIT_NAMES.len() - 1]).take(60);
        let v: Vec<f64> = rest.collect();
        let jumps = v.windows(2).map(|p| (p[1] - p[0]).abs());
        let biggest = jumps.fold(0.0, f64::max);
        assert!(
            biggest > 0.01 && biggest <= 2.0 * JITTER + 1e-12,
            "{biggest}"
        );
    }
}
