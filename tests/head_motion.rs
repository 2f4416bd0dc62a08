//! A head that turns: the face node's rotation is felt by the interior as the inertial forces
//! of the head's frame, so the flesh lags by the predicted a/ω² while the head accelerates and
//! settles after it stops. The test also says how much of the settling is backward Euler's
//! own damping (the flesh has no material damping).

mod common;

use furrow::io::load::{load_bytes, LoadOptions};
use furrow::io::model::{MorphTarget, WeightKeys};
use furrow::pipeline::record::Stage;
use furrow::pipeline::{self, RunOptions};
use furrow::scene::Scene;
use nalgebra::{UnitQuaternion, Vector3};
use std::path::Path;

/// Distance of the face from the turning axis (m).
const REACH: f64 = 0.09;
/// Flesh depth behind the face (m).
const DEPTH: f64 = 0.025;
/// The turn: 30° in 0.2 s, constant angular acceleration for 0.1 s, then braking.
const TURN: f64 = std::f64::consts::PI / 6.0;
const TURN_TIME: f64 = 0.2;
/// Length of the clip (s).
const CLIP: f64 = 0.6;

/// Yaw angle at time t (rad): bang-bang, α = 4 Θ / T².
fn yaw(t: f64) -> f64 {
    let alpha = 4.0 * TURN / (TURN_TIME * TURN_TIME);
    let half = TURN_TIME / 2.0;
    if t <= 0.0 {
        0.0
    } else if t <= half {
        0.5 * alpha * t * t
    } else if t <= TURN_TIME {
        TURN - 0.5 * alpha * (TURN_TIME - t) * (TURN_TIME - t)
    } else {
        TURN
    }
}

/// Split GLB bytes into JSON and the binary chunk.
fn split_glb(bytes: &[u8]) -> (serde_json::Value, Vec<u8>) {
    let u32_at = |o: usize| u32::from_le_bytes(bytes[o..o + 4].try_into().unwrap()) as usize;
    let jl = u32_at(12);
    let json = serde_json::from_slice(&bytes[20..20 + jl]).unwrap();
    let bo = 20 + jl;
    let bl = u32_at(bo);
    (json, bytes[bo + 8..bo + 8 + bl].to_vec())
}

/// A face patch 8 cm square at `REACH` in front of the node's origin (facing +z), one blend
/// shape that does nothing, and the node turning about +y by [`yaw`], keyed at 240 Hz.
fn turning_rig() -> Vec<u8> {
    let mut mesh = common::grid_mesh(0.08, 0.08, 16, 16);
    for p in &mut mesh.positions {
        *p += Vector3::new(-0.04, -0.04, REACH);
    }
    let target = MorphTarget {
        name: "still".into(),
        positions: vec![Vector3::zeros(); mesh.positions.len()],
        normals: None,
    };
    let keys = WeightKeys {
        times: vec![0.0, CLIP],
        weights: vec![vec![0.0], vec![0.0]],
    };
    let glb = furrow::io::export::rig_glb("turn", &mesh, &[target], &keys).unwrap();
    let (mut json, mut bin) = split_glb(&glb);
    while bin.len() % 4 != 0 {
        bin.push(0);
    }
    let n = (CLIP * 240.0).round() as usize + 1;
    let times: Vec<f32> = (0..n).map(|i| (i as f64 / 240.0) as f32).collect();
    let quats: Vec<f32> = times
        .iter()
        .flat_map(|&t| {
            let q = UnitQuaternion::from_axis_angle(&Vector3::y_axis(), yaw(t as f64));
            [q.i as f32, q.j as f32, q.k as f32, q.w as f32]
        })
        .collect();
    let mut push = |data: &[f32]| {
        let off = bin.len();
        bin.extend(data.iter().flat_map(|v| v.to_le_bytes()));
        let views = json["bufferViews"].as_array_mut().unwrap();
        views.push(
            serde_json::json!({ "buffer": 0, "byteOffset": off, "byteLength": 4 * data.len() }),
        );
        views.len() - 1
    };
    let (tv, qv) = (push(&times), push(&quats));
    json["buffers"][0]["byteLength"] = bin.len().into();
    let accessors = json["accessors"].as_array_mut().unwrap();
    accessors.push(
        serde_json::json!({ "bufferView": tv, "componentType": 5126, "count": n,
        "type": "SCALAR", "min": [0.0], "max": [times[n - 1]] }),
    );
    accessors.push(
        serde_json::json!({ "bufferView": qv, "componentType": 5126, "count": n, "type": "VEC4" }),
    );
    let (ta, qa) = (accessors.len() - 2, accessors.len() - 1);
    let anim = &mut json["animations"][0];
    let samplers = anim["samplers"].as_array_mut().unwrap();
    samplers.push(serde_json::json!({ "input": ta, "output": qa, "interpolation": "LINEAR" }));
    let s = samplers.len() - 1;
    let node = anim["channels"][0]["target"]["node"].clone();
    anim["channels"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::json!({ "sampler": s, "target": { "node": node, "path": "rotation" } }));
    common::glb_bytes(&json, &bin)
}

