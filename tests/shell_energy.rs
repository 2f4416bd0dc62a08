//! Physics checks of the thin shell energies: finite differences on random deformed meshes,
//! rigid-motion invariance, and the cylinder bending calibration D/(2R²).

use furrow::math::fd::{check_gradient, check_hessian};
use furrow::math::rng::Lcg;
use furrow::math::Energy;
use furrow::mesh::TriMesh;
use furrow::shell::sheet::equilateral_sheet;
use furrow::shell::{Shell, ShellMaterial};
use nalgebra::{Rotation3, Vector3};

fn material() -> ShellMaterial {
    ShellMaterial {
        young: 2.0e6,
        poisson: 0.35,
        thickness: 1.0e-3,
    }
}

/// A small sheet with a curved, irregular rest shape, and a random large deformation of it.
fn random_case(seed: u64) -> (Shell, Vec<f64>, f64) {
    let a = 0.01;
    let mut rng = Lcg::from_state(seed);
    let mut s = equilateral_sheet(3, 3, a).mesh;
    for p in s.positions.iter_mut() {
        p.x += 0.15 * a * rng.next_signed();
        p.y += 0.15 * a * rng.next_signed();
        p.z += 0.3 * a * rng.next_signed();
    }
    let shell = Shell::new(s.clone(), material()).unwrap();
    let x: Vec<f64> = s
        .positions
        .iter()
        .flat_map(|p| {
            let q = Vector3::new(p.x * 1.1, p.y * 0.93, p.z + 3.0 * (p.x / 0.03).powi(2) * a);
            [
                q.x + 0.2 * a * rng.next_signed(),
                q.y + 0.2 * a * rng.next_signed(),
                q.z + 0.3 * a * rng.next_signed(),
            ]
        })
        .collect();
    (shell, x, a)
}

#[test]
fn fd_gradient_and_hessian_of_every_energy_on_random_deformed_meshes() {
    for seed in [1u64, 7, 42] {
        let (shell, x, a) = random_case(seed);
        let parts: [(&str, &dyn Energy); 3] = [
            ("membrane", &shell.membrane),
            ("bending", &shell.bending),
            ("shell", &shell),
        ];
        for (name, e) in parts {
            let g = check_gradient(e, &x, a);
            let h = check_hessian(e, &x, a);
            println!(
                "seed {seed} {name}: gradient rel err {:.2e} (step {:.0e}), Hessian rel err {:.2e} (step {:.0e})",
                g.rel_error, g.step, h.rel_error, h.step
            );
            assert!(g.rel_error < 1e-6, "{name} gradient {g:?}");
            assert!(h.rel_error < 1e-6, "{name} Hessian {h:?}");
        }
        // The projected Hessian is PSD and equals the exact one where that is already PSD.
        let mut t = Vec::new();
        shell.eval(&x, None, Some(&mut t), true);
        let n = x.len();
        let d = furrow::math::sparse::dense_from_triplets(n, &t);
        let m = nalgebra::DMatrix::from_row_slice(n, n, &d);
        let eig = m.symmetric_eigenvalues();
        let max = eig.max();
        assert!(
            eig.min() > -1e-9 * max,
            "projected Hessian has eigenvalue {}",
            eig.min()
        );
    }
}

#[test]
fn rigid_motions_give_zero_energy_and_force() {
    let (shell, xdef, a) = random_case(3);
    let rot = Rotation3::from_euler_angles(0.7, -1.1, 2.3);
    let t = Vector3::new(0.3, -2.0, 1.5);
    let moved: Vec<f64> = shell
        .rest
        .positions
        .iter()
        .flat_map(|p| {
            let q = rot * p + t;
            [q.x, q.y, q.z]
        })
        .collect();
    let mut g = vec![0.0; moved.len()];
    let e = shell.eval(&moved, Some(&mut g), None, false);
    // Scales: membrane energy of a 1 % strain over the sheet, and the force E h a.
    let mat = material();
    let e_scale = mat.stretch_stiffness() * 1e-4 * shell.rest.area();
    let f_scale = mat.stretch_stiffness() * a;
    let gmax = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    println!("rigid motion: energy {e:.3e} J (scale {e_scale:.1e}), max force {gmax:.3e} N (scale {f_scale:.1e})");
    assert!(e.abs() < 1e-12 * e_scale);
    assert!(gmax < 1e-10 * f_scale);
    // A rigid motion of a deformed state keeps the energy and rotates the forces.
    let mut g0 = vec![0.0; xdef.len()];
    let e0 = shell.eval(&xdef, Some(&mut g0), None, false);
    let xm: Vec<f64> = xdef
        .chunks(3)
        .flat_map(|c| {
            let q = rot * Vector3::new(c[0], c[1], c[2]) + t;
            [q.x, q.y, q.z]
        })
        .collect();
    let mut g1 = vec![0.0; xdef.len()];
    let e1 = shell.eval(&xm, Some(&mut g1), None, false);
    assert!((e1 - e0).abs() < 1e-10 * e0.abs(), "{e0} vs {e1}");
    let gn: f64 = g0.iter().map(|v| v * v).sum::<f64>().sqrt();
    for (c0, c1) in g0.chunks(3).zip(g1.chunks(3)) {
        let r = rot * Vector3::new(c0[0], c0[1], c0[2]);
        assert!((r - Vector3::new(c1[0], c1[1], c1[2])).norm() < 1e-9 * gn);
    }
}

