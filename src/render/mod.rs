//! Drawing: charts (PNG) of measurements and software-rendered preview images of meshes
//! (shaded, or coloured by a per-vertex quantity such as wrinkle depth), composed side by side
//! or as a contact sheet. No GPU and no system fonts: text uses the shipped DejaVu Sans
//! ([`font`]). All output is deterministic and written atomically. This layer sits below the
//! pipeline (which draws previews with it) and never runs it; the studies that run the
//! pipeline and chart the results are [`crate::studies`].

#![warn(missing_docs)]

pub mod bench;
pub mod colormap;
pub mod contour;
pub mod font;
pub mod pareto;
pub mod plot;
pub mod preview;
pub mod raster;

use anyhow::{anyhow, Result};
use image::RgbImage;
use std::path::Path;

/// Write `img` as a PNG file at `path`, atomically (temporary file in the same folder, then
/// rename; see [`crate::io::atomic`]), replacing an existing file. Parent folders are created.
pub fn write_png(path: &Path, img: &RgbImage) -> Result<()> {
    let mut bytes = Vec::new();
    img.write_to(
        &mut std::io::Cursor::new(&mut bytes),
        image::ImageFormat::Png,
    )
    .map_err(|e| anyhow!("{}: cannot encode PNG: {e}", path.display()))?;
    crate::io::atomic::write(path, &bytes, crate::io::atomic::Overwrite::Replace)
}
