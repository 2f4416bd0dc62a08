//! Skin thickness over the face: uniform (`skin.thickness`), from a per-vertex glTF attribute
//! (`skin.thickness_attribute`, metres) or a grey texture sampled at TEXCOORD_0
//! (`skin.thickness_texture`, grey 0..1 → min..max metres), with `[[skin.regions]]` (boxes
//! or spheres in model metres) on top. The result is one thickness per triangle of the face:
//! a triangle takes the mean of its vertices' values, then the last region containing its
//! centroid, if any, overrides it. Where neither attribute nor texture gives it, the eyelids
//! (`skin.lids`, on by default) are thinner than the rest ([`lid_triangles`]).

use super::SkinSection;
use crate::io::load::Rig;
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// `[[skin.regions]]`: a box (`min`, `max`) or a sphere (`centre`, `radius`) in model space
/// (m, the same space as `skin.mask`) and the skin thickness (m) of the triangles whose
/// centroid lies in it. Later regions win where regions overlap.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ThicknessRegion {
    /// Box lower corner (with `max`).
    /// - unit: m
    /// - default: none
    pub min: Option<[f64; 3]>,
    /// Box upper corner (with `min`).
    /// - unit: m
    /// - default: none
    pub max: Option<[f64; 3]>,
    /// Sphere centre (with `radius`).
    /// - unit: m
    /// - default: none
    pub centre: Option<[f64; 3]>,
    /// Sphere radius (with `centre`).
    /// - unit: m
    /// - default: none
    pub radius: Option<f64>,
    /// Skin thickness inside the region.
    /// - unit: m
    /// - default: required
    pub thickness: f64,
}

impl ThicknessRegion {
    /// Whether the point `p` (m) lies in the region (boundary included).
    pub fn contains(&self, p: &Vector3<f64>) -> bool {
        match (self.min, self.max, self.centre, self.radius) {
            (Some(lo), Some(hi), _, _) => (0..3).all(|k| p[k] >= lo[k] && p[k] <= hi[k]),
            (_, _, Some(c), Some(r)) => (p - Vector3::from(c)).norm() <= r,
            _ => false,
        }
    }

    /// Check the region; `key` (e.g. `skin.regions[2]`) names it in the message.
    pub fn validate(&self, key: &str) -> anyhow::Result<()> {
        let is_box = self.min.is_some() || self.max.is_some();
        let is_sphere = self.centre.is_some() || self.radius.is_some();
        match (is_box, is_sphere) {
            (true, true) => {
                bail!("`{key}`: give a box (min, max) or a sphere (centre, radius), not both")
            }
            (false, false) => {
                bail!("`{key}`: give a box (min, max) or a sphere (centre, radius), in metres")
            }
            (true, false) => {
                let (Some(lo), Some(hi)) = (self.min, self.max) else {
                    bail!("`{key}`: a box needs both min and max (m)");
                };
                if lo.iter().chain(&hi).any(|v| !v.is_finite()) || (0..3).any(|k| lo[k] > hi[k]) {
                    bail!("`{key}`: min must be ≤ max on every axis and finite (m)");
                }
            }
            (false, true) => {
                let (Some(c), Some(r)) = (self.centre, self.radius) else {
                    bail!("`{key}`: a sphere needs both centre and radius (m)");
                };
                if c.iter().any(|v| !v.is_finite()) || !(r.is_finite() && r > 0.0) {
                    bail!("`{key}`: the centre must be finite and the radius a positive number of metres, got {r}");
                }
            }
        }
        if !(self.thickness.is_finite() && self.thickness > 0.0) {
            bail!(
                "`{key}.thickness` must be a positive number of metres, got {}",
                self.thickness
            );
        }
        Ok(())
    }
}

/// `skin.thickness_texture`: a grey image (PNG) sampled at the face's TEXCOORD_0 (bilinear,
/// repeat wrap, glTF's convention: u to the right, v down from the image's top-left); grey
/// g ∈ [0, 1] (stored value, no gamma) gives the thickness min + g (max − min) (m).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ThicknessTexture {
    /// Image file (PNG); a relative path is taken from the scene file's folder.
    /// - unit: –
    /// - default: required
    pub path: String,
    /// Thickness at grey 0 (black).
    /// - unit: m
    /// - default: required
    pub min: f64,
    /// Thickness at grey 1 (white).
    /// - unit: m
    /// - default: required
    pub max: f64,
}

