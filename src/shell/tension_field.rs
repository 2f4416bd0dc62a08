//! The membrane relaxed over wrinkles (tension-field theory, Pipkin 1986; Steigmann 1990),
//! with the compression a wrinkled skin still carries: the force the skin puts on the lattice
//! at a smooth deformation, without solving for its wrinkles.
//!
//! A skin that is free to wrinkle cannot be compressed much further than its buckling load:
//! past it, the excess length goes into wrinkles. With principal stretches s₁ ≥ s₂ of a
//! triangle and the membrane law's principal forces t_i = ∂W/∂s_i (N/m), the relaxed energy
//! per rest area is
//!
//! - taut, t₂(s₁, s₂) ≥ −N_c: W(s₁, s₂);
//! - wrinkled across direction 2: W(s₁, s₂') + N_c (s₂' − s₂), with s₂' > s₂ the stretch at
//!   which t₂(s₁, s₂') = −N_c (the sheet's own width; the wrinkles take the rest at force
//!   N_c), while t₁(s₁, s₂') ≥ −N_c;
//! - wrinkled both ways: W(s*, s*) + N_c (2s* − s₁ − s₂), t(s*, s*) = −N_c.
//!
//! It is the lower envelope of W(s₁', s₂') + N_c Σ (s_i' − s_i) over s_i' ≥ s_i, so its
//! principal forces are t₁ and −N_c (wrinkled) or −N_c twice, continuous across the regimes.
//! N_c = 0 is the classical tension field (a wrinkled sheet carries no compression).
//!
//! N_c is the critical membrane force of the wrinkles the embedded skin forms: its clusters
//! hold every wave longer than the wavelength λ, and a plate bent into a wave of wavenumber
//! k = 2π/λ buckles at N_c = D k² (D = E h³ / 12(1 − ν²)), and holds about that force past
//! buckling (the Euler plateau).

use super::membrane::{MembraneElement, MembraneEnergy, MembraneLaw};
use nalgebra::{Matrix2, Matrix3x2, Vector2, Vector3};
use rayon::prelude::*;

/// Principal stretches below this are floored (a triangle flattened to a segment), where
/// the force's direction is undefined.
const FLAT_STRETCH: f64 = 1e-9;

/// Bisection steps for a relaxed stretch: the bracket (at most a few units of stretch) is
/// then narrower than 1e-12.
const BISECTIONS: usize = 60;

/// Energy per rest area W(s₁, s₂) (J/m²) of `law` with Lamé parameters times thickness
/// (`mu_h`, `lambda_h`, N/m) at principal stretches `s`, and its principal forces
/// ∂W/∂s_i (N/m). The same laws as [`crate::shell::membrane`], written in principal stretches.
pub fn principal_density(
    law: MembraneLaw,
    (mu_h, lambda_h): (f64, f64),
    s: [f64; 2],
) -> (f64, [f64; 2]) {
    match law {
        MembraneLaw::Biot => {
            let d = [s[0] - 1.0, s[1] - 1.0];
            let tr = d[0] + d[1];
            let w = mu_h * (d[0] * d[0] + d[1] * d[1]) + 0.5 * lambda_h * tr * tr;
            let t = d.map(|di| 2.0 * mu_h * di + lambda_h * tr);
            (w, t)
        }
        MembraneLaw::StVenantKirchhoff => {
            let e = s.map(|si| 0.5 * (si * si - 1.0));
            let tr = e[0] + e[1];
            let w = mu_h * (e[0] * e[0] + e[1] * e[1]) + 0.5 * lambda_h * tr * tr;
            let t = [0, 1].map(|i| s[i] * (2.0 * mu_h * e[i] + lambda_h * tr));
            (w, t)
        }
    }
}

