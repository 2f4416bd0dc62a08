//! The `muscles` and `fit` stages of the set-up: the muscles of the lattice (generated from the
//! rig's blend shapes, or read from a muscle file) and the fitter that turns each frame's
//! target into their activations (a clarabel QP on the muscles' responses in the pipeline's
//! interior).

use crate::coupling::embedded::EmbeddedShell;
use crate::fem::Interior;
use crate::io::mesh::MeshInstance;
use crate::io::model::MorphTarget;
use crate::lattice::Lattice;
use crate::muscle::generate::BlendShapes;
use crate::muscle::jaw::{Hinge, JawBone};
use crate::muscle::samples::{ShapeSamples, SAMPLE_LEVELS};
use crate::muscle::{Coupling, FitSettings, Fitter, GenerateSettings, Generated, MuscleError};
use crate::pipeline::record::{Stage, StagePlan};
use crate::scene::{MuscleSource, Scene, SkinHold};
use crate::solver::SolveStatus;
use anyhow::{bail, Context};
use std::path::Path;
use std::time::Instant;

use super::interior::MUSCLE_TRACKING;
use super::weld::Welded;

/// Muscles of a run and their current activations.
pub struct MuscleDrive {
    /// The muscles and the per-frame activation fit.
    pub fitter: Fitter,
    /// Activation of each muscle at the current frame (dimensionless, in [0, 1]).
    pub activations: Vec<f64>,
    /// Activation of each muscle at the last frame (dimensionless): a frame's sub-steps move
    /// from these to `activations` ([`Self::at`]), as tracking moves its target.
    pub previous: Vec<f64>,
    /// Where the muscles came from (for the report).
    pub origin: String,
    /// How well each generated muscle makes its shape (empty for a muscle file).
    pub made: Vec<MuscleMade>,
    /// Whether the current frame's fit failed, so that tracking at full stiffness drives the
    /// interior for this frame instead of the kept activations.
    pub fallback: bool,
    /// The jaw's hinge, when generated muscles turn the jaw's bone about it (the bone and
    /// its muscle are the fitter's forward model's, [`crate::muscle::Forward::bone`]).
    pub jaw: Option<Hinge>,
}

impl MuscleDrive {
    /// Back to rest: activations zero (within bounds) and the fit's memory of the last frame
    /// forgotten, for a pose solved alone from rest.
    pub fn reset(&mut self) {
        self.fitter.reset();
        self.activations = rest_activations(self.fitter.muscles());
        self.previous = self.activations.clone();
        self.fallback = false;
    }

    /// Relax the muscles: this frame's activations back to rest, so that the frame's
    /// sub-steps move them there from the last frame's.
    pub fn relax(&mut self) {
        self.activations = rest_activations(self.fitter.muscles());
    }

    /// The activations at fraction `at` of the frame interval (dimensionless): linear from
    /// the last frame's to this frame's.
    pub fn at(&self, at: f64) -> Vec<f64> {
        let lerp = |(p, a): (&f64, &f64)| p + (a - p) * at.clamp(0.0, 1.0);
        self.previous
            .iter()
            .zip(&self.activations)
            .map(lerp)
            .collect()
    }
}

/// The mean shape error (RMS over the vertices each shape moves, as a fraction of the shape's
/// displacement) beyond which generated muscles do not drive a rig by default: they do not
/// reproduce it, and on a lattice too coarse for its shapes they cost more time and redone
/// frames than tracking while missing the shapes about as much.
pub const MUSCLE_SHAPE_LIMIT: f64 = 0.2;

/// Why muscles by default should leave a rig to tracking, if they should: generated muscles
/// whose `made` records say they make the rig's shapes worse than [`MUSCLE_SHAPE_LIMIT`] RMS
/// on average (the lattice too coarse for its shapes) do not reproduce the rig, which is what
/// muscles drive by default for. `None` without records (a muscle file: nothing to judge
/// against).
pub fn cannot_make_shapes(made: &[MuscleMade]) -> Option<String> {
    if made.is_empty() {
        return None;
    }
    let n = made.len() as f64;
    let mean = made.iter().map(|m| m.shape_error).sum::<f64>() / n;
    let projection = made.iter().map(|m| m.projection).sum::<f64>() / n;
    (mean > MUSCLE_SHAPE_LIMIT).then(|| {
        format!(
            "its generated muscles make its blend shapes only within {:.1} % RMS on average \
             (the lattice's own projection residual: {:.1} %), beyond the {:.0} % muscles drive \
             by default within; a finer lattice (`interior.cell_size`) lets muscles make them, \
             and `[muscles] source = \"auto\"` drives it with these anyway",
            100.0 * mean,
            100.0 * projection,
            100.0 * MUSCLE_SHAPE_LIMIT
        )
    })
}

