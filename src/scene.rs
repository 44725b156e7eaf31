//! The scene file: the TOML contract between users, documentation, tests and
//! outside checks.
//!
//! ```toml
//! name = "seed-fig3"              # default: the scene file's stem; output goes to out/<name>/
//! [system]                        # kind is the only required key
//! kind = "impact-oscillator"      # or "henon", "lorenz"; then that system's parameters
//! zeta = 0.05
//! [sweep]
//! parameter = "eta"               # default: the system's usual control parameter
//! from = 0.5                      # from, to, count (inclusive, evenly spaced; count default 101)
//! to = 1.5                        # ... or values = [..]; neither: the [system] value alone
//! count = 4096
//! [sweep.second]                  # optional: a second parameter, for a map over the grid
//! parameter = "f"                 #   (same keys; lanes run over the grid, first axis fastest)
//! values = [0.5, 1.0, 2.0]
//! [integration]
//! steps_per_period = 450          # RK4 steps per map period (flows; raised where a lane's
//!                                 #   fastest time scale needs it, and the summary says so)
//! transient = 500                 # iterations discarded before averaging
//! align = 50                      # of those, the last ones whose Jacobians turn the
//!                                 #   QR frame (default: a tenth of the transient)
//! iterations = 1000               # iterations averaged
//! initial_state = [0.0, 0.0]      # default: the system's (Lorenz: [1, 1, 1])
//! perturbation = 1e-6             # δ, relative to max(1, |x|) (f32: 2e-4)
//! difference = "central"          # or "forward" (the paper's)
//! impact_location = "newton"      # or "linear" (the paper's)
//! submaps = 1                     # parts per iteration; default: as many as the
//!                                 #   fastest contraction needs (CPU path)
//! [run]
//! backend = "auto"                # "cpu", "gpu", "exact"
//! precision = "f64"               # or "f32" (gpu only)
//! validate = 4                    # GPU runs: sweep values recomputed on the CPU
//! [output]
//! lyapunov = "spectrum"           # or "none"
//! bifurcation_points = 0          # last reference points kept per parameter value
//! plot = true                     # figures (PNG and SVG); default: when the sweep has
//!                                 #   more than one value
//! ```
//!
//! Unknown keys, wrong types and impossible values are errors that name the key.

use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::error::{clip, clip_quoted, Error, Result};
use crate::integrate::ImpactLocation;
use crate::method::jacobian::Difference;
use crate::system::{self, Params, SystemInfo};

/// Default RK4 steps per map period: the first step count on the measured
/// Pareto front (docs/BENCHMARKS.md) below 1e-8 with newton location and
/// central differences at δ = 1e-6, 2.3e-9 in 0.23 s on the bench's 17
/// values; 1800, the paper's, is 3.7 times slower there for no gain (the
/// seed's scene keeps it, to reproduce the paper). Lanes whose fastest time
/// scale needs more get more (`method::lane::plan_lane`).
pub const DEFAULT_STEPS_PER_PERIOD: usize = 450;
pub const DEFAULT_TRANSIENT: usize = 500;
/// Default `align`: the transient's last tenth. The frame Q starts from a
/// fixed frame (`method::qr::generic_frame`), and its projection onto the
/// directions of growth stays in the sums of
/// ln R_ii, a bias of O(1/N) over N averaged iterations (3e-4 per unit time
/// on the friction belt at η = 0.6, N = 300); turned by the Jacobians of
/// the transient's last iterations first, the frame starts the window
/// aligned, and on a periodic orbit the bias then vanishes with the
/// window a multiple of the orbit's period. The frame converges at the
/// rate of the gaps between exponents, so a tenth of the default 500 is
/// ample for the gaps this tool meets, for a twentieth of a run's work.
pub const DEFAULT_ALIGN_FRACTION: usize = 10;
pub const DEFAULT_ITERATIONS: usize = 1000;
/// Default δ in f64, for central differences (error O(δ²) against rounding
/// ε·√steps/δ, optimum near ε^(1/3)): on the measured front at 450 to 1800
/// steps (docs/BENCHMARKS.md), 30 to 200 times more accurate on the periodic
/// points than δ = 1e-8. Near-grazing iterations, where a large δ would
/// leave the linear regime, are re-estimated down a ladder of smaller δ
/// (`method::lane::estimate_resolving_grazing`).
pub const DEFAULT_PERTURBATION_F64: f64 = 1e-6;
/// Default δ in f32 (on the GPU, with central differences), relative to
/// max(1, ‖x‖∞) like every δ: the compensated f32 images carry about 1e-7
/// relative error, so δ must be large, and the O(δ²) error of central
/// differences allows it. Measured on lavapipe over 512 η in [0.5, 1.5] of the
/// seed's scene, the largest sum-rule error is 1.5e-4, 6.3e-5, 4.8e-4 and
/// 7.9e-4 at δ = 2e-4, 5e-4, 1e-3 and 2e-3: rounding limits small δ; above
/// 5e-4 a lane of the chaotic window, whose copies graze where the
/// reference does not, limits large δ, and the host re-estimates ever more
/// grazing iterations (93, 381, 813 and 7455). 5e-4's gain did not pay
/// for four times the re-estimations (docs/BENCHMARKS.md, "f32's
/// perturbation δ").
pub const DEFAULT_PERTURBATION_F32: f64 = 2e-4;
/// Default number of sweep values a GPU run recomputes on the CPU.
pub const DEFAULT_VALIDATE: usize = 4;
/// Evenly spaced values when a sweep gives `from` and `to` but no `count`.
pub const DEFAULT_COUNT: usize = 101;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Backend {
    /// A hardware GPU when there is one, otherwise the CPU.
    #[default]
    Auto,
    Cpu,
    Gpu,
    /// The closed-form tangent map: the ground truth.
    Exact,
}

