//! The summary of a finished run, built once from the scene and what the
//! run produced: what ran where, on what, how, what was adjusted, how long
//! it took and what came out. The command line prints it (its `Display`),
//! the Python package returns its [`RunSummary::record`] as a dict; neither
//! derives a fact of it on its own.

use std::collections::BTreeMap;
use std::fmt;
use std::path::PathBuf;
use std::time::Duration;

use super::Outcome;
use crate::backend::gpu::pipeline::Timings;
use crate::driver::orbits::OrbitRun;
use crate::driver::Summary;
use crate::error::number;
use crate::method::lane::MAX_STEP_RATE;
use crate::orbit::trace::Kind;
use crate::scene::{Backend, Precision, Scene};

/// What a run reports when it is done.
pub struct RunSummary {
    /// The scene's name.
    pub name: String,
    /// The system's kind (a built-in one, or the model's name).
    pub system: &'static str,
    /// Why `auto` chose the backend, if it did.
    pub choice: Option<String>,
    pub backend: Backend,
    pub precision: Precision,
    /// The CPU's threads.
    pub threads: usize,
    /// A GPU run's adapter, kernels and timings.
    pub gpu: Option<GpuRun>,
    /// Why the CPU ran the model on the interpreter (its native code failed
    /// to build).
    pub interpreter_fallback: Option<String>,
    /// The swept values, the starts, the shard's part.
    pub sweep: SweepRun,
    /// The method's settings as this backend used them.
    pub method: Method,
    /// What the run changed or left out of the scene.
    pub adjustments: Adjustments,
    /// The run's wall-clock time.
    pub time: Duration,
    /// With `[attractors]`: what the many starts found.
    pub attractors: Option<Found>,
    /// With `[orbits]`: the branches traced.
    pub orbits: Option<Traced>,
    /// The sum rule's largest miss, over the lanes that have exponents.
    pub max_sum_error: Option<f64>,
    /// The largest `lambda_error` of a row.
    pub max_error: Option<f64>,
    /// The lanes run (this shard's).
    pub lanes: usize,
    /// Lanes whose status is not `ok`, by status name.
    pub flagged_by_status: BTreeMap<&'static str, usize>,
    /// Lanes that gave no exponents at all, by status name.
    pub failures: BTreeMap<&'static str, usize>,
    /// The paths of the output set.
    pub written: Vec<PathBuf>,
}

/// A GPU run's adapter, kernels, timings, and the lanes the CPU recomputed.
pub struct GpuRun {
    pub adapter: String,
    /// The adapter's graphics API, e.g. "vulkan".
    pub adapter_backend: String,
    /// The kernel variant compiled.
    pub kernels: String,
    /// Where the kernels' sources came from when not from the binary
    /// (`LYAPSWEEP_SHADER_DIR`).
    pub kernel_sources: Option<PathBuf>,
    pub timings: Timings,
    /// Device batches.
    pub batches: usize,
    /// RK4 steps per dispatch.
    pub chunk_steps: usize,
    /// Device memory per lane.
    pub bytes_per_lane: u64,
    /// Batches redone with shorter dispatches.
    pub retries: usize,
    /// Sweep values the kernels flagged sliding, recomputed on the CPU.
    pub recomputed: usize,
    /// Sweep values recomputed on the CPU to validate the GPU's.
    pub validation: Option<Validated>,
}

/// The GPU's lanes checked against the CPU's.
pub struct Validated {
    /// Sweep values recomputed.
    pub values: usize,
    /// The largest difference found.
    pub max_difference: f64,
    /// Above this a row is marked `gpu-mismatch`.
    pub tolerance: f64,
}

/// The lanes: each axis's values, the starts per value and the shard's part.
pub struct SweepRun {
    pub axes: Vec<AxisValues>,
    /// With `[attractors]`: the starts per value.
    pub starts: Option<usize>,
    pub shard: Option<ShardPart>,
}

/// One swept parameter's values.
pub struct AxisValues {
    pub parameter: String,
    pub count: usize,
    /// The smallest and largest value.
    pub low: f64,
    pub high: f64,
}

/// A shard's part of the sweep.
pub struct ShardPart {
    pub index: usize,
    pub count: usize,
    /// The shard's lanes, of the sweep's `of`.
    pub lanes: usize,
    pub of: usize,
}