/// Each muscle's activation at rest: zero, within its bounds (dimensionless).
fn rest_activations(muscles: &[crate::muscle::Muscle]) -> Vec<f64> {
    muscles
        .iter()
        .map(|m| 0.0f64.clamp(m.bounds[0], m.bounds[1]))
        .collect()
}

/// How well a generated muscle makes its blend shape at activation 1, in the interior the
/// pipeline runs (tracking included), over the vertices the shape moves by more than a tenth
/// of its largest displacement.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MuscleMade {
    /// The muscle (and blend shape) name.
    pub name: String,
    /// RMS error of the muscle's surface against the shape, over the shape's RMS
    /// displacement (dimensionless).
    pub shape_error: f64,
    /// The lattice's own projection residual of the shape, relative as `shape_error`: what no
    /// muscle on this lattice can beat.
    pub projection: f64,
    /// Lattice elements the actuation covers.
    pub elements: usize,
    /// Nonlinear corrections of the actuation.
    pub corrections: usize,
}

impl MuscleMade {
    /// The records of each of the `generated` muscles.
    pub fn of(generated: &Generated) -> Vec<MuscleMade> {
        (generated.muscles.iter().zip(&generated.fits))
            .map(|(m, f)| MuscleMade {
                name: m.name.clone(),
                shape_error: f.shape_error,
                projection: f.projection,
                elements: f.elements.len(),
                corrections: f.corrections,
            })
            .collect()
    }
}

/// What the muscles' fit sees in the interior besides the flesh.
pub struct Beside<'s> {
    /// The tracking's stiffness and pull.
    pub coupling: Coupling,
    /// The simulated skin, whose force at each shape the actuations hold: given only when
    /// the driver fits generated muscles with the skin in the loop
    /// ([`crate::pipeline::plan::Driver::skin_in_fit`]).
    pub skin: Option<&'s mut EmbeddedShell>,
    /// The wavelength the skin wrinkles at (m, its thinnest part's).
    pub wavelength: f64,
    /// How the muscles hold the skin (`muscles.skin_hold`), for the record.
    pub hold: SkinHold,
}

