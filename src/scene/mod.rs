//! What a run needs: materials, lattice, skin, dynamics, muscles, solver and export settings,
//! read from a TOML scene file (every key optional; a missing file means the defaults).
//!
//! Two kinds of scene share this schema: rig scenes (`furrow animate RIG --scene S.toml`, the face
//! comes from the glTF) and synthetic scenes (`furrow scene S.toml`, with a `[geometry]` and a
//! `[load]` section: slabs, cushions, cubes). Unknown keys are errors (a typo must not silently
//! fall back to a default), and every value is checked with a message naming the key.

pub mod choices;
pub mod materials;
pub mod thickness;

use crate::fem::Material;
use crate::shell::ShellMaterial;
use anyhow::{bail, Context};
pub use choices::{
    ElementKind, ExportSurface, GeometryKind, InteriorTangent, Lids, MembraneLaw, MuscleSource,
    SkinAtShapes, SkinHold, SkinSelection, SkinSolver, SkinStiffness,
};
use serde::{Deserialize, Serialize};
use std::path::Path;
pub use thickness::{ThicknessRegion, ThicknessTexture};

/// A whole scene file. Every key is optional; `docs/scenes.md` lists each with its unit,
/// default and meaning, generated from the doc comments of this module and
/// [`thickness`]: each field's doc ends with a `- unit:` and a `- default:` line
/// (`tests/docs.rs` checks that the page is current).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scene {
    /// The scene's name: `furrow scene` names its output files `NAME.glb` and `NAME.json`.
    /// - unit: –
    /// - default: the scene file's name without its extension
    pub name: Option<String>,
    /// The rig file's units.
    pub rig: RigSection,
    /// The skin (thin shell).
    pub skin: SkinSection,
    /// The interior (lattice solid).
    pub interior: InteriorSection,
    /// Time stepping.
    pub dynamics: DynamicsSection,
    /// Muscles and the activation fit.
    pub muscles: MuscleSection,
    /// Solver tolerances.
    pub solver: SolverSection,
    /// What the exported files carry.
    pub export: ExportSection,
    /// Synthetic geometry (`furrow scene` only).
    pub geometry: Option<Geometry>,
    /// The load applied to synthetic geometry (`furrow scene` only).
    pub load: Option<Load>,
}

/// `[rig]`: how the rig file is read.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RigSection {
    /// Metres per file unit, or `"auto"`: a face larger or smaller than a human face by a
    /// power of ten is simulated at human size and written back in its own units. A scene
    /// whose materials are for another scale (a robot) sets `scale = 1`. Boxes and regions
    /// of the scene are in simulated metres (after this scale). `--scale` overrides it.
    /// - unit: m per file unit
    /// - default: `"auto"`
    pub scale: Option<crate::io::units::ScaleSetting>,
    /// The face mesh's skin primitives, by index in the mesh or material name (e.g.
    /// `[0, "M_BackHead"]`); the others ride along unchanged. `--skin-primitives` overrides
    /// it.
    /// - unit: –
    /// - default: decided from the materials (alpha-blended and alpha-masked cards ride
    ///   along) and the geometry (the largest surface the shapes move is skin; closed or
    ///   small surfaces apart from it ride along)
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_primitives: Option<Vec<crate::io::parts::PrimitivePick>>,
}

