//! The `outside` stage: where a pose of the rig leaves the skin's model, and what happens
//! there.
//!
//! Real rigs fold their surface by design: lips that press or roll, lids that close, a mouth
//! corner that tucks in. In a pose (a frame of the clip, or for a still rig a shape at weight
//! 1), the welded triangles that
//! - the pose folds past [`FOLD_ANGLE`] (two triangles that agree at rest turn their normals
//!   more than 150° apart),
//! - pass through other triangles of the pose where they do not at rest, or
//! - the pose collapses (quality 2 r_in / r_circ below [`DEGENERATE_QUALITY`], fine at rest)
//!
//! are outside the skin's model, and so is the skin within a margin (one critical wavelength
//! of the thickest skin) of them. In that pose that region follows the blend shape: its
//! simulated vertices are pinned to the interior (x = B q, so the exported t + (x − B q) is
//! the target there), and the wrinkles near it fade out of the export over another margin,
//! and over [`FADE_SECONDS`] before the region appears and after it goes, so that a region
//! switching on or off does not jolt the skin. The rest of the skin wrinkles as before.

use super::weld::Welded;
use crate::io::load::Rig;
use crate::mesh::grid::PointGrid;
use crate::mesh::intersect::self_intersections_beyond;
use crate::mesh::quality::triangle_quality;
use crate::mesh::TriMesh;
use crate::pipeline::plan::Plan;
use crate::pipeline::record::{Stage, StagePlan};
use crate::pipeline::setup::skin::DEGENERATE_QUALITY;
use crate::pipeline::step::blend::weld_positions;
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::time::Instant;

/// Dihedral turn (rad) across a skin edge beyond which a pose folds the skin over itself:
/// the two triangles' normals, which agree at rest, point more than 150° apart.
pub const FOLD_ANGLE: f64 = 150.0 * std::f64::consts::PI / 180.0;

/// How long the wrinkles fade out of the export before an out-of-model region appears, and
/// back in after it goes (s). Long enough that a switch does not jolt the skin: on
/// `rigs/avatar_clip.glb` (a blink, a lip press, a lip roll, a viseme) the 99th percentile
/// of the wrinkles' per-frame change where a fade changes is 2.6× the clip's elsewhere at
/// 0.1 s, 1.2× at 0.3 s, 1.04× at 0.4 s and 0.87× at 0.5 s (REPORT.json
/// `out_of_model.jolt`, tests/real_rigs.rs `an_animated_avatar_folds_without_a_jolt`).
pub const FADE_SECONDS: f64 = 0.5;

/// Why skin is outside the model in a pose.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum OutsideCause {
    /// The pose folds the skin past [`FOLD_ANGLE`].
    Fold,
    /// The pose passes the skin through itself.
    Crossing,
    /// The pose collapses a triangle.
    Degenerate,
}

impl OutsideCause {
    /// The cause in words.
    pub fn describe(self) -> &'static str {
        match self {
            Self::Fold => "fold the skin past 150°",
            Self::Crossing => "pass the skin through itself",
            Self::Degenerate => "collapse skin triangles",
        }
    }
}

/// The region of one pose that follows the blend shape.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct PoseRegion {
    /// The pose: frame index (animated) or shape index (still rig).
    pub pose: usize,
    /// Welded triangles that follow the blend shape (the causes' triangles and the margin).
    #[serde(skip)]
    pub triangles: Vec<usize>,
    /// Their rest area as a fraction of the skin's (0–1).
    pub area_fraction: f64,
    /// Edges folded past [`FOLD_ANGLE`].
    pub folded_edges: usize,
    /// The largest turn between two triangles that agree at rest (degrees), when folded.
    pub worst_fold_deg: Option<f64>,
    /// Triangles that pass through others.
    pub crossing_triangles: usize,
    /// Triangles the pose collapses.
    pub degenerate_triangles: usize,
}

impl PoseRegion {
    /// The causes present.
    pub fn causes(&self) -> Vec<OutsideCause> {
        let mut c = Vec::new();
        if self.folded_edges > 0 {
            c.push(OutsideCause::Fold);
        }
        if self.crossing_triangles > 0 {
            c.push(OutsideCause::Crossing);
        }
        if self.degenerate_triangles > 0 {
            c.push(OutsideCause::Degenerate);
        }
        c
    }
}

