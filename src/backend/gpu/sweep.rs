//! One GPU sweep: buffers, the dispatch schedule and the streaming readback.
//!
//! Per map iteration, and per part of one when it is cut into sub-maps, the
//! host encodes `ceil(steps / chunk_steps)` integrate dispatches and one
//! finish dispatch; nothing crosses back to the host per iteration. The transient runs references only, with no readback. While
//! averaging, each chunk of iterations writes its Jacobians, points and
//! summaries into a ring of slots that is copied to one of two staging
//! buffers; the host maps and accumulates QR for one chunk while the GPU
//! computes the next.

use std::sync::mpsc;
use std::time::Instant;

use nalgebra::{Const, DimMin, SMatrix};
use rayon::prelude::*;
use wgpu::util::DeviceExt;

use super::context::Gpu;
use super::pipeline::{
    compiled_once, compute_pipeline, gpu_error, read_back, real_bytes, reals_from, storage_entry,
    uniform_entry, wait_for, Dispatch, GpuRun, Timings, TRUNCATION_RETRY,
};
use super::seed::{lane_constants, Seeds};
use super::shader::{Kernel, Variant};
use super::stopwatch::{self, Stopwatch};
use crate::backend::options::RunOptions;
use crate::backend::progress::Progress;
use crate::error::{Error, Result};
use crate::method::lane::{is_grazing, LanePlan};
use crate::method::{LaneAccumulator, LaneResult, MethodSettings};
use crate::scene::{Precision, Scene};
use crate::system::{IterationStats, Part};

/// Steps per integrate dispatch with a wall on a software adapter. lavapipe
/// caps the loop iterations of one invocation at 65 535 (every loop
/// together, shared by a SIMD group; see `loop_budget_exhausted` in
/// shaders/shared/bindings.wgsl), and a step with impacts runs many loops:
/// a dispatch of 1 300 steps with 3 700 impacts went past it. Quiet steps
/// cost a few dozen iterations, so 256 leave room for ~60 impacts of 1 000
/// each; a batch whose dispatches still ran past the cap is redone with
/// dispatches `TRUNCATION_RETRY` times shorter.
const SOFTWARE_WALL_CHUNK: usize = 256;
/// Lane-steps per transient submission, after which the host waits.
const SUBMIT_LANE_STEPS: usize = 1 << 26;
/// Bytes of Jacobians, points and summaries per chunk of iterations.
const CHUNK_BYTES: u64 = 32 << 20;
/// Trajectory-steps per chunk of iterations on a software adapter, about
/// 0.1 s of lavapipe's on 2 cores: a stop waits for the chunk in flight,
/// and a chunk of the byte budget alone (5 000 iterations of 64 lanes)
/// took it 7 s to stop there. Hardware GPUs keep the byte budget.
const SOFTWARE_CHUNK_STEPS: usize = 1 << 24;

/// Runs the lanes of `scene` (one device batch: at most [`max_batch_lanes`])
/// of a period map. The first try's dispatches take at most
/// `options.dispatch_steps` steps; a try whose dispatches the adapter cut
/// short is redone with shorter ones (`GpuRun::retries`), and the caller
/// starts its next batches at the length that held (`GpuRun::chunk_steps`).
pub fn run(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &RunOptions,
) -> Result<GpuRun> {
    match scene.system.dimension() {
        1 => run_dim::<1>(gpu, scene, variant, settings, options),
        2 => run_dim::<2>(gpu, scene, variant, settings, options),
        3 => run_dim::<3>(gpu, scene, variant, settings, options),
        4 => run_dim::<4>(gpu, scene, variant, settings, options),
        d => Err(Error::Backend {
            backend: "gpu".into(),
            reason: format!("maps of dimension {d} are not supported on the GPU (1 to 4 are)"),
        }),
    }
}

/// The most lanes of `scene` one device batch holds: its trajectories in
/// one dispatch and in one storage binding, one ring slot of its lanes in
/// one binding (and at most `options.max_batch_lanes`).
pub fn max_batch_lanes(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &RunOptions,
) -> usize {
    let layout = Layout::new(scene, variant, settings);
    let binding = gpu.max_binding();
    let by_dispatch = Dispatch::new(gpu, options).max_invocations() / layout.traj;
    let by_binding = (binding / (layout.traj * layout.traj_stride) as u64 / layout.real) as usize;
    let by_ring = (binding / layout.largest_per_iteration()) as usize;
    by_dispatch
        .min(by_binding)
        .min(by_ring)
        .min(options.max_batch_lanes.unwrap_or(usize::MAX))
        .max(1)
}

/// Sizes that depend on the variant, in bytes.
struct Layout {
    traj: usize,
    real: u64,
    lane_stride: usize,
    traj_stride: usize,
    /// Ring bytes per lane and part of an iteration: summary (with stops,
    /// followed by the impacts on each), Jacobian, point.
    summary: u64,
    /// `[u32; 4]`s of summary per slot: `SUMMARY_STRIDE` in the WGSL.
    summary_stride: usize,
    jacobian: u64,
    point: u64,
    /// The reference's Σ ln |det S| of its crossings of general surfaces
    /// (a real), with surfaces.
    flux: u64,
    /// Parts (sub-maps) per iteration, each with its ring slot.
    parts: usize,
}

