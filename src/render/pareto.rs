//! The Pareto front of (run time, error) measurements: the runs that no other run beats on both
//! time and error, i.e. the settings worth choosing from.

/// Indices of the Pareto-optimal points of `points = [(time, error), …]` (both to be
/// minimised), ordered by increasing time (so by decreasing error). A point is on the front
/// when no other point is at least as good in both coordinates and strictly better in one.
/// Of several identical optimal points only the first is kept. Points with a non-finite
/// coordinate are never on the front.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..points.len())
        .filter(|&i| points[i].0.is_finite() && points[i].1.is_finite())
        .collect();
    // Sort by time, then error, then index (stable and deterministic).
    idx.sort_by(|&a, &b| {
        let (pa, pb) = (points[a], points[b]);
        pa.0.total_cmp(&pb.0)
            .then(pa.1.total_cmp(&pb.1))
            .then(a.cmp(&b))
    });
    let mut front = Vec::new();
    let mut best_err = f64::INFINITY;
    for i in idx {
        // Everything before i has time ≤ t_i; i is dominated unless its error is strictly
        // below every earlier error.
        if points[i].1 < best_err {
            best_err = points[i].1;
            front.push(i);
        }
    }
    front
}

/// The front's points themselves, in the order of [`pareto_front`].
pub fn pareto_points(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    pareto_front(points)
        .into_iter()
        .map(|i| points[i])
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Brute-force definition: i is optimal iff no j dominates it.
    fn brute(points: &[(f64, f64)]) -> Vec<usize> {
        let dominated = |i: usize| {
            points.iter().enumerate().any(|(j, q)| {
                let p = points[i];
                j != i && q.0 <= p.0 && q.1 <= p.1 && (q.0 < p.0 || q.1 < p.1)
            })
        };
        (0..points.len()).filter(|&i| !dominated(i)).collect()
    }

    #[test]
    fn known_front() {
        // (time s, error mm)
        let p = [
            (1.0, 10.0),     // 0: fastest, worst: on the front
            (2.0, 5.0),      // 1: on the front
            (2.5, 6.0),      // 2: dominated by 1
            (4.0, 1.0),      // 3: on the front
            (3.0, 5.0),      // 4: dominated by 1 (same error, slower)
            (8.0, 0.5),      // 5: on the front
            (9.0, 0.5),      // 6: dominated by 5
            (f64::NAN, 0.1), // 7: not a measurement
        ];
        assert_eq!(pareto_front(&p), vec![0, 1, 3, 5]);
        assert_eq!(pareto_points(&p)[2], (4.0, 1.0));
    }

    #[test]
    fn matches_the_definition_on_a_scatter() {
        // A deterministic pseudo-random cloud with ties: the sweep agrees with brute force.
        let mut rng = crate::math::rng::Lcg::from_state(12345);
        let mut next = || (rng.next_f64() * 20.0).floor();
        let p: Vec<(f64, f64)> = (0..200).map(|_| (next(), next())).collect();
        // Brute force keeps duplicates of an optimal point; the sweep keeps the first.
        let want = brute(&p);
        let mut got = pareto_front(&p);
        got.sort();
        let mut want_unique: Vec<usize> = Vec::new();
        for i in want {
            if !want_unique.iter().any(|&j| p[j] == p[i]) {
                want_unique.push(i);
            }
        }
        assert_eq!(got, want_unique);
        assert!(pareto_front(&[]).is_empty());
    }
}
