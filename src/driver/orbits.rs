//! The stage of a run with `[orbits]`, after the sweep and its
//! continuation passes: the periodic orbits the lanes ended on are
//! gathered batch by batch ([`OrbitStarts`]), then each branch is traced
//! once from them and from the scene's listed orbits ([`trace`]), on the
//! CPU path in f64 whatever backend ran the lanes (Newton's Jacobians and
//! the multipliers' δ ladder are the CPU method's).
//!
//! With a second swept parameter, each of its values is a row: the
//! one-parameter stage run in the first parameter at that value, from that
//! row's lanes and the orbits listed at it. The rows are traced in
//! parallel on the host's cores and written in the order of the second
//! axis's values (then the listed orbits' own values), so the files do
//! not depend on the number of threads; the branches are numbered through
//! the rows.

use std::time::{Duration, Instant};

use super::report::Report;
use crate::backend::RunOptions;
use crate::method::lane::LaneStatus;
use crate::orbit::dispatch::tracer;
use crate::orbit::trace::{switched_from, trace_all, Origin, Start, Traced};
use crate::plan::method_settings;
use crate::scene::{Backend, Precision, Scene};

/// The starts a sweep's lanes give: each periodic lane's final state, its
/// period and its orbit's points.
#[derive(Default)]
pub struct OrbitStarts {
    /// With whether the lane's status was `ok` (those are traced first)
    /// and its value of the second swept parameter, if any.
    starts: Vec<(bool, Option<f64>, Start)>,
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
            let values = batch.lane_values(j);
            let start = Start {
                parameter: values[0],
                state,
                period,
                points: lane.orbit.clone(),
                origin: Origin::Lane(batch.sweep_lane(j)),
                onward: None,
            };
            let ok = lane.status == LaneStatus::Ok;
            self.starts.push((ok, values.get(1).copied(), start));
        }
    }
}

/// What the stage found: every branch (in each row those that failed at
/// their start last), and the time it took.
#[derive(Clone, Debug)]
pub struct OrbitRun {
    pub branches: Vec<Traced>,
    /// With two swept parameters, each branch's value of the second.
    pub second: Option<Vec<f64>>,
    pub elapsed: Duration,
}

impl OrbitRun {
    /// The bifurcations located on all branches.
    pub fn bifurcations(&self) -> usize {
        self.branches.iter().map(|b| b.bifurcations.len()).sum()
    }
}

/// The starts traced at one value of the second swept parameter (`None`
/// with one swept parameter: the whole stage is one row).
struct Row {
    second: Option<f64>,
    starts: Vec<Start>,
}

/// The rows of the stage: one per value of the second axis, in its order
/// (then any value only a listed orbit names), each with its listed
/// orbits first, then with `from_sweep` its lanes (`ok` lanes first, each
/// in the sweep's order).
fn rows(scene: &Scene, starts: OrbitStarts) -> Vec<Row> {
    let Some(orbits) = scene.orbits.as_ref() else {
        return Vec::new();
    };
    let mut rows: Vec<Row> = Vec::new();
    let seconds: Vec<Option<f64>> = match &scene.sweep.second {
        Some(axis) => axis.values.iter().map(|&v| Some(v)).collect(),
        None => vec![None],
    };
    for second in seconds {
        row_of(&mut rows, second);
    }
    for (i, listed) in orbits.list.iter().enumerate() {
        let k = row_of(&mut rows, listed.second);
        rows[k].starts.push(Start {
            parameter: listed.value,
            state: listed.state.clone(),
            period: listed.period,
            points: Vec::new(),
            origin: Origin::Listed(i),
            onward: None,
        });
    }
    if orbits.from_sweep {
        let mut lanes = starts.starts;
        // Stable sort: `ok` lanes first, each group in the lanes' order.
        lanes.sort_by_key(|(ok, ..)| !ok);
        for (_, second, start) in lanes {
            let k = row_of(&mut rows, second);
            rows[k].starts.push(start);
        }
    }
    rows
}

/// The index of the row at `second` (the same value to the bit), a new
/// row at the end if none is.
fn row_of(rows: &mut Vec<Row>, second: Option<f64>) -> usize {
    let same = |r: &Row| r.second.map(f64::to_bits) == second.map(f64::to_bits);
    rows.iter().position(same).unwrap_or_else(|| {
        rows.push(Row {
            second,
            starts: Vec::new(),
        });
        rows.len() - 1
    })
}

/// Traces the branches of `scene`'s `[orbits]` (none without the table),
/// row by row ([`rows`]), the rows in parallel. A stop asked for ends the
/// stage between branches.
pub fn trace(scene: &Scene, starts: OrbitStarts, options: &RunOptions) -> Option<OrbitRun> {
    use rayon::prelude::*;
    let orbits = scene.orbits.as_ref()?;
    let clock = Instant::now();
    let settings = method_settings(scene, Backend::Cpu, Precision::F64);
    let stop = || options.stop.requested();
    let rows = rows(scene, starts);
    let traced: Vec<Vec<Traced>> = rows
        .par_iter()
        .map(|row| {
            let mut params = scene.params.clone();
            if let (Some(axis), Some(value)) = (&scene.sweep.second, row.second) {
                params.set(axis.index, value);
            }
            trace_all(
                tracer(scene.system),
                &params,
                &settings,
                &orbits.trace,
                &row.starts,
                &stop,
            )
        })
        .collect();
    let mut branches = Vec::new();
    let mut second = Vec::new();
    for (row, traced) in rows.iter().zip(traced) {
        let offset = branches.len();
        second.extend(std::iter::repeat_n(
            row.second.unwrap_or(f64::NAN),
            traced.len(),
        ));
        branches.extend(traced.into_iter().map(|b| numbered_from(b, offset)));
    }
    Some(OrbitRun {
        branches,
        second: scene.sweep.second.as_ref().map(|_| second),
        elapsed: clock.elapsed(),
    })
}

/// A row's branch as numbered through the whole stage: the row's first
/// branch is the stage's `offset`, so a switched branch names the branch
/// it came from by that number.
fn numbered_from(mut branch: Traced, offset: usize) -> Traced {
    if let (Origin::Branch(from), Some(onward)) = (branch.start.origin, &branch.start.onward) {
        if branch.ends[0] == switched_from(onward.kind, from) {
            branch.ends[0] = switched_from(onward.kind, from + offset);
        }
        branch.start.origin = Origin::Branch(from + offset);
    }
    branch
}
