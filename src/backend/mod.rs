//! Where the lanes run: the CPU reference path (the paper's method on RK4),
//! the exact closed-form tangent map, and the GPU ensemble.

pub mod cpu;
pub mod gpu;
pub mod options;
pub mod progress;

use std::time::{Duration, Instant};

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::method::lane::LanePlan;
use crate::method::{LaneResult, LaneStatus, MethodSettings};
use crate::plan::{cpu_twin, method_settings};
use crate::scene::{Backend, Precision, Scene};
use gpu::context::{self, Want};
use gpu::shader::Variant;
pub use options::RunOptions;
pub use progress::Progress;

/// The outcome of a sweep.
#[derive(Clone, Debug)]
pub struct Report {
    /// The backend that ran (never `Auto`).
    pub backend: Backend,
    /// The precision the lanes were computed in.
    pub precision: Precision,
    /// Why `auto` chose it, if it did.
    pub choice: Option<String>,
    /// One result per sweep value, in sweep order.
    pub lanes: Vec<LaneResult>,
    /// The expected exponent sum of each lane (volume law).
    pub expected_sums: Vec<f64>,
    pub elapsed: Duration,
    pub threads: usize,
    /// What the GPU did, on a GPU run.
    pub gpu: Option<GpuReport>,
}

/// The GPU part of a report.
#[derive(Clone, Debug)]
pub struct GpuReport {
    pub adapter: String,
    pub adapter_backend: String,
    /// The kernel variant (what was compiled in).
    pub variant: String,
    /// Where the kernels' sources came from when not from the binary
    /// (`LYAPSWEEP_SHADER_DIR`, for kernel experiments): a run says so.
    pub kernel_sources: Option<std::path::PathBuf>,
    pub timings: gpu::pipeline::Timings,
    /// Device batches (see [`gpu::max_batch_lanes`]).
    pub batches: usize,
    pub chunk_steps: usize,
    /// Batches redone with shorter dispatches (see `gpu::pipeline::GpuRun::retries`).
    pub retries: usize,
    /// Device memory per lane (see `gpu::pipeline::GpuRun::bytes_per_lane`;
    /// the largest batch's).
    pub bytes_per_lane: u64,
    pub validation: Option<Validation>,
    /// Indices of the sweep values the kernels flagged `sliding` (a motion
    /// on switches they do not integrate) and the CPU path recomputed.
    pub recomputed: Vec<usize>,
}

impl GpuReport {
    /// Adds the GPU part of a later batch, whose lanes start at lane
    /// `first` of this report's run.
    fn absorb(&mut self, batch: &GpuReport, first: usize) {
        self.timings.add(&batch.timings);
        self.batches += batch.batches;
        self.retries += batch.retries;
        self.bytes_per_lane = self.bytes_per_lane.max(batch.bytes_per_lane);
        self.chunk_steps = self.chunk_steps.min(batch.chunk_steps);
        self.recomputed
            .extend(batch.recomputed.iter().map(|k| first + k));
        if let (Some(v), Some(w)) = (&mut self.validation, &batch.validation) {
            v.lanes.extend(w.lanes.iter().map(|k| first + k));
            v.max_difference = v.max_difference.max(w.max_difference);
        }
    }
}

/// The CPU recomputation of a few sweep values of a GPU run.
#[derive(Clone, Debug)]
pub struct Validation {
    /// Indices of the recomputed sweep values.
    pub lanes: Vec<usize>,
    /// The largest difference found (see [`validation_difference`]).
    pub max_difference: f64,
    /// Above this a row is marked `gpu-mismatch`.
    pub tolerance: f64,
}

impl Report {
    /// Appends the report of the next batch, whose lanes start at lane
    /// `first` of this one's.
    fn append(&mut self, batch: Report, first: usize) {
        debug_assert_eq!(first, self.lanes.len());
        self.lanes.extend(batch.lanes);
        self.expected_sums.extend(batch.expected_sums);
        self.elapsed += batch.elapsed;
        if let (Some(gpu), Some(next)) = (&mut self.gpu, &batch.gpu) {
            gpu.absorb(next, first);
        }
    }

    /// The largest |λ_sum - expected_sum| over lanes that finished.
    pub fn max_sum_error(&self) -> Option<f64> {
        self.lanes
            .iter()
            .zip(&self.expected_sums)
            .filter(|(l, _)| !l.exponents.is_empty() && l.exponents.iter().all(|e| e.is_finite()))
            .map(|(l, expected)| (l.exponent_sum() - expected).abs())
            .filter(|e| !e.is_nan())
            .fold(None, |m, e| Some(m.map_or(e, |m: f64| m.max(e))))
    }

