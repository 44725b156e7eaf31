//! Continuation across the sweep's values, in passes over all values at
//! once, so that the lanes of a pass fill the backend together: pass 0 is
//! the scene's own lanes, each later pass the lanes a [`Continuation`]
//! starts from what the passes before it found, until it starts none. The
//! passes of `[attractors]` ([`attractors`]) are one; another (periodic
//! orbits followed across values) is a [`Continuation`] beside it, run by
//! the same [`passes`].

use super::report::{Report, Summary};
use super::runner::Runner;
use crate::attractor::{Attractors, Found};
use crate::error::Result;
use crate::scene::{self, Scene, Seed};

/// What a continuation takes in from each batch of lanes, and which lanes
/// it starts next.
pub trait Continuation {
    /// Takes in a batch's lanes (of the scene's own or of a pass).
    fn absorb(&mut self, batch: &Scene, report: &Report);
    /// The lanes of the next pass, from what the pass before found: none
    /// when the continuation is done.
    fn next_pass(&mut self, scene: &Scene) -> Vec<Seed>;
}

/// Runs `scene`'s lanes, then the passes `continuation` starts, on
/// `runner` in batches of at most `batch_lanes`, each batch handed to
/// `continuation` and to `sink` and added to `summary`; returns the passes
/// run after the scene's own lanes, and their lanes.
pub fn passes(
    runner: &Runner,
    scene: &Scene,
    batch_lanes: usize,
    summary: &mut Option<Summary>,
    mut sink: impl FnMut(&Scene, &Report) -> Result<()>,
    continuation: &mut impl Continuation,
) -> Result<(usize, usize)> {
    runner.stream(scene, batch_lanes, summary, |batch, report| {
        continuation.absorb(batch, report);
        sink(batch, report)
    })?;
    let (mut passes, mut continued_lanes) = (0, 0);
    loop {
        let seeds = continuation.next_pass(scene);
        if seeds.is_empty() {
            break;
        }
        continued_lanes += seeds.len();
        passes += 1;
        let pass = scene.continued(seeds);
        runner.progress().extend(runner.work(&pass));
        runner.stream(&pass, batch_lanes, summary, |batch, report| {
            continuation.absorb(batch, report);
            sink(batch, report)
        })?;
    }
    Ok((passes, continued_lanes))
}

/// The passes of `[attractors]`: each value's lanes told apart into
/// attractors as they come, each later pass starting every value from the
/// final states of the attractors new at its neighbours in the pass
/// before.
struct AttractorPasses {
    found: Found,
    /// The attractors new in the pass so far, as (grid point, index).
    frontier: Vec<(usize, usize)>,
    continuation: scene::Continuation,
}

impl Continuation for AttractorPasses {
    fn absorb(&mut self, batch: &Scene, report: &Report) {
        let new = self.found.absorb(
            batch,
            &report.lanes,
            &report.expected_sums,
            report.precision,
        );
        self.frontier.extend(new);
    }

    fn next_pass(&mut self, scene: &Scene) -> Vec<Seed> {
        let seeds = self.found.seeds(scene, &self.frontier, self.continuation);
        self.frontier.clear();
        seeds
    }
}

/// Runs `scene` (a scene with `[attractors]`) and its continuation passes
/// (see [`passes`]), and returns the attractors found, matched into
/// branches.
pub fn attractors(
    runner: &Runner,
    scene: &Scene,
    batch_lanes: usize,
    summary: &mut Option<Summary>,
    sink: impl FnMut(&Scene, &Report) -> Result<()>,
) -> Result<Attractors> {
    let starts = scene
        .sweep
        .starts
        .as_ref()
        .expect("a scene with [attractors]");
    let mut run = AttractorPasses {
        found: Found::new(scene).expect("a scene with starts"),
        frontier: Vec::new(),
        continuation: starts.continuation,
    };
    if runner.stops_early() {
        let learning = learn(runner, scene, batch_lanes)?;
        runner.set_known(learning.known());
        run.found.learn_from(&learning);
    }
    let (passes, continued_lanes) = passes(runner, scene, batch_lanes, summary, sink, &mut run)?;
    Ok(run.found.into_attractors(scene, passes, continued_lanes))
}

/// Learned starts are every this many along both states of a basin grid.
/// The learned lanes run whole, so their share (1/16) bounds what early
/// stops save; the labels do not depend on it (a start stops only on an
/// orbit learned, and runs whole where none is near), only the share of
/// starts that stop: an attractor whose basin the coarse grid misses is
/// found by its own starts run whole.
const LEARNING_STRIDE: usize = 4;

/// The attractors of `scene`'s basin grids at a coarser resolution (every
/// [`LEARNING_STRIDE`]-th start along both states, the corner (0, 0)
/// first), each lane run whole: the orbits the scene's own starts may then
/// stop early on (`attractors.early_stop`). These lanes are not the run's
/// rows: each start runs again with the others, a learned one stopping
/// early too.
fn learn(runner: &Runner, scene: &Scene, batch_lanes: usize) -> Result<Found> {
    let starts = scene.sweep.starts.as_ref().expect("a scene with starts");
    let scene::Layout::Grid { counts } = &starts.layout else {
        unreachable!("early stops are checked to come with a basin grid");
    };
    let nx = counts[0];
    let learned: Vec<usize> = (0..counts[1])
        .step_by(LEARNING_STRIDE)
        .flat_map(|j| (0..nx).step_by(LEARNING_STRIDE).map(move |i| j * nx + i))
        .collect();
    let seeds = (0..scene.sweep.points())
        .flat_map(|point| {
            learned.iter().map(move |&start| Seed {
                point,
                start,
                state: starts.states[start].clone(),
            })
        })
        .collect();
    let pass = scene.continued(seeds);
    runner.progress().extend(runner.work(&pass));
    let mut found = Found::new(scene).expect("a scene with starts");
    let mut summary = None;
    runner.stream(&pass, batch_lanes, &mut summary, |batch, report| {
        found.absorb(
            batch,
            &report.lanes,
            &report.expected_sums,
            report.precision,
        );
        Ok(())
    })?;
    Ok(found)
}
