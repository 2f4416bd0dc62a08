//! Wavelength validation on a small grid (the full sweep is `furrow validate wavelength`).

use furrow::validate::slab::{run_slab, SlabSettings};
use furrow::validate::wavelength::{bilayer, zero_crossings};

#[test]
#[ignore]
fn explore() {
    let mut s = SlabSettings::new(bilayer(1000.0, 0.3e-3));
    if let Ok(f) = std::env::var("SIGMA") { s.sigma_factor = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("NV") { s.vertices_per_wavelength = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("EPS") { s.compression = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("STEPS") { s.steps = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("ONSET") { s.onset = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("NOISE") { s.noise = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("LEN") { s.length = f.parse().unwrap(); }
    if let Ok(f) = std::env::var("WID") { s.width = f.parse().unwrap(); }
    let r = run_slab(&s).unwrap();
    for (rr, e) in r.rounds.iter().zip(&r.strains) {
        println!("eps {e:.4} {:?} it {} res {:.3e} viol {:.3e} shell {:.2}s coup {:.3}s int {:.3}s int_it {} {:?}", rr.shell.status, rr.shell.iterations, rr.shell.residual, rr.shell.constraint_violation, rr.shell_s, rr.coupling_s, rr.interior_s, rr.interior.iterations, rr.interior.status);
    }
    println!("lambda {:.4e} sigma {:.4e} L {:.4e} verts {} nodes {} clusters {:?} conv {} {:.2}s", r.predicted, r.sigma, r.length, r.skin_vertices, r.nodes, r.clusters, r.converged, r.seconds);
    let c = zero_crossings(&r.profile, 0.1);
    println!("measured {:?} ratio {:?}", c, c.map(|c| c.wavelength / r.predicted));
    for (x, w) in r.profile.iter().step_by(2) { print!("{:.2}:{:+.2e} ", x / r.predicted, w / r.predicted); }
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
                let fs: Vec<f64> = m.positions.iter().map(|p| (2.0 * std::f64::consts::PI * coord(p) / len).sin()).collect();
                let fc: Vec<f64> = m.positions.iter().map(|p| (2.0 * std::f64::consts::PI * coord(p) / len).cos()).collect();
                let hs = c.apply(&fs);
                let hc = c.apply(&fc);
                for (k, &centre) in c.centres.iter().enumerate() {
                    let p = m.positions[centre];
                    if p.x > 3.0 * sigma && p.x < side - 3.0 * sigma && p.y > 3.0 * sigma && p.y < sidey - 3.0 * sigma {
                        amp += (hs[k] * hs[k] + hc[k] * hc[k]).sqrt();
                        count += 1;
                    }
                }
            }
            println!("sigma {sigma} L/sigma {ratio:.3}: T = {:.4}", amp / count as f64);
        }
    }
}
