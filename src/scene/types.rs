//! The checked scene and its parts: what a run is asked to compute.

use std::path::PathBuf;

use serde::Deserialize;

use super::defaults::{DEFAULT_PERTURBATION_F32, DEFAULT_PERTURBATION_F64};
pub use super::starts::{Layout, Starts};
use crate::error::{clip, Error, Result};
use crate::integrate::ImpactLocation;
use crate::method::jacobian::Difference;
use crate::system::{Params, SystemInfo};

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
    /// `[orbits]`: periodic orbits followed over the sweep's range after
    /// its lanes.
    pub orbits: Option<super::orbits::Orbits>,
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
/// over their grid, each point of the grid from one start or from many
/// (`[attractors]`). Lanes run over the starts fastest, then the grid with
/// its first axis fastest: with S starts, lane k is start k % S of the
/// point g = k / S, (first[g % n₁], second[g / n₁]).
#[derive(Clone, Debug, PartialEq)]
pub struct Sweep {
    pub first: Axis,
    pub second: Option<Axis>,
    /// Many starts per point of the grid, if the scene asks for them.
    pub starts: Option<Starts>,
    /// Lanes given one by one instead of points × starts: a continuation
    /// pass, each lane a neighbouring value's attractor carried over.
    pub seeds: Option<Vec<Seed>>,
}

/// A lane of a continuation pass: point `point` of the grid started from
/// `state`, numbered `start` among its point's lanes (after the scene's
/// own starts).
#[derive(Clone, Debug, PartialEq)]
pub struct Seed {
    pub point: usize,
    pub start: usize,
    pub state: Vec<f64>,
}

impl Sweep {
    /// Lanes in the whole sweep.
    pub fn lanes(&self) -> usize {
        match &self.seeds {
            Some(seeds) => seeds.len(),
            None => self.points() * self.starts_per_point(),
        }
    }

    /// The point of the grid lane `k` runs at.
    pub fn point_of(&self, k: usize) -> usize {
        match &self.seeds {
            Some(seeds) => seeds[k].point,
            None => k / self.starts_per_point(),
        }
    }

    /// Points of the parameter grid (values of a one-parameter sweep).
    pub fn points(&self) -> usize {
        self.first.values.len() * self.second.as_ref().map_or(1, |a| a.values.len())
    }

    /// Lanes per point of the grid: its starts (1 without `[attractors]`).
    pub fn starts_per_point(&self) -> usize {
        self.starts.as_ref().map_or(1, |s| s.states.len())
    }

    /// The longest orbit period a lane is tested for (`attractors.max_period`).
    pub fn max_period(&self) -> usize {
        self.starts
            .as_ref()
            .map_or(super::starts::DEFAULT_MAX_PERIOD, |s| s.max_period)
    }

    /// The start of lane `k` among its point's (0 without `[attractors]`).
    pub fn start_index(&self, k: usize) -> usize {
        match &self.seeds {
            Some(seeds) => seeds[k].start,
            None => k % self.starts_per_point(),
        }
    }

    /// The state lane `k` starts from: its start's, or `initial_state`.
    pub fn initial_state_at<'a>(&'a self, k: usize, initial_state: &'a [f64]) -> &'a [f64] {
        match (&self.seeds, &self.starts) {
            (Some(seeds), _) => &seeds[k].state,
            (None, Some(starts)) => &starts.states[self.start_index(k)],
            (None, None) => initial_state,
        }
    }

    /// The axes, first then second.
    pub fn axes(&self) -> impl Iterator<Item = &Axis> {
        std::iter::once(&self.first).chain(self.second.as_ref())
    }

    /// The swept values of lane `k`, one per axis.
    pub fn values_at(&self, k: usize) -> Vec<f64> {
        self.values_at_point(self.point_of(k))
    }

    /// The swept values at point `g` of the grid, one per axis.
    pub fn values_at_point(&self, g: usize) -> Vec<f64> {
        let n = self.first.values.len();
        let mut values = vec![self.first.values[g % n]];
        values.extend(self.second.as_ref().map(|a| a.values[g / n]));
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
        self.params_at_point(self.sweep.point_of(k))
    }

    /// The parameter values at point `g` of the grid.
    pub fn params_at_point(&self, g: usize) -> Params {
        let mut p = self.params.clone();
        for (axis, value) in self.sweep.axes().zip(self.sweep.values_at_point(g)) {
            p.set(axis.index, value);
        }
        p
    }

    /// This scene's lanes replaced by `seeds` (a continuation pass): the
    /// same system, values and settings, each lane started where its seed
    /// says.
    pub fn continued(&self, seeds: Vec<Seed>) -> Scene {
        Scene {
            sweep: std::sync::Arc::new(Sweep {
                seeds: Some(seeds),
                ..(*self.sweep).clone()
            }),
            shard: None,
            batch: None,
            ..self.clone()
        }
    }

    /// The parameter values of this run's lane `j`.
    pub fn lane_params(&self, j: usize) -> Params {
        self.params_at(self.sweep_lane(j))
    }

    /// The state this run's lane `j` starts from.
    pub fn lane_initial_state(&self, j: usize) -> &[f64] {
        self.sweep
            .initial_state_at(self.sweep_lane(j), &self.integration.initial_state)
    }

    /// Whether this run's lane `j` starts outside the admissible states at
    /// its values. Only a basin image's grid may hold such starts (the wall
    /// cuts the picture's box; the scene refuses them everywhere else), and
    /// they are not run: their lanes are [`LaneStatus::Inadmissible`].
    ///
    /// [`LaneStatus::Inadmissible`]: crate::method::LaneStatus::Inadmissible
    pub fn lane_start_inadmissible(&self, j: usize) -> bool {
        let images = self.sweep.seeds.is_none()
            && self
                .sweep
                .starts
                .as_ref()
                .is_some_and(Starts::may_be_inadmissible);
        images
            && (self.system.check_state)(&self.lane_params(j), self.lane_initial_state(j)).is_err()
    }

    /// The start of this run's lane `j` among its point's.
    pub fn lane_start(&self, j: usize) -> usize {
        self.sweep.start_index(self.sweep_lane(j))
    }

    /// The swept values of this run's lane `j`, one per axis.
    pub fn lane_values(&self, j: usize) -> Vec<f64> {
        self.sweep.values_at(self.sweep_lane(j))
    }

    /// "eta = 0.7" or "eta = 0.7, f = 2" (", start 3" with many starts):
    /// where sweep lane `k` is.
    pub fn describe(&self, k: usize) -> String {
        let mut at: Vec<String> = self
            .sweep
            .axes()
            .zip(self.sweep.values_at(k))
            .map(|(axis, v)| format!("{} = {}", axis.parameter, crate::error::number(v)))
            .collect();
        if self.sweep.starts.is_some() {
            at.push(format!("start {}", self.sweep.start_index(k)));
        }
        at.join(", ")
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
        if self.sweep.starts.is_some() {
            // A value's attractors are told apart from all its lanes, and
            // branches from its neighbours': a shard holds neither whole.
            return Err(Error::invalid(
                "--shard",
                "a scene with [attractors] runs whole: a value's starts and its neighbours are compared with each other",
            ));
        }
        if self.orbits.is_some() {
            return Err(Error::invalid(
                "--shard",
                "a scene with [orbits] runs whole: its branches are followed over the whole sweep's range",
            ));
        }
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
