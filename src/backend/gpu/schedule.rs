//! The skeleton both GPU schedules run on, generic over what differs
//! between a period map's (`sweep`) and a Poincaré map's (`section`):
//! their buffers, their dispatches, and what a chunk's read-back turns
//! into. The skeleton compiles the kernels once over the layout
//! `bindings` states, binds the buffers by their names there, tries the
//! batch, and redoes it with shorter dispatches while the adapter cuts
//! their loops short; the read-back ring takes a chunk's results off the
//! device while the next one computes.

use std::sync::mpsc;
use std::time::Instant;

use wgpu::util::DeviceExt;

use super::bindings::Bindings;
use super::context::Gpu;
use super::pipeline::{
    compiled_once, compute_pipeline, gpu_error, wait_for, Dispatch, GpuRun, Timings,
    TRUNCATION_RETRY,
};
use super::shader::{Kernel, Variant};
use crate::backend::options::RunOptions;
use crate::backend::progress::Progress;
use crate::error::Result;
use crate::method::LaneResult;

/// What a schedule supplies to the skeleton.
pub(super) trait Schedule {
    /// The layout its kernels run over.
    const BINDINGS: &'static Bindings;

    /// Steps per dispatch of the first try.
    fn first_chunk(&self, run: &Run) -> usize;

    /// One try of the batch, its dispatches at most `max_chunk` steps.
    fn attempt(&mut self, run: &Run, max_chunk: usize) -> Result<Attempt>;
}

/// One try of a batch.
pub(super) struct Attempt {
    /// The lanes, or `None` when the adapter cut a dispatch's loops short
    /// (the lanes are then wrong, and the batch is redone).
    pub lanes: Option<Vec<LaneResult>>,
    pub timings: Timings,
    /// Steps per dispatch the try ended at.
    pub chunk_steps: usize,
    /// Dispatches the try itself redid shorter.
    pub retries: usize,
    pub bytes_per_lane: u64,
}

/// What every try of a batch shares: the device, the variant, how its
/// dispatches are laid out and its kernels, compiled.
pub(super) struct Run<'a> {
    pub gpu: &'a Gpu,
    pub variant: &'a Variant,
    pub dispatch: Dispatch,
    pub kernels: Kernels,
    pub progress: Progress,
}

/// Runs one device batch on `schedule`: its kernels compiled (once per
/// process), then tries until one holds, each after a cut one with
/// dispatches `TRUNCATION_RETRY` times shorter.
pub(super) fn run<S: Schedule>(
    gpu: &Gpu,
    variant: &Variant,
    options: &RunOptions,
    mut schedule: S,
) -> Result<GpuRun> {
    let start = Instant::now();
    let dispatch = Dispatch::new(gpu, options);
    let run = Run {
        gpu,
        variant,
        dispatch,
        kernels: Kernels::cached(gpu, variant, S::BINDINGS, dispatch.workgroup),
        progress: options.progress.clone().unwrap_or_default(),
    };
    let mut timings = Timings {
        setup: start.elapsed(),
        ..Default::default()
    };
    let mut max_chunk = schedule.first_chunk(&run);
    let mut retries = 0;
    loop {
        let attempt = schedule.attempt(&run, max_chunk)?;
        timings.add(&attempt.timings);
        retries += attempt.retries;
        if let Some(lanes) = attempt.lanes {
            return Ok(GpuRun {
                lanes,
                timings,
                chunk_steps: attempt.chunk_steps,
                retries,
                bytes_per_lane: attempt.bytes_per_lane,
            });
        }
        max_chunk = shorter(attempt.chunk_steps)?;
        retries += 1;
    }
}

/// The steps per dispatch after dispatches of `chunk_steps` were cut
/// short, or the error that says no dispatch is short enough.
pub(super) fn shorter(chunk_steps: usize) -> Result<usize> {
    if chunk_steps == 1 {
        return Err(gpu_error(
            "the adapter cut the loops of a single RK4 step short (lavapipe's cap \
             of 65 535 loop iterations per invocation): use backend = \"cpu\""
                .into(),
        ));
    }
    Ok((chunk_steps / TRUNCATION_RETRY).max(1))
}

/// A variant's compute pipelines over one bind group layout.
#[derive(Clone)]
pub(super) struct Kernels {
    bindings: &'static Bindings,
    layout: wgpu::BindGroupLayout,
    pipelines: Vec<(Kernel, wgpu::ComputePipeline)>,
}