/// Bending energy per unit area of a flat sheet of `nx` × `ny` equilateral cells, edge `a`,
/// wrapped isometrically onto a cylinder of radius `r` (axis along y).
fn cylinder_density(nx: usize, ny: usize, a: f64, r: f64) -> (f64, f64) {
    let sheet = equilateral_sheet(nx, ny, a);
    let shell = Shell::new(sheet.mesh.clone(), material()).unwrap();
    let x: Vec<f64> = sheet
        .mesh
        .positions
        .iter()
        .flat_map(|p| [r * (p.x / r).sin(), p.y, r * (1.0 - (p.x / r).cos())])
        .collect();
    let eb = shell.bending.eval(&x, None, None, false);
    // Area carried by the hinges: a third of each of the two triangles (interior region).
    let m: &TriMesh = &shell.rest;
    let hinge_area: f64 = shell
        .topology
        .hinges
        .iter()
        .map(|h| (m.triangle_area(h.tris[0]) + m.triangle_area(h.tris[1])) / 3.0)
        .sum();
    (eb / hinge_area, eb / m.area())
}

#[test]
fn cylinder_bending_stores_d_over_2r2_and_converges() {
    let d = material().bending_rigidity();
    let r = 0.05;
    let width = r; // the sheet spans one radian of the cylinder
    let exact = d / (2.0 * r * r);
    let mut prev = f64::INFINITY;
    for nx in [10usize, 20, 40, 80] {
        let a = width / nx as f64;
        let ny = (nx as f64 / (3f64.sqrt() / 2.0)).round() as usize;
        let (per_hinge_area, per_area) = cylinder_density(nx, ny, a, r);
        let err = (per_hinge_area / exact - 1.0).abs();
        let err_total = (per_area / exact - 1.0).abs();
        println!(
            "nx {nx:3}: a/R = {:.4}, energy/hinge area = {:.5} D/(2R²) (error {:.3} %), energy/total area error {:.2} %",
            a / r,
            per_hinge_area / exact,
            100.0 * err,
            100.0 * err_total
        );
        assert!(err < prev, "error must fall as the mesh refines");
        prev = err;
        if nx == 80 {
            assert!(err < 0.03, "fine mesh error {err}");
            assert!(
                err_total < 0.05,
                "fine mesh error over total area {err_total}"
            );
        }
    }
}

#[test]
fn cylinder_calibration_does_not_depend_on_bending_direction() {
    let d = material().bending_rigidity();
    let r = 0.05;
    let nx = 40;
    let a = r / nx as f64;
    let ny = (nx as f64 / (3f64.sqrt() / 2.0)).round() as usize;
    let sheet = equilateral_sheet(nx, ny, a);
    let shell = Shell::new(sheet.mesh.clone(), material()).unwrap();
    let m = &shell.rest;
    let hinge_area: f64 = shell
        .topology
        .hinges
        .iter()
        .map(|h| (m.triangle_area(h.tris[0]) + m.triangle_area(h.tris[1])) / 3.0)
        .sum();
    for phi in [0.0f64, 0.3, std::f64::consts::FRAC_PI_2] {
        // Bend about an axis at angle phi from y: s is the arc coordinate across the axis.
        let (c, s) = (phi.cos(), phi.sin());
        let x: Vec<f64> = m
            .positions
            .iter()
            .flat_map(|p| {
                let u = c * p.x + s * p.y;
                let v = -s * p.x + c * p.y;
                let (uu, zz) = (r * (u / r).sin(), r * (1.0 - (u / r).cos()));
                [c * uu - s * v, s * uu + c * v, zz]
            })
            .collect();
        let eb = shell.bending.eval(&x, None, None, false);
        let ratio = eb / hinge_area / (d / (2.0 * r * r));
        println!("axis angle {phi:.2} rad: energy/hinge area = {ratio:.5} D/(2R²)");
        assert!((ratio - 1.0).abs() < 0.03);
    }
}
