//! The GPU ensemble backend: WGSL compute kernels through wgpu integrate the
//! reference and the perturbed trajectories of thousands of parameter values
//! at once, each lane locating its own impacts; the host reads the Jacobians
//! back in chunks and accumulates QR while the next chunk computes. A
//! Poincaré map's lanes run on their own schedule (`section`): the GPU
//! steps, the host locates crossings and builds the factors.

pub mod context;
pub mod pipeline;
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

/// Runs the whole sweep on `gpu`: a Poincaré section's lanes on the
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
