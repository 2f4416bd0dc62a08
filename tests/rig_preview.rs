//! Preview renders of the face rig for a person to look at (ignored by default):
//! `RIG_PREVIEW_DIR=/tmp/rig cargo test --test rig_preview -- --ignored` writes one PNG per
//! target (front and side views, neutral and at weight 1, Lambert shading, orthographic).

use furrow::rig::face::generate;
use image::{Rgb, RgbImage};
use nalgebra::{Rotation3, Vector3};

/// Rasterise `tris` orthographically (looking along −Z after `rot`) into the `w × h` tile at
/// `(ox, 0)` of `img`, `scale` pixels per metre.
fn render(
    img: &mut RgbImage,
    ox: u32,
    pos: &[Vector3<f64>],
    tris: &[[usize; 3]],
    rot: Rotation3<f64>,
) {
    let (w, h) = (400u32, 400u32);
    let scale = 1700.0;
    let mut depth = vec![f64::MIN; (w * h) as usize];
    let light = Vector3::new(0.3, 0.5, 1.0).normalize();
    let p: Vec<Vector3<f64>> = pos.iter().map(|q| rot * q).collect();
    for &[a, b, c] in tris {
        let nrm = (p[b] - p[a]).cross(&(p[c] - p[a]));
        if nrm.z <= 0.0 {
            continue;
        }
        let shade = nrm.normalize().dot(&light).max(0.0) * 0.85 + 0.15;
        let px = |q: &Vector3<f64>| (w as f64 / 2.0 + q.x * scale, h as f64 / 2.0 - q.y * scale);
        let (pa, pb, pc) = (px(&p[a]), px(&p[b]), px(&p[c]));
        let xmin = pa.0.min(pb.0).min(pc.0).floor().max(0.0) as u32;
        let xmax = pa.0.max(pb.0).max(pc.0).ceil().min(w as f64 - 1.0) as u32;
        let ymin = pa.1.min(pb.1).min(pc.1).floor().max(0.0) as u32;
        let ymax = pa.1.max(pb.1).max(pc.1).ceil().min(h as f64 - 1.0) as u32;
        let area = (pb.0 - pa.0) * (pc.1 - pa.1) - (pc.0 - pa.0) * (pb.1 - pa.1);
        if area.abs() < 1e-12 {
            continue;
        }
        for y in ymin..=ymax {
            for x in xmin..=xmax {
                let (fx, fy) = (x as f64 + 0.5, y as f64 + 0.5);
                let w0 = ((pb.0 - fx) * (pc.1 - fy) - (pc.0 - fx) * (pb.1 - fy)) / area;
                let w1 = ((pc.0 - fx) * (pa.1 - fy) - (pa.0 - fx) * (pc.1 - fy)) / area;
                let w2 = 1.0 - w0 - w1;
                if w0 < 0.0 || w1 < 0.0 || w2 < 0.0 {
                    continue;
                }
                let z = w0 * p[a].z + w1 * p[b].z + w2 * p[c].z;
                let k = (y * w + x) as usize;
                if z > depth[k] {
                    depth[k] = z;
                    let g = (shade * 230.0) as u8;
                    img.put_pixel(
                        ox + x,
                        y,
                        Rgb([g, (g as f64 * 0.85) as u8, (g as f64 * 0.75) as u8]),
                    );
                }
            }
        }
    }
}

#[test]
#[ignore = "writes preview pictures of the rigs for a person to look at"]
fn write_previews() {
    let dir = std::env::var("RIG_PREVIEW_DIR").unwrap_or_else(|_| "/tmp/rig_preview".into());
    std::fs::create_dir_all(&dir).unwrap();
    let rig = generate();
    let front = Rotation3::identity();
    let side = Rotation3::from_axis_angle(&Vector3::y_axis(), -std::f64::consts::FRAC_PI_2 * 0.75);
    let mut shapes: Vec<(String, Vec<Vector3<f64>>)> =
        vec![("neutral".into(), rig.mesh.positions.clone())];
    for t in &rig.targets {
        let def = rig
            .mesh
            .positions
            .iter()
            .zip(&t.positions)
            .map(|(p, d)| p + d)
            .collect();
        shapes.push((t.name.clone(), def));
    }
    for (name, pos) in shapes {
        let mut img = RgbImage::from_pixel(800, 400, Rgb([40, 40, 50]));
        render(&mut img, 0, &pos, &rig.mesh.triangles, front);
        render(&mut img, 400, &pos, &rig.mesh.triangles, side);
        img.save(format!("{dir}/{name}.png")).unwrap();
    }
}