impl Layout {
    fn new(scene: &Scene, variant: &Variant, settings: &MethodSettings) -> Self {
        let dim = scene.system.dimension();
        let real = match variant.precision {
            Precision::F64 => 8,
            Precision::F32 => 4,
        };
        Layout {
            traj: variant.trajectories(),
            real,
            lane_stride: scene.system.parameters.len() + 5,
            // With surfaces, each trajectory's region and flux follow.
            traj_stride: 2 * dim + 3 + 2 * usize::from(variant.surfaces()),
            summary: 16 * (1 + u64::from(variant.wall)),
            summary_stride: 1 + usize::from(variant.wall),
            jacobian: if variant.lyapunov {
                (dim * dim) as u64 * real
            } else {
                0
            },
            point: dim as u64 * real,
            flux: if variant.surfaces() { real } else { 0 },
            parts: settings.submaps.unwrap_or(1),
        }
    }

    fn per_iteration(&self) -> u64 {
        (self.summary + self.jacobian + self.point + self.flux) * self.parts as u64
    }

    /// The largest ring array's bytes per lane and iteration.
    fn largest_per_iteration(&self) -> u64 {
        self.jacobian.max(self.point).max(self.summary) * self.parts as u64
    }
}

fn run_dim<const D: usize>(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &RunOptions,
) -> Result<GpuRun>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let start = Instant::now();
    let dispatch = Dispatch::new(gpu, options);
    let pipelines = Pipelines::cached(gpu, variant, dispatch);
    let stopwatch = Stopwatch::new(gpu);
    let layout = Layout::new(scene, variant, settings);
    let count = scene.lane_count();
    debug_assert!(count <= max_batch_lanes(gpu, scene, variant, settings, options));
    let mut timings = Timings {
        setup: start.elapsed(),
        ..Default::default()
    };
    let software_stops = variant.wall && !gpu.summary.is_hardware();
    let default_chunk = if software_stops {
        SOFTWARE_WALL_CHUNK
    } else {
        usize::MAX
    };
    let mut max_chunk = options.dispatch_steps.unwrap_or(default_chunk);
    let mut retries = 0;
    let progress = options.progress.clone().unwrap_or_default();
    loop {
        let batch = Batch::<D>::new(
            gpu,
            &pipelines,
            stopwatch.as_ref(),
            scene,
            variant,
            settings,
            &layout,
            count,
            max_chunk,
        );
        let chunk_steps = batch.chunk_steps;
        let bytes_per_lane = batch.device_bytes / count as u64;
        let (results, t) = batch.run(gpu, &pipelines, &progress)?;
        timings.add(&t);
        if let Some(lanes) = results {
            return Ok(GpuRun {
                lanes,
                timings,
                chunk_steps,
                retries,
                bytes_per_lane,
            });
        }
        // The adapter cut a dispatch's loops short: the results are
        // wrong, and shorter dispatches stay within its cap.
        if chunk_steps == 1 {
            return Err(gpu_error(
                "the adapter cut the loops of a single RK4 step short (lavapipe's cap \
                 of 65 535 loop iterations per invocation): use backend = \"cpu\""
                    .into(),
            ));
        }
        max_chunk = (chunk_steps / TRUNCATION_RETRY).max(1);
        retries += 1;
    }
}

/// The two compute pipelines of a variant over one bind group layout.
#[derive(Clone)]
struct Pipelines {
    layout: wgpu::BindGroupLayout,
    integrate: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
    lyapunov: bool,
    /// The per-stop impact counts (binding 8) of a variant with stops.
    wall: bool,
    /// The fluxes (binding 9) of a variant with general surfaces.
    surfaces: bool,
    dispatch: Dispatch,
}

impl Pipelines {
    /// The pipelines of `variant` (compiled once per workgroup size), to
    /// be dispatched as `dispatch` lays out.
    fn cached(gpu: &Gpu, variant: &Variant, dispatch: Dispatch) -> Self {
        let source = variant.source(Kernel::Integrate) + &variant.source(Kernel::Finish);
        let compiled = compiled_once(gpu, source, dispatch.workgroup, || {
            Self::new(gpu, variant, dispatch)
        });
        Pipelines {
            dispatch,
            ..compiled
        }
    }

    fn new(gpu: &Gpu, variant: &Variant, dispatch: Dispatch) -> Self {
        let workgroup = dispatch.workgroup;
        let mut entries = vec![
            uniform_entry(0),
            storage_entry(1, true),
            storage_entry(2, false),
            storage_entry(3, false),
            storage_entry(4, false),
        ];
        if variant.lyapunov {
            entries.extend([storage_entry(5, false), storage_entry(6, false)]);
        }
        entries.push(storage_entry(7, false));
        if variant.wall {
            entries.push(storage_entry(8, false));
        }
        if variant.surfaces() {
            entries.push(storage_entry(9, false));
        }
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("sweep"),
                entries: &entries,
            });
        let pipeline =
            |kernel: Kernel| compute_pipeline(gpu, &layout, &entries, variant, kernel, workgroup);
        Pipelines {
            integrate: pipeline(Kernel::Integrate),
            finish: pipeline(Kernel::Finish),
            layout,
            lyapunov: variant.lyapunov,
            wall: variant.wall,
            surfaces: variant.surfaces(),
            dispatch,
        }
    }
}

