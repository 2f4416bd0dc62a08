//! What a run did, frame by frame and stage by stage: the content of `REPORT.json`.

use serde::Serialize;

/// A stage of a run's set-up and frames, in the order they run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Stage {
    /// Reading the rig: the face chosen and the clip.
    Load,
    /// Welding the face's vertices that share a position into one surface.
    Weld,
    /// Choosing the skin that can wrinkle (the rest rides on the interior).
    Select,
    /// Finding the poses that leave the skin's model (folds, crossings, collapsed triangles).
    Outside,
    /// Refining the skin to resolve the critical wavelength.
    Refine,
    /// Building the volumetric lattice of the interior.
    Lattice,
    /// The low-frequency clusters that tie the skin to the interior.
    Clusters,
    /// Making the muscles of the interior from the rig's shapes.
    Muscles,
    /// Fitting the muscle activations to each frame (a QP).
    Fit,
    /// The interior's step (backward Euler or quasi-static).
    Interior,
    /// The skin's thin-shell statics.
    Shell,
}

impl Stage {
    /// The snake_case name written to reports.
    pub fn as_str(&self) -> &'static str {
        match self {
            Stage::Load => "load",
            Stage::Weld => "weld",
            Stage::Select => "select",
            Stage::Outside => "outside",
            Stage::Refine => "refine",
            Stage::Lattice => "lattice",
            Stage::Clusters => "clusters",
            Stage::Muscles => "muscles",
            Stage::Fit => "fit",
            Stage::Interior => "interior",
            Stage::Shell => "shell",
        }
    }
}

impl std::fmt::Display for Stage {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(self.as_str())
    }
}

/// Whether a stage ran; its `why` says why (or why not).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum StageStatus {
    /// The stage ran.
    Ran,
    /// The stage was left out: the scene or the rig does not need it.
    Skipped,
    /// The stage could not run on this rig, and tracking the blended surface took its place
    /// (default muscles that cannot drive the rig).
    Tracked,
}

impl std::fmt::Display for StageStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.pad(match self {
            StageStatus::Ran => "ran",
            StageStatus::Skipped => "skipped",
            StageStatus::Tracked => "tracked",
        })
    }
}

/// Whether a stage ran, and why (or why not).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct StagePlan {
    /// The stage.
    pub stage: Stage,
    /// Whether it ran.
    pub status: StageStatus,
    /// The reason, for the user.
    pub why: String,
    /// Wall time of the stage's set-up or of the whole stage when it is not per frame (ms).
    pub ms: f64,
}

impl StagePlan {
    /// A stage that ran.
    pub fn ran(stage: Stage, why: impl Into<String>, ms: f64) -> Self {
        Self {
            stage,
            status: StageStatus::Ran,
            why: why.into(),
            ms,
        }
    }
    /// A stage that was left out.
    pub fn skipped(stage: Stage, why: impl Into<String>) -> Self {
        Self {
            stage,
            status: StageStatus::Skipped,
            why: why.into(),
            ms: 0.0,
        }
    }
    /// A stage that could not run, with tracking in its place.
    pub fn tracked(stage: Stage, why: impl Into<String>) -> Self {
        Self {
            stage,
            status: StageStatus::Tracked,
            why: why.into(),
            ms: 0.0,
        }
    }
    /// Whether the stage ran.
    pub fn is_ran(&self) -> bool {
        self.status == StageStatus::Ran
    }
}

/// One stage's numerical outcome in one frame.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct StageRecord {
    /// How the stage's solve ended (for the fit: its last QP's outcome).
    pub status: crate::solver::SolveStatus,
    /// Fit: why tracking drove this muscle-driven frame instead of the muscles, when it did.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracked: Option<Tracked>,
    /// Newton (or interior-point) iterations.
    pub iterations: usize,
    /// Final residual: N for the shell and the interior, m (RMS surface distance) for the fit.
    pub residual: f64,
    /// Wall time (ms).
    pub ms: f64,
    /// Interior: halvings of a sub-step that did not converge (each retries it as two half
    /// steps), summed over the frame.
    #[serde(skip_serializing_if = "is_zero")]
    pub halvings: usize,
    /// Skin: the equal load steps a solve that did not converge directly was redone in (0
    /// when it converged directly).
    #[serde(skip_serializing_if = "is_zero")]
    pub load_steps: usize,
    /// Skin: factorisations of the whole skin's KKT matrix.
    #[serde(skip_serializing_if = "is_zero")]
    pub factorizations: usize,
    /// Skin: factorisations of patch blocks (`solver.skin_solver = "patches"`).
    #[serde(skip_serializing_if = "is_zero")]
    pub patch_factorizations: usize,
    /// Skin: solves with a factor (GMRES iterations).
    #[serde(skip_serializing_if = "is_zero")]
    pub linear_solves: usize,
    /// Skin: where the wall time went (ms), when the stage solved anything.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub time: Option<SolveTime>,
    /// Skin: vertices pinned to the interior in this frame because the solved skin passed
    /// through itself there (that skin is outside the model and follows the blend shape).
    #[serde(skip_serializing_if = "is_zero")]
    pub crossing_pins: usize,
}

