//! A system given as data: a scene's `[model]` table (see `crate::model`),
//! compiled once per run into the tapes the CPU integrator evaluates (one
//! field per region of its switches), with its events and switches as the
//! integrator's surfaces, and described to the rest of the tool like a
//! built-in system.
//!
//! An event that is a stop (a surface `x - c` or `c - x` on one state x, c
//! of parameters alone, whose equation is another state v, x' = v, with a
//! reset of v alone that is linear in v, `v = "-e*v"`) runs as a wall: the
//! vectorised detection and the sticking of `integrate::impact`; each
//! impact multiplies phase-space volume by e², which the sum rule adds.
//! Any other event, and every switch, is a general surface
//! (`integrate::surface`), whose ln|det S| the integrator records crossing
//! by crossing. A model that is piecewise linear also gets the exact
//! backend ([`piecewise_linear`]).

use nalgebra::{DMatrix, DVector, SMatrix};

use super::{FlowSettings, IterationStats, Parameter, Params, Part, System, SystemInfo};
use crate::error::{Error, Result};
use crate::integrate::clock::Phase;
use crate::integrate::impact::MAX_WALLS;
use crate::integrate::piecewise_linear::{
    LinearField, LinearSurface, PiecewiseLinear, PiecewiseStatus,
};
use crate::integrate::surface::MAX_SURFACES;
use crate::integrate::{
    part_map_many, rk4, time_map, time_map_many, Flow, Surface, SurfaceValues, Wall,
};
use crate::model::expr::{Expr, Var, Written};
use crate::model::jit::{Kind, Layout, Native};
use crate::model::tape::{Registers, Tape};
use crate::model::{Map, Model};

/// The largest model dimension the CPU path is compiled for.
pub const MAX_STATES: usize = 6;

/// A model compiled for the integrator, built once per scene.
#[derive(Debug)]
pub struct Code {
    pub model: Model,
    /// The equations (of region 0, where there are switches), one output
    /// per state: the forcing clock and `model check`'s figures.
    pub equations: Tape,
    pub walls: Vec<Stop>,
    /// div F = Σ ∂F_i/∂x_i when it is a function of the parameters alone
    /// (then the flow contracts volume at a constant rate); `None` when it
    /// depends on the state.
    pub divergence: Option<Expr>,
    /// div F compiled, where it depends on the state and the map is a
    /// Poincaré section: integrated along the reference's returns (see
    /// `system::section`), its time average enters the sum rule.
    pub divergence_along: Option<Tape>,
    /// ∂F_i/∂x_j, row-major: the time scales of the flow (see
    /// [`ModelFlow::stiffness`]).
    pub jacobian: Vec<Expr>,
    /// The Poincaré section of a section map (see `system::section`).
    pub section: Option<SectionSpec>,
    /// Events that are not stops, then the switches: the integrator's
    /// general surfaces (`integrate::surface`), counted after the walls.
    pub surfaces: Vec<GeneralSurface>,
    /// Their kinds, in the same order (what `Flow::surfaces` gives).
    pub kinds: Vec<Surface>,
    /// The field of every region of the switches (one without switches),
    /// indexed by the region's bits.
    pub regions: Vec<Field>,
    /// ω of the model's forcing clock: the equations' `cos(w*t)`, or else
    /// a moving surface's (a wall vibrating at w).
    pub clock: Option<Expr>,
    /// Whether the model is piecewise linear (every region's field linear
    /// with constant coefficients plus harmonic forcing, its surfaces and
    /// resets linear): then it has an exact backend
    /// ([`piecewise_linear`]).
    pub is_piecewise_linear: bool,
}

/// An event that is not a stop, or a switch of the field.
#[derive(Debug)]
pub struct GeneralSurface {
    pub name: String,
    pub kind: Surface,
    /// g(y), parameters and states.
    pub g: Expr,
    /// ∇g, one derivative per state.
    pub gradient: Vec<Expr>,
    /// An event's reset: every state's value after it (the states it does
    /// not name keep theirs), and its Jacobian DR, row-major. Empty for a
    /// switch.
    pub reset: Vec<Expr>,
    pub reset_jacobian: Vec<Expr>,
    /// ∂R/∂t of an event's reset, one per state (zeros unless it reads `t`).
    pub reset_rate: Vec<Expr>,
    /// A switch's stick limit (see `integrate::surface`), if it has one.
    pub stick_limit: Option<Expr>,
}

/// One region's field, compiled.
#[derive(Debug)]
pub struct Field {
    pub equations: Tape,
    /// The equations as native code, where the host allows (else the
    /// tape's interpreter runs them).
    pub native: Option<Native>,
    /// g of every general surface, padded to `MAX_SURFACES`, then their
    /// rates ∇g·F along this field, padded the same.
    pub surfaces: Tape,
    /// ∂F_i/∂x_j of this field, row-major.
    pub jacobian: Vec<Expr>,
}

/// A section y_state = at (parameters alone), crossed increasing or not.
#[derive(Debug)]
pub struct SectionSpec {
    pub state: usize,
    pub at: Expr,
    pub increasing: bool,
}

/// An event that is a stop: a rigid wall on one state, from one side.
#[derive(Debug)]
pub struct Stop {
    pub name: String,
    pub coordinate: usize,
    pub velocity: usize,
    pub side: f64,
    /// Where the wall is (parameters alone).
    pub position: Expr,
    /// e in v → -e·v (parameters alone).
    pub restitution: Expr,
    /// The key of the reset, for messages about e.
    pub reset_key: String,
}

fn reads_state_or_time(e: &Expr) -> bool {
    match e {
        Expr::Num(_) => false,
        Expr::Var(v) => !matches!(v, Var::Param(_)),
        Expr::Neg(a) => reads_state_or_time(a),
        Expr::Bin(_, a, b) => reads_state_or_time(a) || reads_state_or_time(b),
        Expr::Call(_, args) => args.iter().any(reads_state_or_time),
    }
}

/// The states an expression reads.
fn states_read(e: &Expr, n: usize) -> Vec<usize> {
    (0..n).filter(|&i| e.uses(Var::State(i))).collect()
}