impl Backend {
    pub fn name(self) -> &'static str {
        match self {
            Backend::Auto => "auto",
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
            Backend::Exact => "exact",
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    #[default]
    F64,
    F32,
}

impl Precision {
    pub fn name(self) -> &'static str {
        match self {
            Precision::F64 => "f64",
            Precision::F32 => "f32",
        }
    }

    /// The unit roundoff of the arithmetic, as an f64.
    pub fn rounding_unit(self) -> f64 {
        match self {
            Precision::F64 => f64::EPSILON,
            Precision::F32 => f64::from(f32::EPSILON),
        }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Lyapunov {
    #[default]
    Spectrum,
    None,
}

/// A scene, parsed, completed with defaults and checked.
#[derive(Clone, Debug)]
pub struct Scene {
    pub name: String,
    pub system: &'static SystemInfo,
    /// The `[system]` parameter values (the swept one at its scene value).
    pub params: Params,
    /// Shared by the batches a large run is streamed in (see [`Scene::batch`]).
    pub sweep: std::sync::Arc<Sweep>,
    pub integration: Integration,
    pub backend: Backend,
    pub precision: Precision,
    /// Sweep values a GPU run recomputes on the CPU to check itself.
    pub validate: usize,
    pub lyapunov: bool,
    pub bifurcation_points: usize,
    /// The points the scene file asked for, when `--set
    /// integration.iterations` lowered the iterations below them: a lane
    /// keeps at most one point per iteration, so `bifurcation_points` is
    /// lowered to the iterations (and the summary says so).
    pub bifurcation_points_asked: Option<usize>,
    /// Draw the figures next to the CSV files.
    pub plot: bool,
    /// The part of the sweep this run computes (`--shard i/n`), if not all.
    pub shard: Option<Shard>,
    /// The lanes of the shard (or sweep) computed now, when a large run is
    /// streamed in batches (see [`Scene::batch`]).
    pub batch: Option<std::ops::Range<usize>>,
    /// The scene as TOML after overrides (keys sorted), written next to the
    /// results so that `plot` and `merge` know what produced them.
    pub source: String,
    /// The files the scene was read from: the scene file and the model
    /// file it names (none for a scene given as text). Its output folder
    /// must not hold them.
    pub files: Vec<PathBuf>,
}

/// One swept parameter and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Axis {
    pub parameter: String,
    /// Index of the parameter in the system's list.
    pub index: usize,
    pub values: Vec<f64>,
}

/// What a scene sweeps: one parameter, or two (`[sweep.second]`) for a map
/// over their grid. Lanes run over the grid with the first axis fastest:
/// lane k is (first[k % n₁], second[k / n₁]).
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub first: Axis,
    pub second: Option<Axis>,
}

impl Sweep {
    /// Lanes in the whole sweep.
    pub fn lanes(&self) -> usize {
        self.first.values.len() * self.second.as_ref().map_or(1, |a| a.values.len())
    }

    /// The axes, first then second.
    pub fn axes(&self) -> impl Iterator<Item = &Axis> {
        std::iter::once(&self.first).chain(self.second.as_ref())
    }

    /// The swept values of lane `k`, one per axis.
    pub fn values_at(&self, k: usize) -> Vec<f64> {
        let n = self.first.values.len();
        let mut values = vec![self.first.values[k % n]];
        values.extend(self.second.as_ref().map(|a| a.values[k / n]));
        values
    }
}

/// Shard `index` of `count` (`--shard i/n`, counted from 0): sweep lanes
/// index, index + count, index + 2·count, …, so that every shard gets its
/// share of each region of the sweep (chaotic windows cost more).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl Shard {
    /// `i/n` as the command line gives it.
    pub fn parse(text: &str) -> Result<Shard> {
        let bad = |reason: &str| Error::invalid("--shard", format!("{:?}: {reason}", clip(text)));
        let (i, n) = text
            .split_once('/')
            .ok_or_else(|| bad("expected i/n, e.g. 0/4"))?;
        let number = |t: &str| {
            t.trim()
                .parse::<usize>()
                .map_err(|_| bad("i and n must be whole numbers"))
        };
        let (index, count) = (number(i)?, number(n)?);
        if count == 0 || index >= count {
            return Err(bad("needs 0 ≤ i < n"));
        }
        Ok(Shard { index, count })
    }

    /// The sweep lanes of this shard, in order.
    pub fn lanes(&self, sweep_lanes: usize) -> impl Iterator<Item = usize> {
        (self.index..sweep_lanes).step_by(self.count)
    }
}

#[derive(Clone, Debug, PartialEq)]
pub struct Integration {
    pub steps_per_period: usize,
    pub transient: usize,
    /// The transient's last iterations taken with Jacobians, to align the
    /// QR frame before the averaging (`method::lane`).
    pub align: usize,
    pub iterations: usize,
    pub initial_state: Vec<f64>,
    /// δ as the scene gives it; [`Scene::perturbation`] applies the default.
    pub perturbation: Option<f64>,
    /// As the scene gives it; [`Scene::difference`] applies the default.
    pub difference: Option<Difference>,
    pub impact_location: ImpactLocation,
    /// Parts per iteration, when the scene fixes them; otherwise each lane
    /// takes what its fastest contraction needs.
    pub submaps: Option<usize>,
}

impl Integration {
    /// The RK4 trajectory-steps of one lane: the reference over the transient,
    /// and with its `copies` over the aligning and averaged iterations, at the
    /// requested steps (lanes may need more).
    pub fn steps_per_lane(&self, is_flow: bool, copies: usize) -> f64 {
        let steps = if is_flow {
            self.steps_per_period as f64
        } else {
            1.0
        };
        let i = self;
        let plain = (i.transient - i.align) as f64;
        let with_copies = (i.align + i.iterations) as f64 * (1 + copies) as f64;
        (plain + with_copies) * steps
    }
}

