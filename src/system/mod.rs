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
//!
//! The trait is [`map`]'s and the type-erased description [`info`]'s; this
//! file is the registry of kinds that looks a system up.

pub mod henon;
pub mod model;
pub mod section;

pub mod info;
pub mod map;

// The trait and the description live in children below the systems that
// give them (a child importing this file's items would import its own
// importer); the paths here stay the ones the tool names.
pub use crate::integrate::{FlowSettings, IterationStats, Part};
pub use info::{check_finite, ExactPropagator, Parameter, Params, SystemInfo};
pub use map::{forcing_of, is_no_return, period_of, time_map_lanes, System, NO_RETURN};

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
        .and_then(|model| crate::model::compiled::Code::compile(model, "model"));
    match compiled {
        Ok(code) => model::info_as(code, "system", m.default_sweep, m.exact),
        Err(e) => panic!("the {} kind's model file: {e}", m.kind),
    }
}
