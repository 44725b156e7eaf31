//! Poincaré maps on the GPU, on `schedule`'s skeleton: the CPU's algorithm
//! (`system::section`), with its RK4 steps on the device.
//!
//! One iteration of a section map is a return of the reference to the
//! section, then the tangent map of that return in parts, each part a
//! fixed number of steps of the reference and its copies from a frame
//! (see `SectionFlow::tangent_factors`). The number of steps is the
//! lane's own (its return time), and so is the number of parts. The host
//! runs each lane through these stages with the very functions the CPU
//! path calls (`tangent_parts`, `part_starts`, `part_end`,
//! `last_factor`), and hands every stepping to the GPU as rounds of jobs
//! across lanes: one round for the returns, then one per part. The kernel
//! (`shaders/section.wgsl`) only steps: it leaves a crossing's step to the
//! host, which locates it as the CPU does (`crossing_in_step`). So on an
//! adapter whose f64 RK4 step is the CPU's to the bit (lavapipe), a lane's
//! exponents are the CPU path's to the bit, chaotic lanes included.
//!
//! In f32 the kernel compensates its steps (Kahan) and the host works in
//! f64 from the f32 states.
//!
//! The price is a readback per round (a few per iteration), which a period
//! map's schedule avoids; the steps, which dominate, run on the GPU. A
//! state-dependent divergence (Rössler's) is integrated along the
//! reference on the host, the CPU's integral, so that the sum rule holds.

use std::time::Instant;

use nalgebra::{Const, DimMin, SMatrix};
use rayon::prelude::*;

use super::bindings::{
    Bindings, SectionControl, ADVANCE, CROSSED, DONE, MISSED, SECTION, SEEK, TRUNCATED,
};
use super::context::Gpu;
use super::pipeline::{gpu_error, real_bytes, real_size, reals_from, Dispatch, GpuRun, Timings};
use super::schedule::{self, buffer_of, buffer_with, Attempt, Ring, Run, Schedule, STORAGE};
use super::shader::{Kernel, Variant};
use crate::backend::options::RunOptions;
use crate::backend::progress::Progress;
use crate::error::{Error, Result};
use crate::integrate::section::{crossing_in_step, Crossing};
use crate::method::lane::{not_run, plan_lane};
use crate::method::{LaneAccumulator, LaneResult, MethodSettings};
use crate::scene::{Precision, Scene};
use crate::system::section::{Return, SectionFlow, TangentParts};
use crate::system::{FlowSettings, IterationStats, System};

/// Steps per dispatch on a software adapter: lavapipe caps the loop
/// iterations of one invocation at 65 535 (see `SOFTWARE_WALL_CHUNK` in
/// sweep.rs), and a step of a model that calls math64's functions runs
/// loops of its own. A dispatch cut short stores nothing and is redone
/// with dispatches `TRUNCATION_RETRY` times shorter.
const SOFTWARE_CHUNK: usize = 1024;

/// Runs the lanes of `scene` (one device batch: at most
/// [`max_batch_lanes`]) of a section model on the GPU.
pub fn run(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &RunOptions,
) -> Result<GpuRun> {
    debug_assert!(scene.lane_count() <= max_batch_lanes(gpu, scene, variant, settings, options));
    match scene.system.dimension() {
        1 => schedule::run(
            gpu,
            variant,
            options,
            Section::<1, 2>::new(scene, variant, settings),
        ),
        2 => schedule::run(
            gpu,
            variant,
            options,
            Section::<2, 3>::new(scene, variant, settings),
        ),
        3 => schedule::run(
            gpu,
            variant,
            options,
            Section::<3, 4>::new(scene, variant, settings),
        ),
        d => Err(gpu_error(format!(
            "a Poincaré map of dimension {d} is not supported on the GPU (1 to 3 are)"
        ))),
    }
}

/// The bytes a lane takes in the round's buffers (every job's table entry
/// and two states), and its trajectories.
fn device_bytes_per_lane(
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
) -> (u64, usize) {
    let d = scene.system.dimension();
    let trajectories = 1 + if settings.lyapunov {
        settings.difference.copies(d)
    } else {
        0
    };
    let real = real_size(variant.precision) as usize;
    (
        ((16 + 2 * real * (d + 1)) * trajectories) as u64,
        trajectories,
    )
}

