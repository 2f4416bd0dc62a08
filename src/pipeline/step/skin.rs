//! The `skin` step: the thin shell solved quasi-statically on the interior's new state,
//! H x = H B q (its clusters follow the lattice at low frequency; wrinkles are what they
//! leave free), from the last frame's skin. The skin has no contact: a solve that ends with
//! the skin through itself is redone in load steps (`solver.skin_continuation`), and one that
//! still does is recorded as `self_intersecting`, not as converged. Only the skin's own
//! crossings count, not those it inherits from the interior's embedded surface B q: where
//! the artist's lips close, the embedded lips cross each other by the interior's miss of the
//! shape, and the skin pinned to them at the slit
//! ([`crate::pipeline::setup::skin::pin_slits`]) crosses with them, though the exported
//! t + (x − B q) keeps the artist's lips apart; counting those would redo such frames by
//! tracking for nothing.

use crate::coupling::embedded::EmbeddedShell;
use crate::mesh::intersect::{first_self_intersection_beyond, self_intersections_beyond};
use crate::pipeline::record::{SolveTime, StageRecord};
use crate::solver::SolveStatus;
use std::time::Instant;

/// Solve the skin for node positions `q` (flat, m) at `loosening` times its statics'
/// tolerance (1 for a frame's result) and record the statics' outcome; `moved_unchecked`:
/// a loosened solve of the frame moved the skin since its last self-intersection check.
/// A result that still passes the skin through itself has the crossing triangles and the
/// skin within `margin` (m) of them pinned to the interior for this frame, and is solved
/// again from where it started (up to [`CROSSING_RETRIES`] times): that skin is outside the
/// model, which has no contact, and follows the blend shape.
pub fn solve_skin(
    skin: &mut EmbeddedShell,
    q: &[f64],
    (loosening, moved_unchecked): (f64, bool),
    margin: f64,
) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let start = skin.x().to_vec();
    let (mut record, mut crossing) = solve_once(skin, q, loosening, moved_unchecked)?;
    let mut retries = 0;
    while !crossing.is_empty() && retries < CROSSING_RETRIES {
        retries += 1;
        let before = skin.pinned().len();
        let pins = pins_about(&skin.shell.rest, skin.pinned(), &crossing, margin);
        record.crossing_pins += pins.len() - before;
        skin.set_pinned(&pins)?;
        skin.set_x(&start)?;
        let (again, still) = solve_once(skin, q, loosening, true)?;
        let pinned = record.crossing_pins;
        record.then(again);
        record.crossing_pins = pinned;
        crossing = still;
    }
    record.ms = t.elapsed().as_secs_f64() * 1e3;
    Ok(record)
}

/// Attempts at a frame's skin that pin more of it where it passes through itself.
pub const CROSSING_RETRIES: usize = 3;

/// `pinned` (sorted shell vertices) and every vertex of `rest` within `margin` (m) of a
/// vertex of the `crossing` triangle pairs, sorted.
fn pins_about(
    rest: &crate::mesh::TriMesh,
    pinned: &[usize],
    crossing: &[(usize, usize)],
    margin: f64,
) -> Vec<usize> {
    let mut seed = vec![false; rest.triangles.len()];
    for &(a, b) in crossing {
        seed[a] = true;
        seed[b] = true;
    }
    let grown = crate::pipeline::setup::outside::grow(rest, &seed, margin);
    let mut pins = pinned.to_vec();
    for (t, tri) in rest.triangles.iter().enumerate() {
        if grown[t] {
            pins.extend_from_slice(tri);
        }
    }
    pins.sort_unstable();
    pins.dedup();
    pins
}

/// One solve of the skin ([`solve_skin`] without the retries): its record and, for a
/// result, the pairs of shell triangles that pass through each other where B q does not.
fn solve_once(
    skin: &mut EmbeddedShell,
    q: &[f64],
    loosening: f64,
    moved_unchecked: bool,
) -> anyhow::Result<(StageRecord, Vec<(usize, usize)>)> {
    let t = Instant::now();
    // A loosened solve is not a result (its force only feeds the frame's next coupling
    // pass, whose exact solve checks where the skin ends).
    let result = loosening <= 1.0;
    // No contact in the model: an equilibrium through itself is not a result, and the solve
    // redoes it in load increments, along which the wrinkles may grow clear of each other.
    // Each check (8 ms on the demo's 19,729 triangles) keeps the state it saw.
    let (rest, bq) = (skin.shell.rest.clone(), skin.embedded_flat(q));
    let mut checked: Option<(bool, Vec<f64>)> = None;
    let mut clear = |x: &[f64]| {
        let ok = first_self_intersection_beyond(&rest, x, Some(&bq)).is_none();
        checked = Some((ok, x.to_vec()));
        ok
    };
    let rep = if result {
        skin.solve_loosened_accepting(q, loosening, &mut clear)?
    } else {
        skin.solve_loosened(q, loosening)?
    };
    let mut status = rep.status;
    // A solve that took no step left the skin where the last check saw it.
    let crossed = match checked {
        Some((ok, x)) if x == skin.x() => !ok,
        _ => {
            (rep.iterations > 0 || moved_unchecked)
                && first_self_intersection_beyond(&rest, skin.x(), Some(&bq)).is_some()
        }
    };
    let mut crossing = Vec::new();
    if result && crossed {
        status = SolveStatus::SelfIntersecting;
        crossing = self_intersections_beyond(&rest, skin.x(), Some(&bq));
    }
    let record = StageRecord {
        status,
        tracked: None,
        iterations: rep.iterations,
        residual: rep.residual,
        ms: t.elapsed().as_secs_f64() * 1e3,
        halvings: 0,
        load_steps: if rep.increments > 1 {
            rep.increments
        } else {
            0
        },
        factorizations: rep.factorizations,
        patch_factorizations: rep.patch_factorizations,
        linear_solves: rep.linear_solves,
        time: (rep.iterations > 0).then_some(SolveTime {
            assembly_ms: rep.assembly_s * 1e3,
            symbolic_ms: rep.symbolic_s * 1e3,
            factor_ms: rep.factor_s * 1e3,
            solve_ms: rep.solve_s * 1e3,
            line_search_ms: rep.line_search_s * 1e3,
        }),
        crossing_pins: 0,
    };
    Ok((record, crossing))
}