/// The muscles from `source` (`auto`: generated from the blend shapes of `face` (from the rig
/// at `path`) on the `welded` skin, their lattice fit held on its subdivided surface;
/// otherwise a muscle TOML file), with their fitter and the `muscles` and `fit` records.
/// Actuations and the fitter's J see the interior the pipeline runs: its elasticity with the
/// tracking's coupling and, with `muscles.skin_hold = "shapes"`, the skin's force at each shape
/// (`beside`). Muscles by default (`muscles.source` not given) that cannot make the rig's
/// shapes ([`cannot_make_shapes`]) are an error, which `set_up` falls back on.
pub fn build_muscles(
    face: &MeshInstance,
    path: &str,
    scene: &Scene,
    lattice: &Lattice,
    welded: &Welded,
    source: &MuscleSource,
    beside: Beside,
) -> anyhow::Result<(MuscleDrive, [StagePlan; 2])> {
    let Beside {
        coupling,
        skin,
        wavelength,
        hold,
    } = beside;
    let t = Instant::now();
    // Before any fit: a lattice without bone (a closed surface) cannot carry muscles.
    crate::muscle::forward::check_bone(&lattice.pinned)?;
    let material = scene.interior.material()?;
    let mut made = String::new();
    let mut calibration = None;
    let mut made_by = Vec::new();
    let (mut bone, mut jaw_hinge) = (None, None);
    let (muscles, origin) = if *source == MuscleSource::Auto {
        let targets = welded_targets(face, &welded.loaded_of);
        let samples = ShapeSamples::subdivided(lattice, &welded.mesh, SAMPLE_LEVELS)
            .with_context(|| format!("{path}: the muscles' shape samples"))?;
        let jaw = JawBone::find(lattice, &welded.mesh.positions, &targets);
        let interior = Interior::new(lattice, &material)?;
        let way = match scene.muscles.skin_at_shapes.unwrap_or_default() {
            crate::scene::SkinAtShapes::Solved => SkinWay::Solved,
            crate::scene::SkinAtShapes::TensionField => SkinWay::TensionField { wavelength },
        };
        let mut at_shapes = skin.map(|shell| SkinAtShapes::new(shell, lattice.rest_flat(), way));
        let mut force = at_shapes.as_mut().map(|a| move |u: &[f64]| a.force(u));
        let g = crate::muscle::generate::generate_muscles_with_skin(
            lattice,
            &interior,
            BlendShapes {
                targets: &targets,
                samples: &samples,
            },
            Some(&coupling),
            &GenerateSettings::default(),
            force
                .as_mut()
                .map(|f| f as crate::muscle::generate::SkinForce),
            jaw.as_ref().map(|j| &j.0),
        )?;
        (bone, jaw_hinge) = g.jaw(jaw).unzip();
        made = shape_errors(&g);
        if let Some(a) = &at_shapes {
            made.push_str(&a.summary(&g.without_skin));
        }
        made_by = MuscleMade::of(&g);
        calibration = Some(g.calibration());
        (g.muscles, "generated from the blend shapes".to_string())
    } else {
        (
            crate::muscle::rigfile::load(Path::new(source.as_str()), lattice, &welded.mesh)?,
            format!("from {source}"),
        )
    };
    if muscles.is_empty() {
        bail!(
            "{path}: no muscles ({source}): every blend shape is empty; give a muscle file or use muscles.source = \"none\""
        );
    }
    // Muscles by default only where they make the rig's shapes (`set_up` falls back), judged
    // before their fitter is built.
    if let Some(why) = cannot_make_shapes(&made_by).filter(|_| scene.muscles.source.is_none()) {
        bail!(why);
    }
    let n = muscles.len();
    let rest = rest_activations(&muscles);
    let fitter = Fitter::coupled(
        lattice,
        &material,
        muscles,
        FitSettings {
            gauss_newton: scene.muscles.gauss_newton.unwrap_or(0),
            ..FitSettings::default()
        },
        Some(coupling),
        calibration,
        bone,
    )?;
    let drive = MuscleDrive {
        fitter,
        activations: rest.clone(),
        previous: rest,
        origin,
        made: made_by,
        fallback: false,
        jaw: jaw_hinge,
    };
    let records = [
        StagePlan::ran(
            Stage::Muscles,
            format!(
                "{n} muscles {}{made}{}{}; a weak tracking (κ = {MUSCLE_TRACKING}) carries what they cannot make",
                drive.origin,
                bone_summary(&drive),
                hold_summary(hold),
            ),
            t.elapsed().as_secs_f64() * 1e3,
        ),
        StagePlan::ran(
            Stage::Fit,
            "activations per frame: clarabel QP on the muscles' responses in this interior, the tracking's own pull removed (warm-started)",
            0.0,
        ),
    ];
    Ok((drive, records))
}

/// What the muscles' record says of how they hold the skin (`muscles.skin_hold`).
fn hold_summary(hold: SkinHold) -> &'static str {
    match hold {
        SkinHold::Reached => {
            "; they hold the skin's pull at the state the interior reaches, so the skin rides on the flesh they shape and does not load it"
        }
        // The fit's own summary says how.
        SkinHold::Shapes => "",
        SkinHold::None => "; nothing holds the skin's pull on the flesh they drive",
    }
}

/// What the muscles' record says of the jaw's bone (empty without one).
fn bone_summary(drive: &MuscleDrive) -> String {
    match (&drive.fitter.forward.bone, &drive.jaw) {
        (Some((m, bone)), Some(hinge)) => format!(
            "; {} bone nodes turn with muscle {} about the jaw's hinge ({:.1}° at activation 1)",
            bone.nodes.len(),
            drive.fitter.muscles()[*m].name,
            hinge.angle_deg
        ),
        _ => String::new(),
    }
}