    /// The largest `lambda_error` over lanes that state one.
    pub fn max_error(&self) -> Option<f64> {
        self.lanes
            .iter()
            .map(|l| l.error)
            .filter(|e| e.is_finite())
            .fold(None, |m, e| Some(m.map_or(e, |m: f64| m.max(e))))
    }

    /// Lanes whose status is not `ok`.
    pub fn flagged(&self) -> usize {
        self.lanes
            .iter()
            .filter(|l| l.status != LaneStatus::Ok)
            .count()
    }
}

/// The per-precision tolerance of the GPU's validation against the CPU.
pub fn validation_tolerance(precision: Precision) -> f64 {
    match precision {
        Precision::F64 => 1e-6,
        Precision::F32 => 1e-3,
    }
}

/// The sum rule's tolerance for a lane: the precision's own accuracy, as
/// the GPU's validation holds it, relative to the exponents' scale
/// max(1, Σ|λ_i|), plus the error the row already states (`grazing_bound`,
/// its near-grazing iterations' estimate).
pub fn sum_rule_tolerance(precision: Precision, lane: &LaneResult) -> f64 {
    let scale = lane.exponents.iter().map(|e| e.abs()).sum::<f64>().max(1.0);
    let stated = if lane.grazing_bound.is_finite() {
        lane.grazing_bound
    } else {
        0.0
    };
    validation_tolerance(precision) * scale + stated
}

/// Marks `ok` lanes whose exponents miss the sum rule (the tool's built-in
/// accuracy check) by more than [`sum_rule_tolerance`]: an error the lane's
/// other checks did not catch (copies carried out of the linear regime by a
/// burst of expansion, the paper's linear impact location), which its
/// numbers carry.
fn flag_sum_rule(lanes: &mut [LaneResult], expected_sums: &[f64], precision: Precision) {
    lanes
        .par_iter_mut()
        .zip(expected_sums)
        .for_each(|(lane, &expected)| {
            let finite = lane.exponents.iter().all(|e| e.is_finite());
            if lane.status != LaneStatus::Ok || lane.exponents.is_empty() || !finite {
                return;
            }
            let miss = (lane.exponent_sum() - expected).abs();
            if miss > sum_rule_tolerance(precision, lane) {
                lane.status = LaneStatus::SumRule { miss };
            }
        });
}

/// Time scales of the flow's slowest mode (1/|μ|, see
/// `SystemInfo::slowest_rate`) that a lane's averaging must span, or it is
/// `short-average`. On the seed's oscillator (|μ| = 1) the period-1
/// orbit's exponents over 1000 iterations are off by 0.8 of their size at
/// 0.63 time scales (η = 1e4), by 1e-3 at 6.3 (η = 1e3) and 63 (η = 100)
/// alike; below about ten the error depends on where in its turn the
/// frame stopped, so no estimate from the run itself can be trusted
/// (docs/STABILITY.md, "How sure a row is").
pub const SHORT_AVERAGE: f64 = 10.0;

/// The largest `lambda_error` a row may state and stay `ok`: a tenth of
/// |λ1|, the exponent whose sign tells chaos from order, plus a
/// thousandth of the spectrum's scale max |λ_i|, so that a λ1 at zero (a
/// bifurcation, a flow's neutral direction in a time-T map) is judged
/// against the rest of the spectrum.
pub fn error_tolerance(lane: &LaneResult) -> f64 {
    let scale = lane.exponents.iter().fold(0.0_f64, |m, e| m.max(e.abs()));
    0.1 * lane.exponents[0].abs() + 1e-3 * scale
}

/// Marks `ok` lanes whose exponents are not yet the limit they estimate:
/// an averaging time short against the flow's slowest time scale
/// ([`SHORT_AVERAGE`]), or an error estimate above
/// [`error_tolerance`] (NaN: too few iterations to make one).
fn flag_uncertain(scene: &Scene, lanes: &mut [LaneResult]) {
    let iterations = scene.integration.iterations as f64;
    lanes.par_iter_mut().enumerate().for_each(|(k, lane)| {
        let finite = lane.exponents.iter().all(|e| e.is_finite());
        if lane.status != LaneStatus::Ok || lane.exponents.is_empty() || !finite {
            return;
        }
        let rate = (scene.system.slowest_rate)(&scene.lane_params(k));
        let scales = lane.period * iterations * rate;
        if rate > 0.0 && scales < SHORT_AVERAGE {
            lane.status = LaneStatus::ShortAverage { scales };
        } else if lane.error.is_nan() || lane.error > error_tolerance(lane) {
            lane.status = LaneStatus::Uncertain { error: lane.error };
        }
    });
}

