//! The skin's local solver (`solver.skin_solver = "local"`, the default: Newton directions by
//! GMRES with the lagged global factor and fresh factors of only the patches whose Hessian
//! changed) against the global reference on the same selected skin: the local run's states
//! pass the reference's own residual test, the wrinkles agree, and it factorises less.

use furrow::pipeline::{self, RunOptions};
use furrow::scene::Scene;
use furrow::studies::locality::compare_solvers;
use furrow::studies::tradeoff::{sheet_rig, SheetRig};

fn options(solver: &str) -> RunOptions {
    let mut scene = Scene::default();
    scene.solver.skin_solver = Some(solver.into());
    RunOptions {
        scene,
        scene_path: None,
        fps: 30.0,
        frames: None,
    }
}

/// The sheet compressed on its left half and stretched on its right (10 cm, 15 %).
fn sheet() -> furrow::io::load::Rig {
    sheet_rig(&SheetRig::default()).unwrap()
}

/// Both solvers converge every frame to the same residual test; the local one makes fewer
/// factorisations of the whole skin; the wrinkles agree to a small fraction of their depth
/// (each run solves to the tolerance, so they differ by what the tolerance allows), and the
/// phase-free amplitude per 2λ region within 10 %.
#[test]
fn local_and_global_skin_solves_agree_and_the_local_one_factorises_less() {
    let rig = sheet();
    let c = compare_solvers(&rig, &options("local").clone()).unwrap();
    eprintln!("{}", serde_json::to_string_pretty(&c).unwrap());
    let [global, local] = [&c.runs[0], &c.runs[1]];
    assert_eq!(global.solver, "global");
    assert_eq!(local.solver, "local");
    assert_eq!(global.frames_not_converged, 0, "{global:?}");
    assert_eq!(local.frames_not_converged, 0, "{local:?}");
    assert!(
        local.factorizations < global.factorizations,
        "local {} against global {} factorisations",
        local.factorizations,
        global.factorizations
    );
    assert!(
        c.max_depth_m > 1e-4,
        "the sheet wrinkles: {}",
        c.max_depth_m
    );
    assert!(
        c.max_difference_m < 0.01 * c.max_depth_m,
        "the runs differ by {} m of {} m",
        c.max_difference_m,
        c.max_depth_m
    );
    assert!(c.amplitude_error < 0.1, "{}", c.amplitude_error);
}

/// Every frame's final skin state of the local run, handed to the global reference solver,
/// is already converged there: it passes the reference's own residual test.
#[test]
fn the_local_solution_passes_the_global_residual_test() {
    let rig = sheet();
    let out = pipeline::run(&rig, &options("local"), &|_, _, _| {}).unwrap();
    let checked = furrow::studies::locality::check_with_global(&rig, &options("local")).unwrap();
    assert_eq!(checked.frames, out.frames.len());
    assert_eq!(
        checked.failed, 0,
        "{} of {} frames fail the reference's residual test (worst {} N against {} N)",
        checked.failed, checked.frames, checked.worst_residual, checked.tolerance
    );
}

/// Once the shape is held, the skin's patches stop changing: the last frames of a held clip
/// factorise nothing, neither the whole skin nor any patch.
#[test]
fn held_frames_refactorise_no_patch() {
    let spec = SheetRig {
        hold: 0.3,
        ..SheetRig::default()
    };
    let rig = sheet_rig(&spec).unwrap();
    let out = pipeline::run(&rig, &options("local"), &|_, _, _| {}).unwrap();
    let frames = &out.report.per_frame;
    let held = &frames[frames.len() - 4..];
    for f in held {
        let s = f.shell.as_ref().unwrap();
        assert_eq!(s.status, "converged");
        assert_eq!(
            (s.factorizations, s.patch_factorizations),
            (0, 0),
            "frame {}: {s:?}",
            f.frame
        );
    }
}