/// `[skin]`: the thin shell's material, thickness and resolution.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkinSection {
    /// Material preset: `skin`, `leather`, `rubber` or `latex` (see the presets table).
    /// - unit: –
    /// - default: `"skin"`
    pub preset: Option<String>,
    /// Young's modulus E_x of the skin; overrides the preset's.
    /// - unit: Pa
    /// - default: the preset's
    pub young: Option<f64>,
    /// Poisson's ratio ν_x of the skin, in (−1, 0.5); overrides the preset's.
    /// - unit: –
    /// - default: the preset's
    pub poisson: Option<f64>,
    /// Uniform thickness h, overriding the preset's: the skin's thickness wherever no
    /// attribute, texture, lid or region gives another.
    /// - unit: m
    /// - default: the preset's
    pub thickness: Option<f64>,
    /// Regions of another thickness (`[[skin.regions]]`, boxes or spheres in model metres,
    /// each with its `thickness`): a triangle whose centroid lies in one takes its
    /// thickness; later regions win. Applied on top of the attribute, texture or lids.
    /// - unit: m
    /// - default: none
    pub regions: Vec<ThicknessRegion>,
    /// Name of a per-vertex SCALAR float glTF attribute of the face holding the thickness in
    /// metres, e.g. `"_THICKNESS"`; a triangle takes the mean of its vertices'. Refused when
    /// missing, not a scalar float, or not positive. Not with `thickness_texture`.
    /// - unit: – (values in m)
    /// - default: none
    pub thickness_attribute: Option<String>,
    /// A grey texture sampled at the face's TEXCOORD_0 giving the thickness
    /// (`{ path = "h.png", min = 0.0002, max = 0.001 }`, grey 0..1 → min..max m). With any
    /// varying thickness each triangle is refined for its own λ and the cluster width grows
    /// with the local thickness, so each region wrinkles at its own λ.
    /// - unit: –, m, m
    /// - default: none
    pub thickness_texture: Option<ThicknessTexture>,
    /// The eyelids: `"auto"` gives the skin the rig's blink shapes move (see
    /// [`thickness::lid_triangles`]) the thickness `lid_thickness`; `"off"` leaves it as the
    /// rest of the skin. Only where no attribute or texture gives the thickness; regions
    /// still win.
    /// - unit: –
    /// - default: `"auto"`
    pub lids: Option<Lids>,
    /// Thickness of the eyelids' skin (eyelid skin, about 0.5 mm, is the body's thinnest,
    /// about half the face's).
    /// - unit: m
    /// - default: half of `thickness`
    pub lid_thickness: Option<f64>,
    /// Most 1-to-4 subdivision levels the simulated skin may be refined by to hold
    /// `vertices_per_wavelength`; a skin that needs more is refused with the numbers (at most
    /// 4).
    /// - unit: levels
    /// - default: 3
    pub refine_limit: Option<usize>,
    /// Skin vertices wanted per critical wavelength λ: the simulated triangles are refined
    /// ⌈log₂(N ā / λ)⌉ times (ā their mean edge) by the modified butterfly rule, with a
    /// graded band to the coarse skin left out. In [2, 64].
    /// - unit: –
    /// - default: 6
    pub vertices_per_wavelength: Option<f64>,
    /// Names of the meshes that are skin; furrow checks that the face it simulates is among
    /// them.
    /// - unit: –
    /// - default: the face furrow picks
    pub meshes: Vec<String>,
    /// The part of the skin to simulate: boxes `{ min = [x,y,z], max = [x,y,z] }` in world
    /// space; outside them the skin keeps the blend shapes.
    /// - unit: m
    /// - default: everything
    pub mask: Vec<Aabb>,
    /// Which skin the shell simulates: `"compressed"` (the triangles some frame of the clip,
    /// or for a still rig some shape at weight 1, compresses past `compression_threshold`,
    /// plus a margin of one λ; the rest follows the blend shapes exactly and stays as coarse
    /// as the input) or `"all"`.
    /// - unit: –
    /// - default: `"compressed"`
    pub simulate: Option<SkinSelection>,
    /// Compression 1 − s_min (s_min the smaller principal stretch against rest) beyond which
    /// a triangle can wrinkle, in [0, 0.5).
    /// - unit: – (strain)
    /// - default: half the bilayer's onset strain ε_c = ¼ (3 Ē_q / Ē_x)^(2/3), Ē = E / (1 − ν²)
    ///   (about 1.2 % for skin on flesh)
    pub compression_threshold: Option<f64>,
    /// The membrane law: `"biot"` (corotated linear in the principal stretches, stable in
    /// compression) or `"stvk"` (Saint Venant–Kirchhoff, which softens past 42 %
    /// compression; the reference). Both have the same small-strain behaviour.
    /// - unit: –
    /// - default: `"biot"`
    pub membrane: Option<MembraneLaw>,
}