/// The face's tangential lag (m, along x in the head's frame; negative: behind the turn)
/// per frame, averaged over the middle of the patch, for a scene with `dt` (s).
fn lag_per_frame(rig_bytes: &[u8], dt: f64, tracking: f64) -> Vec<f64> {
    let rig = load_bytes(Path::new("turn.glb"), rig_bytes, &LoadOptions::default()).unwrap();
    assert!(rig.motion.is_some(), "the node's rotation is read");
    let opts = options(dt, tracking);
    let out = pipeline::run(&rig, &opts, &|_, _, _| {}).unwrap();
    let interior = out.report.stage(Stage::Interior);
    let why = format!("{:?}", interior.unwrap());
    assert!(why.contains("inertial forces"), "{why}");
    assert!(why.contains("up to 30.0° from the displayed pose"), "{why}");
    out.frames
        .iter()
        .zip(&out.smooth)
        .map(|(x, rest)| {
            let mid: Vec<f64> = x
                .iter()
                .zip(rest)
                .filter(|(_, r)| r.x.abs() < 0.012 && r.y.abs() < 0.012)
                .map(|(p, r)| p.x - r.x)
                .collect();
            mid.iter().sum::<f64>() / mid.len() as f64
        })
        .collect()
}

/// The scene: 10 kPa flesh `DEPTH` deep on 5 mm cells, tracking factor `tracking`,
/// backward Euler steps of `dt` (s), the simulated surface exported. The rig's shape stays
/// at weight 0, so no muscle would pull: the interior is driven by tracking alone (none at
/// `tracking` 0), which keeps the test to the head's motion.
fn options(dt: f64, tracking: f64) -> RunOptions {
    let text = format!(
        "[interior]\nyoung = 1.0e4\npoisson = 0.45\ndensity = 1050.0\ndepth = {DEPTH}\n\
         cell_size = 0.005\ntracking = {tracking}\n[dynamics]\nenabled = true\ndt = {dt}\n\
         [muscles]\nsource = \"none\"\n[export]\nsurface = \"simulated\"\n"
    );
    RunOptions::new(Scene::parse(&text, "turn.toml").unwrap())
}

/// The flesh's fundamental angular frequency ω (rad/s) as the model has it, for the turn's
/// load: Rayleigh's quotient ω² = uᵀ f / uᵀ M u of the static response u to the uniform
/// tangential acceleration field (f = M a), and that static lag at the face's middle (m).
fn model_frequency(rig_bytes: &[u8], accel: f64) -> (f64, f64) {
    let rig = load_bytes(Path::new("turn.glb"), rig_bytes, &LoadOptions::default()).unwrap();
    let opts = options(0.02, 0.0);
    let plan = furrow::pipeline::plan::Plan::new(&rig, &opts).unwrap();
    let mut log = furrow::pipeline::setup::Log::default();
    let (model, mut state) =
        furrow::pipeline::setup::set_up(&rig, &opts.scene, &plan, &mut log, &|_, _, _| {}).unwrap();
    let be = &mut state.interior;
    let q0 = be.q.clone();
    let a: Vec<f64> = (0..q0.len())
        .map(|i| if i % 3 == 0 { accel } else { 0.0 })
        .collect();
    let f = be.mass_times(&a);
    be.quasi_static(&f, None).unwrap();
    let u: Vec<f64> = be.q.iter().zip(&q0).map(|(q, r)| q - r).collect();
    let mu = be.mass_times(&u);
    let dot = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(a, b)| a * b).sum::<f64>();
    let omega = (dot(&u, &f) / dot(&u, &mu)).sqrt();
    let mid: Vec<f64> = (0..model.embedding.point_count())
        .zip(&model.skin_mesh.positions)
        .filter(|(_, p)| p.x.abs() < 0.012 && p.y.abs() < 0.012)
        .map(|(v, _)| model.embedding.point(v, &u).x)
        .collect();
    (omega, mid.iter().sum::<f64>() / mid.len() as f64)
}

