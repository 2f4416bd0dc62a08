//! Quasi-static checks of the shell with the constrained Newton solver: uniaxial tension
//! against the exact relations of both membrane laws (Biot and StVK, plane stress), and
//! Euler buckling of a pinned strip.

use furrow::math::Energy;
use furrow::shell::membrane::MembraneLaw;
use furrow::shell::sheet::{equilateral_sheet, Sheet};
use furrow::shell::{Shell, ShellMaterial};
use furrow::solver::{LinearConstraints, SolveStatus, StaticProblem, StaticSettings, StaticSolver};

/// Nodal forces on the end x = L of `sheet`: total force `fx` (N) along x, spread by the
/// tributary length of each end vertex (the consistent load of a uniform traction).
fn end_forces(sheet: &Sheet, fx: f64) -> Vec<f64> {
    let p = &sheet.mesh.positions;
    let ends: Vec<usize> = sheet.rows.iter().map(|r| *r.last().unwrap()).collect();
    let ys: Vec<f64> = ends.iter().map(|&v| p[v].y).collect();
    let b = ys.last().unwrap() - ys[0];
    let mut f = vec![0.0; 3 * p.len()];
    for (k, &v) in ends.iter().enumerate() {
        let lo = if k > 0 { ys[k] - ys[k - 1] } else { 0.0 };
        let hi = if k + 1 < ys.len() {
            ys[k + 1] - ys[k]
        } else {
            0.0
        };
        f[3 * v] = fx * 0.5 * (lo + hi) / b;
    }
    f
}

/// Solve the sheet under end force `fx`, left end on rollers (x pinned), vertex 0 pinned
/// in y, all z pinned; `pin_lateral` pins every y too (uniaxial strain). Returns the mean
/// axial strain of the loaded end and the lateral strain.
fn tension(fx: f64, pin_lateral: bool, mat: ShellMaterial, law: MembraneLaw) -> (f64, f64) {
    let sheet = equilateral_sheet(8, 4, 0.01);
    let mut shell = Shell::new(sheet.mesh.clone(), mat).unwrap();
    shell.membrane.law = law;
    let n = sheet.mesh.vertex_count();
    let mut pinned: Vec<usize> = sheet.rows.iter().map(|r| 3 * r[0]).collect();
    pinned.push(1);
    for v in 0..n {
        pinned.push(3 * v + 2);
        if pin_lateral && v != 0 {
            pinned.push(3 * v + 1);
        }
    }
    let problem = StaticProblem {
        pinned,
        constraints: LinearConstraints::none(),
        forces: end_forces(&sheet, fx),
    };
    let tol = 1e-12 * mat.stretch_stiffness() * 0.01;
    let mut solver = StaticSolver::new(StaticSettings {
        tolerance: tol,
        ..Default::default()
    })
    .unwrap();
    let mut x = sheet.mesh.flat_positions();
    let rep = solver.solve(&shell, &problem, &mut x).unwrap();
    assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
    let l = 0.08;
    let ends: Vec<usize> = sheet.rows.iter().map(|r| *r.last().unwrap()).collect();
    let ex = ends.iter().map(|&v| x[3 * v] / l - 1.0).sum::<f64>() / ends.len() as f64;
    let top = *sheet.rows.last().unwrap().first().unwrap();
    let y0 = sheet.mesh.positions[top].y;
    let ey = x[3 * top + 1] / y0 - 1.0;
    println!(
        "tension fx = {fx:.4e} N (lateral pinned: {pin_lateral}): strain {ex:.6e}, lateral {ey:.6e}, {} Newton iterations, residual {:.1e} N",
        rep.iterations, rep.residual
    );
    (ex, ey)
}