/// The most lanes of `scene` one device batch holds: the readback of a
/// round in one buffer, the states in one binding, the jobs in one
/// dispatch (and at most `options.max_batch_lanes`).
pub fn max_batch_lanes(
    gpu: &Gpu,
    scene: &Scene,
    variant: &Variant,
    settings: &MethodSettings,
    options: &RunOptions,
) -> usize {
    let (per_lane, trajectories) = device_bytes_per_lane(scene, variant, settings);
    let by_buffer = gpu.max_binding() / per_lane;
    let by_dispatch = (Dispatch::new(gpu, options).max_invocations() / trajectories) as u64;
    (by_buffer.min(by_dispatch) as usize)
        .min(options.max_batch_lanes.unwrap_or(usize::MAX))
        .max(1)
}

/// One trajectory's stepping, for one round.
struct Job<const N: usize> {
    lane: u32,
    /// To the section (at most `limit` steps), or `limit` steps.
    seek: bool,
    limit: u32,
    h: f64,
    y: [f64; N],
}

/// How a job ended.
enum Outcome<const N: usize> {
    /// The state after the job's steps.
    Advanced([f64; N]),
    /// The section was crossed in step `step`, from `before` to `after`.
    Crossed {
        step: usize,
        before: [f64; N],
        after: [f64; N],
    },
    /// No crossing within the steps allowed (or the state overflowed).
    Missed,
}

/// The kernel and its buffers, sized for `capacity` jobs.
struct Stepper<'a> {
    gpu: &'a Gpu,
    pipeline: wgpu::ComputePipeline,
    bind_group: wgpu::BindGroup,
    control: wgpu::Buffer,
    jobs: wgpu::Buffer,
    steps: wgpu::Buffer,
    states: wgpu::Buffer,
    /// One staging buffer: a round's table and states are read back
    /// before its next dispatches.
    readback: Ring,
    dispatch: Dispatch,
    /// The reals of the buffers.
    precision: Precision,
    /// Steps per dispatch.
    chunk: usize,
    retries: usize,
    /// The most steps a return has taken so far: how many to dispatch for
    /// the next returns before looking.
    longest_return: usize,
    timings: Timings,
}

impl<'a> Stepper<'a> {
    /// The kernel of `run` with its buffers for `capacity` jobs of states
    /// of `dim` reals, at `chunk` steps per dispatch.
    fn new(run: &Run<'a>, lane_data: &[f64], capacity: usize, dim: usize, chunk: usize) -> Self {
        let gpu = run.gpu;
        let capacity = capacity as u64;
        let control = buffer_of(
            gpu,
            "section control",
            std::mem::size_of::<SectionControl>() as u64,
            wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
        );
        let precision = run.variant.precision;
        let real = real_size(precision);
        let lanes = buffer_with(
            gpu,
            "section lanes",
            &real_bytes(lane_data, precision),
            wgpu::BufferUsages::STORAGE,
        );
        let jobs = buffer_of(gpu, "section jobs", 16 * capacity, STORAGE);
        let steps = buffer_of(gpu, "section steps", real * capacity, STORAGE);
        let states = buffer_of(
            gpu,
            "section states",
            2 * real * dim as u64 * capacity,
            STORAGE,
        );
        let readback = Ring::new(gpu, 1, (16 + 2 * real * dim as u64) * capacity);
        let bind_group = run.kernels.bind_group(gpu, run.variant, |name| match name {
            "control" => Some(&control),
            "lanes" => Some(&lanes),
            "jobs" => Some(&jobs),
            "steps" => Some(&steps),
            "states" => Some(&states),
            _ => None,
        });
        Stepper {
            gpu,
            pipeline: run.kernels.pipeline(Kernel::Section).clone(),
            bind_group,
            control,
            jobs,
            steps,
            states,
            readback,
            dispatch: run.dispatch,
            precision,
            chunk,
            retries: 0,
            longest_return: 0,
            timings: Timings::default(),
        }
    }

