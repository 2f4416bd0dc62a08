//! A rig's length unit: how many metres one unit of the file is. glTF says metres, but
//! exporters often do not care; furrow's material presets are human tissue, so a face ten
//! times human size would wrinkle at a tenth of its scale (or not at all: too coarse a skin).
//! By default (`auto`) a face that is larger or smaller than a human face by a power of ten
//! is simulated at human size, and the output is written back in the file's own units.

use super::load::Rig;
use super::mesh::MeshInstance;
pub use super::model::RigScale;
use nalgebra::Vector3;
use serde::{Deserialize, Serialize};

/// Height range of a human face (m), over what its blend shapes move: brow to chin is about
/// 0.12 m, a whole head about 0.25 m; a face rig's moving region lies in between.
pub const HUMAN_FACE_M: (f64, f64) = (0.12, 0.4);

/// Fraction of the largest target motion below which a vertex counts as not moved.
const MOVED_FRACTION: f64 = 0.01;

/// `[rig] scale` and `--scale`: `auto` or metres per file unit.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum ScaleSetting {
    /// Simulate at human size when the face is off by a power of ten (the default).
    #[default]
    Auto,
    /// Metres per file unit, as given (1: the file is in metres, as glTF says).
    MetresPerUnit(f64),
}

impl ScaleSetting {
    /// Parse `auto` or a positive number (metres per file unit); the error names `what`.
    pub fn parse(text: &str, what: &str) -> anyhow::Result<Self> {
        let t = text.trim();
        if t.eq_ignore_ascii_case("auto") {
            return Ok(Self::Auto);
        }
        let v: f64 = t.parse().map_err(|_| {
            anyhow::anyhow!(
                "{what} = {text:?}: give \"auto\" or the metres one unit of the file is \
                 (1 for metres, 0.01 for centimetres)"
            )
        })?;
        Self::metres(v, what)
    }

    /// A checked metres-per-unit setting.
    pub fn metres(v: f64, what: &str) -> anyhow::Result<Self> {
        if !(v.is_finite() && (1e-6..=1e6).contains(&v)) {
            anyhow::bail!("{what} = {v}: metres per file unit must lie in [1e-6, 1e6]");
        }
        Ok(Self::MetresPerUnit(v))
    }
}

impl Serialize for ScaleSetting {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            Self::Auto => s.serialize_str("auto"),
            Self::MetresPerUnit(v) => s.serialize_f64(*v),
        }
    }
}

impl<'de> Deserialize<'de> for ScaleSetting {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        #[derive(Deserialize)]
        #[serde(untagged)]
        enum Raw {
            Text(String),
            Number(f64),
        }
        let r = match Raw::deserialize(d)? {
            Raw::Text(t) => Self::parse(&t, "rig.scale"),
            Raw::Number(v) => Self::metres(v, "rig.scale"),
        };
        r.map_err(serde::de::Error::custom)
    }
}

/// The height (largest bounding-box side, file units) of the vertices the targets of `face`
/// move by more than 1 % of the largest motion; the whole face's when that is one point.
pub fn moved_extent(face: &MeshInstance) -> f64 {
    let motion: Vec<f64> = (0..face.positions.len())
        .map(|v| {
            face.targets
                .iter()
                .map(|t| t.positions[v].norm())
                .fold(0.0, f64::max)
        })
        .collect();
    let largest = motion.iter().copied().fold(0.0, f64::max);
    let extent = |pick: &dyn Fn(usize) -> bool| {
        let (mut lo, mut hi) = (
            Vector3::repeat(f64::INFINITY),
            Vector3::repeat(f64::NEG_INFINITY),
        );
        for (_, p) in face.positions.iter().enumerate().filter(|&(v, _)| pick(v)) {
            lo = lo.inf(p);
            hi = hi.sup(p);
        }
        (hi - lo).max()
    };
    let moved = extent(&|v| largest > 0.0 && motion[v] > MOVED_FRACTION * largest);
    if moved.is_finite() && moved > 0.0 {
        moved
    } else {
        extent(&|_| true)
    }
}

