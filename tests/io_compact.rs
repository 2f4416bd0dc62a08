//! The compact glTF writer (`furrow::io::compact`): its files pass the Khronos glTF Validator.

mod common;

use furrow::io::compact::rig_glb;
use furrow::io::model::{MorphTarget, WeightKeys};
use nalgebra::Vector3;

/// A 12 × 10 sheet with a dense target, a target moving four vertices, a target moving none
/// and an odd number of targets (the weights rows are not a multiple of 4 bytes).
fn sheet() -> Vec<u8> {
    let mesh = common::grid_mesh(0.12, 0.1, 12, 10);
    let n = mesh.vertex_count();
    let dense: Vec<Vector3<f64>> = mesh
        .positions
        .iter()
        .map(|p| Vector3::new(-0.05 * p.x, 0.0, 0.01 * p.y))
        .collect();
    let mut few = vec![Vector3::zeros(); n];
    for (k, v) in [20, 21, 33, 34].into_iter().enumerate() {
        few[v] = Vector3::new(0.0, 0.0, 0.002 * (k + 1) as f64);
    }
    let n0 = mesh.vertex_normals();
    let normals_of = |d: &[Vector3<f64>]| mesh.normal_deltas(&n0, d);
    let targets = vec![
        MorphTarget {
            name: "dense".into(),
            normals: Some(normals_of(&dense)),
            positions: dense,
        },
        MorphTarget {
            name: "few".into(),
            normals: Some(normals_of(&few)),
            positions: few,
        },
        MorphTarget {
            name: "still".into(),
            normals: None,
            positions: vec![Vector3::zeros(); n],
        },
    ];
    let times: Vec<f64> = (0..40).map(|k| k as f64 / 30.0).collect();
    let weights = times
        .iter()
        .map(|t| vec![(t * 2.0).min(1.0), 0.5 + 0.5 * (t * 9.0).sin(), 0.0])
        .collect();
    rig_glb("sheet", &mesh, &targets, &WeightKeys { times, weights }).expect("writes")
}

#[test]
fn compact_files_pass_the_validator() {
    let dir = std::env::temp_dir().join(format!("furrow-compact-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join("sheet.glb");
    std::fs::write(&path, sheet()).expect("writes");
    let mut files = vec![path];
    let head = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/head.glb");
    if head.exists() {
        files.push(head);
    }
    let Some(reports) = common::validate(&files) else {
        return;
    };
    for r in &reports {
        println!("{r}");
    }
    common::assert_valid(&reports);
    let _ = std::fs::remove_dir_all(&dir);
}
