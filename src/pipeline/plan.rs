//! The plan of a run: every check on the rig and the options before any work starts, and what
//! follows from them (the frames to simulate, the materials, the skin's thickness and critical
//! wavelength, whether the interior is dynamic and in how many sub-steps per frame). Nothing
//! here builds a mesh or a solver: a plan that exists is a run that may start.

use super::frames::FrameRange;
use super::record::{Stage, StagePlan};
use super::RunOptions;
use crate::coupling::wavelength::Bilayer;
use crate::io::load::Rig;
pub use crate::scene::SkinHold;
use crate::scene::{Materials, MuscleSource, Scene};
use anyhow::bail;

/// How the interior is driven towards each frame's blend-shape target.
#[derive(Debug, Clone, PartialEq)]
pub enum Driver {
    /// A stiff quadratic tracking energy pulls the embedded surface to the target.
    Tracking,
    /// Muscle activations fitted per frame (a QP) drive it; `source` is `auto` (generated from
    /// the blend shapes) or a muscle file's path.
    Muscles {
        /// `Auto` or a muscle TOML file (never `None`).
        source: MuscleSource,
    },
}

impl Driver {
    /// The driver a scene asks for on `rig`: `muscles.source` when given (`none` is
    /// tracking); by default muscles generated from the blend shapes (`auto`) when the rig's
    /// face has a blend shape that moves it, tracking otherwise (nothing to make muscles of).
    pub fn of(scene: &Scene, rig: &Rig) -> Self {
        match &scene.muscles.source {
            Some(MuscleSource::None) => Self::Tracking,
            Some(s) => Self::Muscles { source: s.clone() },
            None if has_moving_shape(rig) => Self::Muscles {
                source: MuscleSource::Auto,
            },
            None => Self::Tracking,
        }
    }

    /// How muscles hold the skin under this driver (`muscles.skin_hold`; `None` when
    /// tracking drives). Holding it at each shape needs generated muscles: a muscle file's
    /// muscles are not fitted to shapes, so they hold it at the state reached instead.
    pub fn skin_hold(&self, scene: &Scene) -> Option<SkinHold> {
        let Self::Muscles { .. } = self else {
            return None;
        };
        Some(match scene.muscles.skin_hold.unwrap_or_default() {
            SkinHold::None => SkinHold::None,
            SkinHold::Shapes if self.generates_muscles() => SkinHold::Shapes,
            _ => SkinHold::Reached,
        })
    }

    /// Whether generated muscles are fitted with the skin in the loop, each actuation holding
    /// the skin's force at its shape (`muscles.skin_hold = "shapes"`).
    pub fn skin_in_fit(&self, scene: &Scene) -> bool {
        self.skin_hold(scene) == Some(SkinHold::Shapes)
    }

    /// Whether muscles are generated from the blend shapes (`auto`).
    pub fn generates_muscles(&self) -> bool {
        matches!(
            self,
            Self::Muscles {
                source: MuscleSource::Auto
            }
        )
    }

    /// The driver's name in the report.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Tracking => "tracking of the blended surface",
            Self::Muscles { .. } => "muscle activations",
        }
    }
}

/// Whether the rig's face has a blend shape that moves a vertex.
fn has_moving_shape(rig: &Rig) -> bool {
    rig.face()
        .targets
        .iter()
        .any(|t| t.positions.iter().any(|d| d.norm() > 0.0))
}

/// Skin thickness over the face and the critical wavelengths it gives.
#[derive(Debug, Clone)]
pub struct SkinScale {
    /// Skin thickness per loaded face triangle (m), when the scene varies it.
    pub face_thickness: Option<Vec<f64>>,
    /// Thinnest and thickest skin (m).
    pub thickness: [f64; 2],
    /// Critical wavelength of the thinnest skin (m): the refinement and the clusters use it.
    pub lambda: f64,
    /// Critical wavelength of the thickest skin (m).
    pub lambda_max: f64,
    /// The lids given their own thickness ([`crate::scene::thickness::rig_lids`]): how
    /// many face triangles, and how thick (m).
    pub lids: Option<(usize, f64)>,
}

