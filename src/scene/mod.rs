//! What a run needs: materials, lattice, skin, dynamics, muscles, solver and export settings,
//! read from a TOML scene file (every key optional; a missing file means the defaults).
//!
//! Two kinds of scene share this schema: rig scenes (`furrow animate RIG --scene S.toml`, the face
//! comes from the glTF) and synthetic scenes (`furrow scene S.toml`, with a `[geometry]` and a
//! `[load]` section: slabs, cushions, cubes). Unknown keys are errors (a typo must not silently
//! fall back to a default), and every value is checked with a message naming the key.

pub mod materials;
pub mod thickness;

use crate::fem::Material;
use crate::shell::ShellMaterial;
use anyhow::{bail, Context};
use serde::{Deserialize, Serialize};
use std::path::Path;
pub use thickness::{ThicknessRegion, ThicknessTexture};

/// A whole scene file (see the README for every key and its unit).
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Scene {
    /// A name for reports.
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
    /// Metres per file unit, or `"auto"` (default): a face larger or smaller than a human
    /// face by a power of ten is simulated at human size and written back in its own units.
    /// A scene whose materials are for another scale (a robot) sets `scale = 1`. Boxes and
    /// regions of the scene are in simulated metres (after this scale).
    pub scale: Option<crate::io::units::ScaleSetting>,
    /// The face mesh's skin primitives, by index in the mesh or material name (e.g.
    /// `[0, "M_BackHead"]`); the others ride along unchanged. Default: decided from the
    /// materials (alpha-blended and alpha-masked cards ride along) and the geometry (the
    /// largest surface the shapes move is skin; closed or small surfaces apart from it ride
    /// along).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skin_primitives: Option<Vec<crate::io::parts::PrimitivePick>>,
}

/// `[skin]`: the thin shell's material, thickness and resolution.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkinSection {
    /// Preset name (`skin`, `leather`, `rubber`, `latex`); default `skin`.
    pub preset: Option<String>,
    /// Young's modulus E_x (Pa), overrides the preset.
    pub young: Option<f64>,
    /// Poisson's ratio ν_x, overrides the preset.
    pub poisson: Option<f64>,
    /// Uniform thickness h (m), overrides the preset; the skin's thickness wherever no
    /// attribute, texture or region gives another.
    pub thickness: Option<f64>,
    /// Regions of another thickness (`[[skin.regions]]`, boxes or spheres in model metres,
    /// each with its `thickness` in m): a triangle whose centroid lies in one takes its
    /// thickness; later regions win. Applied on top of the attribute or texture.
    pub regions: Vec<ThicknessRegion>,
    /// Name of a per-vertex float glTF attribute of the face holding the thickness (m), e.g.
    /// `_THICKNESS`; a triangle takes the mean of its vertices'.
    pub thickness_attribute: Option<String>,
    /// A grey texture sampled at TEXCOORD_0 giving the thickness (grey 0..1 → min..max m).
    pub thickness_texture: Option<ThicknessTexture>,
    /// The eyelids: `auto` (default) gives the skin the rig's blink shapes move (see
    /// [`thickness::lid_triangles`]) the thickness `lid_thickness`; `off` leaves it as the rest
    /// of the skin. Only where no attribute or texture gives the thickness; regions still win.
    pub lids: Option<String>,
    /// Thickness of the eyelids' skin (m); default half of `thickness` (eyelid skin, about
    /// 0.5 mm, is the body's thinnest, about half the face's).
    pub lid_thickness: Option<f64>,
    /// Most subdivision levels the skin may be refined by to hold enough vertices per
    /// wavelength (default 2).
    pub refine_limit: Option<usize>,
    /// Shell vertices wanted per critical wavelength (default 6).
    pub vertices_per_wavelength: Option<f64>,
    /// Names of the meshes that are skin (default: the face furrow picks).
    pub meshes: Vec<String>,
    /// The part of the skin to simulate: boxes in world space (m); outside them the skin
    /// follows the interior (the embedding). Empty: all of it.
    pub mask: Vec<Aabb>,
    /// Which skin the shell simulates: `compressed` (default: the triangles some frame of the
    /// clip compresses past `compression_threshold`, plus a margin of one λ; the rest follows
    /// the blend shapes exactly) or `all`.
    pub simulate: Option<String>,
    /// Compression (1 − smaller principal stretch, dimensionless) beyond which a triangle can
    /// wrinkle; default half the bilayer's onset strain ε_c = ¼ (3 Ē_q / Ē_x)^(2/3).
    pub compression_threshold: Option<f64>,
    /// The membrane law: `biot` (default: corotated linear, stable in compression) or
    /// `stvk` (Saint Venant–Kirchhoff, which softens past 42 % compression; the reference).
    pub membrane: Option<String>,
}

