//! A run's plan, made from the scene once: the method's settings on each
//! path, and what the run will hold in memory and how much work it is,
//! estimated before anything is allocated, so that a run too large for the
//! machine is advised at once (naming the keys that make it large and how
//! to split it) instead of failing hours in, or with an out-of-memory
//! abort.
//!
//! A run holds its sweep values (8 bytes per value of each axis) and the
//! results of one batch of lanes: the lanes are streamed through the output
//! in batches of at most [`BATCH_BYTES`] of results (see
//! `driver::run_streaming`), so only the values and one lane's kept
//! points grow without bound (with `[attractors]`, also each value's
//! attractors, one lane's result each, and 8 bytes per lane for its branch).

use crate::limits::{available_memory, bytes};
use crate::method::{LaneResult, MethodSettings, Tangent};
use crate::scene::{Backend, Precision, Scene};
use crate::system::FlowSettings;

/// The per-lane settings a scene implies for a backend and precision.
pub fn method_settings(scene: &Scene, backend: Backend, precision: Precision) -> MethodSettings {
    let i = &scene.integration;
    let steps = if scene.system.is_flow {
        i.steps_per_period
    } else {
        1
    };
    MethodSettings {
        // The aligning iterations run with Jacobians, as the averaging
        // ones do; the lane's accumulator takes them for the frame alone.
        transient: i.transient - i.align,
        iterations: i.align + i.iterations,
        align: i.align,
        initial_state: i.initial_state.clone(),
        perturbation: scene.perturbation(),
        difference: scene.difference(),
        flow: FlowSettings {
            steps_per_period: i.steps_per_period,
            impact_location: i.impact_location,
            stop: Default::default(),
        },
        tangent: if backend == Backend::Exact {
            Tangent::Exact
        } else {
            Tangent::FiniteDifference
        },
        lyapunov: scene.lyapunov,
        bifurcation_points: scene.bifurcation_points,
        max_period: scene.sweep.max_period(),
        keep_orbit: scene.sweep.starts.is_some() || scene.orbits.is_some(),
        keep_settling: scene
            .sweep
            .starts
            .as_ref()
            .is_some_and(|s| s.basins.values > 0),
        early_stop: scene
            .sweep
            .starts
            .as_ref()
            .map_or(0, |s| s.basins.early_stop),
        keep_jacobians: false,
        // The f32 kernels compensate the state update (Kahan), so rounding
        // does not accumulate over the steps of an iteration.
        rounding_accumulates: precision == Precision::F64 && steps > 1,
        submaps: scene.integration.submaps,
        rounding_unit: precision.rounding_unit(),
    }
}

/// The CPU path's settings for lanes of a GPU run with `gpu`'s settings:
/// f64, with the steps and parts every lane of the GPU's sweep followed, so
/// that a lane the host recomputes, re-estimates or validates on the CPU
/// differs from its GPU twin by arithmetic alone.
pub fn cpu_twin(scene: &Scene, gpu: &MethodSettings) -> MethodSettings {
    let mut cpu = method_settings(scene, Backend::Cpu, Precision::F64);
    cpu.flow.steps_per_period = gpu.flow.steps_per_period;
    cpu.submaps = gpu.submaps;
    cpu.flow.stop = gpu.flow.stop.clone();
    cpu
}

/// Results held at once: a batch of lanes is at most this large.
pub const BATCH_BYTES: usize = 1 << 30;
/// Bytes of results one lane holds until its batch is written.
pub fn lane_bytes(scene: &Scene) -> usize {
    let dim = scene.system.dimension();
    // Kept with `[attractors]` or `[orbits]` alone (`MethodSettings::keep_orbit`): at
    // most 2·max_period points when the orbit has no period.
    let orbit = if scene.sweep.starts.is_some() || scene.orbits.is_some() {
        8 * dim * 2 * scene.sweep.max_period()
    } else {
        0
    };
    std::mem::size_of::<LaneResult>()
        + 8 * (dim + 1) // exponents, expected sum
        + 8 * dim * scene.bifurcation_points
        + orbit
}

/// Lanes per batch of the streamed run (all of them for most runs).
pub fn batch_lanes(scene: &Scene) -> usize {
    let budget = available_memory().map_or(BATCH_BYTES, |a| BATCH_BYTES.min((a / 4.0) as usize));
    (budget / lane_bytes(scene)).clamp(1, scene.run_lane_count().max(1))
}

/// The RK4 lane-steps of the run (of its shard).
pub fn lane_steps(scene: &Scene) -> f64 {
    let copies = if scene.lyapunov {
        scene.difference().copies(scene.system.dimension())
    } else {
        0
    };
    scene.run_lane_count() as f64
        * scene
            .integration
            .steps_per_lane(scene.system.is_flow, copies)
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
                format!(", results streamed in batches of at most {batch} lanes")
            } else {
                String::new()
            }
        )
    })
}
