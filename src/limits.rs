//! What one process takes on: the lanes a sweep may have, the RK4
//! lane-steps one process may run, and the memory the sweep's values may
//! hold, checked from the scene file's counts before any value is generated
//! (`scene::resolve`), so that a sweep too large is refused at once, naming
//! the keys that make it large and how to split it.

use crate::error::{Error, Result};

/// Lanes of one sweep: past this even checking every value takes minutes
/// (split the sweep into several scenes).
pub const MAX_SWEEP_LANES: f64 = 1e10;
/// RK4 lane-steps (trajectory-steps: the reference's and every copy's) one
/// process may take on: about 9 hours at the 3e10 per second sought on an
/// H100, months on a workstation's CPU. Larger runs are split with
/// `--shard`.
pub const MAX_LANE_STEPS: f64 = 1e15;

/// The memory this machine can give, in bytes (`MemAvailable` of
/// /proc/meminfo), where it can be told.
pub fn available_memory() -> Option<f64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemAvailable:"))?;
    let kib: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib * 1024.0)
}

/// "1.5 GB"-style sizes for messages.
pub fn bytes(b: f64) -> String {
    match b {
        b if b >= 1e12 => format!("{:.1} TB", b / 1e12),
        b if b >= 1e9 => format!("{:.1} GB", b / 1e9),
        b if b >= 1e6 => format!("{:.1} MB", b / 1e6),
        b => format!("{:.0} kB", b / 1e3),
    }
}

/// The size of a sweep as the scene file gives it, checked before its
/// values are generated: the lanes must be countable, and the values and
/// one lane's kept points must fit in memory. `counts` are the values per
/// axis with their keys; `max_period` is `attractors.max_period` when the
/// scene gives it.
pub fn check_sweep(
    counts: &[(String, usize)],
    dimension: usize,
    bifurcation_points: usize,
    max_period: Option<usize>,
    lane_steps_per_lane: f64,
    shards: Option<usize>,
) -> Result<()> {
    let keys = || {
        counts
            .iter()
            .map(|(k, _)| k.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let lanes: f64 = counts.iter().map(|(_, n)| *n as f64).product();
    if lanes > MAX_SWEEP_LANES {
        return Err(Error::TooLarge {
            keys: keys(),
            reason: format!(
                "{lanes:.3e} lanes, more than one sweep may hold ({MAX_SWEEP_LANES:.0e}): split it into several scenes (over ranges of the parameter)"
            ),
        });
    }
    // The work of this process's lanes (its shard's), at the requested steps
    // (lanes may need more).
    let run_lanes = shards.map_or(lanes, |n| (lanes / n as f64).ceil());
    let work = run_lanes * lane_steps_per_lane;
    if work > MAX_LANE_STEPS {
        // Shards split the lanes, never a lane: past the limit for one
        // value, no shard count helps.
        if lane_steps_per_lane > MAX_LANE_STEPS {
            return Err(Error::TooLarge {
                keys: "integration.iterations, integration.transient, integration.steps_per_period".into(),
                reason: format!(
                    "one sweep value alone is about {lane_steps_per_lane:.1e} RK4 lane-steps, more than one process takes on ({MAX_LANE_STEPS:.0e}), and --shard splits the values, not a value's work: lower integration.iterations or integration.transient (or integration.steps_per_period, for a flow)"
                ),
            });
        }
        // A shard takes up to ⌈lanes / n⌉ values: n must leave each shard
        // at most the values one process takes on.
        let per_process = (MAX_LANE_STEPS / lane_steps_per_lane).floor().max(1.0);
        let shards = (lanes / per_process).ceil();
        return Err(Error::TooLarge {
            keys: format!("{}, integration.iterations, integration.steps_per_period", keys()),
            reason: format!(
                "about {work:.1e} RK4 lane-steps, more than one process takes on ({MAX_LANE_STEPS:.0e}): split the run with --shard i/{shards} (or more, up to {lanes}: one value each), one process each, and `lyapsweep merge` the results"
            ),
        });
    }
    let available = available_memory();
    let values: f64 = counts.iter().map(|(_, n)| 8.0 * *n as f64).sum();
    if let Some(available) = available.filter(|&a| values > a / 2.0) {
        return Err(Error::TooLarge {
            keys: keys(),
            reason: format!(
                "the sweep's values alone take {}, more than half of the {} this machine has free: split it into several scenes",
                bytes(values),
                bytes(available)
            ),
        });
    }
    let points = 8.0 * dimension as f64 * bifurcation_points as f64;
    if let Some(available) = available.filter(|&a| points > a / 2.0) {
        return Err(Error::TooLarge {
            keys: "output.bifurcation_points".into(),
            reason: format!(
                "{bifurcation_points} points of one lane take {}, more than half of the {} this machine has free",
                bytes(points),
                bytes(available)
            ),
        });
    }
    // Each lane in work holds up to 2·max_period points for its period
    // test, and keeps as many in its result when it finds no period; a lane
    // is in work on each thread at once.
    if let Some(max_period) = max_period {
        let threads = rayon::current_num_threads() as f64;
        let orbit = 2.0 * 8.0 * dimension as f64 * 2.0 * max_period as f64 * threads;
        if let Some(available) = available.filter(|&a| orbit > a / 2.0) {
            return Err(Error::TooLarge {
                keys: "attractors.max_period".into(),
                reason: format!(
                    "the last 2·{max_period} points that each of the {threads} lanes in work holds for its period test take {}, more than half of the {} this machine has free: lower attractors.max_period",
                    bytes(orbit),
                    bytes(available)
                ),
            });
        }
    }
    Ok(())
}
