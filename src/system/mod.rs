//! The dynamical systems, one file each, behind one trait.
//!
//! A system is what the method needs to know about a model: how one map
//! iteration x_{n+1} = U(x_n) is computed (a map formula, or a flow integrated
//! over one period with an optional wall), the period T of that iteration,
//! the sum of exponents the divergence theorem predicts, and, when a closed
//! form exists, the exact tangent map. A built-in system is its file here
//! (and, for the GPU backend, its WGSL twin in `shaders/`) and one line in
//! [`SYSTEMS`]; a user's system is a model ([`model`], [`section`]),
//! described at run time from a scene's `[model]` table.

pub mod henon;
pub mod impact_oscillator;
pub mod lorenz;
pub mod model;
pub mod section;

use nalgebra::SMatrix;

use crate::integrate::clock::Phase;

use crate::integrate::ImpactLocation;
use crate::method::Lane;

/// Every system the tool knows, by its scene `kind`.
pub static SYSTEMS: &[&SystemInfo] = &[&impact_oscillator::INFO, &henon::INFO, &lorenz::INFO];

/// Looks a system up by its scene `kind`.
pub fn by_kind(kind: &str) -> Option<&'static SystemInfo> {
    SYSTEMS.iter().copied().find(|s| s.kind == kind)
}

/// One named parameter of a system, with the value a scene gets when it omits it.
#[derive(Debug)]
pub struct Parameter {
    pub name: &'static str,
    pub default: f64,
    pub doc: &'static str,
}

/// The type-erased description of a system: everything the scene parser,
/// the output writers and the backends need without knowing its dimension.
pub struct SystemInfo {
    /// The scene's `[system] kind`.
    pub kind: &'static str,
    pub parameters: &'static [Parameter],
    /// Names of the map's state coordinates (the bifurcation CSV's columns).
    pub state_names: &'static [&'static str],
    /// The parameter swept when a scene's `[sweep]` names none.
    pub default_sweep: &'static str,
    pub default_initial_state: &'static [f64],
    /// Whether one iteration integrates a flow (so `steps_per_period` matters).
    pub is_flow: bool,
    /// Whether the `exact` backend (closed-form tangent map) exists for it.
    pub has_exact: bool,
    /// Checks parameter values; on failure names the parameter and the reason.
    pub check: fn(&Params) -> Result<(), (&'static str, String)>,
    /// Checks an initial state against the parameters (e.g. not behind a wall).
    pub check_state: fn(&Params, &[f64]) -> Result<(), String>,
    /// The exponent sum the phase-space volume law predicts, per unit time,
    /// given the measured impacts per unit time on each wall.
    pub expected_sum: fn(&Params, &[f64]) -> f64,
    /// The time T of one map iteration at these parameters.
    pub period: fn(&Params) -> f64,
    /// ω of the forcing (cos ωt enters the right-hand side); 0 if autonomous.
    pub forcing_frequency: fn(&Params) -> f64,
    /// Runs one lane on the dimension-specific code path.
    pub run_lane: fn(&Lane) -> crate::method::LaneResult,
    /// [`crate::method::lane::run_lanes`]: neighbouring lanes, their
    /// transients stepped together.
    pub run_lanes: fn(&[Lane]) -> Vec<crate::method::LaneResult>,
    /// Why the GPU kernels cannot run a lane with these parameters, if
    /// they cannot (what the CPU path models and the kernels do not yet).
    pub gpu_refuses: fn(&Params) -> Option<String>,
    /// One part's Jacobian (the whole iteration's, or a sub-map's) from x,
    /// re-estimated on the CPU with the grazing ladder
    /// (`method::lane::reestimate_of`): what the GPU host does with the
    /// parts its kernels flag as grazing. Row-major.
    pub reestimate: Reestimate,
    /// How a lane would be cut (`method::lane::plan_lane`), without running it.
    pub plan: fn(&Params, &crate::method::MethodSettings) -> crate::method::lane::LanePlan,
    /// The system's WGSL twin (`shaders/system/<kind>.wgsl`): its `Params`
    /// struct (fields in the order of `parameters`) and `rhs` for a flow
    /// (with `wall_position`/`wall_restitution` when it has a wall) or
    /// `map_step` for a map. `None`: no GPU backend for this system.
    pub wgsl: Option<&'static str>,
    /// Whether the trajectory from this start can reach the system's wall at
    /// these parameters (a conservative bound: `true` when unsure); `None`
    /// for a system without a wall. A sweep that cannot reach it runs GPU
    /// kernels compiled without impact code.
    pub wall_reachable: Option<fn(&Params, &[f64]) -> bool>,
    /// The compiled model of a system given as data (`None` for a built-in).
    pub model: Option<&'static model::Code>,
    /// The scene table its parameters are keys of ("system", or
    /// "model.parameters"), for messages.
    pub table: &'static str,
    /// The names of its walls (a model's events), one output column each;
    /// empty for the built-ins, whose one wall is `impacts_per_period`.
    pub events: &'static [&'static str],
}