/// An axis-aligned box in world space (m).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Aabb {
    /// Lower corner (m).
    pub min: [f64; 3],
    /// Upper corner (m).
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
    /// Preset name (`flesh`, `foam`, `gel`); default `flesh`.
    pub preset: Option<String>,
    /// Young's modulus E_q (Pa), overrides the preset.
    pub young: Option<f64>,
    /// Poisson's ratio ν_q, overrides the preset.
    pub poisson: Option<f64>,
    /// Density (kg/m³), overrides the preset.
    pub density: Option<f64>,
    /// Lattice cell edge (m); default from `target_cells`.
    pub cell_size: Option<f64>,
    /// Approximate cell count over the bounding box when no cell size is given (default 500).
    pub target_cells: Option<usize>,
    /// Flesh depth behind an open surface (m); default 10 % of the bounding-box diagonal.
    pub depth: Option<f64>,
    /// `quadratic` (default) or `trilinear` elements.
    pub elements: Option<String>,
    /// Tracking stiffness factor κ (dimensionless, ≥ 0): each skin vertex is pulled towards
    /// its blend-shape position with stiffness κ E_q A_v / ℓ. Default 10 when tracking drives
    /// the interior, 1 with muscles; 0 leaves the flesh to its elasticity, bone and muscles.
    pub tracking: Option<f64>,
}

/// `[dynamics]`: time stepping of the interior.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DynamicsSection {
    /// Run backward Euler (default: yes when the rig is animated; a still pose is solved
    /// quasi-statically).
    pub enabled: Option<bool>,
    /// Time step (s); default 0.02, or 1/fps when that is smaller.
    pub dt: Option<f64>,
    /// Apply gravity (default false for faces: the blend shapes were sculpted under gravity).
    pub gravity: Option<bool>,
    /// Feel the face node's animated motion (a head that turns and nods) as inertial forces
    /// in the head's frame (default true; needs dynamics).
    pub head_motion: Option<bool>,
}

/// `[muscles]`: where activations come from.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MuscleSection {
    /// `auto` (muscles generated from the blend shapes, activations fitted per frame by a
    /// QP; the default when the rig has a blend shape that moves it), `none` (the interior
    /// tracks the blended surface directly, no QP; the default for a rig without blend
    /// shapes), or the path of a muscle TOML file.
    pub source: Option<String>,
    /// How the muscles hold the skin (default `reached` under muscles; see
    /// [`SKIN_HOLDS`]): `reached`: the muscles hold the skin's pull on the lattice at the
    /// state the interior reaches, every step, so the skin rides on the flesh the muscles
    /// shape and does not load it; `shapes`: each generated muscle's actuation is fitted
    /// holding the skin's force at its blend shape (`skin_at_shapes` says how it is found),
    /// which makes `solver.coupling_iterations` default to 2; `none`: the skin pulls on the
    /// muscle-driven interior and nothing holds it.
    pub skin_hold: Option<String>,
    /// The older name of `skin_hold = "shapes"` (true) and `"none"` (false): an error that
    /// says so.
    pub skin_in_fit: Option<bool>,
    /// Gauss–Newton re-linearisations of each frame's activation fit (default 0: the QP on
    /// the muscles' responses at rest alone): each solves the muscle-driven interior's
    /// nonlinear equilibrium at the fitted activations, takes the responses there and fits
    /// again, so that the corotational flesh's departure from the linear model is corrected.
    pub gauss_newton: Option<usize>,
    /// How the skin's force at each blend shape is found for `skin_hold = "shapes"`:
    /// `tension_field` (default: the membrane relaxed over wrinkles at the shape's smooth
    /// surface, each wrinkled direction carrying the wrinkles' critical force D (2π/λ)²;
    /// milliseconds per shape) or `solved` (the reference: the skin solved quasi-statically
    /// from rest with its clusters on the shape's lattice fit; seconds per shape).
    pub skin_at_shapes: Option<String>,
}