/// How far a GPU lane is from its CPU recomputation: the largest exponent
/// difference on a regular lane; on a chaotic one (λ1 > 0), where rounding
/// differences decorrelate the two trajectories within tens of iterations
/// and the exponents then differ by their statistical error, the difference
/// of the exponent sums less their orbit terms (which is local to each
/// iteration: a Poincaré map's flux term ln |F_k(x_0)/F_k(x_n)| / T depends
/// on where each trajectory ends, and differs by ~1e-5 at Lorenz's ρ = 28
/// over 500 returns).
pub fn validation_difference(gpu: &LaneResult, cpu: &LaneResult) -> f64 {
    if cpu.exponents.first().is_some_and(|&l1| l1 > 0.0) {
        ((gpu.exponent_sum() - gpu.orbit_term) - (cpu.exponent_sum() - cpu.orbit_term)).abs()
    } else {
        gpu.exponents
            .iter()
            .zip(&cpu.exponents)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max)
    }
}

/// Where a run goes.
enum Plan {
    Cpu,
    Exact,
    Gpu(wgpu::Adapter, context::AdapterSummary),
}

fn plan(scene: &Scene, device: Option<usize>) -> Result<(Plan, Precision, Option<String>)> {
    match scene.backend {
        Backend::Auto => {
            if let Some(why) = no_kernels(scene) {
                return Ok((
                    Plan::Cpu,
                    Precision::F64,
                    Some(format!("auto: CPU path, since {why}")),
                ));
            }
            let gpu_settings = method_settings(scene, Backend::Gpu, scene.precision);
            if let Err(Error::Invalid { reason, .. }) = gpu_plan(scene, &gpu_settings) {
                return Ok((
                    Plan::Cpu,
                    Precision::F64,
                    Some(format!("auto: CPU path, since {reason}")),
                ));
            }
            let chosen = match context::choose(Want::Hardware, scene.precision, device) {
                Ok(Some(pick)) => pick,
                Ok(None) => {
                    return Ok((
                        Plan::Cpu,
                        Precision::F64,
                        Some(
                            "auto: no hardware GPU found, so the CPU reference path runs (f64)"
                                .into(),
                        ),
                    ))
                }
                Err(e @ Error::Invalid { .. }) => {
                    return Ok((
                        Plan::Cpu,
                        Precision::F64,
                        Some(format!("auto: CPU path, since {e}")),
                    ));
                }
                Err(e) => return Err(e),
            };
            let why = format!(
                "auto: hardware GPU {} ({}), {}",
                chosen.1.name,
                chosen.1.backend,
                if scene.precision == Precision::F64 {
                    "f64"
                } else {
                    "f32"
                }
            );
            Ok((Plan::Gpu(chosen.0, chosen.1), scene.precision, Some(why)))
        }
        Backend::Gpu => {
            if let Some(why) = no_kernels(scene) {
                return Err(Error::Backend {
                    backend: "gpu".into(),
                    reason: format!("{why}: use backend = \"cpu\" (\"auto\" does)"),
                });
            }
            let (adapter, summary) = context::choose(Want::Any, scene.precision, device)?
                .expect("Want::Any yields an adapter or an error");
            Ok((Plan::Gpu(adapter, summary), scene.precision, None))
        }
        Backend::Exact if !scene.system.has_exact => Err(Error::Backend {
            backend: "exact".into(),
            reason: format!(
                "{} has no closed-form tangent map; use \"cpu\"",
                scene.system.kind
            ),
        }),
        cpu_side => {
            if scene.precision == Precision::F32 {
                return Err(Error::invalid(
                    "run.precision",
                    format!(
                        "\"f32\" runs on the gpu backend only; the {} backend computes in f64",
                        cpu_side.name()
                    ),
                ));
            }
            Ok((
                if cpu_side == Backend::Exact {
                    Plan::Exact
                } else {
                    Plan::Cpu
                },
                Precision::F64,
                None,
            ))
        }
    }
}

/// Why the GPU kernels cannot run the scene's system at all, if they
/// cannot: a built-in without a WGSL twin, or a model whose generated WGSL
/// the kernels do not run yet (`model::codegen::wgsl::check`, the same for every
/// lane, so the first lane's parameters ask).
fn no_kernels(scene: &Scene) -> Option<String> {
    let system = scene.system;
    system.wgsl.is_none().then(|| {
        let why = (system.gpu_refuses)(&scene.params_at(0))
            .unwrap_or_else(|| "it has no WGSL kernel".into());
        format!("{}: {why}", system.kind)
    })
}

/// The kernel variant a scene needs: only the parts it uses.
pub fn variant(scene: &Scene, precision: Precision) -> Variant {
    // Over the whole sweep, so that every shard compiles the same kernels.
    let wall = scene.system.wall_reachable.is_some_and(|reachable| {
        (0..scene.sweep.lanes()).any(|k| {
            let state = scene
                .sweep
                .initial_state_at(k, &scene.integration.initial_state);
            reachable(&scene.params_at(k), state)
        })
    });
    Variant {
        system: scene.system,
        precision,
        lyapunov: scene.lyapunov,
        difference: scene.difference(),
        wall,
        impact_location: scene.integration.impact_location,
    }
}

