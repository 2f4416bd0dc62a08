//! The wrinkle layer of a run (the default export): the rig's own blend shapes carried onto
//! the refined skin by the subdivision S, and K wrinkle targets.
//!
//! Animated rigs: the wrinkle offsets of the written frames, w_k = x_k − S t_k (the wrinkled
//! surface minus the blend-shape surface, m), are reduced to a truncated SVD basis
//! ([`crate::math::modes`]) with the fewest modes whose largest per-vertex error over every
//! frame is at most [`LAYER_TOLERANCE`] of the clip's largest wrinkle depth, capped so that
//! the mesh holds at most [`MAX_TARGETS`] targets. Each mode is scaled so that its weights
//! reach ±1 at most. Normals are not linear in positions, so each mode's NORMAL target is a
//! least-squares fit over the frames of the wrinkle's normal change, n(x_k) − n(S t_k), to the
//! modes' weights; the report gives the angular error of the normals it rebuilds.
//!
//! Still rigs (no animation): each shape was solved alone at weight 1; its wrinkle offset is a
//! corrective target `<shape>_wrinkle`, exact at weight 1 with its shape.
//!
//! [`check_file`] reads a written file back with furrow's loader and measures the largest
//! position error of its frames (every target at each frame's weights) against the layer
//! before storage and against the frame sequence.

use super::step::blend::blend_frame;
use super::step::compose::carry;
use crate::io::face_weights::WrinkleKeys;
use crate::io::layer::{Layer, LayerTarget};
use crate::io::load::{load_bytes, LoadOptions, Rig};
use crate::io::parts::PrimitivePick;
use crate::io::split::FaceMap;
use crate::math::modes::{self, FieldFit, ModeBound};
use crate::mesh::TriMesh;
use anyhow::{bail, Context};
use nalgebra::Vector3;
use serde::Serialize;

/// Largest per-frame reconstruction error of the wrinkle modes, as a fraction of the clip's
/// largest wrinkle depth.
pub const LAYER_TOLERANCE: f64 = 0.02;

/// Most morph targets on the face (the rig's and the wrinkles'): three.js and Filament hold
/// morph targets in a texture array whose portable limit is 256 layers.
pub const MAX_TARGETS: usize = 256;

/// The clip the frames come from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Clip {
    /// An animated clip: frame k at k / `fps` s; the written frames start at `first_frame`
    /// of `clip_frames`.
    Animated {
        /// Frames per second (Hz).
        fps: f64,
        /// First written frame.
        first_frame: usize,
        /// Frames in the whole clip.
        clip_frames: usize,
    },
    /// A still rig: frame j is shape `first_shape + j` alone at weight 1.
    Still {
        /// The first written shape.
        first_shape: usize,
    },
}

impl Clip {
    /// The clip of written frames starting at `first` of `count` (frames of an animated rig
    /// at `fps`, or a still rig's shapes).
    pub fn of(animated: bool, fps: f64, first: usize, count: usize) -> Self {
        if animated {
            Self::Animated {
                fps,
                first_frame: first,
                clip_frames: count,
            }
        } else {
            Self::Still { first_shape: first }
        }
    }
}

/// What a run gives the layer: the rig, how its refined skin maps onto the face, and the
/// written frames with their weights.
pub struct LayerInput<'a> {
    /// The rig (at the scale it was simulated at).
    pub rig: &'a Rig,
    /// The refined skin's map.
    pub map: &'a FaceMap,
    /// The wrinkled surface of each written frame (world, m).
    pub frames: &'a [Vec<Vector3<f64>>],
    /// The rig's weights of each written frame.
    pub weights: &'a [Vec<f64>],
    /// Where the frames come from.
    pub clip: Clip,
}

/// The normals' angular error (degrees) over every frame and vertex the wrinkles tilt.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct AngleError {
    /// Largest.
    pub max_deg: f64,
    /// Root mean square.
    pub rms_deg: f64,
}

/// The written file, read back.
#[derive(Debug, Clone, PartialEq, Default, Serialize)]
pub struct FileReport {
    /// Its size (bytes).
    pub bytes: usize,
    /// How accessors are stored.
    pub precision: String,
    /// Whether `EXT_meshopt_compression` is used.
    pub compressed: bool,
    /// Largest position error of its frames (every target at each frame's weights, read back
    /// with furrow's loader) against the layer before storage (m).
    pub decoded_error_m: f64,
    /// The same, as a fraction of the largest wrinkle depth.
    pub decoded_error_of_depth: f64,
    /// Largest position error of its frames against the frame sequence (basis and storage
    /// together, m).
    pub total_error_m: f64,
    /// The same, as a fraction of the largest wrinkle depth.
    pub total_error_of_depth: f64,
}