    /// Runs one round of jobs to their ends.
    fn run<const N: usize>(&mut self, jobs: &[Job<N>]) -> Result<Vec<Outcome<N>>> {
        if jobs.is_empty() {
            return Ok(Vec::new());
        }
        let queue = &self.gpu.queue;
        let mut table: Vec<[u32; 4]> = jobs
            .iter()
            .map(|j| [j.lane, if j.seek { SEEK } else { ADVANCE }, j.limit, 0])
            .collect();
        let hs: Vec<f64> = jobs.iter().map(|j| j.h).collect();
        let mut states = vec![0.0; 2 * N * jobs.len()];
        for (k, j) in jobs.iter().enumerate() {
            states[2 * N * k..2 * N * k + N].copy_from_slice(&j.y);
        }
        queue.write_buffer(&self.jobs, 0, bytemuck::cast_slice(&table));
        queue.write_buffer(&self.steps, 0, &real_bytes(&hs, self.precision));
        let state_bytes = real_bytes(&states, self.precision);
        queue.write_buffer(&self.states, 0, &state_bytes);
        let jobs_bytes = 16 * jobs.len() as u64;
        let states_bytes = state_bytes.len() as u64;
        let ahead = self.steps_ahead(jobs);
        loop {
            let (read_jobs, read_states) =
                self.dispatch(jobs.len(), ahead, jobs_bytes, states_bytes)?;
            table = read_jobs;
            states = read_states;
            if table.iter().any(|j| j[1] & TRUNCATED != 0) {
                // The adapter cut a dispatch's loops short: that dispatch
                // stored nothing, so the jobs go on from where they were,
                // with shorter dispatches.
                self.chunk = schedule::shorter(self.chunk)?;
                for j in &mut table {
                    j[1] &= !TRUNCATED;
                }
                queue.write_buffer(&self.jobs, 0, bytemuck::cast_slice(&table));
                self.retries += 1;
                continue;
            }
            if table.iter().all(|j| j[1] != ADVANCE && j[1] != SEEK) {
                break;
            }
        }
        Ok(self.outcomes::<N>(&table, &states))
    }

    /// Steps to dispatch before each look: all of them for ADVANCE, the
    /// longest return so far for SEEK.
    fn steps_ahead<const N: usize>(&self, jobs: &[Job<N>]) -> usize {
        jobs.iter()
            .map(|j| {
                if j.seek {
                    self.longest_return.max(1)
                } else {
                    j.limit as usize
                }
            })
            .max()
            .unwrap_or(1)
            .min(jobs.iter().map(|j| j.limit as usize).max().unwrap_or(1))
            .max(1)
    }

    /// One submission: `ahead` steps of every job in dispatches of
    /// `chunk` steps, then the jobs' table and states read back.
    fn dispatch(
        &mut self,
        job_count: usize,
        ahead: usize,
        jobs_bytes: u64,
        states_bytes: u64,
    ) -> Result<(Vec<[u32; 4]>, Vec<f64>)> {
        let queue = &self.gpu.queue;
        let control = SectionControl {
            job_count: job_count as u32,
            chunk_steps: self.chunk as u32,
            opaque_zero: 0,
            pad: 0,
        };
        queue.write_buffer(&self.control, 0, bytemuck::bytes_of(&control));
        let dispatches = ahead.div_ceil(self.chunk);
        let mut encoder = self.gpu.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("section"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &self.bind_group, &[]);
            let (x, y) = self.dispatch.grid(job_count);
            for _ in 0..dispatches {
                pass.dispatch_workgroups(x, y, 1);
            }
        }
        let staging = self.readback.slot(0);
        encoder.copy_buffer_to_buffer(&self.jobs, 0, staging, 0, jobs_bytes);
        encoder.copy_buffer_to_buffer(&self.states, 0, staging, jobs_bytes, states_bytes);
        let pending = self.readback.submit(self.gpu, encoder, 0);
        Ring::wait(self.gpu, &pending, &mut self.timings)?;
        self.readback.read(pending, |b| {
            let jobs_part = &b[..jobs_bytes as usize];
            let states_part = &b[jobs_bytes as usize..(jobs_bytes + states_bytes) as usize];
            (
                bytemuck::pod_collect_to_vec::<u8, [u32; 4]>(jobs_part),
                reals_from(states_part, self.precision),
            )
        })
    }

    /// What each job's table entry and states say happened.
    fn outcomes<const N: usize>(&mut self, table: &[[u32; 4]], states: &[f64]) -> Vec<Outcome<N>> {
        table
            .iter()
            .enumerate()
            .map(|(k, j)| {
                let state = |offset: usize| -> [f64; N] {
                    crate::array::from_fn(|i| states[2 * N * k + offset + i])
                };
                match j[1] {
                    CROSSED => {
                        self.longest_return = self.longest_return.max(j[3] as usize + 1);
                        Outcome::Crossed {
                            step: j[3] as usize,
                            before: state(0),
                            after: state(N),
                        }
                    }
                    MISSED => Outcome::Missed,
                    mode => {
                        debug_assert_eq!(mode, DONE);
                        Outcome::Advanced(state(0))
                    }
                }
            })
            .collect()
    }
}

