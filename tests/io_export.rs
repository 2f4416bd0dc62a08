//! glTF export: round trips through the loader and the Khronos glTF Validator.

mod common;

use furrow::io::atomic::Overwrite;
use furrow::io::export::{self, FrameSet, VertexOrigin};
use furrow::io::{load, LoadOptions};
use nalgebra::Vector3;

fn frames_of(path: &std::path::Path, fps: f64) -> (furrow::io::Rig, Vec<Vec<Vector3<f64>>>) {
    let rig = load(path, &LoadOptions::default()).unwrap();
    let frames: Vec<_> = rig.frame_weights(fps).iter().map(|w| rig.blend(w)).collect();
    (rig, frames)
}

#[test]
fn animated_export_round_trips_and_validates_for_every_shared_file() {
    let dir = tempfile::tempdir().unwrap();
    let mut written = Vec::new();
    for path in common::shared_glbs() {
        let (rig, frames) = frames_of(&path, 10.0);
        let face = rig.face();
        let origin: Vec<_> = (0..face.positions.len()).map(VertexOrigin::same).collect();
        let set = FrameSet { triangles: &face.triangles, frames: &frames, origin: &origin, fps: 10.0 };
        let out = dir.path().join(path.file_name().unwrap());
        export::write_animated(&rig, &set, &out, Overwrite::Refuse).unwrap();
        // Re-load: the new face has one target per frame and frame k shows at k / fps.
        let back = load(&out, &LoadOptions { mesh: Some(face.name.clone() + " (furrow)"), animation: Some("furrow_wrinkles".into()) }).unwrap();
        let bf = back.face();
        assert_eq!(bf.targets.len(), if frames.len() > 1 { frames.len() } else { 0 }, "{}", path.display());
        let w = back.frame_weights(10.0);
        assert_eq!(w.len(), frames.len());
        let scale = face.positions.iter().map(|p| p.norm()).fold(0.0, f64::max).max(1e-9);
        for k in [0, frames.len() / 2, frames.len() - 1] {
            let got = back.blend(&w[k]);
            let err = got.iter().zip(&frames[k]).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
            // f32 storage of positions and deltas: relative error ~1e-6 of the model size.
            assert!(err < 1e-5 * scale, "{}: frame {k} differs by {err}", path.display());
        }
        // One still frame.
        let still = dir.path().join(format!("still_{}", path.file_name().unwrap().to_string_lossy()));
        std::fs::write(&still, export::frame_glb(&rig, &set, frames.len() - 1).unwrap()).unwrap();
        written.push(out);
        written.push(still);
    }
    if let Some(reports) = common::validate(&written) {
        common::assert_valid(&reports);
    }
}
