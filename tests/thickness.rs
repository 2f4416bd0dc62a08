//! Skin thickness that varies over the skin: per-face thickness in the shell energies
//! (finite differences, bit-identity of the uniform case, the membrane-in-series and
//! cylinder-bending formulas), the scene keys that set it (regions, a vertex attribute, a
//! texture) and their errors, and the wavelength it gives in a simulation.

mod common;

use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::Energy;
use furrow::shell::sheet::equilateral_sheet;
use furrow::shell::{Shell, ShellMaterial};

/// Deterministic pseudo-random numbers in [−1, 1] (64-bit LCG).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 11) as f64 / (1u64 << 53) as f64) * 2.0 - 1.0
    }
}

fn material(poisson: f64) -> ShellMaterial {
    ShellMaterial {
        young: 2.0e6,
        poisson,
        thickness: 1.0e-3,
    }
}

#[test]
fn fd_gradient_and_hessian_with_varying_thickness() {
    for seed in [3u64, 11] {
        let a = 0.01;
        let mut rng = Lcg(seed);
        let mut m = equilateral_sheet(3, 3, a).mesh;
        for p in m.positions.iter_mut() {
            p.x += 0.15 * a * rng.next();
            p.y += 0.15 * a * rng.next();
            p.z += 0.3 * a * rng.next();
        }
        // Thickness from 0.3 to 3 mm, a different value on every face.
        let h: Vec<f64> = (0..m.triangles.len())
            .map(|_| 1e-3 * 10f64.powf(0.5 * rng.next()))
            .collect();
        let shell = Shell::with_thickness(m.clone(), material(0.35), h).unwrap();
        let x: Vec<f64> = m
            .positions
            .iter()
            .flat_map(|p| {
                [
                    1.1 * p.x + 0.2 * a * rng.next(),
                    0.93 * p.y + 0.2 * a * rng.next(),
                    p.z + 3.0 * (p.x / 0.03).powi(2) * a + 0.3 * a * rng.next(),
                ]
            })
            .collect();
        let parts: [(&str, &dyn Energy); 3] = [
            ("membrane", &shell.membrane),
            ("bending", &shell.bending),
            ("shell", &shell),
        ];
        for (name, e) in parts {
            let g = check_gradient(e, &x, a);
            let hh = check_hessian(e, &x, a);
            println!(
                "seed {seed} {name}: gradient rel err {:.2e}, Hessian rel err {:.2e}",
                g.rel_error, hh.rel_error
            );
            assert!(g.rel_error < 1e-6, "{name} gradient {g:?}");
            assert!(hh.rel_error < 1e-6, "{name} Hessian {hh:?}");
        }
    }
}

#[test]
fn uniform_thickness_is_bit_identical_and_bad_lists_are_refused() {
    let m = equilateral_sheet(4, 4, 0.01).mesh;
    let mat = material(0.4);
    let a = Shell::new(m.clone(), mat).unwrap();
    let b = Shell::with_thickness(m.clone(), mat, vec![mat.thickness; m.triangles.len()]).unwrap();
    let mut rng = Lcg(5);
    let x: Vec<f64> = m
        .flat_positions()
        .iter()
        .map(|v| v + 2e-3 * rng.next())
        .collect();
    let (mut ga, mut gb) = (vec![0.0; x.len()], vec![0.0; x.len()]);
    let (mut ha, mut hb) = (Vec::new(), Vec::new());
    let ea = a.eval(&x, Some(&mut ga), Some(&mut ha), true);
    let eb = b.eval(&x, Some(&mut gb), Some(&mut hb), true);
    assert_eq!(ea.to_bits(), eb.to_bits());
    assert!(ga.iter().zip(&gb).all(|(p, q)| p.to_bits() == q.to_bits()));
    assert!(ha
        .iter()
        .zip(&hb)
        .all(|(p, q)| p.0 == q.0 && p.1 == q.1 && p.2.to_bits() == q.2.to_bits()));
    let err = Shell::with_thickness(m.clone(), mat, vec![1e-3; 3]).unwrap_err();
    assert!(format!("{err}").contains("triangles"), "{err}");
    let mut h = vec![1e-3; m.triangles.len()];
    h[7] = 0.0;
    let err = Shell::with_thickness(m.clone(), mat, h).unwrap_err();
    assert!(format!("{err}").contains("triangle 7"), "{err}");
}

/// A sheet whose faces below `y_mid` have thickness `h1`, the rest `h2`.
fn two_halves(
    nx: usize,
    ny: usize,
    a: f64,
    h1: f64,
    h2: f64,
) -> (furrow::mesh::TriMesh, f64, Vec<f64>) {
    let sheet = equilateral_sheet(nx, ny, a);
    let m = sheet.mesh;
    let y_mid = (ny / 2) as f64 * a * 3f64.sqrt() / 2.0;
    let h = m
        .triangles
        .iter()
        .map(|t| {
            let cy = t.iter().map(|&v| m.positions[v].y).sum::<f64>() / 3.0;
            if cy < y_mid {
                h1
            } else {
                h2
            }
        })
        .collect();
    (m, y_mid, h)
}