/// A lane through its iterations.
struct Lane<const D: usize, const N: usize> {
    system: SectionFlow<D, N>,
    /// The state of the flow the lane starts from.
    initial: [f64; N],
    flow: FlowSettings,
    x: [f64; D],
    accumulator: LaneAccumulator<D>,
    /// The result, once the lane has one (not run, or failed in the
    /// transient).
    result: Option<LaneResult>,
    /// The iteration under way: its statistics, its return, its tangent
    /// parts and the factors so far.
    stats: IterationStats,
    back: Option<Return<D>>,
    tangent: Option<TangentParts<N>>,
    factors: Vec<SMatrix<f64, D, D>>,
}

impl<const D: usize, const N: usize> Lane<D, N>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    fn active(&self) -> bool {
        self.result.is_none()
    }

    fn h(&self) -> f64 {
        SectionFlow::<D, N>::return_steps(&self.flow).0
    }

    fn return_job(&self, lane: usize, start: [f64; N]) -> Job<N> {
        let (h, max_steps) = SectionFlow::<D, N>::return_steps(&self.flow);
        Job {
            lane: lane as u32,
            seek: true,
            limit: max_steps.min(u32::MAX as usize) as u32,
            h,
            y: start,
        }
    }

    /// The return that ended in `outcome`, from `start`.
    fn return_of(&self, start: &[f64; N], outcome: Outcome<N>) -> Return<D> {
        let crossing: Crossing<N> = match outcome {
            Outcome::Crossed {
                step,
                before,
                after,
            } => Some(crossing_in_step(
                self.system.flow(),
                self.system.section(),
                &before,
                &after,
                self.h(),
                step,
            )),
            _ => None,
        };
        self.system.return_from(start, crossing)
    }
}

/// A Poincaré map's schedule: per batch, the lanes planned, their
/// transient, then their averaging iterations, each a round of returns
/// (and of tangents) for every lane still running.
struct Section<'a, const D: usize, const N: usize> {
    scene: &'a Scene,
    settings: &'a MethodSettings,
    /// Device bytes per lane in the round's buffers, and trajectories per
    /// lane: the reference and its copies.
    per_lane: (u64, usize),
}

impl<'a, const D: usize, const N: usize> Section<'a, D, N> {
    fn new(scene: &'a Scene, variant: &Variant, settings: &'a MethodSettings) -> Self {
        Section {
            scene,
            settings,
            per_lane: device_bytes_per_lane(scene, variant, settings),
        }
    }
}

impl<const D: usize, const N: usize> Schedule for Section<'_, D, N>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    const BINDINGS: &'static Bindings = &SECTION;

    /// On a hardware GPU the dispatch's lane-steps over every job; on a
    /// software adapter [`SOFTWARE_CHUNK`].
    fn first_chunk(&self, run: &Run) -> usize {
        if run.gpu.summary.is_hardware() {
            let capacity = self.scene.lane_count() * self.per_lane.1;
            (run.dispatch.lane_steps / capacity.max(1)).max(1)
        } else {
            SOFTWARE_CHUNK
        }
    }

    /// The whole batch: a round cut short is redone within it, with
    /// shorter dispatches (`Stepper::run`), so a try always holds.
    fn attempt(&mut self, run: &Run, chunk: usize) -> Result<Attempt> {
        let (scene, settings) = (self.scene, self.settings);
        let start = Instant::now();
        let count = scene.lane_count();
        let mut lanes = plan_lanes::<D, N>(scene, settings);
        // Per lane: its parameters and the section's position.
        let mut lane_data = Vec::new();
        for (k, lane) in lanes.iter().enumerate() {
            lane_data.extend_from_slice(&scene.lane_params(k).values);
            lane_data.push(lane.system.section().at);
        }
        let (per_lane, trajectories) = self.per_lane;
        let mut stepper = Stepper::new(run, &lane_data, count * trajectories, N, chunk);
        stepper.timings.setup = start.elapsed();

        let transient_start = Instant::now();
        transient(&mut stepper, &mut lanes, settings, &run.progress)?;
        stepper.timings.transient = transient_start.elapsed();

        let averaging = Instant::now();
        average(&mut stepper, &mut lanes, settings, &run.progress)?;
        stepper.timings.averaging = averaging.elapsed();
        let results = lanes
            .into_iter()
            .map(|lane| match lane.result {
                Some(result) => result,
                None => lane.accumulator.finish(),
            })
            .collect();
        Ok(Attempt {
            lanes: Some(results),
            timings: stepper.timings,
            chunk_steps: stepper.chunk,
            retries: stepper.retries,
            bytes_per_lane: per_lane + 8 * (scene.system.parameters.len() as u64 + 1),
        })
    }
}