#[test]
fn uniaxial_tension_reaches_the_predicted_strain() {
    let mat = ShellMaterial {
        young: 1.0e6,
        poisson: 0.3,
        thickness: 1.0e-3,
    };
    let (e, nu, h) = (mat.young, mat.poisson, mat.thickness);
    let b = 4.0 * 0.01 * 3f64.sqrt() / 2.0;
    // Small strain: linear theory, ε = F / (E h b) free lateral, F (1 − ν²) / (E h b) pinned.
    for (pin, modulus) in [(false, e), (true, e / (1.0 - nu * nu))] {
        let eps = 1e-4;
        let (ex, ey) = tension(modulus * h * b * eps, pin, mat, MembraneLaw::default());
        assert!((ex / eps - 1.0).abs() < 0.01, "linear strain {ex} vs {eps}");
        if !pin {
            assert!((ey / (-nu * eps) - 1.0).abs() < 0.01, "lateral {ey}");
        }
    }
    // 1 % strain: the exact StVK relation, nominal stress (1 + ε) M (ε + ε²/2) with
    // M = E (free lateral, Green strain E22 = −ν E11) or E / (1 − ν²) (lateral pinned).
    for (pin, modulus) in [(false, e), (true, e / (1.0 - nu * nu))] {
        let eps: f64 = 0.01;
        let p = (1.0 + eps) * modulus * (eps + 0.5 * eps * eps);
        let (ex, ey) = tension(p * h * b, pin, mat, MembraneLaw::StVenantKirchhoff);
        assert!((ex / eps - 1.0).abs() < 1e-6, "StVK strain {ex} vs {eps}");
        if !pin {
            let e11 = eps + 0.5 * eps * eps;
            let lat = (1.0 - 2.0 * nu * e11).sqrt() - 1.0;
            assert!((ey / lat - 1.0).abs() < 1e-6, "lateral {ey} vs {lat}");
        } else {
            assert!(ey.abs() < 1e-12);
        }
    }
    // 5 % strain: Biot's exact relation is linear in the stretch, nominal stress M ε, and the
    // free lateral stretch is −ν ε.
    for (pin, modulus) in [(false, e), (true, e / (1.0 - nu * nu))] {
        let eps: f64 = 0.05;
        let (ex, ey) = tension(modulus * eps * h * b, pin, mat, MembraneLaw::Biot);
        assert!((ex / eps - 1.0).abs() < 1e-6, "Biot strain {ex} vs {eps}");
        if !pin {
            assert!((ey / (-nu * eps) - 1.0).abs() < 1e-6, "lateral {ey}");
        }
    }
}

/// A strip of length L = nx a (x), ny rows of triangles, simply supported at both ends
/// (z = 0 on the end lines, x pinned at x = 0, compressive force P at x = L). Rows
/// ny − 1 and ny repeat rows 0 and 1 in z through linear constraints, which makes the strip
/// one period of an infinitely wide plate: no anticlastic curvature, so the buckling load is
/// the cylindrical-bending Euler load π² D b / L² (b = ny · a √3/2, ν = 0).
struct Strip {
    sheet: Sheet,
    shell: Shell,
    length: f64,
    width: f64,
    pinned: Vec<usize>,
    constraints: LinearConstraints,
}

fn strip(mat: ShellMaterial) -> Strip {
    let (nx, ny, a) = (40usize, 5usize, 0.0025);
    let sheet = equilateral_sheet(nx, ny, a);
    let shell = Shell::new(sheet.mesh.clone(), mat).unwrap();
    let mut pinned = vec![1usize];
    for r in &sheet.rows {
        let (first, last) = (r[0], *r.last().unwrap());
        pinned.extend([3 * first, 3 * first + 2, 3 * last + 2]);
    }
    let mut c = LinearConstraints::none();
    for (src, dst) in [(0usize, ny - 1), (1, ny)] {
        let (rs, rd) = (&sheet.rows[src], &sheet.rows[dst]);
        assert_eq!(rs.len(), rd.len());
        // End vertices are already pinned in z; tie the interior ones.
        for k in 1..rs.len() - 1 {
            c.entries.push((c.rows, 3 * rd[k] + 2, 1.0));
            c.entries.push((c.rows, 3 * rs[k] + 2, -1.0));
            c.rhs.push(0.0);
            c.rows += 1;
        }
    }
    let width = ny as f64 * a * 3f64.sqrt() / 2.0;
    Strip {
        sheet,
        shell,
        length: nx as f64 * a,
        width,
        pinned,
        constraints: c,
    }
}

/// Complete elliptic integral of the first kind K(k) by the arithmetic-geometric mean.
fn elliptic_k(k: f64) -> f64 {
    let (mut a, mut b) = (1.0f64, (1.0 - k * k).sqrt());
    for _ in 0..30 {
        let (an, bn) = (0.5 * (a + b), (a * b).sqrt());
        a = an;
        b = bn;
    }
    std::f64::consts::PI / (2.0 * a)
}

