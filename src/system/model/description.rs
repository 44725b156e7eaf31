//! A compiled model described to the rest of the tool like a built-in
//! system ([`info`]): its parameters, states and events by name, its
//! checks of parameters and states, the sum rule's expected sum, its time
//! scales, and why the GPU cannot run it where it cannot.

use nalgebra::{DMatrix, DVector};

use crate::error::number;
use crate::integrate::Surface;
use crate::model::compiled::{piecewise_linear, walls_at, Code};
use crate::model::language::expr::{Expr, Var};
use crate::system::{ExactPropagator, Parameter, Params, SystemInfo};

/// Model descriptions built in this process ([`info_as`]): each is kept
/// for the process, so this counts what the process holds for its models.
static DESCRIBED: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How many model descriptions this process has built and keeps.
pub fn described() -> usize {
    DESCRIBED.load(std::sync::atomic::Ordering::Relaxed)
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_owned().into_boxed_str())
}

/// The system description of a compiled model, for the scene, the
/// backends and the writers. Built once per scene and kept for the
/// process (the description is static for the built-ins).
pub fn info(code: Code) -> &'static SystemInfo {
    let sweep = code.model.names.parameters.first().cloned();
    info_as(
        code,
        "model.parameters",
        sweep.as_deref().unwrap_or_default(),
        ExactPropagator::PiecewiseLinear,
    )
}

/// [`info`] of a model whose `[model]` table reads as `text` (its
/// canonical form: the same table, the same text), compiled by `compile`
/// the first time this process meets it and kept: a model is compiled,
/// and its description held, once per process, however many scenes run
/// it (a Python loop over runs holds one, not one per run). The
/// environment that decides what the compiler builds (`CC`,
/// `LYAPSWEEP_STEP_LOOPS`, the cache directory) is part of the key. What is
/// held grows with the distinct models a process runs, not with its runs;
/// each is a few kilobytes besides its native code.
pub fn info_of(
    text: &str,
    compile: impl FnOnce() -> crate::error::Result<Code>,
) -> crate::error::Result<&'static SystemInfo> {
    type Kept = std::collections::BTreeMap<String, &'static SystemInfo>;
    static KEPT: std::sync::Mutex<Kept> = std::sync::Mutex::new(Kept::new());
    let environment: Vec<Option<String>> = ["CC", "LYAPSWEEP_STEP_LOOPS", "XDG_CACHE_HOME", "HOME"]
        .iter()
        .map(|name| std::env::var(name).ok())
        .collect();
    let key = format!("{text}\u{0}{environment:?}");
    let kept = |key: &str| {
        KEPT.lock()
            .unwrap_or_else(|e| e.into_inner())
            .get(key)
            .copied()
    };
    if let Some(info) = kept(&key) {
        return Ok(info);
    }
    // Compiled outside the lock: other models compile at the same time.
    let code = compile()?;
    let mut all = KEPT.lock().unwrap_or_else(|e| e.into_inner());
    // Another thread may have kept the same model meanwhile: its is used,
    // and this one dropped.
    Ok(*all.entry(key).or_insert_with(|| info(code)))
}

/// [`info`] for a built-in kind given as a model (`system::MODEL_KINDS`):
/// its parameters are the scene's `[system]` keys, and `default_sweep` is
/// what a sweep naming no parameter sweeps, and `exact` how the exact
/// backend propagates it.
pub fn info_as(
    code: Code,
    table: &'static str,
    default_sweep: &str,
    exact: ExactPropagator,
) -> &'static SystemInfo {
    DESCRIBED.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let code: &'static Code = Box::leak(Box::new(code));
    let model = &code.model;
    let parameters: Vec<Parameter> = model
        .names
        .parameters
        .iter()
        .zip(&model.defaults)
        .map(|(name, &default)| Parameter {
            name: leak(name),
            default,
            doc: "",
        })
        .collect();
    let on_section = code.section.as_ref().map(|s| s.state);
    let state_names: Vec<&'static str> = model
        .names
        .states
        .iter()
        .enumerate()
        .filter(|(i, _)| Some(*i) != on_section)
        .map(|(_, s)| leak(s))
        .collect();
    let mut events: Vec<&'static str> = code
        .walls
        .iter()
        .map(|w| leak(&w.name))
        .chain(code.surfaces.iter().map(|s| leak(&s.name)))
        .collect();
    // A built-in kind keeps the columns its scenes always had: its one
    // wall's crossings are `impacts_per_period`.
    if table == "system" && events.len() <= 1 {
        events.clear();
    }
    // A Poincaré map starts from a point of the flow (all states).
    let initial = if code.section.is_some() { 1.0 } else { 0.0 };
    Box::leak(Box::new(SystemInfo {
        kind: leak(&model.name),
        parameters: Box::leak(parameters.into_boxed_slice()),
        state_names: Box::leak(state_names.into_boxed_slice()),
        default_sweep: leak(default_sweep),
        default_initial_state: Box::leak(vec![initial; code.states()].into_boxed_slice()),
        is_flow: true,
        has_exact: code.is_piecewise_linear,
        exact,
        check,
        check_state,
        expected_sum,
        period: |p| code_of(p).period(&p.values),
        slowest_rate,
        forcing_frequency: |p| code_of(p).frequency(&p.values),
        gpu_refuses,
        wgsl: crate::model::codegen::wgsl::system_file(code),
        wall_reachable: if code.walls.is_empty() && code.surfaces.is_empty() {
            None
        } else {
            Some(may_reach_an_event)
        },
        model: Some(code),
        table,
        events: Box::leak(events.into_boxed_slice()),
    }))
}