/// The lanes of `scene` (a batch), each planned; a lane whose plan is not
/// affordable has its result already.
fn plan_lanes<const D: usize, const N: usize>(
    scene: &Scene,
    settings: &MethodSettings,
) -> Vec<Lane<D, N>>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    (0..scene.lane_count())
        .map(|k| {
            let params = scene.lane_params(k);
            let system = SectionFlow::<D, N>::new(&params);
            let plan = plan_lane(&system, settings);
            let flow = FlowSettings {
                steps_per_period: plan.steps_per_period,
                ..settings.flow.clone()
            };
            let result = (!plan.affordable()).then(|| not_run(settings, D, system.period(), plan));
            let start = scene.lane_initial_state(k);
            Lane {
                accumulator: LaneAccumulator::new(settings, system.period(), plan),
                system,
                initial: crate::array::from_fn(|i| start[i]),
                flow,
                x: [f64::NAN; D],
                result,
                stats: IterationStats::default(),
                back: None,
                tangent: None,
                factors: Vec::new(),
            }
        })
        .collect()
}

/// The first point (from the scene's state of the flow to the section),
/// then the transient's returns; a lane that goes non-finite fails there.
fn transient<const D: usize, const N: usize>(
    stepper: &mut Stepper,
    lanes: &mut [Lane<D, N>],
    settings: &MethodSettings,
    progress: &Progress,
) -> Result<()>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let count = lanes.len();
    returns(stepper, lanes, |lane| lane.initial)?;
    for lane in lanes.iter_mut().filter(|l| l.active()) {
        lane.x = lane.back.take().expect("a return").image;
        if !lane.x.iter().all(|v| v.is_finite()) {
            let mut accumulator = lane.accumulator.clone();
            accumulator.fail_at(0, &lane.x, &IterationStats::default());
            lane.result = Some(accumulator.finish());
        }
    }
    for n in 0..settings.transient {
        if settings.flow.stop.requested() {
            return Err(Error::Stopped);
        }
        returns(stepper, lanes, |lane| lane.system.lift(&lane.x))?;
        for lane in lanes.iter_mut().filter(|l| l.active()) {
            lane.x = lane.back.take().expect("a return").image;
            lane.system.wrap(&mut lane.x);
            if !lane.x.iter().all(|v| v.is_finite()) {
                let mut accumulator = lane.accumulator.clone();
                accumulator.fail_at(n, &lane.x, &IterationStats::default());
                lane.result = Some(accumulator.finish());
            }
        }
        progress.advance(count as u64);
    }
    Ok(())
}

/// The averaging iterations: each lane's return, its tangent factors, then
/// its accumulator on the host.
fn average<const D: usize, const N: usize>(
    stepper: &mut Stepper,
    lanes: &mut [Lane<D, N>],
    settings: &MethodSettings,
    progress: &Progress,
) -> Result<()>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let count = lanes.len();
    for _ in 0..settings.iterations {
        if settings.flow.stop.requested() {
            return Err(Error::Stopped);
        }
        for lane in lanes.iter_mut() {
            lane.stats = IterationStats::default();
            lane.factors.clear();
        }
        returns(stepper, lanes, |lane| lane.system.lift(&lane.x))?;
        // In the CPU's order: the return's terms, then each part's
        // divergence integral (the same sum to the bit).
        for lane in lanes.iter_mut().filter(|l| l.active()) {
            lane.back.expect("a return").add_to(&mut lane.stats);
        }
        if settings.lyapunov {
            tangents(stepper, lanes, settings)?;
        }
        let host = Instant::now();
        lanes
            .par_iter_mut()
            .filter(|l| l.active())
            .for_each(|lane| {
                let mut next = lane.back.take().expect("a return").image;
                lane.system.wrap(&mut next);
                if lane.accumulator.push(&next, &lane.factors, &lane.stats) {
                    lane.x = next;
                } else {
                    lane.result = Some(lane.accumulator.clone().finish());
                }
            });
        stepper.timings.host_qr += host.elapsed();
        progress.advance(count as u64);
    }
    Ok(())
}