/// The GPU integrates every lane of a sweep with the same plan: the most
/// steps and the most parts (sub-maps) any lane of the whole sweep (not
/// only of the shard) needs (see
/// `method::lane::plan_lane`), the steps raised to a whole number per part.
/// A lane cut into more parts than it needs gives the same exponents from
/// more, shorter differences.
fn gpu_plan(scene: &Scene, settings: &MethodSettings) -> Result<LanePlan> {
    let mut plan = LanePlan {
        steps_per_period: settings.flow.steps_per_period,
        parts: 1,
    };
    // Whether the kernels would compile impact code (precision is irrelevant).
    let wall = variant(scene, Precision::F64).wall;
    // Over the whole sweep, so that a shard runs every lane as the whole
    // sweep would. The starts of one point share its parameters, so its
    // refusal and plan: one lane of each run of lanes at one point is
    // planned (a million starts per value once took minutes here).
    let mut last_point = None;
    for k in 0..scene.sweep.lanes() {
        let point = scene.sweep.point_of(k);
        if last_point.replace(point) == Some(point) {
            continue;
        }
        let params = scene.params_at_point(point);
        if let Some(reason) = (scene.system.gpu_refuses)(&params).filter(|_| wall) {
            return Err(Error::invalid(
                "run.backend",
                format!(
                    "{}: {reason}: use backend = \"cpu\" (\"auto\" does)",
                    scene.describe(k)
                ),
            ));
        }
        let lane = (crate::method::runner(scene.system).plan)(&params, settings);
        if !lane.affordable() {
            // Not run: its row says too-many-steps (see `run_batch`).
            continue;
        }
        plan.steps_per_period = plan.steps_per_period.max(lane.steps_per_period);
        plan.parts = plan.parts.max(lane.parts);
    }
    plan.steps_per_period = plan.steps_per_period.next_multiple_of(plan.parts);
    // The kernels count steps in u32.
    if plan.steps_per_period > u32::MAX as usize {
        return Err(Error::invalid(
            "integration.steps_per_period",
            format!(
                "the sweep needs {} RK4 steps per period, more than the GPU kernels count (2^32 - 1)",
                plan.steps_per_period
            ),
        ));
    }
    Ok(plan)
}

/// `settings` for every lane of a GPU sweep, and for the CPU lanes that
/// validate or re-estimate it: the sweep's [`gpu_plan`].
fn follow_gpu_plan(scene: &Scene, settings: &mut MethodSettings) -> Result<()> {
    let plan = gpu_plan(scene, settings)?;
    settings.flow.steps_per_period = plan.steps_per_period;
    settings.submaps = Some(plan.parts);
    Ok(())
}

/// Runs a whole sweep on the backend the scene asks for.
pub fn run(scene: &Scene) -> Result<Report> {
    run_with(scene, &RunOptions::default())
}

/// [`run`] with options that are not part of the scene.
pub fn run_with(scene: &Scene, options: &RunOptions) -> Result<Report> {
    let runner = Runner::new(scene, options)?;
    runner.progress.start(runner.work(scene));
    runner.run(scene)
}

/// A run's backend, chosen and opened once, with the settings every lane
/// follows: the lanes of the scene it was made for, or of scenes derived
/// from it at the same values (a continuation pass), run on it alike.
pub struct Runner {
    precision: Precision,
    choice: Option<String>,
    backend: Backend,
    settings: MethodSettings,
    gpu: Option<(context::Gpu, Variant)>,
    options: RunOptions,
    progress: Progress,
    /// RK4 steps per dispatch that held once the adapter cut longer ones
    /// short (0 until then): the next batches start there.
    held_dispatch_steps: std::sync::atomic::AtomicUsize,
}

impl Runner {
    /// Chooses and opens the backend `scene` asks for, and plans its lanes.
    pub fn new(scene: &Scene, options: &RunOptions) -> Result<Runner> {
        let mut options = options.clone();
        if options.dispatch_lane_steps.is_none() {
            options.dispatch_lane_steps = options::dispatch_lane_steps_from_environment()?;
        }
        let options = &options;
        let (plan, precision, choice) = plan(scene, options.device)?;
        let (backend, settings, gpu) = match plan {
            Plan::Cpu | Plan::Exact => {
                let backend = if matches!(plan, Plan::Exact) {
                    Backend::Exact
                } else {
                    Backend::Cpu
                };
                let mut settings = method_settings(scene, backend, Precision::F64);
                settings.keep_jacobians = options.keep_jacobians;
                settings.stop = options.stop.clone();
                (backend, settings, None)
            }
            Plan::Gpu(adapter, summary) => {
                let mut settings = method_settings(scene, Backend::Gpu, precision);
                settings.keep_jacobians = options.keep_jacobians;
                settings.stop = options.stop.clone();
                follow_gpu_plan(scene, &mut settings)?;
                let variant = variant(scene, precision);
                gpu::shader::check_composed(&variant)?;
                let gpu = context::open(adapter, summary, precision)?;
                (Backend::Gpu, settings, Some((gpu, variant)))
            }
        };
        Ok(Runner {
            precision,
            choice,
            backend,
            settings,
            gpu,
            options: options.clone(),
            progress: options.progress.clone().unwrap_or_default(),
            held_dispatch_steps: Default::default(),
        })
    }