/// Where the poses of a run leave the model: each pose's region and the export's fade.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct OutOfModel {
    /// Whether the poses are frames of a clip (else shapes at weight 1).
    pub animated: bool,
    /// The margin about the causes that follows the blend shape too (m).
    pub margin_m: f64,
    /// Frames over which the wrinkles fade in and out about a region (animated clips).
    pub fade_frames: usize,
    /// The poses with a region, in order.
    pub regions: Vec<PoseRegion>,
    /// How much the exported surface moves between frames about the regions, against
    /// elsewhere (animated clips; filled after the run).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jolt: Option<Jolt>,
    /// Per pose, the weight (0–1) of the wrinkles in the export at each welded vertex where
    /// it is below one.
    #[serde(skip)]
    fade: BTreeMap<usize, Vec<(usize, f64)>>,
}

impl OutOfModel {
    /// The region of `pose`, when it has one.
    pub fn region(&self, pose: usize) -> Option<&PoseRegion> {
        self.regions
            .binary_search_by_key(&pose, |r| r.pose)
            .ok()
            .map(|i| &self.regions[i])
    }

    /// The wrinkles' weight at the welded vertices where it is below one in `pose`.
    pub fn fade(&self, pose: usize) -> &[(usize, f64)] {
        self.fade.get(&pose).map_or(&[], Vec::as_slice)
    }

    /// The largest area fraction of any pose (0–1).
    pub fn worst_area_fraction(&self) -> f64 {
        self.regions
            .iter()
            .map(|r| r.area_fraction)
            .fold(0.0, f64::max)
    }

    /// One line per cause present: how many poses, and the worst.
    pub fn summary(&self) -> Vec<String> {
        let what = if self.animated { "frames" } else { "shapes" };
        let name = |r: &PoseRegion| {
            if self.animated {
                format!("frame {}", r.pose)
            } else {
                format!("shape {}", r.pose)
            }
        };
        let causes = [
            OutsideCause::Fold,
            OutsideCause::Crossing,
            OutsideCause::Degenerate,
        ];
        causes
            .into_iter()
            .filter_map(|c| {
                let with: Vec<&PoseRegion> = self
                    .regions
                    .iter()
                    .filter(|r| r.causes().contains(&c))
                    .collect();
                let worst = with
                    .iter()
                    .max_by(|a, b| a.area_fraction.total_cmp(&b.area_fraction))?;
                let angle = match (c, worst.worst_fold_deg) {
                    (OutsideCause::Fold, Some(a)) => format!(", {a:.0}°"),
                    _ => String::new(),
                };
                Some(format!(
                    "{} {what} {}: that skin and {:.1} mm about it follow the blend shape there \
                     (largest in {}{angle}: {:.2} % of the skin's area)",
                    with.len(),
                    c.describe(),
                    self.margin_m * 1e3,
                    name(worst),
                    100.0 * worst.area_fraction
                ))
            })
            .collect()
    }
}

/// How a pose's region reaches the simulated skin and the export: the shell's own pins
/// (slits, degenerate corners, the selection's border), and for each refined triangle its
/// welded ancestor and each refined vertex its shell vertex.
#[derive(Debug, Clone, Default)]
pub struct PoseMaps {
    /// Shell vertices pinned in every pose (sorted).
    pub static_pins: Vec<usize>,
    /// Shell vertex of each refined vertex (`u32::MAX` where not simulated).
    pub shell_of_refined: Vec<u32>,
    /// Welded triangle of each refined triangle.
    pub welded_of_refined: Vec<u32>,
    /// Per pose of a still rig, the welded triangles it alone can wrinkle (compressed
    /// beyond the threshold, grown by the margin): the skin elsewhere is pinned in that
    /// pose. Empty for a clip, whose frames share their history.
    pub active: Vec<Vec<bool>>,
}

