//! Preview images of a run (no GPU): for a few chosen frames the blend shapes alone beside the
//! wrinkled skin and a map of wrinkle depth, and a contact sheet of the clip.

use super::RunOutput;
use crate::io::atomic::Overwrite;
use crate::mesh::TriMesh;
use crate::render::preview::{self, View};
use std::path::{Path, PathBuf};

/// Most tiles on the contact sheet (frames are subsampled evenly beyond that).
pub const CONTACT_TILES: usize = 24;

/// Frames shown in detail: the frame of deepest wrinkles and up to three more evenly spread.
pub fn chosen_frames(out: &RunOutput) -> Vec<usize> {
    let n = out.frames.len();
    if n == 0 {
        return Vec::new();
    }
    let deepest = out
        .report
        .per_frame
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.wrinkle_depth_max_m.total_cmp(&b.1.wrinkle_depth_max_m))
        .map_or(0, |(i, _)| i);
    let mut v = vec![deepest];
    for k in 1..=3 {
        let f = (k * (n - 1)) / 3;
        if !v.contains(&f) {
            v.push(f);
        }
    }
    v.sort_unstable();
    v
}

/// Write the previews into `dir`: `frame_NNNNN.png` (blend shapes | wrinkled | wrinkle depth)
/// for [`chosen_frames`] and `contact_sheet.png`. Refuses to replace existing files unless
/// `overwrite` says so. Returns the paths.
pub fn write_previews(
    out: &RunOutput,
    dir: &Path,
    overwrite: Overwrite,
) -> anyhow::Result<Vec<PathBuf>> {
    let chosen = chosen_frames(out);
    let mut paths: Vec<PathBuf> = chosen
        .iter()
        .map(|&k| dir.join(format!("frame_{:05}.png", out.report.frames[0] + k)))
        .collect();
    paths.push(dir.join("contact_sheet.png"));
    crate::io::atomic::check_free(&paths, overwrite)?;
    let mesh_at =
        |pos: &Vec<nalgebra::Vector3<f64>>| TriMesh::new(pos.clone(), out.triangles.clone());
    let smooth: Vec<TriMesh> = chosen.iter().map(|&k| mesh_at(&out.smooth[k])).collect();
    let refs: Vec<&TriMesh> = smooth.iter().collect();
    let view = View {
        bounds: preview::union_bounds(&refs),
        ..View::default()
    };
    let size = (480, 480);
    for (i, &k) in chosen.iter().enumerate() {
        let base = &smooth[i];
        let wrinkled = mesh_at(&out.frames[k]);
        let depth = preview::wrinkle_depth_mm(base, &out.frames[k])?;
        let m = depth.iter().fold(0.0f64, |a, d| a.max(d.abs())).max(1e-3);
        let images = [
            preview::render(base, &view, size),
            preview::render(&wrinkled, &view, size),
            preview::render_scalar(base, &depth, (-m, m), &view, size)?,
        ];
        let frame = out.report.frames[0] + k;
        let img = preview::side_by_side(
            &images,
            &[
                &format!("frame {frame}: blend shapes"),
                "wrinkled",
                "wrinkle depth",
            ],
        );
        preview::write_png(&paths[i], &img)?;
    }
    let n = out.frames.len();
    let tiles: Vec<usize> = if n <= CONTACT_TILES {
        (0..n).collect()
    } else {
        (0..CONTACT_TILES)
            .map(|i| i * (n - 1) / (CONTACT_TILES - 1))
            .collect()
    };
    let images: Vec<_> = tiles
        .iter()
        .map(|&k| preview::render(&mesh_at(&out.frames[k]), &view, (200, 200)))
        .collect();
    let labels: Vec<String> = tiles
        .iter()
        .map(|&k| format!("{}", out.report.frames[0] + k))
        .collect();
    let label_refs: Vec<&str> = labels.iter().map(|s| s.as_str()).collect();
    let sheet = preview::contact_sheet(&images, &label_refs, 6);
    preview::write_png(paths.last().expect("contact sheet path"), &sheet)?;
    Ok(paths)
}