    /// The work of `scene`'s lanes, in lane-iterations, for the progress.
    pub fn work(&self, scene: &Scene) -> u64 {
        let i = &scene.integration;
        (scene.run_lane_count() * (i.transient + i.iterations)) as u64
    }

    /// The run's progress (a continuation pass extends its total).
    pub fn progress(&self) -> &Progress {
        &self.progress
    }

    /// Runs `scene`'s lanes in batches of at most `batch_lanes`, handing
    /// each to `sink` and adding it to `summary`.
    pub fn stream(
        &self,
        scene: &Scene,
        batch_lanes: usize,
        summary: &mut Option<Summary>,
        mut sink: impl FnMut(&Scene, &Report) -> Result<()>,
    ) -> Result<()> {
        self.batches(scene, batch_lanes, |batch, report| {
            sink(&batch, &report)?;
            let first = batch.batch.as_ref().map_or(0, |b| b.start);
            match summary {
                Some(s) => s.absorb(&report, first),
                None => *summary = Some(Summary::of(scene, &report)),
            }
            Ok(())
        })
    }

    /// The lanes of `scene` (the whole run, or a batch of it) in one
    /// report, run in the device's batches.
    pub fn run(&self, scene: &Scene) -> Result<Report> {
        let mut whole: Option<(Report, usize)> = None;
        self.batches(scene, usize::MAX, |batch, report| {
            let first = batch.batch.as_ref().map_or(0, |b| b.start);
            match &mut whole {
                None => whole = Some((report, first)),
                Some((whole, start)) => whole.append(report, first - *start),
            }
            Ok(())
        })?;
        Ok(whole.expect("a scene has at least one lane").0)
    }

    /// Runs `scene`'s lanes in batches, each handed to `take` with its
    /// scene (`Scene::batch`) once the host has finished it: at most
    /// `results_lanes` lanes' results held at once, and on the GPU at most
    /// the lanes one device batch holds ([`gpu::max_batch_lanes`]).
    ///
    /// A GPU run of several batches overlaps them: the device runs batch
    /// k + 1 while the host finishes batch k (recomputed and validated
    /// lanes, the sum rule, `take`'s rows). Two batches' results are then
    /// held at once, so a run over `results_lanes` takes batches of half
    /// of it. (The CPU path's lanes take every core, and would gain
    /// nothing.)
    fn batches(
        &self,
        scene: &Scene,
        results_lanes: usize,
        mut take: impl FnMut(Scene, Report) -> Result<()>,
    ) -> Result<()> {
        let lanes = scene.batch.clone().unwrap_or(0..scene.run_lane_count());
        let size = match &self.gpu {
            None => results_lanes,
            Some((gpu, variant)) => {
                let held = if results_lanes < lanes.len() {
                    results_lanes.div_ceil(2)
                } else {
                    results_lanes
                };
                held.min(gpu::max_batch_lanes(
                    gpu,
                    scene,
                    variant,
                    &self.settings,
                    &self.options,
                ))
            }
        }
        .max(1);
        let overlap = self.gpu.is_some() && size < lanes.len();
        let end = lanes.end;
        let batches = lanes
            .step_by(size)
            .map(|start| scene.batch(start..start.saturating_add(size).min(end)));
        let mut finish = |batch: Scene, ran: Ran| -> Result<()> {
            let report = self.finish(&batch, ran);
            take(batch, report)
        };
        if !overlap {
            for batch in batches {
                let ran = self.lanes(&batch)?;
                finish(batch, ran)?;
            }
            return Ok(());
        }
        std::thread::scope(|scope| {
            let (ready, next) = std::sync::mpsc::sync_channel(0);
            scope.spawn(move || {
                for batch in batches {
                    let ran = self.lanes(&batch);
                    let failed = ran.is_err();
                    // The host stopped taking batches (an error) or this
                    // one failed: no more.
                    if ready.send((batch, ran)).is_err() || failed {
                        return;
                    }
                }
            });
            let result = next.iter().try_for_each(|(batch, ran)| finish(batch, ran?));
            if result.is_err() {
                // The batch on the device is not wanted: end it now.
                self.settings.stop.request();
            }
            result
        })
    }