impl PoseMaps {
    /// The shell vertices pinned in `pose`: the static pins and those on refined triangles
    /// of the pose's region or, for a still rig, outside what the pose can wrinkle (sorted,
    /// each once).
    pub fn pins(&self, outside: &OutOfModel, refined: &TriMesh, pose: usize) -> Vec<usize> {
        let region = outside.region(pose);
        let active = self.active.get(pose);
        if region.is_none() && active.is_none() {
            return self.static_pins.clone();
        }
        let welded = self
            .welded_of_refined
            .iter()
            .max()
            .map_or(0, |&t| t as usize + 1);
        let mut held = vec![false; welded];
        if let Some(a) = active {
            held.iter_mut().zip(a).for_each(|(h, &a)| *h = !a);
        }
        for &t in region.map_or(&[][..], |r| &r.triangles) {
            held[t] = true;
        }
        let mut pins = self.static_pins.clone();
        for (t, tri) in refined.triangles.iter().enumerate() {
            if held[self.welded_of_refined[t] as usize] {
                let shell = tri.iter().map(|&v| self.shell_of_refined[v]);
                pins.extend(shell.filter(|&s| s != u32::MAX).map(|s| s as usize));
            }
        }
        pins.sort_unstable();
        pins.dedup();
        pins
    }
}

impl PoseMaps {
    /// The share of the welded triangles `pose` can wrinkle (0–1; 1 for a clip's frame):
    /// what its skin solve costs, roughly.
    pub fn active_share(&self, pose: usize) -> f64 {
        self.active.get(pose).map_or(1.0, |a| {
            a.iter().filter(|&&t| t).count() as f64 / a.len().max(1) as f64
        })
    }

    /// Whether `pose` needs a skin solve: a still rig's shape that compresses no skin in the
    /// model does not.
    pub fn solves(&self, pose: usize) -> bool {
        self.active.get(pose).is_none_or(|a| a.contains(&true))
    }
}

/// The wrinkles' weight (0–1) at each refined vertex in `pose`, carried from the welded
/// vertices' by the subdivision `target_of`; `None` where it is one everywhere.
pub fn refined_fade(
    outside: &OutOfModel,
    target_of: &[Vec<(usize, f64)>],
    pose: usize,
) -> Option<Vec<f64>> {
    let below = outside.fade(pose);
    if below.is_empty() {
        return None;
    }
    let mut missing = std::collections::HashMap::with_capacity(below.len());
    for &(v, w) in below {
        missing.insert(v, 1.0 - w);
    }
    Some(
        target_of
            .iter()
            .map(|o| {
                let gone: f64 = o
                    .iter()
                    .map(|(v, a)| a * missing.get(v).unwrap_or(&0.0))
                    .sum();
                (1.0 - gone).clamp(0.0, 1.0)
            })
            .collect(),
    )
}

/// Attempts at clearing the exported surface of crossings its target lacks.
const EXPORT_CLEARING: usize = 3;

/// Take the wrinkles out of the exported surface `wrinkled` (per refined vertex of `mesh`, m)
/// where it passes through itself and its `target` (the blend shape) does not: on the
/// crossing triangles the surface is the target, and the wrinkles come back linearly over
/// `margin` (m) about them (rest distance). Repeated while crossings remain, up to
/// [`EXPORT_CLEARING`] times. Returns how many refined vertices lost some of their wrinkles
/// (0 when the surface adds no crossing, and then it is unchanged).
pub fn clear_new_crossings(
    mesh: &TriMesh,
    target: &[Vector3<f64>],
    wrinkled: &mut [Vector3<f64>],
    margin: f64,
) -> usize {
    let flat =
        |p: &[Vector3<f64>]| -> Vec<f64> { p.iter().flat_map(|v| [v.x, v.y, v.z]).collect() };
    let reference = flat(target);
    let mut weight = vec![1.0f64; wrinkled.len()];
    for _ in 0..EXPORT_CLEARING {
        let pairs = self_intersections_beyond(mesh, &flat(wrinkled), Some(&reference));
        if pairs.is_empty() {
            break;
        }
        let mut region = vec![false; mesh.triangles.len()];
        for (a, b) in pairs {
            region[a] = true;
            region[b] = true;
        }
        let fade = spatial_fade(mesh, &region, margin);
        for (v, w) in weight.iter_mut().enumerate() {
            let now = w.min(fade[v]);
            if now < *w {
                // Scale what is left of the wrinkle by the new weight over the old.
                let kept = if *w > 0.0 { now / *w } else { 0.0 };
                wrinkled[v] = target[v] + (wrinkled[v] - target[v]) * kept;
                *w = now;
            }
        }
    }
    weight.iter().filter(|&&w| w < 1.0).count()
}

