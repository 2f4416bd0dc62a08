//! A still rig's shapes: each solved alone from rest, those that compress no skin not at
//! all. The shapes are independent, so workers solve them side by side, each on its own
//! copy of the state ([`State::at_rest_copy`]), the largest first, and their results are
//! put back in shape order: the same bits as one worker solving them one after another.

use super::record::{FrameRecord, NotSimulated};
use super::setup::{Model, State};
use super::step::{self, compose::Composed, Scratch, StepOptions};
use super::{Phase, Progress};
use crate::io::load::Rig;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

/// One shape's record and surfaces.
pub type Solved = (FrameRecord, Composed);

/// Solve shapes `shapes` (indices into `weights`, each a shape alone at weight 1) of the
/// still `rig` from rest with `state` and, when `extra` holds more states at rest, as many
/// more workers; `fps` times the records. Returns each shape's record and surfaces in
/// shape order; the first error any worker meets ends the run.
pub fn solve_shapes(
    rig: &Rig,
    (model, weights, fps): (&Model, &[Vec<f64>], f64),
    shapes: std::ops::Range<usize>,
    (state, mut extra): (&mut State, Vec<State>),
    options: StepOptions,
    progress: Progress,
) -> anyhow::Result<Vec<Solved>> {
    let results: Mutex<Vec<Option<Solved>>> = Mutex::new(shapes.clone().map(|_| None).collect());
    // The largest shapes first, so that no worker is left with a large one at the end.
    let share: Vec<f64> = shapes
        .clone()
        .map(|k| model.pose_maps.active_share(k))
        .collect();
    let mut order: Vec<usize> = shapes.clone().collect();
    order.sort_by(|&a, &b| {
        let of = |k: usize| share[k - shapes.start];
        of(b).total_cmp(&of(a)).then(a.cmp(&b))
    });
    let (next, done) = (AtomicUsize::new(0), AtomicUsize::new(0));
    let first_error: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let work = |state: &mut State, report: &dyn Fn(usize)| {
        let mut at_rest = true;
        loop {
            let Some(&k) = order.get(next.fetch_add(1, Ordering::Relaxed)) else {
                return;
            };
            if first_error.lock().expect("error lock").is_some() {
                return;
            }
            let solved = solve_one(rig, (model, &weights[k], fps), k, state, at_rest, options);
            at_rest = false;
            match solved {
                Ok(s) => results.lock().expect("results lock")[k - shapes.start] = Some(s),
                Err(e) => {
                    first_error.lock().expect("error lock").get_or_insert(e);
                    return;
                }
            }
            report(done.fetch_add(1, Ordering::Relaxed) + 1);
        }
    };
    let report = |d: usize| progress(Phase::Frames, shapes.start + d, shapes.end);
    if extra.is_empty() {
        work(state, &report);
    } else {
        // Each worker has a pool of one thread: the workers are the parallelism (nested
        // parallel loops on one shared pool contend; the element loops and the tree
        // factorisation give the same bits on one thread as on two). This thread reports
        // progress as the workers finish shapes.
        let pools = (0..=extra.len())
            .map(|_| rayon::ThreadPoolBuilder::new().num_threads(1).build())
            .collect::<Result<Vec<_>, _>>()?;
        let (tell, finished) = std::sync::mpsc::channel::<usize>();
        std::thread::scope(|scope| {
            let states = std::iter::once(state).chain(extra.iter_mut());
            for (worker_state, pool) in states.zip(&pools) {
                let (work, tell) = (&work, tell.clone());
                scope.spawn(move || {
                    pool.install(|| {
                        work(worker_state, &|d| {
                            let _ = tell.send(d);
                        })
                    })
                });
            }
            drop(tell);
            for d in finished {
                report(d);
            }
        });
    }
    if let Some(e) = first_error.into_inner().expect("error lock") {
        return Err(e);
    }
    Ok(results
        .into_inner()
        .expect("results lock")
        .into_iter()
        .map(|r| r.expect("every shape solved"))
        .collect())
}

/// Shape `k` (weights `w`) alone: not simulated when it compresses no skin, else solved from
/// rest (`state` put back at rest unless `at_rest`).
fn solve_one(
    rig: &Rig,
    (model, w, fps): (&Model, &[f64], f64),
    k: usize,
    state: &mut State,
    at_rest: bool,
    options: StepOptions,
) -> anyhow::Result<Solved> {
    if !model.pose_maps.solves(k) {
        let why = (fps, NotSimulated::CompressesNothing);
        return step::unsimulated_frame(rig, w, k, model, why);
    }
    if !at_rest {
        state.reset_to_rest(model);
    }
    let mut scratch = Scratch::new(model.lattice.node_count());
    step::step_frame(rig, w, k, model, state, &mut scratch, options)
}

/// Workers for `shapes` shapes to solve: one per thread of the pool, at most one per shape.
pub fn worker_count(shapes: usize) -> usize {
    rayon::current_num_threads().clamp(1, shapes.max(1))
}