/// What the layer holds and how well it reproduces the frames (in the run report as
/// `export`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LayerReport {
    /// `wrinkle_layer` (modes animated with the rig) or `correctives` (one per shape).
    pub form: String,
    /// The rig's own targets.
    pub rig_targets: usize,
    /// Wrinkle targets K.
    pub wrinkle_targets: usize,
    /// What decided K: `error` (the tolerance was met), `target_cap` (the 256-target cap),
    /// `rank` (every mode the clip has), `one_per_shape` (correctives), `no_wrinkles`.
    pub bound: String,
    /// The largest wrinkle depth of the written frames, ‖x − S t‖ (m).
    pub wrinkle_depth_m: f64,
    /// The tolerance on the modes' error (m).
    pub tolerance_m: f64,
    /// Largest per-frame, per-vertex error of the modes against the frames (m).
    pub basis_error_m: f64,
    /// The same, as a fraction of the largest wrinkle depth.
    pub basis_error_of_depth: f64,
    /// Angular error of the normals rebuilt from the targets.
    pub normal_error: AngleError,
    /// How the wrinkle weights were animated (kept keys, resampled).
    pub weights: Option<String>,
    /// The written file read back (size and errors).
    pub file: Option<FileReport>,
    /// What the user should know.
    pub notes: Vec<String>,
}

/// The layer and its report.
pub struct Built {
    /// What to write.
    pub layer: Layer,
    /// How well it reproduces the frames.
    pub report: LayerReport,
    /// The blend-shape surface S t of each written frame (world, m).
    pub smooth: Vec<Vec<Vector3<f64>>>,
    /// The rig's weights of each written frame.
    pub rig_weights: Vec<Vec<f64>>,
    /// The wrinkle targets' weights of each written frame, as the layer holds them (for
    /// correctives: 1 for the frame's shape's corrective).
    pub wrinkle_weights: Vec<Vec<f64>>,
}

/// The rig's blend-shape surface on the refined skin for `weights` (m): blended, welded (as
/// the frame step does) and carried by S.
fn smooth_surface(
    rig: &Rig,
    map: &FaceMap,
    weights: &[f64],
    k: usize,
) -> anyhow::Result<Vec<Vector3<f64>>> {
    let welded = blend_frame(rig, weights, &map.welded_of_loaded, map.welded_count, k)?;
    Ok(carry(&map.subdivision, &welded))
}

/// The refined rest surface, its normals and the rig's shapes carried by S with their normal
/// changes (m; world).
fn rig_on_skin(
    rig: &Rig,
    map: &FaceMap,
) -> anyhow::Result<(TriMesh, Vec<Vector3<f64>>, Vec<LayerTarget>)> {
    let face = rig.face();
    let n = face.targets.len();
    let base = smooth_surface(rig, map, &vec![0.0; n], 0)?;
    let mesh = TriMesh::new(base, map.triangles.clone());
    let normals = mesh.vertex_normals();
    let shapes = face
        .targets
        .iter()
        .map(|t| {
            let welded = super::step::blend::weld_positions(
                &t.positions,
                &map.welded_of_loaded,
                map.welded_count,
            );
            let positions = carry(&map.subdivision, &welded);
            let normals = mesh.normal_deltas(&normals, &positions);
            LayerTarget {
                name: t.name.clone(),
                positions,
                normals,
            }
        })
        .collect();
    Ok((mesh, normals, shapes))
}

/// Build the layer of `input`'s frames.
pub fn build(input: &LayerInput) -> anyhow::Result<Built> {
    let (rig, map) = (input.rig, input.map);
    let face = rig.face();
    map.check(face).with_context(|| {
        format!(
            "{}: the frames' skin does not fit this rig's face",
            rig.path.display()
        )
    })?;
    if input.frames.len() != input.weights.len() || input.frames.is_empty() {
        bail!("one weight vector per written frame is needed");
    }
    let (mesh, base_normals, shapes) = rig_on_skin(rig, map)?;
    let smooth: Vec<Vec<Vector3<f64>>> = input
        .weights
        .iter()
        .enumerate()
        .map(|(k, w)| smooth_surface(rig, map, w, k))
        .collect::<anyhow::Result<_>>()?;
    let offsets = |k: usize| -> Vec<Vector3<f64>> {
        input.frames[k]
            .iter()
            .zip(&smooth[k])
            .map(|(x, t)| x - t)
            .collect()
    };
    let (wrinkles, keys, mut report) = match input.clip {
        Clip::Animated {
            fps,
            first_frame,
            clip_frames,
        } => {
            let (modes, weights, report) = wrinkle_modes(input, &mesh, &smooth, &offsets)?;
            let keys = WrinkleKeys {
                fps,
                first_frame,
                clip_frames,
                rig_weights: input.weights.to_vec(),
                weights,
            };
            (modes, Some(keys), report)
        }
        Clip::Still { first_shape } => {
            let (c, report) = correctives(input, &mesh, &smooth, first_shape)?;
            (c, None, report)
        }
    };
    let wrinkle_weights = match &keys {
        Some(k) => k.weights.clone(),
        None => one_hot(&wrinkles, input.rig, input.clip, input.frames.len()),
    };
    report.rig_targets = shapes.len();
    let layer = Layer {
        base: mesh.positions,
        base_normals,
        shapes,
        wrinkles,
        keys,
    };
    Ok(Built {
        layer,
        report,
        smooth,
        rig_weights: input.weights.to_vec(),
        wrinkle_weights,
    })
}

