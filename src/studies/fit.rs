//! Growth laws fitted to measurements, e.g. how shell solve time grows with face count:
//! t ≈ c · n^p, fitted by least squares on log t against log n.

/// A power law y = coefficient · x^exponent fitted to data.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PowerLaw {
    /// The growth exponent p (dimensionless): 1 means linear growth, 1.5 means doubling x
    /// multiplies y by 2^1.5 ≈ 2.8.
    pub exponent: f64,
    /// The coefficient c, in units of y per (unit of x)^p.
    pub coefficient: f64,
    /// Coefficient of determination of the fit in log–log space (1 = the points lie exactly
    /// on a power law).
    pub r_squared: f64,
    /// Number of points used (those with finite, positive x and y).
    pub points: usize,
}

impl PowerLaw {
    /// The fitted y at `x`.
    pub fn eval(&self, x: f64) -> f64 {
        self.coefficient * x.powf(self.exponent)
    }
}

/// Least-squares fit of ln y = ln c + p ln x over the points with finite, positive coordinates.
/// `None` when fewer than two such points have distinct x.
pub fn power_law(points: &[(f64, f64)]) -> Option<PowerLaw> {
    let lp: Vec<(f64, f64)> = points
        .iter()
        .filter(|(x, y)| x.is_finite() && y.is_finite() && *x > 0.0 && *y > 0.0)
        .map(|(x, y)| (x.ln(), y.ln()))
        .collect();
    let n = lp.len() as f64;
    if lp.len() < 2 {
        return None;
    }
    let mx = lp.iter().map(|p| p.0).sum::<f64>() / n;
    let my = lp.iter().map(|p| p.1).sum::<f64>() / n;
    let sxx: f64 = lp.iter().map(|p| (p.0 - mx).powi(2)).sum();
    let sxy: f64 = lp.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
    let syy: f64 = lp.iter().map(|p| (p.1 - my).powi(2)).sum();
    if sxx <= 1e-300 {
        return None;
    }
    let p = sxy / sxx;
    let a = my - p * mx;
    let ss_res: f64 = lp.iter().map(|q| (q.1 - a - p * q.0).powi(2)).sum();
    let r_squared = if syy > 0.0 { 1.0 - ss_res / syy } else { 1.0 };
    Some(PowerLaw {
        exponent: p,
        coefficient: a.exp(),
        r_squared,
        points: lp.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recovers_an_exact_power_law() {
        // t = 2e-5 · n^1.4 at n = 2k, 20k, 80k faces: exponent and coefficient come back.
        let pts: Vec<(f64, f64)> = [2e3f64, 2e4, 8e4]
            .iter()
            .map(|&n| (n, 2e-5 * n.powf(1.4)))
            .collect();
        let f = power_law(&pts).unwrap();
        assert!((f.exponent - 1.4).abs() < 1e-12);
        assert!((f.coefficient / 2e-5 - 1.0).abs() < 1e-10);
        assert!((f.r_squared - 1.0).abs() < 1e-12);
        assert!((f.eval(4e4) / (2e-5 * 4e4f64.powf(1.4)) - 1.0).abs() < 1e-10);
    }

    #[test]
    fn noisy_points_and_bad_input() {
        // Multiplicative noise of ±5% alternating: exponent within 0.05 of the truth, R² < 1.
        let pts: Vec<(f64, f64)> = (1..=8)
            .map(|k| {
                let x = 1000.0 * 2f64.powi(k);
                (x, x.powf(1.2) * if k % 2 == 0 { 1.05 } else { 0.95 })
            })
            .collect();
        let f = power_law(&pts).unwrap();
        assert!((f.exponent - 1.2).abs() < 0.05, "{}", f.exponent);
        assert!(f.r_squared < 1.0 && f.r_squared > 0.99);
        assert!(power_law(&[(1.0, 1.0)]).is_none());
        assert!(power_law(&[(2.0, 1.0), (2.0, 3.0)]).is_none());
        let g = power_law(&[(1.0, 1.0), (2.0, 4.0), (0.0, 5.0), (f64::NAN, 1.0)]).unwrap();
        assert_eq!(g.points, 2);
        assert!((g.exponent - 2.0).abs() < 1e-12);
    }
}
