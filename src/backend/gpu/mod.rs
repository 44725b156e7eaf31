//! The GPU ensemble backend: WGSL compute kernels through wgpu integrate the
//! reference and the perturbed trajectories of thousands of parameter values
//! at once, each lane locating its own impacts; the host reads the Jacobians
//! back in chunks and accumulates QR while the next chunk computes. A
//! Poincaré map's lanes run on their own schedule (`section`): the GPU
//! steps, the host locates crossings and builds the factors.

pub mod bindings;
pub mod context;
pub mod pipeline;
pub mod plan;
pub mod schedule;
pub mod section;
pub mod seed;
pub mod shader;
pub mod spirv;
pub mod stopwatch;
pub mod sweep;

use crate::error::Result;
use crate::method::MethodSettings;
use crate::scene::Scene;
use context::Gpu;
use pipeline::GpuRun;
use shader::Variant;

/// Runs the lanes of `scene`, one device batch (at most
/// [`max_batch_lanes`]), on `gpu`: a Poincaré section's lanes on the
/// section's schedule, a period map's in the sweep's kernels.
pub fn run(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &crate::backend::options::RunOptions,
) -> Result<GpuRun> {
    if variant.section() {
        section::run(gpu, scene, variant, settings, options)
    } else {
        sweep::run(gpu, scene, variant, settings, options)
    }
}

/// The most lanes of `scene` that one device batch holds: the device's
/// limits on one dispatch and one storage binding decide, and
/// `options.max_batch_lanes`. A run of more lanes is cut into batches by
/// the runner (`crate::driver::Runner::stream`).
pub fn max_batch_lanes(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &crate::backend::options::RunOptions,
) -> usize {
    if variant.section() {
        section::max_batch_lanes(gpu, scene, variant, settings, options)
    } else {
        sweep::max_batch_lanes(gpu, scene, variant, settings, options)
    }
}
