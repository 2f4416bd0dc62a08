//! The strip of a dense case: its skin and geometrically graded substrate layers, the
//! mesh-independent geometric imperfection, and the sliding sides and bottom.

use super::case::DenseCase;
use super::mesh::QuadMesh;
use super::svk::PlaneStrainSvk;
use crate::math::rng::Lcg;
use crate::solver::statics::StaticProblem;
use anyhow::Context;

/// The strip mesh of a case for predicted wavelength `lambda` (m), with its element
/// materials (E (Pa), ν): returns (mesh, materials, height of the skin's bottom (m)).
fn strip_mesh(case: &DenseCase, lambda: f64) -> (QuadMesh, Vec<(f64, f64)>, f64) {
    let b = &case.bilayer;
    let h = b.thickness;
    let length = case.periods * lambda;
    let nx = (case.periods * case.elements_per_wavelength as f64).ceil() as usize;
    let dx = length / nx as f64;
    let depth = case.depth * lambda;
    // Substrate layers from the top down: first 0.5 dx, growing by 1.3.
    let mut sub = Vec::new();
    let mut t = 0.5 * dx;
    let mut acc = 0.0;
    while acc + t < depth {
        sub.push(t);
        acc += t;
        t *= 1.3;
    }
    // Stretch the layers so they end exactly at the bottom.
    let scale = depth / acc.max(f64::MIN_POSITIVE);
    let mut ys = vec![0.0];
    for &t in sub.iter().rev() {
        let last = *ys.last().unwrap();
        ys.push(last + t * scale);
    }
    *ys.last_mut().unwrap() = depth;
    let substrate_layers = ys.len() - 1;
    for i in 1..=case.skin_layers {
        ys.push(depth + h * i as f64 / case.skin_layers as f64);
    }
    let mesh = QuadMesh::rectangle(length, nx, &ys);
    let mats = mesh
        .element_row
        .iter()
        .map(|&r| {
            if r >= substrate_layers {
                (b.skin_modulus, b.skin_poisson)
            } else {
                (b.interior_modulus, b.interior_poisson)
            }
        })
        .collect();
    (mesh, mats, depth)
}

/// The dense strip of a case, ready to compress: its imperfect mesh, energy and sliding
/// boundary conditions.
pub(super) struct Strip {
    /// The mesh, with the geometric imperfection applied to its reference positions (m).
    pub(super) mesh: QuadMesh,
    /// The plane-strain SVK energy of the mesh.
    pub(super) energy: PlaneStrainSvk,
    /// Sliding sides and bottom (pinned dofs).
    pub(super) problem: StaticProblem,
    /// Strip length L (m).
    pub(super) length: f64,
}

impl Strip {
    /// The strip of `case` for predicted wavelength `lambda` (m).
    pub(super) fn new(case: &DenseCase, lambda: f64) -> anyhow::Result<Self> {
        let (mut mesh, mats, depth) = strip_mesh(case, lambda);
        let length = case.periods * lambda;
        add_imperfection(&mut mesh, case, length, depth + case.bilayer.thickness);
        let energy = PlaneStrainSvk::new(&mesh, &mats).context("building the dense strip")?;
        let problem = StaticProblem {
            pinned: sliding_pins(&mesh),
            ..Default::default()
        };
        Ok(Self {
            mesh,
            energy,
            problem,
            length,
        })
    }
}

/// Shift the mesh's reference positions by the geometric imperfection. Independent of the
/// mesh: every sliding-compatible mode cos(mπX/L) (strip length `length`, m) with wavelength
/// down to λ/4 gets the same amplitude and a random sign, so the mode that grows is chosen by
/// the mechanics, not by the imperfection; it tapers linearly to zero from the top `top_y`
/// (m) to the bottom.
fn add_imperfection(mesh: &mut QuadMesh, case: &DenseCase, length: f64, top_y: f64) {
    let modes = (8.0 * case.periods).ceil() as usize;
    let mut rng = Lcg::from_state(
        case.seed
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .wrapping_add(17),
    );
    let signs: Vec<f64> = (0..modes).map(|_| rng.next_signed().signum()).collect();
    let amp = case.imperfection * case.bilayer.thickness / (modes as f64).sqrt();
    let eta = |x: f64| -> f64 {
        signs
            .iter()
            .enumerate()
            .map(|(m, s)| s * ((m + 1) as f64 * std::f64::consts::PI * x / length).cos())
            .sum::<f64>()
            * amp
    };
    for p in mesh.nodes.iter_mut() {
        p[1] += eta(p[0]) * (p[1] / top_y);
    }
}

/// The pinned dofs of sliding sides (x pinned) and a sliding bottom (y pinned), sorted.
fn sliding_pins(mesh: &QuadMesh) -> Vec<usize> {
    let mut pinned = Vec::new();
    for r in 0..mesh.rows {
        pinned.push(2 * mesh.node(0, r));
        pinned.push(2 * mesh.node(mesh.columns - 1, r));
    }
    for c in 0..mesh.columns {
        pinned.push(2 * mesh.node(c, 0) + 1);
    }
    pinned.sort_unstable();
    pinned.dedup();
    pinned
}