/// Midspan deflection / length of the pinned–pinned inextensible elastica at load ratio
/// P/Pcr (0 below 1): K(k) = (π/2) √(P/Pcr), δ/L = k / K(k).
fn elastica_deflection(ratio: f64) -> f64 {
    if ratio <= 1.0 {
        return 0.0;
    }
    let target = 0.5 * std::f64::consts::PI * ratio.sqrt();
    let (mut lo, mut hi) = (0.0f64, 0.999999f64);
    for _ in 0..80 {
        let mid = 0.5 * (lo + hi);
        if elliptic_k(mid) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let k = 0.5 * (lo + hi);
    k / elliptic_k(k)
}

fn midspan_deflection(s: &Strip, x: &[f64]) -> f64 {
    let row = &s.sheet.rows[2];
    let mid = row[row.len() / 2];
    x[3 * mid + 2]
}

#[test]
fn pinned_strip_buckles_at_the_euler_load() {
    let mat = ShellMaterial {
        young: 1.0e6,
        poisson: 0.0,
        thickness: 2.0e-4,
    };
    let s = strip(mat);
    let d = mat.bending_rigidity();
    let p_euler = std::f64::consts::PI.powi(2) * d * s.width / s.length.powi(2);
    let tol = 1e-7 * p_euler;
    let mut solver = StaticSolver::new(StaticSettings {
        tolerance: tol,
        max_iterations: 300,
        ..Default::default()
    })
    .unwrap();
    let rest = s.sheet.mesh.flat_positions();
    let stable_at = |load: f64, solver: &mut StaticSolver| -> bool {
        let problem = StaticProblem {
            pinned: s.pinned.clone(),
            constraints: s.constraints.clone(),
            forces: end_forces(&s.sheet, -load),
        };
        let mut x = rest.clone();
        let rep = solver.solve(&s.shell, &problem, &mut x).unwrap();
        assert_eq!(rep.status, SolveStatus::Converged, "{rep:?}");
        assert!(
            midspan_deflection(&s, &x).abs() < 1e-12,
            "flat state expected"
        );
        solver.stability(&s.shell, &problem, &x).unwrap().inertia_ok
    };
    // Onset: the flat equilibrium stops being a minimum where the constrained Hessian gets
    // a negative eigenvalue (inertia of the KKT factorisation); bisect on the load.
    let (mut lo, mut hi) = (0.5 * p_euler, 1.5 * p_euler);
    assert!(stable_at(lo, &mut solver));
    assert!(!stable_at(hi, &mut solver));
    for _ in 0..14 {
        let mid = 0.5 * (lo + hi);
        if stable_at(mid, &mut solver) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let p_cr = 0.5 * (lo + hi);
    println!(
        "buckling load {p_cr:.6e} N, Euler π² D b / L² = {p_euler:.6e} N, ratio {:.4}",
        p_cr / p_euler
    );
    assert!((p_cr / p_euler - 1.0).abs() < 0.05);
    assert_eq!(
        solver.symbolic_analyses(),
        1,
        "one symbolic analysis for all loads"
    );

    // Below the load a perturbed strip returns flat; above it the equilibrium found from the
    // same perturbation is buckled, with the exact elastica amplitude δ/L = k / K(k) where
    // K(k) = (π/2) √(P/Pcr) (K the complete elliptic integral of the first kind).
    // Out-of-plane motion needs the energy merit in the line search (see solver::linesearch).
    solver.settings.energy_merit = true;
    let mut perturbed = rest.clone();
    for (i, v) in s.sheet.mesh.positions.iter().enumerate() {
        perturbed[3 * i + 2] = 1e-3 * s.length * (std::f64::consts::PI * v.x / s.length).sin();
    }
    for (ratio, buckled) in [(0.9, false), (1.1, true)] {
        let problem = StaticProblem {
            pinned: s.pinned.clone(),
            constraints: s.constraints.clone(),
            forces: end_forces(&s.sheet, -ratio * p_cr),
        };
        let mut x = perturbed.clone();
        let rep = solver.solve(&s.shell, &problem, &mut x).unwrap();
        let w = midspan_deflection(&s, &x).abs() / s.length;
        let predicted = elastica_deflection(ratio);
        println!(
            "P = {ratio} Pcr: status {:?}, {} iterations ({} with modified Hessian), midspan deflection {w:.4e} L (elastica {predicted:.4e} L)",
            rep.status, rep.iterations, rep.modified_hessian_steps
        );
        assert_eq!(rep.status, SolveStatus::Converged);
        if buckled {
            assert!(
                (w / predicted - 1.0).abs() < 0.02,
                "buckled amplitude {w} vs {predicted}"
            );
            assert!(
                solver.stability(&s.shell, &problem, &x).unwrap().inertia_ok,
                "buckled state is stable"
            );
        } else {
            // Perturbation 1e-3 L; the residual tolerance allows ~1e-6 L of soft-mode error.
            assert!(w < 1e-6, "flat expected below the load, got {w}");
        }
    }
    let _ = s.shell.dofs();
}