/// The blend shapes of `face` on the welded skin, whose vertex `i` is loaded vertex
/// `welded_loaded[i]` (offsets from rest, m).
pub(super) fn welded_targets(face: &MeshInstance, welded_loaded: &[usize]) -> Vec<MorphTarget> {
    face.targets
        .iter()
        .map(|t| MorphTarget {
            name: t.name.clone(),
            positions: welded_loaded.iter().map(|&i| t.positions[i]).collect(),
            normals: None,
        })
        .collect()
}

/// Statics' tolerance of a skin solved at a blend shape, over the frames' tolerance: the
/// force it gives is held by an actuation, and at 100× the frames' (about 0.03 N on the demo
/// face, whose shapes' skin forces are 2–30 N) the muscles' shape error and wrinkles were
/// those of the frames' tolerance to 0.1 %, in two-thirds of the time.
const SHAPE_SKIN_LOOSENING: f64 = 100.0;

/// How the skin's force at a blend shape is found (`muscles.skin_at_shapes`).
#[derive(Debug, Clone, Copy)]
enum SkinWay {
    /// The membrane relaxed over wrinkles at the shape's smooth surface B q, each wrinkled
    /// direction carrying the critical force of wrinkles of this wavelength (m).
    TensionField { wavelength: f64 },
    /// The skin solved quasi-statically from rest with its clusters on the shape's lattice
    /// fit (the reference).
    Solved,
}

/// The skin's force at each blend shape, for the actuation fit (`muscles.skin_hold = "shapes"`).
struct SkinAtShapes<'s> {
    shell: &'s mut EmbeddedShell,
    way: SkinWay,
    /// Lattice node positions at rest (flat, m).
    rest_q: Vec<f64>,
    /// The skin's state at rest (flat, m): where each shape's solve starts, restored after it.
    rest_x: Vec<f64>,
    shapes: usize,
    failed: usize,
    seconds: f64,
}

impl<'s> SkinAtShapes<'s> {
    fn new(shell: &'s mut EmbeddedShell, rest_q: Vec<f64>, way: SkinWay) -> Self {
        let rest_x = shell.x().to_vec();
        Self {
            shell,
            way,
            rest_q,
            rest_x,
            shapes: 0,
            failed: 0,
            seconds: 0.0,
        }
    }

    /// The skin's force on the nodes (flat, N) with the lattice at node displacements `u`
    /// (flat, m) from rest. A solve that does not converge gives zero (the muscle is then
    /// fitted without it, and the summary counts it).
    fn force(&mut self, u: &[f64]) -> Result<Vec<f64>, MuscleError> {
        let t = Instant::now();
        let q: Vec<f64> = self.rest_q.iter().zip(u).map(|(a, b)| a + b).collect();
        let force = match self.way {
            SkinWay::TensionField { wavelength } => self.shell.tension_field_force(&q, wavelength),
            SkinWay::Solved => self.solved_force(&q)?,
        };
        self.shapes += 1;
        self.seconds += t.elapsed().as_secs_f64();
        Ok(force)
    }

    /// The skin's force at node positions `q` (flat, m), solved from rest.
    fn solved_force(&mut self, q: &[f64]) -> Result<Vec<f64>, MuscleError> {
        let skin_error = |e: String| MuscleError::Input(format!("skin at a blend shape: {e}"));
        let report = self.shell.solve_loosened(q, SHAPE_SKIN_LOOSENING);
        let converged =
            report.map_err(|e| skin_error(e.to_string()))?.status == SolveStatus::Converged;
        let force = if converged {
            self.shell.coupling_force()
        } else {
            self.failed += 1;
            vec![0.0; q.len()]
        };
        self.shell
            .set_x(&self.rest_x)
            .map_err(|e| skin_error(e.to_string()))?;
        Ok(force)
    }

