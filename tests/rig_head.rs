//! The capture-shaped head rig (`furrow rig generate --kind head`, `rigs/head.glb`): the
//! committed file is what the generator makes, loads with its 52 ARKit shapes and 11 s
//! performance, has the size of a head, leaves the back of the head, the ears and the neck
//! still, and needs two levels of refinement with the default skin. Run with
//! `-- --nocapture` to see the measured numbers.

mod common;

use furrow::coupling::refine::{refine_for_wavelength, RefineSettings};
use furrow::coupling::wavelength::Bilayer;
use furrow::rig::head_shapes::ARKIT_NAMES;
use furrow::scene::materials::{interior_preset, skin_preset};
use std::path::Path;
use std::process::Command;

fn committed() -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/head.glb")
}

#[test]
fn generator_is_deterministic_and_the_committed_head_is_what_it_makes() {
    let d = tempfile::tempdir().unwrap();
    let mut bytes = Vec::new();
    for k in 0..2 {
        let out = d.path().join(format!("head{k}.glb"));
        let o = Command::new(env!("CARGO_BIN_EXE_furrow"))
            .args(["--json", "rig", "generate", "--kind", "head", "-o"])
            .arg(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(v["targets"].as_array().unwrap().len(), 52);
        bytes.push(std::fs::read(&out).unwrap());
    }
    assert_eq!(bytes[0], bytes[1], "two runs differ");
    assert_eq!(
        bytes[0],
        std::fs::read(committed()).unwrap(),
        "rigs/head.glb is stale: run `furrow rig generate --kind head -o rigs/head.glb --force`"
    );
    // The compact file against a float export of the same rig.
    let rig = furrow::rig::head::generate();
    let float = furrow::io::export::rig_glb("head", &rig.mesh, &rig.targets, &rig.keys).unwrap();
    println!(
        "rigs/head.glb {} bytes; float export {} bytes ({:.1}×)",
        bytes[0].len(),
        float.len(),
        float.len() as f64 / bytes[0].len() as f64
    );
    assert!(bytes[0].len() * 4 < float.len());
}

#[test]
fn head_loads_with_52_shapes_a_long_performance_and_a_still_back() {
    let rig = furrow::io::load(&committed(), &Default::default()).unwrap();
    let f = rig.face();
    let names: Vec<&str> = f.targets.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ARKIT_NAMES.to_vec());
    let frames = rig.frame_weights(30.0);
    assert!(frames.len() >= 330, "{} frames", frames.len());
    let n = f.positions.len();
    assert!((2500..=3000).contains(&n), "{n} vertices");
    let (mut lo, mut hi) = (f.positions[0], f.positions[0]);
    for p in &f.positions {
        lo = lo.inf(p);
        hi = hi.sup(p);
    }
    let height = hi.y - lo.y;
    println!(
        "{n} vertices, {} triangles, box {:.3} × {:.3} × {:.3} m, {} frames",
        f.triangles.len(),
        hi.x - lo.x,
        height,
        hi.z - lo.z,
        frames.len()
    );
    assert!((height - 0.23).abs() < 0.005, "height {height}");
    // Back of the head and ears (z < 0) and the neck (y < −0.105 m): no shape moves them.
    let still: Vec<usize> = (0..n)
        .filter(|&v| f.positions[v].z < 0.0 || f.positions[v].y < -0.105)
        .collect();
    assert!(still.len() > n / 3, "{} still vertices", still.len());
    for t in &f.targets {
        for &v in &still {
            assert_eq!(t.positions[v].norm(), 0.0, "{} moves vertex {v}", t.name);
        }
        let moved = t.positions.iter().filter(|d| d.norm() > 0.0).count();
        assert!(
            moved > 0 && moved < n / 2,
            "{} moves {moved} vertices",
            t.name
        );
    }
    // Every shape is stored sparse (it moves fewer than half the vertices).
    let j = &rig.container.json;
    for t in j["meshes"][0]["primitives"][0]["targets"]
        .as_array()
        .unwrap()
    {
        let a = &j["accessors"][t["POSITION"].as_u64().unwrap() as usize];
        assert!(a["sparse"].is_object());
    }
}

#[test]
fn head_needs_two_refinement_levels_with_the_default_skin() {
    let rig = furrow::io::load(&committed(), &Default::default()).unwrap();
    let f = rig.face();
    let (skin, flesh) = (
        skin_preset("skin").unwrap(),
        interior_preset("flesh").unwrap(),
    );
    let lambda = Bilayer {
        thickness: skin.material.thickness,
        skin_modulus: skin.material.young,
        skin_poisson: skin.material.poisson,
        interior_modulus: flesh.material.young,
        interior_poisson: flesh.material.poisson,
    }
    .critical_wavelength();
    let mesh = furrow::mesh::TriMesh::new(f.positions.clone(), f.triangles.clone());
    let r = refine_for_wavelength(&mesh, lambda, &RefineSettings::default()).unwrap();
    println!(
        "λ = {:.2} mm: {} levels, {} → {} vertices, mean edge {:.2} mm",
        lambda * 1e3,
        r.report.levels,
        r.report.vertices_before,
        r.report.vertices_after,
        r.report.mean_edge_before * 1e3
    );
    assert_eq!(r.report.levels, 2);
}

#[test]
fn head_passes_the_validator() {
    if let Some(r) = common::validate(&[committed()]) {
        common::assert_valid(&r);
    }
}