/// `Control` in shared/bindings.wgsl.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Control {
    lane_count: u32,
    steps_per_period: u32,
    chunk_steps: u32,
    transient: u32,
    ring: u32,
    /// Always 0; see `opaque_zero` in the WGSL.
    opaque_zero: u32,
    part_steps: u32,
    parts: u32,
}

/// One batch of lanes with its buffers.
struct Batch<'a, const D: usize> {
    stopwatch: Option<&'a Stopwatch>,
    settings: &'a MethodSettings,
    layout: &'a Layout,
    precision: Precision,
    count: usize,
    steps: usize,
    /// Steps per part (sub-map) of an iteration, `steps / layout.parts`.
    part_steps: usize,
    chunk_steps: usize,
    transient_chunk_steps: usize,
    ring: usize,
    transient_control: wgpu::BindGroup,
    averaging_control: wgpu::BindGroup,
    summary: wgpu::Buffer,
    jac: Option<wgpu::Buffer>,
    points: wgpu::Buffer,
    fluxes: Option<wgpu::Buffer>,
    staging: [wgpu::Buffer; 2],
    /// Where the staging buffers hold the chunk's pass timestamps.
    ticks_offset: u64,
    /// The transient passes' timestamps, read back after each submission.
    transient_ticks: Option<wgpu::Buffer>,
    periods: Vec<f64>,
    /// The trajectories (read once after the transient, for grazing).
    traj: wgpu::Buffer,
    grazing: Option<Grazing>,
    /// Bytes of device memory in the batch's buffers.
    device_bytes: u64,
}

/// What the host needs to re-estimate the iterations the kernels flag as
/// grazing: the CPU path's estimate with its δ ladder, at the reference's
/// point, in f64 (`method::lane::estimate_resolving_grazing`).
struct Grazing {
    system: &'static crate::system::SystemInfo,
    params: Vec<crate::system::Params>,
    settings: MethodSettings,
}