    /// The lanes of `scene` as its backend ran them, before the host's
    /// checks.
    fn lanes(&self, scene: &Scene) -> Result<Ran> {
        let start = Instant::now();
        let options = &self.options;
        let progress = self.progress.clone();
        let settings = &self.settings;
        let (lanes, gpu_report) = match &self.gpu {
            None => (cpu::sweep(scene, settings, &progress), None),
            Some((gpu, variant)) => {
                use std::sync::atomic::Ordering::Relaxed;
                let held = self.held_dispatch_steps.load(Relaxed);
                let options = RunOptions {
                    dispatch_steps: (held > 0).then_some(held).or(options.dispatch_steps),
                    ..options.clone()
                };
                let mut run = gpu::run(gpu, scene, variant, settings, &options)?;
                if run.retries > 0 {
                    self.held_dispatch_steps.store(run.chunk_steps, Relaxed);
                }
                // The kernels ran every lane with the sweep's plan; a lane whose
                // own plan is beyond reach is not to be trusted (the CPU path
                // does not run it at all).
                // (Over the host's cores, as the other steps over every
                // lane are: at a million lanes each is a serial 0.1 s.)
                run.lanes.par_iter_mut().enumerate().for_each(|(k, lane)| {
                    let own =
                        (crate::method::runner(scene.system).plan)(&scene.lane_params(k), settings);
                    if !own.affordable() {
                        *lane = crate::method::lane::not_run(
                            settings,
                            scene.system.dimension(),
                            lane.period,
                            own,
                        );
                    }
                });
                let report = GpuReport {
                    adapter: gpu.summary.name.clone(),
                    adapter_backend: gpu.summary.backend.clone(),
                    variant: variant.name(),
                    kernel_sources: gpu::shader::source_dir(),
                    timings: run.timings,
                    batches: 1,
                    chunk_steps: run.chunk_steps,
                    retries: run.retries,
                    bytes_per_lane: run.bytes_per_lane,
                    validation: None,
                    recomputed: Vec::new(),
                };
                (run.lanes, Some(report))
            }
        };
        // A stopped run's lanes ended part way: they are not results.
        if self.settings.stop.requested() {
            return Err(Error::Stopped);
        }
        Ok(Ran {
            lanes,
            gpu: gpu_report,
            elapsed: start.elapsed(),
        })
    }

    /// The report of `scene`'s lanes as they ran: on the GPU, the lanes the
    /// host recomputes and validates; the sum rule checked.
    fn finish(&self, scene: &Scene, ran: Ran) -> Report {
        let Ran {
            mut lanes,
            gpu: gpu_report,
            elapsed,
        } = ran;
        let precision = self.precision;
        let gpu_report = gpu_report.map(|mut report| {
            report.recomputed = recompute_sliding(scene, &self.settings, &mut lanes);
            date_transient_failures(scene, &mut lanes);
            report.validation = validate(scene, precision, &self.settings, &mut lanes);
            report
        });
        // The period-map kernels do not integrate a state-dependent divergence
        // along the reference: on the GPU such a model's sum rule is unknown,
        // not 0. (A section's host integrates it, as the CPU does.)
        let orbit_unknown = gpu_report.is_some()
            && scene
                .system
                .model
                .is_some_and(|code| code.divergence_along.is_some() && code.section.is_none());
        let expected_sums: Vec<f64> = lanes
            .par_iter()
            .enumerate()
            .map(|(k, lane)| {
                if orbit_unknown {
                    return f64::NAN;
                }
                let rates = lane.crossings_per_period.map(|c| c / lane.period);
                (scene.system.expected_sum)(&scene.lane_params(k), &rates) + lane.orbit_term
            })
            .collect();
        flag_sum_rule(&mut lanes, &expected_sums, precision);
        flag_uncertain(scene, &mut lanes);
        Report {
            backend: self.backend,
            precision,
            choice: self.choice.clone(),
            lanes,
            expected_sums,
            elapsed,
            threads: rayon::current_num_threads(),
            gpu: gpu_report,
        }
    }
}

/// A batch's lanes as the backend ran them (see [`Runner::finish`]).
struct Ran {
    lanes: Vec<LaneResult>,
    gpu: Option<GpuReport>,
    /// The lanes' time.
    elapsed: Duration,
}