/// How much the wrinkles on the exported surface change per vertex between consecutive
/// frames (m; the change of the exported surface beyond the blend shape's own): inside the
/// bands where the wrinkles fade about an out-of-model region, and where that fade changes
/// between the two frames (a region switching on or off), against the clip's 99th
/// percentile elsewhere. A switch does not jolt the skin when the switching percentile is
/// at most the one elsewhere.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Jolt {
    /// Largest per-vertex change between consecutive frames among vertices whose wrinkles
    /// fade in either frame (m).
    pub band_max_m: f64,
    /// The later frame of that change.
    pub band_frame: usize,
    /// The 99th percentile of the per-vertex changes among vertices whose wrinkles fade (m;
    /// the upper edge of a logarithmic histogram bin, within 1 %).
    pub band_p99_m: f64,
    /// The 99th percentile of the per-vertex changes everywhere else (m; the upper edge of a
    /// logarithmic histogram bin, within 1 %).
    pub elsewhere_p99_m: f64,
    /// Largest per-vertex change between consecutive frames among vertices whose fade
    /// changes between them: where a region switches on or off (m).
    pub switching_max_m: f64,
    /// The later frame of that change.
    pub switching_frame: usize,
    /// The 99th percentile of the per-vertex changes where a region switches (m; the upper
    /// edge of a logarithmic histogram bin, within 1 %): the jolt a switch gives, against
    /// `elsewhere_p99_m`.
    pub switching_p99_m: f64,
}

/// Counts of positive lengths in logarithmic bins ([`BINS_PER_DECADE`]), for percentiles.
#[derive(Debug, Default)]
struct LogHistogram {
    bins: BTreeMap<i64, u64>,
    count: u64,
}

impl LogHistogram {
    fn add(&mut self, c: f64) {
        let bin = if c > 0.0 {
            (c.log10() * BINS_PER_DECADE).ceil() as i64
        } else {
            i64::MIN
        };
        *self.bins.entry(bin).or_default() += 1;
        self.count += 1;
    }

    /// The upper edge of the bin holding quantile `p` (0 for no counts).
    fn quantile(&self, p: f64) -> f64 {
        let rank = (p * self.count as f64).ceil() as u64;
        let mut seen = 0;
        self.bins
            .iter()
            .find_map(|(&bin, &n)| {
                seen += n;
                (seen >= rank).then_some(bin)
            })
            .map_or(0.0, |bin| {
                if bin == i64::MIN {
                    0.0
                } else {
                    10f64.powf(bin as f64 / BINS_PER_DECADE)
                }
            })
    }
}

/// Positions of the refined skin vertices at each exported frame (m).
pub type FramePositions = [Vec<Vector3<f64>>];

/// Bins per decade of the changes' histogram ([`jolt`]).
const BINS_PER_DECADE: f64 = 230.0;

/// The [`Jolt`] of exported frames `frames` over their blend shapes `smooth` (per refined
/// vertex, m), the first being pose `first`, with the wrinkle fades of `outside` carried by
/// `target_of`; `None` with fewer than two frames or no fade among them.
pub fn jolt(
    outside: &OutOfModel,
    target_of: &[Vec<(usize, f64)>],
    (frames, smooth): (&FramePositions, &FramePositions),
    first: usize,
) -> Option<Jolt> {
    let fade = |j: usize| refined_fade(outside, target_of, first + j);
    jolt_of_fades(&fade, (frames, smooth), first)
}