/// A return of every active lane's reference from `start(lane)`, left in
/// `lane.back`.
fn returns<const D: usize, const N: usize>(
    stepper: &mut Stepper,
    lanes: &mut [Lane<D, N>],
    start: impl Fn(&Lane<D, N>) -> [f64; N],
) -> Result<()>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    let active: Vec<usize> = (0..lanes.len()).filter(|&k| lanes[k].active()).collect();
    let starts: Vec<[f64; N]> = active.iter().map(|&k| start(&lanes[k])).collect();
    let jobs: Vec<Job<N>> = active
        .iter()
        .zip(&starts)
        .map(|(&k, &y)| lanes[k].return_job(k, y))
        .collect();
    let outcomes = stepper.run(&jobs)?;
    let host = Instant::now();
    let backs: Vec<Return<D>> = active
        .par_iter()
        .zip(starts.par_iter())
        .zip(outcomes.into_par_iter())
        .map(|((&k, start), outcome)| lanes[k].return_of(start, outcome))
        .collect();
    for (&k, back) in active.iter().zip(backs) {
        lanes[k].back = Some(back);
    }
    stepper.timings.host_qr += host.elapsed();
    Ok(())
}

/// The tangent maps of the active lanes' returns, part by part, into
/// `lane.factors` (with their divergence integrals in `lane.stats`).
fn tangents<const D: usize, const N: usize>(
    stepper: &mut Stepper,
    lanes: &mut [Lane<D, N>],
    settings: &MethodSettings,
) -> Result<()>
where
    Const<D>: DimMin<Const<D>, Output = Const<D>>,
{
    for lane in lanes.iter_mut().filter(|l| l.active()) {
        let back = lane.back.as_ref().expect("a return");
        lane.tangent = back
            .time
            .is_finite()
            .then(|| lane.system.tangent_parts(&lane.x, back.time, &lane.flow));
    }
    let parts = lanes
        .iter()
        .filter_map(|l| l.tangent.as_ref().map(|t| t.parts))
        .max()
        .unwrap_or(0);
    for part in 0..parts {
        let in_part = |l: &Lane<D, N>| l.tangent.as_ref().is_some_and(|t| part < t.parts);
        let host = Instant::now();
        // Per lane in this part: its trajectories' starts.
        let starts: Vec<(usize, f64, Vec<[f64; N]>)> = lanes
            .par_iter()
            .enumerate()
            .filter(|(_, l)| l.active() && in_part(l))
            .map(|(k, l)| {
                let t = l.tangent.as_ref().expect("in a part");
                let (delta, ys) =
                    l.system
                        .part_starts(t, settings.perturbation, settings.difference);
                (k, delta, ys)
            })
            .collect();
        stepper.timings.host_qr += host.elapsed();
        let jobs: Vec<Job<N>> = starts
            .iter()
            .flat_map(|(k, _, ys)| {
                let t = lanes[*k].tangent.as_ref().expect("in a part");
                ys.iter().map(move |&y| Job {
                    lane: *k as u32,
                    seek: false,
                    limit: t.steps as u32,
                    h: t.h,
                    y,
                })
            })
            .collect();
        let mut outcomes = stepper.run(&jobs)?.into_iter();
        let host = Instant::now();
        let mut ends: Vec<(usize, f64, Vec<[f64; N]>)> = Vec::with_capacity(starts.len());
        for (k, delta, ys) in starts {
            let reached = (0..ys.len())
                .map(|_| match outcomes.next() {
                    Some(Outcome::Advanced(y)) => y,
                    _ => [f64::NAN; N],
                })
                .collect();
            ends.push((k, delta, reached));
        }
        let mut by_lane: Vec<Option<(f64, Vec<[f64; N]>)>> = vec![None; lanes.len()];
        for (k, delta, ys) in ends {
            by_lane[k] = Some((delta, ys));
        }
        lanes
            .par_iter_mut()
            .zip(by_lane.into_par_iter())
            .filter_map(|(lane, end)| end.map(|e| (lane, e)))
            .for_each(|(lane, (delta, ys))| {
                let t = lane.tangent.as_mut().expect("in a part");
                if let Some(integral) = lane.system.part_divergence(t, &settings.flow.stop) {
                    lane.stats.log_flux += integral;
                }
                let factor = lane.system.part_end(t, &ys, delta, settings.difference);
                lane.factors.push(factor);
            });
        stepper.timings.host_qr += host.elapsed();
    }
    for lane in lanes.iter_mut().filter(|l| l.active()) {
        if let (Some(t), Some(back)) = (&lane.tangent, &lane.back) {
            let last = lane.system.last_factor(t, &back.image);
            lane.factors.push(last);
        }
    }
    Ok(())
}
