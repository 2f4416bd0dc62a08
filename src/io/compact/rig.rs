//! A blend-shape rig as a compact GLB (the capture-shaped head, `rigs/head.glb`):
//!
//! | data | storage |
//! | --- | --- |
//! | `POSITION` | normalized i16 VEC3 (8-byte stride); the node's uniform `scale` and `translation` dequantize it: world = t + s · q / 32767 (m) |
//! | `NORMAL` | normalized i8 VEC3 (4-byte stride) |
//! | indices | u16 (u32 past 65 535 vertices), meshopt `TRIANGLES` |
//! | target `POSITION` deltas | normalized i16 on the same grid as the positions (step s / 32767 m, exact in the node transform) |
//! | target `NORMAL` deltas | normalized i8 |
//! | targets that move less than half the vertices | sparse accessors (no dense data): the vertices whose quantized position or normal delta is non-zero, indices shared by both |
//! | animation times | f32 (s) |
//! | animation weights | normalized u16, one row of target weights per key |

use super::targets::{unit_i8, TargetData, Vec3Data};
use super::{add_extension, Codec, CompactDocument};
use crate::io::model::{MorphTarget, WeightKeys};
use crate::mesh::TriMesh;
use anyhow::bail;
use nalgebra::Vector3;
use serde_json::{json, Value};

/// Largest normalized i16 value (`SHORT` normalized maps q to q / 32767).
const I16_MAX: f64 = 32767.0;
/// Largest normalized u16 value.
const U16_MAX: f64 = 65535.0;

/// The position grid of a quantized mesh: world = `translation` + `scale` · q / 32767 (m)
/// for normalized i16 q, with `translation` and `scale` exact f32 values (they are the node's
/// TRS, so a loader's f32 transform dequantizes exactly as the f64 one).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Quantization {
    /// Centre of the bounding box (m), rounded to f32.
    pub translation: Vector3<f64>,
    /// Half the largest bounding-box extent, or the largest delta component if larger (m),
    /// rounded up to an f32.
    pub scale: f64,
}

/// `x` rounded to the nearest f32 (as f64).
fn f32_round(x: f64) -> f64 {
    x as f32 as f64
}

impl Quantization {
    /// The grid for `mesh` and the deltas of `targets` (every delta component must fit in
    /// ±scale). Errors on an empty mesh.
    pub fn of(mesh: &TriMesh, targets: &[MorphTarget]) -> anyhow::Result<Self> {
        let Some((lo, hi)) = mesh.bounding_box() else {
            bail!("the mesh has no vertices to quantize");
        };
        let c = (lo + hi) / 2.0;
        let translation = Vector3::new(f32_round(c.x), f32_round(c.y), f32_round(c.z));
        let mut half: f64 = mesh
            .positions
            .iter()
            .map(|p| (p - translation).abs().max())
            .fold(0.0, f64::max);
        for t in targets {
            for d in &t.positions {
                half = half.max(d.abs().max());
            }
        }
        let half = half.max(1e-9);
        let mut s = half as f32;
        if (s as f64) < half {
            s = f32::from_bits(s.to_bits() + 1);
        }
        Ok(Self {
            translation,
            scale: s as f64,
        })
    }

    /// The grid step (m): the largest position or delta error is half of it per component.
    pub fn step(&self) -> f64 {
        self.scale / I16_MAX
    }

    /// Quantized position (normalized i16 components).
    pub fn point(&self, p: &Vector3<f64>) -> [i16; 3] {
        self.delta(&(p - self.translation))
    }

    /// Quantized delta on the same grid (normalized i16 components).
    pub fn delta(&self, d: &Vector3<f64>) -> [i16; 3] {
        let q = |x: f64| (x / self.scale * I16_MAX).round().clamp(-I16_MAX, I16_MAX) as i16;
        [q(d.x), q(d.y), q(d.z)]
    }
}