/// [`jolt`] with the wrinkles' weight per refined vertex at written frame j given by
/// `fade(j)` (`None` where it is one everywhere).
fn jolt_of_fades(
    fade: &dyn Fn(usize) -> Option<Vec<f64>>,
    (frames, smooth): (&FramePositions, &FramePositions),
    first: usize,
) -> Option<Jolt> {
    let (mut band, mut switching) = (BandChanges::default(), BandChanges::default());
    let mut elsewhere = LogHistogram::default();
    let mut before = fade(0);
    for j in 1..frames.len() {
        let now = fade(j);
        let weight = |f: &Option<Vec<f64>>, v: usize| f.as_ref().map_or(1.0, |f| f[v]);
        let (now_x, now_t, was_x, was_t) = (&frames[j], &smooth[j], &frames[j - 1], &smooth[j - 1]);
        for v in 0..now_x.len() {
            let c = ((now_x[v] - now_t[v]) - (was_x[v] - was_t[v])).norm();
            let (was, is) = (weight(&before, v), weight(&now, v));
            if was < 1.0 || is < 1.0 {
                band.add(c, first + j);
                if was != is {
                    switching.add(c, first + j);
                }
            } else {
                elsewhere.add(c);
            }
        }
        before = now;
    }
    if band.changes.count == 0 || elsewhere.count == 0 {
        return None;
    }
    Some(Jolt {
        band_max_m: band.max,
        band_frame: band.frame,
        band_p99_m: band.changes.quantile(0.99),
        elsewhere_p99_m: elsewhere.quantile(0.99),
        switching_max_m: switching.max,
        switching_frame: switching.frame,
        switching_p99_m: switching.changes.quantile(0.99),
    })
}

/// Per-vertex changes of a band of the skin: their histogram, the largest and its frame.
#[derive(Default)]
struct BandChanges {
    changes: LogHistogram,
    max: f64,
    frame: usize,
}

impl BandChanges {
    /// Count a change `c` (m) at frame `frame`.
    fn add(&mut self, c: f64, frame: usize) {
        self.changes.add(c);
        if c > self.max {
            (self.max, self.frame) = (c, frame);
        }
    }
}

/// The `outside` stage: every pose of `plan` judged on the `welded` skin, with a margin of
/// the thinnest skin's wavelength; its record.
pub fn find(rig: &Rig, plan: &Plan, welded: &Welded) -> (OutOfModel, StagePlan) {
    let t = Instant::now();
    let mesh = &welded.mesh;
    let margin = plan.skin.lambda;
    let judge = Judge::new(mesh);
    let count = mesh.positions.len();
    let found: Vec<(PoseRegion, Vec<bool>)> = plan
        .weights
        .par_iter()
        .enumerate()
        .filter_map(|(k, w)| {
            let pose = weld_positions(&rig.blend(w), &welded.of_loaded, count);
            judge.region(k, &pose, margin)
        })
        .collect();
    let fade_frames = if plan.animated {
        (FADE_SECONDS * plan.fps).ceil() as usize
    } else {
        0
    };
    let spatial: Vec<(usize, Vec<f64>)> = found
        .par_iter()
        .map(|(r, region)| (r.pose, spatial_fade(mesh, region, margin)))
        .collect();
    let fade = temporal_fade(&spatial, fade_frames, plan.weights.len());
    let out = OutOfModel {
        animated: plan.animated,
        margin_m: margin,
        fade_frames,
        regions: found.into_iter().map(|(r, _)| r).collect(),
        jolt: None,
        fade,
    };
    let ms = t.elapsed().as_secs_f64() * 1e3;
    let record = if out.regions.is_empty() {
        StagePlan::skipped(
            Stage::Outside,
            "no pose folds, crosses or collapses the skin: all of it stays in the model",
        )
    } else {
        StagePlan::ran(Stage::Outside, out.summary().join("; "), ms)
    };
    (out, record)
}

/// What a pose is judged against: the rest skin, its triangle pairs that agree at rest, its
/// rest positions and areas.
struct Judge<'a> {
    mesh: &'a TriMesh,
    edges: Vec<(usize, usize)>,
    rest_flat: Vec<f64>,
    rest_ok: Vec<bool>,
    areas: Vec<f64>,
    total_area: f64,
}