/// The values of `muscles.skin_hold`, the default first.
pub const SKIN_HOLDS: [&str; 3] = ["reached", "shapes", "none"];

/// The values of `muscles.skin_at_shapes`.
pub const SKIN_AT_SHAPES: [&str; 2] = ["tension_field", "solved"];

/// The values of `solver.skin_solver`.
pub const SKIN_SOLVERS: [&str; 3] = ["lagged", "patches", "global"];

/// `[solver]`: tolerances.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SolverSection {
    /// Shell Newton tolerance: the RMS residual force per skin vertex relative to the skin's
    /// stretch stiffness × mean edge (default 1e-6 on rigs, 1e-8 in synthetic scenes).
    pub shell_tolerance: Option<f64>,
    /// Shell Newton iteration limit (default 60).
    pub shell_iterations: Option<usize>,
    /// Interior Newton iterations per step (default 4 on rigs, 20 in synthetic scenes); a
    /// step that does not converge within them is retried as two half steps.
    pub interior_iterations: Option<usize>,
    /// The interior Newton matrix: `consistent` (default: with the rotation's derivative,
    /// quadratic convergence) or `frozen` (the warped stiffness R K₀ Rᵀ, the reference).
    pub interior_tangent: Option<String>,
    /// Load stepping of the skin: a frame whose skin solve does not converge directly is
    /// redone with its constraint targets moved in 2, then 4, … up to 2^levels equal steps
    /// (default 2; 0 turns it off).
    pub skin_continuation: Option<usize>,
    /// When the skin's stiffness Bᵀ K_x B seen by the interior is recomputed: `once` (at
    /// rest; default, the force Bᵀ F_x is always current) or `every_frame` (the paper).
    pub skin_stiffness: Option<String>,
    /// Most solves of the interior and the skin per frame (default 2 with generated muscles
    /// fitted holding the skin at their shapes, `muscles.skin_hold = "shapes"`; 1 otherwise): the staggered coupling (interior with the skin's force
    /// linearised, then the skin on the interior) is repeated from the frame's start, each
    /// time linearised about the last skin, until the interior moves by less than a
    /// thousandth of the frame's motion. 1 is the paper's one pass per frame, whose coupling
    /// settles over the next frames.
    pub coupling_iterations: Option<usize>,
    /// How the skin's Newton directions are solved: `lagged` (default: GMRES preconditioned
    /// with a single-precision factor of the whole skin, kept across iterations and frames
    /// while it converges within 10 solves), `patches` (the same, corrected by fresh factors
    /// of only the patches whose Hessian changed) or `global` (the reference: a
    /// double-precision factor, made afresh whenever the last one does not converge within
    /// 5 solves). All solve each direction to the same forcing term and stop at the same
    /// residual test.
    pub skin_solver: Option<String>,
}

/// `[export]`: what goes into the output files.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExportSection {
    /// `wrinkles_on_blend` (default: the blend-shape surface plus the skin's wrinkles, so the
    /// artist's shape is kept exactly) or `simulated` (the simulated skin itself).
    pub surface: Option<String>,
}

/// `[geometry]` of a synthetic scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Geometry {
    /// `slab`, `cushion` or `cube`.
    pub kind: String,
    /// Size along x, y, z (m); y is up.
    pub size: [f64; 3],
    /// Skin edge length (m).
    pub skin_edge: f64,
    /// How many copies side by side (each may take its own skin, see `skins`).
    #[serde(default)]
    pub copies: Option<usize>,
    /// Skin presets or overrides per copy (default: the `[skin]` section for all).
    #[serde(default)]
    pub skins: Vec<SkinSection>,
}

