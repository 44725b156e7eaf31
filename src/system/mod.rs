//! The dynamical systems, one file each, behind one trait.
//!
//! A system is what the method needs to know about a model: how one map
//! iteration x_{n+1} = U(x_n) is computed (a map formula, or a flow integrated
//! over one period with an optional wall), the period T of that iteration,
//! the sum of exponents the divergence theorem predicts, and, when a closed
//! form exists, the exact tangent map. A built-in system is its file here
//! (and, for the GPU backend, its WGSL twin in `shaders/`), one line in
//! [`SYSTEMS`] and one in `method::dispatch` (which instance of the lane
//! code runs it: systems know nothing of the method); a user's system is
//! a model ([`model`], [`section`]), described at run time from a scene's
//! `[model]` table. A built-in kind that a model file matches in results
//! and speed is that file ([`MODEL_KINDS`]): one code path, not two.

pub mod henon;
pub mod model;
pub mod section;

use nalgebra::SMatrix;

use crate::integrate::clock::Phase;

pub use crate::integrate::{FlowSettings, IterationStats, Part};

/// Every coordinate of a map image that does not exist: a Poincaré map's
/// trajectory that never came back to its section within the return bound.
/// Not finite, so the lane fails as on any non-finite point, and
/// [`is_no_return`] tells the two apart for its status.
pub const NO_RETURN: f64 = f64::INFINITY;

/// Whether `x` is the image of no return ([`NO_RETURN`]) rather than a
/// point that blew up.
pub fn is_no_return(x: &[f64]) -> bool {
    !x.is_empty() && x.iter().all(|&v| v == NO_RETURN)
}

/// The systems written here by hand, by their scene `kind`.
pub static SYSTEMS: &[&SystemInfo] = &[&henon::INFO];

/// A scene `kind` that runs a model file of `models/`, its `[system]` keys
/// the model's parameters.
pub struct ModelKind {
    pub kind: &'static str,
    pub text: &'static str,
    /// The parameter a sweep naming none sweeps.
    pub default_sweep: &'static str,
    /// The exact backend's propagator.
    pub exact: ExactPropagator,
}

/// How the exact backend propagates a model.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExactPropagator {
    /// The piecewise-linear propagator read off the model's expressions
    /// (`integrate::piecewise_linear`), where the model is piecewise linear.
    PiecewiseLinear,
    /// The seed oscillator's hand-written closed form
    /// (`integrate::closed_form`), for the `impact-oscillator` kind: the
    /// ground truth the piecewise-linear propagator is tested against, and
    /// fast where a stiffly damped mass bounces on the wall thousands of
    /// times a period (e = 1: 2x2 closed-form cost per bounce rather than
    /// the general scan's; docs/STABILITY.md, "Stiff damping with a
    /// reachable wall").
    SeedClosedForm,
}

/// The built-in kinds given as models: each kind's hand-written Rust and
/// WGSL were retired for its model file once the model matched it in
/// results and speed. The Lorenz flow's model ran 1.11 times the built-in's speed on
/// the CPU and 0.89 times on lavapipe; the seed's impact oscillator's gave
/// the same spectra to the bit over the main job's 4096 η, at 0.79 times
/// the built-in's lane-steps per second on the CPU and 1.00 times on
/// lavapipe. Its closed form (`integrate::closed_form`) stays as the
/// kind's exact backend, the ground truth.
pub static MODEL_KINDS: &[ModelKind] = &[
    ModelKind {
        kind: "impact-oscillator",
        text: include_str!("../../models/impact-oscillator.toml"),
        default_sweep: "eta",
        exact: ExactPropagator::SeedClosedForm,
    },
    ModelKind {
        kind: "lorenz",
        text: include_str!("../../models/lorenz-flow.toml"),
        default_sweep: "rho",
        exact: ExactPropagator::PiecewiseLinear,
    },
];

/// Every scene `kind`, for messages.
pub fn kinds() -> impl Iterator<Item = &'static str> {
    SYSTEMS
        .iter()
        .map(|s| s.kind)
        .chain(MODEL_KINDS.iter().map(|m| m.kind))
}