/// An axis-aligned box in world space (m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    /// Lower corner.
    /// - unit: m
    /// - default: required
    pub min: [f64; 3],
    /// Upper corner.
    /// - unit: m
    /// - default: required
    pub max: [f64; 3],
}

impl Aabb {
    /// Whether `p` lies in the box (boundary included).
    pub fn contains(&self, p: &nalgebra::Vector3<f64>) -> bool {
        (0..3).all(|k| p[k] >= self.min[k] && p[k] <= self.max[k])
    }
}

/// `[interior]`: the lattice solid.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InteriorSection {
    /// Material preset: `flesh`, `foam` or `gel` (see the presets table).
    /// - unit: –
    /// - default: `"flesh"`
    pub preset: Option<String>,
    /// Young's modulus E_q of the interior; overrides the preset's.
    /// - unit: Pa
    /// - default: the preset's
    pub young: Option<f64>,
    /// Poisson's ratio ν_q of the interior; overrides the preset's.
    /// - unit: –
    /// - default: the preset's
    pub poisson: Option<f64>,
    /// Density of the interior (mass, gravity); overrides the preset's.
    /// - unit: kg/m³
    /// - default: the preset's
    pub density: Option<f64>,
    /// Lattice cell edge. Not with `target_cells`.
    /// - unit: m
    /// - default: rigs: from `target_cells`, or under generated muscles (when neither key is
    ///   given) the coarsest lattice whose own projection holds the clip within 4 % of its
    ///   motion; synthetic scenes: half the box's z size
    pub cell_size: Option<f64>,
    /// Approximate cell count over the bounding box when no cell size is given.
    /// - unit: cells
    /// - default: 500
    pub target_cells: Option<usize>,
    /// Flesh depth behind an open surface; deeper lattice nodes are bone (pinned).
    /// - unit: m
    /// - default: 10 % of the bounding-box diagonal
    pub depth: Option<f64>,
    /// Element kind: `"quadratic"` (27-node B-spline hexahedra) or `"trilinear"` (8-node,
    /// for comparison).
    /// - unit: –
    /// - default: `"quadratic"`
    pub elements: Option<ElementKind>,
    /// Tracking stiffness factor κ (≥ 0): each skin vertex is pulled towards its blend-shape
    /// position with stiffness κ E_q A_v / ℓ (A_v its area, ℓ the cell edge); 0 leaves the
    /// flesh to its elasticity, bone and muscles.
    /// - unit: –
    /// - default: 1 when muscles drive the interior, 10 when tracking does
    pub tracking: Option<f64>,
}

/// `[dynamics]`: time stepping of the interior.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicsSection {
    /// Run backward Euler; without it each frame is solved quasi-statically.
    /// - unit: –
    /// - default: rigs: `true` when the rig is animated, `false` for a still rig; synthetic
    ///   scenes: `false`
    pub enabled: Option<bool>,
    /// Largest time step: each frame is split into equal sub-steps no longer than this.
    /// - unit: s
    /// - default: 0.02
    pub dt: Option<f64>,
    /// Gravity on the interior (faces were sculpted under gravity, so off by default).
    /// - unit: –
    /// - default: `false`
    pub gravity: Option<bool>,
    /// Feel the face node's animated translation and rotation (and its ancestors'), a head
    /// that turns and nods, as the inertial forces of the head's frame (needs dynamics).
    /// - unit: –
    /// - default: `true`
    pub head_motion: Option<bool>,
}

