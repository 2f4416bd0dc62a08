//! The `lattice` stage's cell size for generated muscles, when the scene gives none: the
//! muscles can make a frame only as well as the lattice can hold it, so the lattice is
//! chosen by how well it holds the rig's clip. Candidates run from the default's cells
//! ([`crate::lattice::DEFAULT_TARGET_CELLS`] over the box) down a ladder of [`CELL_STEP`] a
//! rung, up to [`ELEMENT_BUDGET`] times the default's elements; the coarsest tried whose own
//! projection of the clip misses it by at most [`CLIP_PROJECTION_GOAL`] of the clip's motion
//! is taken. The projection is the muscles' own first step ([`fit_node_displacements`]: least
//! squares through the embedding with the elastic regulariser, the jaw's bone turned), so it
//! is the floor of their fit. The measure is not monotone in the cell size (where the cells
//! fall on the mouth matters), hence a ladder rather than a bisection; it is walked every
//! [`COARSE_STRIDE`]-th rung first, then rung by rung below the last coarse miss ([`climb`]).
//! The muscles' fit is held on the skin's subdivided surface as well as at the rig's
//! vertices ([`crate::muscle::samples`]), as the skin the pipeline renders lies between them;
//! the projection's miss is the larger of its misses at the vertices and over the whole
//! subdivided surface. A slit parts only on cells well under its length (a quadratic
//! B-spline spans three cells), so a mouth on cells near its own length is held shut and the
//! ladder climbs below them.

use crate::io::model::MorphTarget;
use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::muscle::generate::{fit_node_displacements, GenerateSettings};
use crate::muscle::jaw::JawBone;
use crate::muscle::samples::{ShapeSamples, SAMPLE_LEVELS};
use crate::scene::InteriorSection;
use anyhow::Context;

/// Ratio of one candidate cell size to the last (dimensionless).
pub const CELL_STEP: f64 = 0.975;

/// Elements a chosen lattice may have at most, over the default's (dimensionless).
pub const ELEMENT_BUDGET: f64 = 12.0;

/// The projection's miss of the clip a lattice is taken at, as a share of the clip's motion:
/// below the fit's 5 % goal by what the muscles themselves add to it (the face's muscles make
/// eight of their nine shapes within 1 % of the projection).
pub const CLIP_PROJECTION_GOAL: f64 = 0.04;

/// Rungs of the ladder skipped by its coarse pass, plus one (see [`climb`]).
pub const COARSE_STRIDE: i32 = 4;

/// How the cell size was chosen: each candidate tried (cell size m, elements, projection's
/// miss of the clip as a share of its motion), coarsest first, and which was taken.
#[derive(Debug, Clone, PartialEq)]
pub struct CellChoice {
    /// Candidates tried: (cell size m, elements, miss of the clip).
    pub tried: Vec<(f64, usize, f64)>,
    /// Index in `tried` of the lattice taken (0, the default, when none met the goal).
    pub taken: usize,
}

impl CellChoice {
    /// Whether a candidate met [`CLIP_PROJECTION_GOAL`].
    pub fn met(&self) -> bool {
        self.tried[self.taken].2 <= CLIP_PROJECTION_GOAL
    }

    /// One line for the lattice's record.
    pub fn summary(&self) -> String {
        let (_, _, miss) = self.tried[self.taken];
        let (h0, _, miss0) = self.tried[0];
        if self.taken == 0 && self.met() {
            format!(
                "; the default lattice holds the clip within {:.1} % (muscles' floor)",
                100.0 * miss
            )
        } else if self.met() {
            format!(
                "; chosen for the muscles: the coarsest of {} lattices tried that holds the clip within {:.0} % ({:.1} %; the default {:.1} mm: {:.1} %)",
                self.tried.len(),
                100.0 * CLIP_PROJECTION_GOAL,
                100.0 * miss,
                1e3 * h0,
                100.0 * miss0
            )
        } else {
            format!(
                "; the default kept: no lattice of at most {ELEMENT_BUDGET}× its elements holds the clip within {:.0} % (best tried {:.1} mm: {:.1} %)",
                100.0 * CLIP_PROJECTION_GOAL,
                1e3 * self.best().0,
                100.0 * self.best().2
            )
        }
    }