/// The method's settings as the backend used them.
pub struct Method {
    pub transient: usize,
    /// The transient's last iterations, aligning the QR frame.
    pub align: usize,
    pub iterations: usize,
    /// The finite differences' δ (none for the exact backend, or without
    /// exponents).
    pub delta: Option<f64>,
    /// A flow's RK4 steps per period (none for the exact backend).
    pub steps_per_period: Option<usize>,
    /// How a flow with a reachable wall locates its impacts.
    pub impact_location: Option<&'static str>,
}

/// What the run changed or left out of the scene.
pub struct Adjustments {
    /// `output.bifurcation_points` lowered to the averaged iterations.
    pub points_lowered: Option<Lowered>,
    /// Keys of the scene this run did not use.
    pub unused: Vec<String>,
    /// Whether the exact backend ran (which is why `unused` went unused).
    pub exact: bool,
    /// Lanes whose RK4 steps were raised, and the most steps per period.
    pub raised: (usize, usize),
    /// Lanes cut into sub-maps, and the most parts.
    pub cut: (usize, usize),
}

/// `output.bifurcation_points` lowered: a lane keeps at most one point per
/// averaged iteration.
pub struct Lowered {
    pub asked: usize,
    pub kept: usize,
    pub iterations: usize,
}

/// What the many starts per value found.
pub struct Found {
    /// Attractors over all values.
    pub total: usize,
    /// The sweep's values (points of its grid).
    pub values: usize,
    pub branches: usize,
    /// Values that hold more than one attractor.
    pub several: usize,
    /// Continuation passes, and the lanes they ran.
    pub passes: usize,
    pub continued_lanes: usize,
    /// The scene's starts' convergence times (runs with basin images): their
    /// mean and the longest, in iterations, over every value's starts.
    pub convergence: Option<(f64, usize)>,
}

/// The mean and the longest convergence time over every attractor's
/// starts (`None` when no start kept one).
fn convergence(found: &crate::attractor::Attractors) -> Option<(f64, usize)> {
    let times = found
        .values
        .iter()
        .flat_map(|v| &v.attractors)
        .flat_map(|a| &a.settling);
    let (count, sum, longest) = times.fold((0usize, 0.0, 0usize), |(n, s, m), &t| {
        (n + 1, s + t as f64, m.max(t))
    });
    (count > 0).then(|| (sum / count as f64, longest))
}

/// A value of [`RunSummary::record`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value<'a> {
    Text(&'a str),
    Count(usize),
    Number(f64),
    /// Lanes by status name.
    ByStatus(&'a BTreeMap<&'static str, usize>),
    /// Nothing to say (Python's None).
    Nothing,
}

impl<'a> From<Option<&'a str>> for Value<'a> {
    fn from(text: Option<&'a str>) -> Self {
        text.map_or(Value::Nothing, Value::Text)
    }
}

impl From<Option<f64>> for Value<'_> {
    fn from(number: Option<f64>) -> Self {
        number.map_or(Value::Nothing, Value::Number)
    }
}

impl RunSummary {
    /// The summary of `outcome`, a run of `scene`.
    pub fn of(scene: &Scene, outcome: &Outcome) -> RunSummary {
        let report = &outcome.summary;
        let exact = report.backend == Backend::Exact;
        let i = &scene.integration;
        let flow = scene.system.is_flow && !exact;
        RunSummary {
            name: scene.name.clone(),
            system: scene.system.kind,
            choice: report.choice.clone(),
            backend: report.backend,
            precision: report.precision,
            threads: report.threads,
            gpu: report.gpu.as_ref().map(|gpu| GpuRun {
                adapter: gpu.adapter.clone(),
                adapter_backend: gpu.adapter_backend.clone(),
                kernels: gpu.variant.clone(),
                kernel_sources: gpu.kernel_sources.clone(),
                timings: gpu.timings,
                batches: gpu.batches,
                chunk_steps: gpu.chunk_steps,
                bytes_per_lane: gpu.bytes_per_lane,
                retries: gpu.retries,
                recomputed: gpu.recomputed.len(),
                validation: gpu.validation.as_ref().map(|v| Validated {
                    values: v.lanes.len(),
                    max_difference: v.max_difference,
                    tolerance: v.tolerance,
                }),
            }),
            interpreter_fallback: report.interpreter_fallback.clone(),
            sweep: SweepRun::of(scene),
            method: Method {
                transient: i.transient,
                align: i.align,
                iterations: i.iterations,
                delta: (!exact && scene.lyapunov).then(|| scene.perturbation()),
                steps_per_period: flow.then_some(i.steps_per_period),
                impact_location: (flow && scene.system.wall_reachable.is_some())
                    .then(|| i.impact_location.name()),
            },
            adjustments: Adjustments {
                points_lowered: scene.bifurcation_points_asked.map(|asked| Lowered {
                    asked,
                    kept: scene.bifurcation_points,
                    iterations: i.iterations,
                }),
                unused: scene.unused_keys(report.backend),
                exact,
                raised: report.raised,
                cut: report.cut,
            },
            time: report.elapsed,
            attractors: outcome.attractors.as_ref().map(|found| Found {
                total: found.values.iter().map(|v| v.count()).sum(),
                values: scene.sweep.points(),
                branches: found.branches,
                several: found.several(),
                passes: found.passes,
                continued_lanes: found.continued_lanes,
                convergence: convergence(found),
            }),
            orbits: outcome.orbits.as_ref().map(Traced::of),
            max_sum_error: report.max_sum_error,
            max_error: report.max_error,
            lanes: report.lanes,
            flagged_by_status: report.flagged_by_status.clone(),
            failures: report.failures.clone(),
            written: outcome.written.clone(),
        }
    }

