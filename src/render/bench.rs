//! The rasteriser's speed (`furrow bench render`): a domed, wrinkled square patch rendered
//! plain and as a scalar field, at two supersampling levels.

use super::preview::{render, render_scalar, View};
use crate::mesh::TriMesh;
use nalgebra::Vector3;
use std::time::Instant;

/// A 0.2 m square patch of 2 (n − 1)² triangles: a dome 5 cm high carrying wrinkles of
/// 8 mm wavelength and `amp` (m) amplitude along x, fading in y.
pub fn wrinkled_patch(n: usize, amp: f64) -> TriMesh {
    let mut pos = Vec::with_capacity(n * n);
    for j in 0..n {
        for i in 0..n {
            let x = -0.1 + 0.2 * i as f64 / (n - 1) as f64;
            let y = -0.1 + 0.2 * j as f64 / (n - 1) as f64;
            let dome = 0.05 * (1.0 - (x * x + y * y) / 0.03);
            let wr =
                amp * (2.0 * std::f64::consts::PI * x / 0.008).sin() * (-(y * y) / 0.002).exp();
            pos.push(Vector3::new(x, y, dome + wr));
        }
    }
    TriMesh::new(pos, crate::mesh::grid_triangles(n, n))
}

/// Mean wall time (ms) of rendering a patch of about `triangles` triangles at `size` × `size`
/// pixels, plain and as a scalar field (its depth), with supersampling 1 and 2; `reps`
/// renders each.
pub fn bench_render(triangles: usize, size: u32, reps: usize) -> anyhow::Result<serde_json::Value> {
    let n = ((triangles as f64 / 2.0).sqrt().round() as usize + 1).max(2);
    let mesh = wrinkled_patch(n, 0.0005);
    let depth: Vec<f64> = mesh.positions.iter().map(|p| p.z).collect();
    let mut rows = Vec::new();
    for supersample in [1, 2] {
        let view = View {
            supersample,
            ..View::default()
        };
        let t = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(render(&mesh, &view, (size, size)));
        }
        let plain_ms = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
        let t = Instant::now();
        for _ in 0..reps {
            std::hint::black_box(render_scalar(
                &mesh,
                &depth,
                (0.0, 0.05),
                &view,
                (size, size),
            )?);
        }
        let scalar_ms = t.elapsed().as_secs_f64() * 1e3 / reps as f64;
        rows.push(serde_json::json!({
            "supersample": supersample, "render_ms": plain_ms, "render_scalar_ms": scalar_ms,
        }));
    }
    Ok(serde_json::json!({
        "triangles": mesh.triangles.len(), "pixels": size, "reps": reps, "runs": rows,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The benchmark runs on a tiny patch and reports finite times.
    #[test]
    fn bench_render_runs_on_a_small_patch() {
        let v = bench_render(200, 32, 1).unwrap();
        assert_eq!(v["runs"].as_array().unwrap().len(), 2);
        assert!(v["runs"][1]["render_ms"].as_f64().unwrap().is_finite());
    }
}