impl Scene {
    /// The difference scheme: the scene's, or central. Central differences
    /// are what lets a column switch sides when a copy crosses a grazing
    /// boundary the reference does not: with the paper's forward differences
    /// the seed's 4096-value sweep missed the sum rule by up to 8e-4 at 6
    /// values in the chaotic window (1.2e-4 over 401 values of [0.70, 0.74]),
    /// with central ones by at most 2.3e-6, for 1.3 times the work (δ = 1e-8).
    /// In f32 the O(δ²) error also lets δ be large against rounding.
    pub fn difference(&self) -> Difference {
        self.integration.difference.unwrap_or(Difference::Central)
    }

    /// δ of the perturbed copies: the scene's, or the default for its precision.
    pub fn perturbation(&self) -> f64 {
        self.integration
            .perturbation
            .unwrap_or(match self.precision {
                Precision::F64 => DEFAULT_PERTURBATION_F64,
                Precision::F32 => DEFAULT_PERTURBATION_F32,
            })
    }

    /// Lanes this run computes: the sweep's, or its shard's, or of the
    /// batch being computed.
    pub fn lane_count(&self) -> usize {
        self.batch
            .as_ref()
            .map_or(self.run_lane_count(), |b| b.len())
    }

    /// Lanes of the whole run: the sweep's, or its shard's (batches aside).
    pub fn run_lane_count(&self) -> usize {
        let all = self.sweep.lanes();
        self.shard.map_or(all, |s| s.lanes(all).count())
    }

    /// The sweep lane of this run's lane `j`.
    pub fn sweep_lane(&self, j: usize) -> usize {
        let j = self.batch.as_ref().map_or(j, |b| b.start + j);
        self.shard.map_or(j, |s| s.index + j * s.count)
    }

    /// This scene restricted to lanes `range` of its run (of the shard,
    /// when sharded): a batch of a run streamed in parts. Every lane is
    /// computed as in the whole run.
    pub fn batch(&self, range: std::ops::Range<usize>) -> Scene {
        Scene {
            batch: Some(range),
            ..self.clone()
        }
    }

    /// The parameter values of sweep lane `k` (of the whole sweep).
    pub fn params_at(&self, k: usize) -> Params {
        let mut p = self.params.clone();
        for (axis, value) in self.sweep.axes().zip(self.sweep.values_at(k)) {
            p.set(axis.index, value);
        }
        p
    }

    /// The parameter values of this run's lane `j`.
    pub fn lane_params(&self, j: usize) -> Params {
        self.params_at(self.sweep_lane(j))
    }

    /// The swept values of this run's lane `j`, one per axis.
    pub fn lane_values(&self, j: usize) -> Vec<f64> {
        self.sweep.values_at(self.sweep_lane(j))
    }

    /// "eta = 0.7" or "eta = 0.7, f = 2": where sweep lane `k` is.
    pub fn describe(&self, k: usize) -> String {
        self.sweep
            .axes()
            .zip(self.sweep.values_at(k))
            .map(|(axis, v)| format!("{} = {v}", axis.parameter))
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The `[integration]` keys the scene sets that `backend` does not use
    /// (the exact backend propagates in closed form; a system without a
    /// wall locates no impacts), for the summary to say so.
    pub fn unused_keys(&self, backend: Backend) -> Vec<String> {
        let set: Vec<String> = self
            .source
            .parse::<toml::Table>()
            .ok()
            .and_then(|t| t.get("integration").and_then(|i| i.as_table()).cloned())
            .map(|i| i.keys().cloned().collect())
            .unwrap_or_default();
        let mut unused: Vec<&str> = Vec::new();
        if backend == Backend::Exact {
            unused.extend([
                "steps_per_period",
                "perturbation",
                "difference",
                "impact_location",
            ]);
        }
        if self.system.wall_reachable.is_none() || !self.system.is_flow {
            unused.push("impact_location");
        }
        if !self.system.is_flow {
            unused.push("steps_per_period");
        }
        unused.sort_unstable();
        unused.dedup();
        unused
            .into_iter()
            .filter(|k| set.iter().any(|s| s == k))
            .map(|k| format!("integration.{k}"))
            .collect()
    }

    /// This scene restricted to `shard` (checked against the sweep's size).
    pub fn sharded(mut self, shard: Shard) -> Result<Scene> {
        let lanes = self.sweep.lanes();
        if shard.count > lanes {
            return Err(Error::invalid(
                "--shard",
                format!(
                    "{}/{}: the sweep has {lanes} lanes, so it splits into at most {lanes} shards (shards {lanes} to {} of {} would be empty)",
                    shard.index,
                    shard.count,
                    shard.count - 1,
                    shard.count
                ),
            ));
        }
        self.shard = Some(shard);
        Ok(self)
    }
}

// The file's shape. `[system]` is read by hand: its keys depend on `kind`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    system: Option<toml::Table>,
    /// A system given as data (see `crate::model`); a file's name is
    /// replaced by the file's table before anything else reads the scene.
    model: Option<toml::Value>,
    #[serde(default)]
    sweep: RawSweep,
    #[serde(default)]
    integration: RawIntegration,
    #[serde(default)]
    run: RawRun,
    #[serde(default)]
    output: RawOutput,
}

// The first axis's keys are spelled out rather than flattened from
// RawAxis: serde's flatten loses the key of a bad value ("sweep: invalid
// type" instead of "sweep.count: invalid type").
#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSweep {
    parameter: Option<String>,
    from: Option<f64>,
    to: Option<f64>,
    count: Option<usize>,
    values: Option<Vec<f64>>,
    second: Option<RawAxis>,
}

