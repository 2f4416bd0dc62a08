//! Wavelength validation on a small grid (the full sweep is `furrow validate wavelength`).

use furrow::validate::slab::{run_slab, SlabSettings};
use furrow::validate::wavelength::{bilayer, run_point, run_point_with, summary, zero_crossings};

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

#[test]
#[ignore]
fn explore() {
    let mut s = SlabSettings::new(bilayer(1000.0, 0.3e-3));
    if let Ok(f) = std::env::var("SIGMA") {
        s.sigma_factor = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("NV") {
        s.vertices_per_wavelength = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("EPS") {
        s.compression = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("STEPS") {
        s.steps = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("ONSET") {
        s.onset = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("NOISE") {
        s.noise = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("LEN") {
        s.length = f.parse().unwrap();
    }
    if let Ok(f) = std::env::var("WID") {
        s.width = f.parse().unwrap();
    }
    let r = run_slab(&s).unwrap();
    for (rr, e) in r.rounds.iter().zip(&r.strains) {
        println!("eps {e:.4} {:?} it {} res {:.3e} viol {:.3e} shell {:.2}s coup {:.3}s int {:.3}s int_it {} {:?}", rr.shell.status, rr.shell.iterations, rr.shell.residual, rr.shell.constraint_violation, rr.shell_s, rr.coupling_s, rr.interior_s, rr.interior.iterations, rr.interior.status);
    }
    println!(
        "lambda {:.4e} sigma {:.4e} L {:.4e} verts {} nodes {} clusters {:?} conv {} {:.2}s",
        r.predicted,
        r.sigma,
        r.length,
        r.skin_vertices,
        r.nodes,
        r.clusters,
        r.converged,
        r.seconds
    );
    let c = zero_crossings(&r.profile, 0.1);
    println!(
        "measured {:?} ratio {:?}",
        c,
        c.map(|c| c.wavelength / r.predicted)
    );
    for (x, w) in r.profile.iter().step_by(2) {
        print!("{:.2}:{:+.2e} ", x / r.predicted, w / r.predicted);
    }
    println!();
}

#[test]
#[ignore]
fn transmission() {
    use furrow::coupling::clusters::Clusters;
    use furrow::shell::sheet::equilateral_sheet;
    let a = 1e-3;
    let sheet = equilateral_sheet(140, 160, a);
    let m = &sheet.mesh;
    for sigma in [6e-3, 10e-3] {
        let c = Clusters::build(m, sigma).unwrap();
        let side = 140.0 * a;
        let sidey = 160.0 * a * 0.866;
        for ratio in [1.8, 2.0, 2.2, 2.5, 3.0, std::f64::consts::PI, 4.0] {
            let len = ratio * sigma;
            let mut amp = 0.0;
            let mut count = 0;
            for dir in 0..2 {
                let coord = |p: &nalgebra::Vector3<f64>| if dir == 0 { p.x } else { p.y };
                let fs: Vec<f64> = m
                    .positions
                    .iter()
                    .map(|p| (2.0 * std::f64::consts::PI * coord(p) / len).sin())
                    .collect();
                let fc: Vec<f64> = m
                    .positions
                    .iter()
                    .map(|p| (2.0 * std::f64::consts::PI * coord(p) / len).cos())
                    .collect();
                let hs = c.apply(&fs);
                let hc = c.apply(&fc);
                for (k, &centre) in c.centres.iter().enumerate() {
                    let p = m.positions[centre];
                    if p.x > 3.0 * sigma
                        && p.x < side - 3.0 * sigma
                        && p.y > 3.0 * sigma
                        && p.y < sidey - 3.0 * sigma
                    {
                        amp += (hs[k] * hs[k] + hc[k] * hc[k]).sqrt();
                        count += 1;
                    }
                }
            }
            println!(
                "sigma {sigma} L/sigma {ratio:.3}: T = {:.4}",
                amp / count as f64
            );
        }
    }
}