/// `[load]` of a synthetic scene.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Load {
    /// In-plane compression strain along x reached at the last frame (0.1 = 10 %).
    #[serde(default)]
    pub compression: Option<f64>,
    /// A weight pressing on the top (kg), spread over the top face.
    #[serde(default)]
    pub weight: Option<f64>,
    /// Frames to reach the full load.
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
        if let Some(l) = s.lids.as_deref() {
            if !matches!(l, "auto" | "off") {
                bail!("`skin.lids` = {l:?}: use \"auto\" (thin skin where the blink shapes move it) or \"off\"");
            }
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
        if let Some(m) = s.simulate.as_deref() {
            if !matches!(m, "compressed" | "all") {
                bail!("`skin.simulate` = \"{m}\": use \"compressed\" (the skin some frame compresses) or \"all\"");
            }
        }
        if let Some(m) = s.membrane.as_deref() {
            if !matches!(m, "biot" | "stvk") {
                bail!("`skin.membrane` = \"{m}\": use \"biot\" (the default) or \"stvk\"");
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
        if let Some(e) = &i.elements {
            if e != "quadratic" && e != "trilinear" {
                bail!("`interior.elements` must be \"quadratic\" or \"trilinear\", got \"{e}\"");
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
        if let Some(m) = &self.solver.skin_stiffness {
            if m != "once" && m != "every_frame" {
                bail!("`solver.skin_stiffness` must be \"once\" or \"every_frame\", got \"{m}\"");
            }
        }
        if let Some(n) = self.solver.coupling_iterations {
            if !(1..=10).contains(&n) {
                bail!("`solver.coupling_iterations` must be 1 to 10, got {n}");
            }
        }
        if let Some(m) = &self.solver.skin_solver {
            if !SKIN_SOLVERS.contains(&m.as_str()) {
                bail!(
                    "`solver.skin_solver` must be \"lagged\", \"patches\" or \"global\", got \"{m}\""
                );
            }
        }
        if let Some(m) = &self.export.surface {
            if m != "wrinkles_on_blend" && m != "simulated" {
                bail!(
                    "`export.surface` must be \"wrinkles_on_blend\" or \"simulated\", got \"{m}\""
                );
            }
        }
        if let Some(k) = self.interior.tracking {
            if !(k.is_finite() && (0.0..=1e6).contains(&k)) {
                bail!("`interior.tracking` must be a factor in [0, 1e6], got {k}");
            }
        }
        if let Some(m) = &self.muscles.source {
            if m.is_empty() {
                bail!("`muscles.source` is empty: use \"auto\", \"none\" or a file path");
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
        if let Some(h) = &self.muscles.skin_hold {
            if !SKIN_HOLDS.contains(&h.as_str()) {
                bail!(
                    "`muscles.skin_hold` must be \"reached\", \"shapes\" or \"none\", got \"{h}\""
                );
            }
        }
        if let Some(m) = &self.muscles.skin_at_shapes {
            if !SKIN_AT_SHAPES.contains(&m.as_str()) {
                bail!(
                    "`muscles.skin_at_shapes` must be \"tension_field\" or \"solved\", got \"{m}\""
                );
            }
        }
        if let Some(t) = &self.solver.interior_tangent {
            if t != "consistent" && t != "frozen" {
                bail!(
                    "`solver.interior_tangent` must be \"consistent\" or \"frozen\", got \"{t}\""
                );
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
            if !["slab", "cushion", "cube"].contains(&g.kind.as_str()) {
                bail!(
                    "`geometry.kind` must be slab, cushion or cube, got \"{}\"",
                    g.kind
                );
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
            e.contains("muscles.skin_at_shapes") && e.contains("exact"),
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
            e.contains("muscles.skin_hold") && e.contains("always"),
            "{e}"
        );
        let ok = Scene::parse("[muscles]\nskin_at_shapes = \"solved\"\n", "t").unwrap();
        assert_eq!(ok.muscles.skin_at_shapes.as_deref(), Some("solved"));
    }
}