/// `[muscles]`: where activations come from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MuscleSection {
    /// `"auto"` (actuation muscles generated from the blend shapes, their activations fitted
    /// to every frame by a QP, with a weak tracking for what they cannot make), `"none"` (the
    /// interior tracks the blended surface, no QP), or the path of a muscle TOML file. Default
    /// muscles that cannot be made for a rig, or that miss its shapes by more than 20 % RMS on
    /// average, leave the interior to tracking with a warning; asked for explicitly, the first
    /// is an error and the second drives anyway.
    /// - unit: –
    /// - default: `"auto"` when a blend shape of the rig moves it, else `"none"`
    pub source: Option<MuscleSource>,
    /// How the muscles hold the skin's pull on the lattice:
    /// `"reached"`: at the state the interior reaches, every step, so the skin rides on the
    /// flesh the muscles shape and does not load it; `"shapes"`: each generated muscle's
    /// actuation is fitted holding the skin's force at its blend shape (`skin_at_shapes` says
    /// how it is found), which makes `solver.coupling_iterations` default to 2; `"none"`: the
    /// skin pulls on the muscle-driven interior and nothing holds it.
    /// - unit: –
    /// - default: `"reached"`
    pub skin_hold: Option<SkinHold>,
    /// The older name of `skin_hold = "shapes"` (true) and `"none"` (false): an error that
    /// says so.
    /// - unit: –
    /// - default: none (refused)
    pub skin_in_fit: Option<bool>,
    /// Gauss–Newton re-linearisations of each frame's activation fit (at most 50): each
    /// solves the muscle-driven interior's nonlinear equilibrium at the fitted activations,
    /// takes the muscles' responses there and fits again; 0 fits on the responses at rest.
    /// - unit: –
    /// - default: 0
    pub gauss_newton: Option<usize>,
    /// How the skin's force at each blend shape is found for `skin_hold = "shapes"`:
    /// `"tension_field"` (the membrane relaxed over wrinkles at the shape's smooth surface,
    /// each wrinkled direction carrying the wrinkles' critical force D (2π/λ)²; milliseconds
    /// per shape) or `"solved"` (the reference: the skin solved quasi-statically from rest
    /// with its clusters on the shape's lattice fit; seconds per shape).
    /// - unit: –
    /// - default: `"tension_field"`
    pub skin_at_shapes: Option<SkinAtShapes>,
}

/// `[solver]`: tolerances.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSection {
    /// Skin Newton tolerance: the RMS residual force per simulated skin vertex, relative to
    /// the skin's stretch stiffness E_x h / (1 − ν_x²) × mean edge.
    /// - unit: –
    /// - default: 1e-6 on rigs, 1e-8 in synthetic scenes
    pub shell_tolerance: Option<f64>,
    /// Skin Newton iteration limit per frame.
    /// - unit: iterations
    /// - default: 60 on rigs, 100 in synthetic scenes
    pub shell_iterations: Option<usize>,
    /// Interior Newton iterations per step; a step that does not converge within them is
    /// retried as two half steps (down to 1/16 of the sub-step).
    /// - unit: iterations
    /// - default: 4 on rigs, 20 in synthetic scenes
    pub interior_iterations: Option<usize>,
    /// The interior's Newton matrix: `"consistent"` (with the rotation's derivative,
    /// quadratic convergence) or `"frozen"` (the warped stiffness R K₀ Rᵀ, linear
    /// convergence; the reference).
    /// - unit: –
    /// - default: `"consistent"`
    pub interior_tangent: Option<InteriorTangent>,
    /// Load stepping of the skin: a frame whose skin solve does not converge, or ends with
    /// the skin through itself, is redone with its constraint targets moved in 2, then 4, …
    /// up to 2^levels equal steps (at most 6); 0 turns it off.
    /// - unit: levels
    /// - default: 2
    pub skin_continuation: Option<usize>,
    /// When the interior's view of the skin's stiffness Bᵀ K_x B is rebuilt: `"once"` (at
    /// rest; the force Bᵀ F_x is always current) or `"every_frame"` (the paper).
    /// - unit: –
    /// - default: `"once"`
    pub skin_stiffness: Option<SkinStiffness>,
    /// Most interior–skin passes per frame (1 to 10): the staggered coupling (interior with
    /// the skin's force linearised, then the skin on the interior) is repeated from the
    /// frame's start, linearised about the last skin and relaxed by Aitken's Δ² factor, until
    /// the interior moves by less than a thousandth of the frame's motion. 1 is the paper's
    /// one pass per frame, whose coupling settles over the next frames.
    /// - unit: passes
    /// - default: 2 when generated muscles hold the skin at their shapes
    ///   (`muscles.skin_hold = "shapes"`), else 1
    pub coupling_iterations: Option<usize>,
    /// How the skin's Newton directions are solved: `"lagged"` (GMRES preconditioned with a
    /// single-precision factor of the whole skin, kept across iterations and frames while it
    /// converges within 10 solves), `"patches"` (the same, corrected by fresh factors of only
    /// the patches whose Hessian changed) or `"global"` (the reference: a double-precision
    /// factor, made afresh whenever the last one does not converge within 5 solves). All
    /// solve each direction to the same forcing term and stop at the same residual test.
    /// - unit: –
    /// - default: `"lagged"`
    pub skin_solver: Option<SkinSolver>,
}