/// For each of the `frames` written frames of a still rig (shape `first_shape + j`), 1 for that shape's
/// corrective among `correctives` (named `<shape>_wrinkle`) and 0 for the others.
fn one_hot(correctives: &[LayerTarget], rig: &Rig, clip: Clip, frames: usize) -> Vec<Vec<f64>> {
    let Clip::Still { first_shape } = clip else {
        return Vec::new();
    };
    let shapes = &rig.face().targets;
    let count = correctives.len();
    (first_shape..first_shape + frames)
        .map(|s| {
            let name = format!("{}_wrinkle", shapes[s].name);
            (0..count)
                .map(|c| {
                    if correctives[c].name == name {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        })
        .collect()
}

/// An empty report of `form`.
fn report_of(form: &str, depth: f64) -> LayerReport {
    LayerReport {
        form: form.into(),
        rig_targets: 0,
        wrinkle_targets: 0,
        bound: String::new(),
        wrinkle_depth_m: depth,
        tolerance_m: 0.0,
        basis_error_m: 0.0,
        basis_error_of_depth: 0.0,
        normal_error: AngleError::default(),
        weights: None,
        file: None,
        notes: Vec::new(),
    }
}

/// The wrinkle modes of an animated clip (scaled so their weights reach ±1 at most, with
/// fitted normal targets), their weights per frame, and the report.
fn wrinkle_modes(
    input: &LayerInput,
    mesh: &TriMesh,
    smooth: &[Vec<Vector3<f64>>],
    offsets: &dyn Fn(usize) -> Vec<Vector3<f64>>,
) -> anyhow::Result<(Vec<LayerTarget>, Vec<Vec<f64>>, LayerReport)> {
    let n = mesh.positions.len();
    let frames = input.frames.len();
    let a = modes::clip_matrix(frames, n, |k| Ok(offsets(k)))?;
    let depth = modes::largest_norm(&a);
    let mut report = report_of("wrinkle_layer", depth);
    let rig_targets = input.rig.face().targets.len();
    let cap = MAX_TARGETS.saturating_sub(rig_targets);
    if depth == 0.0 {
        report.bound = "no_wrinkles".into();
        report
            .notes
            .push("the written frames have no wrinkles: no wrinkle targets".into());
        return Ok((Vec::new(), vec![Vec::new(); frames], report));
    }
    report.tolerance_m = LAYER_TOLERANCE * depth;
    let basis = modes::truncated_basis(a, report.tolerance_m, cap)?;
    report.bound = match basis.bound {
        ModeBound::Error => "error",
        ModeBound::Cap => "target_cap",
        ModeBound::Rank => "rank",
    }
    .into();
    if basis.bound == ModeBound::Cap {
        report.notes.push(format!(
            "the {MAX_TARGETS}-target cap leaves {cap} wrinkle targets: the largest error is {:.2} % of the wrinkle depth, over the {:.0} % asked",
            100.0 * basis.error / depth,
            100.0 * LAYER_TOLERANCE
        ));
    }
    report.wrinkle_targets = basis.modes.len();
    report.basis_error_m = basis.error;
    report.basis_error_of_depth = basis.error / depth;
    // Vertices the clip never wrinkles keep exact zeros (round-off of the SVD aside).
    let still: Vec<bool> = (0..n)
        .map(|v| (0..frames).all(|k| input.frames[k][v] == smooth[k][v]))
        .collect();
    let k_modes = basis.modes.len();
    let amp: Vec<f64> = (0..k_modes)
        .map(|m| {
            basis
                .coefficients
                .iter()
                .map(|c| c[m].abs())
                .fold(0.0, f64::max)
        })
        .collect();
    let weights: Vec<Vec<f64>> = basis
        .coefficients
        .iter()
        .map(|c| {
            c.iter()
                .zip(&amp)
                .map(|(x, a)| if *a > 0.0 { x / a } else { 0.0 })
                .collect()
        })
        .collect();
    let positions: Vec<Vec<Vector3<f64>>> = basis
        .modes
        .iter()
        .zip(&amp)
        .map(|(u, a)| {
            u.iter()
                .zip(&still)
                .map(|(d, s)| if *s { Vector3::zeros() } else { d * *a })
                .collect()
        })
        .collect();
    let (normals, angle) = fit_normals(input, mesh, smooth, &weights)?;
    report.normal_error = angle;
    let targets = positions
        .into_iter()
        .zip(normals)
        .enumerate()
        .map(|(m, (positions, normals))| LayerTarget {
            name: format!("wrinkle_{m:02}"),
            positions,
            normals,
        })
        .collect();
    Ok((targets, weights, report))
}

/// The modes' NORMAL targets fitted by least squares to the wrinkles' normal change over the
/// frames, n(x_k) − n(S t_k), and the angular error of normal(n(S t_k) + Σ_m w_km g_m)
/// against n(x_k) where the wrinkles tilt the normal.
fn fit_normals(
    input: &LayerInput,
    mesh: &TriMesh,
    smooth: &[Vec<Vector3<f64>>],
    weights: &[Vec<f64>],
) -> anyhow::Result<(Vec<Vec<Vector3<f64>>>, AngleError)> {
    let n = mesh.positions.len();
    let k_modes = weights.first().map_or(0, |w| w.len());
    if k_modes == 0 {
        return Ok((Vec::new(), AngleError::default()));
    }
    let change = |k: usize| -> (Vec<Vector3<f64>>, Vec<Vector3<f64>>) {
        let wr = mesh.vertex_normals_of(&input.frames[k]);
        let sm = mesh.vertex_normals_of(&smooth[k]);
        (wr, sm)
    };
    let mut fit = FieldFit::new(k_modes, n);
    for (k, w) in weights.iter().enumerate() {
        let (wr, sm) = change(k);
        let y: Vec<Vector3<f64>> = wr.iter().zip(&sm).map(|(a, b)| a - b).collect();
        fit.add(&y, w)?;
    }
    let fields = fit.solve()?;
    let (mut worst, mut sum, mut count) = (0.0f64, 0.0, 0usize);
    for (k, w) in weights.iter().enumerate() {
        let (wr, sm) = change(k);
        for v in 0..n {
            if wr[v] == sm[v] {
                continue;
            }
            let rebuilt: Vector3<f64> = sm[v]
                + (0..k_modes)
                    .map(|m| fields[m][v] * w[m])
                    .sum::<Vector3<f64>>();
            let angle = rebuilt.angle(&wr[v]).to_degrees();
            worst = worst.max(angle);
            sum += angle * angle;
            count += 1;
        }
    }
    let angle = AngleError {
        max_deg: worst,
        rms_deg: if count > 0 {
            (sum / count as f64).sqrt()
        } else {
            0.0
        },
    };
    Ok((fields, angle))
}

/// A still rig's correctives: shape k's wrinkle offset at weight 1 with its normal change,
/// named `<shape>_wrinkle`, for the shapes that wrinkle (the deepest first when the target
/// cap leaves fewer places than shapes), and the report.
fn correctives(
    input: &LayerInput,
    mesh: &TriMesh,
    smooth: &[Vec<Vector3<f64>>],
    first_shape: usize,
) -> anyhow::Result<(Vec<LayerTarget>, LayerReport)> {
    let face = input.rig.face();
    let mut found: Vec<(f64, LayerTarget)> = Vec::new();
    for (j, x) in input.frames.iter().enumerate() {
        let positions: Vec<Vector3<f64>> = x.iter().zip(&smooth[j]).map(|(a, b)| a - b).collect();
        let depth = positions.iter().map(|d| d.norm()).fold(0.0, f64::max);
        if depth == 0.0 {
            continue;
        }
        let wr = mesh.vertex_normals_of(x);
        let sm = mesh.vertex_normals_of(&smooth[j]);
        let name = &face.targets[first_shape + j].name;
        found.push((
            depth,
            LayerTarget {
                name: format!("{name}_wrinkle"),
                positions,
                normals: wr.iter().zip(&sm).map(|(a, b)| a - b).collect(),
            },
        ));
    }
    let depth = found.iter().map(|f| f.0).fold(0.0, f64::max);
    let mut report = report_of("correctives", depth);
    let cap = MAX_TARGETS.saturating_sub(face.targets.len());
    let wrinkled = found.len();
    if wrinkled > cap {
        let mut order: Vec<usize> = (0..wrinkled).collect();
        order.sort_by(|&a, &b| found[b].0.total_cmp(&found[a].0).then(a.cmp(&b)));
        let mut keep = vec![false; wrinkled];
        order[..cap].iter().for_each(|&i| keep[i] = true);
        let mut i = 0;
        found.retain(|_| {
            i += 1;
            keep[i - 1]
        });
        report.notes.push(format!(
            "{wrinkled} shapes wrinkle but the {MAX_TARGETS}-target cap leaves {cap} places: the deepest {cap} got correctives"
        ));
    }
    let none = input.frames.len() - wrinkled;
    if none > 0 {
        report.notes.push(format!(
            "{none} shape(s) do not wrinkle at weight 1: no corrective for them"
        ));
    }
    report.bound = if wrinkled == 0 {
        "no_wrinkles"
    } else {
        "one_per_shape"
    }
    .into();
    report.wrinkle_targets = found.len();
    Ok((found.into_iter().map(|f| f.1).collect(), report))
}

/// Read the written `bytes` back with furrow's loader and measure its frames against the
/// layer before storage (`built`) and against the frame sequence (`frames`, m): every target
/// at each written frame's weights (for correctives: shape and corrective at 1). Fills the
/// report's `file`. `refined_of_vertex` maps the written face's vertices to refined ones.
pub fn check_file(
    rig: &Rig,
    built: &mut Built,
    written: &crate::io::layer::Written,
    frames: &[Vec<Vector3<f64>>],
) -> anyhow::Result<()> {
    // The written face's skin is the rig's: the same primitives, refined.
    let skin = rig.parts.parts.iter().filter(|p| p.skin);
    let face_mesh = LoadOptions {
        mesh: Some(written.mesh.to_string()),
        skin_primitives: Some(skin.map(|p| PrimitivePick::Index(p.primitive)).collect()),
        ..Default::default()
    };
    let back = load_bytes(&rig.path, &written.bytes, &face_mesh)
        .context("furrow cannot read back the file it wrote")?;
    let layer = &built.layer;
    let (nr, kw) = (layer.shapes.len(), layer.wrinkles.len());
    let face = back.face();
    if face.targets.len() != nr + kw || face.positions.len() != written.refined_of_vertex.len() {
        bail!("the written file's face does not hold the layer's vertices and targets");
    }
    let f = rig.scale.metres_per_unit;
    let (mut decoded, mut total) = (0.0f64, 0.0f64);
    for (j, x) in frames.iter().enumerate() {
        let w = file_weights(&back, built, j, &written.weight_scale);
        if w.len() != face.targets.len() {
            bail!(
                "the written file's animation has {} weights for {} targets",
                w.len(),
                face.targets.len()
            );
        }
        for (i, &v) in written.refined_of_vertex.iter().enumerate() {
            let mut p = face.positions[i];
            for (t, wt) in face.targets.iter().zip(&w) {
                if *wt != 0.0 {
                    p += t.positions[i] * *wt;
                }
            }
            let p = p * f;
            let mut reference = built.smooth[j][v];
            for (t, wt) in layer.wrinkles.iter().zip(&built.wrinkle_weights[j]) {
                reference += t.positions[v] * *wt;
            }
            decoded = decoded.max((p - reference).norm());
            total = total.max((p - x[v]).norm());
        }
    }
    let depth = built.report.wrinkle_depth_m.max(f64::MIN_POSITIVE);
    built.report.file = Some(FileReport {
        bytes: written.bytes.len(),
        precision: String::new(),
        compressed: false,
        decoded_error_m: decoded,
        decoded_error_of_depth: decoded / depth,
        total_error_m: total,
        total_error_of_depth: total / depth,
    });
    Ok(())
}

/// The written face's weights at written frame `j`: the file's own animation sampled at the
/// frame's time; without one (correctives, or a single frame), the rig's weights and the
/// wrinkle weights as the file scales them.
fn file_weights(back: &Rig, built: &Built, j: usize, scale: &[f64]) -> Vec<f64> {
    if let (Some(k), Some(track)) = (&built.layer.keys, &back.track) {
        return track.sample((k.first_frame + j) as f64 / k.fps);
    }
    let mut w = built.rig_weights[j].clone();
    w.extend(
        built.wrinkle_weights[j]
            .iter()
            .zip(scale)
            .map(|(a, s)| a * s),
    );
    w
}
