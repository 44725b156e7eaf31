//! A model compiled: the parsed expressions of a scene's `[model]` table
//! (`super::Model`) turned once per run into what the integrator and the
//! kernels evaluate: one field per region of its switches (tape, native
//! code, surfaces, Jacobian), its events sorted into stops and general
//! surfaces, its map, and where it is piecewise linear its exact
//! propagator's matrices ([`piecewise_linear`]). `system::model` runs it;
//! `wgsl` and `describe` read it.
//!
//! An event that is a stop (a surface `x - c` or `c - x` on one state x, c
//! of parameters alone, whose equation is another state v, x' = v, with a
//! reset of v alone that is linear in v, `v = "-e*v"`) runs as a wall: the
//! vectorised detection and the sticking of `integrate::impact`; each
//! impact multiplies phase-space volume by e², which the sum rule adds.
//! Any other event, and every switch, is a general surface
//! (`integrate::surface`), whose ln|det S| the integrator records crossing
//! by crossing.

use nalgebra::{DMatrix, DVector};

use crate::error::{Error, Result};
use crate::integrate::impact::MAX_WALLS;
use crate::integrate::piecewise_linear::{LinearField, LinearSurface, PiecewiseLinear};
use crate::integrate::surface::MAX_SURFACES;
use crate::integrate::{Surface, Wall};
use crate::model::ir::tape::Tape;
pub(crate) use crate::model::language::expr::reads_state_or_time;
use crate::model::language::expr::{Expr, Var, Written};
use crate::model::native::abi::{step_loops, Loops, StopCode};
use crate::model::native::library::{Native, SwitchLoops};
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
    /// `system::model::ModelFlow::stiffness`).
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
    /// The regions' step loop with the surfaces' detection where the map
    /// is a period map with general surfaces: the C compiler's, or why it
    /// did not build it.
    pub switch_loops: Option<std::result::Result<SwitchLoops, String>>,
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
    /// Whether ∇g reads the time: only then does evaluating it need the
    /// time of a forcing phase (an `atan2`, which the sliding of a
    /// friction model paid at every stage of every step).
    pub gradient_reads_time: bool,
    /// An event's reset: every state's value after it (the states it does
    /// not name keep theirs), and its Jacobian DR, row-major. Empty for a
    /// switch.
    pub reset: Vec<Expr>,
    pub reset_jacobian: Vec<Expr>,
    /// ∂R/∂t of an event's reset, one per state (zeros unless it reads `t`).
    pub reset_rate: Vec<Expr>,
    /// A switch's stick limit (see `integrate::surface`), if it has one.
    pub stick_limit: Option<Expr>,
    /// What holding the motion on an event's surface takes (an event of a
    /// model without switches): see [`EventHold`].
    pub hold: Option<EventHold>,
}

/// Sticking on an event's surface (a ball locked onto a vibrating table):
/// where the event's crossings accumulate, the motion stays on g = 0 with
/// ġ = 0, pushed by a constraint force along the states the reset changes
/// (the velocities), as large as keeps g̈ = 0, for as long as the free
/// field presses the motion into the surface (`integrate::impact`'s
/// held-on-event motion). The trees are built from the event's g and the
/// field by symbolic derivatives.
#[derive(Debug)]
pub struct EventHold {
    /// ġ = ∇g·F + ∂g/∂t along the field.
    pub rate: Expr,
    /// ∇ġ, one derivative per state.
    pub rate_gradient: Vec<Expr>,
    /// g̈ = ∇ġ·F + ∂ġ/∂t along the free field: > 0 presses the motion into
    /// the surface (it sticks), < 0 pulls it away (it leaves).
    pub pressing: Expr,
    /// The states the reset changes: the constraint force acts on them.
    pub pushed: Vec<bool>,
}