impl<'a, const D: usize> Batch<'a, D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    /// The batch of `scene`'s `count` lanes: their constants and
    /// starting trajectories uploaded, the ring of iterations read back per
    /// chunk sized, the dispatches' steps chosen and the buffers bound.
    #[allow(clippy::too_many_arguments)]
    fn new(
        gpu: &Gpu,
        pipelines: &Pipelines,
        stopwatch: Option<&'a Stopwatch>,
        scene: &'a Scene,
        variant: &Variant,
        settings: &'a MethodSettings,
        layout: &'a Layout,
        count: usize,
        max_chunk: usize,
    ) -> Self {
        let precision = variant.precision;
        let steps = if scene.system.is_flow {
            settings.flow.steps_per_period
        } else {
            1
        };
        // The backend makes the steps a multiple of the parts (`gpu_plan`).
        assert_eq!(steps % layout.parts, 0, "steps are whole parts");
        let part_steps = steps / layout.parts;
        let (lane_data, periods) = lane_constants(scene, settings, layout.lane_stride, steps);
        let seeds = Seeds::new::<D>(
            scene,
            settings,
            (layout.traj, layout.traj_stride),
            pipelines.surfaces,
            precision,
        );
        let per_iteration = layout.per_iteration() * count as u64;
        let ring = ring_size(gpu, layout, settings, count, per_iteration);
        let ring = if gpu.summary.is_hardware() {
            ring
        } else {
            ring.min((SOFTWARE_CHUNK_STEPS / (count * layout.traj * steps).max(1)).max(1))
        };
        let lane_steps = pipelines.dispatch.lane_steps;
        let chunk = |trajectories: usize| (lane_steps / trajectories.max(1)).clamp(1, steps);
        // While averaging a dispatch stops at the end of a part.
        let chunk_steps = chunk(count * layout.traj).min(part_steps).min(max_chunk);
        let transient_chunk_steps = chunk(count).min(max_chunk);
        let control = |transient: bool, chunk_steps: usize| Control {
            lane_count: count as u32,
            steps_per_period: steps as u32,
            chunk_steps: chunk_steps as u32,
            transient: u32::from(transient),
            ring: ring as u32,
            opaque_zero: 0,
            part_steps: part_steps as u32,
            parts: layout.parts as u32,
        };
        let controls = [
            control(true, transient_chunk_steps),
            control(false, chunk_steps),
        ];
        let slots = (ring * layout.parts * count) as u64;
        let ticks_offset = per_iteration * ring as u64;
        let b = Buffers::new(
            gpu,
            pipelines,
            layout,
            stopwatch.is_some(),
            precision,
            (count, slots, ticks_offset),
            &lane_data,
            &seeds,
            controls,
        );
        let grazing = variant.reestimates().then(|| {
            let cpu = crate::plan::cpu_twin(scene, settings);
            Grazing {
                system: scene.system,
                params: (0..count).map(|k| scene.lane_params(k)).collect(),
                settings: cpu,
            }
        });
        Batch {
            device_bytes: b.device_bytes(),
            stopwatch,
            settings,
            layout,
            precision,
            count,
            steps,
            part_steps,
            chunk_steps,
            transient_chunk_steps,
            ring,
            transient_control: b.bind_group(gpu, pipelines, &b.transient_uniform),
            averaging_control: b.bind_group(gpu, pipelines, &b.averaging_uniform),
            summary: b.summary,
            jac: b.jac,
            points: b.points,
            fluxes: b.fluxes,
            staging: b.staging,
            ticks_offset,
            transient_ticks: b.transient_ticks,
            periods,
            traj: b.traj,
            grazing,
        }
    }

    /// Encodes `iterations` map iterations: per part (the whole iteration in
    /// the transient), integrate dispatches in chunks of `chunk_steps`, then
    /// the finish kernel; one pass, timed in `slot`.
    fn encode_iterations(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        pipelines: &Pipelines,
        transient: bool,
        iterations: usize,
        slot: u32,
    ) {
        let (bind_group, chunk, invocations, parts, part_steps) = if transient {
            (
                &self.transient_control,
                self.transient_chunk_steps,
                self.count,
                1,
                self.steps,
            )
        } else {
            (
                &self.averaging_control,
                self.chunk_steps,
                self.count * self.layout.traj,
                self.layout.parts,
                self.part_steps,
            )
        };
        let (invocations, lanes) = (
            pipelines.dispatch.grid(invocations),
            pipelines.dispatch.grid(self.count),
        );
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(if transient { "transient" } else { "averaging" }),
            timestamp_writes: self.stopwatch.map(|s| s.writes(slot)),
        });
        pass.set_bind_group(0, bind_group, &[]);
        for _ in 0..iterations * parts {
            pass.set_pipeline(&pipelines.integrate);
            for _ in 0..part_steps.div_ceil(chunk) {
                pass.dispatch_workgroups(invocations.0, invocations.1, 1);
            }
            pass.set_pipeline(&pipelines.finish);
            pass.dispatch_workgroups(lanes.0, lanes.1, 1);
        }
    }

    /// The batch's lanes, or `None` when a dispatch ran past the adapter's
    /// loop cap (the lanes are then wrong and the batch must be redone).
    #[allow(clippy::type_complexity)]
    fn run(
        self,
        gpu: &Gpu,
        pipelines: &Pipelines,
        progress: &Progress,
    ) -> Result<(Option<Vec<LaneResult>>, Timings)> {
        let device = &gpu.device;
        let queue = &gpu.queue;
        let settings = self.settings;
        let mut timings = Timings::default();
        let mut progress = progress.attempt();

        // The transient: references only, no readback.
        let start = Instant::now();
        let per_submit = (SUBMIT_LANE_STEPS / (self.count * self.steps).max(1)).max(1);
        let mut done = 0;
        while done < settings.transient {
            if settings.stop.requested() {
                return Err(Error::Stopped);
            }
            let n = per_submit.min(settings.transient - done);
            let mut encoder = device.create_command_encoder(&Default::default());
            let slot = stopwatch::TRANSIENT_SLOT;
            self.encode_iterations(&mut encoder, pipelines, true, n, slot);
            if let (Some(s), Some(ticks)) = (self.stopwatch, &self.transient_ticks) {
                s.copy_out(&mut encoder, slot, ticks, 0);
            }
            let index = queue.submit([encoder.finish()]);
            wait_for(device, index)?;
            if let (Some(s), Some(ticks)) = (self.stopwatch, &self.transient_ticks) {
                let busy = read_back(device, ticks, |bytes| s.elapsed(bytes))?;
                *timings.gpu_busy.get_or_insert_default() += busy;
            }
            done += n;
            progress.advance((self.count * n) as u64);
        }
        // The reference points x_0 the first averaging iteration starts from,
        // for re-estimating it should it graze.
        let mut previous: Vec<Option<[f64; D]>> = vec![None; self.count];
        if self.grazing.is_some() {
            previous = self.reference_states(gpu)?.into_iter().map(Some).collect();
        }
        timings.transient = start.elapsed();

        // Averaging, streamed in chunks of `ring` iterations.
        let start = Instant::now();
        let plan = LanePlan {
            steps_per_period: self.steps,
            parts: self.layout.parts,
        };
        let mut accumulators: Vec<LaneAccumulator<D>> = self
            .periods
            .iter()
            .map(|&period| LaneAccumulator::new(settings, period, plan))
            .collect();
        let chunks: Vec<(usize, usize)> = (0..settings.iterations)
            .step_by(self.ring)
            .map(|first| (first, self.ring.min(settings.iterations - first)))
            .collect();
        // Chunk c computes while the host reads and accumulates chunk c - 1.
        let mut pending: Option<Pending> = None;
        for (c, &(_, n)) in chunks.iter().enumerate() {
            if settings.stop.requested() {
                // Let the chunk in flight finish before its buffers go.
                if let Some(in_flight) = pending {
                    wait_for(device, in_flight.index)?;
                }
                return Err(Error::Stopped);
            }
            let mut encoder = device.create_command_encoder(&Default::default());
            let slot = (c % 2) as u32;
            self.encode_iterations(&mut encoder, pipelines, false, n, slot);
            self.copy_to_staging(&mut encoder, &self.staging[c % 2], n);
            if let Some(s) = self.stopwatch {
                s.copy_out(&mut encoder, slot, &self.staging[c % 2], self.ticks_offset);
            }
            let index = queue.submit([encoder.finish()]);
            let submitted = Pending {
                chunk: c,
                receiver: self.map_staging(c % 2),
                index,
            };
            if let Some(done) = pending.replace(submitted) {
                let lanes = &mut accumulators;
                let n = chunks[done.chunk].1;
                if !self.collect(gpu, lanes, &mut previous, &chunks, done, &mut timings)? {
                    // Let the chunk in flight finish before its buffers go.
                    if let Some(in_flight) = pending {
                        wait_for(device, in_flight.index)?;
                    }
                    progress.undo();
                    return Ok((None, timings));
                }
                progress.advance((self.count * n) as u64);
            }
        }
        if let Some(last) = pending {
            let lanes = &mut accumulators;
            let n = chunks[last.chunk].1;
            if !self.collect(gpu, lanes, &mut previous, &chunks, last, &mut timings)? {
                progress.undo();
                return Ok((None, timings));
            }
            progress.advance((self.count * n) as u64);
        }
        timings.averaging = start.elapsed();
        Ok((
            Some(
                accumulators
                    .into_iter()
                    .map(LaneAccumulator::finish)
                    .collect(),
            ),
            timings,
        ))
    }

    /// The references' states, read back (after the transient).
    fn reference_states(&self, gpu: &Gpu) -> Result<Vec<[f64; D]>> {
        let bytes = self.traj.size();
        let readable = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("reference states"),
            size: bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let mut encoder = gpu.device.create_command_encoder(&Default::default());
        encoder.copy_buffer_to_buffer(&self.traj, 0, &readable, 0, bytes);
        let index = gpu.queue.submit([encoder.finish()]);
        wait_for(&gpu.device, index)?;
        let reals = read_back(&gpu.device, &readable, |b| reals_from(b, self.precision))?;
        let per_lane = self.layout.traj * self.layout.traj_stride;
        Ok((0..self.count)
            .map(|lane| crate::array::from_fn(|k| reals[lane * per_lane + k]))
            .collect())
    }

    fn copy_to_staging(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        staging: &wgpu::Buffer,
        iterations: usize,
    ) {
        let lanes = (iterations * self.layout.parts * self.count) as u64;
        let mut offset = 0;
        let mut copy = |source: &wgpu::Buffer, bytes: u64| {
            if bytes > 0 {
                encoder.copy_buffer_to_buffer(source, 0, staging, offset, bytes);
                offset += bytes;
            }
        };
        copy(&self.summary, self.layout.summary * lanes);
        if let Some(jac) = &self.jac {
            copy(jac, self.layout.jacobian * lanes);
        }
        copy(&self.points, self.layout.point * lanes);
        if let Some(fluxes) = &self.fluxes {
            copy(fluxes, self.layout.flux * lanes);
        }
    }

    fn map_staging(&self, which: usize) -> MapReceiver {
        let (sender, receiver) = mpsc::channel();
        self.staging[which].map_async(wgpu::MapMode::Read, .., move |result| {
            let _ = sender.send(result);
        });
        receiver
    }

    /// Waits for a submitted chunk's staging copy, then accumulates QR for
    /// every lane straight from the mapped buffer, the lanes spread over
    /// the host's cores (each reads and converts its own slots, so the
    /// read-back is no serial step before them); false (nothing
    /// accumulated) when a dispatch ran past the adapter's loop cap.
    fn collect(
        &self,
        gpu: &Gpu,
        accumulators: &mut [LaneAccumulator<D>],
        previous: &mut [Option<[f64; D]>],
        chunks: &[(usize, usize)],
        pending: Pending,
        timings: &mut Timings,
    ) -> Result<bool> {
        let (first_iteration, n) = chunks[pending.chunk];
        let start = Instant::now();
        wait_for(&gpu.device, pending.index)?;
        timings.gpu_wait += start.elapsed();
        let start = Instant::now();
        pending
            .receiver
            .recv()
            .map_err(|_| gpu_error("readback was cancelled".into()))?
            .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
        let staging = &self.staging[pending.chunk % 2];
        let view = staging
            .get_mapped_range(..)
            .map_err(|e| gpu_error(format!("readback failed: {e}")))?;
        let chunk = self.readback(&view, n);
        if let Some(s) = self.stopwatch {
            let busy = s.elapsed(&view[self.ticks_offset as usize..]);
            *timings.gpu_busy.get_or_insert_default() += busy;
        }
        let stride = self.layout.summary_stride;
        let truncated =
            (0..chunk.slots).any(|slot| chunk.summary(stride * slot)[1] & FLAG_TRUNCATED != 0);
        timings.readback += start.elapsed();
        if !truncated {
            let start = Instant::now();
            accumulators
                .par_iter_mut()
                .zip(previous.par_iter_mut())
                .enumerate()
                .for_each(|(lane, (acc, x_n))| {
                    self.accumulate(&chunk, lane, first_iteration, n, acc, x_n);
                });
            timings.host_qr += start.elapsed();
        }
        drop(view);
        staging.unmap();
        Ok(!truncated)
    }

    /// The parts of a mapped staging buffer holding a chunk of `n`
    /// iterations (see `copy_to_staging`).
    fn readback<'b>(&self, bytes: &'b [u8], n: usize) -> Readback<'b> {
        let slots = n * self.layout.parts * self.count;
        let lanes = slots as u64;
        let s_end = (self.layout.summary * lanes) as usize;
        let j_end = s_end + (self.layout.jacobian * lanes) as usize;
        let p_end = j_end + (self.layout.point * lanes) as usize;
        let f_end = p_end + (self.layout.flux * lanes) as usize;
        let reals = |range: std::ops::Range<usize>| Reals {
            bytes: &bytes[range],
            precision: self.precision,
        };
        Readback {
            slots,
            summary: &bytes[..s_end],
            jac: reals(s_end..j_end),
            points: reals(j_end..p_end),
            fluxes: reals(p_end..f_end),
        }
    }

    /// Lane `lane`'s `n` iterations of a chunk starting at averaging
    /// iteration `first_iteration`, taken into its accumulator; `x_n` is
    /// its latest reference point (where a grazing part is redone).
    fn accumulate(
        &self,
        chunk: &Readback,
        lane: usize,
        first_iteration: usize,
        n: usize,
        acc: &mut LaneAccumulator<D>,
        x_n: &mut Option<[f64; D]>,
    ) {
        let parts = self.layout.parts;
        let stride = self.layout.summary_stride;
        let mut jacobians: Vec<SMatrix<f64, D, D>> = Vec::with_capacity(parts);
        for j in 0..n {
            let slot = |part: usize| (j * parts + part) * self.count + lane;
            // A failed reference reports in its iteration's last
            // part; the earlier slots may hold an older iteration.
            if (0..parts).any(|p| chunk.summary(stride * slot(p))[1] & FLAG_NONFINITE != 0) {
                acc.fail(self.settings.transient + first_iteration + j);
                break;
            }
            let mut stats = IterationStats::default();
            let mut scale = 0.0;
            let mut point = None;
            jacobians.clear();
            for p in 0..parts {
                let s = slot(p);
                let [_, _, scale_bits, nonlinearity_bits] = chunk.summary(stride * s);
                let mut part = part_stats::<D>(chunk, stride, s);
                // A flagged part's trajectories stopped at the flag,
                // not at the part's end: its columns are no
                // derivative of the map (a copy frozen at one state,
                // the reference at another gave a singular one,
                // which failed the lane as non-finite).
                if self.jac.is_some() && !part.sliding {
                    let jacobian = SMatrix::from_fn(|r, c| chunk.jac.get(s * D * D + r * D + c));
                    let nonlinearity = f64::from(f32::from_bits(nonlinearity_bits));
                    let part_of = Part {
                        index: p,
                        count: parts,
                    };
                    jacobians.push(self.reestimate_grazing(
                        jacobian,
                        nonlinearity,
                        &mut part,
                        lane,
                        part_of,
                        x_n.as_ref(),
                    ));
                }
                stats.merge(&part);
                point = Some(crate::array::from_fn(|k| chunk.points.get(s * D + k)));
                *x_n = point;
                // The size of the iteration's image, as on the CPU.
                scale = f64::from(f32::from_bits(scale_bits));
            }
            if !acc.record(scale, point.as_ref(), &jacobians, &stats) {
                break;
            }
        }
    }

    /// A part's Jacobian as the kernels estimated it, or, for a grazing
    /// part, as the host redoes it on the CPU from the point `x` it started
    /// at, with the δ ladder (noted in `part`'s statistics).
    fn reestimate_grazing(
        &self,
        jacobian: SMatrix<f64, D, D>,
        nonlinearity: f64,
        part: &mut IterationStats,
        lane: usize,
        index: Part,
        x: Option<&[f64; D]>,
    ) -> SMatrix<f64, D, D> {
        let (Some(g), Some(x)) = (self.grazing.as_ref(), x) else {
            return jacobian;
        };
        if part.rank_loss != 0
            || !is_grazing(self.settings, self.part_steps, nonlinearity, &jacobian)
        {
            return jacobian;
        }
        let (cpu, cpu_stats) =
            (crate::method::runner(g.system).reestimate)(&g.params[lane], &g.settings, index, x);
        part.grazing = true;
        part.grazing_error = cpu_stats.grazing_error;
        SMatrix::from_row_slice(&cpu)
    }
}