pub(super) fn code_of(p: &Params) -> &'static Code {
    p.info.model.expect("a model's parameters")
}

pub(super) fn check(p: &Params) -> std::result::Result<(), (&'static str, String)> {
    let code = code_of(p);
    crate::system::check_finite(p)?;
    for ((param, &value), &(min, max)) in p
        .info
        .parameters
        .iter()
        .zip(&p.values)
        .zip(&code.model.ranges)
    {
        if !(min..=max).contains(&value) {
            let reason = match (min.is_finite(), max.is_finite()) {
                (true, true) => format!(
                    "must lie in [{}, {}], got {}",
                    number(min),
                    number(max),
                    number(value)
                ),
                (true, false) => format!("must be >= {}, got {}", number(min), number(value)),
                _ => format!("must be <= {}, got {}", number(max), number(value)),
            };
            return Err((param.name, reason));
        }
    }
    let t = code.period(&p.values);
    if !(t.is_finite() && t > 0.0) {
        let crate::model::Map::Period(period) = &code.model.map else {
            unreachable!("a Poincaré map has no period expression")
        };
        // A period that is one parameter (the `lorenz` kind's
        // `system.period`) is that parameter's fault.
        let bare = match period {
            Expr::Var(Var::Param(i)) => Some(p.info.parameters[*i].name),
            _ => None,
        };
        return Err(match bare.or_else(|| blamed(p, period)) {
            Some(name) => (
                name,
                format!(
                    "the map's period must be a finite number > 0, got {}",
                    number(t)
                ),
            ),
            None => (
                "model.map.period",
                format!("must be a finite number > 0, got {}", number(t)),
            ),
        });
    }
    if let Some(section) = &code.section {
        let at = section.at.eval(&[], &p.values, 0.0);
        if !at.is_finite() {
            return Err((
                "model.map.section.at",
                format!("must be finite, got {}", number(at)),
            ));
        }
    }
    for limit in code
        .model
        .switches
        .iter()
        .filter_map(|s| s.stick_limit.as_ref())
    {
        if let Some(value) = crate::model::language::table::bad_stick_limit(limit, &p.values) {
            return Err((
                blamed(p, limit).unwrap_or("model.switches.stick_limit"),
                format!(
                    "the stick limit {}, got {}",
                    crate::model::language::table::STICK_LIMIT_RULE,
                    number(value)
                ),
            ));
        }
    }
    for w in &code.walls {
        let e = w.restitution.eval(&[], &p.values, 0.0);
        if !(0.0..=1.0).contains(&e) {
            return Err((
                blamed(p, &w.restitution).unwrap_or(w.reset_key.as_str()),
                format!("the restitution e must lie in [0, 1], got {e}"),
            ));
        }
    }
    Ok(())
}

/// The parameter a bad value of an expression that the scene's author did
/// not write is blamed on: a built-in kind given as a model
/// (`system::MODEL_KINDS`) has no `model.map.period` in its `[system]`
/// table to name, so an expression of one parameter names that parameter.
fn blamed(p: &Params, expr: &Expr) -> Option<&'static str> {
    if p.info.table != "system" {
        return None;
    }
    let mut read = (0..p.values.len()).filter(|&i| expr.uses(Var::Param(i)));
    match (read.next(), read.next()) {
        (Some(i), None) => Some(p.info.parameters[i].name),
        _ => None,
    }
}