#[test]
fn turning_head_lags_by_a_over_omega_squared_and_settles() {
    let rig = turning_rig();
    let young: f64 = 1.0e4;
    let mu = young / (2.0 * 1.45);
    // A layer DEPTH deep clamped at its base: ω = (π / 2H) √(μ/ρ).
    let layer = std::f64::consts::PI / (2.0 * DEPTH) * (mu / 1050.0).sqrt();
    let alpha = 4.0 * TURN / (TURN_TIME * TURN_TIME);
    let accel = alpha * REACH;
    let (omega, static_lag) = model_frequency(&rig, accel);
    let predicted = accel / (omega * omega);
    eprintln!(
        "a = {accel:.2} m/s²; the model's ω = {omega:.1} rad/s (a {DEPTH} m layer clamped at \
         its base: {layer:.1}, a/ω² = {:.3} mm); static lag {:.3} mm",
        accel / (layer * layer) * 1e3,
        -static_lag * 1e3
    );
    // Two sub-steps per frame (the default dt at 30 fps), then five.
    let coarse = lag_per_frame(&rig, 0.02, 0.0);
    let fine = lag_per_frame(&rig, 1.0 / 150.0, 0.0);
    let tracked = lag_per_frame(&rig, 0.02, 10.0);
    let show = |v: &[f64]| {
        v.iter()
            .map(|x| format!("{:.3}", x * 1e3))
            .collect::<Vec<_>>()
            .join(" ")
    };
    eprintln!(
        "predicted lag a/ω² = {:.3} mm (ω = {omega:.1} rad/s)",
        predicted * 1e3
    );
    eprintln!("lag per frame (mm), 2 sub-steps:  {}", show(&coarse));
    eprintln!("lag per frame (mm), 5 sub-steps: {}", show(&fine));
    eprintln!("lag per frame (mm), tracking κ = 10: {}", show(&tracked));
    // While the head accelerates at a constant rate (frames 1–3, t ≤ 0.1 s) the face lags
    // behind the turn, swinging about a/ω² (the acceleration starts as a step, so the lag
    // overshoots it, by at most a factor 2 without damping).
    let accelerating = |v: &[f64]| -(v[1] + v[2] + v[3]) / 3.0;
    let peak = |v: &[f64]| v[1..=3].iter().fold(0.0f64, |m, x| m.max(-x));
    for (name, v) in [("2 sub-steps", &coarse), ("5 sub-steps", &fine)] {
        let rel = (accelerating(v) - predicted) / predicted;
        eprintln!(
            "{name}: lag {:.3} mm on average while accelerating ({:+.1} % from a/ω²), {:.3} mm \
             at most",
            accelerating(v) * 1e3,
            rel * 1e2,
            peak(v) * 1e3
        );
        assert!(
            rel.abs() < 0.25,
            "{name}: lag {:.3e} m vs {predicted:.3e} m",
            accelerating(v)
        );
        assert!(peak(v) < 2.0 * predicted, "{name}: {v:?}");
    }
    // The tracking spring to the target holds the flesh: what it lets through is far less.
    assert!(peak(&tracked) < 0.05 * peak(&coarse), "{tracked:?}");
    // After the stop (t = 0.2 s, frame 6) the flesh swings back and settles. It has no
    // material damping: backward Euler's amplification per step, 1/√(1 + (ω h)²), is all the
    // decay; one period of the flesh is about three frames.
    let period = 2.0 * std::f64::consts::PI / omega;
    let envelope =
        |v: &[f64], from: usize| v[from..from + 3].iter().fold(0.0f64, |m, x| m.max(x.abs()));
    for (name, v, h) in [
        ("2 sub-steps", &coarse, 1.0 / 60.0),
        ("5 sub-steps", &fine, 1.0 / 150.0),
    ] {
        let last = v.len() - 1;
        assert!(
            v[last].abs() < 0.02 * predicted,
            "{name} has not settled: {v:?}"
        );
        let per_step = 1.0 / (1.0 + (omega * h).powi(2)).sqrt();
        let per_period = per_step.powf(period / h);
        let measured = envelope(v, 10) / envelope(v, 7);
        eprintln!(
            "{name}: backward Euler keeps {:.0} % of the amplitude per step, {:.2} per period \
             ({:.0} ms); measured over the frames after the stop: {measured:.2} per 3 frames",
            per_step * 1e2,
            per_period,
            period * 1e3
        );
        assert!(measured < 0.6, "{name} does not settle: {v:?}");
    }
}

/// A rotation channel whose output does not match its keys is refused, naming the file and
/// the channel.
#[test]
fn a_rotation_channel_of_the_wrong_size_is_refused() {
    let (mut json, mut bin) = common::tiny_rig();
    let off = bin.len();
    bin.extend([0f32, 0.0, 0.0, 1.0].iter().flat_map(|v| v.to_le_bytes()));
    json["bufferViews"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::json!({ "buffer": 0, "byteOffset": off, "byteLength": 16 }));
    json["buffers"][0]["byteLength"] = bin.len().into();
    let accessors = json["accessors"].as_array_mut().unwrap();
    accessors.push(
        serde_json::json!({ "bufferView": 5, "componentType": 5126, "count": 1, "type": "VEC4" }),
    );
    let anim = &mut json["animations"][0];
    anim["samplers"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::json!({ "input": 3, "output": 5 }));
    anim["channels"]
        .as_array_mut()
        .unwrap()
        .push(serde_json::json!({ "sampler": 1, "target": { "node": 0, "path": "rotation" } }));
    let bytes = common::glb_bytes(&json, &bin);
    let err = load_bytes(Path::new("bad_turn.glb"), &bytes, &LoadOptions::default())
        .err()
        .expect("refused")
        .to_string();
    assert!(
        err.contains("bad_turn.glb") && err.contains("rotation"),
        "{err}"
    );
}