impl CompactDocument {
    /// A LINEAR weights animation of node 0: f32 times (s), normalized u16 weights (one row of
    /// `targets` weights per key, each clamped to [0, 1]).
    fn push_weights_animation(&mut self, keys: &WeightKeys, targets: usize) {
        let times: Vec<u8> = keys
            .times
            .iter()
            .flat_map(|&t| (t as f32).to_le_bytes())
            .collect();
        let tview = self.push_view(times, Codec::Attributes { stride: 4 }, None, None);
        let (t0, t1) = (
            keys.times[0] as f32,
            keys.times[keys.times.len() - 1] as f32,
        );
        let input = self.push_accessor(json!({ "bufferView": tview, "componentType": 5126,
            "count": keys.times.len(), "type": "SCALAR", "min": [t0], "max": [t1] }));
        let w: Vec<u8> = keys
            .weights
            .iter()
            .flatten()
            .map(|&x| (x.clamp(0.0, 1.0) * U16_MAX).round() as u16)
            .flat_map(u16::to_le_bytes)
            .collect();
        // Stored plainly (as `rigs/head.glb` has them; the weights are a small part).
        let wview = self.push_view(w, Codec::Plain, None, None);
        let output = self.push_accessor(json!({ "bufferView": wview, "componentType": 5123,
            "normalized": true, "count": keys.times.len() * targets, "type": "SCALAR" }));
        self.doc.json["animations"] = json!([{
            "name": "performance",
            "samplers": [{ "input": input, "output": output, "interpolation": "LINEAR" }],
            "channels": [{ "sampler": 0, "target": { "node": 0, "path": "weights" } }],
        }]);
    }
}

/// Check the rig's arrays agree (deltas per vertex, a weight per target per key).
fn check_rig(mesh: &TriMesh, targets: &[MorphTarget], keys: &WeightKeys) -> anyhow::Result<()> {
    let n = mesh.positions.len();
    if n == 0 || mesh.triangles.is_empty() {
        bail!("the mesh has no triangles to write");
    }
    for t in targets {
        let bad_normals = t.normals.as_ref().is_some_and(|v| v.len() != n);
        if t.positions.len() != n || bad_normals {
            bail!(
                "target {} has deltas for {} of {n} vertices",
                t.name,
                t.positions.len()
            );
        }
    }
    crate::io::export::check_weight_keys(keys, targets.len())?;
    let all_finite = mesh
        .positions
        .iter()
        .all(|p| p.iter().all(|x| x.is_finite()))
        && targets
            .iter()
            .all(|t| t.positions.iter().all(|p| p.iter().all(|x| x.is_finite())));
    if !all_finite {
        bail!("the mesh or a target has a non-finite value (NaN or infinity)");
    }
    Ok(())
}