impl RawSweep {
    fn first(&self) -> RawAxis {
        RawAxis {
            parameter: self.parameter.clone(),
            from: self.from,
            to: self.to,
            count: self.count,
            values: self.values.clone(),
        }
    }
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAxis {
    parameter: Option<String>,
    from: Option<f64>,
    to: Option<f64>,
    count: Option<usize>,
    values: Option<Vec<f64>>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawIntegration {
    steps_per_period: Option<usize>,
    transient: Option<usize>,
    align: Option<usize>,
    iterations: Option<usize>,
    initial_state: Option<Vec<f64>>,
    perturbation: Option<f64>,
    difference: Option<Difference>,
    impact_location: Option<ImpactLocation>,
    submaps: Option<usize>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRun {
    backend: Option<Backend>,
    precision: Option<Precision>,
    validate: Option<usize>,
}

#[derive(Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawOutput {
    lyapunov: Option<Lyapunov>,
    bifurcation_points: Option<usize>,
    plot: Option<bool>,
}

/// Reads and checks a scene file, applying `--set key.path=value` overrides first.
pub fn load(path: &Path, overrides: &[String]) -> Result<Scene> {
    load_shard(path, overrides, None)
}

/// [`load`], restricted to `shard` of the sweep: the run's size is checked
/// for the shard's lanes (see `limits::check_sweep`).
pub fn load_shard(path: &Path, overrides: &[String], shard: Option<Shard>) -> Result<Scene> {
    let text = std::fs::read_to_string(path).map_err(|source| Error::ReadScene {
        path: path.to_owned(),
        source,
    })?;
    let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("scene");
    let mut scene = parse_in(
        &text,
        &path.display().to_string(),
        stem,
        overrides,
        shard,
        path.parent(),
    )?;
    scene.files.insert(0, path.to_owned());
    Ok(scene)
}

/// Parses scene text; `origin` names it in messages, `default_name` is the
/// name when the scene gives none.
pub fn parse(text: &str, origin: &str, default_name: &str, overrides: &[String]) -> Result<Scene> {
    parse_shard(text, origin, default_name, overrides, None)
}

/// [`parse`], restricted to `shard` (see [`load_shard`]).
pub fn parse_shard(
    text: &str,
    origin: &str,
    default_name: &str,
    overrides: &[String],
    shard: Option<Shard>,
) -> Result<Scene> {
    parse_in(text, origin, default_name, overrides, shard, None)
}

/// [`parse_shard`] of a scene whose `model = "file"` is relative to `base`
/// (the working directory when `None`).
fn parse_in(
    text: &str,
    origin: &str,
    default_name: &str,
    overrides: &[String],
    shard: Option<Shard>,
    base: Option<&Path>,
) -> Result<Scene> {
    let mut table: toml::Table = text.parse().map_err(|e: toml::de::Error| {
        let at = e.span().map(|span| {
            let line = text[..span.start].matches('\n').count() + 1;
            format!("line {line}: ")
        });
        Error::Syntax {
            path: origin.to_owned(),
            message: format!(
                "{}{}",
                at.unwrap_or_default(),
                clip_quoted(e.message().trim())
            ),
        }
    })?;
    let model_file = inline_model_file(&mut table, base)?;
    let mut overridden = Vec::new();
    for o in overrides {
        check_model_override(&table, o)?;
        overridden.push((apply_override(&mut table, o, model_file.as_deref())?, o));
    }
    let overrides_set = |key: &str| {
        overridden
            .iter()
            .any(|(o, _)| key == o || key.starts_with(&format!("{o}.")))
    };
    // A quick look (`--set integration.iterations=10`) keeps the points the
    // scene asked for up to the iterations there are, rather than refusing
    // every scene that keeps points; points given by `--set`, or a scene
    // that asks for more points than its own iterations, are still refused.
    let bifurcation_points_asked =
        if overrides_set("integration.iterations") && !overrides_set("output.bifurcation_points") {
            lower_bifurcation_points(&mut table)
        } else {
            None
        };
    // The name goes into the written scene, so that it reads back the same
    // wherever the file lies.
    table
        .entry("name")
        .or_insert_with(|| toml::Value::String(default_name.to_owned()));
    let source = toml::to_string(&table).expect("a parsed table serialises");
    let raw: RawScene =
        serde_path_to_error::deserialize(toml::Value::Table(table)).map_err(|e| {
            let path = e.path().to_string();
            let key = if path == "." {
                String::new()
            } else {
                format!("{}: ", clip(&path))
            };
            // The value deserializer appends "in `path`" on a second line;
            // the path is already in front.
            let inner = e.inner().to_string();
            let first_line = clip_quoted(inner.lines().next().unwrap_or_default().trim());
            // A value an override gave is the override's fault, not the file's.
            let from = |key: &str| {
                path == key
                    || path.starts_with(&format!("{key}."))
                    || path.starts_with(&format!("{key}["))
            };
            match overridden.iter().rev().find(|(key, _)| from(key)) {
                Some((_, assignment)) => {
                    Error::invalid(set_key(assignment), format!("{key}{first_line}"))
                }
                None => Error::Syntax {
                    path: origin.to_owned(),
                    message: format!("{key}{first_line}"),
                },
            }
        })?;
    let mut scene = resolve(raw, default_name, source, shard)
        .map_err(|e| model_error(e, model_file.as_deref(), &overridden))?;
    scene.bifurcation_points_asked = bifurcation_points_asked;
    scene.files.extend(model_file);
    match shard {
        Some(shard) => scene.sharded(shard),
        None => Ok(scene),
    }
}

/// `--set integration.iterations=2000`: the value is read as TOML, or as a
/// string when it is a bare word (so `--set run.backend=cpu` works); returns
/// the key's path ("integration.iterations"). A key of the path may index
/// an array (`model.events[0].surface`), which must hold that element;
/// `model_file` is where the scene's model came from, for messages.
fn apply_override(
    table: &mut toml::Table,
    assignment: &str,
    model_file: Option<&Path>,
) -> Result<String> {
    let bad = |reason: &str| Error::invalid(set_key(assignment), reason);
    let (path, value) = assignment
        .split_once('=')
        .ok_or_else(|| bad("expected key.path=value"))?;
    let bare_word = |v: &str| {
        v.chars().next().is_some_and(|c| c.is_ascii_alphabetic())
            && v.chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
    };
    let value: toml::Value = match format!("v = {value}").parse::<toml::Table>() {
        Ok(mut t) => t.remove("v").expect("just parsed"),
        Err(_) if bare_word(value.trim()) => toml::Value::String(value.trim().to_owned()),
        Err(e) => {
            return Err(bad(&format!(
                "the value is not TOML ({}); quote a string: key='\"text\"'",
                clip_quoted(&e.message().split_whitespace().collect::<Vec<_>>().join(" "))
            )))
        }
    };
    let steps = override_path(path.trim()).map_err(|reason| bad(&reason))?;
    // Where a key of the model is looked for, when the model is a file's.
    let of_model = |shown: &str| match model_file {
        Some(file) if shown == "model" || shown.starts_with("model.") => {
            format!(" (the scene's model is {})", file.display())
        }
        _ => String::new(),
    };
    let (last, parents) = steps.split_last().expect("a path has at least one key");
    // The root is taken out of `table` to be walked as a value, and put back
    // whatever the outcome.
    let mut root = toml::Value::Table(std::mem::take(table));
    let result = (|| {
        let mut node = &mut root;
        let mut shown = String::new();
        for (k, step) in parents.iter().enumerate() {
            let next_indexes = matches!(steps[k + 1], Step::Index(_));
            node = match step {
                Step::Key(key) => {
                    let map = node.as_table_mut().ok_or_else(|| {
                        format!("`{}` is not a table{}", clip(&shown), of_model(&shown))
                    })?;
                    let path = step.after(&shown);
                    if next_indexes && !map.contains_key(key) {
                        return Err(format!(
                            "`{}` is not in the scene: there is no array to index{}",
                            clip(&path),
                            of_model(&path)
                        ));
                    }
                    shown = path;
                    map.entry(key.clone())
                        .or_insert_with(|| toml::Value::Table(toml::Table::new()))
                }
                Step::Index(i) => {
                    let element = element(node, *i, &shown).map_err(|e| e + &of_model(&shown))?;
                    shown = step.after(&shown);
                    element
                }
            };
        }
        match last {
            Step::Key(key) => {
                let map = node.as_table_mut().ok_or_else(|| {
                    format!("`{}` is not a table{}", clip(&shown), of_model(&shown))
                })?;
                match map.get_mut(key) {
                    // A model parameter given with its range ({ value, min, max }):
                    // the override sets its value and keeps the range.
                    Some(toml::Value::Table(parameter))
                        if parameter.contains_key("value") && !value.is_table() =>
                    {
                        parameter.insert("value".into(), value);
                    }
                    _ => {
                        map.insert(key.clone(), value);
                    }
                }
            }
            Step::Index(i) => {
                *element(node, *i, &shown).map_err(|e| e + &of_model(&shown))? = value;
            }
        }
        Ok(())
    })();
    let toml::Value::Table(root) = root else {
        unreachable!("the root stays a table")
    };
    *table = root;
    result.map_err(|reason| bad(&reason))?;
    Ok(steps
        .iter()
        .fold(String::new(), |shown, step| step.after(&shown)))
}

/// One step of an override's path: a key of a table, or an element of an
/// array.
#[derive(Debug, PartialEq)]
enum Step {
    Key(String),
    Index(usize),
}

impl Step {
    /// The path `shown` followed by this step, as messages and serde's
    /// paths spell it ("model.events[0].surface").
    fn after(&self, shown: &str) -> String {
        match self {
            Step::Key(key) if shown.is_empty() => key.clone(),
            Step::Key(key) => format!("{shown}.{key}"),
            Step::Index(i) => format!("{shown}[{i}]"),
        }
    }
}

/// `model.events[0].surface` as steps: dotted keys, each followed by any
/// number of `[i]`.
fn override_path(path: &str) -> std::result::Result<Vec<Step>, String> {
    let mut steps = Vec::new();
    for part in path.split('.') {
        let (key, mut indexes) = part.split_at(part.find('[').unwrap_or(part.len()));
        if key.is_empty() {
            return Err("empty key in the path".into());
        }
        if key.contains(']') {
            return Err(format!("`{}`: a `]` without its `[`", clip(part)));
        }
        steps.push(Step::Key(key.to_owned()));
        while !indexes.is_empty() {
            let index = indexes
                .strip_prefix('[')
                .and_then(|rest| rest.split_once(']'))
                .and_then(|(number, rest)| Some((number.trim().parse::<usize>().ok()?, rest)));
            let Some((i, rest)) = index else {
                return Err(format!(
                    "`{}`: an index is written [n], n a whole number from 0",
                    clip(part)
                ));
            };
            steps.push(Step::Index(i));
            indexes = rest;
        }
    }
    Ok(steps)
}

/// Element `i` of the array `node` (at `shown`), or why there is none.
fn element<'a>(
    node: &'a mut toml::Value,
    i: usize,
    shown: &str,
) -> std::result::Result<&'a mut toml::Value, String> {
    let Some(array) = node.as_array_mut() else {
        return Err(format!(
            "`{}` is not an array, so it has no element [{i}]",
            clip(shown)
        ));
    };
    let len = array.len();
    array.get_mut(i).ok_or_else(|| match len {
        0 => format!("`{}` is empty: there is no element [{i}]", clip(shown)),
        _ => format!(
            "`{}` has {len} element{}, [0] to [{}]: there is no [{i}]",
            clip(shown),
            if len == 1 { "" } else { "s" },
            len - 1
        ),
    })
}

