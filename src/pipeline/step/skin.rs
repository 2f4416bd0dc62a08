//! The `skin` step: the thin shell solved quasi-statically on the interior's new state,
//! H x = H B q (its clusters follow the lattice at low frequency; wrinkles are what they
//! leave free), from the last frame's skin. The skin has no contact: a solve that ends with
//! the skin through itself is recorded as `self_intersecting`, not as converged. Only the
//! skin's own crossings count, not those it inherits from the interior's embedded surface
//! B q: where the artist's lips close, the embedded lips cross each other by the interior's
//! miss of the shape (demo frames 157–163 and 238–245 under a 22 mm lattice's muscles), and
//! the skin pinned to them at the slit with them, though the exported t + (x − B q) keeps
//! the artist's lips apart. Judged on x itself, that clip had 52 frames redone by tracking
//! (259 s); the 21.6 mm clip with the slit's first ring pinned as well
//! ([`crate::pipeline::setup::skin::pin_slits`]) had 74 (265 s), and none with inherited
//! crossings left out (103.9 s).

use crate::coupling::embedded::EmbeddedShell;
use crate::mesh::intersect::first_self_intersection_beyond;
use crate::pipeline::record::{SolveTime, StageRecord};
use std::time::Instant;

/// Solve the skin for node positions `q` (flat, m) at `loosening` times its statics'
/// tolerance (1 for a frame's result) and record the statics' outcome; `moved_unchecked`:
/// a loosened solve of the frame moved the skin since its last self-intersection check.
pub fn solve_skin(
    skin: &mut EmbeddedShell,
    q: &[f64],
    loosening: f64,
    moved_unchecked: bool,
) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let rep = skin.solve_loosened(q, loosening)?;
    let mut status = rep.status.as_str().to_string();
    // 8 ms on the demo's 19,729 triangles. A solve that took no step left the skin where
    // the last check saw it; a loosened one is not a result (its force only feeds the
    // frame's next coupling pass, whose exact solve checks where the skin ends).
    let result = loosening <= 1.0;
    if result
        && (rep.iterations > 0 || moved_unchecked)
        && first_self_intersection_beyond(&skin.shell.rest, skin.x(), Some(&skin.embedded_flat(q)))
            .is_some()
    {
        // No contact in the model: an equilibrium through itself is not a result.
        status = "self_intersecting".into();
    }
    Ok(StageRecord {
        status,
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
    })
}