/// The smallest root above `from` of `f(s) = −critical` for a force `f` that is below it at
/// `from` and grows past it further on (bisection).
fn relaxed_stretch(from: f64, critical: f64, f: impl Fn(f64) -> f64) -> f64 {
    let (mut lo, mut hi) = (from, from.max(1.0) + 1.0);
    // A law with positive moduli gets there within a few doublings; the bound keeps a
    // degenerate one (no stiffness) from looping.
    for _ in 0..BISECTIONS {
        if f(hi) >= -critical {
            break;
        }
        lo = hi;
        hi *= 2.0;
    }
    for _ in 0..BISECTIONS {
        let mid = 0.5 * (lo + hi);
        if f(mid) < -critical {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// The relaxed energy per rest area (J/m²) at principal stretches `s` (s₁ ≥ s₂) with
/// wrinkling force `critical` (N_c ≥ 0, N/m), and its principal forces (N/m): the module's
/// three regimes.
pub fn relaxed_density(
    law: MembraneLaw,
    lame: (f64, f64),
    critical: f64,
    s: [f64; 2],
) -> (f64, [f64; 2]) {
    let (w, t) = principal_density(law, lame, s);
    if t[1] >= -critical {
        return (w, t);
    }
    let width = relaxed_stretch(s[1], critical, |v| {
        principal_density(law, lame, [s[0], v]).1[1]
    });
    let (w2, t2) = principal_density(law, lame, [s[0], width]);
    if t2[0] >= -critical {
        return (w2 + critical * (width - s[1]), [t2[0], -critical]);
    }
    let both = relaxed_stretch(s[0], critical, |v| {
        principal_density(law, lame, [v, v]).1[0]
    });
    let (w3, _) = principal_density(law, lame, [both, both]);
    (
        w3 + critical * (2.0 * both - s[0] - s[1]),
        [-critical, -critical],
    )
}

/// Relaxed energy (J) of one membrane element at vertex positions `x` (m), with its Lamé
/// parameters times thickness `lame` (N/m) and wrinkling force `critical` (N/m); adds the
/// 9-vector gradient (N) when asked.
pub fn relaxed_element(
    el: &MembraneElement,
    x: [Vector3<f64>; 3],
    (law, lame, critical): (MembraneLaw, (f64, f64), f64),
    grad: Option<&mut [f64; 9]>,
) -> f64 {
    let b = el.b.map(|bi| Vector2::new(bi[0], bi[1]));
    let f: Matrix3x2<f64> = (0..3).map(|i| x[i] * b[i].transpose()).sum();
    let c: Matrix2<f64> = f.transpose() * f;
    let eig = c.symmetric_eigen();
    let (hi, lo) = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        (0, 1)
    } else {
        (1, 0)
    };
    let s = [hi, lo].map(|k| eig.eigenvalues[k].max(0.0).sqrt().max(FLAT_STRETCH));
    let (w, t) = relaxed_density(law, lame, critical, s);
    if let Some(g) = grad {
        // P = ∂W/∂F = Σ t_k u_k v_kᵀ with u_k = F v_k / s_k; gradient_i = A P b_i.
        let p: Matrix3x2<f64> = [hi, lo]
            .iter()
            .zip(t.iter().zip(&s))
            .map(|(&k, (&tk, &sk))| {
                let v = eig.eigenvectors.column(k);
                (tk / sk) * f * v * v.transpose()
            })
            .sum();
        for i in 0..3 {
            let gi = el.area * p * b[i];
            for a in 0..3 {
                g[3 * i + a] += gi[a];
            }
        }
    }
    el.area * w
}

/// The relaxed membrane energy (J) of `membrane` at positions `x` (flat, m) with wrinkling
/// force `critical[t]` (N/m) per triangle; adds its gradient (flat, N) to `grad` when given.
pub fn relaxed_energy(
    membrane: &MembraneEnergy,
    critical: &[f64],
    x: &[f64],
    grad: Option<&mut [f64]>,
) -> f64 {
    let at = |v: usize| Vector3::new(x[3 * v], x[3 * v + 1], x[3 * v + 2]);
    let law = membrane.law;
    let per_element: Vec<(f64, [f64; 9])> = membrane
        .elements
        .par_iter()
        .zip(membrane.element_lame.par_iter().zip(critical.par_iter()))
        .map(|(el, (&lame, &nc))| {
            let mut g = [0.0; 9];
            let e = relaxed_element(el, el.v.map(at), (law, lame, nc), Some(&mut g));
            (e, g)
        })
        .collect();
    if let Some(grad) = grad {
        for (el, (_, g)) in membrane.elements.iter().zip(&per_element) {
            for (k, &v) in el.v.iter().enumerate() {
                for a in 0..3 {
                    grad[3 * v + a] += g[3 * k + a];
                }
            }
        }
    }
    per_element.iter().map(|p| p.0).sum()
}

/// The wrinkling force N_c = D (2π/λ)² (N/m) of a skin of Young's modulus `young` (Pa),
/// Poisson ratio `poisson`, thickness `h` (m) wrinkling at wavelength `lambda` (m).
pub fn critical_force(young: f64, poisson: f64, h: f64, lambda: f64) -> f64 {
    let d = young * h.powi(3) / (12.0 * (1.0 - poisson * poisson));
    let k = 2.0 * std::f64::consts::PI / lambda;
    d * k * k
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shell::membrane::membrane_element;
    use crate::shell::membrane::membrane_rest;

    const LAME: (f64, f64) = (400.0, 600.0);

    fn triangle() -> MembraneElement {
        let p = [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1e-2, 0.0, 0.0),
            Vector3::new(3e-3, 8e-3, 0.0),
        ];
        membrane_rest([0, 1, 2], p).expect("not degenerate")
    }

    /// Positions of the rest triangle stretched by `sx`, `sy` along x and y, then turned
    /// and moved.
    fn deformed(sx: f64, sy: f64) -> [Vector3<f64>; 3] {
        let rot = nalgebra::Rotation3::from_euler_angles(0.3, -0.7, 1.1);
        [
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1e-2 * sx, 0.0, 0.0),
            Vector3::new(3e-3 * sx, 8e-3 * sy, 0.0),
        ]
        .map(|p| rot * p + Vector3::new(0.1, -0.2, 0.05))
    }

    fn energy_and_gradient(x: [Vector3<f64>; 3], law: MembraneLaw, nc: f64) -> (f64, [f64; 9]) {
        let mut g = [0.0; 9];
        let e = relaxed_element(&triangle(), x, (law, LAME, nc), Some(&mut g));
        (e, g)
    }

    /// The gradient is the energy's: central differences over every coordinate, in each
    /// regime (taut, wrinkled one way, both ways) and for both laws.
    #[test]
    fn gradient_matches_finite_differences_in_every_regime() {
        let nc = 5.0;
        for law in [MembraneLaw::Biot, MembraneLaw::StVenantKirchhoff] {
            for (sx, sy) in [(1.1, 1.05), (1.1, 0.9), (0.9, 0.95), (1.02, 0.7)] {
                let x = deformed(sx, sy);
                let (_, g) = energy_and_gradient(x, law, nc);
                let h = 1e-8;
                for k in 0..9 {
                    let (mut a, mut b) = (x, x);
                    a[k / 3][k % 3] += h;
                    b[k / 3][k % 3] -= h;
                    let fd = (energy_and_gradient(a, law, nc).0
                        - energy_and_gradient(b, law, nc).0)
                        / (2.0 * h);
                    let scale = g.iter().fold(0.0f64, |m, v| m.max(v.abs()));
                    assert!(
                        (fd - g[k]).abs() <= 1e-6 * scale,
                        "{law:?} {sx} {sy} dof {k}: fd {fd} vs {}",
                        g[k]
                    );
                }
            }
        }
    }

    /// A taut triangle has the membrane's own energy and gradient.
    #[test]
    fn a_taut_triangle_is_the_membrane() {
        for law in [MembraneLaw::Biot, MembraneLaw::StVenantKirchhoff] {
            let x = deformed(1.1, 1.04);
            let (e, g) = energy_and_gradient(x, law, 5.0);
            let mut gm = [0.0; 9];
            let xs = x.map(|p| [p.x, p.y, p.z]);
            let em = membrane_element(&triangle(), xs, (law, LAME.0, LAME.1), Some(&mut gm), None);
            assert!((e - em).abs() <= 1e-12 * em.abs(), "{law:?} {e} vs {em}");
            for k in 0..9 {
                assert!(
                    (g[k] - gm[k]).abs() <= 1e-9 * gm[k].abs().max(1e-3),
                    "{law:?} {k}"
                );
            }
        }
    }

    /// Compressed across one direction past the wrinkling force, the triangle carries
    /// exactly −N_c across it and the uniaxial tension along the other; compressed both
    /// ways, −N_c both ways; rigid motions change nothing (the forces sum to zero).
    #[test]
    fn wrinkled_triangles_carry_the_critical_force_across_the_wrinkles() {
        let nc = 5.0;
        let law = MembraneLaw::Biot;
        let (mu, la) = LAME;
        let (w, t) = relaxed_density(law, LAME, nc, [1.1, 0.8]);
        assert!((t[1] + nc).abs() < 1e-9, "{t:?}");
        // t₂ = −N_c fixes s₂' − 1 = (−N_c − λ (s₁ − 1)) / (2μ + λ).
        let width = 1.0 + (-nc - la * 0.1) / (2.0 * mu + la);
        let t1 = 2.0 * mu * 0.1 + la * (0.1 + width - 1.0);
        assert!((t[0] - t1).abs() < 1e-6 * t1, "{} vs {t1}", t[0]);
        let taut_at_width = principal_density(law, LAME, [1.1, width]).0;
        assert!((w - taut_at_width - nc * (width - 0.8)).abs() < 1e-9);
        let (_, t) = relaxed_density(law, LAME, nc, [0.9, 0.8]);
        assert_eq!(t, [-nc, -nc]);
        // The classical tension field: a slack triangle has no energy.
        assert_eq!(relaxed_density(law, LAME, 0.0, [0.95, 0.9]).0, 0.0);
        for (sx, sy) in [(1.1, 0.8), (0.9, 0.8)] {
            let (_, g) = energy_and_gradient(deformed(sx, sy), law, nc);
            let sum: Vector3<f64> = (0..3)
                .map(|i| Vector3::new(g[3 * i], g[3 * i + 1], g[3 * i + 2]))
                .sum();
            assert!(sum.norm() < 1e-12, "{sum}");
        }
    }

    /// D k² for a 1 mm skin of 1 MPa wrinkling at 20.2 mm: the demo face's 10.1 N/m.
    #[test]
    fn the_critical_force_of_the_demo_skin() {
        let nc = critical_force(1e6, 0.45, 1e-3, 0.020_221);
        assert!((nc - 10.09).abs() < 0.01, "{nc}");
    }
}