impl SystemInfo {
    /// The dimension of the map (number of exponents).
    pub fn dimension(&self) -> usize {
        self.state_names.len()
    }

    pub fn parameter_index(&self, name: &str) -> Option<usize> {
        self.parameters.iter().position(|p| p.name == name)
    }

    /// The scene key of parameter (or other key) `name` in messages: a
    /// name with a dot is a whole key already ("model.map.period").
    pub fn key(&self, name: &str) -> String {
        if name.contains('.') {
            name.to_owned()
        } else {
            format!("{}.{name}", self.table)
        }
    }

    pub fn parameter_names(&self) -> String {
        let names: Vec<_> = self.parameters.iter().map(|p| p.name).collect();
        names.join(", ")
    }
}

impl std::fmt::Debug for SystemInfo {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SystemInfo")
            .field("kind", &self.kind)
            .finish()
    }
}

/// Parameter values of one system, in the order of its [`SystemInfo::parameters`].
#[derive(Clone, Debug)]
pub struct Params {
    pub info: &'static SystemInfo,
    pub values: Vec<f64>,
}

impl Params {
    /// The system's defaults.
    pub fn defaults(info: &'static SystemInfo) -> Self {
        Params {
            info,
            values: info.parameters.iter().map(|p| p.default).collect(),
        }
    }

    /// The value of a parameter. Panics on a name the system does not have,
    /// which is a programming error: scene names are checked on parsing.
    pub fn get(&self, name: &str) -> f64 {
        let i = self
            .info
            .parameter_index(name)
            .unwrap_or_else(|| panic!("{} has no parameter {name}", self.info.kind));
        self.values[i]
    }

    pub fn set(&mut self, index: usize, value: f64) {
        self.values[index] = value;
    }
}

/// How one flow iteration is integrated (the part of `[integration]` a system sees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FlowSettings {
    pub steps_per_period: usize,
    pub impact_location: ImpactLocation,
}

/// See [`SystemInfo::reestimate`].
pub type Reestimate =
    fn(&Params, &crate::method::MethodSettings, Part, &[f64]) -> (Vec<f64>, IterationStats);

/// Part `index` of `count` equal parts of one map iteration: a sub-map.
/// Over a long period a strongly contracting direction shrinks below what a
/// finite difference (or even a product of exact tangent maps) resolves, so
/// the method estimates the map as the composition of its parts, re-seeding
/// the perturbations and accumulating QR at each (see `method::lane`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Part {
    pub index: usize,
    pub count: usize,
}

impl Part {
    pub const WHOLE: Part = Part { index: 0, count: 1 };

    /// This part's share of `total` RK4 steps.
    pub fn steps(&self, total: usize) -> std::ops::Range<usize> {
        total * self.index / self.count..total * (self.index + 1) / self.count
    }

    /// This part's time span within a period (the last one ends at `period` exactly).
    pub fn span(&self, period: f64) -> (f64, f64) {
        let at = |k: usize| {
            if k == self.count {
                period
            } else {
                period * k as f64 / self.count as f64
            }
        };
        (at(self.index), at(self.index + 1))
    }

    /// The parts of one iteration, in order.
    pub fn all(count: usize) -> impl Iterator<Item = Part> {
        (0..count).map(move |index| Part { index, count })
    }
}

