//! The flat test sheet rig: a square sheet with one blend shape that compresses its left
//! half and stretches its right half, for sweeps and tests that need a rig without a file.

use crate::io::load::{load_bytes, LoadOptions, Rig};
use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use std::path::Path;

/// A flat test sheet rig (see [`sheet_rig`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SheetRig {
    /// Quads per side (the sheet has 2 n² triangles).
    pub n: usize,
    /// Side length (m).
    pub size: f64,
    /// Strain of the blend shape at weight 1: the left half is compressed by it along x, the
    /// right half stretched by it (dimensionless).
    pub strain: f64,
    /// Weight of the blend shape at the end of the clip (1 = the full shape; −0.5 and 2 test
    /// extrapolated weights).
    pub weight: f64,
    /// Clip length (s): the weight ramps linearly from 0 at t = 0 to `weight`.
    pub seconds: f64,
    /// Make two near-zero-area triangles: move vertex (n/2, n/2) along x by (1 − `sliver`)
    /// of an edge, so the triangles it shares with the vertex on its right have area
    /// ½ `sliver` ℓ² (ℓ the edge, m). `None`: a regular sheet.
    pub sliver: Option<f64>,
    /// Seconds the final weight is held after the ramp (the clip then lasts `seconds` +
    /// `hold`).
    pub hold: f64,
}

impl Default for SheetRig {
    /// 24 × 24 quads over 10 cm, 15 % strain reached in 0.3 s.
    fn default() -> Self {
        Self {
            n: 24,
            size: 0.1,
            strain: 0.15,
            weight: 1.0,
            seconds: 0.3,
            sliver: None,
            hold: 0.0,
        }
    }
}

/// A flat sheet rig (x, y in [0, size], z = 0, facing +z) with one blend shape "squeeze"
/// that compresses the left half along x and stretches the right half (see [`SheetRig`]),
/// loaded as a [`Rig`] (its path is `sheet.glb`, only used in messages).
pub fn sheet_rig(s: &SheetRig) -> anyhow::Result<Rig> {
    anyhow::ensure!(s.n >= 2, "the sheet needs at least 2 quads per side");
    let n = s.n;
    let h = s.size / n as f64;
    let mut pos = Vec::new();
    for j in 0..=n {
        for i in 0..=n {
            pos.push(Vector3::new(h * i as f64, h * j as f64, 0.0));
        }
    }
    let id = |i: usize, j: usize| j * (n + 1) + i;
    if let Some(eps) = s.sliver {
        pos[id(n / 2, n / 2)].x += (1.0 - eps) * h;
    }
    let mut tris = Vec::new();
    for j in 0..n {
        for i in 0..n {
            tris.push([id(i, j), id(i + 1, j), id(i + 1, j + 1)]);
            tris.push([id(i, j), id(i + 1, j + 1), id(i, j + 1)]);
        }
    }
    let mid = s.size / 2.0;
    let deltas: Vec<Vector3<f64>> = pos
        .iter()
        .map(|p| Vector3::new((p.x - mid).abs() * s.strain, 0.0, 0.0))
        .collect();
    let mesh = TriMesh::new(pos, tris);
    let mut keys = WeightKeys {
        times: vec![0.0, s.seconds],
        weights: vec![vec![0.0], vec![s.weight]],
    };
    if s.hold > 0.0 {
        keys.times.push(s.seconds + s.hold);
        keys.weights.push(vec![s.weight]);
    }
    let target = MorphTarget {
        name: "squeeze".into(),
        positions: deltas,
        normals: None,
    };
    let bytes = crate::io::export::rig_glb("sheet", &mesh, &[target], &keys)?;
    Ok(load_bytes(
        Path::new("sheet.glb"),
        &bytes,
        &LoadOptions::default(),
    )?)
}