/// The key of an error in `--set ASSIGNMENT`, the assignment clipped.
fn set_key(assignment: &str) -> String {
    format!("--set {}", clip(assignment))
}

/// Lowers `output.bifurcation_points` to `integration.iterations` where it
/// exceeds them; returns the points it asked for, when lowered. Values of
/// the wrong type are left for the scene's checks to name.
fn lower_bifurcation_points(table: &mut toml::Table) -> Option<usize> {
    let iterations = table
        .get("integration")
        .and_then(|i| i.get("iterations"))
        .and_then(|i| i.as_integer())
        .filter(|&i| i >= 1)?;
    let points = table
        .get_mut("output")
        .and_then(|o| o.as_table_mut())
        .and_then(|o| o.get_mut("bifurcation_points"))?;
    let asked = points.as_integer().filter(|&p| p > iterations)?;
    *points = toml::Value::Integer(iterations);
    usize::try_from(asked).ok()
}

/// An error about a key of `[model]`, its key clipped, and said to be an
/// override's when `--set` gave the key (a value of the user's command
/// line, not of a file), or else, when the model is another file's (`model
/// = "file.toml"`), that file's: the key is written there, not in the
/// scene.
fn model_error(e: Error, file: Option<&Path>, overridden: &[(String, &String)]) -> Error {
    let Error::Invalid { key, reason } = e else {
        return e;
    };
    if !key.starts_with("model.") {
        return Error::Invalid { key, reason };
    }
    let from = |o: &str| {
        key == o || key.starts_with(&format!("{o}.")) || key.starts_with(&format!("{o}["))
    };
    match (overridden.iter().rev().find(|(o, _)| from(o)), file) {
        (Some((_, assignment)), _) => {
            Error::invalid(set_key(assignment), format!("{}: {reason}", clip(&key)))
        }
        (None, Some(file)) => {
            Error::invalid(format!("{} in {}", clip(&key), file.display()), reason)
        }
        (None, None) => Error::invalid(clip(&key), reason),
    }
}