/// Looks a system up by its scene `kind`.
pub fn by_kind(kind: &str) -> Option<&'static SystemInfo> {
    if let Some(info) = SYSTEMS.iter().copied().find(|s| s.kind == kind) {
        return Some(info);
    }
    let index = MODEL_KINDS.iter().position(|m| m.kind == kind)?;
    // Compiled once per process, on first use.
    static COMPILED: std::sync::OnceLock<Vec<&'static SystemInfo>> = std::sync::OnceLock::new();
    let compiled = COMPILED.get_or_init(|| MODEL_KINDS.iter().map(model_kind).collect());
    Some(compiled[index])
}

fn model_kind(m: &ModelKind) -> &'static SystemInfo {
    let table: toml::Value = m.text.parse::<toml::Table>().map_or_else(
        |e| panic!("the {} kind's model file: {e}", m.kind),
        |mut t| t.remove("model").expect("a [model] table"),
    );
    let compiled = crate::model::Model::parse(&table, "model")
        .and_then(|model| crate::model::code::Code::compile(model, "model"));
    match compiled {
        Ok(code) => model::info_as(code, "system", m.default_sweep, m.exact),
        Err(e) => panic!("the {} kind's model file: {e}", m.kind),
    }
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
    /// A model's exact propagator (`PiecewiseLinear` for the others).
    pub exact: ExactPropagator,
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
    /// Why the GPU kernels cannot run a lane with these parameters, if
    /// they cannot (what the CPU path models and the kernels do not yet).
    pub gpu_refuses: fn(&Params) -> Option<String>,
    /// The system's WGSL twin (`shaders/system/<kind>.wgsl`): its `Params`
    /// struct (fields in the order of `parameters`) and `rhs` for a flow
    /// (with its stops as `shaders/shared/impact.wgsl` reads them, `WALLS`
    /// and per stop its coordinate, velocity, side, position and
    /// restitution, when it has any) or `map_step` for a map. `None`: no
    /// GPU backend for this system.
    pub wgsl: Option<crate::model::wgsl::SystemFile>,
    /// Whether the trajectory from this start can reach the system's wall at
    /// these parameters (a conservative bound: `true` when unsure); `None`
    /// for a system without a wall. A sweep that cannot reach it runs GPU
    /// kernels compiled without impact code.
    pub wall_reachable: Option<fn(&Params, &[f64]) -> bool>,
    /// The compiled model of a system given as data (`None` for a built-in).
    pub model: Option<&'static crate::model::code::Code>,
    /// The scene table its parameters are keys of ("system", or
    /// "model.parameters"), for messages.
    pub table: &'static str,
    /// The names of its walls (a model's events), one output column each;
    /// empty for the built-in kinds, whose one wall is `impacts_per_period`.
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

    /// One map iteration of trajectory k of `systems[k]`, for every k (the
    /// references of neighbouring lanes of a sweep in their transient, or
    /// their references and copies while they average); a flow steps them
    /// as batches across lanes ([`crate::integrate::time_map_lanes`]).
    fn iterate_lanes(
        systems: &[&Self],
        xs: &mut [[f64; D]],
        flow: &FlowSettings,
        stats: &mut [IterationStats],
    ) {
        for ((system, x), st) in systems.iter().zip(xs.iter_mut()).zip(stats) {
            *x = system.iterate(x, flow, st);
        }
    }

    /// Whether neighbouring lanes may average in lockstep, their references
    /// and copies stepped together by [`iterate_lanes`](Self::iterate_lanes)
    /// (`method::lane::run_lanes`): where that gives every trajectory the
    /// bits and statistics [`part_many`](Self::part_many) gives it over the
    /// whole iteration, and runs faster. A time map of a flow whose
    /// divergence is not integrated along the reference does.
    fn averages_across_lanes(&self) -> bool {
        false
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
        _delta: f64,
        _difference: crate::perturbation::Difference,
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
    systems: &[&S],
    xs: &mut [[f64; D]],
    flow: &FlowSettings,
    stats: &mut [IterationStats],
) {
    let periods: Vec<f64> = systems.iter().map(|s| s.period()).collect();
    crate::integrate::time_map_lanes(systems, xs, &periods, flow, stats);
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