impl Code {
    /// Compiles a parsed model; errors name the model's key (`key` is
    /// "model").
    pub fn compile(model: Model, key: &str) -> Result<Code> {
        let n = model.names.states.len();
        let states = &model.names.states;
        if n > MAX_STATES {
            return Err(Error::invalid(
                format!("{key}.states"),
                format!("{n} states: at most {MAX_STATES} are supported"),
            ));
        }
        let region_zero: Vec<Expr> = model.equations.iter().map(|e| e.in_region(0)).collect();
        let equations = Tape::compile(&region_zero, n, None).map_err(|(i, why)| {
            Error::invalid(format!("{key}.equations.{}", states[i]), why.to_string())
        })?;
        let section = match &model.map {
            Map::Period(_) => None,
            Map::Section {
                state,
                at,
                increasing,
            } => {
                if equations.frequency.is_some() {
                    return Err(Error::invalid(
                        format!("{key}.map.section"),
                        "a Poincaré section needs an autonomous flow, and the equations read \
                         the time (cos(w*t) or sin(w*t)): give period = \"...\" instead",
                    ));
                }
                if !model.events.is_empty() || !model.switches.is_empty() {
                    return Err(Error::invalid(
                        format!(
                            "{key}.{}",
                            if model.events.is_empty() {
                                "switches"
                            } else {
                                "events"
                            }
                        ),
                        "events and switches in a model with a Poincaré section are not \
                         supported yet",
                    ));
                }
                Some(SectionSpec {
                    state: *state,
                    at: at.clone(),
                    increasing: *increasing,
                })
            }
        };
        let mut walls = Vec::new();
        let mut surfaces = Vec::new();
        for (j, event) in model.events.iter().enumerate() {
            let column = crate::output::event_column(&event.name);
            if model.events[..j]
                .iter()
                .any(|e| crate::output::event_column(&e.name) == column)
            {
                return Err(Error::invalid(
                    format!("{key}.events[{j}].name"),
                    format!(
                        "'{}' names the column {column} of an earlier event: give each event its own name",
                        event.name
                    ),
                ));
            }
            let event_key = format!("{key}.events[{j}]");
            match stop(&model, event, &event_key) {
                Some(stop) => walls.push(stop),
                None => surfaces.push(general_event(
                    &model,
                    event,
                    &event_key,
                    equations.frequency.clone(),
                )?),
            }
        }
        if walls.len() > MAX_WALLS {
            return Err(Error::invalid(
                format!("{key}.events"),
                format!("{} stops: at most {MAX_WALLS} are supported", walls.len()),
            ));
        }
        for (b, switch) in model.switches.iter().enumerate() {
            surfaces.push(GeneralSurface {
                name: switch.name.clone(),
                kind: Surface::Switch { bit: b as u32 },
                g: switch.surface.clone(),
                gradient: (0..n)
                    .map(|i| switch.surface.derivative(Var::State(i)))
                    .collect(),
                reset: Vec::new(),
                reset_jacobian: Vec::new(),
                reset_rate: Vec::new(),
                stick_limit: switch.stick_limit.clone(),
            });
        }
        if surfaces.len() > MAX_SURFACES {
            return Err(Error::invalid(
                format!("{key}.events"),
                format!(
                    "{} events that are not stops and switches together: at most \
                     {MAX_SURFACES} are supported",
                    surfaces.len()
                ),
            ));
        }
        for (j, s) in surfaces.iter().enumerate() {
            let column = crate::output::event_column(&s.name);
            let earlier = walls
                .iter()
                .map(|w| &w.name)
                .chain(surfaces[..j].iter().map(|s| &s.name));
            if let Some(other) = earlier
                .into_iter()
                .find(|o| crate::output::event_column(o) == column)
            {
                return Err(Error::invalid(
                    format!("{key}.switches"),
                    format!(
                        "'{}' and '{other}' name the same column {column}: give each its own name",
                        s.name
                    ),
                ));
            }
        }
        let kinds: Vec<Surface> = surfaces.iter().map(|s| s.kind).collect();
        let regions = (0..1u32 << model.switches.len())
            .map(|r| field(&model, &surfaces, r, equations.frequency.clone(), key))
            .collect::<Result<Vec<_>>>()?;
        let whole_divergence = (0..n)
            .map(|i| model.equations[i].derivative(Var::State(i)))
            .reduce(|a, b| Expr::Bin(crate::model::expr::Op::Add, Box::new(a), Box::new(b)))
            .expect("a model has a state");
        // A divergence that reads the switches' sides is the same
        // everywhere only when every region's is the same.
        let whole_divergence = if whole_divergence.reads_sides() {
            let first = whole_divergence.in_region(0);
            if regions
                .iter()
                .enumerate()
                .all(|(r, _)| whole_divergence.in_region(r as u32) == first)
            {
                Some(first)
            } else {
                None
            }
        } else {
            Some(whole_divergence)
        };
        let (divergence, divergence_along) = match whole_divergence {
            None => (None, None),
            Some(whole_divergence) => {
                if !reads_state_or_time(&whole_divergence) {
                    (Some(whole_divergence), None)
                } else if section.is_some() || walls.is_empty() {
                    let clock = equations.frequency.clone();
                    let tape =
                        Tape::compile([&whole_divergence], n, clock).map_err(|(_, why)| {
                            Error::invalid(
                                format!("{key}.equations"),
                                format!(
                                    "their divergence {}: {why}",
                                    Written {
                                        expr: &whole_divergence,
                                        names: &model.names
                                    }
                                ),
                            )
                        })?;
                    (None, Some(tape))
                } else {
                    (None, None)
                }
            }
        };
        let jacobian = (0..n * n)
            .map(|ij| model.equations[ij / n].derivative(Var::State(ij % n)))
            .collect();
        let is_piecewise_linear = section_free_linear(&model, &regions, &surfaces);
        let clock = equations
            .frequency
            .clone()
            .or_else(|| regions.iter().find_map(|f| f.surfaces.frequency.clone()));
        Ok(Code {
            clock,
            is_piecewise_linear,
            model,
            equations,
            walls,
            divergence,
            divergence_along,
            jacobian,
            section,
            surfaces,
            kinds,
            regions,
        })
    }

