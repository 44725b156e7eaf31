//! What a caller asks of a run beyond its scene: batch limits, a progress
//! display, the adapter, the workgroup and dispatch sizes, a way to stop it.

use super::progress::Progress;
use crate::error::{clip, Error, Result};
use crate::method::Stop;

/// Options of a run that are not part of a scene.
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    /// Split GPU sweeps into batches of at most this many lanes (the limits
    /// of the device split them anyway; tests use this to exercise it).
    pub max_batch_lanes: Option<usize>,
    /// Keep every iteration's Jacobian in the lane results.
    pub keep_jacobians: bool,
    /// Invocations per GPU workgroup (default [`super::gpu::pipeline::DEFAULT_WORKGROUP`]);
    /// the benchmark varies it.
    pub workgroup_size: Option<u32>,
    /// Advanced as lanes run, for a progress display.
    pub progress: Option<Progress>,
    /// Run on adapter number `device` of `lyapsweep devices` (one process
    /// per GPU of a machine, each with its shard).
    pub device: Option<usize>,
    /// RK4 steps per GPU integrate dispatch at most (default: 256 on a
    /// software adapter with stops, else a whole period); tests set it to
    /// run lavapipe as a hardware GPU runs.
    pub dispatch_steps: Option<usize>,
    /// Workgroups per row of a GPU dispatch at most (default: the device's
    /// limit per dimension); tests set it low so that a small sweep is laid
    /// out in rows of workgroups, as a million lanes are.
    pub workgroups_per_row: Option<u32>,
    /// RK4 lane-steps per GPU integrate dispatch at most (default
    /// [`super::gpu::pipeline::DISPATCH_LANE_STEPS`], or the environment's
    /// [`DISPATCH_LANE_STEPS_VARIABLE`]): a card with no watchdog can take
    /// longer dispatches, each loading and storing every trajectory fewer
    /// times.
    pub dispatch_lane_steps: Option<usize>,
    /// Ends the run early when requested: it then returns
    /// [`crate::Error::Stopped`], and a front end writes nothing.
    pub stop: Stop,
}

/// The environment variable of [`RunOptions::dispatch_lane_steps`].
pub const DISPATCH_LANE_STEPS_VARIABLE: &str = "LYAPSWEEP_DISPATCH_LANE_STEPS";

/// [`RunOptions::dispatch_lane_steps`] from the environment, when set.
pub(crate) fn dispatch_lane_steps_from_environment() -> Result<Option<usize>> {
    let text = std::env::var(DISPATCH_LANE_STEPS_VARIABLE).unwrap_or_default();
    if text.trim().is_empty() {
        return Ok(None);
    }
    match text.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(Some(n)),
        _ => Err(Error::Invalid {
            key: DISPATCH_LANE_STEPS_VARIABLE.into(),
            reason: format!(
                "\"{}\" is not a whole number of RK4 lane-steps of at least 1",
                clip(&text)
            ),
        }),
    }
}
