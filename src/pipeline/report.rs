//! `REPORT.json`: what a run did, assembled from the set-up's stage records, the per-frame
//! records and what the set-up and the export found.

use super::record::{FrameRecord, Stage, StagePlan, Totals};
use serde::Serialize;

/// `REPORT.json`.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RunReport {
    /// furrow's version.
    pub furrow: String,
    /// Input rig.
    pub rig: String,
    /// Scene file, when one was given.
    pub scene: Option<String>,
    /// Face (skin) mesh name.
    pub face: String,
    /// The scale the rig was simulated at (metres per file unit), the face's size in file
    /// units and why; lengths in this report are simulated metres, the exported geometry is
    /// in the file's units.
    pub rig_scale: crate::io::units::RigScale,
    /// Frames per second.
    pub fps: f64,
    /// Frames written [start, end).
    pub frames: [usize; 2],
    /// Frames simulated from rest before the first written one (`--preroll`); absent when
    /// the clip's whole history was simulated.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub preroll: Option<usize>,
    /// Materials used (SI).
    pub materials: serde_json::Value,
    /// Critical wavelength λ (m) and cluster width σ = λ/π (m).
    pub wavelength_m: f64,
    /// Cluster width σ (m).
    pub sigma_m: f64,
    /// Sizes: skin vertices/triangles, lattice elements/nodes, clusters, muscles.
    pub sizes: serde_json::Value,
    /// Every stage, ran or skipped, with the reason.
    pub stages: Vec<StagePlan>,
    /// Per frame.
    pub per_frame: Vec<FrameRecord>,
    /// Totals.
    pub totals: Totals,
    /// Warnings said to the user.
    pub warnings: Vec<String>,
    /// How well each generated muscle makes its shape (absent without generated muscles).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub muscles: Vec<super::setup::muscles::MuscleMade>,
    /// The jaw's hinge fitted from the shape that opens it (`jawOpen`, `jaw_open`), when the
    /// rig has one: axis, pivot (m), angle at weight 1 and how rigidly the shape turns.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub jaw: Option<crate::muscle::jaw::Hinge>,
    /// The written file's form, its wrinkle targets and how well they reproduce the frames
    /// (filled by the export; absent for the frame-sequence form).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub export: Option<super::layer::LayerReport>,
    /// The face mesh's primitives: which are skin and which ride along unchanged, and why
    /// (absent for a face of one primitive).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub face_parts: Option<crate::io::parts::FaceParts>,
    /// The poses that leave the skin's model (folds, crossings, collapsed triangles): per
    /// pose, the area that followed the blend shape and why (absent when none does).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub out_of_model: Option<super::setup::outside::OutOfModel>,
}

impl RunReport {
    /// The record of the set-up stage `stage`, if planned.
    pub fn stage(&self, stage: Stage) -> Option<&StagePlan> {
        self.stages.iter().find(|s| s.stage == stage)
    }
}