impl ThicknessTexture {
    /// Check the range (finite, positive, min ≤ max).
    pub fn validate(&self) -> anyhow::Result<()> {
        if !(self.min.is_finite() && self.min > 0.0 && self.max.is_finite() && self.max >= self.min)
        {
            bail!(
                "`skin.thickness_texture`: min and max are thicknesses in metres with 0 < min ≤ max, got min = {}, max = {}",
                self.min,
                self.max
            );
        }
        if self.path.is_empty() {
            bail!("`skin.thickness_texture.path` is empty");
        }
        Ok(())
    }
}

/// A grey image: values in [0, 1], row-major from the top-left.
#[derive(Debug, Clone, PartialEq)]
pub struct GreyImage {
    /// Width (pixels).
    pub width: usize,
    /// Height (pixels).
    pub height: usize,
    /// Grey values, `width × height`, row 0 at the top.
    pub data: Vec<f32>,
}

impl GreyImage {
    /// Read an image file as grey (luma of colour images, alpha ignored); the error names
    /// the file.
    pub fn load(path: &Path) -> anyhow::Result<Self> {
        let img = image::open(path)
            .with_context(|| format!("{}: cannot read the thickness texture", path.display()))?;
        let g = img.to_luma32f();
        let (w, h) = (g.width() as usize, g.height() as usize);
        if w == 0 || h == 0 {
            bail!("{}: the thickness texture is empty", path.display());
        }
        Ok(Self {
            width: w,
            height: h,
            data: g.into_raw(),
        })
    }

    /// Bilinear sample at texture coordinates (u, v) with repeat wrap (pixel centres at
    /// ((i + ½)/W, (j + ½)/H)).
    pub fn sample(&self, u: f64, v: f64) -> f64 {
        let (w, h) = (self.width as i64, self.height as i64);
        let x = u * w as f64 - 0.5;
        let y = v * h as f64 - 0.5;
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let at = |i: i64, j: i64| -> f64 {
            let (i, j) = (i.rem_euclid(w), j.rem_euclid(h));
            self.data[(j * w + i) as usize] as f64
        };
        let (i, j) = (x0 as i64, y0 as i64);
        (1.0 - fy) * ((1.0 - fx) * at(i, j) + fx * at(i + 1, j))
            + fy * ((1.0 - fx) * at(i, j + 1) + fx * at(i + 1, j + 1))
    }
}

/// Whether the skin section asks for anything but a uniform thickness.
pub fn varies(skin: &SkinSection) -> bool {
    !skin.regions.is_empty()
        || skin.thickness_attribute.is_some()
        || skin.thickness_texture.is_some()
}

/// Per-vertex thickness (m) of the rig's face from its attribute or texture, or `None` when
/// the scene gives neither. `scene_dir` anchors a relative texture path. Errors name the
/// file, the mesh, and the bad value.
pub fn vertex_thickness(
    rig: &Rig,
    skin: &SkinSection,
    scene_dir: Option<&Path>,
) -> anyhow::Result<Option<Vec<f64>>> {
    let file = rig.path.display();
    let face = rig.face();
    if let Some(name) = &skin.thickness_attribute {
        let a = rig.face_attribute(name)?;
        if a.components != 1 || !a.float {
            bail!(
                "{file}: mesh '{}': the thickness attribute {name} must be a SCALAR of 32-bit floats (metres), found {} component(s){}",
                face.name,
                a.components,
                if a.float { "" } else { " of integers" }
            );
        }
        if let Some((v, h)) = a
            .data
            .iter()
            .enumerate()
            .find(|(_, h)| !(h.is_finite() && **h > 0.0))
        {
            bail!(
                "{file}: mesh '{}': thickness attribute {name} of vertex {v} is {h}; it must be a positive number of metres",
                face.name
            );
        }
        return Ok(Some(a.data));
    }
    if let Some(t) = &skin.thickness_texture {
        let uv = rig.face_attribute("TEXCOORD_0").map_err(|e| {
            anyhow::anyhow!(
                "{e}; skin.thickness_texture is sampled at TEXCOORD_0: give the face texture coordinates or use regions / an attribute"
            )
        })?;
        if uv.components != 2 {
            bail!(
                "{file}: mesh '{}': TEXCOORD_0 has {} components, not 2",
                face.name,
                uv.components
            );
        }
        let p = Path::new(&t.path);
        let p = match scene_dir {
            Some(d) if p.is_relative() => d.join(p),
            _ => p.to_path_buf(),
        };
        let img = GreyImage::load(&p)?;
        return Ok(Some(
            uv.data
                .chunks(2)
                .map(|c| t.min + img.sample(c[0], c[1]).clamp(0.0, 1.0) * (t.max - t.min))
                .collect(),
        ));
    }
    Ok(None)
}