/// A chunk's results in the mapped staging buffer, per slot (iteration ×
/// part × lane), read where they lie.
struct Readback<'a> {
    slots: usize,
    summary: &'a [u8],
    jac: Reals<'a>,
    points: Reals<'a>,
    fluxes: Reals<'a>,
}

impl Readback<'_> {
    /// Summary entry `i` (a slot has `summary_stride` of them).
    fn summary(&self, i: usize) -> [u32; 4] {
        bytemuck::pod_read_unaligned(&self.summary[16 * i..16 * (i + 1)])
    }
}

/// Reals of the kernels' precision, read as f64 one at a time (the mapped
/// bytes need not be aligned for a cast).
struct Reals<'a> {
    bytes: &'a [u8],
    precision: Precision,
}

impl Reals<'_> {
    fn len(&self) -> usize {
        match self.precision {
            Precision::F64 => self.bytes.len() / 8,
            Precision::F32 => self.bytes.len() / 4,
        }
    }

    fn get(&self, i: usize) -> f64 {
        match self.precision {
            Precision::F64 => bytemuck::pod_read_unaligned(&self.bytes[8 * i..8 * (i + 1)]),
            Precision::F32 => f64::from(bytemuck::pod_read_unaligned::<f32>(
                &self.bytes[4 * i..4 * (i + 1)],
            )),
        }
    }
}