impl EventHold {
    fn new(g: &Expr, gradient: &[Expr], reset: &[Expr], field: &[Expr]) -> Self {
        use crate::model::language::expr::{add, mul};
        let along = |gradient: &[Expr], of: &Expr| {
            gradient
                .iter()
                .zip(field)
                .fold(of.derivative(Var::Time), |sum, (d, f)| {
                    add(sum, mul(d.clone(), f.clone()))
                })
        };
        let rate = along(gradient, g);
        let rate_gradient: Vec<Expr> = (0..field.len())
            .map(|i| rate.derivative(Var::State(i)))
            .collect();
        let pressing = along(&rate_gradient, &rate);
        EventHold {
            pushed: reset
                .iter()
                .enumerate()
                .map(|(i, r)| !matches!(r, Expr::Var(Var::State(k)) if *k == i))
                .collect(),
            rate,
            rate_gradient,
            pressing,
        }
    }
}

/// One region's field, compiled.
#[derive(Debug)]
pub struct Field {
    pub equations: Tape,
    /// The equations as native code, where the host's C compiler builds
    /// it (else the tape's interpreter runs them).
    pub native: Option<Native>,
    /// Why there is no native code, where there is none.
    pub native_failure: Option<String>,
    /// g of each general surface followed by its rate ∇g·F along this
    /// field, surface by surface (rows 2j and 2j + 1 of a
    /// `surface::SurfaceBatch`).
    pub surfaces: Tape,
    /// The surfaces' tape as native code, where the model has surfaces
    /// and the host allows: the integrator evaluates it for every
    /// trajectory at every step.
    pub surfaces_native: Option<Native>,
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

/// The states an expression reads.
fn states_read(e: &Expr, n: usize) -> Vec<usize> {
    (0..n).filter(|&i| e.uses(Var::State(i))).collect()
}

impl Code {
    /// Where the host's C compiler was asked for the model's native code
    /// and failed (the interpreter then runs it, 8 to 10 times slower): a
    /// warning naming the compiler (`$CC`, else `cc`) and its error. `None`
    /// where it built the code, or `LYAPSWEEP_STEP_LOOPS=interpreter`
    /// asked for the interpreter.
    pub fn interpreter_fallback(&self) -> Option<String> {
        if step_loops() == Loops::Interpreter {
            return None;
        }
        let why = self
            .regions
            .iter()
            .find_map(|f| f.native_failure.as_deref())
            .or(match &self.switch_loops {
                Some(Err(why)) => Some(why.as_str()),
                _ => None,
            })?;
        Some(format!(
            "the C compiler (CC = {}) did not build the model's native code, so the CPU runs it on the interpreter, 8 to 10 times slower: {why}",
            crate::model::native::compiler::compiler()
        ))
    }

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
        let section = section_of(&model, &equations, key)?;
        let (walls, surfaces) = events_of(&model, &equations, key)?;
        let kinds: Vec<Surface> = surfaces.iter().map(|s| s.kind).collect();
        // A period map without general surfaces steps in a loop of native
        // code between the steps that meet a stop (`Flow::walk_shared`).
        let stop_codes: Vec<StopCode> = walls
            .iter()
            .map(|w: &Stop| StopCode {
                coordinate: w.coordinate,
                velocity: w.velocity,
                side: w.side,
            })
            .collect();
        let stepping = (section.is_none() && surfaces.is_empty()).then_some(&stop_codes[..]);
        let regions = (0..1u32 << model.switches.len())
            .map(|r| {
                let stops = stepping;
                field(
                    &model,
                    &surfaces,
                    r,
                    equations.frequency.clone(),
                    stops,
                    key,
                )
            })
            .collect::<Result<Vec<_>>>()?;
        let (divergence, divergence_along) = divergence_of(
            &model,
            regions.len(),
            section.is_some() || walls.is_empty(),
            equations.frequency.clone(),
            key,
        )?;
        let jacobian = (0..n * n)
            .map(|ij| model.equations[ij / n].derivative(Var::State(ij % n)))
            .collect();
        // With general surfaces, the same between the steps that meet a
        // stop or may cross a surface, in a loop of every region's field
        // (`Flow::walk_shared`); only the C compiler builds it, and
        // without it the step loop of `integrate` takes every step.
        let switch_loops = match (section.is_none() && !surfaces.is_empty(), step_loops()) {
            (true, Loops::CCompiler) => {
                let fields: Vec<(&Tape, &Tape)> = regions
                    .iter()
                    .map(|f| (&f.equations, &f.surfaces))
                    .collect();
                Some(SwitchLoops::build(&fields, &stop_codes, &kinds))
            }
            _ => None,
        };
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
            switch_loops,
        })
    }

    /// The compiled divergence of a period map without walls whose
    /// divergence depends on the state (see `ModelFlow::part_many`).
    pub(crate) fn equations_divergence(&self) -> Option<&Tape> {
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
        crate::model::language::expr::Op::Mul,
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
    use crate::model::language::expr::Func;
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
    let gradient: Vec<Expr> = (0..n)
        .map(|i| event.surface.derivative(Var::State(i)))
        .collect();
    Ok(GeneralSurface {
        name: event.name.clone(),
        kind: Surface::Event,
        g: event.surface.clone(),
        gradient_reads_time: gradient.iter().any(|e| e.uses(Var::Time)),
        gradient,
        reset,
        reset_jacobian,
        reset_rate,
        stick_limit: None,
        // Set once the switches are known (`Code::compile`).
        hold: None,
    })
}