impl StageRecord {
    /// Fold a later solve of the same stage in the same frame into this record: counts and
    /// times add up; the status and residual are the later solve's.
    pub fn then(&mut self, later: StageRecord) {
        self.iterations += later.iterations;
        self.ms += later.ms;
        self.halvings += later.halvings;
        self.load_steps += later.load_steps;
        self.factorizations += later.factorizations;
        self.patch_factorizations += later.patch_factorizations;
        self.linear_solves += later.linear_solves;
        self.crossing_pins += later.crossing_pins;
        self.time = match (self.time, later.time) {
            (Some(mut a), Some(b)) => {
                a.add(&b);
                Some(a)
            }
            (a, b) => a.or(b),
        };
        self.status = later.status;
        self.residual = later.residual;
        self.tracked = later.tracked.or(self.tracked.take());
    }
}

/// Where a skin solve's wall time went (ms): the rest of `ms` is the solve's own bookkeeping
/// and the self-intersection check.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct SolveTime {
    /// Hessian and KKT assembly.
    pub assembly_ms: f64,
    /// Symbolic analysis (ordering) of the KKT pattern.
    pub symbolic_ms: f64,
    /// Numeric factorisations, the whole skin's and the patches'.
    pub factor_ms: f64,
    /// Solves with the factors (GMRES).
    pub solve_ms: f64,
    /// Energy and gradient evaluations of the line search.
    pub line_search_ms: f64,
}

impl SolveTime {
    /// Add another solve's times.
    pub fn add(&mut self, o: &SolveTime) {
        self.assembly_ms += o.assembly_ms;
        self.symbolic_ms += o.symbolic_ms;
        self.factor_ms += o.factor_ms;
        self.solve_ms += o.solve_ms;
        self.line_search_ms += o.line_search_ms;
    }
}

fn is_zero(n: &usize) -> bool {
    *n == 0
}

/// One frame of the report.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FrameRecord {
    /// Frame index in the clip.
    pub frame: usize,
    /// Clip time (s).
    pub time_s: f64,
    /// Activation fit, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fit: Option<StageRecord>,
    /// Interior step, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub interior: Option<StageRecord>,
    /// Skin statics, when it ran.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub shell: Option<StageRecord>,
    /// Largest wrinkle depth: distance of the skin from the smooth embedded surface (m).
    pub wrinkle_depth_max_m: f64,
    /// How far the interior is from the artist's shape: RMS over the surface's vertices of
    /// the embedded surface B q from the blend-shape target (m). It is what the driver
    /// (tracking or muscles) leaves undone against the skin's resistance, plus the lattice's
    /// projection residual; the default export adds the wrinkles to the target, so this miss
    /// is not in it, but the wrinkles form at the interior's compression, not the target's.
    pub shape_miss_m: f64,
    /// RMS over the surface's vertices of the blend-shape target's displacement from rest
    /// (m): the scale of [`Self::shape_miss_m`].
    pub shape_motion_m: f64,
    /// The angle the jaw's bone nodes stand at about its hinge after the frame (degrees,
    /// measured on the interior), when muscles turn a jaw bone.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jaw_deg: Option<f64>,
    /// Why the frame was not simulated, when it was not (its surface is the blend shape).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub not_simulated: Option<NotSimulated>,
    /// Exported vertices whose wrinkles were taken out (in part) because the exported
    /// surface passed through itself there and the blend shape does not.
    #[serde(skip_serializing_if = "is_zero")]
    pub crossing_cleared: usize,
}

/// Why a frame (a still rig's shape) was not simulated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum NotSimulated {
    /// The shape compresses no skin in the model past the wrinkling threshold: it cannot
    /// wrinkle, and gets no corrective.
    CompressesNothing,
}

