//! Colour maps for per-vertex quantities. The default is a symmetric diverging map (ColorBrewer
//! RdBu, blue for negative, near-white for zero, red for positive), suited to signed quantities
//! such as wrinkle depth: furrows blue, ridges red.

/// ColorBrewer RdBu (11 classes), from the negative end (dark blue) to the positive end
/// (dark red).
const RDBU: [[u8; 3]; 11] = [
    [5, 48, 97],
    [33, 102, 172],
    [67, 147, 195],
    [146, 197, 222],
    [209, 229, 240],
    [247, 247, 247],
    [253, 219, 199],
    [244, 165, 130],
    [214, 96, 77],
    [178, 24, 43],
    [103, 0, 31],
];

/// Colour shown for a missing (non-finite) value: a neutral grey that the diverging map never
/// produces.
pub const MISSING: [u8; 3] = [120, 120, 120];

/// Colour of the diverging map at `t ∈ [0, 1]` (clamped; 0 = most negative, 0.5 = zero,
/// 1 = most positive), as linear interpolation between the map's control colours, in 0..=1
/// floats per channel. Non-finite `t` gives [`MISSING`].
pub fn diverging_f(t: f64) -> [f64; 3] {
    if !t.is_finite() {
        return MISSING.map(|c| c as f64 / 255.0);
    }
    let s = t.clamp(0.0, 1.0) * (RDBU.len() - 1) as f64;
    let k = (s.floor() as usize).min(RDBU.len() - 2);
    let u = s - k as f64;
    let (a, b) = (RDBU[k], RDBU[k + 1]);
    [0, 1, 2].map(|c| ((1.0 - u) * a[c] as f64 + u * b[c] as f64) / 255.0)
}

/// [`diverging_f`] as 8-bit RGB (rounded).
pub fn diverging(t: f64) -> [u8; 3] {
    diverging_f(t).map(|c| (c * 255.0).round().clamp(0.0, 255.0) as u8)
}

/// Position of `value` in `range = (lo, hi)` as `t ∈ [0, 1]` (clamped), NaN for a non-finite
/// value. `lo < hi` is the caller's duty (see [`symmetric_range`]).
pub fn normalise(value: f64, range: (f64, f64)) -> f64 {
    if !value.is_finite() {
        return f64::NAN;
    }
    ((value - range.0) / (range.1 - range.0)).clamp(0.0, 1.0)
}

/// A symmetric range `(−m, m)` for a signed quantity: `m` the 99th percentile of `|v|` over
/// the finite values (so a few spikes do not wash out the rest), or `fallback` when that is
/// zero or there is no finite value.
pub fn symmetric_range(values: &[f64], fallback: f64) -> (f64, f64) {
    let mut a: Vec<f64> = values
        .iter()
        .filter(|v| v.is_finite())
        .map(|v| v.abs())
        .collect();
    if a.is_empty() {
        return (-fallback, fallback);
    }
    a.sort_by(f64::total_cmp);
    let k = ((a.len() - 1) as f64 * 0.99).round() as usize;
    let m = a[k];
    if m > 0.0 {
        (-m, m)
    } else {
        (-fallback, fallback)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ends_middle_and_missing() {
        assert_eq!(diverging(0.0), RDBU[0]);
        assert_eq!(diverging(1.0), RDBU[10]);
        assert_eq!(diverging(0.5), RDBU[5]);
        assert_eq!(diverging(-3.0), RDBU[0]);
        assert_eq!(diverging(f64::NAN), MISSING);
        // Symmetric: blue for negative, red for positive.
        let (neg, pos) = (diverging(0.2), diverging(0.8));
        assert!(neg[2] > neg[0] && pos[0] > pos[2]);
        assert_eq!(normalise(0.0, (-2.0, 2.0)), 0.5);
        assert!(normalise(f64::INFINITY, (-1.0, 1.0)).is_nan());
    }

    #[test]
    fn symmetric_range_ignores_spikes() {
        let mut v: Vec<f64> = (0..1000).map(|k| (k as f64 / 999.0) - 0.5).collect();
        v.push(1e6);
        v.push(f64::NAN);
        let (lo, hi) = symmetric_range(&v, 1.0);
        assert_eq!(lo, -hi);
        assert!(hi > 0.48 && hi <= 0.5, "{hi}");
        assert_eq!(symmetric_range(&[0.0, f64::NAN], 0.1), (-0.1, 0.1));
    }
}