fn resolve(
    raw: RawScene,
    default_name: &str,
    source: String,
    shard: Option<Shard>,
) -> Result<Scene> {
    let (info, params) = match (&raw.system, &raw.model) {
        (Some(_), Some(_)) => {
            return Err(Error::invalid(
                "model",
                "a scene gives [system] or [model], not both",
            ))
        }
        (Some(system), None) => resolve_system(system)?,
        (None, Some(model)) => resolve_model(model)?,
        (None, None) => {
            return Err(Error::invalid(
                "system",
                "is required: [system] with a kind, or a [model] (or model = \"file.toml\")",
            ))
        }
    };

    let i = raw.integration;
    let transient = i.transient.unwrap_or(DEFAULT_TRANSIENT);
    let align = match i.align {
        Some(align) if align > transient => {
            return Err(Error::invalid(
                "integration.align",
                format!(
                    "the aligning iterations are the transient's last ones: \
                     must not exceed integration.transient ({transient}), got {align}"
                ),
            ))
        }
        Some(align) => align,
        None => transient / DEFAULT_ALIGN_FRACTION,
    };
    let integration = Integration {
        steps_per_period: positive(
            "integration.steps_per_period",
            i.steps_per_period,
            DEFAULT_STEPS_PER_PERIOD,
        )?,
        transient,
        align,
        iterations: positive("integration.iterations", i.iterations, DEFAULT_ITERATIONS)?,
        initial_state: i
            .initial_state
            .unwrap_or_else(|| info.default_initial_state.to_vec()),
        perturbation: i.perturbation,
        difference: i.difference,
        impact_location: i.impact_location.unwrap_or_default(),
        submaps: match i.submaps {
            Some(n) => Some(positive("integration.submaps", Some(n), 1)?),
            None => None,
        },
    };
    // The run's size is checked before the sweep's values are generated:
    // the values, one lane's points, and the work of this process's lanes.
    let mut counts = vec![("sweep.count".to_owned(), axis_len(&raw.sweep.first()))];
    if let Some(second) = &raw.sweep.second {
        counts.push(("sweep.second.count".to_owned(), axis_len(second)));
    }
    let lyapunov = raw.output.lyapunov.unwrap_or_default() == Lyapunov::Spectrum;
    let copies = if lyapunov {
        integration
            .difference
            .unwrap_or(Difference::Central)
            .copies(info.dimension())
    } else {
        0
    };
    crate::limits::check_sweep(
        &counts,
        info.dimension(),
        raw.output.bifurcation_points.unwrap_or(0),
        integration.steps_per_lane(info.is_flow, copies),
        shard.map(|s| s.count),
    )?;
    let sweep = resolve_sweep(info, &params, raw.sweep)?;

    if let Some(delta) = integration
        .perturbation
        .filter(|d| !(d.is_finite() && *d > 0.0))
    {
        return Err(Error::invalid(
            "integration.perturbation",
            format!("must be a finite number > 0, got {delta}"),
        ));
    }
    let state = &integration.initial_state;
    let states = info.default_initial_state.len();
    if state.len() != states {
        let names = match info.model {
            Some(code) if states != info.dimension() => format!(
                "a point of the flow from which it reaches its Poincaré section: {}",
                code.model.names.states.join(", ")
            ),
            _ => info.state_names.join(", "),
        };
        return Err(Error::invalid(
            "integration.initial_state",
            format!(
                "{} has a {states}-dimensional state ({names}), got {} numbers",
                info.kind,
                state.len()
            ),
        ));
    }
    if let Some(v) = state.iter().find(|v| !v.is_finite()) {
        return Err(Error::invalid(
            "integration.initial_state",
            format!("must be finite, got {v}"),
        ));
    }
    // The start must be admissible at every swept value (the wall may be swept).
    // One copy of the parameters per axis, not per value: a sweep may have
    // 10^9 values.
    for axis in sweep.axes() {
        let mut p = params.clone();
        for (k, value) in axis.values.iter().enumerate() {
            p.set(axis.index, *value);
            (info.check_state)(&p, state).map_err(|reason| {
                let at = if axis.values.len() > 1 {
                    format!(" (at {} = {value}, sweep value {k})", axis.parameter)
                } else {
                    String::new()
                };
                Error::invalid("integration.initial_state", format!("{reason}{at}"))
            })?;
        }
    }

    let bifurcation_points = raw.output.bifurcation_points.unwrap_or(0);
    if bifurcation_points > integration.iterations {
        return Err(Error::invalid(
            "output.bifurcation_points",
            format!(
                "must not exceed integration.iterations ({}), got {bifurcation_points}",
                integration.iterations
            ),
        ));
    }
    if !lyapunov && bifurcation_points == 0 {
        return Err(Error::invalid(
            "output.lyapunov",
            "\"none\" with bifurcation_points = 0 leaves nothing to compute",
        ));
    }

    let name = raw.name.unwrap_or_else(|| default_name.to_owned());
    if name.is_empty() || name.contains(['/', '\\']) || name == "." || name == ".." {
        return Err(Error::invalid(
            "name",
            format!("must be a plain folder name, got {:?}", clip(&name)),
        ));
    }
    let precision = raw.run.precision.unwrap_or_default();
    // A δ below a few units of rounding starts the copies where the
    // reference is: every column would be 0/0.
    let unit = precision.rounding_unit();
    if let Some(delta) = integration.perturbation.filter(|&d| d < 4.0 * unit) {
        return Err(Error::invalid(
            "integration.perturbation",
            format!(
                "{delta:e} is below what {} resolves (x + δ·max(1, |x|) would round to x): it must be at least {:.1e}",
                precision.name(),
                4.0 * unit
            ),
        ));
    }
    let plot = raw.output.plot.unwrap_or(sweep.lanes() > 1);
    Ok(Scene {
        name,
        system: info,
        params,
        sweep: std::sync::Arc::new(sweep),
        integration,
        backend: raw.run.backend.unwrap_or_default(),
        precision,
        validate: raw.run.validate.unwrap_or(DEFAULT_VALIDATE),
        lyapunov,
        bifurcation_points,
        plot,
        shard: None,
        batch: None,
        source,
        bifurcation_points_asked: None,
        files: Vec::new(),
    })
}