/// Why tracking drove a muscle-driven frame, and the detail for the user.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Tracked {
    /// What failed.
    pub because: TrackedBecause,
    /// The failed solve's outcome or error, for the user.
    pub detail: String,
}

/// What made tracking drive a muscle-driven frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum TrackedBecause {
    /// The activation fit failed (its QP left no answer, or the target is not finite).
    FitFailed,
    /// The muscle-driven interior did not converge.
    InteriorNotConverged,
    /// The skin on the muscle-driven interior did not converge.
    SkinNotConverged,
    /// The muscle-driven frame failed with an error.
    FrameFailed,
}

/// Totals over the run.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct Totals {
    /// Frames simulated (including a replayed prefix).
    pub frames_simulated: usize,
    /// Frames written.
    pub frames_written: usize,
    /// Frames whose shell or interior did not converge.
    pub frames_not_converged: usize,
    /// Muscle-driven runs: frames that tracking drove instead (the fit failed, or the
    /// muscle-driven frame did not converge and was redone; see `per_frame[].fit.tracked`).
    pub frames_tracked: usize,
    /// Milliseconds per stage summed over frames.
    pub fit_ms: f64,
    /// Interior milliseconds.
    pub interior_ms: f64,
    /// Shell milliseconds.
    pub shell_ms: f64,
    /// Export milliseconds.
    pub export_ms: f64,
    /// Skin factorisations of the whole KKT matrix, summed over frames.
    pub skin_factorizations: usize,
    /// Skin factorisations of patch blocks, summed over frames.
    pub skin_patch_factorizations: usize,
    /// Skin Newton iterations, summed over frames.
    pub skin_iterations: usize,
    /// Where the skin's time went, summed over frames (ms).
    pub skin_time: SolveTime,
    /// Wall time of the whole run (s).
    pub wall_s: f64,
}

impl Totals {
    /// Count a simulated frame: its stages' milliseconds, and whether the interior or the
    /// shell did not converge (the fit's QP status is reported per frame only).
    pub fn add(&mut self, frame: &FrameRecord) {
        let unconverged =
            |r: &Option<StageRecord>| r.as_ref().is_some_and(|r| !r.status.is_converged());
        if unconverged(&frame.interior) || unconverged(&frame.shell) {
            self.frames_not_converged += 1;
        }
        let tracked = |r: &StageRecord| r.tracked.is_some();
        self.frames_tracked += usize::from(frame.fit.as_ref().is_some_and(tracked));
        self.frames_simulated += 1;
        let ms = |r: &Option<StageRecord>| r.as_ref().map_or(0.0, |r| r.ms);
        self.fit_ms += ms(&frame.fit);
        self.interior_ms += ms(&frame.interior);
        self.shell_ms += ms(&frame.shell);
        if let Some(s) = &frame.shell {
            self.skin_factorizations += s.factorizations;
            self.skin_patch_factorizations += s.patch_factorizations;
            self.skin_iterations += s.iterations;
            if let Some(t) = &s.time {
                self.skin_time.add(t);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame's second coupling pass folds into its record: counts and times add up, the
    /// status and residual are the last pass's.
    #[test]
    fn a_later_pass_folds_into_the_frame_record() {
        let time = |ms: f64| SolveTime {
            assembly_ms: ms,
            factor_ms: 2.0 * ms,
            ..Default::default()
        };
        let mut first = StageRecord {
            status: crate::solver::SolveStatus::IterationLimit,
            iterations: 3,
            residual: 1.0,
            ms: 10.0,
            factorizations: 1,
            linear_solves: 4,
            time: Some(time(1.0)),
            ..Default::default()
        };
        first.then(StageRecord {
            status: crate::solver::SolveStatus::Converged,
            iterations: 2,
            residual: 1e-6,
            ms: 5.0,
            load_steps: 2,
            linear_solves: 3,
            time: Some(time(0.5)),
            ..Default::default()
        });
        assert_eq!(first.status, crate::solver::SolveStatus::Converged);
        assert_eq!((first.iterations, first.factorizations), (5, 1));
        assert_eq!((first.linear_solves, first.load_steps), (7, 2));
        assert_eq!((first.ms, first.residual), (15.0, 1e-6));
        assert_eq!(first.time, Some(time(1.5)));
        // A pass that solved nothing keeps the earlier times.
        first.then(StageRecord::default());
        assert_eq!(first.time, Some(time(1.5)));
    }
}