impl<'a> Judge<'a> {
    fn new(mesh: &'a TriMesh) -> Self {
        let areas: Vec<f64> = (0..mesh.triangles.len())
            .map(|t| mesh.triangle_area(t))
            .collect();
        let rest_ok = mesh
            .triangles
            .iter()
            .map(|t| triangle_quality(t.map(|v| mesh.positions[v])).0 >= DEGENERATE_QUALITY)
            .collect();
        Self {
            mesh,
            edges: judged_edges(mesh),
            rest_flat: mesh.flat_positions(),
            rest_ok,
            total_area: areas.iter().sum(),
            areas,
        }
    }

    /// The region of pose `k` at welded positions `pose` (m), with its per-triangle flags;
    /// `None` when the pose stays in the model.
    fn region(
        &self,
        k: usize,
        pose: &[Vector3<f64>],
        margin: f64,
    ) -> Option<(PoseRegion, Vec<bool>)> {
        let n = self.mesh.triangles.len();
        let mut core = vec![false; n];
        let (mut folded, mut worst) = (0, None::<f64>);
        let cos_fold = FOLD_ANGLE.cos();
        for &(u, t) in &self.edges {
            let (Some(a), Some(b)) = (
                triangle_normal(self.mesh, pose, u),
                triangle_normal(self.mesh, pose, t),
            ) else {
                continue;
            };
            let c = a.dot(&b);
            if c < cos_fold {
                folded += 1;
                core[u] = true;
                core[t] = true;
                let deg = c.clamp(-1.0, 1.0).acos().to_degrees();
                worst = Some(worst.map_or(deg, |w| w.max(deg)));
            }
        }
        let flat: Vec<f64> = pose.iter().flat_map(|p| [p.x, p.y, p.z]).collect();
        let mut crossing = vec![false; n];
        for (s, t) in self_intersections_beyond(self.mesh, &flat, Some(&self.rest_flat)) {
            crossing[s] = true;
            crossing[t] = true;
        }
        let mut degenerate = 0;
        for (t, tri) in self.mesh.triangles.iter().enumerate() {
            let collapsed =
                self.rest_ok[t] && triangle_quality(tri.map(|v| pose[v])).0 < DEGENERATE_QUALITY;
            degenerate += usize::from(collapsed);
            core[t] |= collapsed || crossing[t];
        }
        if !core.contains(&true) {
            return None;
        }
        let region = grow(self.mesh, &core, margin);
        let triangles: Vec<usize> = (0..n).filter(|&t| region[t]).collect();
        let area: f64 = triangles.iter().map(|&t| self.areas[t]).sum();
        let r = PoseRegion {
            pose: k,
            triangles,
            area_fraction: if self.total_area > 0.0 {
                area / self.total_area
            } else {
                0.0
            },
            folded_edges: folded,
            worst_fold_deg: worst,
            crossing_triangles: crossing.iter().filter(|&&c| c).count(),
            degenerate_triangles: degenerate,
        };
        Some((r, region))
    }
}

/// The pairs of triangles (in edge order) sharing an edge whose normals agree at rest: the
/// edges a fold is judged on (a crease at rest, or a non-manifold pair, is not judged).
fn judged_edges(rest: &TriMesh) -> Vec<(usize, usize)> {
    let normals: Vec<Option<Vector3<f64>>> = (0..rest.triangles.len())
        .map(|t| triangle_normal(rest, &rest.positions, t))
        .collect();
    let mut by_edge: HashMap<(usize, usize), usize> = HashMap::new();
    let mut pairs = Vec::new();
    for (t, tri) in rest.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri[k], tri[(k + 1) % 3]);
            let Some(u) = by_edge.insert((a.min(b), a.max(b)), t) else {
                continue;
            };
            if let (Some(n0), Some(n1)) = (normals[u], normals[t]) {
                if n0.dot(&n1) > 0.0 {
                    pairs.push((u, t));
                }
            }
        }
    }
    pairs
}

/// Unit normal of triangle `t` of `mesh` at positions `p`, `None` when degenerate.
fn triangle_normal(mesh: &TriMesh, p: &[Vector3<f64>], t: usize) -> Option<Vector3<f64>> {
    let [a, b, c] = mesh.triangles[t].map(|v| p[v]);
    (b - a).cross(&(c - a)).try_normalize(1e-300)
}

