//! `furrow bench fit`: the activation fit with 52 muscles on a lattice of a few hundred
//! elements.

use super::fit::{FitSettings, Fitter};
use super::generate::{generate_muscles, synthetic_arkit_targets, BlendShapes, GenerateSettings};
use super::samples::{ShapeSamples, SAMPLE_LEVELS};
use crate::fem::{Interior, Material};
use crate::lattice::{Lattice, LatticeSettings};
use crate::math::rng::Lcg;
use nalgebra::Vector3;
use std::time::Instant;

/// Weights of `n` shapes over `frames` frames at 30 fps: each shape follows its own slow
/// sinusoid (0.2–1 Hz), clipped to [0, 1], so that several shapes are active at once.
pub fn synthetic_clip(n: usize, frames: usize, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = Lcg::new(seed);
    let params: Vec<(f64, f64, f64)> = (0..n)
        .map(|_| {
            (
                0.2 + 0.8 * rng.next_f64(),
                std::f64::consts::TAU * rng.next_f64(),
                0.3 + 0.7 * rng.next_f64(),
            )
        })
        .collect();
    (0..frames)
        .map(|k| {
            let t = k as f64 / 30.0;
            params
                .iter()
                .map(|&(f, ph, amp)| {
                    (amp * (std::f64::consts::TAU * f * t + ph).sin()).clamp(0.0, 1.0)
                })
                .collect()
        })
        .collect()
}

/// Run the fit benchmark and return its measurements as a flat JSON object.
///
/// The procedural face rig (`rig::face::generate()`, ~10k vertices) gets a lattice of about
/// `target_cells` grid cells and the 52 synthetic ARKit shapes
/// ([`super::generate::synthetic_arkit_targets`], 2 mm bumps of 2 cm radius), from which 52
/// muscles are generated (`generate_s`). `jacobian_s` is the rest Jacobian (one
/// factorisation, 52 solves, the products with B and JᵀJ); a 335-frame clip of
/// [`synthetic_clip`] weights is then fitted with the linear model: `qp_ms_mean`/`max` are
/// the QP times per frame (Jᵀd, clarabel and the polish), `frame_ms_mean` the whole frame
/// (with the residual), `clip_s` = `jacobian_s` + all frames (targets blended beforehand).
/// `gauss_newton1_frame_s` is the mean time of a frame with one Gauss–Newton
/// re-linearisation (two nonlinear equilibria and one Jacobian), over `gn_frames` frames.
pub fn bench_fit(target_cells: usize, gn_frames: usize) -> anyhow::Result<serde_json::Value> {
    let rig = crate::rig::face::generate();
    let lattice = Lattice::build(
        &rig.mesh,
        &LatticeSettings {
            target_cells: Some(target_cells),
            ..Default::default()
        },
    )?;
    let material = Material::default();
    let interior = Interior::new(&lattice, &material)?;
    let targets = synthetic_arkit_targets(&rig.mesh, 0.002, 0.02, 7);
    let samples = ShapeSamples::subdivided(&lattice, &rig.mesh, SAMPLE_LEVELS)?;
    let t = Instant::now();
    let generated = generate_muscles(
        &lattice,
        &interior,
        BlendShapes {
            targets: &targets,
            samples: &samples,
        },
        None,
        &GenerateSettings::default(),
    )?;
    let generate_s = t.elapsed().as_secs_f64();
    let source = generated.source.clone();
    let t = Instant::now();
    let mut fitter = Fitter::new(
        &lattice,
        &material,
        generated.muscles,
        FitSettings::default(),
    )?;
    let setup_s = t.elapsed().as_secs_f64();
    let frames = 335;
    let weights = synthetic_clip(targets.len(), frames, 1);
    let blend = |w: &[f64]| -> Vec<Vector3<f64>> {
        let mut p = rig.mesh.positions.clone();
        for (t, &wt) in targets.iter().zip(w) {
            if wt != 0.0 {
                for (pi, d) in p.iter_mut().zip(&t.positions) {
                    *pi += d * wt;
                }
            }
        }
        p
    };
    let frames_xyz: Vec<Vec<Vector3<f64>>> = weights.iter().map(|w| blend(w)).collect();
    let t = Instant::now();
    let mut qp = Vec::with_capacity(frames);
    let mut rms_sum = 0.0;
    let mut failed = 0;
    for x in &frames_xyz {
        let f = fitter.fit_frame(x)?;
        qp.push(f.qp_s);
        rms_sum += f.rms_residual;
        failed += usize::from(f.status != super::fit::FrameStatus::Fitted);
    }
    let frames_s = t.elapsed().as_secs_f64();
    let target_rms = frames_xyz
        .iter()
        .map(|x| {
            (x.iter()
                .zip(&rig.mesh.positions)
                .map(|(a, b)| (a - b).norm_squared())
                .sum::<f64>()
                / x.len() as f64)
                .sqrt()
        })
        .sum::<f64>()
        / frames as f64;
    let mut gn_s = 0.0;
    if gn_frames > 0 {
        fitter.settings.gauss_newton = 1;
        fitter.reset();
        let t = Instant::now();
        for x in frames_xyz.iter().take(gn_frames) {
            fitter.fit_frame(x)?;
        }
        gn_s = t.elapsed().as_secs_f64() / gn_frames.min(frames) as f64;
    }
    let qp_mean = qp.iter().sum::<f64>() / frames as f64;
    let qp_max = qp.iter().fold(0.0f64, |a, &b| a.max(b));
    Ok(serde_json::json!({
        "vertices": rig.mesh.vertex_count(),
        "elements": lattice.elements.len(),
        "nodes": lattice.node_count(),
        "free_dofs": fitter.forward.free_dofs(),
        "shapes": targets.len(),
        "muscles": fitter.muscles().len(),
        "muscles_from_shapes": source.len(),
        "generate_s": generate_s,
        "jacobian_s": fitter.jacobian_s,
        "fitter_setup_s": setup_s,
        "frames": frames,
        "qp_ms_mean": qp_mean * 1e3,
        "qp_ms_max": qp_max * 1e3,
        "frame_ms_mean": frames_s / frames as f64 * 1e3,
        "clip_s": fitter.jacobian_s + frames_s,
        "failed_frames": failed,
        "target_rms_mean_m": target_rms,
        "fit_rms_mean_m": rms_sum / frames as f64,
        "gn_frames": gn_frames,
        "gauss_newton1_frame_s": gn_s,
    }))
}