    /// The candidate that missed the clip least.
    fn best(&self) -> (f64, usize, f64) {
        *self
            .tried
            .iter()
            .min_by(|a, b| a.2.total_cmp(&b.2))
            .expect("the default is always tried")
    }
}

/// The lattice under the welded `skin` (rest, m) for generated muscles, chosen as the module
/// says from its blend shapes `targets` (welded, offsets m) and the clip's weights `frames`
/// (per frame, per shape; frames without motion count each shape alone), with its choice.
pub fn choose_lattice(
    skin: &TriMesh,
    targets: &[MorphTarget],
    frames: &[Vec<f64>],
    interior: &InteriorSection,
    path: &str,
) -> anyhow::Result<(Lattice, CellChoice)> {
    let material = interior.material()?;
    let build = |cell_size: Option<f64>| {
        let sized = InteriorSection {
            cell_size,
            target_cells: None,
            ..interior.clone()
        };
        Lattice::build(skin, &sized.lattice_settings())
            .with_context(|| format!("{path}: building the lattice"))
    };
    let frames = moving_frames(frames, targets.len());
    let miss = |l: &Lattice| clip_projection_miss(l, &material, skin, targets, &frames);
    let first = build(None)?;
    let first_miss = miss(&first)?;
    let budget = ELEMENT_BUDGET * first.elements.len() as f64;
    let start = (first.cell_size, first.elements.len(), first_miss);
    climb(first, start, |h| {
        let lattice = build(Some(h))?;
        if lattice.elements.len() as f64 > budget {
            return Ok(None);
        }
        let m = miss(&lattice)?;
        Ok(Some((lattice.elements.len(), m, lattice)))
    })
}

/// The ladder from the default lattice `first` ((cell size m, elements, miss) in `start`):
/// `next(h)` builds the candidate of cell size h and gives (elements, miss, it), or `None`
/// past the budget. Rungs are h₀ · [`CELL_STEP`]ᵏ. The coarse pass tries every
/// [`COARSE_STRIDE`]-th rung until one meets the goal (or the budget ends the ladder); the
/// fine pass then tries the rungs between it and the last coarse rung that missed, coarsest
/// first. The coarsest candidate tried that meets the goal is taken, else `first`.
fn climb<L>(
    first: L,
    start: (f64, usize, f64),
    mut next: impl FnMut(f64) -> anyhow::Result<Option<(usize, f64, L)>>,
) -> anyhow::Result<(L, CellChoice)> {
    let mut choice = CellChoice {
        tried: vec![start],
        taken: 0,
    };
    let miss = start.2;
    if miss <= CLIP_PROJECTION_GOAL {
        return Ok((first, choice));
    }
    let rung = |k: i32| start.0 * CELL_STEP.powi(k);
    // Coarse pass: the first coarse rung within the goal (its lattice kept), or the rung the
    // budget stopped at.
    let mut missed = 0;
    let mut met: Option<L> = None;
    let end = loop {
        let k = missed + COARSE_STRIDE;
        let Some((elements, m, candidate)) = next(rung(k))? else {
            break k;
        };
        choice.tried.push((rung(k), elements, m));
        if m <= CLIP_PROJECTION_GOAL {
            choice.taken = choice.tried.len() - 1;
            met = Some(candidate);
            break k;
        }
        missed = k;
    };
    // Fine pass: the rungs between, coarsest first.
    for k in missed + 1..end {
        let Some((elements, m, candidate)) = next(rung(k))? else {
            break;
        };
        choice.tried.push((rung(k), elements, m));
        if m <= CLIP_PROJECTION_GOAL {
            choice.taken = choice.tried.len() - 1;
            return Ok((candidate, choice));
        }
    }
    Ok((met.unwrap_or(first), choice))
}

