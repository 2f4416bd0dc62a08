//! The `skin` step: the thin shell solved quasi-statically on the interior's new state,
//! H x = H B q (its clusters follow the lattice at low frequency; wrinkles are what they
//! leave free), from the last frame's skin.

use crate::coupling::embedded::EmbeddedShell;
use crate::pipeline::record::StageRecord;
use std::time::Instant;

/// Solve the skin for node positions `q` (flat, m) and record the statics' outcome.
pub fn solve_skin(skin: &mut EmbeddedShell, q: &[f64]) -> anyhow::Result<StageRecord> {
    let t = Instant::now();
    let rep = skin.solve(q)?;
    Ok(StageRecord {
        status: rep.status.as_str().into(),
        iterations: rep.iterations,
        residual: rep.residual,
        ms: t.elapsed().as_secs_f64() * 1e3,
        halvings: 0,
        load_steps: if rep.increments > 1 {
            rep.increments
        } else {
            0
        },
    })
}