/// `[export]`: what goes into the output files.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportSection {
    /// `"wrinkles_on_blend"` (the blend-shape surface plus the skin's wrinkles x − B q, so
    /// the artist's shape is kept exactly) or `"simulated"` (the simulated skin itself, with
    /// the interior's low-frequency motion).
    /// - unit: –
    /// - default: `"wrinkles_on_blend"`
    pub surface: Option<ExportSurface>,
}

/// `[geometry]` of a synthetic scene (`furrow scene` only).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// `"slab"`, `"cushion"` or `"cube"`.
    /// - unit: –
    /// - default: required
    pub kind: GeometryKind,
    /// Size along x, y, z (z up in the scene; the written glTF is y up).
    /// - unit: m
    /// - default: required
    pub size: [f64; 3],
    /// Skin edge length on the top face (at most half the smallest size).
    /// - unit: m
    /// - default: required
    pub skin_edge: f64,
    /// How many copies side by side, 1 to 16 (each may take its own skin, see `skins`).
    /// - unit: –
    /// - default: the number of `skins`, at least 1
    #[serde(default)]
    pub copies: Option<usize>,
    /// Skin of each copy (`[[geometry.skins]]`, the keys of `[skin]`).
    /// - unit: –
    /// - default: the `[skin]` section for every copy
    #[serde(default)]
    pub skins: Vec<SkinSection>,
}

/// `[load]` of a synthetic scene (`furrow scene` only): `compression`, `weight` or both.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Load {
    /// In-plane compression strain along x reached at the last frame (0.1 = 10 %), in
    /// [0, 0.6).
    /// - unit: – (strain)
    /// - default: none
    #[serde(default)]
    pub compression: Option<f64>,
    /// A weight pressing on the middle third of the top face.
    /// - unit: kg
    /// - default: none
    #[serde(default)]
    pub weight: Option<f64>,
    /// Frames to reach the full load (1 to 10,000).
    /// - unit: frames
    /// - default: required
    pub frames: usize,
}

/// Concrete settings after presets, defaults and overrides.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Materials {
    /// The skin.
    pub skin: ShellMaterial,
    /// The interior.
    pub interior: Material,
}

fn positive(key: &str, v: Option<f64>) -> anyhow::Result<()> {
    if let Some(x) = v {
        if !(x.is_finite() && x > 0.0) {
            bail!("`{key}` must be a positive finite number, got {x}");
        }
    }
    Ok(())
}

impl SkinSection {
    /// The skin material with overrides applied.
    pub fn material(&self) -> anyhow::Result<ShellMaterial> {
        let name = self.preset.as_deref().unwrap_or("skin");
        let p = materials::skin_preset(name).with_context(|| {
            format!(
                "`skin.preset` = \"{name}\" is not a skin preset (known: {})",
                materials::names(&materials::SKIN_PRESETS, |p| p.name)
            )
        })?;
        let mut m = p.material;
        if let Some(e) = self.young {
            m.young = e;
        }
        if let Some(nu) = self.poisson {
            m.poisson = nu;
        }
        if let Some(h) = self.thickness {
            m.thickness = h;
        }
        m.validate().map_err(|e| anyhow::anyhow!("`skin`: {e}"))?;
        Ok(m)
    }
}

