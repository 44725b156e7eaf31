//! A period map's GPU schedule, on `schedule`'s skeleton: its buffers, its
//! dispatches, and what a chunk's read-back turns into (host QR).
//!
//! Per map iteration, and per part of one when it is cut into sub-maps, the
//! host encodes `ceil(steps / chunk_steps)` integrate dispatches and one
//! finish dispatch; nothing crosses back to the host per iteration. The
//! transient runs references only, with no readback. While averaging, each
//! chunk of iterations writes its Jacobians, points and summaries into a
//! ring of slots that is copied to one of two staging buffers (the
//! skeleton's read-back ring); the host maps and accumulates QR for one
//! chunk while the GPU computes the next.

use std::time::Instant;

use nalgebra::{Const, DimMin, SMatrix};
use rayon::prelude::*;

use super::bindings::{
    Bindings, SweepControl, FLAG_CHATTERING, FLAG_NONFINITE, FLAG_RANK_ONE, FLAG_RANK_TWO,
    FLAG_SLIDING, FLAG_TOO_MANY_EVENTS, FLAG_TRUNCATED, SWEEP,
};
use super::context::Gpu;
use super::pipeline::{
    read_back, real_bytes, real_size, reals_from, wait_for, Dispatch, GpuRun, Timings,
};
use super::schedule::{
    self, buffer_of, buffer_with, Attempt, Pending, Ring, Run, Schedule, READABLE, STORAGE,
};
use super::seed::{lane_constants, Seeds};
use super::shader::{Kernel, Variant};
use super::stopwatch::{self, Stopwatch};
use crate::backend::options::RunOptions;
use crate::backend::progress::Attempt as Tally;
use crate::error::{Error, Result};
use crate::method::lane::{is_grazing, Failure, LanePlan};
use crate::method::{LaneAccumulator, LaneResult, MethodSettings};
use crate::scene::{Precision, Scene};
use crate::system::{IterationStats, Part};

/// Steps per integrate dispatch with a wall on a software adapter. lavapipe
/// caps the loop iterations of one invocation at 65 535 (every loop
/// together, shared by a SIMD group; see `loop_budget_exhausted` in
/// shaders/shared/loop_budget.wgsl), and a step with impacts runs many loops:
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
        let real = real_size(variant.precision);
        let strides = SWEEP.strides(scene.system, &variant.defines());
        Layout {
            traj: variant.trajectories(),
            real,
            lane_stride: strides.lane,
            traj_stride: strides.traj,
            summary: 16 * strides.summary as u64,
            summary_stride: strides.summary,
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

/// A batch of a period map's lanes on the schedule's skeleton.
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
    debug_assert!(scene.lane_count() <= max_batch_lanes(gpu, scene, variant, settings, options));
    let sweep = Sweep::<D> {
        scene,
        settings,
        layout: Layout::new(scene, variant, settings),
        stopwatch: Stopwatch::new(gpu),
        dispatch_steps: options.dispatch_steps,
    };
    schedule::run(gpu, variant, options, sweep)
}

/// A period map's schedule: per try, a [`Batch`] of the scene's lanes.
struct Sweep<'a, const D: usize> {
    scene: &'a Scene,
    settings: &'a MethodSettings,
    layout: Layout,
    stopwatch: Option<Stopwatch>,
    /// The steps per dispatch the run asks for, if any.
    dispatch_steps: Option<usize>,
}