impl SkinScale {
    /// Critical wavelength (m) of skin `h` thick (m): λ grows in proportion to the thickness
    /// ([`Bilayer::critical_wavelength`], the materials fixed).
    pub fn wavelength_of(&self, h: f64) -> f64 {
        self.lambda * h / self.thickness[0]
    }
}

/// A checked run: what to simulate and with what.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Blend-shape weights per frame of the clip, sampled at the run's fps; for a still rig,
    /// each shape alone at weight 1 (see [`clip_weights`]).
    pub weights: Vec<Vec<f64>>,
    /// Frames to write; frames [`Plan::first_simulated`]..`range.end` are simulated (the
    /// clip's history).
    pub range: FrameRange,
    /// Frames simulated before `range.start` from rest (`None`: all of them, from frame 0).
    pub preroll: Option<usize>,
    /// Frames per second (Hz).
    pub fps: f64,
    /// Whether the rig has an animation of more than one frame.
    pub animated: bool,
    /// Materials (SI).
    pub materials: Materials,
    /// The skin's thickness and wavelengths.
    pub skin: SkinScale,
    /// Interior sub-steps per frame under backward Euler; 0 when the interior is quasi-static.
    pub substeps: usize,
    /// What drives the interior.
    pub driver: Driver,
    /// The face node's motion the interior feels as inertial forces (dynamics only).
    pub head_motion: Option<HeadMotion>,
}

/// The head's motion: the face node's animated rigid motion, felt by the interior as the
/// inertial forces of its frame ([`crate::fem::frame`]).
#[derive(Debug, Clone)]
pub struct HeadMotion {
    /// The node's motion (file units).
    pub motion: crate::io::motion::NodeMotion,
    /// Metres per file unit of the rig.
    pub metres_per_unit: f64,
}

impl HeadMotion {
    /// The frame's acceleration over the time step of `h` (s) that ends at `t` (s).
    pub fn acceleration(&self, t: f64, h: f64) -> crate::fem::FrameAcceleration {
        let g = |t: f64| self.motion.at_scaled(t, self.metres_per_unit);
        crate::fem::FrameAcceleration::of_motion(g, t, h)
    }

    /// The largest rotation from the displayed pose (rad) and the largest frame acceleration
    /// at any of `points` (flat, m; m/s²), over `frames` frames sampled at `fps` (Hz).
    pub fn extent(&self, frames: usize, fps: f64, points: &[f64]) -> (f64, f64) {
        let h = 1.0 / fps;
        (0..frames).fold((0.0f64, 0.0f64), |(ang, acc), k| {
            let t = k as f64 * h;
            let g = self.motion.at_scaled(t, self.metres_per_unit);
            let a = self.acceleration(t, h);
            let peak = points
                .chunks_exact(3)
                .map(|p| a.at(&nalgebra::Vector3::new(p[0], p[1], p[2])).norm())
                .fold(0.0, f64::max);
            (
                ang.max(crate::io::motion::rotation_angle(&g)),
                acc.max(peak),
            )
        })
    }
}