/// The frames whose weights move the face (any nonzero weight); each shape alone when none do.
fn moving_frames(frames: &[Vec<f64>], shapes: usize) -> Vec<Vec<f64>> {
    let moving: Vec<Vec<f64>> = frames
        .iter()
        .filter(|w| w.iter().any(|&a| a != 0.0))
        .cloned()
        .collect();
    if !moving.is_empty() {
        return moving;
    }
    (0..shapes)
        .map(|m| (0..shapes).map(|i| f64::from(u8::from(i == m))).collect())
        .collect()
}

/// The lattice's projection of the clip: Σ_k RMS(B u(w_k) − Δ(w_k)) / Σ_k RMS(Δ(w_k)) over
/// `frames` weights w_k, with Δ(w) = Σ_m w_m Δ_m the blend's displacement and u(w) =
/// Σ_m w_m u_m the shapes' node fits (linear, so one fit per shape serves every frame); the
/// larger of the ratios over the rig's vertices and over all the samples (the subdivided
/// surface between them too), so a lattice is taken only where it holds both.
fn clip_projection_miss(
    lattice: &Lattice,
    material: &crate::fem::Material,
    skin: &TriMesh,
    targets: &[MorphTarget],
    frames: &[Vec<f64>],
) -> anyhow::Result<f64> {
    let jaw = JawBone::find(lattice, &skin.positions, targets);
    let interior = crate::fem::Interior::new(lattice, material)?;
    let regulariser = GenerateSettings::default().regulariser;
    let samples = ShapeSamples::subdivided(lattice, skin, SAMPLE_LEVELS)?;
    let u = fit_node_displacements(
        lattice,
        &interior,
        targets,
        &samples,
        regulariser,
        jaw.as_ref().map(|j| &j.0),
    )?;
    let nv = samples.len();
    let embed = samples.embedding(lattice);
    // Each shape's miss r_m = B u_m − Δ_m and displacement Δ_m (flat per sample, m).
    let shapes: Vec<(Vec<f64>, Vec<f64>)> = u
        .iter()
        .zip(targets)
        .map(|(um, t)| {
            let delta = samples.displacement(&t.positions);
            let r = embed
                .positions_flat(um)
                .iter()
                .zip(&delta)
                .map(|(b, d)| b - d)
                .collect();
            (r, delta)
        })
        .collect();
    let vertices = 3 * skin.positions.len();
    let (mut missed, mut moved) = ([0.0; 2], [0.0; 2]);
    let (mut r, mut d) = (vec![0.0; 3 * nv], vec![0.0; 3 * nv]);
    for w in frames {
        r.iter_mut().chain(d.iter_mut()).for_each(|v| *v = 0.0);
        for (&a, (rm, dm)) in w.iter().zip(&shapes).filter(|(a, _)| **a != 0.0) {
            r.iter_mut().zip(rm).for_each(|(x, y)| *x += a * y);
            d.iter_mut().zip(dm).for_each(|(x, y)| *x += a * y);
        }
        for (i, n) in [vertices, 3 * nv].into_iter().enumerate() {
            missed[i] += rms(&r[..n]);
            moved[i] += rms(&d[..n]);
        }
    }
    Ok((missed[0] / moved[0].max(1e-300)).max(missed[1] / moved[1].max(1e-300)))
}