/// The statistics the kernels report for slot `s` (its summary's flags and
/// counts, `stride` summary entries a slot, and its flux term).
fn part_stats<const D: usize>(chunk: &Readback, stride: usize, s: usize) -> IterationStats {
    let [impacts, flags, _, _] = chunk.summary(stride * s);
    // With stops, the impacts on each follow (their sum
    // is `impacts`); without, there are none.
    let per_stop = if stride > 1 {
        chunk.summary(stride * s + 1)
    } else {
        [0; 4]
    };
    IterationStats {
        impacts,
        crossings: crate::array::from_fn(|j| per_stop.get(j).copied().unwrap_or(0)),
        // After a motion the kernels flagged sliding
        // (sticky: FLAG_STICKY), whatever else they
        // report comes from a state they did not
        // integrate: the lane is `sliding`, which the
        // backend recomputes on the CPU.
        chattering: flags & FLAG_CHATTERING != 0 && flags & FLAG_SLIDING == 0,
        sliding: flags & FLAG_SLIDING != 0,
        // Counted in the flags' high half.
        sliding_phases: flags >> 16,
        log_flux: if s < chunk.fluxes.len() {
            chunk.fluxes.get(s)
        } else {
            0.0
        },
        // Sticking collapses the mass's position and
        // velocity (all of a 2-state system).
        rank_loss: if flags & FLAG_RANK_TWO != 0 {
            2.min(D as u32)
        } else {
            u32::from(flags & FLAG_RANK_ONE != 0)
        },
        ..Default::default()
    }
}