/// The wrinkles' weight per welded vertex about a region (per-triangle flags `region`): 0 on
/// the region's vertices, rising linearly with the straight-line rest distance to 1 at
/// `margin` (m) from them.
fn spatial_fade(mesh: &TriMesh, region: &[bool], margin: f64) -> Vec<f64> {
    let (on, grid) = region_vertices(mesh, region, margin);
    mesh.positions
        .iter()
        .enumerate()
        .map(|(v, p)| {
            if on[v] {
                return 0.0;
            }
            let d = grid
                .near(p)
                .map(|s| (mesh.positions[s] - p).norm())
                .fold(f64::INFINITY, f64::min);
            (d / margin).min(1.0)
        })
        .collect()
}

/// Each pose's wrinkle weights below one, from the poses' spatial fades (`spatial`, per pose
/// with a region): the smallest over those poses j of max(s_j, |k − j| / `frames`) for pose
/// k of `poses` (only pose j itself when `frames` is 0).
fn temporal_fade(
    spatial: &[(usize, Vec<f64>)],
    frames: usize,
    poses: usize,
) -> BTreeMap<usize, Vec<(usize, f64)>> {
    let mut dense: BTreeMap<usize, Vec<f64>> = BTreeMap::new();
    for (j, s) in spatial {
        let lo = j.saturating_sub(frames);
        let hi = (j + frames).min(poses.saturating_sub(1));
        for k in lo..=hi {
            let time = if frames == 0 {
                0.0
            } else {
                k.abs_diff(*j) as f64 / frames as f64
            };
            if time >= 1.0 {
                continue;
            }
            let m = dense.entry(k).or_insert_with(|| vec![1.0; s.len()]);
            for (mv, &sv) in m.iter_mut().zip(s) {
                *mv = mv.min(sv.max(time));
            }
        }
    }
    dense
        .into_iter()
        .map(|(k, m)| {
            let below = m
                .into_iter()
                .enumerate()
                .filter(|&(_, w)| w < 1.0)
                .collect();
            (k, below)
        })
        .collect()
}

/// The vertices of the triangles of `mesh` flagged in `region`, and a grid of them with cells
/// of `margin` (m) for finding those near a point.
fn region_vertices(mesh: &TriMesh, region: &[bool], margin: f64) -> (Vec<bool>, PointGrid) {
    let mut on = vec![false; mesh.positions.len()];
    for (t, tri) in mesh.triangles.iter().enumerate() {
        if region[t] {
            tri.iter().for_each(|&v| on[v] = true);
        }
    }
    let seeds = (0..on.len()).filter(|&v| on[v]);
    let grid = PointGrid::new(margin, seeds.map(|v| (v, mesh.positions[v])));
    (on, grid)
}

