//! The membrane's two laws: finite differences of both on random large deformations
//! (including strong compression), the same small-strain behaviour, and the uniaxial force
//! in compression, which Saint Venant–Kirchhoff loses past s = 1/√3 and Biot keeps.

use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::rng::Lcg;
use furrow::math::Energy;
use furrow::shell::membrane::{MembraneEnergy, MembraneLaw};
use furrow::shell::sheet::equilateral_sheet;
use furrow::shell::ShellMaterial;

fn material() -> ShellMaterial {
    ShellMaterial {
        young: 2.0e6,
        poisson: 0.35,
        thickness: 1.0e-3,
    }
}

fn membrane(law: MembraneLaw) -> (MembraneEnergy, Vec<f64>) {
    let mesh = equilateral_sheet(3, 3, 0.01).mesh;
    let mut m = MembraneEnergy::new(&mesh, &material()).unwrap();
    m.law = law;
    let rest = mesh
        .positions
        .iter()
        .flat_map(|p| [p.x, p.y, p.z])
        .collect();
    (m, rest)
}

/// Rest positions mapped by x ↦ (sx·x, sy·y, z) plus noise of `noise` × the edge.
fn deformed(rest: &[f64], sx: f64, sy: f64, noise: f64, seed: u64) -> Vec<f64> {
    let mut rng = Lcg::from_state(seed);
    rest.chunks(3)
        .flat_map(|p| {
            [
                sx * p[0] + noise * 0.01 * rng.next_signed(),
                sy * p[1] + noise * 0.01 * rng.next_signed(),
                p[2] + noise * 0.01 * rng.next_signed(),
            ]
        })
        .collect()
}

#[test]
fn both_laws_match_finite_differences_in_stretch_and_strong_compression() {
    for law in [MembraneLaw::StVenantKirchhoff, MembraneLaw::Biot] {
        let (m, rest) = membrane(law);
        for (k, (sx, sy)) in [(1.1, 0.93), (0.4, 1.0), (0.25, 0.6)]
            .into_iter()
            .enumerate()
        {
            let x = deformed(&rest, sx, sy, 0.05, 3 + k as u64);
            let g = check_gradient(&m, &x, 0.01);
            let h = check_hessian(&m, &x, 0.01);
            println!(
                "{law:?} ({sx}, {sy}): gradient {:.1e}, Hessian {:.1e}",
                g.rel_error, h.rel_error
            );
            assert!(
                g.rel_error < 1e-6 && h.rel_error < 1e-6,
                "{law:?}: {g:?} {h:?}"
            );
        }
    }
}

#[test]
fn the_laws_agree_at_small_strain() {
    let (a, rest) = membrane(MembraneLaw::StVenantKirchhoff);
    let (b, _) = membrane(MembraneLaw::Biot);
    for eps in [1e-3, 1e-4] {
        let x = deformed(&rest, 1.0 - eps, 1.0 + 0.5 * eps, 0.0, 1);
        let (ea, eb) = (a.eval(&x, None, None, false), b.eval(&x, None, None, false));
        println!("ε = {eps:e}: StVK {ea:.6e} J, Biot {eb:.6e} J");
        // The laws differ at third order in the strain: relative difference O(ε).
        assert!((ea - eb).abs() < 3.0 * eps * ea, "{ea} vs {eb}");
    }
}

/// Uniaxial compression (the sheet free to contract sideways is not needed: the force is
/// the energy's slope in s at fixed lateral stretch 1).
#[test]
fn biot_keeps_its_compressive_force_where_stvk_loses_it() {
    let slope = |law: MembraneLaw, s: f64| {
        let (m, rest) = membrane(law);
        let h = 1e-5;
        let e = |s: f64| m.eval(&deformed(&rest, s, 1.0, 0.0, 1), None, None, false);
        (e(s + h) - e(s - h)) / (2.0 * h)
    };
    let stvk: Vec<f64> = [0.9, 0.58, 0.3]
        .iter()
        .map(|&s| slope(MembraneLaw::StVenantKirchhoff, s))
        .collect();
    let biot: Vec<f64> = [0.9, 0.58, 0.3]
        .iter()
        .map(|&s| slope(MembraneLaw::Biot, s))
        .collect();
    println!("dW/ds at s = 0.9, 0.58, 0.3: StVK {stvk:.4?}, Biot {biot:.4?}");
    // Biot: the resisting force (−dW/ds) grows as the sheet is compressed further.
    assert!(
        biot[0] < 0.0 && biot[1] < biot[0] && biot[2] < biot[1],
        "{biot:?}"
    );
    // StVK: it has fallen again by s = 0.3 (its μ-part peaks at 1/√3 ≈ 0.577).
    assert!(stvk[2] > stvk[1], "{stvk:?}");
}