    /// Lanes whose status is not `ok`.
    pub fn flagged(&self) -> usize {
        self.flagged_by_status.values().sum()
    }

    /// The summary as keys and values, in order: the Python package's
    /// dict. `attractors` (their total) and `branches` only with
    /// `[attractors]`.
    pub fn record(&self) -> Vec<(&'static str, Value<'_>)> {
        let mut record = vec![
            ("name", Value::Text(&self.name)),
            ("system", Value::Text(self.system)),
            ("backend", Value::Text(self.backend.name())),
            ("precision", Value::Text(self.precision.name())),
            ("choice", self.choice.as_deref().into()),
            (
                "adapter",
                self.gpu.as_ref().map(|g| g.adapter.as_str()).into(),
            ),
            ("threads", Value::Count(self.threads)),
            ("lanes", Value::Count(self.lanes)),
            ("time", Value::Number(self.time.as_secs_f64())),
            ("max_sum_error", self.max_sum_error.into()),
            ("max_error", self.max_error.into()),
            (
                "interpreter_fallback",
                self.interpreter_fallback.as_deref().into(),
            ),
            ("flagged", Value::Count(self.flagged())),
            ("failures", Value::ByStatus(&self.failures)),
            (
                "flagged_by_status",
                Value::ByStatus(&self.flagged_by_status),
            ),
        ];
        if let Some(found) = &self.attractors {
            record.push(("attractors", Value::Count(found.total)));
            record.push(("branches", Value::Count(found.branches)));
            if let Some((mean, longest)) = found.convergence {
                record.push(("convergence_mean", Value::Number(mean)));
                record.push(("convergence_max", Value::Count(longest)));
            }
        }
        if let Some(traced) = &self.orbits {
            record.push(("orbit_branches", Value::Count(traced.branches)));
            record.push(("orbit_starts_failed", Value::Count(traced.failed)));
            record.push(("bifurcations", Value::Count(traced.bifurcations())));
            record.push(("orbits_time", Value::Number(traced.time.as_secs_f64())));
        }
        record
    }
}

impl SweepRun {
    fn of(scene: &Scene) -> SweepRun {
        let axes = scene.sweep.axes().map(|axis| {
            let (low, high) = axis
                .values
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
                    (a.min(v), b.max(v))
                });
            AxisValues {
                parameter: axis.parameter.clone(),
                count: axis.values.len(),
                low,
                high,
            }
        });
        SweepRun {
            axes: axes.collect(),
            starts: scene.sweep.starts.as_ref().map(|s| s.states.len()),
            shard: scene.shard.map(|s| ShardPart {
                index: s.index,
                count: s.count,
                lanes: scene.lane_count(),
                of: scene.sweep.lanes(),
            }),
        }
    }
}

/// The summary as the command line prints it, a line each.
impl fmt::Display for RunSummary {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(out, "lyapsweep: {} ({})", self.name, self.system)?;
        if let Some(choice) = &self.choice {
            writeln!(out, "  {choice}")?;
        }
        self.write_backend(out)?;
        if let Some(fallback) = &self.interpreter_fallback {
            writeln!(out, "  interpreter  {fallback}")?;
        }
        writeln!(out, "  lanes        {}", self.sweep)?;
        writeln!(out, "  method       {}", self.method)?;
        write!(out, "{}", self.adjustments)?;
        writeln!(out, "  time         {:.3} s", self.time.as_secs_f64())?;
        if let Some(gpu) = &self.gpu {
            write!(out, "{gpu}")?;
        }
        if let Some(found) = &self.attractors {
            write!(out, "{found}")?;
        }
        if let Some(traced) = &self.orbits {
            write!(out, "{traced}")?;
        }
        self.write_outcome(out)
    }
}