/// What a run did over all its batches: what the command prints.
#[derive(Clone, Debug)]
pub struct Summary {
    pub backend: Backend,
    pub precision: Precision,
    /// Why `auto` chose the backend, if it did.
    pub choice: Option<String>,
    pub threads: usize,
    pub elapsed: Duration,
    /// The GPU part, summed over batches (validation: the largest difference).
    pub gpu: Option<GpuReport>,
    pub lanes: usize,
    /// Lanes whose status is not `ok`, by status name.
    pub flagged_by_status: std::collections::BTreeMap<&'static str, usize>,
    /// Lanes that gave no exponents at all (see [`LaneStatus::is_failure`]),
    /// by status name.
    pub failures: std::collections::BTreeMap<&'static str, usize>,
    pub max_sum_error: Option<f64>,
    /// The largest `lambda_error` of a row (see `LaneResult::error`).
    pub max_error: Option<f64>,
    /// Lanes whose RK4 steps were raised, and the most steps per period.
    pub raised: (usize, usize),
    /// Lanes cut into sub-maps, and the most parts.
    pub cut: (usize, usize),
    /// Why the CPU runs the model on the interpreter, where the host's C
    /// compiler failed to build its native code (a CPU run only).
    pub interpreter_fallback: Option<String>,
    /// The scene's RK4 steps per period, against which `raised` counts.
    requested_steps: usize,
}

impl Summary {
    /// The summary of `report`, a run of `scene` (or its first batch).
    pub fn of(scene: &Scene, report: &Report) -> Summary {
        let mut summary = Summary {
            backend: report.backend,
            precision: report.precision,
            choice: report.choice.clone(),
            threads: report.threads,
            elapsed: Duration::ZERO,
            gpu: None,
            lanes: 0,
            flagged_by_status: Default::default(),
            failures: Default::default(),
            max_sum_error: None,
            max_error: None,
            raised: (0, 0),
            cut: (0, 0),
            interpreter_fallback: match report.backend {
                Backend::Cpu => scene.system.model.and_then(|m| m.interpreter_fallback()),
                _ => None,
            },
            requested_steps: if scene.system.is_flow && report.backend != Backend::Exact {
                scene.integration.steps_per_period
            } else {
                usize::MAX
            },
        };
        summary.absorb(report, 0);
        summary
    }

    /// Adds one more batch's report, of the lanes from lane `first` of the
    /// run.
    pub fn absorb(&mut self, report: &Report, first: usize) {
        self.elapsed += report.elapsed;
        self.lanes += report.lanes.len();
        for lane in report.lanes.iter().filter(|l| l.status != LaneStatus::Ok) {
            *self
                .flagged_by_status
                .entry(lane.status.name())
                .or_default() += 1;
            if lane.status.is_failure() {
                *self.failures.entry(lane.status.name()).or_default() += 1;
            }
        }
        self.max_sum_error = match (self.max_sum_error, report.max_sum_error()) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        self.max_error = match (self.max_error, report.max_error()) {
            (Some(a), Some(b)) => Some(a.max(b)),
            (a, b) => a.or(b),
        };
        if let Some(gpu) = &report.gpu {
            match &mut self.gpu {
                None => self.gpu = Some(gpu.clone()),
                Some(sum) => sum.absorb(gpu, first),
            }
        }
        let requested = self.requested_steps;
        // A lane not run for its plan counts as failed, not as raised.
        for lane in report.lanes.iter().filter(|l| l.plan.affordable()) {
            let (steps, parts) = (lane.plan.steps_per_period, lane.plan.parts);
            if steps > requested {
                self.raised = (self.raised.0 + 1, self.raised.1.max(steps));
            }
            if parts > 1 {
                self.cut = (self.cut.0 + 1, self.cut.1.max(parts));
            }
        }
    }

    /// Lanes whose status is not `ok`.
    pub fn flagged(&self) -> usize {
        self.flagged_by_status.values().sum()
    }

    /// Counts by status name as the messages say them: "2 sum-rule, 1
    /// too-many-steps" (of `flagged_by_status` or `failures`).
    pub fn by_status(counts: &std::collections::BTreeMap<&'static str, usize>) -> String {
        let counts: Vec<String> = counts
            .iter()
            .map(|(name, n)| format!("{n} {name}"))
            .collect();
        counts.join(", ")
    }

    /// Whether every lane failed (the command then exits with 1).
    pub fn all_failed(&self) -> bool {
        self.failures.values().sum::<usize>() == self.lanes
    }
}

/// Recomputes on the CPU path (f64, with the GPU's steps and parts) the
/// lanes the kernels flagged `sliding`: a motion on a switch they do not
/// integrate (another surface met while sliding, two switches slid on at
/// once), which they flag rather than step through; the CPU integrates
/// it. Returns their indices.
///
/// A lane the kernels end non-finite stays non-finite: a flagged part
/// gives the host no Jacobian, so a motion stopped at its flag no longer
/// fails the QR. The lanes once recomputed for that (a ball locking onto
/// a table, a belt's mass pressed into a stop) are flagged ones now
/// (docs/VALIDATION.md, `a_mass_carried_by_the_belt_into_a_stop_is_recomputed_on_the_cpu`).
fn recompute_sliding(scene: &Scene, gpu: &MethodSettings, lanes: &mut [LaneResult]) -> Vec<usize> {
    let flagged: Vec<usize> = (0..lanes.len())
        .filter(|&k| matches!(lanes[k].status, LaneStatus::Sliding { .. }))
        .collect();
    if flagged.is_empty() {
        return flagged;
    }
    let settings = cpu_twin(scene, gpu);
    for (&k, lane) in flagged.iter().zip(cpu_lanes(scene, &settings, &flagged)) {
        lanes[k] = lane;
    }
    flagged
}