/// The field of region `region` of the switches, compiled, with its
/// surfaces' values and rates.
fn field(
    model: &Model,
    surfaces: &[GeneralSurface],
    region: u32,
    frequency: Option<Expr>,
    stops: Option<&[StopCode]>,
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
    // Each surface's g, then its rate, surface by surface: the rows a
    // batch keeps them in (`surface::SurfaceBatch`), so a model with one
    // surface computes and stores two rows, not `2·MAX_SURFACES`.
    let rows: Vec<Expr> = surfaces
        .iter()
        .flat_map(|s| {
            let rate = (0..n)
                .map(|i| {
                    Expr::Bin(
                        crate::model::language::expr::Op::Mul,
                        Box::new(s.gradient[i].clone()),
                        Box::new(equations[i].clone()),
                    )
                })
                // ∂g/∂t: a surface that moves with the forcing.
                .chain([s.g.derivative(Var::Time)])
                .reduce(|a, b| {
                    Expr::Bin(
                        crate::model::language::expr::Op::Add,
                        Box::new(a),
                        Box::new(b),
                    )
                })
                .expect("a model has a state");
            [s.g.clone(), rate]
        })
        .collect();
    let surface_tape = Tape::compile(&rows, n, frequency).map_err(|(i, why)| {
        Error::invalid(
            format!("{key}: the surface of '{}'", surfaces[i / 2].name),
            why.to_string(),
        )
    })?;
    let jacobian = (0..n * n)
        .map(|ij| equations[ij / n].derivative(Var::State(ij % n)))
        .collect();
    let (native, native_failure) = match Native::compile_stepping(&tape, stops) {
        Ok(native) => (Some(native), None),
        Err(why) => (None, Some(why)),
    };
    Ok(Field {
        native,
        native_failure,
        equations: tape,
        surfaces_native: if surfaces.is_empty() {
            None
        } else {
            Native::compile(&surface_tape).ok()
        },
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

/// The stops of `code` as the integrator's walls at parameter values
/// `params`.
pub fn walls_at(code: &Code, params: &[f64]) -> Vec<Wall> {
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

/// The `spectrum.csv` column of a model's event: its crossings per
/// period (the model is refused where two events' columns would collide).
pub fn event_column(event: &str) -> String {
    let name: String = event
        .chars()
        .map(|c| if c.is_alphanumeric() { c } else { '_' })
        .collect();
    format!("{name}_per_period")
}

/// The Poincaré section of a model whose map is one: refused where the
/// flow reads the time or has events or switches.
fn section_of(model: &Model, equations: &Tape, key: &str) -> Result<Option<SectionSpec>> {
    let Map::Section {
        state,
        at,
        increasing,
    } = &model.map
    else {
        return Ok(None);
    };
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
    Ok(Some(SectionSpec {
        state: *state,
        at: at.clone(),
        increasing: *increasing,
    }))
}

/// The model's events sorted into stops and general surfaces, then its
/// switches as surfaces after the events (the CPU's and the kernels'
/// order), each column's name checked to be its own.
fn events_of(
    model: &Model,
    equations: &Tape,
    key: &str,
) -> Result<(Vec<Stop>, Vec<GeneralSurface>)> {
    let n = model.names.states.len();
    let mut walls = Vec::new();
    let mut surfaces = Vec::new();
    for (j, event) in model.events.iter().enumerate() {
        let column = event_column(&event.name);
        if model.events[..j]
            .iter()
            .any(|e| event_column(&e.name) == column)
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
        match stop(model, event, &event_key) {
            Some(stop) => walls.push(stop),
            None => surfaces.push(general_event(
                model,
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
        let gradient: Vec<Expr> = (0..n)
            .map(|i| switch.surface.derivative(Var::State(i)))
            .collect();
        surfaces.push(GeneralSurface {
            name: switch.name.clone(),
            kind: Surface::Switch { bit: b as u32 },
            g: switch.surface.clone(),
            gradient_reads_time: gradient.iter().any(|e| e.uses(Var::Time)),
            gradient,
            reset: Vec::new(),
            reset_jacobian: Vec::new(),
            reset_rate: Vec::new(),
            stick_limit: switch.stick_limit.clone(),
            hold: None,
        });
    }
    if model.switches.is_empty() {
        // Sticking on an event is integrated where one smooth field
        // holds (no switches); elsewhere an accumulation is flagged.
        for s in surfaces.iter_mut().filter(|s| s.kind == Surface::Event) {
            s.hold = Some(EventHold::new(
                &s.g,
                &s.gradient,
                &s.reset,
                &model.equations,
            ));
        }
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
        let column = event_column(&s.name);
        let earlier = walls
            .iter()
            .map(|w| &w.name)
            .chain(surfaces[..j].iter().map(|s| &s.name));
        if let Some(other) = earlier.into_iter().find(|o| event_column(o) == column) {
            return Err(Error::invalid(
                format!("{key}.switches"),
                format!(
                    "'{}' and '{other}' name the same column {column}: give each its own name",
                    s.name
                ),
            ));
        }
    }
    Ok((walls, surfaces))
}

/// The divergence of the field, for the sum rule: a constant, or a tape
/// along the flow where it reads the state or time and the sum rule
/// integrates it (`along`: a section's map or a flow without stops).
/// `None` for both where it differs between the switches' `regions`, or
/// where stops would have to integrate a varying one.
fn divergence_of(
    model: &Model,
    regions: usize,
    along: bool,
    clock: Option<Expr>,
    key: &str,
) -> Result<(Option<Expr>, Option<Tape>)> {
    let n = model.names.states.len();
    let whole_divergence = (0..n)
        .map(|i| model.equations[i].derivative(Var::State(i)))
        .reduce(|a, b| {
            Expr::Bin(
                crate::model::language::expr::Op::Add,
                Box::new(a),
                Box::new(b),
            )
        })
        .expect("a model has a state");
    // A divergence that reads the switches' sides is the same
    // everywhere only when every region's is the same.
    let whole_divergence = if whole_divergence.reads_sides() {
        let first = whole_divergence.in_region(0);
        if (0..regions).all(|r| whole_divergence.in_region(r as u32) == first) {
            Some(first)
        } else {
            None
        }
    } else {
        Some(whole_divergence)
    };
    Ok(match whole_divergence {
        None => (None, None),
        Some(whole_divergence) => {
            if !reads_state_or_time(&whole_divergence) {
                (Some(whole_divergence), None)
            } else if along {
                let tape = Tape::compile([&whole_divergence], n, clock).map_err(|(_, why)| {
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
    })
}