/// The thickness under the regions: per vertex, or uniform with the lids' own.
#[derive(Debug, Clone, Copy)]
pub struct BaseThickness<'a> {
    /// Per-vertex thickness (m) from an attribute or texture; the others are unused with it.
    pub vertex_h: Option<&'a [f64]>,
    /// The skin's thickness (m).
    pub uniform: f64,
    /// The lids' thickness (m) and a flag per triangle ([`rig_lids`]).
    pub lids: Option<(f64, &'a [bool])>,
}

impl BaseThickness<'_> {
    /// The thickness of triangle `t` (m) with corners `tri`.
    fn of(&self, t: usize, tri: &[usize; 3]) -> f64 {
        match (self.vertex_h, self.lids) {
            (Some(vh), _) => tri.iter().map(|&v| vh[v]).sum::<f64>() / 3.0,
            (None, Some((h, lid))) if lid[t] => h,
            _ => self.uniform,
        }
    }
}

/// Thickness per triangle (m): its `base` (the mean of its vertices' thickness, the lids' or the
/// uniform one), then the last of `regions` that contains the triangle's centroid overrides
/// it. Refuses a value not below `model_size` (m), the face's bounding-box diagonal: a skin
/// thicker than the model it covers is a unit mistake.
pub fn face_thickness(
    positions: &[Vector3<f64>],
    triangles: &[[usize; 3]],
    base: BaseThickness,
    regions: &[ThicknessRegion],
    model_size: f64,
) -> anyhow::Result<Vec<f64>> {
    let h: Vec<f64> = triangles
        .iter()
        .enumerate()
        .map(|(i, t)| {
            let c = t.iter().map(|&v| positions[v]).sum::<Vector3<f64>>() / 3.0;
            let base = base.of(i, t);
            regions
                .iter()
                .rev()
                .find(|r| r.contains(&c))
                .map_or(base, |r| r.thickness)
        })
        .collect();
    if let Some(&big) = h.iter().find(|&&x| x.is_nan() || x >= model_size) {
        bail!(
            "a skin thickness of {big} m is not below the face's size ({model_size:.4} m): thicknesses are in metres"
        );
    }
    Ok(h)
}

/// Share of a blink shape's largest displacement beyond which it moves a vertex of the lid
/// (dimensionless): as the muscles' own "vertices a shape moves" measure.
pub const LID_MOTION_SHARE: f64 = 0.1;

/// The eyelids of a face: the triangles with a vertex that one of its blink shapes (a morph
/// target whose name holds "blink", any case: ARKit's `eyeBlinkLeft`/`eyeBlinkRight`) moves by
/// more than [`LID_MOTION_SHARE`] of that shape's largest displacement. Empty without blink
/// shapes. Why they matter: a blink stretches the lid's skin by about a third, and skin as
/// thick as the face's elsewhere would pull the muscle-driven flesh about the eyes with it
/// until the forehead buckles; real eyelid skin is about half as thick.
/// Returns one flag per triangle and the names of the shapes used.
pub fn lid_triangles(face: &crate::io::mesh::MeshInstance) -> (Vec<bool>, Vec<String>) {
    let mut moved = vec![false; face.positions.len()];
    let mut names = Vec::new();
    for target in face
        .targets
        .iter()
        .filter(|t| t.name.to_lowercase().contains("blink"))
    {
        let most = target
            .positions
            .iter()
            .map(|d| d.norm())
            .fold(0.0, f64::max);
        if most <= 0.0 {
            continue;
        }
        for (m, d) in moved.iter_mut().zip(&target.positions) {
            *m |= d.norm() > LID_MOTION_SHARE * most;
        }
        names.push(target.name.clone());
    }
    let lid = face
        .triangles
        .iter()
        .map(|t| t.iter().any(|&v| moved[v]))
        .collect();
    (lid, names)
}

/// The lids' thickness (m) and flags per face triangle when `skin.lids` is on (default), no
/// attribute or texture gives the thickness, and the face has blink shapes; `uniform` is the
/// skin's thickness (m).
pub fn rig_lids(rig: &Rig, skin: &SkinSection, uniform: f64) -> Option<(f64, Vec<bool>)> {
    let on = skin.lids.unwrap_or_default() == super::Lids::Auto;
    if !on || skin.thickness_attribute.is_some() || skin.thickness_texture.is_some() {
        return None;
    }
    let (lid, names) = lid_triangles(rig.face());
    (!names.is_empty() && lid.contains(&true))
        .then(|| (skin.lid_thickness.unwrap_or(0.5 * uniform), lid))
}