/// The power of ten 10^k that brings a face `size` (m) nearest to [`HUMAN_FACE_M`] (on a log
/// scale; 1 when it is already inside, the smaller |k| among equals).
pub fn human_factor(size: f64) -> f64 {
    if !(size.is_finite() && size > 0.0) {
        return 1.0;
    }
    let (lo, hi) = (HUMAN_FACE_M.0.log10(), HUMAN_FACE_M.1.log10());
    let off = |k: i32| {
        let s = size.log10() + k as f64;
        (lo - s).max(s - hi).max(0.0)
    };
    let k = (-12..=12)
        .min_by(|&a: &i32, &b| off(a).total_cmp(&off(b)).then(a.abs().cmp(&b.abs())))
        .unwrap_or(0);
    10f64.powi(k)
}

/// Decide the scale of `rig` from `setting` (file units as loaded: metres per glTF).
pub fn decide(rig: &Rig, setting: ScaleSetting) -> RigScale {
    let size = moved_extent(rig.face());
    match setting {
        ScaleSetting::MetresPerUnit(m) => RigScale {
            metres_per_unit: m,
            face_size: size,
            why: format!("scale = {m} m per file unit, as set (the face is {size:.3} units tall)"),
        },
        ScaleSetting::Auto => {
            let f = human_factor(size);
            let why = if f == 1.0 {
                format!(
                    "the face is {size:.3} m tall (what its blend shapes move), human size: \
                     simulated as in the file"
                )
            } else {
                format!(
                    "the face is {size:.3} m tall (what its blend shapes move), not a human \
                     face's {:.2}–{:.2} m: simulated at {f} m per file unit ({:.3} m tall; set \
                     `--scale 1` or `[rig] scale = 1` to keep the file's size), written back in \
                     the file's units",
                    HUMAN_FACE_M.0,
                    HUMAN_FACE_M.1,
                    size * f
                )
            };
            RigScale {
                metres_per_unit: f,
                face_size: size,
                why,
            }
        }
    }
}

/// clap's parser for `--scale` (`auto` or metres per file unit).
pub fn scale_arg(text: &str) -> Result<ScaleSetting, String> {
    ScaleSetting::parse(text, "--scale").map_err(|e| e.to_string())
}

/// Decide and apply the scale of `rig`: `--scale` (`flag`) over the scene's `[rig] scale`
/// over `auto`. Returns why, to be said.
pub fn apply(rig: &mut Rig, flag: Option<ScaleSetting>, scene: Option<ScaleSetting>) -> String {
    let scale = decide(rig, flag.or(scene).unwrap_or_default());
    let why = scale.why.clone();
    rig.rescale(scale);
    why
}

impl Rig {
    /// Simulate the rig at `scale`: every position and morph delta is multiplied by its
    /// metres per unit, and the local-to-world transforms with it, so that results mapped
    /// back to the file's local coordinates come out in the file's own units.
    pub fn rescale(&mut self, scale: RigScale) {
        let f = scale.metres_per_unit;
        if f != 1.0 {
            self.instances.iter_mut().for_each(|m| m.scale(f));
            self.skin.scale(f);
        }
        self.scale = scale;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn human_factor_is_the_nearest_power_of_ten() {
        assert_eq!(human_factor(0.2), 1.0);
        assert_eq!(human_factor(0.12), 1.0);
        assert_eq!(human_factor(2.3), 0.1);
        assert_eq!(human_factor(20.0), 0.01);
        assert_eq!(human_factor(0.002), 100.0);
        // 0.06 m is 0.30 decades below the range, 0.6 m 0.18 above: ×10.
        assert_eq!(human_factor(0.06), 10.0);
        assert_eq!(human_factor(f64::NAN), 1.0);
    }

    #[test]
    fn settings_parse_and_refuse_nonsense() {
        assert_eq!(
            ScaleSetting::parse("auto", "s").unwrap(),
            ScaleSetting::Auto
        );
        assert_eq!(
            ScaleSetting::parse("0.01", "s").unwrap(),
            ScaleSetting::MetresPerUnit(0.01)
        );
        assert!(ScaleSetting::parse("-1", "--scale").is_err());
        let e = ScaleSetting::parse("cm", "--scale")
            .unwrap_err()
            .to_string();
        assert!(e.contains("--scale") && e.contains("auto"), "{e}");
    }
}