/// A blend-shape rig as a compact GLB (see the module table): one node named `name` carrying
/// the quantization (translation, uniform scale), one mesh with `targets` (names in
/// `extras.targetNames`), normals computed from `mesh`, and a linear weights animation
/// "performance" from `keys` (omitted when there are no keys). Positions and deltas in metres.
pub fn rig_glb(
    name: &str,
    mesh: &TriMesh,
    targets: &[MorphTarget],
    keys: &WeightKeys,
) -> anyhow::Result<Vec<u8>> {
    check_rig(mesh, targets, keys)?;
    let qz = Quantization::of(mesh, targets)?;
    let mut cd = CompactDocument::new();
    let pos: Vec<[i16; 3]> = mesh.positions.iter().map(|p| qz.point(p)).collect();
    let nrm: Vec<[i8; 3]> = mesh.vertex_normals().iter().map(unit_i8).collect();
    let pa = cd.push_vec3(&Vec3Data::I16(pos), true);
    let na = cd.push_vec3(&Vec3Data::I8(nrm), false);
    let ia = cd.push_triangles(&mesh.triangles);
    let tj: Vec<Value> = targets
        .iter()
        .map(|t| {
            let q = TargetData {
                positions: Vec3Data::I16(t.positions.iter().map(|d| qz.delta(d)).collect()),
                normals: t
                    .normals
                    .as_ref()
                    .map(|v| Vec3Data::I8(v.iter().map(unit_i8).collect())),
            };
            cd.push_target(&q)
        })
        .collect();
    let mut prim = json!({ "attributes": { "POSITION": pa, "NORMAL": na }, "indices": ia,
        "material": 0, "mode": 4 });
    let mut m = json!({ "name": name, "primitives": [] });
    if !targets.is_empty() {
        prim["targets"] = json!(tj);
        m["weights"] = json!(vec![0.0; targets.len()]);
        m["extras"] = json!({ "targetNames": targets.iter().map(|t| &t.name).collect::<Vec<_>>() });
    }
    m["primitives"] = json!([prim]);
    let j = &mut cd.doc.json;
    j["materials"] = json!([{ "name": "skin", "pbrMetallicRoughness": {
        "baseColorFactor": [0.87, 0.68, 0.58, 1.0], "metallicFactor": 0.0, "roughnessFactor": 0.6 } }]);
    j["meshes"] = json!([m]);
    let t = qz.translation;
    j["nodes"] = json!([{ "name": name, "mesh": 0, "translation": [t.x, t.y, t.z],
        "scale": [qz.scale, qz.scale, qz.scale] }]);
    j["scenes"] = json!([{ "nodes": [0] }]);
    j["scene"] = json!(0);
    for key in ["extensionsUsed", "extensionsRequired"] {
        add_extension(j, key, "KHR_mesh_quantization");
    }
    if !keys.times.is_empty() && !targets.is_empty() {
        cd.push_weights_animation(keys, targets.len());
    }
    cd.to_glb(true)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::accessor::AccessorReader;
    use crate::io::load::{load_bytes, LoadOptions};
    use std::path::Path;

    /// A 9 × 7 wavy sheet 8 × 6 cm with a dense target (every vertex), a sparse one (three
    /// vertices) and an empty one, and five weight keys.
    pub(crate) fn small_rig() -> (TriMesh, Vec<MorphTarget>, WeightKeys) {
        let (nx, ny) = (9, 7);
        let mut positions = Vec::new();
        for j in 0..ny {
            for i in 0..nx {
                let (x, y) = (0.01 * i as f64, 0.01 * j as f64);
                positions.push(Vector3::new(x + 0.3, y - 0.1, 0.004 * (40.0 * x).sin()));
            }
        }
        let mesh = TriMesh::new(positions, crate::mesh::grid_triangles(nx, ny));
        let n = mesh.vertex_count();
        let dense: Vec<Vector3<f64>> = mesh
            .positions
            .iter()
            .map(|p| Vector3::new(0.002 * p.y, -0.001, 0.003 * (p.x * 50.0).cos()))
            .collect();
        let mut few = vec![Vector3::zeros(); n];
        few[10] = Vector3::new(0.001, 0.0, 0.0);
        few[31] = Vector3::new(0.0, -0.0023, 0.0004);
        few[32] = Vector3::new(0.0, 0.0, 0.005);
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
                name: "none".into(),
                positions: vec![Vector3::zeros(); n],
                normals: None,
            },
        ];
        let keys = WeightKeys {
            times: vec![0.0, 0.1, 0.2, 0.3, 0.4],
            weights: vec![
                vec![0.0, 0.0, 0.0],
                vec![0.25, 0.5, 0.0],
                vec![1.0, 0.123_456, 0.0],
                vec![0.7, 1.0, 0.0],
                vec![0.0, 0.01, 0.0],
            ],
        };
        (mesh, targets, keys)
    }

    #[test]
    fn round_trip_within_the_quantization_step() {
        let (mesh, targets, keys) = small_rig();
        let bytes = rig_glb("sheet", &mesh, &targets, &keys).expect("writes");
        let qz = Quantization::of(&mesh, &targets).expect("grid");
        let rig =
            load_bytes(Path::new("sheet.glb"), &bytes, &LoadOptions::default()).expect("loads");
        let f = rig.face();
        // Half a grid step per component, plus f32 rounding of the node's TRS product.
        let tol = 0.5 * qz.step() + 1e-7 * qz.scale;
        for (a, b) in f.positions.iter().zip(&mesh.positions) {
            assert!((a - b).abs().max() <= tol, "position {a} vs {b}, tol {tol}");
        }
        assert_eq!(f.targets.len(), 3);
        for (lt, t) in f.targets.iter().zip(&targets) {
            assert_eq!(lt.name, t.name);
            for (a, b) in lt.positions.iter().zip(&t.positions) {
                assert!((a - b).abs().max() <= tol, "{}: delta {a} vs {b}", t.name);
            }
        }
        // Normals: i8 components (half-step 0.5 / 127) then renormalised.
        for (a, b) in f
            .normals
            .as_ref()
            .expect("normals")
            .iter()
            .zip(mesh.vertex_normals())
        {
            assert!((a - b).norm() < 0.01, "normal {a} vs {b}");
        }
        // Normal deltas in the file's local space, within half an i8 step.
        let reader = AccessorReader::new(&rig.path, &rig.container);
        let tj = &rig.container.json["meshes"][0]["primitives"][0]["targets"];
        for (k, t) in targets.iter().enumerate().take(2) {
            let d = reader
                .read(tj[k]["NORMAL"].as_u64().expect("NORMAL") as usize)
                .expect("reads");
            for (i, b) in t.normals.as_ref().expect("normals").iter().enumerate() {
                let e = (d.vec3(i) - b).abs().max();
                assert!(
                    e <= 0.5 / 127.0 + 1e-9 || b.abs().max() > 1.0,
                    "{}: {e}",
                    t.name
                );
            }
        }
        let track = rig.track.as_ref().expect("weights animation");
        for (time, w) in keys.times.iter().zip(&keys.weights) {
            for (a, b) in track.sample(*time).iter().zip(w) {
                assert!((a - b).abs() <= 0.5 / 65535.0 + 1e-6, "weight {a} vs {b}");
            }
        }
    }

    #[test]
    fn targets_that_move_few_vertices_are_sparse_and_everything_is_compressed() {
        let (mesh, targets, keys) = small_rig();
        let bytes = rig_glb("sheet", &mesh, &targets, &keys).expect("writes");
        let rig =
            load_bytes(Path::new("sheet.glb"), &bytes, &LoadOptions::default()).expect("loads");
        let j = &rig.container.json;
        let tj = &j["meshes"][0]["primitives"][0]["targets"];
        let acc =
            |t: usize, k: &str| &j["accessors"][tj[t][k].as_u64().expect("accessor") as usize];
        assert!(
            acc(0, "POSITION")["sparse"].is_null(),
            "the dense target is dense"
        );
        let sparse = &acc(1, "POSITION")["sparse"];
        // Vertices 10, 31, 32 and the normals of their neighbours, padded to a multiple of 4.
        let count = sparse["count"].as_u64().expect("sparse count");
        assert!(
            count >= 3 && count % 4 == 0 && count < 40,
            "sparse count {count}"
        );
        assert!(acc(1, "POSITION")["bufferView"].is_null());
        assert_eq!(acc(1, "NORMAL")["sparse"]["indices"], sparse["indices"]);
        assert_eq!(acc(0, "POSITION")["componentType"], 5122);
        assert_eq!(acc(0, "NORMAL")["componentType"], 5120);
        for v in j["bufferViews"].as_array().expect("views") {
            assert!(v["extensions"]["EXT_meshopt_compression"].is_object() || v["buffer"] == 0);
        }
        for key in ["extensionsUsed", "extensionsRequired"] {
            assert_eq!(
                j[key],
                json!(["EXT_meshopt_compression", "KHR_mesh_quantization"])
            );
        }
        assert_eq!(
            j["buffers"][1]["extensions"]["EXT_meshopt_compression"]["fallback"],
            true
        );
    }

    #[test]
    fn quantization_grid_is_exact_in_f32_and_covers_the_mesh() {
        let (mesh, targets, _) = small_rig();
        let q = Quantization::of(&mesh, &targets).expect("grid");
        assert_eq!(q.scale, q.scale as f32 as f64);
        assert_eq!(q.translation.x, q.translation.x as f32 as f64);
        // Half the largest extent (8 cm wide sheet): at least 4 cm, at most a hair above.
        assert!(
            q.scale >= 0.04 && q.scale < 0.04 * (1.0 + 1e-6),
            "scale {}",
            q.scale
        );
    }
}