    /// What the skin in the fit did, for the `muscles` record, with the shapes whose muscle
    /// was fitted `without` the skin's force (name, why).
    fn summary(&self, without: &[(String, String)]) -> String {
        let mut failed = if self.failed > 0 {
            format!(
                "; {} skin solves did not converge, and their muscles were fitted without the skin",
                self.failed
            )
        } else {
            String::new()
        };
        for (name, why) in without {
            failed.push_str(&format!("; {name} fitted without the skin ({why})"));
        }
        let how = match self.way {
            SkinWay::TensionField { .. } => {
                "from the membrane relaxed over wrinkles (tension field)"
            }
            SkinWay::Solved => "solved",
        };
        format!(
            "; the skin in the fit: its force at each of {} shapes {how} in {:.2} s, each actuation holds it{failed}",
            self.shapes, self.seconds
        )
    }
}

/// How well the generated actuations make their shapes at activation 1 in the pipeline's
/// interior: the mean and worst relative RMS error and the worst against the lattice's own
/// projection residual (for the `muscles` record).
fn shape_errors(g: &Generated) -> String {
    if g.fits.is_empty() {
        return String::new();
    }
    let n = g.fits.len() as f64;
    let mean = g.fits.iter().map(|f| f.shape_error).sum::<f64>() / n;
    let (worst, w) = g
        .fits
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.shape_error.total_cmp(&b.1.shape_error))
        .map(|(i, f)| (i, f.shape_error))
        .expect("not empty");
    let ratio = g
        .fits
        .iter()
        .map(|f| f.shape_error / f.projection.max(1e-12))
        .fold(0.0f64, f64::max);
    format!(
        " (actuations fitted in the pipeline's interior with its tracking: each makes its shape within {:.1} % RMS on average, {:.1} % at worst ({}), at most {ratio:.2}× the lattice's own projection residual)",
        100.0 * mean,
        100.0 * w,
        g.muscles[worst].name
    )
}

/// The `muscles` and `fit` records of a run without muscles: `scene` asked for none, or
/// (by default) the rig has no blend shape to make them of.
pub fn skipped(scene: &Scene) -> [StagePlan; 2] {
    without_muscles(if scene.muscles.source.is_some() {
        "muscles.source = none: the interior tracks the blended surface directly".into()
    } else {
        "the rig has no blend shape that moves it, so no muscles to make: the interior tracks \
         the surface directly"
            .into()
    })
}

/// The `muscles` and `fit` records of a run whose default muscles could not be made
/// (`error` says why): the interior tracks the blended surface.
pub fn fell_back(error: &anyhow::Error) -> [StagePlan; 2] {
    [
        StagePlan::tracked(
            Stage::Muscles,
            format!(
                "muscles cannot drive this rig ({error:#}): the interior tracks the blended \
                 surface directly"
            ),
        ),
        StagePlan::skipped(Stage::Fit, "no muscles: no activation QP"),
    ]
}