/// Iterations of the batch read back at once: as many as fit the chunk's
/// byte budget and a storage binding, at least 1 and at most the run's.
fn ring_size(
    gpu: &Gpu,
    layout: &Layout,
    settings: &MethodSettings,
    count: usize,
    per_iteration: u64,
) -> usize {
    let binding = gpu.max_binding();
    let ring_budget = CHUNK_BYTES.min(binding);
    let ring_by_budget = (ring_budget / per_iteration.max(1)) as usize;
    let ring_by_binding = (binding / (layout.largest_per_iteration() * count as u64)) as usize;
    ring_by_budget
        .min(ring_by_binding)
        .clamp(1, settings.iterations.max(1))
}

/// A batch's device buffers, before they are bound.
struct Buffers {
    transient_uniform: wgpu::Buffer,
    averaging_uniform: wgpu::Buffer,
    lanes: wgpu::Buffer,
    traj: wgpu::Buffer,
    counts: wgpu::Buffer,
    crossings: Option<wgpu::Buffer>,
    summary: wgpu::Buffer,
    deltas: Option<wgpu::Buffer>,
    jac: Option<wgpu::Buffer>,
    points: wgpu::Buffer,
    fluxes: Option<wgpu::Buffer>,
    staging: [wgpu::Buffer; 2],
    transient_ticks: Option<wgpu::Buffer>,
}

