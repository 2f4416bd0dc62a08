//! The scene's choices: each key that takes one of a few named values is an enum, parsed once
//! when the scene is read. A value outside the list is refused by the TOML parser with the
//! line of the key and the allowed values.

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// Declares a scene choice: a unit-variant enum serialised in snake_case whose first
/// variant is the default, with its name as written in a scene file.
macro_rules! choice {
    ($(#[$doc:meta])* $name:ident { $(#[$fdoc:meta])* $first:ident = $ftext:literal, $($(#[$vdoc:meta])* $variant:ident = $text:literal,)* }) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
        #[serde(rename_all = "snake_case")]
        pub enum $name {
            $(#[$fdoc])* $first,
            $($(#[$vdoc])* $variant,)*
        }

        impl $name {
            /// The value as written in a scene file.
            pub fn as_str(&self) -> &'static str {
                match self {
                    $name::$first => $ftext,
                    $($name::$variant => $text,)*
                }
            }
        }

        impl Default for $name {
            fn default() -> Self {
                $name::$first
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.pad(self.as_str())
            }
        }
    };
}

choice! {
    /// `skin.lids`: whether the eyelids get their own, thinner skin.
    Lids {
        /// The skin the rig's blink shapes move gets `skin.lid_thickness`.
        Auto = "auto",
        /// The lids have the rest of the skin's thickness.
        Off = "off",
    }
}

choice! {
    /// `skin.simulate`: which skin the shell simulates.
    SkinSelection {
        /// The triangles some frame compresses past the threshold, plus a margin of one λ.
        Compressed = "compressed",
        /// The whole skin.
        All = "all",
    }
}

choice! {
    /// `skin.membrane`: the membrane law of the skin.
    MembraneLaw {
        /// Corotated linear in the principal stretches, stable in compression.
        Biot = "biot",
        /// Saint Venant–Kirchhoff, which softens past 42 % compression (the reference).
        Stvk = "stvk",
    }
}

choice! {
    /// `interior.elements`: the lattice's element kind.
    ElementKind {
        /// 27-node quadratic B-spline hexahedra.
        Quadratic = "quadratic",
        /// 8-node trilinear hexahedra, for comparison.
        Trilinear = "trilinear",
    }
}

choice! {
    /// `muscles.skin_hold`: how the muscles hold the skin's pull on the lattice.
    ///
    /// The blend shapes are the face's equilibria with its skin on, so the muscles that make
    /// them also hold the skin there. The skin's force is not linear in the activations
    /// (wrinkling relieves its compression), so a per-shape hold summed over a frame's shapes
    /// mispredicts it while the state reached carries it exactly.
    SkinHold {
        /// At the state the interior reaches, every step: an active force equal and opposite
        /// to the skin's pull, so the skin rides on the flesh the muscles shape and does not
        /// load it (the actuations are fitted against the flesh alone, as the interior they
        /// drive then is).
        Reached = "reached",
        /// Each generated muscle's actuation holds the skin's force at its own blend shape, a
        /// constant load in its fit; the skin's actual force loads the interior.
        Shapes = "shapes",
        /// Nothing holds the skin: its force loads the muscle-driven interior, which the
        /// muscles, fitted against the flesh alone, do not expect.
        None = "none",
    }
}

choice! {
    /// `muscles.skin_at_shapes`: how the skin's force at each blend shape is found for
    /// `skin_hold = "shapes"`.
    SkinAtShapes {
        /// The membrane relaxed over wrinkles at the shape's smooth surface (milliseconds per
        /// shape).
        TensionField = "tension_field",
        /// The skin solved quasi-statically from rest on the shape's lattice fit (the
        /// reference; seconds per shape).
        Solved = "solved",
    }
}

choice! {
    /// `solver.interior_tangent`: the interior's Newton matrix.
    InteriorTangent {
        /// With the rotation's derivative: quadratic convergence.
        Consistent = "consistent",
        /// The warped stiffness R K₀ Rᵀ: linear convergence (the reference).
        Frozen = "frozen",
    }
}

choice! {
    /// `solver.skin_stiffness`: when the interior's view of the skin's stiffness Bᵀ K_x B is
    /// rebuilt.
    SkinStiffness {
        /// At rest; the force Bᵀ F_x is always current.
        Once = "once",
        /// Every frame (the paper).
        EveryFrame = "every_frame",
    }
}

choice! {
    /// `solver.skin_solver`: how the skin's Newton directions are solved.
    SkinSolver {
        /// GMRES preconditioned with a lagged single-precision factor of the whole skin.
        Lagged = "lagged",
        /// The lagged factor corrected by fresh factors of the patches whose Hessian changed.
        Patches = "patches",
        /// A double-precision factor, made afresh when the last one stops converging (the
        /// reference).
        Global = "global",
    }
}

choice! {
    /// `export.surface`: what surface the written file carries.
    ExportSurface {
        /// The blend-shape surface plus the skin's wrinkles x − B q: the artist's shape kept.
        WrinklesOnBlend = "wrinkles_on_blend",
        /// The simulated skin itself, with the interior's low-frequency motion.
        Simulated = "simulated",
    }
}

choice! {
    /// `geometry.kind`: the shape of a synthetic scene's block.
    GeometryKind {
        /// A flat slab of flesh under a skin on its top face.
        Slab = "slab",
        /// A slab with rounded edges.
        Cushion = "cushion",
        /// A cube skinned on every face.
        Cube = "cube",
    }
}

/// `muscles.source`: where the interior's muscles come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum MuscleSource {
    /// Generated from the blend shapes, their activations fitted to every frame.
    Auto,
    /// No muscles: the interior tracks the blended surface.
    None,
    /// A muscle TOML file at this path.
    File(String),
}

impl MuscleSource {
    /// The value as written in a scene file.
    pub fn as_str(&self) -> &str {
        match self {
            MuscleSource::Auto => "auto",
            MuscleSource::None => "none",
            MuscleSource::File(p) => p,
        }
    }
}

impl std::fmt::Display for MuscleSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

impl Serialize for MuscleSource {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.serialize_str(self.as_str())
    }
}

impl<'de> Deserialize<'de> for MuscleSource {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let text = String::deserialize(d)?;
        match text.as_str() {
            "auto" => Ok(MuscleSource::Auto),
            "none" => Ok(MuscleSource::None),
            "" => Err(serde::de::Error::custom(
                "`muscles.source` is empty: use \"auto\", \"none\" or a file path",
            )),
            _ => Ok(MuscleSource::File(text)),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize)]
    struct Holder {
        hold: SkinHold,
        source: MuscleSource,
    }

    /// Values parse from their snake_case names and print back the same; a value outside
    /// the list is refused with the allowed values.
    #[test]
    fn choices_parse_print_and_refuse() {
        let h: Holder = toml::from_str("hold = \"shapes\"\nsource = \"m.toml\"").unwrap();
        assert_eq!(h.hold, SkinHold::Shapes);
        assert_eq!(h.source, MuscleSource::File("m.toml".into()));
        assert_eq!(SkinHold::Shapes.to_string(), "shapes");
        assert_eq!(SkinSolver::default(), SkinSolver::Lagged);
        assert_eq!(SkinHold::default(), SkinHold::Reached);
        let e = toml::from_str::<Holder>("hold = \"always\"\nsource = \"auto\"")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("always") && e.contains("reached"), "{e}");
        let e = toml::from_str::<Holder>("hold = \"none\"\nsource = \"\"")
            .err()
            .unwrap()
            .to_string();
        assert!(e.contains("empty"), "{e}");
    }
}
