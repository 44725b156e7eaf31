//! What a caller asks of a run beyond its scene: batch limits, a progress
//! display, the adapter, the workgroup and dispatch sizes, a way to stop it.

use super::progress::Progress;
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
    /// `crate::environment::DISPATCH_LANE_STEPS`): a card with no watchdog can take
    /// longer dispatches, each loading and storing every trajectory fewer
    /// times.
    pub dispatch_lane_steps: Option<usize>,
    /// Ends the run early when requested: it then returns
    /// [`crate::Error::Stopped`], and a front end writes nothing.
    pub stop: Stop,
}