/// What happened during one map iteration of one trajectory.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IterationStats {
    /// Wall impacts during the iteration.
    pub impacts: u32,
    /// The crossings of each wall of the flow, in its order, then of each
    /// general surface (events and switches).
    pub crossings: [u32; crate::integrate::MAX_EVENTS],
    /// An integration step needed more impacts than the bound allows, or the
    /// mass was pressed into the wall: the iteration is not trustworthy.
    pub chattering: bool,
    /// A sliding motion that is not integrated (a wall or an event met
    /// while sliding, switches whose signs multiply in the field, a stick
    /// limit below Filippov's, or sliding on two switches at once in the
    /// exact propagator): the iteration is not trustworthy.
    pub sliding: bool,
    /// Dimensions the iteration collapsed: 1 after an impact with e = 0 (the
    /// velocity is forgotten), D after sticking (the state on release depends
    /// on the forcing alone). The map's Jacobian then has rank D - rank_loss
    /// and the last rank_loss exponents are -∞.
    pub rank_loss: u32,
    /// Sliding phases the iteration entered (one per switch a motion
    /// began to slide on): each collapses one direction where it
    /// happens, so together they bound the map's rank loss from above
    /// (`rank_loss`, the most switches slid on at once, bounds it from
    /// below; phases one after the other on two switches collapse two
    /// directions where the switches' motions are independent, one where
    /// the flow couples them). See `LaneAccumulator`.
    pub sliding_phases: u32,
    /// The slowest approach speed of the iteration's impacts (infinite
    /// without impacts): a slow impact is near grazing.
    pub slowest_impact: f64,
    /// Of a Jacobian estimate: how far the perturbed copies left the linear
    /// regime, as the largest relative difference between a copy's slowest
    /// impact speed and the reference's (infinite when a column's copies
    /// met the wall a different number of times on both sides); 0 without
    /// impacts. A finite difference is off by about this fraction (forward)
    /// or its square (central).
    pub nonlinearity: f64,
    /// Of a Jacobian estimate: re-estimated over a ladder of smaller δ
    /// because `nonlinearity` was too large for the Jacobian's conditioning
    /// (a grazing iteration).
    pub grazing: bool,
    /// Of a grazing iteration: the error left in ln R_ii of the chosen
    /// estimate, measured as the change between neighbouring rungs of the
    /// ladder (0 for other iterations).
    pub grazing_error: f64,
    /// The time the iteration took, where it is not the system's period
    /// (a Poincaré section's return time); 0 otherwise.
    pub time: f64,
    /// ln |F_k(start) / F_k(end)| of a section map on state k, plus
    /// ∫ div F dt along the reference where div F depends on the state,
    /// plus ln |det S| of every crossing of a general surface: the
    /// iteration's ln |det| beyond what the system's expected sum has
    /// (the determinant is exp(∫ div F dt)·F_k(start)/F_k(end)·Π det S);
    /// 0 otherwise.
    pub log_flux: f64,
}

impl IterationStats {
    /// Adds a part's statistics to its iteration's.
    pub fn merge(&mut self, part: &IterationStats) {
        self.impacts += part.impacts;
        for (c, p) in self.crossings.iter_mut().zip(part.crossings) {
            *c += p;
        }
        self.chattering |= part.chattering;
        self.rank_loss = self.rank_loss.max(part.rank_loss);
        self.sliding_phases += part.sliding_phases;
        self.slowest_impact = self.slowest_impact.min(part.slowest_impact);
        self.nonlinearity = self.nonlinearity.max(part.nonlinearity);
        self.grazing |= part.grazing;
        self.grazing_error += part.grazing_error;
        self.time += part.time;
        self.log_flux += part.log_flux;
        self.sliding |= part.sliding;
    }
}

impl Default for IterationStats {
    fn default() -> Self {
        IterationStats {
            impacts: 0,
            crossings: [0; crate::integrate::MAX_EVENTS],
            sliding: false,
            chattering: false,
            rank_loss: 0,
            sliding_phases: 0,
            slowest_impact: f64::INFINITY,
            nonlinearity: 0.0,
            grazing: false,
            grazing_error: 0.0,
            time: 0.0,
            log_flux: 0.0,
        }
    }
}

/// A system of map dimension `D`.
pub trait System<const D: usize>: Sized + Send + Sync {
    /// Builds the system from checked parameter values.
    fn new(params: &Params) -> Self;

    /// The time T of one map iteration (exponents are per unit time: ln R_ii / T).
    fn period(&self) -> f64;

