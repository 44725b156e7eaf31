//! What a run will hold in memory and how much work it is, estimated from
//! the scene before anything is allocated, so that a sweep too large for
//! the machine is refused at once (naming the keys that make it large and
//! how to split it) instead of failing hours in, or with an out-of-memory
//! abort.
//!
//! A run holds its sweep values (8 bytes per value of each axis) and the
//! results of one batch of lanes: the lanes are streamed through the output
//! in batches of at most [`BATCH_BYTES`] of results (see
//! `backend::run_streaming`), so only the values and one lane's kept points
//! grow without bound.

use crate::error::{Error, Result};
use crate::method::LaneResult;
use crate::scene::{Integration, Scene, Shard};

/// Results held at once: a batch of lanes is at most this large.
pub const BATCH_BYTES: usize = 1 << 30;
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
/// axis with their keys.
pub fn check_sweep(
    counts: &[(String, usize)],
    dimension: usize,
    bifurcation_points: usize,
    lane_steps_per_lane: f64,
    shard: Option<Shard>,
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
    let run_lanes = shard.map_or(lanes, |s| (lanes / s.count as f64).ceil());
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
    Ok(())
}

/// Bytes of results one lane holds until its batch is written.
pub fn lane_bytes(scene: &Scene) -> usize {
    let dim = scene.system.dimension();
    std::mem::size_of::<LaneResult>()
        + 8 * (dim + 1) // exponents, expected sum
        + 8 * dim * scene.bifurcation_points
}

/// Lanes per batch of the streamed run (all of them for most runs).
pub fn batch_lanes(scene: &Scene) -> usize {
    let budget = available_memory().map_or(BATCH_BYTES, |a| BATCH_BYTES.min((a / 4.0) as usize));
    (budget / lane_bytes(scene)).clamp(1, scene.run_lane_count().max(1))
}

/// The RK4 trajectory-steps of one lane: the reference over the transient,
/// and with its `copies` over the aligning and averaged iterations, at the
/// requested steps (lanes may need more).
pub fn steps_per_lane(integration: &Integration, is_flow: bool, copies: usize) -> f64 {
    let steps = if is_flow {
        integration.steps_per_period as f64
    } else {
        1.0
    };
    let i = integration;
    let plain = (i.transient - i.align) as f64;
    let with_copies = (i.align + i.iterations) as f64 * (1 + copies) as f64;
    (plain + with_copies) * steps
}

/// The RK4 lane-steps of the run (of its shard).
pub fn lane_steps(scene: &Scene) -> f64 {
    let copies = if scene.lyapunov {
        scene.difference().copies(scene.system.dimension())
    } else {
        0
    };
    scene.run_lane_count() as f64 * steps_per_lane(&scene.integration, scene.system.is_flow, copies)
}

/// A line describing a run large enough that its user should see what it
/// will take (the limits were checked when the scene was read).
pub fn large_run(scene: &Scene) -> Option<String> {
    let work = lane_steps(scene);
    let lanes = scene.run_lane_count();
    let batch = batch_lanes(scene);
    let held = 8.0
        * scene
            .sweep
            .axes()
            .map(|a| a.values.len() as f64)
            .sum::<f64>()
        + (batch.min(lanes) * lane_bytes(scene)) as f64;
    (work > 1e12 || held > 1e9 || batch < lanes).then(|| {
        format!(
            "a large run: {lanes} lanes, about {work:.1e} RK4 lane-steps, {} held in memory{}",
            bytes(held),
            if batch < lanes {
                format!(", results streamed in batches of {batch} lanes")
            } else {
                String::new()
            }
        )
    })
}
