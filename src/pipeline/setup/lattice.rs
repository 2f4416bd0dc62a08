//! The `lattice` stage: the coarse volumetric lattice of the interior, built over the welded
//! (unrefined) skin from the scene's `[interior]` settings.

use crate::lattice::Lattice;
use crate::mesh::TriMesh;
use crate::pipeline::record::{Stage, StagePlan};
use crate::scene::InteriorSection;
use anyhow::Context;
use std::time::Instant;

/// The `lattice` stage: the lattice embedding `skin` (m), with its record; `path` names the
/// rig in errors.
pub fn build_lattice(
    skin: &TriMesh,
    interior: &InteriorSection,
    path: &str,
) -> anyhow::Result<(Lattice, StagePlan)> {
    let t = Instant::now();
    let lattice = Lattice::build(skin, &interior.lattice_settings())
        .with_context(|| format!("{path}: building the lattice"))?;
    let record = record(&lattice, "", t);
    Ok((lattice, record))
}

/// The `lattice` stage's record of `lattice`, built since `start`, with `how` it was chosen
/// appended (empty for the scene's own).
fn record(lattice: &Lattice, how: &str, start: Instant) -> StagePlan {
    StagePlan::ran(
        Stage::Lattice,
        format!(
            "{} elements, {} nodes ({} bone), cell {:.1} mm{how}",
            lattice.elements.len(),
            lattice.node_count(),
            lattice.pinned_count(),
            lattice.cell_size * 1e3
        ),
        start.elapsed().as_secs_f64() * 1e3,
    )
}

/// The `lattice` stage of a run: under generated muscles (`plan.driver`) with no cell size
/// or cell count in the scene, the lattice chosen for them from the blend shapes of `face`
/// on the `welded` skin and the clip's weights ([`super::cell::choose_lattice`]), which the
/// record says; otherwise [`build_lattice`].
pub fn lattice_for_run(
    face: &crate::io::mesh::MeshInstance,
    welded: &super::weld::Welded,
    interior: &InteriorSection,
    plan: &crate::pipeline::plan::Plan,
    path: &str,
) -> anyhow::Result<(Lattice, StagePlan)> {
    let skin = &welded.mesh;
    if !plan.driver.generates_muscles()
        || interior.cell_size.is_some()
        || interior.target_cells.is_some()
        || face.targets.is_empty()
    {
        return build_lattice(skin, interior, path);
    }
    let t = Instant::now();
    let targets = super::muscles::welded_targets(face, &welded.loaded_of);
    let weights = &plan.weights;
    let (lattice, choice) = super::cell::choose_lattice(skin, &targets, weights, interior, path)?;
    let record = record(&lattice, &choice.summary(), t);
    Ok((lattice, record))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lattice::ElementOrder;
    use crate::pipeline::setup::test_support::bump_sheet;
    use crate::scene::ElementKind;

    #[test]
    fn builds_a_lattice_under_a_small_sheet_and_records_it() {
        let sheet = bump_sheet(6);
        let interior = InteriorSection {
            cell_size: Some(0.01),
            ..Default::default()
        };
        let (lattice, record) = build_lattice(&sheet, &interior, "sheet.glb").unwrap();
        assert!(record.is_ran());
        assert_eq!(record.stage, Stage::Lattice);
        assert!(!lattice.elements.is_empty());
        assert!((lattice.cell_size - 0.01).abs() < 1e-12);
        assert!(record
            .why
            .contains(&format!("{} elements", lattice.elements.len())));
        let trilinear = InteriorSection {
            elements: Some(ElementKind::Trilinear),
            ..interior
        };
        assert_eq!(trilinear.lattice_settings().order, ElementOrder::Trilinear);
    }
}