impl Plan {
    /// Check the rig and the options (scene settings, fps, frame range, skin mesh names,
    /// materials, thickness) and derive the plan; an `Err` names the file and what is wrong.
    pub fn new(rig: &Rig, opts: &RunOptions) -> anyhow::Result<Self> {
        let scene = &opts.scene;
        scene.validate()?;
        if !(opts.fps.is_finite() && opts.fps > 0.0 && opts.fps <= 1000.0) {
            bail!("fps must lie in (0, 1000], got {}", opts.fps);
        }
        if scene.geometry.is_some() {
            bail!(
                "this scene describes synthetic geometry; run it with `furrow scene`, not on a rig"
            );
        }
        let (weights, animated) = clip_weights(rig, opts.fps);
        let range = opts.frames.unwrap_or(FrameRange::all(weights.len()));
        if range.end > weights.len() || range.is_empty() {
            bail!(
                "{}: frames {}:{} are outside the clip's {} frames",
                rig.path.display(),
                range.start,
                range.end,
                weights.len()
            );
        }
        let materials = scene.materials()?;
        let skin = skin_scale(rig, scene, &materials)?;
        check_skin_meshes(rig, scene)?;
        let dynamics = scene.dynamics.enabled.unwrap_or(animated);
        let substeps = if dynamics {
            substeps_per_frame(opts.fps, scene.dynamics.dt.unwrap_or(DEFAULT_DT))
        } else {
            0
        };
        Ok(Self {
            weights,
            range,
            preroll: opts.preroll,
            fps: opts.fps,
            animated,
            materials,
            skin,
            substeps,
            driver: Driver::of(scene, rig),
            head_motion: head_motion(rig, scene, substeps > 0),
        })
    }

    /// The first frame simulated: 0 for a clip's whole history, `range.start − preroll`
    /// (at least 0) with a pre-roll, and `range.start` for a still rig (each shape alone).
    pub fn first_simulated(&self) -> usize {
        match (self.animated, self.preroll) {
            (false, _) => self.range.start,
            (true, None) => 0,
            (true, Some(p)) => self.range.start.saturating_sub(p),
        }
    }

    /// Whether the interior runs backward Euler (otherwise it is quasi-static).
    pub fn dynamics(&self) -> bool {
        self.substeps > 0
    }

    /// The `load` stage's record: the face chosen and the clip.
    pub fn load_stage(&self, rig: &Rig) -> StagePlan {
        StagePlan::ran(
            Stage::Load,
            format!(
                "{}; {} frames at {} fps",
                rig.face_reason,
                self.weights.len(),
                self.fps
            ),
            0.0,
        )
    }
}

/// The poses a run simulates, and whether the rig is animated: every frame of the clip at
/// `fps` (Hz) when it has an animation of more than one frame; otherwise (a still rig, such
/// as a downloaded avatar) each blend shape alone at weight 1, one "frame" per shape, each
/// solved from rest.
pub fn clip_weights(rig: &Rig, fps: f64) -> (Vec<Vec<f64>>, bool) {
    let weights = rig.frame_weights(fps);
    if rig.track.is_some() && weights.len() > 1 {
        return (weights, true);
    }
    let n = rig.face().targets.len();
    let unit = |i: usize| (0..n).map(|j| if i == j { 1.0 } else { 0.0 }).collect();
    ((0..n).map(unit).collect(), false)
}

/// Backward Euler sub-steps per frame at `fps` (Hz) so that none is longer than `dt` (s).
pub fn substeps_per_frame(fps: f64, dt: f64) -> usize {
    (1.0 / fps / dt - 1e-9).ceil().max(1.0) as usize
}

/// Backward Euler's largest time step when the scene gives none (s).
pub const DEFAULT_DT: f64 = 0.02;

/// Skin thickness per loaded face triangle when it varies (regions, attribute, texture, the
/// lids), and the critical wavelengths of the thinnest and thickest skin (λ ∝ h).
fn skin_scale(rig: &Rig, scene: &Scene, materials: &Materials) -> anyhow::Result<SkinScale> {
    use crate::scene::thickness;
    let h0 = materials.skin.thickness;
    // The lids ([`thickness::rig_lids`]) vary it where the scene does not.
    let found = thickness::rig_lids(rig, &scene.skin, h0);
    let face_thickness = if thickness::varies(&scene.skin) || found.is_some() {
        Some(thickness::rig_face_thickness_with(
            rig,
            &scene.skin,
            h0,
            None,
            found.as_ref(),
        )?)
    } else {
        None
    };
    let lids = found.map(|(h, lid)| (lid.iter().filter(|&&l| l).count(), h));
    let (h_min, h_max) = face_thickness.as_deref().map_or((h0, h0), |h| {
        h.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            })
    });
    let wavelength_of = |h: f64| {
        Bilayer {
            thickness: h,
            skin_modulus: materials.skin.young,
            skin_poisson: materials.skin.poisson,
            interior_modulus: materials.interior.young,
            interior_poisson: materials.interior.poisson,
        }
        .critical_wavelength()
    };
    Ok(SkinScale {
        face_thickness,
        thickness: [h_min, h_max],
        lambda: wavelength_of(h_min),
        lambda_max: wavelength_of(h_max),
        lids,
    })
}