/// Whether the motion from `x` can reach one of the model's events at
/// these parameters (`SystemInfo::wall_reachable`): proved unreachable only
/// for a linear field between events
/// ([`PiecewiseLinear::may_reach_an_event`]).
fn may_reach_an_event(p: &Params, x: &[f64]) -> bool {
    piecewise_linear(code_of(p), &p.values)
        .is_none_or(|system| system.may_reach_an_event(&DVector::from_column_slice(x)))
}

fn check_state(p: &Params, x: &[f64]) -> std::result::Result<(), String> {
    let code = code_of(p);
    for s in code.surfaces.iter().filter(|s| s.kind == Surface::Event) {
        let g = s.g.eval(x, &p.values, 0.0);
        if g > 0.0 {
            return Err(format!(
                "it lies beyond the event '{}' (its surface is {} > 0 there)",
                s.name,
                number(g)
            ));
        }
    }
    for w in walls_at(code, &p.values) {
        if w.side * (x[w.coordinate] - w.position) > 0.0 {
            return Err(format!(
                "{} = {} lies behind the stop at {}",
                code.model.names.states[w.coordinate],
                number(x[w.coordinate]),
                number(w.position)
            ));
        }
    }
    Ok(())
}

/// The exponents per unit time sum to div F (constant here) plus, per
/// unit time, 2·ln e of every crossing of a stop (each multiplies volume
/// by e²). Where div F depends on the state, a Poincaré map integrates it
/// along its returns (its average is in the lane's orbit term, 0 here);
/// a period map does not yet (NaN).
fn expected_sum(p: &Params, crossings_per_time: &[f64]) -> f64 {
    let code = code_of(p);
    let mut sum = match (&code.divergence, &code.divergence_along) {
        (Some(divergence), _) => divergence.eval(&[], &p.values, 0.0),
        // Integrated along the orbit: in the lane's orbit term.
        (None, Some(_)) => 0.0,
        (None, None) => return f64::NAN,
    };
    for (w, &rate) in code.walls.iter().zip(crossings_per_time) {
        if rate != 0.0 {
            sum += 2.0 * w.restitution.eval(&[], &p.values, 0.0).ln() * rate;
        }
    }
    sum
}

/// The rate of the slowest of the flow's own modes: the smallest |μ| over
/// the eigenvalues μ of every region's Jacobian at the origin, where the
/// plan reads the fastest too (`ModelFlow::scales_at_origin`). Neutral
/// modes (|μ| below 1e-9 of the largest: a free coordinate, an angle's
/// drift) have no time scale and are left out; 0 when every mode is.
fn slowest_rate(p: &Params) -> f64 {
    let code = code_of(p);
    let n = code.states();
    let origin = vec![0.0; n];
    let slowest = code
        .regions
        .iter()
        .map(|field| {
            let values: Vec<f64> = field
                .jacobian
                .iter()
                .map(|e| e.eval(&origin, &p.values, 0.0))
                .collect();
            let moduli: Vec<f64> = DMatrix::from_row_slice(n, n, &values)
                .complex_eigenvalues()
                .iter()
                .map(|l| l.norm())
                .collect();
            let largest = moduli.iter().copied().fold(0.0, f64::max);
            moduli
                .into_iter()
                .filter(|&m| m > 1e-9 * largest && m.is_finite())
                .fold(f64::INFINITY, f64::min)
        })
        .fold(f64::INFINITY, f64::min);
    if slowest.is_finite() {
        slowest
    } else {
        0.0
    }
}

/// θ in [-π, π): θ - 2π·floor((θ + π)/2π). Twin of the generated
/// `wrap_angles` of `model::codegen::wgsl`, operation for operation.
pub fn wrap_angle(theta: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    theta - TAU * ((theta + PI) / TAU).floor()
}

/// Periods of the pilot that finds a nonlinear model's time scales.
pub(super) const PILOT_PERIODS: usize = 2;
/// Samples of the Jacobian per pilot period.
pub(super) const PILOT_SAMPLES: usize = 32;

/// (max |λ|, max -Re λ, at least 0) of a Jacobian's eigenvalues.
pub(super) fn eigen_scales(j: &DMatrix<f64>) -> (f64, f64) {
    let eigen = j.complex_eigenvalues();
    (
        eigen.iter().map(|l| l.norm()).fold(0.0, f64::max),
        eigen.iter().map(|l| -l.re).fold(0.0, f64::max),
    )
}

/// Why the GPU kernels cannot run this model, the same for every lane
/// (`model::codegen::wgsl::check`); `None` when its generated WGSL runs.
pub(super) fn gpu_refuses(p: &Params) -> Option<String> {
    crate::model::codegen::wgsl::check(code_of(p))
        .err()
        .map(|why| why.to_string())
}