/// The values an axis will have (its checks come later).
fn axis_len(raw: &RawAxis) -> usize {
    match (&raw.values, raw.from, raw.to) {
        (Some(values), _, _) => values.len(),
        (None, Some(_), Some(_)) => raw.count.unwrap_or(DEFAULT_COUNT),
        _ => 1,
    }
}

fn positive(key: &str, value: Option<usize>, default: usize) -> Result<usize> {
    match value {
        Some(0) => Err(Error::invalid(key, "must be at least 1, got 0")),
        Some(v) => Ok(v),
        None => Ok(default),
    }
}

/// A `[model]` table: parsed, compiled, and checked at its defaults.
fn resolve_model(table: &toml::Value) -> Result<(&'static SystemInfo, Params)> {
    let model = crate::model::Model::parse(table, "model")?;
    let info = system::model::info(crate::model::code::Code::compile(model, "model")?);
    let params = Params::defaults(info);
    (info.check)(&params).map_err(|(name, reason)| Error::invalid(info.key(name), reason))?;
    Ok((info, params))
}

/// A scene's `model = "file.toml"` replaced by the file's model table (its
/// `[model]`, or the whole file), read relative to `base`, so that
/// overrides and the written scene see the model itself; returns the
/// file's path.
fn inline_model_file(table: &mut toml::Table, base: Option<&Path>) -> Result<Option<PathBuf>> {
    let Some(toml::Value::String(file)) = table.get("model") else {
        return Ok(None);
    };
    let path = model_path(file, base);
    let model = crate::model::read_table(&path)?;
    table.insert("model".into(), model);
    Ok(Some(path))
}

/// The model file a scene's `model = "file"` names, relative to the
/// scene's folder `base` (the working directory when `None`).
pub fn model_path(file: &str, base: Option<&Path>) -> PathBuf {
    base.map_or_else(|| Path::new(file).to_owned(), |b| b.join(file))
}

/// `--set model.parameters.NAME=...` must name a parameter the model has:
/// a new key there would be a parameter nothing reads (a typo, silently).
fn check_model_override(table: &toml::Table, assignment: &str) -> Result<()> {
    let path = assignment
        .split_once('=')
        .map_or(assignment, |(p, _)| p)
        .trim();
    let Some(name) = path.strip_prefix("model.parameters.") else {
        return Ok(());
    };
    let parameters = table
        .get("model")
        .and_then(|m| m.get("parameters"))
        .and_then(|p| p.as_table());
    match parameters {
        Some(p) if !p.contains_key(name) => Err(Error::invalid(
            set_key(assignment),
            format!(
                "the model has no parameter `{}` (its parameters: {})",
                clip(name),
                p.keys().cloned().collect::<Vec<_>>().join(", ")
            ),
        )),
        _ => Ok(()),
    }
}

