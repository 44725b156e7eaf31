//! What the sweep's kernels and the section's share on the device: the
//! dispatch sizes, the compiled pipelines (once per process), the buffers'
//! reals in either precision, read-back, and a GPU run's result and
//! timings.

use std::any::Any;
use std::sync::{mpsc, Mutex};
use std::time::Duration;

use super::context::Gpu;
use super::shader::{Kernel, Variant};
use crate::backend::options::RunOptions;
use crate::error::{Error, Result};
use crate::method::LaneResult;
use crate::scene::Precision;

/// Lane-steps (RK4 steps of one trajectory) per integrate dispatch: small
/// enough that no dispatch trips a desktop driver's watchdog (~2 s: 6.7e7
/// lane-steps take 2 ms at the 3e10 per second sought on an H100, 0.1 s on a
/// GPU 50 times slower, 0.15 s on lavapipe), large enough that a dispatch's
/// fixed cost (its launch, every trajectory's state loaded and stored) stays
/// small: with a smaller budget a sweep of 262 144 values (1.3 million
/// trajectories) took 3 steps per dispatch, and lavapipe ran it seven times
/// slower per lane-step than 4 096 values (this budget's throughput:
/// docs/BENCHMARKS.md, "Throughput against sweep size").
pub const DISPATCH_LANE_STEPS: usize = 1 << 26;

/// How many times shorter the dispatches of a batch are made when the
/// adapter cut its loops short (`SOFTWARE_WALL_CHUNK` in the sweep).
pub(super) const TRUNCATION_RETRY: usize = 8;

/// Invocations per workgroup unless the run asks otherwise
/// (docs/BENCHMARKS-GPU.md, "What lavapipe runs", and the H100's workgroup
/// table under "NVIDIA H100 and H200").
///
/// On lavapipe a lane chattering against the wall once changed the seven
/// beside it in its SIMD group of 8: they share the adapter's loop budget
/// (see `SOFTWARE_WALL_CHUNK`), which the chattering lane used up. Such a
/// dispatch is now detected and redone; tests/gpu.rs holds lanes apart
/// (`a_faulty_or_chattering_lane_touches_no_other_lane`) and compares size
/// 1, where no lane shares a SIMD group, with this size bit for bit on
/// chaotic, grazing, sticking and overflowing lanes.
pub const DEFAULT_WORKGROUP: u32 = 64;

/// How a dispatch's invocations are laid out in workgroups.
#[derive(Clone, Copy, Debug)]
pub struct Dispatch {
    /// Invocations per workgroup.
    pub workgroup: u32,
    /// Workgroups per row at most: the device's limit per dimension, or
    /// fewer where the run asks.
    pub width: u32,
    /// RK4 lane-steps an integrate dispatch takes at most:
    /// [`DISPATCH_LANE_STEPS`] unless the run asks otherwise.
    pub lane_steps: usize,
}

impl Dispatch {
    pub fn new(gpu: &Gpu, options: &RunOptions) -> Self {
        let device = gpu.limits.max_compute_workgroups_per_dimension;
        Dispatch {
            workgroup: options.workgroup_size.unwrap_or(DEFAULT_WORKGROUP),
            width: options
                .workgroups_per_row
                .map_or(device, |w| w.clamp(1, device)),
            lane_steps: options
                .dispatch_lane_steps
                .unwrap_or(DISPATCH_LANE_STEPS)
                .max(1),
        }
    }

    /// The workgroups (x, y) of a dispatch of `invocations`: one row when
    /// they fit in `width` workgroups, else rows of `width`, the last one
    /// partly idle (the kernels number invocations across rows:
    /// shaders/shared/dispatch.wgsl). One row holds 4.2 million invocations
    /// on most devices, 840 000 lanes of five trajectories: a million-lane
    /// map would otherwise be two batches, the device idle between them.
    pub fn grid(&self, invocations: usize) -> (u32, u32) {
        let groups = invocations.div_ceil(self.workgroup as usize);
        let x = groups.clamp(1, self.width as usize);
        (x as u32, groups.div_ceil(x) as u32)
    }

    /// The most invocations one dispatch holds: `width` rows of `width`
    /// workgroups, within the kernels' 32-bit invocation index.
    pub fn max_invocations(&self) -> usize {
        let grid = u64::from(self.width).pow(2) * u64::from(self.workgroup);
        grid.min(u64::from(u32::MAX)) as usize
    }
}

/// Where a GPU run's wall time went.
#[derive(Clone, Copy, Debug, Default)]
pub struct Timings {
    /// Buffers, pipelines (shader compilation) and uploads.
    pub setup: Duration,
    /// The transient on the GPU (no readback).
    pub transient: Duration,
    /// The averaging iterations, readback and host QR included.
    pub averaging: Duration,
    /// Host idle, waiting for the GPU to finish a streamed chunk.
    pub gpu_wait: Duration,
    /// Mapping and copying out the streamed chunks.
    pub readback: Duration,
    /// Host QR accumulation (overlapping GPU work).
    pub host_qr: Duration,
    /// Device time of the compute passes (transient and averaging), from
    /// timestamp queries; `None` where the adapter has none.
    pub gpu_busy: Option<Duration>,
}

