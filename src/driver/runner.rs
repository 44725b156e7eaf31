//! The `Runner`: a run's backend chosen and opened once, and a scene's
//! lanes run on it in batches, each finished by the host (recomputed and
//! validated lanes, the statuses decided over a finished lane) before it
//! is handed on.

use std::time::{Duration, Instant};

use rayon::prelude::*;

use super::checks::{flag_sum_rule, flag_uncertain};
use super::choice::{plan, Plan};
use super::report::{GpuReport, Report, Summary};
use super::validation::{date_transient_failures, recompute_sliding, settle_on_the_host, validate};
use crate::backend::gpu::context;
use crate::backend::gpu::plan::{follow_lane_plan, variant};
use crate::backend::gpu::shader::Variant;
use crate::backend::{cpu, gpu, Progress, RunOptions};
use crate::error::{Error, Result};
use crate::method::lane::KnownOrbits;
use crate::method::{LaneResult, MethodSettings};
use crate::plan::method_settings;
use crate::scene::{Backend, Precision, Scene};

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
    /// The periodic orbits known at each value that the scene's own
    /// starts may stop early on (`attractors.early_stop`), once learned.
    known: std::sync::RwLock<Option<std::sync::Arc<KnownOrbits>>>,
}

impl Runner {
    /// Chooses and opens the backend `scene` asks for, and plans its lanes.
    pub fn new(scene: &Scene, options: &RunOptions) -> Result<Runner> {
        let mut options = options.clone();
        if options.dispatch_lane_steps.is_none() {
            options.dispatch_lane_steps = crate::environment::dispatch_lane_steps()?;
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
                settings.flow.stop = options.stop.clone();
                (backend, settings, None)
            }
            Plan::Gpu(adapter, summary) => {
                let mut settings = method_settings(scene, Backend::Gpu, precision);
                settings.keep_jacobians = options.keep_jacobians;
                settings.flow.stop = options.stop.clone();
                follow_lane_plan(scene, &mut settings)?;
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
            known: Default::default(),
        })
    }

    /// Whether this run's lanes stop early where the scene asks
    /// (`attractors.early_stop`): on the CPU path and the exact backend,
    /// not on the GPU, whose transient runs on the device.
    pub fn stops_early(&self) -> bool {
        self.settings.early_stop > 0 && self.gpu.is_none()
    }

    /// The orbits the scene's own starts may stop early on from now on.
    pub fn set_known(&self, known: KnownOrbits) {
        *self.known.write().expect("no lane panicked") = Some(std::sync::Arc::new(known));
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
                self.settings.flow.stop.request();
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
            None => {
                let known = self.known.read().expect("no lane panicked").clone();
                (
                    cpu::sweep(scene, settings, known.as_deref(), &progress),
                    None,
                )
            }
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
                // Nor are the starts outside the admissible states: the
                // kernels ran them, the CPU path does not.
                run.lanes.par_iter_mut().enumerate().for_each(|(k, lane)| {
                    if scene.lane_start_inadmissible(k) {
                        *lane = cpu::inadmissible(scene, settings, k);
                        return;
                    }
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
        if self.settings.flow.stop.requested() {
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
            settle_on_the_host(scene, &self.settings, &mut lanes);
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