/// The `muscles` record skipped for `why`, and the `fit` record that follows from it.
fn without_muscles(why: String) -> [StagePlan; 2] {
    [
        StagePlan::skipped(Stage::Muscles, why),
        StagePlan::skipped(Stage::Fit, "no muscles: no activation QP"),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::vector::norm;
    use crate::pipeline::plan::{Driver, Plan};
    use crate::pipeline::record::StageStatus;
    use crate::pipeline::setup::{set_up, Log};

    /// The tension-field force at a shape is the solved skin's (the reference) within 15 %
    /// on the demo face's brow raise and smile and 20 % on its pucker, and several times
    /// closer than the unrelaxed skin's force at the same smooth surface B q, which fights the
    /// compression the skin relieves by wrinkling. The relaxed membrane leaves the triangles
    /// pinned beside the lips' slit unrelaxed, as the solved skin does.
    #[test]
    fn the_tension_field_force_is_near_the_solved_skins_at_the_face_shapes() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb");
        let mut rig = crate::io::load::load(&path, &Default::default()).unwrap();
        crate::io::units::apply(&mut rig, None, None);
        let mut scene = Scene::default();
        scene.muscles.source = Some(MuscleSource::None);
        let opts = crate::pipeline::RunOptions::new(scene);
        let plan = Plan::new(&rig, &opts).unwrap();
        let (model, mut state) =
            set_up(&rig, &opts.scene, &plan, &mut Log::default(), &|_, _, _| {}).unwrap();
        let targets = welded_targets(rig.face(), &model.welded_loaded);
        let interior =
            Interior::new(&model.lattice, &opts.scene.interior.material().unwrap()).unwrap();
        let regulariser = GenerateSettings::default().regulariser;
        let fits = crate::muscle::generate::fit_node_displacements(
            &model.lattice,
            &interior,
            &targets,
            &ShapeSamples::vertices(&model.lattice),
            regulariser,
            None,
        )
        .unwrap();
        let rest = model.lattice.rest_flat();
        let shell = state.skin.as_mut().unwrap();
        for name in ["brow_raise", "smile_left", "pucker"] {
            let u = &fits[targets.iter().position(|t| t.name == name).unwrap()];
            let field = SkinAtShapes::new(
                shell,
                rest.clone(),
                SkinWay::TensionField {
                    wavelength: plan.skin.lambda,
                },
            )
            .force(u)
            .unwrap();
            let solved = SkinAtShapes::new(shell, rest.clone(), SkinWay::Solved)
                .force(u)
                .unwrap();
            let q: Vec<f64> = rest.iter().zip(u).map(|(a, b)| a + b).collect();
            let at_rest = shell.x().to_vec();
            shell.set_x(&shell.embedded_flat(&q)).unwrap();
            let unrelaxed = shell.coupling_force();
            shell.set_x(&at_rest).unwrap();
            let off = |f: &[f64]| {
                let d: Vec<f64> = f.iter().zip(&solved).map(|(a, b)| a - b).collect();
                norm(&d) / norm(&solved)
            };
            println!(
                "{name}: solved {:.2} N; tension field {:.1} % off, unrelaxed at B q {:.1} % off",
                norm(&solved),
                100.0 * off(&field),
                100.0 * off(&unrelaxed)
            );
            let bound = if name == "pucker" { 0.2 } else { 0.15 };
            assert!(off(&field) < bound, "{name}: {}", off(&field));
            assert!(3.0 * off(&field) < off(&unrelaxed), "{name}");
        }
    }

    /// Muscles by default on a rig they cannot drive (a closed surface: no bone behind the
    /// face) leave the interior to tracking, with a warning and the reason in the `muscles`
    /// record; asked for explicitly, the same rig is an error.
    #[test]
    fn default_muscles_that_cannot_be_made_fall_back_to_tracking() {
        use crate::pipeline::setup::test_support::{face_of, sheet_rig};
        let cube = crate::mesh::cube_mesh(0.04, 4);
        let (rig, _) = sheet_rig(face_of(cube));
        let mut scene = Scene::default();
        scene.interior.cell_size = Some(0.01);
        let opts = |scene: &Scene| crate::pipeline::RunOptions::new(scene.clone());
        let plan = Plan::new(&rig, &opts(&scene)).unwrap();
        assert_eq!(
            plan.driver,
            Driver::Muscles {
                source: MuscleSource::Auto
            }
        );
        let mut log = Log::default();
        let (model, state) = set_up(&rig, &scene, &plan, &mut log, &|_, _, _| {}).unwrap();
        assert_eq!(model.driver, Driver::Tracking);
        assert!(plan.driver != model.driver, "the plan is not changed");
        assert!(state.muscles.is_none());
        assert!(
            log.warnings.iter().any(|w| w.contains("no bone")),
            "{:?}",
            log.warnings
        );
        let record = log
            .stages
            .iter()
            .find(|s| s.stage == Stage::Muscles)
            .unwrap();
        assert_eq!(record.status, StageStatus::Tracked, "{record:?}");
        assert!(record.why.contains("no bone"), "{record:?}");
        // The tracking is the tracking driver's (κ = 10), not the weak one beside muscles.
        scene.muscles.source = Some(MuscleSource::None);
        let plan = Plan::new(&rig, &opts(&scene)).unwrap();
        let tracked = set_up(&rig, &scene, &plan, &mut Log::default(), &|_, _, _| {});
        assert_eq!(model.tracking.k, tracked.unwrap().0.tracking.k);
        scene.muscles.source = Some(MuscleSource::Auto);
        let plan = Plan::new(&rig, &opts(&scene)).unwrap();
        let e = set_up(&rig, &scene, &plan, &mut Log::default(), &|_, _, _| {})
            .err()
            .expect("muscles asked for on a rig without bone");
        assert!(format!("{e:#}").contains("no bone"), "{e:#}");
    }
}