impl Timings {
    pub(crate) fn add(&mut self, other: &Timings) {
        self.setup += other.setup;
        self.transient += other.transient;
        self.averaging += other.averaging;
        self.gpu_wait += other.gpu_wait;
        self.readback += other.readback;
        self.host_qr += other.host_qr;
        self.gpu_busy = match (self.gpu_busy, other.gpu_busy) {
            (Some(a), Some(b)) => Some(a + b),
            (a, b) => a.or(b),
        };
    }
}

/// The result of one device batch.
pub struct GpuRun {
    pub lanes: Vec<LaneResult>,
    pub timings: Timings,
    /// RK4 steps per integrate dispatch in the averaging phase.
    pub chunk_steps: usize,
    /// Tries redone with shorter dispatches because the adapter cut a
    /// dispatch's loops short (see `SOFTWARE_WALL_CHUNK`).
    pub retries: usize,
    /// Device memory of the batch's buffers per lane.
    pub bytes_per_lane: u64,
}

/// What `make` compiles for kernel `source` at `workgroup` invocations on
/// `gpu`, compiled once in a process: a benchmark, a test binary or a
/// program running many sweeps would otherwise compile the same kernels for
/// every run (lavapipe takes 350 ms for the seed's wall kernel, NVIDIA's
/// driver on an H100 0.57 s before its disk cache has it). Compiled outside
/// the lock, so that runs of other kernels on other threads do not wait;
/// two runs of a new kernel at once both compile it, and the first kept is
/// used after.
pub(super) fn compiled_once<T: Clone + Send + 'static>(
    gpu: &Gpu,
    source: String,
    workgroup: u32,
    make: impl FnOnce() -> T,
) -> T {
    type Key = (usize, &'static str, String, u32);
    static COMPILED: Mutex<Vec<(Key, Box<dyn Any + Send>)>> = Mutex::new(Vec::new());
    let key = (gpu.id, std::any::type_name::<T>(), source, workgroup);
    let lock = || {
        COMPILED
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner())
    };
    let kept = |compiled: &[(Key, Box<dyn Any + Send>)]| {
        compiled
            .iter()
            .find(|(k, _)| *k == key)
            .and_then(|(_, value)| value.downcast_ref::<T>().cloned())
    };
    if let Some(value) = kept(&lock()) {
        return value;
    }
    let value = make();
    let mut compiled = lock();
    if let Some(first) = kept(&compiled) {
        return first;
    }
    compiled.push((key, Box::new(value.clone())));
    value
}

/// The compute pipeline of one kernel of `variant` over bind group
/// `layout`, with `workgroup` invocations per workgroup.
pub(super) fn compute_pipeline(
    gpu: &Gpu,
    layout: &wgpu::BindGroupLayout,
    entries: &[wgpu::BindGroupLayoutEntry],
    variant: &Variant,
    kernel: Kernel,
    workgroup: u32,
) -> wgpu::ComputePipeline {
    gpu.compute_pipeline(
        &variant.name(),
        layout,
        entries,
        &variant.source(kernel),
        &[("WORKGROUP_SIZE", f64::from(workgroup))],
        variant.precision,
    )
}

/// Bytes per real in `precision`.
pub(super) fn real_size(precision: Precision) -> u64 {
    match precision {
        Precision::F64 => 8,
        Precision::F32 => 4,
    }
}

/// Reals in the precision of the variant, as bytes.
pub(super) fn real_bytes(values: &[f64], precision: Precision) -> Vec<u8> {
    match precision {
        Precision::F64 => bytemuck::cast_slice(values).to_vec(),
        Precision::F32 => {
            let narrow: Vec<f32> = values.iter().map(|&v| v as f32).collect();
            bytemuck::cast_slice(&narrow).to_vec()
        }
    }
}

pub(super) fn reals_from(bytes: &[u8], precision: Precision) -> Vec<f64> {
    match precision {
        Precision::F64 => bytemuck::pod_collect_to_vec::<u8, f64>(bytes),
        Precision::F32 => bytemuck::pod_collect_to_vec::<u8, f32>(bytes)
            .into_iter()
            .map(f64::from)
            .collect(),
    }
}

pub(super) fn gpu_error(reason: String) -> Error {
    Error::Backend {
        backend: "gpu".into(),
        reason,
    }
}

/// Maps a small buffer whose copy has finished and reads it through `read`.
pub(super) fn read_back<T>(
    device: &wgpu::Device,
    buffer: &wgpu::Buffer,
    read: impl FnOnce(&[u8]) -> T,
) -> Result<T> {
    let (sender, receiver) = mpsc::channel();
    buffer.map_async(wgpu::MapMode::Read, .., move |result| {
        let _ = sender.send(result);
    });
    device
        .poll(wgpu::PollType::wait_indefinitely())
        .map_err(|e| gpu_error(format!("the device stopped responding: {e}")))?;
    receiver
        .recv()
        .map_err(|_| gpu_error("readback was cancelled".into()))?
        .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
    let value = {
        let view = buffer
            .get_mapped_range(..)
            .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
        read(&view)
    };
    buffer.unmap();
    Ok(value)
}

/// Blocks until the submission `index` has finished on the device.
pub(super) fn wait_for(device: &wgpu::Device, index: wgpu::SubmissionIndex) -> Result<()> {
    device
        .poll(wgpu::PollType::Wait {
            submission_index: Some(index),
            timeout: None,
        })
        .map(|_| ())
        .map_err(|e| gpu_error(format!("the device stopped responding: {e}")))
}