    /// The compiled divergence of a period map without walls whose
    /// divergence depends on the state (see `ModelFlow::part_many`).
    fn equations_divergence(&self) -> Option<&Tape> {
        match (&self.section, self.walls.is_empty()) {
            (None, true) => self.divergence_along.as_ref(),
            _ => None,
        }
    }

    /// ω of the forcing clock at `params` (0 without one).
    pub fn frequency(&self, params: &[f64]) -> f64 {
        self.clock
            .as_ref()
            .map_or(0.0, |w| w.eval(&[], params, 0.0))
    }

    /// The flow's states.
    pub fn states(&self) -> usize {
        self.model.names.states.len()
    }

    /// The map's dimension (its exponents): the states, or one fewer on a
    /// Poincaré section.
    pub fn dimension(&self) -> usize {
        self.states() - usize::from(self.section.is_some())
    }

    /// The map period at `params`; for a Poincaré map the unit of time
    /// over which `steps_per_period` counts steps (its iterations take
    /// their own return times).
    pub fn period(&self, params: &[f64]) -> f64 {
        self.model.period(params).unwrap_or(1.0)
    }
}

/// The event as a stop, if it is one: a surface `x - c` or `c - x` on one
/// state x (c of parameters alone) whose equation is another state v
/// (x' = v), with a reset of v alone that is linear in v (`v = "-e*v"`).
/// Stops run through the walls' code (vectorised detection, sticking);
/// any other event is a general surface.
fn stop(model: &Model, event: &crate::model::Event, key: &str) -> Option<Stop> {
    let n = model.names.states.len();
    let states = &model.names.states;
    let read = states_read(&event.surface, n);
    if event.surface.uses(Var::Time) || read.len() != 1 {
        return None;
    }
    let coordinate = read[0];
    let side = match event.surface.derivative(Var::State(coordinate)) {
        Expr::Num(s) if s == 1.0 || s == -1.0 => s,
        _ => return None,
    };
    let velocity = match &model.equations[coordinate] {
        Expr::Var(Var::State(v)) if *v != coordinate => *v,
        _ => return None,
    };
    // g = side·(x - c) = side·x + r, so c = -side·r with r = g at x = 0.
    let position = Expr::Neg(Box::new(Expr::Bin(
        crate::model::expr::Op::Mul,
        Box::new(Expr::Num(side)),
        Box::new(at_zero(&event.surface, coordinate)),
    )));
    let [(state, reset)] = event.reset.as_slice() else {
        return None;
    };
    if *state != velocity
        || reset.uses(Var::Time)
        || states_read(reset, n).iter().any(|&i| i != velocity)
    {
        return None;
    }
    let slope = reset.derivative(Var::State(velocity));
    // Linear in v: a constant slope, and 0 at v = 0 (checked at the
    // defaults and at other parameter values, so a term of parameters
    // that vanishes at the defaults alone does not pass).
    let at_rest = replace_state(reset, velocity);
    let elsewhere: Vec<f64> = model.defaults.iter().map(|p| 1.37 * p + 0.11).collect();
    if reads_state_or_time(&slope)
        || at_rest.eval(&[], &model.defaults, 0.0) != 0.0
        || at_rest.eval(&[], &elsewhere, 0.0) != 0.0
    {
        return None;
    }
    Some(Stop {
        name: event.name.clone(),
        coordinate,
        velocity,
        side,
        position,
        restitution: Expr::Neg(Box::new(slope)),
        reset_key: format!("{key}.reset.{}", states[velocity]),
    })
}

/// Whether a period map's fields, surfaces and resets are all linear
/// with constant coefficients (the forcing's harmonic form is checked per
/// lane, [`piecewise_linear`]).
fn section_free_linear(model: &Model, regions: &[Field], surfaces: &[GeneralSurface]) -> bool {
    let constant = |e: &Expr| !reads_state_or_time(e);
    matches!(model.map, Map::Period(_))
        && model.angles.is_empty()
        && regions.iter().all(|f| f.jacobian.iter().all(constant))
        && surfaces.iter().all(|s| {
            s.gradient.iter().all(constant)
                && s.reset_jacobian.iter().all(constant)
                && !s.g.uses(Var::Time)
                && !s.reset.iter().any(|r| r.uses(Var::Time))
        })
}