/// Dates the failures the GPU found at the end of its transient, which
/// runs without readback: a lane that went non-finite (or lost its section)
/// in the transient is reported by the kernels at the first averaging
/// iteration. Its transient is run again on the CPU path, and where that
/// fails too, the row takes the CPU's iteration, as a CPU run would report
/// it (the lane gave no numbers either way).
fn date_transient_failures(scene: &Scene, lanes: &mut [LaneResult]) {
    let mut settings = method_settings(scene, Backend::Cpu, Precision::F64);
    // The kernels' transient is the iterations before the aligning ones.
    let first_with_jacobians = settings.transient;
    let undated = |status: &LaneStatus| match status {
        LaneStatus::NonFinite { iteration } | LaneStatus::NoReturn { iteration } => {
            *iteration == first_with_jacobians
        }
        _ => false,
    };
    let failed: Vec<usize> = (0..lanes.len())
        .filter(|&k| first_with_jacobians > 0 && undated(&lanes[k].status))
        .collect();
    if failed.is_empty() || follow_gpu_plan(scene, &mut settings).is_err() {
        return;
    }
    // The transient alone: no averaging iteration is needed to date it.
    settings.iterations = settings.align + 1;
    for (&k, cpu) in failed.iter().zip(cpu_lanes(scene, &settings, &failed)) {
        if cpu.status.is_failure() {
            lanes[k].status = cpu.status;
        }
    }
}

/// Lanes `picked` of the sweep run on the CPU path with `settings`, in
/// parallel: what a GPU run hands back to the CPU.
fn cpu_lanes(scene: &Scene, settings: &MethodSettings, picked: &[usize]) -> Vec<LaneResult> {
    picked
        .par_iter()
        .map(|&k| {
            let lane = crate::method::Lane {
                params: scene.lane_params(k),
                settings,
                initial_state: scene.lane_initial_state(k).to_vec(),
            };
            (crate::method::runner(scene.system).run_lane)(&lane)
        })
        .collect()
}

/// Recomputes `scene.validate` sweep values, spread over the run, on the
/// CPU path (f64) and marks GPU rows that differ beyond the tolerance: of
/// a batch, those that fall in it.
fn validate(
    scene: &Scene,
    precision: Precision,
    gpu: &MethodSettings,
    lanes: &mut [LaneResult],
) -> Option<Validation> {
    if scene.validate == 0 || !scene.lyapunov || lanes.is_empty() {
        return None;
    }
    // Spread over the run, whichever of its batches `scene` is: the picks
    // that fall in this batch, as its own lanes.
    let n = scene.run_lane_count();
    let batch = scene.batch.clone().unwrap_or(0..n);
    let m = scene.validate.min(n);
    let mut picks: Vec<usize> = (0..m)
        .map(|k| {
            if m == 1 {
                0
            } else {
                (k * (n - 1) + (m - 1) / 2) / (m - 1)
            }
        })
        .filter(|k| batch.contains(k))
        .map(|k| k - batch.start)
        .collect();
    picks.dedup();
    // The same δ and difference scheme as the GPU run (both follow the
    // scene's precision), so the difference measures arithmetic only.
    // The GPU ran every lane with the sweep's steps and parts.
    let settings = cpu_twin(scene, gpu);
    let tolerance = validation_tolerance(precision);
    let mut max_difference: f64 = 0.0;
    for &k in &picks {
        let lane = crate::method::Lane {
            params: scene.lane_params(k),
            settings: &settings,
            initial_state: scene.lane_initial_state(k).to_vec(),
        };
        let cpu = (crate::method::runner(scene.system).run_lane)(&lane);
        let finished = |l: &LaneResult| l.exponents.iter().all(|e| e.is_finite());
        if !finished(&cpu) || !finished(&lanes[k]) {
            continue;
        }
        let difference = validation_difference(&lanes[k], &cpu);
        max_difference = max_difference.max(difference);
        if difference > tolerance && lanes[k].status == LaneStatus::Ok {
            lanes[k].status = LaneStatus::Mismatch { difference };
        }
    }
    Some(Validation {
        lanes: picks,
        max_difference,
        tolerance,
    })
}