impl InteriorSection {
    /// The lattice these settings ask for: cell size or count, element order and flesh depth.
    pub fn lattice_settings(&self) -> crate::lattice::LatticeSettings {
        crate::lattice::LatticeSettings {
            cell_size: self.cell_size,
            target_cells: self.target_cells,
            order: match self.elements.unwrap_or_default() {
                ElementKind::Trilinear => crate::lattice::ElementOrder::Trilinear,
                ElementKind::Quadratic => crate::lattice::ElementOrder::Quadratic,
            },
            depth: self.depth,
        }
    }

    /// The interior material with overrides applied.
    pub fn material(&self) -> anyhow::Result<Material> {
        let name = self.preset.as_deref().unwrap_or("flesh");
        let p = materials::interior_preset(name).with_context(|| {
            format!(
                "`interior.preset` = \"{name}\" is not an interior preset (known: {})",
                materials::names(&materials::INTERIOR_PRESETS, |p| p.name)
            )
        })?;
        let mut m = p.material;
        if let Some(e) = self.young {
            m.young = e;
        }
        if let Some(nu) = self.poisson {
            m.poisson = nu;
        }
        if let Some(d) = self.density {
            m.density = d;
        }
        m.validate()
            .map_err(|e| anyhow::anyhow!("`interior`: {e}"))?;
        Ok(m)
    }
}

impl Scene {
    /// Parse a scene from TOML text (`origin` names the file in messages).
    pub fn parse(text: &str, origin: &str) -> anyhow::Result<Scene> {
        let scene: Scene =
            toml::from_str(text).with_context(|| format!("{origin}: not a valid scene file"))?;
        scene
            .validate()
            .with_context(|| format!("{origin}: invalid scene"))?;
        Ok(scene)
    }