impl Buffers {
    /// The buffers of `count` lanes with `slots` result slots (ring ×
    /// parts × lanes), the staging buffers holding `ticks_offset` bytes of
    /// results and the timestamps after them when `timed`.
    #[allow(clippy::too_many_arguments)]
    fn new(
        gpu: &Gpu,
        pipelines: &Pipelines,
        layout: &Layout,
        timed: bool,
        precision: Precision,
        (count, slots, ticks_offset): (usize, u64, u64),
        lane_data: &[f64],
        seeds: &Seeds,
        [transient, averaging]: [Control; 2],
    ) -> Buffers {
        let device = &gpu.device;
        let traj = layout.traj;
        let storage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_SRC
            | wgpu::BufferUsages::COPY_DST;
        let init = |label: &str, contents: &[u8], usage| {
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents,
                usage,
            })
        };
        let empty = |label: &str, size: u64, usage| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: size.max(16),
                usage,
                mapped_at_creation: false,
            })
        };
        let transient_uniform = init(
            "control (transient)",
            bytemuck::bytes_of(&transient),
            wgpu::BufferUsages::UNIFORM,
        );
        let averaging_uniform = init(
            "control (averaging)",
            bytemuck::bytes_of(&averaging),
            wgpu::BufferUsages::UNIFORM,
        );
        let lanes_buffer = init(
            "lanes",
            &real_bytes(lane_data, precision),
            wgpu::BufferUsages::STORAGE,
        );
        let traj_buffer = init("trajectories", &real_bytes(&seeds.traj, precision), storage);
        let counts = init("counts", bytemuck::cast_slice(&seeds.counts), storage);
        // Per trajectory, its impacts on each stop: none yet.
        let crossings = pipelines.wall.then(|| {
            init(
                "crossings",
                bytemuck::cast_slice(&vec![[0u32; 4]; count * traj]),
                storage,
            )
        });
        let summary = empty("summary", layout.summary * slots, storage);
        let deltas_buffer = pipelines
            .lyapunov
            .then(|| init("deltas", &real_bytes(&seeds.deltas, precision), storage));
        let jac = pipelines
            .lyapunov
            .then(|| empty("jacobians", layout.jacobian * slots, storage));
        let points = empty("points", layout.point * slots, storage);
        let fluxes = pipelines
            .surfaces
            .then(|| empty("fluxes", layout.flux * slots, storage));
        let readable = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        let ticks_bytes = if timed { stopwatch::TICKS_BYTES } else { 0 };
        let staging = [0, 1].map(|_| empty("staging", ticks_offset + ticks_bytes, readable));
        let transient_ticks = timed.then(|| empty("transient ticks", ticks_bytes, readable));
        Buffers {
            transient_uniform,
            averaging_uniform,
            lanes: lanes_buffer,
            traj: traj_buffer,
            counts,
            crossings,
            summary,
            deltas: deltas_buffer,
            jac,
            points,
            fluxes,
            staging,
            transient_ticks,
        }
    }

    /// Bytes of device memory in the buffers the batch holds.
    fn device_bytes(&self) -> u64 {
        [&self.lanes, &self.traj, &self.counts, &self.summary]
            .into_iter()
            .chain(&self.deltas)
            .chain(&self.crossings)
            .chain(&self.jac)
            .chain([&self.points])
            .chain(&self.fluxes)
            .chain(&self.staging)
            .map(|b| b.size())
            .sum()
    }

    /// The bind group of the sweep's kernels with `uniform` as the control.
    fn bind_group(
        &self,
        gpu: &Gpu,
        pipelines: &Pipelines,
        uniform: &wgpu::Buffer,
    ) -> wgpu::BindGroup {
        let mut entries = vec![
            wgpu::BindGroupEntry {
                binding: 0,
                resource: uniform.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 1,
                resource: self.lanes.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 2,
                resource: self.traj.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 3,
                resource: self.counts.as_entire_binding(),
            },
            wgpu::BindGroupEntry {
                binding: 4,
                resource: self.summary.as_entire_binding(),
            },
        ];
        if let (Some(d), Some(j)) = (&self.deltas, &self.jac) {
            entries.push(wgpu::BindGroupEntry {
                binding: 5,
                resource: d.as_entire_binding(),
            });
            entries.push(wgpu::BindGroupEntry {
                binding: 6,
                resource: j.as_entire_binding(),
            });
        }
        entries.push(wgpu::BindGroupEntry {
            binding: 7,
            resource: self.points.as_entire_binding(),
        });
        if let Some(c) = &self.crossings {
            entries.push(wgpu::BindGroupEntry {
                binding: 8,
                resource: c.as_entire_binding(),
            });
        }
        if let Some(f) = &self.fluxes {
            entries.push(wgpu::BindGroupEntry {
                binding: 9,
                resource: f.as_entire_binding(),
            });
        }
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("sweep"),
            layout: &pipelines.layout,
            entries: &entries,
        })
    }
}

/// Where a staging buffer's map_async reports.
type MapReceiver = mpsc::Receiver<std::result::Result<(), wgpu::BufferAsyncError>>;

/// A chunk of averaging iterations submitted and being mapped.
struct Pending {
    chunk: usize,
    receiver: MapReceiver,
    index: wgpu::SubmissionIndex,
}

const FLAG_CHATTERING: u32 = 1;
const FLAG_NONFINITE: u32 = 2;
const FLAG_RANK_ONE: u32 = 4;
const FLAG_RANK_TWO: u32 = 8;
const FLAG_TRUNCATED: u32 = 16;
const FLAG_SLIDING: u32 = 64;