    /// One map iteration x_{n+1} = U(x_n).
    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D];

    /// One map iteration of several trajectories (a reference and its
    /// perturbed copies); a flow integrates them in lockstep
    /// ([`crate::integrate::time_map_many`]).
    fn iterate_many(&self, ys: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        for (y, st) in ys.iter_mut().zip(stats.iter_mut()) {
            *y = self.iterate(y, flow, st);
        }
    }

    /// One map iteration of one trajectory of each of several systems (the
    /// references of neighbouring lanes of a sweep, in their transient); a
    /// flow steps them as one batch ([`crate::integrate::time_map_lanes`]).
    fn iterate_lanes(systems: &[Self], xs: &mut [[f64; D]], flow: &FlowSettings) {
        let mut discard = IterationStats::default();
        for (system, x) in systems.iter().zip(xs.iter_mut()) {
            *x = system.iterate(x, flow, &mut discard);
        }
    }

    /// [`iterate_many`](Self::iterate_many) for one part of the iteration,
    /// from the forcing phase `phase` at its start (advanced to its end).
    /// Only flows have parts; a map is always whole.
    fn part_many(
        &self,
        ys: &mut [[f64; D]],
        flow: &FlowSettings,
        part: Part,
        _phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        assert_eq!(part, Part::WHOLE, "a map iteration has no parts");
        self.iterate_many(ys, flow, stats);
    }

    /// One map iteration (or part of one) with its exact Jacobian, where a
    /// closed form exists (`SystemInfo::has_exact`).
    fn iterate_exact(
        &self,
        _x: &[f64; D],
        _part: Part,
        _stats: &mut IterationStats,
    ) -> Option<([f64; D], SMatrix<f64, D, D>)> {
        None
    }

    /// The largest |eigenvalue| of the flow's linearisation, an estimate
    /// over the region the orbit visits (0 for a map). RK4's step h must
    /// keep h·rate small: stable below 2.78, accurate to a relative 1e-6 in
    /// the fastest exponent near 0.1.
    fn stiffness(&self) -> f64 {
        0.0
    }

    /// An estimate of the fastest contraction rate, -λ_min (0 for a map):
    /// sets how many parts an iteration needs (see [`Part`]).
    fn contraction(&self) -> f64 {
        0.0
    }

    /// One iteration's image with its tangent map pushed onto `factors` as
    /// a product of D×D factors (first applied first), where the system
    /// estimates it itself rather than by the method's perturbed copies
    /// per part (a Poincaré map, see `system::section`); `None` otherwise.
    fn tangent_factors(
        &self,
        _x: &[f64; D],
        _flow: &FlowSettings,
        _settings: &crate::method::MethodSettings,
        _stats: &mut IterationStats,
        _factors: &mut Vec<SMatrix<f64, D, D>>,
    ) -> Option<[f64; D]> {
        None
    }

    /// Brings a map point to its canonical form at the end of an iteration:
    /// a model's angles into [-π, π) (see `model::Model::angles`); nothing
    /// for most systems.
    fn wrap(&self, _x: &mut [f64; D]) {}

    /// The map's first point from the scene's initial state: the state
    /// itself, or for a Poincaré map the first crossing of its section from
    /// a point of the flow (NaN where there is none).
    fn start(&self, initial: &[f64], _flow: &FlowSettings) -> [f64; D] {
        std::array::from_fn(|i| initial[i])
    }

    /// The stiffness and contraction ([`stiffness`](Self::stiffness),
    /// [`contraction`](Self::contraction)) the lane's plan uses, given where
    /// it starts (`initial`, the scene's initial state) and the requested
    /// steps: by default the system's own estimates.
    fn time_scales(&self, _initial: &[f64], _flow: &FlowSettings) -> (f64, f64) {
        (self.stiffness(), self.contraction())
    }

    /// Whether a trajectory may start at y: not behind a wall. A perturbed
    /// copy of a reference within δ of the wall would start behind it.
    fn admits(&self, _y: &[f64; D]) -> bool {
        true
    }
}

/// [`System::iterate_lanes`] of a flow: its time-T maps stepped as one batch.
pub fn time_map_lanes<const D: usize, S: System<D> + crate::integrate::Flow<D>>(
    systems: &[S],
    xs: &mut [[f64; D]],
    flow: &FlowSettings,
) {
    let periods: Vec<f64> = systems.iter().map(|s| s.period()).collect();
    let mut discard = vec![IterationStats::default(); systems.len()];
    crate::integrate::time_map_lanes(systems, xs, &periods, flow, &mut discard);
}

/// [`SystemInfo::period`] from the system's own [`System::period`].
pub fn period_of<const D: usize, S: System<D>>(params: &Params) -> f64 {
    S::new(params).period()
}

/// [`SystemInfo::forcing_frequency`] from the flow's own [`crate::integrate::Flow::forcing_frequency`].
pub fn forcing_of<const D: usize, S: System<D> + crate::integrate::Flow<D>>(
    params: &Params,
) -> f64 {
    S::new(params).forcing_frequency()
}

/// Checks that every parameter is a finite number.
pub fn check_finite(params: &Params) -> Result<(), (&'static str, String)> {
    for (p, v) in params.info.parameters.iter().zip(&params.values) {
        if !v.is_finite() {
            return Err((p.name, format!("must be a finite number, got {v}")));
        }
    }
    Ok(())
}