    /// Read and check a scene file.
    pub fn load(path: &Path) -> anyhow::Result<Scene> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("{}: cannot read the scene file", path.display()))?;
        let mut scene = Self::parse(&text, &path.display().to_string())?;
        // A relative texture path is taken from the scene file's folder.
        if let (Some(t), Some(dir)) = (scene.skin.thickness_texture.as_mut(), path.parent()) {
            if Path::new(&t.path).is_relative() {
                t.path = dir.join(&t.path).display().to_string();
            }
        }
        Ok(scene)
    }

    /// The materials after presets and overrides.
    pub fn materials(&self) -> anyhow::Result<Materials> {
        Ok(Materials {
            skin: self.skin.material()?,
            interior: self.interior.material()?,
        })
    }

    /// Check every value; the message names the key.
    pub fn validate(&self) -> anyhow::Result<()> {
        self.materials()?;
        self.validate_skin()?;
        self.validate_interior()?;
        self.validate_run_settings()?;
        self.validate_geometry()
    }

    /// Check `[skin]`: masks, regions, the thickness source, refinement and resolution.
    fn validate_skin(&self) -> anyhow::Result<()> {
        let s = &self.skin;
        for (i, b) in s.mask.iter().enumerate() {
            check_box(&format!("skin.mask[{i}]"), b.min, b.max)?;
        }
        for (i, r) in s.regions.iter().enumerate() {
            r.validate(&format!("skin.regions[{i}]"))?;
        }
        if s.thickness_attribute.is_some() && s.thickness_texture.is_some() {
            bail!("give `skin.thickness_attribute` or `skin.thickness_texture`, not both");
        }
        if let Some(a) = &s.thickness_attribute {
            if a.is_empty() {
                bail!("`skin.thickness_attribute` is empty: name a per-vertex float attribute such as \"_THICKNESS\"");
            }
        }
        if let Some(t) = &s.thickness_texture {
            t.validate()?;
        }
        if let Some(h) = s.lid_thickness {
            if !(h.is_finite() && h > 0.0) {
                bail!("`skin.lid_thickness` must be a positive number of metres, got {h}");
            }
        }
        if let Some(n) = s.refine_limit {
            if n > 4 {
                bail!("`skin.refine_limit` = {n}: at most 4 levels (each multiplies the triangles by 4)");
            }
        }
        if let Some(v) = s.vertices_per_wavelength {
            if !(v.is_finite() && (2.0..=64.0).contains(&v)) {
                bail!("`skin.vertices_per_wavelength` must lie in [2, 64], got {v}");
            }
        }
        if let Some(t) = s.compression_threshold {
            if !(t.is_finite() && (0.0..0.5).contains(&t)) {
                bail!("`skin.compression_threshold` must lie in [0, 0.5) (a strain: 0.01 = 1 %), got {t}");
            }
        }
        Ok(())
    }

    /// Check `[interior]`: cell size or count, depth and element kind.
    fn validate_interior(&self) -> anyhow::Result<()> {
        let i = &self.interior;
        positive("interior.cell_size", i.cell_size)?;
        positive("interior.depth", i.depth)?;
        if i.cell_size.is_some() && i.target_cells.is_some() {
            bail!("give `interior.cell_size` or `interior.target_cells`, not both");
        }
        if let Some(n) = i.target_cells {
            if n == 0 || n > crate::lattice::MAX_CELLS {
                bail!(
                    "`interior.target_cells` must lie in [1, {}], got {n}",
                    crate::lattice::MAX_CELLS
                );
            }
        }
        Ok(())
    }

    /// Check `[dynamics]`, `[solver]`, `[export]` and `[muscles]`.
    fn validate_run_settings(&self) -> anyhow::Result<()> {
        positive("dynamics.dt", self.dynamics.dt)?;
        if let Some(dt) = self.dynamics.dt {
            if dt > 1.0 {
                bail!(
                    "`dynamics.dt` = {dt} s is longer than a second; a frame step is 0.005–0.1 s"
                );
            }
        }
        positive("solver.shell_tolerance", self.solver.shell_tolerance)?;
        if let Some(n) = self.solver.coupling_iterations {
            if !(1..=10).contains(&n) {
                bail!("`solver.coupling_iterations` must be 1 to 10, got {n}");
            }
        }
        if let Some(k) = self.interior.tracking {
            if !(k.is_finite() && (0.0..=1e6).contains(&k)) {
                bail!("`interior.tracking` must be a factor in [0, 1e6], got {k}");
            }
        }
        if let Some(old) = self.muscles.skin_in_fit {
            let now = if old { "shapes" } else { "none" };
            bail!(
                "`muscles.skin_in_fit` is replaced by `muscles.skin_hold`: write `skin_hold = \"{now}\"` (the default, \"reached\", holds the skin at the state the interior reaches)"
            );
        }
        if let Some(n) = self.muscles.gauss_newton {
            if n > 50 {
                bail!("`muscles.gauss_newton` must be at most 50 re-linearisations per frame, got {n}");
            }
        }
        if let Some(l) = self.solver.skin_continuation {
            if l > 6 {
                bail!("`solver.skin_continuation` is at most 6 (64 load steps), got {l}");
            }
        }
        if self.solver.shell_iterations == Some(0) || self.solver.interior_iterations == Some(0) {
            bail!("`solver.*_iterations` must be at least 1");
        }
        Ok(())
    }

    /// Check `[geometry]` (a synthetic scene) and the `[load]` it needs; a rig scene has
    /// neither.
    fn validate_geometry(&self) -> anyhow::Result<()> {
        if let Some(g) = &self.geometry {
            if thickness::varies(&self.skin) || g.skins.iter().any(thickness::varies) {
                bail!("`skin.regions`, `skin.thickness_attribute` and `skin.thickness_texture` apply to rigs; a synthetic scene gives each copy its own `[[geometry.skins]]` thickness");
            }
            for (k, v) in g.size.iter().enumerate() {
                positive(&format!("geometry.size[{k}]"), Some(*v))?;
            }
            positive("geometry.skin_edge", Some(g.skin_edge))?;
            let min = g.size.iter().copied().fold(f64::INFINITY, f64::min);
            if g.skin_edge > min / 2.0 {
                bail!(
                    "`geometry.skin_edge` = {} m is more than half the smallest size {min} m",
                    g.skin_edge
                );
            }
            for (i, s) in g.skins.iter().enumerate() {
                s.material()
                    .with_context(|| format!("`geometry.skins[{i}]`"))?;
            }
            if let Some(c) = g.copies {
                if c == 0 || c > 16 {
                    bail!("`geometry.copies` must lie in [1, 16], got {c}");
                }
            }
            self.validate_load()?;
        } else if self.load.is_some() {
            bail!("`[load]` needs a `[geometry]` section (rigs are driven by their animation)");
        }
        Ok(())
    }

    /// Check the `[load]` of a synthetic scene: it must be there, with frames, compression
    /// and weight in range.
    fn validate_load(&self) -> anyhow::Result<()> {
        match &self.load {
            None => bail!("a scene with `[geometry]` needs a `[load]` section"),
            Some(l) => {
                if l.frames == 0 || l.frames > 10_000 {
                    bail!("`load.frames` must lie in [1, 10000], got {}", l.frames);
                }
                if let Some(c) = l.compression {
                    if !(c.is_finite() && (0.0..0.6).contains(&c)) {
                        bail!("`load.compression` is a strain in [0, 0.6), got {c}");
                    }
                }
                positive("load.weight", l.weight)?;
            }
        }
        Ok(())
    }
}