/// The model at one lane's parameters as a piecewise-linear system: each
/// region's y' = A·y + c + p·cos ωt + q·sin ωt read off its expressions (A
/// from the derivatives, c, p, q from F(0, t) at ωt = 0, π/2, π), then
/// checked at sample points, so a forcing that is not harmonic (cos²) or a
/// clock in a coefficient is refused (`None`). The walls come first, as
/// events, then the general surfaces: the crossings' order of the CPU path.
pub fn piecewise_linear(code: &Code, params: &[f64]) -> Option<PiecewiseLinear> {
    if !code.is_piecewise_linear {
        return None;
    }
    let n = code.states();
    let omega = code.frequency(params);
    let period = code.period(params);
    let zero = vec![0.0; n];
    let mut fields = Vec::new();
    for region in 0..code.regions.len() as u32 {
        let equations: Vec<Expr> = code
            .model
            .equations
            .iter()
            .map(|e| e.in_region(region))
            .collect();
        let f = |y: &[f64], t: f64| -> DVector<f64> {
            DVector::from_iterator(n, equations.iter().map(|e| e.eval(y, params, t)))
        };
        let a = DMatrix::from_fn(n, n, |i, k| {
            code.regions[region as usize].jacobian[i * n + k].eval(&zero, params, 0.0)
        });
        // c, p and q read with the clock set to (cos, sin) = (0, 0), (1, 0)
        // and (0, 1): exact zeros where the field has no such term, so
        // that the jump across a switch is the same constant where it is.
        let at_clock = |cos: f64, sin: f64| -> DVector<f64> {
            DVector::from_iterator(
                n,
                equations
                    .iter()
                    .map(|e| with_clock(e, cos, sin).eval(&zero, params, 0.0)),
            )
        };
        let constant = at_clock(0.0, 0.0);
        let cos = at_clock(1.0, 0.0) - &constant;
        let sin = at_clock(0.0, 1.0) - &constant;
        let field = LinearField::new(a, constant, cos, sin);
        // The form must reproduce the field elsewhere.
        for k in 1..4 {
            let y: Vec<f64> = (0..n).map(|i| 0.37 * (k * (i + 1)) as f64 - 0.5).collect();
            let t = period * (0.13 * k as f64);
            let expected = f(&y, t);
            let form = field.eval(omega, t, &DVector::from_column_slice(&y));
            let scale = expected.amax().max(1.0);
            if (expected - form).amax() > 1e-9 * scale {
                return None;
            }
        }
        fields.push(field);
    }
    let mut surfaces = Vec::new();
    for w in walls_at(code, params) {
        let mut normal = DVector::zeros(n);
        normal[w.coordinate] = w.side;
        let mut reset = DMatrix::identity(n, n);
        reset[(w.velocity, w.velocity)] = -w.restitution;
        surfaces.push(LinearSurface::event(
            normal,
            w.side * w.position,
            reset,
            DVector::zeros(n),
        ));
    }
    for s in &code.surfaces {
        let normal =
            DVector::from_iterator(n, s.gradient.iter().map(|e| e.eval(&zero, params, 0.0)));
        let offset = -s.g.eval(&zero, params, 0.0);
        surfaces.push(match s.kind {
            // A constant stick limit (or Filippov's) slides in closed form;
            // one that reads the state is left to the RK4 path (`sliding`).
            Surface::Switch { .. } => match &s.stick_limit {
                Some(limit) if reads_state_or_time(limit) => LinearSurface::switch(normal, offset),
                limit => LinearSurface::sliding_switch(
                    normal,
                    offset,
                    limit.as_ref().map(|l| l.eval(&zero, params, 0.0)),
                ),
            },
            Surface::Event => LinearSurface::event(
                normal,
                offset,
                DMatrix::from_fn(n, n, |i, k| {
                    s.reset_jacobian[i * n + k].eval(&zero, params, 0.0)
                }),
                DVector::from_iterator(n, s.reset.iter().map(|e| e.eval(&zero, params, 0.0))),
            ),
        });
    }
    PiecewiseLinear::new(omega, fields, surfaces).ok()
}

/// `e` with the clock's cos(w t) and sin(w t) replaced by the numbers
/// `cos` and `sin` (see [`piecewise_linear`]).
fn with_clock(e: &Expr, cos: f64, sin: f64) -> Expr {
    use crate::model::expr::Func;
    match e {
        Expr::Call(Func::Cos, args) if args[0].uses(Var::Time) => Expr::Num(cos),
        Expr::Call(Func::Sin, args) if args[0].uses(Var::Time) => Expr::Num(sin),
        Expr::Num(_) | Expr::Var(_) => e.clone(),
        Expr::Neg(a) => Expr::Neg(Box::new(with_clock(a, cos, sin))),
        Expr::Bin(op, a, b) => Expr::Bin(
            *op,
            Box::new(with_clock(a, cos, sin)),
            Box::new(with_clock(b, cos, sin)),
        ),
        Expr::Call(f, args) => {
            Expr::Call(*f, args.iter().map(|a| with_clock(a, cos, sin)).collect())
        }
    }
}

/// An event that is not a stop, as a general surface: any g(y) and any
/// reset of the states (time not yet).
fn general_event(
    model: &Model,
    event: &crate::model::Event,
    key: &str,
    clock: Option<Expr>,
) -> Result<GeneralSurface> {
    let n = model.names.states.len();
    // Time may enter as the forcing clock alone, with the equations' ω (a
    // wall vibrating with the forcing), so that it restarts each period.
    let surface_key = format!("{key}.surface");
    Tape::compile([&event.surface], n, clock.clone())
        .map_err(|(_, why)| Error::invalid(&surface_key, why.to_string()))?;
    for (state, value) in &event.reset {
        Tape::compile([value], n, clock.clone()).map_err(|(_, why)| {
            Error::invalid(
                format!("{key}.reset.{}", model.names.states[*state]),
                why.to_string(),
            )
        })?;
    }
    let mut reset: Vec<Expr> = (0..n).map(|i| Expr::Var(Var::State(i))).collect();
    for (state, value) in &event.reset {
        reset[*state] = value.clone();
    }
    if event.reset.is_empty() {
        return Err(Error::invalid(
            format!("{key}.reset"),
            "an event needs a reset (a surface without one is a switch: [[model.switches]])",
        ));
    }
    let reset_jacobian = (0..n * n)
        .map(|ik| reset[ik / n].derivative(Var::State(ik % n)))
        .collect();
    let reset_rate = reset.iter().map(|r| r.derivative(Var::Time)).collect();
    Ok(GeneralSurface {
        name: event.name.clone(),
        kind: Surface::Event,
        g: event.surface.clone(),
        gradient: (0..n)
            .map(|i| event.surface.derivative(Var::State(i)))
            .collect(),
        reset,
        reset_jacobian,
        reset_rate,
        stick_limit: None,
    })
}