impl<const D: usize> Schedule for Sweep<'_, D>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    const BINDINGS: &'static Bindings = &SWEEP;

    fn first_chunk(&self, run: &Run) -> usize {
        let software_stops = run.variant.wall && !run.gpu.summary.is_hardware();
        let default_chunk = if software_stops {
            SOFTWARE_WALL_CHUNK
        } else {
            usize::MAX
        };
        self.dispatch_steps.unwrap_or(default_chunk)
    }

    fn attempt(&mut self, run: &Run, max_chunk: usize) -> Result<Attempt> {
        let count = self.scene.lane_count();
        let batch = Batch::<D>::new(
            run,
            self.stopwatch.as_ref(),
            self.scene,
            self.settings,
            &self.layout,
            max_chunk,
        );
        let chunk_steps = batch.chunk_steps;
        let bytes_per_lane = batch.device_bytes / count as u64;
        let (lanes, timings) = batch.run(run)?;
        Ok(Attempt {
            lanes,
            timings,
            chunk_steps,
            retries: 0,
            bytes_per_lane,
        })
    }
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
    staging: Ring,
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
    fn new(
        run: &Run,
        stopwatch: Option<&'a Stopwatch>,
        scene: &'a Scene,
        settings: &'a MethodSettings,
        layout: &'a Layout,
        max_chunk: usize,
    ) -> Self {
        let (gpu, variant) = (run.gpu, run.variant);
        let count = scene.lane_count();
        let precision = variant.precision;
        let steps = if scene.system.is_flow {
            settings.flow.steps_per_period
        } else {
            1
        };
        // The backend makes the steps a multiple of the parts (`gpu::plan::lane_plan`).
        assert_eq!(steps % layout.parts, 0, "steps are whole parts");
        let part_steps = steps / layout.parts;
        let (lane_data, periods) = lane_constants(scene, settings, layout.lane_stride, steps);
        let seeds = Seeds::new::<D>(
            scene,
            settings,
            (layout.traj, layout.traj_stride),
            variant.surfaces(),
            precision,
        );
        let per_iteration = layout.per_iteration() * count as u64;
        let ring = ring_size(gpu, layout, settings, count, per_iteration);
        let ring = if gpu.summary.is_hardware() {
            ring
        } else {
            ring.min((SOFTWARE_CHUNK_STEPS / (count * layout.traj * steps).max(1)).max(1))
        };
        let lane_steps = run.dispatch.lane_steps;
        let chunk = |trajectories: usize| (lane_steps / trajectories.max(1)).clamp(1, steps);
        // While averaging a dispatch stops at the end of a part.
        let chunk_steps = chunk(count * layout.traj).min(part_steps).min(max_chunk);
        let transient_chunk_steps = chunk(count).min(max_chunk);
        let control = |transient: bool, chunk_steps: usize| SweepControl {
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
            variant,
            layout,
            stopwatch.is_some(),
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
            transient_control: b.bind_group(run, &b.transient_uniform),
            averaging_control: b.bind_group(run, &b.averaging_uniform),
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
        run: &Run,
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
            run.dispatch.grid(invocations),
            run.dispatch.grid(self.count),
        );
        let integrate = run.kernels.pipeline(Kernel::Integrate);
        let finish = run.kernels.pipeline(Kernel::Finish);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some(if transient { "transient" } else { "averaging" }),
            timestamp_writes: self.stopwatch.map(|s| s.writes(slot)),
        });
        pass.set_bind_group(0, bind_group, &[]);
        for _ in 0..iterations * parts {
            pass.set_pipeline(integrate);
            for _ in 0..part_steps.div_ceil(chunk) {
                pass.dispatch_workgroups(invocations.0, invocations.1, 1);
            }
            pass.set_pipeline(finish);
            pass.dispatch_workgroups(lanes.0, lanes.1, 1);
        }
    }

    /// The batch's lanes, or `None` when a dispatch ran past the adapter's
    /// loop cap (the lanes are then wrong and the batch must be redone).
    fn run(self, run: &Run) -> Result<(Option<Vec<LaneResult>>, Timings)> {
        let mut timings = Timings::default();
        let mut progress = run.progress.attempt();
        let start = Instant::now();
        self.transient(run, &mut progress, &mut timings)?;
        // The reference points x_0 the first averaging iteration starts from,
        // for re-estimating it should it graze.
        let mut previous: Vec<Option<[f64; D]>> = vec![None; self.count];
        if self.grazing.is_some() {
            previous = self
                .reference_states(run.gpu)?
                .into_iter()
                .map(Some)
                .collect();
        }
        timings.transient = start.elapsed();
        let start = Instant::now();
        let lanes = self.average(run, &mut progress, &mut previous, &mut timings)?;
        timings.averaging = start.elapsed();
        if lanes.is_none() {
            progress.undo();
        }
        Ok((lanes, timings))
    }

    /// The transient: references only, no readback.
    fn transient(&self, run: &Run, progress: &mut Tally, timings: &mut Timings) -> Result<()> {
        let (device, settings) = (&run.gpu.device, self.settings);
        let per_submit = (SUBMIT_LANE_STEPS / (self.count * self.steps).max(1)).max(1);
        let mut done = 0;
        while done < settings.transient {
            if settings.flow.stop.requested() {
                return Err(Error::Stopped);
            }
            let n = per_submit.min(settings.transient - done);
            let mut encoder = device.create_command_encoder(&Default::default());
            let slot = stopwatch::TRANSIENT_SLOT;
            self.encode_iterations(&mut encoder, run, true, n, slot);
            if let (Some(s), Some(ticks)) = (self.stopwatch, &self.transient_ticks) {
                s.copy_out(&mut encoder, slot, ticks, 0);
            }
            let index = run.gpu.queue.submit([encoder.finish()]);
            wait_for(device, index)?;
            if let (Some(s), Some(ticks)) = (self.stopwatch, &self.transient_ticks) {
                let busy = read_back(device, ticks, |bytes| s.elapsed(bytes))?;
                *timings.gpu_busy.get_or_insert_default() += busy;
            }
            done += n;
            progress.advance((self.count * n) as u64);
        }
        Ok(())
    }

    /// Averaging, streamed in chunks of `ring` iterations through the
    /// read-back ring: the lanes, or `None` when a dispatch ran past the
    /// adapter's loop cap.
    fn average(
        &self,
        run: &Run,
        progress: &mut Tally,
        previous: &mut [Option<[f64; D]>],
        timings: &mut Timings,
    ) -> Result<Option<Vec<LaneResult>>> {
        let (gpu, settings) = (run.gpu, self.settings);
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
        for c in 0..=chunks.len() {
            let submitted = if c < chunks.len() {
                if settings.flow.stop.requested() {
                    // Let the chunk in flight finish before its buffers go.
                    if let Some(in_flight) = &pending {
                        Ring::wait(gpu, in_flight, timings)?;
                    }
                    return Err(Error::Stopped);
                }
                let mut encoder = gpu.device.create_command_encoder(&Default::default());
                let slot = (c % 2) as u32;
                self.encode_iterations(&mut encoder, run, false, chunks[c].1, slot);
                self.copy_to_staging(&mut encoder, self.staging.slot(c), chunks[c].1);
                if let Some(s) = self.stopwatch {
                    s.copy_out(&mut encoder, slot, self.staging.slot(c), self.ticks_offset);
                }
                Some(self.staging.submit(gpu, encoder, c))
            } else {
                None
            };
            let Some(done) = std::mem::replace(&mut pending, submitted) else {
                continue;
            };
            let (first, n) = chunks[done.chunk];
            if !self.collect(gpu, &mut accumulators, previous, (first, n), done, timings)? {
                // Let the chunk in flight finish before its buffers go.
                if let Some(in_flight) = &pending {
                    Ring::wait(gpu, in_flight, timings)?;
                }
                return Ok(None);
            }
            progress.advance((self.count * n) as u64);
        }
        Ok(Some(
            accumulators
                .into_iter()
                .map(LaneAccumulator::finish)
                .collect(),
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
        (first_iteration, n): (usize, usize),
        pending: Pending,
        timings: &mut Timings,
    ) -> Result<bool> {
        Ring::wait(gpu, &pending, timings)?;
        let start = Instant::now();
        self.staging.read(pending, |view| {
            let chunk = self.readback(view, n);
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
            !truncated
        })
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
            let failed = (0..parts)
                .map(|p| chunk.summary(stride * slot(p))[1])
                .find(|flags| flags & FLAG_NONFINITE != 0);
            if let Some(flags) = failed {
                // The cause is kept beside the failure (FLAG_STICKY).
                let cause = if flags & FLAG_TOO_MANY_EVENTS != 0 {
                    Failure::TooManyEvents
                } else {
                    Failure::NonFinite
                };
                acc.fail_because(self.settings.transient + first_iteration + j, cause);
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
        too_many_events: flags & FLAG_TOO_MANY_EVENTS != 0,
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
    staging: Ring,
    transient_ticks: Option<wgpu::Buffer>,
}

impl Buffers {
    /// The buffers of `count` lanes with `slots` result slots (ring ×
    /// parts × lanes), the staging buffers holding `ticks_offset` bytes of
    /// results and the timestamps after them when `timed`.
    #[allow(clippy::too_many_arguments)]
    fn new(
        gpu: &Gpu,
        variant: &Variant,
        layout: &Layout,
        timed: bool,
        (count, slots, ticks_offset): (usize, u64, u64),
        lane_data: &[f64],
        seeds: &Seeds,
        [transient, averaging]: [SweepControl; 2],
    ) -> Buffers {
        let precision = variant.precision;
        let uniform = |label: &str, control: &SweepControl| {
            buffer_with(
                gpu,
                label,
                bytemuck::bytes_of(control),
                wgpu::BufferUsages::UNIFORM,
            )
        };
        let reals = |label: &str, values: &[f64]| {
            buffer_with(gpu, label, &real_bytes(values, precision), STORAGE)
        };
        let results = |label: &str, bytes_per_slot: u64| {
            buffer_of(gpu, label, bytes_per_slot * slots, STORAGE)
        };
        let ticks_bytes = if timed { stopwatch::TICKS_BYTES } else { 0 };
        Buffers {
            transient_uniform: uniform("control (transient)", &transient),
            averaging_uniform: uniform("control (averaging)", &averaging),
            lanes: buffer_with(
                gpu,
                "lanes",
                &real_bytes(lane_data, precision),
                wgpu::BufferUsages::STORAGE,
            ),
            traj: reals("trajectories", &seeds.traj),
            counts: buffer_with(gpu, "counts", bytemuck::cast_slice(&seeds.counts), STORAGE),
            // Per trajectory, its impacts on each stop: none yet.
            crossings: variant.wall.then(|| {
                let none = vec![[0u32; 4]; count * layout.traj];
                buffer_with(gpu, "crossings", bytemuck::cast_slice(&none), STORAGE)
            }),
            summary: results("summary", layout.summary),
            deltas: variant.lyapunov.then(|| reals("deltas", &seeds.deltas)),
            jac: variant
                .lyapunov
                .then(|| results("jacobians", layout.jacobian)),
            points: results("points", layout.point),
            fluxes: variant.surfaces().then(|| results("fluxes", layout.flux)),
            staging: Ring::new(gpu, 2, ticks_offset + ticks_bytes),
            transient_ticks: timed
                .then(|| buffer_of(gpu, "transient ticks", ticks_bytes, READABLE)),
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
            .map(|b| b.size())
            .sum::<u64>()
            + self.staging.device_bytes()
    }

    /// The bind group of the sweep's kernels with `uniform` as the control,
    /// each buffer bound by its name in the kernels (`bindings::SWEEP`).
    fn bind_group(&self, run: &Run, uniform: &wgpu::Buffer) -> wgpu::BindGroup {
        run.kernels
            .bind_group(run.gpu, run.variant, |name| match name {
                "control" => Some(uniform),
                "lanes" => Some(&self.lanes),
                "traj" => Some(&self.traj),
                "counts" => Some(&self.counts),
                "summary" => Some(&self.summary),
                "deltas" => self.deltas.as_ref(),
                "jac" => self.jac.as_ref(),
                "points" => Some(&self.points),
                "crossings" => self.crossings.as_ref(),
                "fluxes" => self.fluxes.as_ref(),
                _ => None,
            })
    }
}