impl RunSummary {
    /// The backend and precision, and for the GPU its adapter and kernels.
    fn write_backend(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        let precision = self.precision.name();
        match &self.gpu {
            Some(gpu) => {
                writeln!(
                    out,
                    "  backend      gpu ({precision}) on {} ({})",
                    gpu.adapter, gpu.adapter_backend
                )?;
                writeln!(out, "  kernels      {}", gpu.kernels)?;
                if let Some(dir) = &gpu.kernel_sources {
                    writeln!(
                        out,
                        "               composed from {} (LYAPSWEEP_SHADER_DIR), not the binary's",
                        dir.display()
                    )?;
                }
                Ok(())
            }
            None => writeln!(
                out,
                "  backend      {} ({precision}, {} threads)",
                self.backend.name(),
                self.threads
            ),
        }
    }

    /// The sum rule's largest miss, the flagged and failed lanes, the files.
    fn write_outcome(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(err) = self.max_sum_error {
            writeln!(out, "  max |lambda_sum - expected_sum| = {err:.3e}")?;
        }
        if let Some(err) = self.max_error {
            writeln!(out, "  max lambda_error = {err:.3e}")?;
        }
        let (flagged, lanes) = (self.flagged(), self.lanes);
        if flagged == 0 {
            writeln!(out, "  flagged lanes {flagged} of {lanes}")?;
        } else {
            let by_status = Summary::by_status(&self.flagged_by_status);
            writeln!(out, "  flagged lanes {flagged} of {lanes} ({by_status})")?;
        }
        if !self.failures.is_empty() {
            let failures = Summary::by_status(&self.failures);
            writeln!(out, "  failed lanes {failures} (no exponents)")?;
        }
        for path in &self.written {
            writeln!(out, "  wrote        {}", path.display())?;
        }
        Ok(())
    }
}

/// The lanes' line: each axis's values, × the starts, and the shard's part.
impl fmt::Display for SweepRun {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        let ranges: Vec<String> = self.axes.iter().map(ToString::to_string).collect();
        write!(out, "{}", ranges.join(" × "))?;
        if let Some(starts) = self.starts {
            write!(out, " × {starts} starts")?;
        }
        if let Some(s) = &self.shard {
            write!(
                out,
                "; shard {} of {}: {} of the {} lanes",
                s.index, s.count, s.lanes, s.of
            )?;
        }
        Ok(())
    }
}

/// "5 values of eta in [0.4, 2]", or "1 value of eta: 0.4".
impl fmt::Display for AxisValues {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (low, high) = (number(self.low), number(self.high));
        match self.count {
            1 => write!(out, "1 value of {}: {low}", self.parameter),
            n => write!(out, "{n} values of {} in [{low}, {high}]", self.parameter),
        }
    }
}

/// The method's line.
impl fmt::Display for Method {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            out,
            "transient {} (the last {} aligning the QR frame), iterations {}",
            self.transient, self.align, self.iterations
        )?;
        if let Some(delta) = self.delta {
            write!(out, ", δ = {delta:e}")?;
        }
        if let Some(steps) = self.steps_per_period {
            write!(out, ", RK4 {steps} steps/period")?;
        }
        if let Some(how) = self.impact_location {
            write!(out, ", impacts located by {how}")?;
        }
        Ok(())
    }
}

/// Points lowered, keys not used, steps raised and iterations cut into
/// sub-maps: a line each, where there are any.
impl fmt::Display for Adjustments {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(Lowered {
            asked,
            kept,
            iterations,
        }) = &self.points_lowered
        {
            writeln!(out,
                "  points       output.bifurcation_points lowered from {asked} to {kept}: a lane keeps at most one point per averaged iteration (integration.iterations = {iterations})"
            )?;
        }
        if !self.unused.is_empty() {
            writeln!(
                out,
                "  not used     {}: {}",
                self.unused.join(", "),
                if self.exact {
                    "the exact backend propagates in closed form"
                } else {
                    "this system has no wall, or is a map"
                }
            )?;
        }
        let (raised, most) = self.raised;
        if raised > 0 {
            writeln!(out,
                "  steps        raised in {raised} lanes, up to {most} per period: their fastest time scale needs RK4 step × rate ≤ {MAX_STEP_RATE}"
            )?;
        }
        let (cut, most) = self.cut;
        if cut > 0 {
            writeln!(out,
                "  sub-maps     {cut} lanes cut each iteration into up to {most} parts: over a whole one the fastest contraction falls below what the finite difference resolves"
            )?;
        }
        Ok(())
    }
}