fn resolve_system(table: &toml::Table) -> Result<(&'static SystemInfo, Params)> {
    let kinds = || {
        system::kinds()
            .map(|kind| format!("\"{kind}\""))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let kind = match table.get("kind") {
        None => {
            return Err(Error::invalid(
                "system.kind",
                format!("is required (one of {})", kinds()),
            ))
        }
        Some(toml::Value::String(k)) => k,
        Some(other) => {
            return Err(Error::invalid(
                "system.kind",
                format!("expected a string, got {other}"),
            ))
        }
    };
    let info = system::by_kind(kind).ok_or_else(|| {
        Error::invalid(
            "system.kind",
            format!("unknown system \"{}\" (known: {})", clip(kind), kinds()),
        )
    })?;
    let mut params = Params::defaults(info);
    for (key, value) in table {
        if key == "kind" {
            continue;
        }
        let index = info.parameter_index(key).ok_or_else(|| {
            Error::invalid(
                format!("system.{}", clip(key)),
                format!(
                    "{kind} has no parameter `{}` (its parameters: {})",
                    clip(key),
                    info.parameter_names()
                ),
            )
        })?;
        let number = match value {
            toml::Value::Float(v) => *v,
            toml::Value::Integer(v) => *v as f64,
            other => {
                return Err(Error::invalid(
                    format!("system.{key}"),
                    format!("expected a number, got {other}"),
                ))
            }
        };
        params.set(index, number);
    }
    (info.check)(&params).map_err(|(name, reason)| Error::invalid(info.key(name), reason))?;
    Ok((info, params))
}

fn resolve_sweep(info: &'static SystemInfo, params: &Params, raw: RawSweep) -> Result<Sweep> {
    let first = resolve_axis(info, params, raw.first(), "sweep")?;
    let second = match raw.second {
        None => None,
        Some(axis) => {
            if axis.parameter.is_none() {
                return Err(Error::invalid(
                    "sweep.second.parameter",
                    "is required: which parameter is the second axis",
                ));
            }
            let second = resolve_axis(info, params, axis, "sweep.second")?;
            if second.index == first.index {
                return Err(Error::invalid(
                    "sweep.second.parameter",
                    format!("{} is already the first axis", second.parameter),
                ));
            }
            Some(second)
        }
    };
    // Each axis was checked with the other at its [system] value; the
    // grid's corners must be valid too (a check may couple parameters).
    if let Some(second) = &second {
        let mut p = params.clone();
        for &x in &first.values {
            for &y in &second.values {
                p.set(first.index, x);
                p.set(second.index, y);
                (info.check)(&p).map_err(|(name, reason)| {
                    Error::invalid(
                        info.key(name),
                        format!(
                            "{reason} (at {} = {x}, {} = {y})",
                            first.parameter, second.parameter
                        ),
                    )
                })?;
            }
        }
    }
    Ok(Sweep { first, second })
}

/// One axis of `[sweep]` (`table` names it in messages: "sweep" or
/// "sweep.second").
fn resolve_axis(
    info: &'static SystemInfo,
    params: &Params,
    raw: RawAxis,
    table: &str,
) -> Result<Axis> {
    let key = |name: &str| format!("{table}.{name}");
    let parameter = raw
        .parameter
        .unwrap_or_else(|| info.default_sweep.to_owned());
    let index = info.parameter_index(&parameter).ok_or_else(|| {
        Error::invalid(
            key("parameter"),
            format!(
                "{} has no parameter `{}` (its parameters: {})",
                info.kind,
                clip(&parameter),
                info.parameter_names()
            ),
        )
    })?;
    // Which key a bad value came from ("from" for a generated one, "to" for
    // the last), and the values.
    let (values, source) = match (raw.values, raw.from, raw.to) {
        (Some(_), Some(_), _) | (Some(_), _, Some(_)) => {
            return Err(Error::invalid(
                key("values"),
                "give either values or from/to/count, not both",
            ))
        }
        (Some(_), None, None) if raw.count.is_some() => {
            return Err(Error::invalid(
                key("count"),
                "goes with from and to, not with values",
            ))
        }
        (Some(values), None, None) => {
            if values.is_empty() {
                return Err(Error::invalid(
                    key("values"),
                    "must hold at least one value",
                ));
            }
            (values, "values")
        }
        (None, Some(from), Some(to)) => {
            let count = positive(&key("count"), raw.count, DEFAULT_COUNT)?;
            for (name, v) in [("from", from), ("to", to)] {
                if !v.is_finite() {
                    return Err(Error::invalid(
                        key(name),
                        format!("must be finite, got {v}"),
                    ));
                }
            }
            let values = if count == 1 {
                vec![from]
            } else {
                (0..count)
                    .map(|k| from + (to - from) * k as f64 / (count - 1) as f64)
                    .collect()
            };
            (values, "from")
        }
        (None, Some(_), None) => {
            return Err(Error::invalid(
                key("to"),
                format!("is required with {}", key("from")),
            ))
        }
        (None, None, Some(_)) => {
            return Err(Error::invalid(
                key("from"),
                format!("is required with {}", key("to")),
            ))
        }
        (None, None, None) => {
            if raw.count.is_some() {
                return Err(Error::invalid(
                    key("count"),
                    format!("needs {} and {}", key("from"), key("to")),
                ));
            }
            (vec![params.values[index]], "system")
        }
    };
    let mut p = params.clone();
    for (k, value) in values.iter().enumerate() {
        p.set(index, *value);
        (info.check)(&p).map_err(|(name, reason)| {
            if name == parameter {
                let at = match source {
                    "from" if k + 1 == values.len() && values.len() > 1 => key("to"),
                    "system" => info.key(&parameter),
                    other => key(other),
                };
                Error::invalid(at, format!("{parameter} = {value}: {parameter} {reason}"))
            } else {
                Error::invalid(
                    info.key(name),
                    format!("{reason} (with {parameter} = {value})"),
                )
            }
        })?;
    }
    Ok(Axis {
        parameter,
        index,
        values,
    })
}