/// The triangles of `mesh` with a vertex within `margin` (m) of a vertex of a `seed` triangle
/// (straight-line distance over the rest shape): the seeds grown by the margin.
pub fn grow(mesh: &TriMesh, seed: &[bool], margin: f64) -> Vec<bool> {
    let (_, grid) = region_vertices(mesh, seed, margin);
    let near = |p: &Vector3<f64>| {
        grid.near(p)
            .any(|s| (mesh.positions[s] - p).norm() <= margin)
    };
    let reached: Vec<bool> = mesh.positions.iter().map(near).collect();
    mesh.triangles
        .iter()
        .enumerate()
        .map(|(t, tri)| seed[t] || tri.iter().any(|&v| reached[v]))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::setup::test_support::bump_sheet;

    #[test]
    fn a_fold_is_found_and_a_bend_is_not() {
        let rest = bump_sheet(9);
        let judge = Judge::new(&rest);
        // Bending the sheet up by 90° along x = 0 is no fold.
        let bend = |p: &Vector3<f64>| {
            if p.x < 0.0 {
                *p
            } else {
                Vector3::new(0.0, p.y, p.z + p.x)
            }
        };
        let bent: Vec<Vector3<f64>> = rest.positions.iter().map(bend).collect();
        assert!(judge.region(0, &bent, 0.001).is_none());
        // Mirroring the left half onto the right (x ↦ −x for x < 0) folds it over.
        let folded: Vec<Vector3<f64>> = rest
            .positions
            .iter()
            .map(|p| Vector3::new(p.x.abs(), p.y, p.z))
            .collect();
        let (r, region) = judge.region(3, &folded, 0.001).expect("a fold");
        assert_eq!(r.pose, 3);
        assert!(
            r.folded_edges > 0 && r.worst_fold_deg.unwrap() > 150.0,
            "{r:?}"
        );
        assert_eq!(r.causes()[0], OutsideCause::Fold);
        // The fold's triangles lie along x = 0, and the margin keeps the far sides out.
        for (t, tri) in rest.triangles.iter().enumerate() {
            let cx = tri.iter().map(|&v| rest.positions[v].x).sum::<f64>() / 3.0;
            if cx.abs() > 0.012 {
                assert!(!region[t], "triangle {t} at x = {cx}");
            }
        }
        assert!(r.area_fraction > 0.0 && r.area_fraction < 0.5, "{r:?}");
    }

    #[test]
    fn a_collapsed_triangle_is_outside() {
        let rest = bump_sheet(5);
        let judge = Judge::new(&rest);
        let mut pose = rest.positions.clone();
        // Move vertex 6 onto the edge from vertex 0 to 1: triangle (0, 1, 6) collapses.
        let [a, b] = [rest.positions[0], rest.positions[1]];
        pose[6] = 0.5 * (a + b);
        let (r, _) = judge.region(0, &pose, 0.001).expect("collapsed");
        assert!(r.degenerate_triangles > 0, "{r:?}");
    }

    #[test]
    fn wrinkles_fade_over_the_margin_and_the_frames_about_a_region() {
        let spatial = vec![(5, vec![0.0, 0.5, 1.0])];
        let fade = temporal_fade(&spatial, 2, 10);
        assert_eq!(fade[&5], vec![(0, 0.0), (1, 0.5)]);
        assert_eq!(fade[&4], vec![(0, 0.5), (1, 0.5)]);
        assert!(!fade.contains_key(&7) && !fade.contains_key(&3));
        // A still rig's shapes do not fade into each other.
        let still = temporal_fade(&spatial, 0, 10);
        assert_eq!(still.keys().copied().collect::<Vec<_>>(), vec![5]);
    }

    /// Three vertices over four frames: vertex 0's fade switches from frame 1 to 2 (its
    /// wrinkle offset jumps by 3 µm there), vertex 1 stays faded at one half and moves by 2 µm
    /// a frame, vertex 2 is never faded and moves by 1 µm a frame. The switch is told apart
    /// from the band's own motion, and the rest is elsewhere.
    #[test]
    fn the_jolt_tells_a_switch_from_the_bands_own_motion() {
        let at = |x: f64| Vector3::new(x, 0.0, 0.0);
        let offsets = [
            [0.0, 0.0, 0.0],
            [0.0, 2e-6, 1e-6],
            [3e-6, 4e-6, 2e-6],
            [3e-6, 6e-6, 3e-6],
        ];
        let frames: Vec<Vec<Vector3<f64>>> = offsets
            .iter()
            .map(|o| o.iter().map(|&d| at(d)).collect())
            .collect();
        let smooth = vec![vec![at(0.0); 3]; 4];
        let fade = |j: usize| Some(vec![if j < 2 { 0.0 } else { 1.0 }, 0.5, 1.0]);
        let j = jolt_of_fades(&fade, (&frames, &smooth), 10).unwrap();
        assert!((j.switching_max_m - 3e-6).abs() < 1e-18, "{j:?}");
        assert_eq!(j.switching_frame, 12);
        assert!((j.band_max_m - 3e-6).abs() < 1e-18, "{j:?}");
        let near = |a: f64, b: f64| (a / b - 1.0).abs() < 0.011;
        assert!(near(j.switching_p99_m, 3e-6), "{j:?}");
        assert!(near(j.elsewhere_p99_m, 1e-6), "{j:?}");
        assert!(near(j.band_p99_m, 3e-6), "{j:?}");
    }
}
