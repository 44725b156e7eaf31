//! A scene run, in one place: the backend chosen and opened once
//! (`choice`, [`Runner`]), the lanes run in batches bounded by memory and
//! by what one device batch holds, each batch finished by the host (on
//! the GPU, `validation`: lanes recomputed and validated on the CPU path;
//! then `checks`: the statuses decided over a finished lane) into a
//! [`Report`], the batches summed into a [`Summary`], and with
//! `[attractors]` the continuation passes (`continuation`); with
//! `[orbits]`, the periodic orbits' branches traced after them (`orbits`).

mod checks;
mod choice;
pub mod continuation;
pub mod orbits;
pub mod report;
mod runner;
pub mod validation;

pub use checks::{error_tolerance, sum_rule_tolerance, SHORT_AVERAGE};
pub use report::{GpuReport, Report, Summary};
pub use runner::Runner;
pub use validation::{validation_difference, validation_tolerance, Validation};

use crate::attractor::Attractors;
use crate::backend::RunOptions;
use crate::error::Result;
use crate::scene::Scene;

/// Runs a whole sweep on the backend the scene asks for.
pub fn run(scene: &Scene) -> Result<Report> {
    run_with(scene, &RunOptions::default())
}

/// [`run`] with options that are not part of the scene.
pub fn run_with(scene: &Scene, options: &RunOptions) -> Result<Report> {
    let runner = Runner::new(scene, options)?;
    runner.progress().start(runner.work(scene));
    runner.run(scene)
}

/// Runs a whole sweep streamed: its lanes in batches of at most
/// `batch_lanes`, each handed to `sink` (with the scene restricted to it,
/// see `Scene::batch`) and dropped, so that the results held at once stay
/// bounded; the backend is chosen and opened once, and every batch runs
/// with the whole run's plan. With `[attractors]`, each value's lanes are
/// told apart into attractors as they come, the continuation passes follow
/// (their batches to `sink` too), and the attractors, matched into
/// branches, come back with the summary.
pub fn run_streaming(
    scene: &Scene,
    options: &RunOptions,
    batch_lanes: usize,
    sink: impl FnMut(&Scene, &Report) -> Result<()>,
) -> Result<(Summary, Option<Attractors>)> {
    let runner = Runner::new(scene, options)?;
    runner.progress().start(runner.work(scene));
    let mut summary = None;
    let attractors = if scene.sweep.starts.is_some() {
        let found = continuation::attractors(&runner, scene, batch_lanes, &mut summary, sink)?;
        Some(found)
    } else {
        runner.stream(scene, batch_lanes, &mut summary, sink)?;
        None
    };
    Ok((summary.expect("a scene has at least one lane"), attractors))
}