/// The field of region `region` of the switches, compiled, with its
/// surfaces' values and rates.
fn field(
    model: &Model,
    surfaces: &[GeneralSurface],
    region: u32,
    frequency: Option<Expr>,
    key: &str,
) -> Result<Field> {
    let n = model.names.states.len();
    let states = &model.names.states;
    let equations: Vec<Expr> = model
        .equations
        .iter()
        .map(|e| e.in_region(region))
        .collect();
    let tape = Tape::compile(&equations, n, frequency.clone()).map_err(|(i, why)| {
        Error::invalid(format!("{key}.equations.{}", states[i]), why.to_string())
    })?;
    let zero = Expr::Num(0.0);
    let pad = |v: Vec<Expr>| -> Vec<Expr> {
        let mut v = v;
        v.resize(MAX_SURFACES, zero.clone());
        v
    };
    let values = pad(surfaces.iter().map(|s| s.g.clone()).collect());
    let rates = pad(surfaces
        .iter()
        .map(|s| {
            (0..n)
                .map(|i| {
                    Expr::Bin(
                        crate::model::expr::Op::Mul,
                        Box::new(s.gradient[i].clone()),
                        Box::new(equations[i].clone()),
                    )
                })
                // ∂g/∂t: a surface that moves with the forcing.
                .chain([s.g.derivative(Var::Time)])
                .reduce(|a, b| Expr::Bin(crate::model::expr::Op::Add, Box::new(a), Box::new(b)))
                .expect("a model has a state")
        })
        .collect());
    let surface_tape =
        Tape::compile(values.iter().chain(&rates), n, frequency).map_err(|(i, why)| {
            let s = &surfaces[i % MAX_SURFACES];
            Error::invalid(
                format!("{key}: the surface of '{}'", s.name),
                why.to_string(),
            )
        })?;
    let jacobian = (0..n * n)
        .map(|ij| equations[ij / n].derivative(Var::State(ij % n)))
        .collect();
    Ok(Field {
        native: Native::compile(&tape),
        equations: tape,
        surfaces: surface_tape,
        jacobian,
    })
}

/// `e` with state i replaced by 0, folded where the result is a number.
fn at_zero(e: &Expr, i: usize) -> Expr {
    let replaced = replace_state(e, i);
    if reads_state_or_time(&replaced) {
        return replaced;
    }
    // An expression of numbers alone folds to its value.
    if is_number(&replaced) {
        return Expr::Num(replaced.eval(&[], &[], 0.0));
    }
    replaced
}

fn is_number(e: &Expr) -> bool {
    match e {
        Expr::Num(_) => true,
        Expr::Var(_) => false,
        Expr::Neg(a) => is_number(a),
        Expr::Bin(_, a, b) => is_number(a) && is_number(b),
        Expr::Call(_, args) => args.iter().all(is_number),
    }
}

fn replace_state(e: &Expr, i: usize) -> Expr {
    match e {
        Expr::Var(Var::State(k)) if *k == i => Expr::Num(0.0),
        Expr::Num(_) | Expr::Var(_) => e.clone(),
        Expr::Neg(a) => Expr::Neg(Box::new(replace_state(a, i))),
        Expr::Bin(op, a, b) => Expr::Bin(
            *op,
            Box::new(replace_state(a, i)),
            Box::new(replace_state(b, i)),
        ),
        Expr::Call(f, args) => Expr::Call(*f, args.iter().map(|a| replace_state(a, i)).collect()),
    }
}

fn leak(s: &str) -> &'static str {
    Box::leak(s.to_owned().into_boxed_str())
}

/// The system description of a compiled model, for the scene, the
/// backends and the writers. Built once per scene and kept for the
/// process (the description is static for the built-ins).
pub fn info(code: Code) -> &'static SystemInfo {
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
    let events: Vec<&'static str> = code
        .walls
        .iter()
        .map(|w| leak(&w.name))
        .chain(code.surfaces.iter().map(|s| leak(&s.name)))
        .collect();
    // A Poincaré map starts from a point of the flow (all states).
    let initial = if code.section.is_some() { 1.0 } else { 0.0 };
    Box::leak(Box::new(SystemInfo {
        kind: leak(&model.name),
        parameters: Box::leak(parameters.into_boxed_slice()),
        state_names: Box::leak(state_names.into_boxed_slice()),
        default_sweep: leak(&model.names.parameters.first().cloned().unwrap_or_default()),
        default_initial_state: Box::leak(vec![initial; code.states()].into_boxed_slice()),
        is_flow: true,
        has_exact: code.is_piecewise_linear,
        check,
        check_state,
        expected_sum,
        period: |p| code_of(p).period(&p.values),
        forcing_frequency: |p| code_of(p).frequency(&p.values),
        gpu_refuses,
        wgsl: crate::model::wgsl::system_file(code),
        wall_reachable: if code.walls.is_empty() && code.surfaces.is_empty() {
            None
        } else {
            Some(|_, _| true)
        },
        model: Some(code),
        table: "model.parameters",
        events: Box::leak(events.into_boxed_slice()),
    }))
}

fn code_of(p: &Params) -> &'static Code {
    p.info.model.expect("a model's parameters")
}

fn check(p: &Params) -> std::result::Result<(), (&'static str, String)> {
    let code = code_of(p);
    super::check_finite(p)?;
    let t = code.period(&p.values);
    if !(t.is_finite() && t > 0.0) {
        return Err((
            "model.map.period",
            format!("must be a finite number > 0, got {t}"),
        ));
    }
    if let Some(section) = &code.section {
        let at = section.at.eval(&[], &p.values, 0.0);
        if !at.is_finite() {
            return Err(("model.map.section.at", format!("must be finite, got {at}")));
        }
    }
    for w in &code.walls {
        let e = w.restitution.eval(&[], &p.values, 0.0);
        if !(0.0..=1.0).contains(&e) {
            return Err((
                w.reset_key.as_str(),
                format!("the restitution e must lie in [0, 1], got {e}"),
            ));
        }
    }
    Ok(())
}

