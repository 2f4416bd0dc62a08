//! Wavelength validation on a small grid (the full sweep is `furrow validate wavelength`).

use furrow::validate::slab::SlabSettings;
use furrow::validate::wavelength::{bilayer, run_point, run_point_with, summary};

/// The goal on a small grid spanning the paper's range (E_x/E_q = 10² … 10⁴, h = 0.1
/// … 0.7 mm): median error under 5 %, none over 15 %, every shell solve converged, and at
/// least 5 full wavelengths counted in each profile (λ well below the slab size: the slab
/// is 8 λ long).
#[test]
fn measured_wavelength_matches_formula_on_a_small_grid() {
    let points = [(100.0, 0.1e-3), (1000.0, 0.3e-3), (1.0e4, 0.7e-3)];
    let mut rows = Vec::new();
    for (ratio, h) in points {
        let r = run_point(ratio, h).unwrap();
        println!(
            "E_x/E_q = {ratio:>7}, h = {:.2} mm: predicted {:.3} mm, measured {:.3} mm, error \
             {:.1} %, {} crossings, {:.1} s",
            h * 1e3,
            r.predicted * 1e3,
            r.measured * 1e3,
            100.0 * r.error,
            r.crossings,
            r.seconds
        );
        assert!(r.converged, "{r:?}");
        assert!(r.crossings >= 10, "{r:?}");
        rows.push(r);
    }
    let (median, worst) = summary(&rows);
    println!(
        "median error {:.1} %, worst {:.1} %",
        100.0 * median,
        100.0 * worst
    );
    assert!(median < 0.05, "median error {median}");
    assert!(worst < 0.15, "worst error {worst}");
}

/// The control: the wavelength is set by the cluster width. With DESIGN.md's σ = λ/π
/// (0.66 of the derived width) the wrinkles come out about that much shorter (measured 0.68 λ
/// in development), so the agreement above is not built into the scene.
#[test]
fn wavelength_follows_the_cluster_width() {
    let mut s = SlabSettings::new(bilayer(1000.0, 0.3e-3));
    s.length = 6.0;
    let derived = {
        let r = run_point_with(&s).unwrap();
        r.measured / r.predicted
    };
    s.sigma_factor = 0.66;
    let r = run_point_with(&s).unwrap();
    let narrow = r.measured / r.predicted;
    println!("λ_measured/λ: {derived:.3} with the derived σ, {narrow:.3} with 0.66 of it");
    assert!(r.converged);
    assert!(
        (narrow / derived - 0.66).abs() < 0.1,
        "{narrow} vs {derived}"
    );
}

/// Why the derived σ: on the slab's kind of mesh the cluster constraints are blind (transmit
/// almost nothing) at the first zero of the truncated kernel's transfer function, z σ / s
/// (z = 2.279 for Euclidean distances, s the edge-path stretch), and still transmit a good
/// part of the critical wave at the design cut-off π σ. The skin wrinkles where the
/// constraints are blind, so σ = s λ / z.
#[test]
fn constraints_are_blind_at_the_kernel_zero() {
    use furrow::coupling::cluster_width::{edge_path_stretch, kernel_zero_wavelength};
    use furrow::coupling::clusters::Clusters;
    use furrow::shell::sheet::equilateral_sheet;
    let a = 1e-3;
    let (nx, ny) = (120, 130);
    let m = equilateral_sheet(nx, ny, a).mesh;
    let sigma = 6e-3;
    let c = Clusters::build(&m, sigma).unwrap();
    let (side_x, side_y) = (nx as f64 * a, ny as f64 * a * 3f64.sqrt() / 2.0);
    // Mean transmitted amplitude of plane waves of length `len` along x and along y, over
    // clusters away from the sheet's edges.
    let transmission = |len: f64| {
        let (mut amp, mut count) = (0.0, 0);
        for dir in 0..2 {
            let phase = |p: &nalgebra::Vector3<f64>| {
                2.0 * std::f64::consts::PI * if dir == 0 { p.x } else { p.y } / len
            };
            let fs: Vec<f64> = m.positions.iter().map(|p| phase(p).sin()).collect();
            let fc: Vec<f64> = m.positions.iter().map(|p| phase(p).cos()).collect();
            let (hs, hc) = (c.apply(&fs), c.apply(&fc));
            for (k, &centre) in c.centres.iter().enumerate() {
                let p = m.positions[centre];
                let margin = 3.0 * sigma;
                if p.x > margin && p.x < side_x - margin && p.y > margin && p.y < side_y - margin {
                    amp += (hs[k] * hs[k] + hc[k] * hc[k]).sqrt();
                    count += 1;
                }
            }
        }
        amp / count as f64
    };
    let s = edge_path_stretch(&m, 2.0 * sigma);
    let zero = kernel_zero_wavelength() * sigma / s;
    let t_zero = transmission(zero);
    let t_pi = transmission(std::f64::consts::PI * sigma);
    let t_long = transmission(4.0 * zero);
    println!(
        "stretch {s:.3}; transmission {t_zero:.4} at the kernel zero {:.3} σ, {t_pi:.3} at π σ, \
         {t_long:.3} at 4× the zero",
        zero / sigma
    );
    assert!(t_zero < 0.05, "{t_zero}");
    assert!(t_pi > 0.2, "{t_pi}");
    assert!(t_long > 0.8, "{t_long}");
}

/// The paper's full grid (5 ratios × 4 thicknesses; about 2–3 minutes in the test profile):
/// `cargo test --test validate_wavelength full_sweep -- --ignored --nocapture`.
#[test]
#[ignore = "the full 20-slab grid takes minutes; `furrow validate wavelength` runs it"]
fn full_sweep() {
    use furrow::validate::wavelength::sweep;
    let ratios = [1e2, 3e2, 1e3, 3e3, 1e4];
    let hs = [0.1e-3, 0.3e-3, 0.5e-3, 0.7e-3];
    let rows = sweep(&ratios, &hs, &|_| {}).unwrap();
    for r in &rows {
        println!(
            "{:>7} {:.1} mm: predicted {:.3} mm measured {:.3} mm error {:.1} % converged {} {:.1} s",
            r.ratio,
            r.thickness * 1e3,
            r.predicted * 1e3,
            r.measured * 1e3,
            100.0 * r.error,
            r.converged,
            r.seconds
        );
    }
    let (median, worst) = summary(&rows);
    println!(
        "median {:.1} %, worst {:.1} %",
        100.0 * median,
        100.0 * worst
    );
    assert!(median < 0.05 && worst < 0.15);
}
