//! What a still rig's correctives cost against a clip's frames: the still rig's shapes and
//! the clip run back to back in one process under the defaults, each from its set-up, and
//! the ratio of the time per solved shape to the time per frame (the goal: at most
//! [`CORRECTIVE_GOAL`]).

use crate::io::load::Rig;
use crate::pipeline::{self, RunOptions};
use serde::Serialize;

/// The most a solved shape may cost, in the clip's mean time per frame (dimensionless).
pub const CORRECTIVE_GOAL: f64 = 3.0;

/// One run's wall time and what it solved.
#[derive(Debug, Clone, Serialize)]
pub struct CostRun {
    /// The rig's file.
    pub rig: String,
    /// Poses run: a still rig's shapes, or a clip's frames.
    pub poses: usize,
    /// Poses solved (a still rig's shapes that compress skin; every frame of a clip).
    pub solved: usize,
    /// Wall time of the run, set-up included (s).
    pub wall_s: f64,
    /// Of it, the skin's solves summed over the poses (s; over workers, so it may exceed the
    /// wall time).
    pub skin_s: f64,
    /// Wall time per solved pose (s).
    pub per_solved_s: f64,
}

/// The still rig's run, the clip's run and the ratio of their times per solved pose.
#[derive(Debug, Clone, Serialize)]
pub struct CorrectivesCost {
    /// The still rig's shapes.
    pub still: CostRun,
    /// The clip's frames.
    pub clip: CostRun,
    /// `still.per_solved_s / clip.per_solved_s` (dimensionless).
    pub ratio: f64,
    /// [`CORRECTIVE_GOAL`].
    pub goal: f64,
    /// Threads of the pool the runs had.
    pub threads: usize,
}

/// Run the still rig `still` (every shape) and then the clip rig `clip` (every frame at
/// `fps`), both under the default scene, and compare their costs.
pub fn measure(still: &Rig, clip: &Rig, fps: f64) -> anyhow::Result<CorrectivesCost> {
    let run = |rig: &Rig, fps: f64| -> anyhow::Result<CostRun> {
        let opts = RunOptions::new(crate::scene::Scene::default()).fps(fps);
        let out = pipeline::run(rig, &opts, &|_, _, _| {})?;
        let t = &out.report.totals;
        let solved = t.frames_simulated.max(1);
        Ok(CostRun {
            rig: rig.path.display().to_string(),
            poses: out.frames.len(),
            solved: t.frames_simulated,
            wall_s: t.wall_s,
            skin_s: t.shell_ms / 1e3,
            per_solved_s: t.wall_s / solved as f64,
        })
    };
    let animated = |rig: &Rig| pipeline::plan::clip_weights(rig, fps).1;
    anyhow::ensure!(
        !animated(still),
        "{}: the rig is animated; correctives are a still rig's (give it as --clip)",
        still.path.display()
    );
    anyhow::ensure!(
        animated(clip),
        "{}: the rig has no animation to compare with",
        clip.path.display()
    );
    let still_run = run(still, fps)?;
    let clip_run = run(clip, fps)?;
    Ok(CorrectivesCost {
        ratio: still_run.per_solved_s / clip_run.per_solved_s.max(1e-12),
        still: still_run,
        clip: clip_run,
        goal: CORRECTIVE_GOAL,
        threads: rayon::current_num_threads(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// An animated rig given as the still one is refused before anything runs, naming it.
    #[test]
    fn an_animated_rig_is_not_taken_for_a_still_one() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("rigs/face.glb");
        let rig = crate::io::load::load(&path, &crate::io::LoadOptions::default()).unwrap();
        let e = measure(&rig, &rig, 30.0).unwrap_err().to_string();
        assert!(e.contains("face.glb") && e.contains("animated"), "{e}");
    }
}
