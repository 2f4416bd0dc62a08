//! The one font furrow draws text with (DejaVu Sans, shipped in `fonts/` with its licence), so
//! plots and preview labels look the same on every machine, with no system fonts.

use image::RgbImage;
use plotters::prelude::*;
use plotters::style::{register_font, FontStyle};
use std::sync::Once;

/// DejaVu Sans 2.37 (Bitstream Vera licence with public-domain DejaVu changes; see
/// `fonts/DejaVuSans-LICENSE.txt`).
pub static DEJAVU_SANS: &[u8] = include_bytes!("fonts/DejaVuSans.ttf");

/// Font family name under which the shipped font is registered with plotters (the family
/// plotters uses by default for axis labels, titles and legends).
pub const FAMILY: &str = "sans-serif";

static REGISTER: Once = Once::new();

/// Register the shipped font with plotters (once per process; later calls do nothing). Every
/// drawing function in [`crate::render`] calls this first, so callers normally need not.
pub fn ensure_registered() {
    REGISTER.call_once(|| {
        // The font is compiled in and known to parse; a failure here is a broken build.
        if register_font(FAMILY, FontStyle::Normal, DEJAVU_SANS).is_err() {
            panic!("the shipped DejaVu Sans font failed to parse");
        }
        for family in ["serif", "monospace", "DejaVu Sans"] {
            let _ = register_font(family, FontStyle::Normal, DEJAVU_SANS);
        }
    });
}

/// Draw `text` onto `img` with its top-left corner at pixel `(x, y)`, `height_px` pixels tall,
/// in colour `rgb`. Text outside the image is clipped.
pub fn draw_text(img: &mut RgbImage, text: &str, x: i32, y: i32, height_px: f64, rgb: [u8; 3]) {
    ensure_registered();
    let (w, h) = img.dimensions();
    if w == 0 || h == 0 || text.is_empty() {
        return;
    }
    let root = BitMapBackend::with_buffer(img, (w, h)).into_drawing_area();
    let color = RGBColor(rgb[0], rgb[1], rgb[2]);
    let style = TextStyle::from((FAMILY, height_px).into_font()).color(&color);
    // Drawing into an in-memory buffer cannot fail except for a missing font, which
    // `ensure_registered` rules out; a glyph error only loses the label, never the image.
    let _ = root.draw_text(text, &style, (x, y));
    let _ = root.present();
}

/// Width and height (pixels) that `text` takes at `height_px` pixels.
pub fn text_size(text: &str, height_px: f64) -> (u32, u32) {
    ensure_registered();
    let font = (FAMILY, height_px).into_font();
    match font.box_size(text) {
        Ok((w, h)) => (w, h),
        Err(_) => (
            (text.chars().count() as f64 * height_px * 0.6) as u32,
            height_px as u32,
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn text_is_drawn_and_measured() {
        let mut img = RgbImage::from_pixel(120, 40, image::Rgb([255, 255, 255]));
        draw_text(&mut img, "λ = 4.04 mm", 4, 4, 20.0, [0, 0, 0]);
        let dark = img.pixels().filter(|p| p.0[0] < 128).count();
        // Nine glyphs of ~20 px: dozens to hundreds of dark pixels, never none nor all.
        assert!(dark > 50 && dark < 120 * 40 / 2, "dark pixels {dark}");
        let (tw, th) = text_size("λ = 4.04 mm", 20.0);
        assert!(tw > 60 && tw < 160 && (10..=30).contains(&th), "{tw}×{th}");
    }
}