impl Kernels {
    /// The kernels of `variant` over `bindings`, compiled once per
    /// workgroup size.
    fn cached(gpu: &Gpu, variant: &Variant, bindings: &'static Bindings, workgroup: u32) -> Self {
        let source: String = variant
            .kernels()
            .iter()
            .map(|&k| variant.source(k))
            .collect();
        compiled_once(gpu, source, workgroup, || {
            let entries = bindings.layout_entries(&variant.defines());
            let layout = gpu
                .device
                .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                    label: Some(bindings.label),
                    entries: &entries,
                });
            let pipelines = variant
                .kernels()
                .iter()
                .map(|&kernel| {
                    let pipeline =
                        compute_pipeline(gpu, &layout, &entries, variant, kernel, workgroup);
                    (kernel, pipeline)
                })
                .collect();
            Kernels {
                bindings,
                layout,
                pipelines,
            }
        })
    }

    pub fn pipeline(&self, kernel: Kernel) -> &wgpu::ComputePipeline {
        let (_, pipeline) = self
            .pipelines
            .iter()
            .find(|(k, _)| *k == kernel)
            .expect("a kernel of the variant");
        pipeline
    }

    /// The bind group of `variant`'s kernels, each binding bound to
    /// `buffer(name)` (its name in the kernels).
    pub fn bind_group<'b>(
        &self,
        gpu: &Gpu,
        variant: &Variant,
        buffer: impl Fn(&str) -> Option<&'b wgpu::Buffer>,
    ) -> wgpu::BindGroup {
        self.bindings
            .bind_group(&gpu.device, &self.layout, &variant.defines(), buffer)
    }
}

/// Storage the kernels write and the host fills and copies from.
pub(super) const STORAGE: wgpu::BufferUsages = wgpu::BufferUsages::STORAGE
    .union(wgpu::BufferUsages::COPY_SRC)
    .union(wgpu::BufferUsages::COPY_DST);
/// A buffer the host maps to read.
pub(super) const READABLE: wgpu::BufferUsages =
    wgpu::BufferUsages::MAP_READ.union(wgpu::BufferUsages::COPY_DST);

/// A buffer holding `contents`.
pub(super) fn buffer_with(
    gpu: &Gpu,
    label: &str,
    contents: &[u8],
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    gpu.device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(label),
            contents,
            usage,
        })
}

/// A buffer of `size` bytes (at least 16: no binding is empty).
pub(super) fn buffer_of(
    gpu: &Gpu,
    label: &str,
    size: u64,
    usage: wgpu::BufferUsages,
) -> wgpu::Buffer {
    gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some(label),
        size: size.max(16),
        usage,
        mapped_at_creation: false,
    })
}

/// The staging buffers chunks of results are copied to and read from, in
/// turn: with two, the host reads chunk c - 1 while the device computes
/// chunk c.
pub(super) struct Ring {
    staging: Vec<wgpu::Buffer>,
}

/// Where a staging buffer's map_async reports.
type MapReceiver = mpsc::Receiver<std::result::Result<(), wgpu::BufferAsyncError>>;

/// A chunk submitted, its staging buffer being mapped.
pub(super) struct Pending {
    pub chunk: usize,
    receiver: MapReceiver,
    index: wgpu::SubmissionIndex,
}

impl Ring {
    /// `slots` staging buffers of `bytes` each.
    pub fn new(gpu: &Gpu, slots: usize, bytes: u64) -> Self {
        Ring {
            staging: (0..slots)
                .map(|_| buffer_of(gpu, "staging", bytes, READABLE))
                .collect(),
        }
    }

    /// The staging buffer chunk `chunk` is copied to.
    pub fn slot(&self, chunk: usize) -> &wgpu::Buffer {
        &self.staging[chunk % self.staging.len()]
    }

    pub fn device_bytes(&self) -> u64 {
        self.staging.iter().map(|b| b.size()).sum()
    }

    /// Submits `encoder` (which copies chunk `chunk`'s results to its
    /// staging buffer) and has the buffer mapped once it has run.
    pub fn submit(&self, gpu: &Gpu, encoder: wgpu::CommandEncoder, chunk: usize) -> Pending {
        let index = gpu.queue.submit([encoder.finish()]);
        let (sender, receiver) = mpsc::channel();
        self.slot(chunk)
            .map_async(wgpu::MapMode::Read, .., move |result| {
                let _ = sender.send(result);
            });
        Pending {
            chunk,
            receiver,
            index,
        }
    }

    /// Waits until the device has run `pending`'s submission, timed as
    /// the host's wait for the GPU.
    pub fn wait(gpu: &Gpu, pending: &Pending, timings: &mut Timings) -> Result<()> {
        let start = Instant::now();
        wait_for(&gpu.device, pending.index.clone())?;
        timings.gpu_wait += start.elapsed();
        Ok(())
    }

    /// `read` of `pending`'s staging buffer, mapped (after [`Ring::wait`]),
    /// then unmapped.
    pub fn read<T>(&self, pending: Pending, read: impl FnOnce(&[u8]) -> T) -> Result<T> {
        pending
            .receiver
            .recv()
            .map_err(|_| gpu_error("readback was cancelled".into()))?
            .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
        let staging = self.slot(pending.chunk);
        let value = {
            let view = staging
                .get_mapped_range(..)
                .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
            read(&view)
        };
        staging.unmap();
        Ok(value)
    }
}
