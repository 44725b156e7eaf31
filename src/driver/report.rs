//! What a run reports: a batch's or a whole run's lanes with what the
//! backend did ([`Report`], its GPU part [`GpuReport`]), and what the
//! command prints of a run over all its batches ([`Summary`]).

use std::time::Duration;

use super::validation::Validation;
use crate::backend::gpu;
use crate::method::{LaneResult, LaneStatus};
use crate::scene::{Backend, Precision, Scene};

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

impl Report {
    /// Appends the report of the next batch, whose lanes start at lane
    /// `first` of this one's.
    pub(super) fn append(&mut self, batch: Report, first: usize) {
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