fn check_box(key: &str, min: [f64; 3], max: [f64; 3]) -> anyhow::Result<()> {
    if min.iter().chain(&max).any(|v| !v.is_finite()) || (0..3).any(|k| min[k] > max[k]) {
        bail!("`{key}`: min must be ≤ max on every axis and finite (m)");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_scene_is_the_defaults() {
        let s = Scene::parse("", "t").unwrap();
        let m = s.materials().unwrap();
        assert_eq!(m.skin, materials::skin_preset("skin").unwrap().material);
        assert_eq!(
            m.interior,
            materials::interior_preset("flesh").unwrap().material
        );
    }

    #[test]
    fn overrides_apply_and_bad_keys_are_named() {
        let s = Scene::parse(
            "[skin]\npreset = \"leather\"\nthickness = 0.003\n[interior]\npreset = \"foam\"\n",
            "t",
        )
        .unwrap();
        let m = s.materials().unwrap();
        assert_eq!(m.skin.thickness, 0.003);
        assert_eq!(m.skin.young, 40e6);
        assert_eq!(m.interior.young, 0.5e6);
        let err = |t: &str| format!("{:#}", Scene::parse(t, "bad.toml").unwrap_err());
        let e = err("[skin]\nthicknes = 0.1\n");
        assert!(e.contains("bad.toml") && e.contains("thicknes"), "{e}");
        let e = err("[skin]\npreset = \"velvet\"\n");
        assert!(e.contains("velvet") && e.contains("leather"), "{e}");
        let e = err("[skin]\nthickness = -1.0\n");
        assert!(e.contains("thickness"), "{e}");
        let e = err("[interior]\npoisson = 0.5\n");
        assert!(e.contains("poisson"), "{e}");
        let e = err("[dynamics]\ndt = nan\n");
        assert!(e.contains("dynamics.dt"), "{e}");
        let e = err("[interior]\ncell_size = 0.01\ntarget_cells = 10\n");
        assert!(e.contains("not both"), "{e}");
        let e = err("[load]\nframes = 3\n");
        assert!(e.contains("geometry"), "{e}");
        let e = err("[muscles]\nskin_at_shapes = \"exact\"\n");
        assert!(
            e.contains("skin_at_shapes") && e.contains("exact") && e.contains("tension_field"),
            "{e}"
        );
        let e = err("[muscles]\nskin_in_fit = false\n");
        assert!(e.contains("skin_hold = \"none\""), "{e}");
        let e = err("[muscles]\ngauss_newton = 51\n");
        assert!(
            e.contains("muscles.gauss_newton") && e.contains("51"),
            "{e}"
        );
        let e = err("[muscles]\nskin_hold = \"always\"\n");
        assert!(
            e.contains("skin_hold") && e.contains("always") && e.contains("reached"),
            "{e}"
        );
        let ok = Scene::parse("[muscles]\nskin_at_shapes = \"solved\"\n", "t").unwrap();
        assert_eq!(ok.muscles.skin_at_shapes, Some(SkinAtShapes::Solved));
    }
}