/// A GPU run's timings, retries, recomputed and validated lanes.
impl fmt::Display for GpuRun {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        let t = &self.timings;
        writeln!(out,
            "               setup {:.3} s, transient {:.3} s, averaging {:.3} s (waiting for the GPU {:.3} s, readback {:.3} s, host QR {:.3} s); {} batch(es), {} RK4 steps per dispatch, {} bytes of device memory per lane",
            t.setup.as_secs_f64(),
            t.transient.as_secs_f64(),
            t.averaging.as_secs_f64(),
            t.gpu_wait.as_secs_f64(),
            t.readback.as_secs_f64(),
            t.host_qr.as_secs_f64(),
            self.batches,
            self.chunk_steps,
            self.bytes_per_lane
        )?;
        if self.retries > 0 {
            writeln!(out,
                "               {} batch run(s) redone with shorter dispatches: the adapter cut loops short past its cap (lavapipe: 65 535 loop iterations per invocation)",
                self.retries
            )?;
        }
        if let Some(busy) = t.gpu_busy {
            writeln!(
                out,
                "               device time of the compute passes (timestamp queries) {:.3} s",
                busy.as_secs_f64()
            )?;
        }
        if self.recomputed > 0 {
            writeln!(out,
                "  sliding      {} values recomputed on the CPU: the kernels flagged a motion they do not integrate (sliding, or held on an event)",
                self.recomputed
            )?;
        }
        if let Some(v) = &self.validation {
            writeln!(out,
                "  validation   {} values recomputed on the CPU: max difference {:.2e} (tolerance {:.0e})",
                v.values, v.max_difference, v.tolerance
            )?;
        }
        Ok(())
    }
}

/// What the many starts found: attractors, branches, continuation.
impl fmt::Display for Found {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            out,
            "  attractors   {} over {} values in {} branches; {} values hold more than one",
            self.total, self.values, self.branches, self.several
        )?;
        if self.passes > 0 {
            writeln!(
                out,
                "  continued    {} lanes in {} passes from the neighbours' attractors",
                self.continued_lanes, self.passes
            )?;
        }
        if let Some((mean, longest)) = self.convergence {
            writeln!(
                out,
                "  converged    after {mean:.1} iterations on average, {longest} at most"
            )?;
        }
        Ok(())
    }
}

/// What `[orbits]` traced: its branches, the starts that gave none, the
/// bifurcations by kind, and the stage's time.
pub struct Traced {
    pub branches: usize,
    pub failed: usize,
    /// Bifurcations per kind, in `orbit::trace::Kind::ALL`'s order.
    pub by_kind: Vec<(&'static str, usize)>,
    pub time: Duration,
}

impl Traced {
    fn of(run: &OrbitRun) -> Traced {
        let failed = run.branches.iter().filter(|b| b.failure.is_some()).count();
        let by_kind = Kind::ALL
            .iter()
            .map(|&kind| {
                let n = run
                    .branches
                    .iter()
                    .flat_map(|b| &b.bifurcations)
                    .filter(|f| f.kind == kind)
                    .count();
                (kind.name(), n)
            })
            .filter(|(_, n)| *n > 0)
            .collect();
        Traced {
            branches: run.branches.len() - failed,
            failed,
            by_kind,
            time: run.elapsed,
        }
    }

    pub fn bifurcations(&self) -> usize {
        self.by_kind.iter().map(|(_, n)| n).sum()
    }
}

impl fmt::Display for Traced {
    fn fmt(&self, out: &mut fmt::Formatter<'_>) -> fmt::Result {
        let kinds: Vec<String> = self
            .by_kind
            .iter()
            .map(|(kind, n)| format!("{kind} {n}"))
            .collect();
        let kinds = if kinds.is_empty() {
            String::new()
        } else {
            format!(" ({})", kinds.join(", "))
        };
        writeln!(
            out,
            "  orbits       {} branches, {} bifurcations{kinds}, in {:.3} s; {} starts gave no orbit",
            self.branches,
            self.bifurcations(),
            self.time.as_secs_f64(),
            self.failed
        )
    }
}