/// A scene that names its skin meshes must name the face furrow simulates.
fn check_skin_meshes(rig: &Rig, scene: &Scene) -> anyhow::Result<()> {
    let face = rig.face();
    if !scene.skin.meshes.is_empty() && !scene.skin.meshes.contains(&face.name) {
        bail!(
            "{}: the scene names skin meshes {:?} but the face furrow simulates is '{}' (pick it with --mesh)",
            rig.path.display(),
            scene.skin.meshes,
            face.name
        );
    }
    Ok(())
}

/// The face node's motion when the run feels it: dynamics on, the scene not opting out, and
/// the node (or an ancestor) animated.
fn head_motion(rig: &Rig, scene: &Scene, dynamics: bool) -> Option<HeadMotion> {
    let wanted = dynamics && scene.dynamics.head_motion.unwrap_or(true);
    rig.motion.as_ref().filter(|_| wanted).map(|m| HeadMotion {
        motion: m.clone(),
        metres_per_unit: rig.scale.metres_per_unit,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sub_steps_cover_the_frame_without_exceeding_dt() {
        assert_eq!(substeps_per_frame(30.0, 0.02), 2);
        assert_eq!(substeps_per_frame(50.0, 0.02), 1);
        assert_eq!(substeps_per_frame(24.0, 0.01), 5);
        assert_eq!(substeps_per_frame(1000.0, 0.02), 1);
    }

    #[test]
    fn the_driver_follows_the_muscle_source() {
        use crate::pipeline::setup::test_support::{bump_sheet, face_of, sheet_rig};
        let (rig, face) = sheet_rig(face_of(bump_sheet(5)));
        let mut scene = Scene::default();
        let auto = Driver::Muscles {
            source: MuscleSource::Auto,
        };
        assert_eq!(Driver::of(&scene, &rig), auto, "muscles by default");
        assert_eq!(auto.skin_hold(&scene), Some(SkinHold::Reached));
        assert!(!auto.skin_in_fit(&scene));
        scene.muscles.skin_hold = Some(SkinHold::Shapes);
        assert!(auto.skin_in_fit(&scene));
        scene.muscles.skin_hold = Some(SkinHold::None);
        assert_eq!(auto.skin_hold(&scene), Some(SkinHold::None));
        scene.muscles.skin_hold = Some(SkinHold::Shapes);
        scene.muscles.source = Some(MuscleSource::None);
        assert_eq!(Driver::of(&scene, &rig), Driver::Tracking);
        assert!(!Driver::Tracking.skin_in_fit(&scene));
        scene.muscles.source = Some(MuscleSource::File("m.toml".into()));
        let file = Driver::of(&scene, &rig);
        assert_eq!(file.name(), "muscle activations");
        assert!(!file.skin_in_fit(&scene), "only generated muscles");
        assert_eq!(file.skin_hold(&scene), Some(SkinHold::Reached));
        assert_eq!(Driver::Tracking.skin_hold(&scene), None);
        // A rig whose only shape moves nothing has nothing to make muscles of.
        let mut still = face;
        still.targets[0]
            .positions
            .iter_mut()
            .for_each(|d| *d *= 0.0);
        let (still, _) = sheet_rig(still);
        assert_eq!(Driver::of(&Scene::default(), &still), Driver::Tracking);
    }
}
