//! Wavelength validation on a small grid (the full sweep is `furrow validate wavelength`).

use furrow::validate::slab::{run_slab, SlabSettings};
use furrow::validate::wavelength::{bilayer, zero_crossings};

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