fn check_state(p: &Params, x: &[f64]) -> std::result::Result<(), String> {
    let code = code_of(p);
    for s in code.surfaces.iter().filter(|s| s.kind == Surface::Event) {
        let g = s.g.eval(x, &p.values, 0.0);
        if g > 0.0 {
            return Err(format!(
                "it lies beyond the event '{}' (its surface is {g} > 0 there)",
                s.name
            ));
        }
    }
    for w in walls_at(code, &p.values) {
        if w.side * (x[w.coordinate] - w.position) > 0.0 {
            return Err(format!(
                "{} = {} lies behind the stop at {}",
                code.model.names.states[w.coordinate], x[w.coordinate], w.position
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

/// θ in [-π, π): θ - 2π·floor((θ + π)/2π). Twin of the generated
/// `wrap_angles` of `model::wgsl`, operation for operation.
pub fn wrap_angle(theta: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    theta - TAU * ((theta + PI) / TAU).floor()
}

/// Periods of the pilot that finds a nonlinear model's time scales.
const PILOT_PERIODS: usize = 2;
/// Samples of the Jacobian per pilot period.
const PILOT_SAMPLES: usize = 32;

/// (max |λ|, max -Re λ, at least 0) of a Jacobian's eigenvalues.
fn eigen_scales(j: &DMatrix<f64>) -> (f64, f64) {
    let eigen = j.complex_eigenvalues();
    (
        eigen.iter().map(|l| l.norm()).fold(0.0, f64::max),
        eigen.iter().map(|l| -l.re).fold(0.0, f64::max),
    )
}

fn walls_at(code: &Code, params: &[f64]) -> Vec<Wall> {
    code.walls
        .iter()
        .map(|w| Wall {
            position: w.position.eval(&[], params, 0.0),
            restitution: w.restitution.eval(&[], params, 0.0),
            coordinate: w.coordinate,
            velocity: w.velocity,
            side: w.side,
        })
        .collect()
}

/// A model at one lane's parameter values.
#[derive(Clone, Debug)]
pub struct ModelFlow<const D: usize> {
    code: &'static Code,
    params: Vec<f64>,
    /// Each region's tape's lane constants at these parameters.
    constants: Vec<Vec<f64>>,
    /// Each region's surface tape's lane constants.
    surface_constants: Vec<Vec<f64>>,
    frequency: f64,
    period: f64,
    walls: Vec<Wall>,
    /// The lane as a piecewise-linear system, where the model is one: the
    /// exact backend's propagator, built when that backend first asks.
    exact: std::sync::OnceLock<Option<PiecewiseLinear>>,
}

impl<const D: usize> Flow<D> for ModelFlow<D> {
    /// The field of the region y lies in (integration goes through
    /// [`rhs_in`](Flow::rhs_in), each step in its trajectory's region).
    fn rhs(&self, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        self.rhs_in(
            crate::integrate::surface::region_of(self, phase, y),
            phase,
            y,
        )
    }

    fn rhs_in(&self, region: u32, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let field = &self.code.regions[region as usize];
        let constants = &self.constants[region as usize];
        let y: [[f64; 1]; D] = std::array::from_fn(|i| [y[i]]);
        let out: [[f64; 1]; D] = match &field.native {
            Some(native) => native.call(Kind::Rhs, Layout::Shared, &y, phase, constants, &[]),
            None => field.equations.eval(|j| [constants[j]], &[*phase], &y),
        };
        std::array::from_fn(|i| out[i][0])
    }

    fn surfaces(&self) -> &[Surface] {
        &self.code.kinds
    }

    fn surface_values(&self, region: u32, phase: &Phase, y: &[f64; D]) -> SurfaceValues {
        let constants = &self.surface_constants[region as usize];
        let y: [[f64; 1]; D] = std::array::from_fn(|i| [y[i]]);
        let out: [[f64; 1]; 2 * MAX_SURFACES] =
            self.code.regions[region as usize]
                .surfaces
                .eval(|j| [constants[j]], &[*phase], &y);
        SurfaceValues {
            g: std::array::from_fn(|j| out[j][0]),
            rate: std::array::from_fn(|j| out[MAX_SURFACES + j][0]),
        }
    }

    #[inline(always)]
    fn surface_values_batch<const W: usize>(
        &self,
        region: u32,
        phases: &[Phase; W],
        y: &[[f64; W]; D],
    ) -> [SurfaceValues; W] {
        let constants = &self.surface_constants[region as usize];
        let out: [[f64; W]; 2 * MAX_SURFACES] =
            self.code.regions[region as usize]
                .surfaces
                .eval(|j| [constants[j]; W], phases, y);
        let mut values = [SurfaceValues::default(); W];
        for (k, v) in values.iter_mut().enumerate() {
            for j in 0..MAX_SURFACES {
                v.g[j] = out[j][k];
                v.rate[j] = out[MAX_SURFACES + j][k];
            }
        }
        values
    }

    fn surface_gradient(&self, j: usize, phase: &Phase, y: &[f64; D]) -> [f64; D] {
        let gradient = &self.code.surfaces[j].gradient;
        let t = self.time_at(phase);
        std::array::from_fn(|i| gradient[i].eval(y, &self.params, t))
    }

    fn stick_limit(&self, j: usize, y: &[f64; D]) -> Option<f64> {
        self.code.surfaces[j]
            .stick_limit
            .as_ref()
            .map(|l| l.eval(y, &self.params, 0.0))
    }

    fn reset(&self, j: usize, phase: &Phase, y: &[f64; D]) -> crate::integrate::Reset<D> {
        let s = &self.code.surfaces[j];
        let t = self.time_at(phase);
        (
            std::array::from_fn(|i| s.reset[i].eval(y, &self.params, t)),
            std::array::from_fn(|i| {
                std::array::from_fn(|k| s.reset_jacobian[i * D + k].eval(y, &self.params, t))
            }),
            std::array::from_fn(|i| s.reset_rate[i].eval(y, &self.params, t)),
        )
    }

    fn forcing_frequency(&self) -> f64 {
        self.frequency
    }

    fn walls(&self) -> &[Wall] {
        &self.walls
    }

    #[inline(always)]
    fn step_shared<const W: usize>(
        &self,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        self.step_shared_in(0, stages, y, h)
    }

    #[inline(always)]
    fn step_shared_in<const W: usize>(
        &self,
        region: u32,
        stages: &[Phase; 3],
        y: &[[f64; W]; D],
        h: f64,
    ) -> [[f64; W]; D] {
        let constants = &self.constants[region as usize];
        if let Some(native) = self.native::<W>(region) {
            let clock = stages.as_flattened();
            return native.call(Kind::Step, Layout::Shared, y, clock, constants, &[h]);
        }
        let tape = &self.code.regions[region as usize].equations;
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| [constants[j]; W]);
        rk4::step_batch(
            #[inline(always)]
            |s, y| tape.run(&mut registers, &[stages[s]; W], y),
            y,
            &[h; W],
        )
    }

    #[inline(always)]
    fn step_each<const W: usize>(
        flows: &[&Self; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        Self::step_each_region(0, flows, stages, y, h)
    }

    /// Slots in different regions are stepped once per region present,
    /// each region's code over the whole batch, its slots kept.
    #[inline(always)]
    fn step_each_in<const W: usize>(
        flows: &[&Self; W],
        regions: &[u32; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        let first = regions[0];
        let mut out = Self::step_each_region(first, flows, stages, y, h);
        let mut done = 1u32 << first;
        for &r in regions {
            if done & (1 << r) == 0 {
                done |= 1 << r;
                let other = Self::step_each_region(r, flows, stages, y, h);
                for k in (0..W).filter(|&k| regions[k] == r) {
                    for i in 0..D {
                        out[i][k] = other[i][k];
                    }
                }
            }
        }
        out
    }
}

/// The most lane constants [`ModelFlow::step_each`] gathers for the native
/// code (on the stack, per step); a model with more runs the interpreter.
const EACH_CONSTANTS: usize = 32;

impl<const D: usize> ModelFlow<D> {
    /// The local time of forcing phase (cos ωt, sin ωt) within the period:
    /// where an expression evaluated as a tree (a reset, a gradient) reads
    /// `t`, it reads the same cos ωt and sin ωt as the tapes' clock.
    fn time_at(&self, phase: &Phase) -> f64 {
        if self.frequency == 0.0 {
            return 0.0;
        }
        phase[1].atan2(phase[0]).rem_euclid(std::f64::consts::TAU) / self.frequency
    }

    /// The native code of a region's equations, if there is one for
    /// batches of W.
    #[inline(always)]
    fn native<const W: usize>(&self, region: u32) -> Option<&'static Native> {
        self.code.regions[region as usize]
            .native
            .as_ref()
            .filter(|_| Native::has::<W>())
    }

    /// One RK4 step of one trajectory of each of W flows, all in region
    /// `region` (see `Flow::step_each`).
    #[inline(always)]
    fn step_each_region<const W: usize>(
        region: u32,
        flows: &[&Self; W],
        stages: &[[Phase; 3]; W],
        y: &[[f64; W]; D],
        h: &[f64; W],
    ) -> [[f64; W]; D] {
        let r = region as usize;
        // Each slot's constants of this region, looked up once per step.
        let slots: [&[f64]; W] = std::array::from_fn(|k| flows[k].constants[r].as_slice());
        let l = slots[0].len();
        if let Some(native) = flows[0].native::<W>(region).filter(|_| l <= EACH_CONSTANTS) {
            // The slots' constants and stage phases side by side.
            let mut lane = [[0.0; W]; EACH_CONSTANTS];
            for (j, row) in lane[..l].iter_mut().enumerate() {
                for k in 0..W {
                    row[k] = slots[k][j];
                }
            }
            let mut clock = [[0.0; W]; 6];
            for s in 0..3 {
                for k in 0..W {
                    clock[2 * s][k] = stages[k][s][0];
                    clock[2 * s + 1][k] = stages[k][s][1];
                }
            }
            let (lane, clock) = (lane[..l].as_flattened(), clock.as_flattened());
            return native.call(Kind::Step, Layout::Each, y, clock, lane, h);
        }
        let tape = &flows[0].code.regions[r].equations;
        let mut registers = Registers::new();
        tape.prepare(&mut registers, |j| std::array::from_fn(|k| slots[k][j]));
        rk4::step_batch(
            #[inline(always)]
            |s, y| tape.run(&mut registers, &std::array::from_fn(|k| stages[k][s]), y),
            y,
            h,
        )
    }

    /// The flow's Jacobian at y and time t, as a matrix.
    fn jacobian_at(&self, y: &[f64; D], t: f64, region: u32) -> DMatrix<f64> {
        let values: Vec<f64> = self.code.regions[region as usize]
            .jacobian
            .iter()
            .map(|e| e.eval(y, &self.params, t))
            .collect();
        DMatrix::from_row_slice(D, D, &values)
    }
}

impl<const D: usize> ModelFlow<D> {
    /// (max |λ|, max -Re λ) of every region's Jacobian at the origin: a
    /// piecewise-linear model's time scales, all of its regions'.
    fn scales_at_origin(&self) -> (f64, f64) {
        (0..self.code.regions.len() as u32)
            .map(|r| eigen_scales(&self.jacobian_at(&[0.0; D], 0.0, r)))
            .fold((0.0, 0.0), |a, b| (a.0.max(b.0), a.1.max(b.1)))
    }
}

impl<const D: usize> System<D> for ModelFlow<D> {
    fn new(p: &Params) -> Self {
        let code = code_of(p);
        ModelFlow {
            code,
            params: p.values.clone(),
            constants: code
                .regions
                .iter()
                .map(|f| f.equations.lane_values(&p.values).constants)
                .collect(),
            surface_constants: code
                .regions
                .iter()
                .map(|f| f.surfaces.lane_values(&p.values).constants)
                .collect(),
            frequency: code.frequency(&p.values),
            period: code.period(&p.values),
            walls: walls_at(code, &p.values),
            exact: std::sync::OnceLock::new(),
        }
    }

    fn period(&self) -> f64 {
        self.period
    }

    fn iterate(&self, x: &[f64; D], flow: &FlowSettings, stats: &mut IterationStats) -> [f64; D] {
        time_map(self, x, self.period, flow, stats)
    }

    /// The piecewise-linear propagator's span: exact flow matrices between
    /// crossings located by a certified search, saltation matrices at them.
    fn iterate_exact(
        &self,
        x: &[f64; D],
        part: Part,
        stats: &mut IterationStats,
    ) -> Option<([f64; D], SMatrix<f64, D, D>)> {
        let exact = self
            .exact
            .get_or_init(|| piecewise_linear(self.code, &self.params))
            .as_ref()?;
        let (t0, t1) = part.span(self.period);
        let y = DVector::from_column_slice(x);
        let it = exact.iterate_span(&y, exact.region(&y), t0, t1);
        let walls = self.walls.len();
        let mut wall_log_det = 0.0;
        for (j, &c) in it.crossings.iter().enumerate() {
            stats.crossings[j] += c;
            if j < walls {
                stats.impacts += c;
                if c > 0 {
                    wall_log_det += 2.0 * f64::from(c) * self.walls[j].restitution.ln();
                }
            }
        }
        // The walls' e² per impact is in the expected sum already; the
        // general surfaces' det S goes with the orbit.
        let general = it.log_det_saltation - wall_log_det;
        if general.is_finite() {
            stats.log_flux += general;
        } else {
            stats.rank_loss = stats.rank_loss.max(1);
        }
        stats.slowest_impact = stats.slowest_impact.min(it.min_crossing_rate);
        match it.status {
            PiecewiseStatus::Ok => {}
            PiecewiseStatus::Sliding => stats.sliding = true,
            PiecewiseStatus::Grazing => {
                stats.grazing = true;
                stats.grazing_error = f64::INFINITY;
            }
            PiecewiseStatus::Chattering | PiecewiseStatus::Sticking => stats.chattering = true,
            PiecewiseStatus::Diverged => {}
        }
        let state: [f64; D] = std::array::from_fn(|i| it.state[i]);
        Some((state, SMatrix::from_column_slice(it.jacobian.as_slice())))
    }

    fn iterate_lanes(systems: &[Self], xs: &mut [[f64; D]], flow: &FlowSettings) {
        super::time_map_lanes(systems, xs, flow)
    }

    fn iterate_many(&self, ys: &mut [[f64; D]], flow: &FlowSettings, stats: &mut [IterationStats]) {
        time_map_many(self, ys, self.period, flow, stats)
    }

    fn part_many(
        &self,
        ys: &mut [[f64; D]],
        flow: &FlowSettings,
        part: Part,
        phase: &mut Phase,
        stats: &mut [IterationStats],
    ) {
        let (start, start_phase) = (ys.first().copied(), *phase);
        part_map_many(self, ys, self.period, flow, part, phase, stats);
        // A divergence that depends on the state: integrated along the
        // reference (the same steps again, alone), for the sum rule.
        if let (Some(tape), Some(start)) = (&self.code.equations_divergence(), start) {
            let h = self.period / flow.steps_per_period as f64;
            let steps = part.steps(flow.steps_per_period).len();
            let constants = tape.lane_values(&self.params).constants;
            let density = |phase: &Phase, y: &[f64; D]| -> f64 {
                let y: [[f64; 1]; D] = std::array::from_fn(|i| [y[i]]);
                let out: [[f64; 1]; 1] = tape.eval(|j| [constants[j]], &[*phase], &y);
                out[0][0]
            };
            let (end, integral) =
                crate::integrate::advance_integrating(self, &start, start_phase, h, steps, density);
            debug_assert_eq!(end, ys[0]);
            stats[0].log_flux += integral;
        }
    }

    /// The largest |eigenvalue| of the Jacobian at the origin: exact for a
    /// flow linear between impacts (the seed's oscillator gives 1, as its
    /// hand-written twin does), an estimate for a nonlinear one (see
    /// `time_scales`).
    fn stiffness(&self) -> f64 {
        self.scales_at_origin().0
    }

    /// The fastest decay rate at the origin, -min Re λ (0 if none decays).
    fn contraction(&self) -> f64 {
        self.scales_at_origin().1
    }

    /// A flow whose Jacobian depends on the state (or time) has its time
    /// scales where its orbit goes, not at the origin (van der Pol's
    /// origin is unstable; it contracts on its relaxation cycle): the
    /// largest over the origin and a pilot of `PILOT_PERIODS` periods
    /// from the initial state, sampled `PILOT_SAMPLES` times a period. A
    /// constant Jacobian (a flow linear between impacts) is read at the
    /// origin alone, as [`stiffness`](System::stiffness) does.
    fn time_scales(&self, initial: &[f64], flow: &FlowSettings) -> (f64, f64) {
        let at_origin = (self.stiffness(), self.contraction());
        let constant = self
            .code
            .regions
            .iter()
            .all(|f| f.jacobian.iter().all(|e| !reads_state_or_time(e)));
        if constant || initial.len() != D {
            return at_origin;
        }
        let mut y: [f64; D] = std::array::from_fn(|i| initial[i]);
        let mut scales = at_origin;
        let mut stats = [IterationStats::default()];
        for _ in 0..PILOT_PERIODS {
            let mut phase = crate::integrate::clock::ZERO_PHASE;
            for part in Part::all(PILOT_SAMPLES) {
                let t = self.period * part.index as f64 / PILOT_SAMPLES as f64;
                let region = crate::integrate::surface::region_of(self, &phase, &y);
                let (stiffness, contraction) = eigen_scales(&self.jacobian_at(&y, t, region));
                scales = (scales.0.max(stiffness), scales.1.max(contraction));
                let mut ys = [y];
                part_map_many(
                    self,
                    &mut ys,
                    self.period,
                    flow,
                    part,
                    &mut phase,
                    &mut stats,
                );
                y = ys[0];
                if !y.iter().all(|v| v.is_finite()) {
                    return scales;
                }
            }
        }
        scales
    }

    fn admits(&self, y: &[f64; D]) -> bool {
        self.walls.iter().all(|w| w.gap(y) <= 0.0)
            && self
                .code
                .surfaces
                .iter()
                .all(|s| s.kind != Surface::Event || s.g.eval(y, &self.params, 0.0) <= 0.0)
    }

    fn wrap(&self, x: &mut [f64; D]) {
        for &i in &self.code.model.angles {
            x[i] = wrap_angle(x[i]);
        }
    }
}

/// Why the GPU kernels cannot run this model, the same for every lane
/// (`model::wgsl::check`); `None` when its generated WGSL runs.
fn gpu_refuses(p: &Params) -> Option<String> {
    crate::model::wgsl::check(code_of(p))
        .err()
        .map(|why| why.to_string())
}