/// Membrane in series: a strip of thickness h1 then h2 (along y) pulled along y carries the
/// same force per unit width N in both halves, so with ν = 0 each half is in uniform uniaxial
/// stress with first Piola–Kirchhoff stress s E h_i G_i = N (stretch s_i, Green strain
/// G_i = (s_i² − 1)/2): the strains go as 1/h. Deforming each half by its own stretch must
/// leave every vertex not on the pulled ends in equilibrium (zero force), and the end force
/// must be N per unit width. Equal strains instead leave an unbalanced force on the step.
#[test]
fn membrane_in_series_strains_scale_as_one_over_thickness() {
    let (a, nx, ny) = (0.002, 10, 12);
    let (h1, h2) = (0.5e-3, 1.5e-3);
    let mat = material(0.0);
    let (m, y_mid, h) = two_halves(nx, ny, a, h1, h2);
    let shell = Shell::with_thickness(m.clone(), mat, h).unwrap();
    let e = mat.young;
    let s1: f64 = 1.01;
    let n = s1 * e * h1 * 0.5 * (s1 * s1 - 1.0);
    // Solve s2 (E h2 (s³ − s)/2 = N) by Newton.
    let mut s2: f64 = 1.0 + (s1 - 1.0) * h1 / h2;
    for _ in 0..50 {
        let f = e * h2 * 0.5 * (s2.powi(3) - s2) - n;
        s2 -= f / (e * h2 * 0.5 * (3.0 * s2 * s2 - 1.0));
    }
    let strain_ratio = (s1 - 1.0) / (s2 - 1.0);
    println!(
        "strain thin/thick = {strain_ratio:.4} (h2/h1 = {:.4}); N = {n:.4} N/m",
        h2 / h1
    );
    assert!((strain_ratio / (h2 / h1) - 1.0).abs() < 0.02);
    let y_top = ny as f64 * a * 3f64.sqrt() / 2.0;
    let deform = |s_lo: f64, s_hi: f64| -> Vec<f64> {
        m.positions
            .iter()
            .flat_map(|p| {
                let y = if p.y <= y_mid {
                    s_lo * p.y
                } else {
                    s_lo * y_mid + s_hi * (p.y - y_mid)
                };
                [p.x, y, 0.0]
            })
            .collect()
    };
    let residual = |x: &[f64]| -> (f64, f64) {
        let mut g = vec![0.0; x.len()];
        shell.eval(x, Some(&mut g), None, false);
        let mut interior: f64 = 0.0;
        let mut top = 0.0;
        for (v, p) in m.positions.iter().enumerate() {
            if p.y == 0.0 {
                continue;
            }
            if (p.y - y_top).abs() < 1e-12 {
                top += g[3 * v + 1]; // the applied pull balances ∇E
                continue;
            }
            for c in 0..3 {
                interior = interior.max(g[3 * v + c].abs());
            }
        }
        (interior, top)
    };
    let width = nx as f64 * a;
    let (res, top) = residual(&deform(s1, s2));
    println!(
        "series stretches: largest interior force {res:.3e} N, end force {top:.6} N vs N w = {:.6} N",
        n * width
    );
    assert!((top / (n * width) - 1.0).abs() < 1e-9);
    assert!(res < 1e-9 * n * a, "interior residual {res}");
    let (res_eq, _) = residual(&deform(s1, s1));
    println!("equal stretches: largest interior force {res_eq:.3e} N");
    assert!(res_eq > 0.1 * n * a);
}

/// A sheet of thicknesses h1 (lower half) and h2 (upper half) wrapped onto a cylinder stores
/// D(h_i)/(2R²) per unit area in each half: the total is (A1 D1 + A2 D2)/(2R²) to the same
/// discretisation error as the uniform calibration (tests/shell_energy.rs: 0.4 % at a/R =
/// 1/80), both for the axis along the step (x) and across it (y).
#[test]
fn cylinder_bending_per_half_is_d_of_h_over_2r2() {
    let r = 0.05;
    let nx = 60;
    let a = r / nx as f64;
    let ny = 2 * ((nx as f64 / (3f64.sqrt() / 2.0) / 2.0).round() as usize);
    let (h1, h2) = (0.4e-3, 1.2e-3);
    let mat = material(0.3);
    let (m, y_mid, h) = two_halves(nx, ny, a, h1, h2);
    let shell = Shell::with_thickness(m.clone(), mat, h.clone()).unwrap();
    let d = |hh: f64| {
        ShellMaterial {
            thickness: hh,
            ..mat
        }
        .bending_rigidity()
    };
    // Hinge-area-weighted expectation, so that the boundary rows (no hinges) do not count.
    let mut expect_area = [0.0; 2];
    for hg in &shell.topology.hinges {
        for &t in &hg.tris {
            let i = usize::from(h[t] != h1);
            expect_area[i] += m.triangle_area(t) / 3.0;
        }
    }
    for axis_along_x in [false, true] {
        let x: Vec<f64> = m
            .positions
            .iter()
            .flat_map(|p| {
                if axis_along_x {
                    let s = p.y - y_mid;
                    [p.x, y_mid + r * (s / r).sin(), r * (1.0 - (s / r).cos())]
                } else {
                    [r * (p.x / r).sin(), p.y, r * (1.0 - (p.x / r).cos())]
                }
            })
            .collect();
        let eb = shell.bending.eval(&x, None, None, false);
        let exact = (expect_area[0] * d(h1) + expect_area[1] * d(h2)) / (2.0 * r * r);
        let err = eb / exact - 1.0;
        // A uniform skin of the mean thickness, for scale.
        let hm = 0.5 * (h1 + h2);
        let naive = (expect_area[0] + expect_area[1]) * d(hm) / (2.0 * r * r);
        println!(
            "axis along {}: E = {eb:.6e} J, (A1 D1 + A2 D2)/(2R²) = {exact:.6e} J, error {:.3} % \
             (a uniform skin of the mean h: {:.1} % off)",
            if axis_along_x {
                "x (parallel to the step)"
            } else {
                "y (across the step)"
            },
            100.0 * err,
            100.0 * (naive / exact - 1.0)
        );
        assert!(err.abs() < 0.01, "error {err}");
    }
}
