//! The stage of a run with `[orbits]`, after the sweep and its
//! continuation passes: the periodic orbits the lanes ended on are
//! gathered batch by batch ([`OrbitStarts`]), then each branch is traced
//! once from them and from the scene's listed orbits ([`trace`]), on the
//! CPU path in f64 whatever backend ran the lanes (Newton's Jacobians and
//! the multipliers' δ ladder are the CPU method's).

use std::time::{Duration, Instant};

use super::report::Report;
use crate::backend::RunOptions;
use crate::method::lane::LaneStatus;
use crate::orbit::dispatch::tracer;
use crate::orbit::trace::{trace_all, Origin, Start, Traced};
use crate::plan::method_settings;
use crate::scene::{Backend, Precision, Scene};

/// The starts a sweep's lanes give: each periodic lane's final state, its
/// period and its orbit's points.
#[derive(Default)]
pub struct OrbitStarts {
    /// With whether the lane's status was `ok`: those are traced first.
    starts: Vec<(bool, Start)>,
}

impl OrbitStarts {
    /// Takes in a batch's lanes (of the scene's own or of a continuation
    /// pass): each lane with a period and exponents (not a failure) is a
    /// start.
    pub fn absorb(&mut self, batch: &Scene, report: &Report) {
        let dim = batch.system.dimension();
        for (j, lane) in report.lanes.iter().enumerate() {
            let Some(period) = lane.orbit_period else {
                continue;
            };
            if lane.status.is_failure() || lane.orbit.len() < dim {
                continue;
            }
            let state = lane.orbit[lane.orbit.len() - dim..].to_vec();
            let start = Start {
                parameter: batch.lane_values(j)[0],
                state,
                period,
                points: lane.orbit.clone(),
                origin: Origin::Lane(batch.sweep_lane(j)),
                onward: None,
            };
            self.starts.push((lane.status == LaneStatus::Ok, start));
        }
    }
}

/// What the stage found: every branch (those that failed at their start
/// last), and the time it took.
#[derive(Clone, Debug)]
pub struct OrbitRun {
    pub branches: Vec<Traced>,
    pub elapsed: Duration,
}

impl OrbitRun {
    /// The bifurcations located on all branches.
    pub fn bifurcations(&self) -> usize {
        self.branches.iter().map(|b| b.bifurcations.len()).sum()
    }
}

/// Traces the branches of `scene`'s `[orbits]` (none without the table):
/// the listed orbits first, then with `from_sweep` the lanes' (`ok` lanes
/// first, each in the sweep's order). A stop asked for ends the stage
/// between branches.
pub fn trace(scene: &Scene, starts: OrbitStarts, options: &RunOptions) -> Option<OrbitRun> {
    let orbits = scene.orbits.as_ref()?;
    let clock = Instant::now();
    let settings = method_settings(scene, Backend::Cpu, Precision::F64);
    let mut all: Vec<Start> = orbits
        .list
        .iter()
        .enumerate()
        .map(|(i, listed)| Start {
            parameter: listed.value,
            state: listed.state.clone(),
            period: listed.period,
            points: Vec::new(),
            origin: Origin::Listed(i),
            onward: None,
        })
        .collect();
    if orbits.from_sweep {
        let mut lanes = starts.starts;
        // Stable sort: `ok` lanes first, each group in the lanes' order.
        lanes.sort_by_key(|(ok, _)| !ok);
        all.extend(lanes.into_iter().map(|(_, s)| s));
    }
    let stop = || options.stop.requested();
    let branches = trace_all(
        tracer(scene.system),
        &scene.params,
        &settings,
        &orbits.trace,
        &all,
        &stop,
    );
    Some(OrbitRun {
        branches,
        elapsed: clock.elapsed(),
    })
}
