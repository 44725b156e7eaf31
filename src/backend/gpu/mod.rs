//! The GPU ensemble backend: WGSL compute kernels through wgpu integrate the
//! reference and the perturbed trajectories of thousands of parameter values
//! at once, each lane locating its own impacts; the host reads the Jacobians
//! back in chunks and accumulates QR while the next chunk computes. A
//! Poincaré map's lanes run on their own schedule (`section`): the GPU
//! steps, the host locates crossings and builds the factors.

pub mod context;
pub mod section;
pub mod shader;
pub mod spirv;
pub mod stopwatch;
pub mod sweep;