/// RMS over vertices of a flat (3 per vertex) vector (m).
fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / (v.len() / 3).max(1) as f64).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rung k of cell size `h` on the ladder from 10 mm (h = 10 mm · CELL_STEPᵏ).
    fn rung(h: f64) -> i32 {
        ((h / 0.01).ln() / CELL_STEP.ln()).round() as i32
    }

    /// Made-up candidates: elements ∝ h⁻³ from 100 at 10 mm, a miss of the clip ∝ hᵖ from
    /// `at_default` at 10 mm, with 0.6 % more on odd rungs (not monotone, as where the
    /// cells fall matters).
    fn candidates(
        at_default: f64,
        power: i32,
    ) -> impl FnMut(f64) -> anyhow::Result<Option<(usize, f64, f64)>> {
        move |h| {
            let elements = (100.0 * (0.01 / h).powi(3)).round() as usize;
            if elements as f64 > ELEMENT_BUDGET * 100.0 {
                return Ok(None);
            }
            let wobble = if rung(h) % 2 == 1 { 0.006 } else { 0.0 };
            let miss = at_default * (h / 0.01).powi(power) + wobble;
            Ok(Some((elements, miss, h)))
        }
    }

    #[test]
    fn the_coarsest_candidate_within_the_goal_is_taken() {
        // 6 % at the default: the coarse pass tries rungs 4 (4.4 %) and 8 (3.3 %), the fine
        // pass 5 (4.1 % + 0.6 %) and 6 (3.8 %: taken).
        let (h, c) = climb(0.01, (0.01, 100, 0.06), candidates(0.06, 3)).unwrap();
        assert!(c.met());
        let rungs: Vec<i32> = c.tried.iter().map(|t| rung(t.0)).collect();
        assert_eq!(rungs, vec![0, 4, 8, 5, 6]);
        assert_eq!(c.taken, 4);
        assert_eq!(c.tried[c.taken].0, h);
        assert!((h - 0.01 * CELL_STEP.powi(6)).abs() < 1e-12, "{h}");
        assert!(
            c.summary().contains("chosen for the muscles"),
            "{}",
            c.summary()
        );
        // The coarse rung within the goal is kept when no rung between meets it: at 5 % rung
        // 4 meets it (3.7 %), rungs 1, 2 and 3 miss (5.2 %, 4.3 %, 4.6 %).
        let (h, c) = climb(0.01, (0.01, 100, 0.05), candidates(0.05, 3)).unwrap();
        let rungs: Vec<i32> = c.tried.iter().map(|t| rung(t.0)).collect();
        assert_eq!(rungs, vec![0, 4, 1, 2, 3]);
        assert_eq!(c.taken, 1);
        assert!((h - 0.01 * CELL_STEP.powi(4)).abs() < 1e-12, "{h}");
        // Within the goal: the default, nothing else tried.
        let (h, c) = climb(0.01, (0.01, 100, 0.03), candidates(0.03, 3)).unwrap();
        assert_eq!((h, c.tried.len(), c.taken), (0.01, 1, 0));
        assert!(c.met(), "{}", c.summary());
        assert!(
            c.summary().contains("the default lattice holds"),
            "{}",
            c.summary()
        );
        // Far from the goal (13 %), the ladder is still climbed: the capture head's default
        // lattice misses its clip by 18 % and its 17.2 mm one holds it.
        let (_, c) = climb(0.01, (0.01, 100, 0.13), candidates(0.13, 3)).unwrap();
        assert!(c.tried.len() > 1 && c.met(), "{:?}", c.tried);
        // The goal lies past the element budget (a miss ∝ h from 10 %: 4.5 % at rung 32,
        // the last within the budget): the default is kept, after every coarse rung.
        let (h, c) = climb(0.01, (0.01, 100, 0.1), candidates(0.1, 1)).unwrap();
        assert_eq!((h, c.taken), (0.01, 0));
        assert!(!c.met(), "{:?}", c.tried);
        let rungs: Vec<i32> = c.tried.iter().map(|t| rung(t.0)).collect();
        assert_eq!(rungs, (0..=32).step_by(4).collect::<Vec<_>>());
        assert!(c.summary().contains("the default kept"), "{}", c.summary());
    }

    #[test]
    fn frames_without_motion_count_each_shape_alone() {
        let still = moving_frames(&[vec![0.0, 0.0]], 2);
        assert_eq!(still, vec![vec![1.0, 0.0], vec![0.0, 1.0]]);
        let clip = moving_frames(&[vec![0.0, 0.0], vec![0.5, 0.0]], 2);
        assert_eq!(clip, vec![vec![0.5, 0.0]]);
    }
}
