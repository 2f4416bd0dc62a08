//! Named material presets with measured-order-of-magnitude values (SI units).
//!
//! Skins are thin sheets (Young's modulus in Pa, Poisson's ratio, thickness in m); interiors are
//! soft solids (Young's modulus in Pa, Poisson's ratio, density in kg/m³). The values are
//! representative of the literature ranges, chosen so the wrinkle wavelength of the usual pairs is
//! the familiar one (a face skin on flesh wrinkles at about 2 cm, a leather cover on foam at a few
//! centimetres); every field can be overridden in the scene file.

use crate::fem::Material;
use crate::shell::ShellMaterial;

/// A named skin preset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SkinPreset {
    /// Preset name used in scene files.
    pub name: &'static str,
    /// The sheet's constants.
    pub material: ShellMaterial,
    /// Where the numbers come from.
    pub note: &'static str,
}

/// A named interior preset.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InteriorPreset {
    /// Preset name used in scene files.
    pub name: &'static str,
    /// The solid's constants.
    pub material: Material,
    /// Where the numbers come from.
    pub note: &'static str,
}

/// Skin presets: `skin`, `leather`, `rubber`, `latex`.
pub const SKIN_PRESETS: [SkinPreset; 4] = [
    SkinPreset {
        name: "skin",
        material: ShellMaterial {
            young: 1.0e6,
            poisson: 0.45,
            thickness: 1.0e-3,
        },
        note: "human facial skin (epidermis + dermis): E ≈ 0.1–2 MPa in vivo, 1–2 mm thick",
    },
    SkinPreset {
        name: "leather",
        material: ShellMaterial {
            young: 40.0e6,
            poisson: 0.4,
            thickness: 2.0e-3,
        },
        note: "upholstery leather: E ≈ 10–100 MPa, 1–2 mm (a couch's cover)",
    },
    SkinPreset {
        name: "rubber",
        material: ShellMaterial {
            young: 2.0e6,
            poisson: 0.49,
            thickness: 1.0e-3,
        },
        note: "soft natural rubber sheet: E ≈ 1–5 MPa, nearly incompressible",
    },
    SkinPreset {
        name: "latex",
        material: ShellMaterial {
            young: 1.0e6,
            poisson: 0.49,
            thickness: 0.3e-3,
        },
        note: "thin latex film: E ≈ 1 MPa, 0.1–0.5 mm",
    },
];

/// Interior presets: `flesh`, `foam`, `gel`.
pub const INTERIOR_PRESETS: [InteriorPreset; 3] = [
    InteriorPreset {
        name: "flesh",
        material: Material {
            young: 1.0e4,
            poisson: 0.45,
            density: 1050.0,
        },
        note: "subcutaneous tissue and relaxed muscle: E ≈ 2–30 kPa, ρ ≈ 1050 kg/m³",
    },
    InteriorPreset {
        name: "foam",
        material: Material {
            young: 0.5e6,
            poisson: 0.3,
            density: 40.0,
        },
        note: "polyurethane upholstery foam: E ≈ 0.1–1 MPa, ρ ≈ 30–50 kg/m³",
    },
    InteriorPreset {
        name: "gel",
        material: Material {
            young: 5.0e3,
            poisson: 0.45,
            density: 1000.0,
        },
        note: "soft silicone gel: E ≈ 1–10 kPa",
    },
];

/// The skin preset called `name`.
pub fn skin_preset(name: &str) -> Option<&'static SkinPreset> {
    SKIN_PRESETS.iter().find(|p| p.name == name)
}

/// The interior preset called `name`.
pub fn interior_preset(name: &str) -> Option<&'static InteriorPreset> {
    INTERIOR_PRESETS.iter().find(|p| p.name == name)
}

/// Names of all presets of one kind, for error messages.
pub fn names<T>(list: &[T], name: impl Fn(&T) -> &'static str) -> String {
    list.iter().map(name).collect::<Vec<_>>().join(", ")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::coupling::wavelength::Bilayer;

    #[test]
    fn presets_are_valid_and_give_the_documented_wavelengths() {
        for p in &SKIN_PRESETS {
            p.material.validate().unwrap();
        }
        for p in &INTERIOR_PRESETS {
            p.material.validate().unwrap();
        }
        let lam = |s: &str, i: &str| {
            let s = skin_preset(s).unwrap().material;
            let i = interior_preset(i).unwrap().material;
            Bilayer {
                thickness: s.thickness,
                skin_modulus: s.young,
                skin_poisson: s.poisson,
                interior_modulus: i.young,
                interior_poisson: i.poisson,
            }
            .critical_wavelength()
        };
        // Face skin on flesh: λ = 2π·1 mm·(1−0.45²)·… ≈ 2 cm.
        let face = lam("skin", "flesh");
        assert!((0.015..0.025).contains(&face), "{face}");
        // Leather on foam (a couch, ν differ slightly): ≈ 3.7 cm.
        let couch = lam("leather", "foam");
        assert!((0.033..0.042).contains(&couch), "{couch}");
        assert!(skin_preset("nope").is_none());
    }
}
