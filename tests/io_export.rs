//! glTF export: round trips through the loader and the Khronos glTF Validator.

mod common;

use furrow::io::atomic::Overwrite;
use furrow::io::export::{self, FrameSet};
use furrow::io::origin::VertexOrigin;
use furrow::io::{load, LoadOptions};
use nalgebra::Vector3;

fn frames_of(path: &std::path::Path, fps: f64) -> (furrow::io::Rig, Vec<Vec<Vector3<f64>>>) {
    let rig = load(path, &LoadOptions::default()).unwrap();
    let frames: Vec<_> = rig
        .frame_weights(fps)
        .iter()
        .map(|w| rig.blend(w))
        .collect();
    (rig, frames)
}

#[test]
fn animated_export_round_trips_and_validates_for_every_shared_file() {
    let Some(shared) = common::shared_glbs() else {
        return;
    };
    export_round_trips_and_validates(shared);
}

/// The same on the project's own rig and its gltfpack copy (quantized + meshopt, as capture
/// tools write): what a clone without `../shared` still covers.
#[test]
fn animated_export_round_trips_and_validates_for_the_face_rig() {
    let face = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb");
    export_round_trips_and_validates(vec![face]);
}

/// Each input, and its gltfpack-compressed copy when gltfpack is installed, exported as an
/// animation and as one still frame: re-loaded, compared with the blended frames, validated.
fn export_round_trips_and_validates(shared: Vec<std::path::PathBuf>) {
    let dir = tempfile::tempdir().unwrap();
    let mut written = Vec::new();
    let mut inputs = shared.clone();
    // gltfpack-compressed copies (quantized + meshopt) must export just as well.
    let packed = dir.path().join("packed");
    std::fs::create_dir_all(&packed).unwrap();
    for src in shared {
        let out = packed.join(src.file_name().unwrap());
        if common::gltfpack(&src, &out) {
            inputs.push(out);
        }
    }
    let outdir = dir.path().join("out");
    std::fs::create_dir_all(&outdir).unwrap();
    for (i, path) in inputs.iter().enumerate() {
        let path = path.clone();
        let (rig, frames) = frames_of(&path, 10.0);
        let face = rig.face();
        let origin: Vec<_> = (0..face.positions.len()).map(VertexOrigin::same).collect();
        let set = FrameSet {
            triangles: &face.triangles,
            frames: &frames,
            origin: &origin,
            fps: 10.0,
            weights: &[],
        };
        let out = outdir.join(format!(
            "{i}_{}",
            path.file_name().unwrap().to_string_lossy()
        ));
        export::write_animated(&rig, &set, &out, Overwrite::Refuse).unwrap();
        written.push(out.clone());
        if frames.len() == 1 {
            // A still face (no weights animation, e.g. gltfpack drops constant tracks): no targets.
            continue;
        }
        // Re-load: the new face has one target per frame and frame k shows at k / fps.
        let back = load(
            &out,
            &LoadOptions {
                mesh: Some(face.name.clone() + " (furrow)"),
                animation: (frames.len() > 1).then(|| "furrow_wrinkles".into()),
                ..Default::default()
            },
        )
        .unwrap();
        let bf = back.face();
        assert_eq!(
            bf.targets.len(),
            if frames.len() > 1 { frames.len() } else { 0 },
            "{}",
            path.display()
        );
        let w = back.frame_weights(10.0);
        assert_eq!(w.len(), frames.len());
        let scale = face
            .positions
            .iter()
            .map(|p| p.norm())
            .fold(0.0, f64::max)
            .max(1e-9);
        for k in [0, frames.len() / 2, frames.len() - 1] {
            let got = back.blend(&w[k]);
            let err = got
                .iter()
                .zip(&frames[k])
                .map(|(a, b)| (a - b).norm())
                .fold(0.0, f64::max);
            // f32 storage of positions and deltas: relative error ~1e-6 of the model size.
            assert!(
                err < 1e-5 * scale,
                "{}: frame {k} differs by {err}",
                path.display()
            );
        }
        // One still frame.
        let still = outdir.join(format!(
            "still_{i}_{}",
            path.file_name().unwrap().to_string_lossy()
        ));
        std::fs::write(
            &still,
            export::frame_glb(&rig, &set, frames.len() - 1).unwrap(),
        )
        .unwrap();
        written.push(still);
    }
    if let Some(reports) = common::validate(&written) {
        common::assert_valid(&reports);
    }
}