/// Thickness of every triangle of the rig's face (m), from the scene's skin section and the
/// uniform thickness `uniform` (m), with the lids' ([`rig_lids`]) before the regions.
/// `scene_dir` anchors a relative texture path.
pub fn rig_face_thickness(
    rig: &Rig,
    skin: &SkinSection,
    uniform: f64,
    scene_dir: Option<&Path>,
) -> anyhow::Result<Vec<f64>> {
    let lids = rig_lids(rig, skin, uniform);
    rig_face_thickness_with(rig, skin, uniform, scene_dir, lids.as_ref())
}

/// [`rig_face_thickness`] with the lids already found (`lids`: [`rig_lids`]'s result), for a
/// caller that also needs them.
pub fn rig_face_thickness_with(
    rig: &Rig,
    skin: &SkinSection,
    uniform: f64,
    scene_dir: Option<&Path>,
    lids: Option<&(f64, Vec<bool>)>,
) -> anyhow::Result<Vec<f64>> {
    let face = rig.face();
    let vh = vertex_thickness(rig, skin, scene_dir)?;
    let (lo, hi) = face.positions.iter().fold(
        (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        ),
        |(lo, hi), p| (lo.inf(p), hi.sup(p)),
    );
    let size = (hi - lo).norm();
    face_thickness(
        &face.positions,
        &face.triangles,
        BaseThickness {
            vertex_h: vh.as_deref(),
            uniform,
            lids: lids.map(|(h, l)| (*h, l.as_slice())),
        },
        &skin.regions,
        size,
    )
    .with_context(|| format!("{}: mesh '{}'", rig.path.display(), face.name))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A base without lids.
    fn base(vertex_h: Option<&[f64]>, uniform: f64) -> BaseThickness<'_> {
        BaseThickness {
            vertex_h,
            uniform,
            lids: None,
        }
    }

    #[test]
    fn bilinear_sampling_interpolates_and_wraps() {
        // 2 × 1 image: 0 on the left pixel, 1 on the right.
        let img = GreyImage {
            width: 2,
            height: 1,
            data: vec![0.0, 1.0],
        };
        assert!((img.sample(0.25, 0.5) - 0.0).abs() < 1e-12);
        assert!((img.sample(0.75, 0.5) - 1.0).abs() < 1e-12);
        assert!((img.sample(0.5, 0.5) - 0.5).abs() < 1e-12);
        // u = 0 sits between the right pixel (wrapped) and the left one.
        assert!((img.sample(0.0, 0.5) - 0.5).abs() < 1e-12);
        assert!((img.sample(1.375, 0.5) - 0.25).abs() < 1e-12);
    }

    #[test]
    fn regions_override_later_wins_and_bad_regions_are_named() {
        let p = vec![
            Vector3::new(0.0, 0.0, 0.0),
            Vector3::new(1.0, 0.0, 0.0),
            Vector3::new(0.0, 1.0, 0.0),
            Vector3::new(3.0, 0.0, 0.0),
            Vector3::new(3.0, 1.0, 0.0),
        ];
        let t = vec![[0, 1, 2], [1, 3, 4]];
        let boxr = ThicknessRegion {
            min: Some([-1.0, -1.0, -1.0]),
            max: Some([5.0, 5.0, 1.0]),
            thickness: 2e-3,
            ..Default::default()
        };
        let sphere = ThicknessRegion {
            centre: Some([0.3, 0.3, 0.0]),
            radius: Some(0.2),
            thickness: 5e-4,
            ..Default::default()
        };
        let vh = [1e-3, 1e-3, 1e-3, 3e-3, 3e-3];
        let h = face_thickness(&p, &t, base(Some(&vh), 9.0), &[], 10.0).unwrap();
        assert_eq!(h, vec![1e-3, (1e-3 + 6e-3) / 3.0]);
        let h = face_thickness(&p, &t, base(None, 1e-3), &[boxr, sphere], 10.0).unwrap();
        assert_eq!(h, vec![5e-4, 2e-3]);
        let h = face_thickness(&p, &t, base(None, 1e-3), &[sphere, boxr], 10.0).unwrap();
        assert_eq!(h, vec![2e-3, 2e-3]);
        let e = face_thickness(&p, &t, base(None, 20.0), &[], 10.0).unwrap_err();
        assert!(format!("{e}").contains("metres"), "{e}");
        let both = ThicknessRegion {
            radius: Some(1.0),
            ..boxr
        };
        let e = both.validate("skin.regions[1]").unwrap_err();
        assert!(format!("{e}").contains("skin.regions[1]"), "{e}");
        let e = ThicknessRegion {
            thickness: -1.0,
            ..sphere
        }
        .validate("skin.regions[0]")
        .unwrap_err();
        assert!(format!("{e}").contains("skin.regions[0].thickness"), "{e}");
    }
}
