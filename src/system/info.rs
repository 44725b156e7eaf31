//! A system described without its dimension: its parameters and their
//! values ([`Params`]), and everything the scene parser, the output
//! writers and the backends read of it ([`SystemInfo`]). Below the
//! systems themselves, which each give one.

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
    /// The rate of the flow's slowest mode, 1 over its longest time scale
    /// (see `system::model`), against which a lane's averaging time is
    /// judged; 0 where the system has none (a map).
    pub slowest_rate: fn(&Params) -> f64,
    /// ω of the forcing (cos ωt enters the right-hand side); 0 if autonomous.
    pub forcing_frequency: fn(&Params) -> f64,
    /// Why the GPU kernels cannot run a lane with these parameters, if
    /// they cannot (what the CPU path models and the kernels do not yet).
    pub gpu_refuses: fn(&Params) -> Option<String>,
    /// The system's WGSL twin (`shaders/system/<kind>.wgsl`): its `Params`
    /// struct (fields in the order of `parameters`) and `rhs` for a flow
    /// (with its stops as `shaders/shared/stops.wgsl` reads them, `WALLS`
    /// and per stop its coordinate, velocity, side, position and
    /// restitution, when it has any) or `map_step` for a map. `None`: no
    /// GPU backend for this system.
    pub wgsl: Option<crate::model::codegen::wgsl::SystemFile>,
    /// Whether the trajectory from this start can reach the system's wall at
    /// these parameters (a conservative bound: `true` when unsure); `None`
    /// for a system without a wall. A sweep that cannot reach it runs GPU
    /// kernels compiled without impact code.
    pub wall_reachable: Option<fn(&Params, &[f64]) -> bool>,
    /// The compiled model of a system given as data (`None` for a built-in).
    pub model: Option<&'static crate::model::compiled::Code>,
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

/// Checks that every parameter is a finite number.
pub fn check_finite(params: &Params) -> Result<(), (&'static str, String)> {
    for (p, v) in params.info.parameters.iter().zip(&params.values) {
        if !v.is_finite() {
            return Err((
                p.name,
                format!("must be a finite number, got {}", crate::error::number(*v)),
            ));
        }
    }
    Ok(())
}
