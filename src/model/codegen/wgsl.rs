//! Models compiled for the GPU: the system file the kernels include
//! (`SystemInfo::wgsl`), generated from the model's lowered tapes, the
//! twin of a hand-written `shaders/system/<kind>.wgsl` (Hénon's).
//!
//! The file has the hand-written files' shape: `struct Params` (every parameter, in
//! the model's order), `fn rhs(p, phase, y) -> State` (one value per
//! state) and, for a model with stops, what `shaders/shared/stops.wgsl`
//! reads of them: `WALLS`, each stop's coordinate, velocity and side
//! (`WALL_COORDINATE`, `WALL_VELOCITY`, `WALL_SIDE`, constants, so that the
//! kernels' per-stop code folds to the seed's `y.x > X_w` for a stop on
//! the first state from below), and its position and restitution as the
//! components of `wall_position(p)` and `wall_restitution(p)`. Every
//! function's body is a tape of its expressions printed by the printer
//! that prints the CPU's native code (`model::codegen::print`), with WGSL's syntax,
//! so that the equations are lowered once:
//!
//! - one `let` per operation, in the tape's order, each operation as the
//!   tree associates it (`(-2*zeta)*v - x + f*phase.x` is four), so in f64
//!   the GPU rounds where the CPU does. The CPU computes a
//!   parameter-only subexpression once per lane with [`Expr::eval`]; the
//!   GPU's tape reads the parameters themselves
//!   (`Tape::compile_reading_parameters`) and recomputes it per call with
//!   the same operations in the same order, which gives the same bits. (A
//!   driver may still fuse a product into the sum that uses it, as
//!   lavapipe does: the seed oscillator as a model was the retired
//!   hand-written kernel to the bit, and the CPU path to rounding.)
//! - `cos(w*t)` and `sin(w*t)` read the forcing clock, `phase.x` and
//!   `phase.y`, exactly where the tape reads its clock (`Tape::compile`);
//! - numbers are `real(…)` of Rust's shortest round-trip form, so an f64
//!   variant has the tree's very number;
//! - `abs`, `sqrt`, `min`, `max` and `sign` are WGSL builtins (defined on
//!   f64); every other function calls a `*_r` wrapper of
//!   `shaders/shared/model_functions.wgsl`, which `backend::gpu::shader`
//!   includes per precision: `shaders/shared/math64.wgsl` (arithmetic
//!   alone) for f64, whose transcendental builtins Vulkan leaves undefined,
//!   WGSL's builtins for f32. sin, cos and tan there are the CPU's own
//!   arithmetic (`model::language::math64`: the same bits on lavapipe); exp, log,
//!   tanh, atan2 and pow are within a few ulp of Rust's functions, not to
//!   the bit, so a model that calls one matches the CPU to rounding.
//!
//! For a model with general surfaces (events that are not stops, and
//! switches) the file adds what the surface code (`model::ir::surfaces`'s
//! generated functions) reads:
//! `SURFACES`, each one's `SURFACE_BIT` (its switch bit, or `EVENT`), the
//! region's layout (`SLIDING_SHIFT`, `SIDES`),
//! `surface_g`, `surface_values` (g and its rate ∇g·F + ∂g/∂t along the
//! field in force, the CPU surface tape's sum in its order),
//! `surface_gradient` and an event's `reset` (the state after it, DR and
//! ∂R/∂t), all printed from tapes of the CPU's trees. `Params` then ends with the
//! trajectory's `region` (bit b set on the positive side of switch b),
//! which the kernels set, and `step(s)`/`sign(s)` of a switch read that
//! bit (`side(p, b)`), never the state: the value 0 or 1 multiplies where
//! the CPU's per-region tape has it folded in, which rounds alike.
//!
//! What the kernels run so far ([`check`]): a period map of a flow of 2 to
//! 4 states (the kernels' `State` is a WGSL vector) with up to four stops,
//! events and switches in all (one vec4 of crossing counts): stops on any
//! state x with its velocity v (x' = v), approached from either side,
//! reset v → -e·v (`system::model::Stop`), with the CPU's sticking (a mass
//! held at rest on a stop while the others move on) and per-stop crossing
//! counts; and general surfaces: events with any surface
//! g(y, clock) and any reset, and switches crossed transversally, each
//! crossing located and applied as on the CPU (`integrate::surface`) with
//! its ln |det S| for the sum rule; and sliding on one switch at a time
//! (Filippov's combination or a stick limit: the friction belt), entered
//! where both fields point into the switch and left where a stick margin
//! runs out, as on the CPU. A motion they do not integrate (another
//! surface or a stop met while sliding, sliding on two switches at once, a
//! mass at rest on a stop of a model with surfaces, whose release the CPU
//! resolves with them) is flagged (`FLAG_SLIDING`) and its lane recomputed
//! on the CPU by the backend; a model with stick limits on several
//! switches (the two-block belt) runs on the CPU.
//!
//! A Poincaré section's file adds `SECTION_STATE` and `SECTION_DIRECTION`
//! (its `at` comes per lane from the host): `shaders/section.wgsl` steps
//! its trajectories, and the host does the rest (`backend::gpu::section`).

use std::fmt::{self, Write};

use crate::model::codegen::print::{self, Inputs, Syntax};
use crate::model::compiled::Code;
use crate::model::ir::tape::{CompileError, Tape};
use crate::model::language::expr::{Expr, Func, Op, Var, Written};

/// The wrappers a generated file may call, defined per precision in
/// `shaders/shared/model_functions.wgsl`: a system file that calls none of
/// them gets neither that file nor `math64.wgsl`.
pub const WRAPPERS: [&str; 7] = [
    "sin_r", "cos_r", "tan_r", "exp_r", "log_r", "tanh_r", "atan2_r",
];

/// The one wrapper with two names in the trees (`x^y` and `pow(x, y)`).
const POW: &str = "pow_r";

/// Whether a system file calls a wrapper of `model_functions.wgsl`.
pub fn calls_wrappers(system: &str) -> bool {
    WRAPPERS
        .iter()
        .chain(&[POW])
        .any(|name| system.contains(&format!("{name}(")))
}

/// Why the GPU kernels cannot run a model (yet).
#[derive(Clone, Debug, PartialEq)]
pub enum Unsupported {
    /// The kernels' `State` is `vec2`..`vec4`.
    States(usize),
    /// More stops, events and switches than the kernels count.
    Events(String),
    /// A number with no WGSL literal (∞ or NaN from folding).
    Number(f64),
    /// `t` outside the forcing clock (the CPU compiler refuses it first).
    Time,
    /// A switch with a stick limit in a model with several switches, made
    /// to be slid on several at once: the kernels slide on one.
    Sliding(String),
    /// An expression nested deeper than the GPU kernels take.
    Depth(usize),
    /// A function of the system file with more operations than a tape's
    /// slots number.
    Length(usize),
}

/// The deepest expression tree the kernels take, the bound docs/models.md
/// states (naga's parser stops at 200 levels of recursion in one
/// expression). The system file is printed one operation per line
/// ([`lines`]), which the parser takes at any depth, so this bound is
/// stricter than the file needs.
pub const MAX_DEPTH: usize = 150;

impl fmt::Display for Unsupported {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Unsupported::States(n) => write!(
                f,
                "the model has {n} state{}: the GPU kernels run 2 to 4 so far",
                if *n == 1 { "" } else { "s" }
            ),
            Unsupported::Events(why) => write!(
                f,
                "{why}: the GPU kernels count up to four stops, events and switches together"
            ),
            Unsupported::Sliding(name) => write!(
                f,
                "the switch '{name}' has a stick limit, and the model other switches: the \
                 GPU kernels slide on one switch at a time so far"
            ),
            Unsupported::Number(v) => write!(f, "the number {v} has no WGSL literal"),
            Unsupported::Time => write!(f, "t appears outside cos(w*t) and sin(w*t)"),
            Unsupported::Length(n) => write!(
                f,
                "a function of the GPU's system file has {n} operations, more than a tape holds"
            ),
            Unsupported::Depth(depth) => write!(
                f,
                "an expression (or its derivative) is {depth} levels deep: the GPU kernels' \
                 WGSL compiler takes {MAX_DEPTH} (group a long sum's terms in parentheses)"
            ),
        }
    }
}

/// Whether the kernels can run `code`, and if not why not.
pub fn check(code: &Code) -> Result<(), Unsupported> {
    // The kernels' State is the flow's: N states, a map of N - 1 for a
    // Poincaré section (which shaders/section.wgsl runs).
    let n = code.states();
    if !(2..=4).contains(&n) {
        return Err(Unsupported::States(n));
    }
    // Stops and general surfaces share the kernels' per-trajectory
    // crossing counts, a vec4: up to four together. A mass at rest on a
    // stop of a model with surfaces is left to the CPU (the kernels' held
    // step does not watch the surfaces): the lane is flagged and
    // recomputed there.
    let events = code.walls.len() + code.surfaces.len();
    if events > crate::integrate::impact::MAX_WALLS {
        return Err(Unsupported::Events(format!(
            "{} stops and {} events and switches",
            code.walls.len(),
            code.surfaces.len()
        )));
    }
    // The kernels slide on one switch at a time (Filippov's combination,
    // or a stick limit): a motion that would slide on two at once is
    // flagged (`FLAG_SLIDING`) and recomputed on the CPU, and a model made
    // to do so (stick limits on several switches: the two-block belt) is
    // the CPU's from the start.
    let switches = code
        .surfaces
        .iter()
        .filter(|s| matches!(s.kind, crate::integrate::Surface::Switch { .. }))
        .count();
    if switches > 1 {
        if let Some(s) = code.surfaces.iter().find(|s| s.stick_limit.is_some()) {
            return Err(Unsupported::Sliding(s.name.clone()));
        }
    }
    // Any stop (Code::compile allows MAX_WALLS, the components of the
    // kernels' vec4 per-stop values).
    debug_assert!(code.walls.len() <= crate::integrate::impact::MAX_WALLS);
    let mut trees: Vec<&Expr> = code.model.equations.iter().collect();
    for stop in &code.walls {
        trees.push(&stop.position);
        trees.push(&stop.restitution);
    }
    let rates: Vec<Expr> = code
        .surfaces
        .iter()
        .map(|s| s.g.derivative(Var::Time))
        .collect();
    for (s, rate) in code.surfaces.iter().zip(&rates) {
        trees.push(&s.g);
        trees.push(rate);
        trees.extend(&s.gradient);
        trees.extend(&s.reset);
        trees.extend(&s.reset_jacobian);
        trees.extend(&s.reset_rate);
        trees.extend(&s.stick_limit);
    }
    for e in trees {
        emittable(e)?;
        let depth = e.depth();
        if depth > MAX_DEPTH {
            return Err(Unsupported::Depth(depth));
        }
    }
    Ok(())
}

/// Every number of `e` has a literal and `t` appears only in the clock.
fn emittable(e: &Expr) -> Result<(), Unsupported> {
    match e {
        Expr::Num(v) if !v.is_finite() => Err(Unsupported::Number(*v)),
        // A switch's side is read from the trajectory's region (`side`).
        Expr::Num(_) | Expr::Var(Var::State(_) | Var::Param(_) | Var::Side(_)) => Ok(()),
        Expr::Var(Var::Time) => Err(Unsupported::Time),
        // The clock: its argument is not emitted (the tape compiler has
        // checked that it is w*t with w of the parameters).
        Expr::Call(Func::Cos | Func::Sin, args) if args[0].uses(Var::Time) => Ok(()),
        Expr::Neg(a) => emittable(a),
        Expr::Bin(_, a, b) => emittable(a).and(emittable(b)),
        Expr::Call(_, args) => args.iter().try_for_each(emittable),
    }
}

/// The system file of `code`, or why the kernels cannot run it.
pub fn system_source(code: &Code) -> Result<String, Unsupported> {
    check(code)?;
    let model = &code.model;
    let names = &model.names;
    let mut out = String::new();
    // Writing to a String cannot fail.
    let w = &mut out;
    let _ = writeln!(
        w,
        "// Generated by src/model/codegen/wgsl.rs from the model '{}': its tapes, the\n\
         // CPU's operations in the CPU's order (src/model/codegen/print.rs).",
        model.name
    );
    for (state, e) in names.states.iter().zip(&model.equations) {
        let _ = writeln!(w, "//   {state}' = {}", Written { expr: e, names });
    }
    let _ = writeln!(w, "\nstruct Params {{");
    for i in 0..names.parameters.len() {
        let _ = writeln!(w, "    {}: real,", field(names, i));
    }
    if names.parameters.is_empty() {
        // WGSL has no empty struct; load_params builds `Params()`.
        let _ = writeln!(w, "    unused: real,");
    }
    if !code.surfaces.is_empty() {
        // The field in force: the region of the switches the trajectory
        // is in (bit b set on the positive side of switch b), set by the
        // kernels, not a parameter of the lane.
        let _ = writeln!(w, "    region: u32,");
    }
    let _ = writeln!(w, "}}\n");
    equations(w, code)?;
    if !code.walls.is_empty() || !code.surfaces.is_empty() {
        stops(w, code)?;
    }
    if !code.surfaces.is_empty() {
        surfaces(w, code)?;
        surface_values(w, code)?;
        gradients_and_resets(w, code)?;
        stick_limits(w, code)?;
    }
    if let Some(section) = &code.section {
        section_constants(w, code, section);
    }
    if !model.angles.is_empty() {
        wrap_angles(w, code);
    }
    Ok(out)
}

/// The field: with surfaces, the field of p's region is `field`, and
/// `rhs` (what RK4 steps) is it or, for a motion sliding on a switch, the
/// sliding field built from it (`model::ir::surfaces`; [`surfaces`]).
fn equations(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let _ = writeln!(
        w,
        "// phase = (cos ωt, sin ωt) of the forcing clock.\n\
         fn {}(p: Params, phase: vec2<real>, y: State) -> State {{",
        if code.surfaces.is_empty() {
            "rhs"
        } else {
            "field"
        }
    );
    let equations: Vec<&Expr> = code.model.equations.iter().collect();
    let values = lines(w, code, &equations, &states(code), "    ")?;
    let _ = writeln!(w, "    return State(");
    for (value, state) in values.iter().zip(&code.model.names.states) {
        let _ = writeln!(w, "        {value}, // {state}'");
    }
    let _ = writeln!(w, "    );\n}}");
    Ok(())
}

/// Twin of `system::model::wrap_angle`: θ - 2π·floor((θ + π)/2π), with
/// Rust's π and 2π to the bit.
fn wrap_angles(w: &mut String, code: &Code) {
    let _ = writeln!(
        w,
        "\n// The angles, into [-π, π) at the end of each map iteration.\n\
         fn wrap_angles(y: State) -> State {{\n    var w = y;"
    );
    for &i in &code.model.angles {
        let _ = writeln!(
            w,
            "    w[{i}] = w[{i}] - {tau} * floor((w[{i}] + {pi}) / {tau}); // {}",
            code.model.names.states[i],
            tau = literal(std::f64::consts::TAU),
            pi = literal(std::f64::consts::PI),
        );
    }
    let _ = writeln!(w, "    return w;\n}}");
}

/// A Poincaré section y_k = at(p), as `shaders/section.wgsl` reads it:
/// the state k and the direction it is crossed in; `at` per lane, from
/// the host (the CPU's own value of the expression).
fn section_constants(w: &mut String, code: &Code, section: &crate::model::compiled::SectionSpec) {
    let _ = writeln!(
        w,
        "\n// The Poincaré section {} = {}, crossed {}.\n\
         const SECTION_STATE: u32 = {}u;\n\
         const SECTION_DIRECTION: real = real({});",
        code.model.names.states[section.state],
        Written {
            expr: &section.at,
            names: &code.model.names
        },
        if section.increasing {
            "increasing"
        } else {
            "decreasing"
        },
        section.state,
        if section.increasing { "1.0" } else { "-1.0" },
    );
}

/// The stops of `code` as `shaders/shared/stops.wgsl` reads them: per
/// stop j, component j of the constants and of the two functions (the
/// components past `WALLS` are never read, and are 0).
fn stops(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let names = &code.model.names;
    let walls = &code.walls;
    let _ = writeln!(w, "\n// The stops, in the model's order:");
    for (j, stop) in walls.iter().enumerate() {
        let _ = writeln!(
            w,
            "//   {j}: '{}', {} {} {}, {}' = {}",
            stop.name,
            names.states[stop.coordinate],
            if stop.side > 0.0 { "<=" } else { ">=" },
            Written {
                expr: &stop.position,
                names
            },
            names.states[stop.coordinate],
            names.states[stop.velocity],
        );
    }
    let vector = |kind: &str, each: &dyn Fn(usize) -> String| {
        let zero = if kind == "u32" { "0u" } else { "real(0.0)" };
        vec4(kind, walls.len(), each, zero)
    };
    let _ = writeln!(w, "const WALLS: u32 = {}u;", walls.len());
    let _ = writeln!(
        w,
        "const WALL_COORDINATE = {};",
        vector("u32", &|j| format!("{}u", walls[j].coordinate))
    );
    let _ = writeln!(
        w,
        "const WALL_VELOCITY = {};",
        vector("u32", &|j| format!("{}u", walls[j].velocity))
    );
    let _ = writeln!(
        w,
        "const WALL_SIDE = {};",
        vector("real", &|j| literal(walls[j].side))
    );
    let positions: Vec<&Expr> = walls.iter().map(|s| &s.position).collect();
    let restitutions: Vec<&Expr> = walls.iter().map(|s| &s.restitution).collect();
    for (name, exprs) in [
        ("wall_position", positions),
        ("wall_restitution", restitutions),
    ] {
        let _ = writeln!(w, "\nfn {name}(p: Params) -> vec4<real> {{");
        let values = lines(w, code, &exprs, &states(code), "    ")?;
        let _ = writeln!(
            w,
            "    return {};\n}}",
            vector("real", &|j| values[j].clone())
        );
    }
    Ok(())
}

/// `vec4<{kind}>(…)` of `each(j)` for the first `n` components, `zero`
/// past them.
fn vec4(kind: &str, n: usize, each: &dyn Fn(usize) -> String, zero: &str) -> String {
    let parts: Vec<String> = (0..crate::integrate::impact::MAX_WALLS)
        .map(|j| if j < n { each(j) } else { zero.into() })
        .collect();
    format!("vec4<{kind}>({})", parts.join(", "))
}

/// The general surfaces of `code` (events that are not stops, then the
/// switches: the CPU's order, `Code::surfaces`) as the surface code of
/// `model::ir::surfaces` reads them:
/// their count, each one's
/// switch bit (or `EVENT`), the side of a switch, the field RK4 steps, and
/// g; their rates ([`surface_values`]), gradients and resets
/// ([`gradients_and_resets`]) follow.
fn surfaces(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let names = &code.model.names;
    let surfaces = &code.surfaces;
    let _ = writeln!(
        w,
        "\n// The events and switches, in the CPU's order (after the stops):"
    );
    for (j, s) in surfaces.iter().enumerate() {
        let kind = match s.kind {
            crate::integrate::Surface::Event => "event".to_owned(),
            crate::integrate::Surface::Switch { bit } => format!("switch (bit {bit})"),
        };
        let _ = writeln!(
            w,
            "//   {j}: {kind} '{}', g = {}",
            s.name,
            Written { expr: &s.g, names }
        );
    }
    let bit = |j: usize| match surfaces[j].kind {
        crate::integrate::Surface::Event => "EVENT".to_owned(),
        crate::integrate::Surface::Switch { bit } => format!("{bit}u"),
    };
    let bits = vec4("u32", surfaces.len(), &bit, "EVENT");
    let _ = writeln!(
        w,
        "const SURFACES: u32 = {}u;\n\
         // A surface's switch bit, or EVENT for an event.\n\
         const EVENT: u32 = 0xffffffffu;\n\
         const SURFACE_BIT = {bits};\n\
         // Region bits from SLIDING_SHIFT up mark a motion sliding on surface\n\
         // j (bit SLIDING_SHIFT + j), the bits below are the sides.\n\
         const SLIDING_SHIFT: u32 = {shift}u;\n\
         const SIDES: u32 = {sides:#x}u;\n\n\
         // The trajectory's side of switch `bit`: 1 on its positive side.\n\
         fn side(p: Params, bit: u32) -> real {{\n    return real((p.region >> bit) & 1u);\n}}\n\n\
         // The field RK4 steps: the region's, or the sliding field (of the\n\
         // surface code, which a variant without it never needs).\n\
         fn rhs(p: Params, phase: vec2<real>, y: State) -> State {{\n\
         #ifdef SURFACES\n    \
         if (is_sliding(p.region)) {{\n        return sliding_field(p, phase, y);\n    }}\n\
         #endif\n    \
         return field(p, phase, y);\n}}\n\n\
         fn surface_g(p: Params, phase: vec2<real>, y: State) -> vec4<real> {{",
        surfaces.len(),
        shift = crate::integrate::region::SLIDING,
        sides = (1u32 << crate::integrate::region::SLIDING) - 1,
    );
    let gs: Vec<&Expr> = surfaces.iter().map(|s| &s.g).collect();
    let values = lines(w, code, &gs, &states(code), "    ")?;
    let _ = writeln!(
        w,
        "    return {};\n}}\n\n\
         struct SurfaceValues {{\n    g: vec4<real>,\n    rate: vec4<real>,\n}}\n",
        vec4("real", surfaces.len(), &|j| values[j].clone(), "real(0.0)")
    );
    Ok(())
}

/// g, and the rate ∇g·F + ∂g/∂t along the field in force (the CPU
/// surface tape's sum, in its order): the products of ∇g with the field's
/// components (`f`, read as states past the model's), summed from the
/// first, then ∂g/∂t added.
fn surface_values(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let n = code.states();
    let surfaces = &code.surfaces;
    let rates: Vec<Expr> = surfaces
        .iter()
        .map(|s| {
            let term = |i: usize| {
                Expr::Bin(
                    Op::Mul,
                    Box::new(s.gradient[i].clone()),
                    Box::new(Expr::Var(Var::State(n + i))),
                )
            };
            let sum = (1..n).fold(term(0), |sum, i| {
                Expr::Bin(Op::Add, Box::new(sum), Box::new(term(i)))
            });
            Expr::Bin(Op::Add, Box::new(sum), Box::new(s.g.derivative(Var::Time)))
        })
        .collect();
    let _ = writeln!(
        w,
        "// g, and the rate ∇g·F + ∂g/∂t along the field of p's region (its\n\
         // sides: a sliding motion's rates are switch_sides').\n\
         fn surface_values(p: Params, phase: vec2<real>, y: State) -> SurfaceValues {{\n    \
         let f = field(p, phase, y);"
    );
    let mut inputs = states(code);
    inputs.extend(COMPONENTS[..n].iter().map(|c| format!("f.{c}")));
    let rates: Vec<&Expr> = rates.iter().collect();
    let values = lines(w, code, &rates, &inputs, "    ")?;
    let _ = writeln!(
        w,
        "    return SurfaceValues(surface_g(p, phase, y), {});\n}}\n",
        vec4("real", surfaces.len(), &|j| values[j].clone(), "real(0.0)")
    );
    Ok(())
}

/// Each surface's gradient ∇g, and an event's reset: the state after it,
/// its Jacobian DR (rows) and ∂R/∂t; a case of the surface's index each.
fn gradients_and_resets(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let n = code.states();
    let surfaces = &code.surfaces;
    let state = |values: &[String]| format!("State({})", values.join(", "));
    let _ = writeln!(
        w,
        "fn surface_gradient(p: Params, phase: vec2<real>, y: State, j: u32) -> State {{\n    \
         switch j {{"
    );
    // Surface 0's is the default.
    let labels = (1..surfaces.len())
        .map(|j| (format!("case {j}u"), j))
        .chain([("default".to_owned(), 0)]);
    for (label, j) in labels {
        let gradient: Vec<&Expr> = surfaces[j].gradient.iter().collect();
        case(w, code, &label, &gradient, &|values| state(values))?;
    }
    let _ = writeln!(
        w,
        "    }}\n}}\n\n\
         // An event's reset: the state after it, its Jacobian DR (rows) and ∂R/∂t.\n\
         struct Reset {{\n    y: State,\n    dr: array<State, DIM>,\n    rate: State,\n}}\n\n\
         fn reset(p: Params, phase: vec2<real>, y: State, j: u32) -> Reset {{\n    switch j {{"
    );
    for (j, s) in surfaces.iter().enumerate() {
        if s.kind != crate::integrate::Surface::Event {
            continue;
        }
        let exprs: Vec<&Expr> = s
            .reset
            .iter()
            .chain(&s.reset_jacobian)
            .chain(&s.reset_rate)
            .collect();
        case(w, code, &format!("case {j}u"), &exprs, &|values| {
            let rows: Vec<String> = (1..=n)
                .map(|i| state(&values[i * n..(i + 1) * n]))
                .collect();
            format!(
                "Reset({}, array<State, DIM>({}), {})",
                state(&values[..n]),
                rows.join(", "),
                state(&values[(n + 1) * n..])
            )
        })?;
    }
    let _ = writeln!(
        w,
        "        default: {{}}\n    }}\n    // A switch: no reset.\n    \
         return Reset(y, array<State, DIM>(), State());\n}}"
    );
    Ok(())
}

/// A switch's stick limit at y (the CPU evaluates it at t = 0), or
/// `filippov` (the half jump) for a switch without one.
fn stick_limits(w: &mut String, code: &Code) -> Result<(), Unsupported> {
    let _ = writeln!(
        w,
        "\nfn stick_limit(p: Params, y: State, j: u32, filippov: real) -> real {{\n    switch j {{"
    );
    for (j, s) in code.surfaces.iter().enumerate() {
        if let Some(limit) = &s.stick_limit {
            case(w, code, &format!("case {j}u"), &[limit], &|values| {
                values[0].clone()
            })?;
        }
    }
    let _ = writeln!(w, "        default: {{ return filippov; }}\n    }}\n}}");
    Ok(())
}

/// A case of a `switch` that returns `value` of `exprs`' values.
fn case(
    w: &mut String,
    code: &Code,
    label: &str,
    exprs: &[&Expr],
    value: &dyn Fn(&[String]) -> String,
) -> Result<(), Unsupported> {
    let _ = writeln!(w, "        {label}: {{");
    let values = lines(w, code, exprs, &states(code), "            ")?;
    let _ = writeln!(w, "            return {};\n        }}", value(&values));
    Ok(())
}

const COMPONENTS: [&str; 4] = ["x", "y", "z", "w"];

/// The states as WGSL reads them: `y.x`, `y.y`, ...
fn states(code: &Code) -> Vec<String> {
    COMPONENTS[..code.states()]
        .iter()
        .map(|c| format!("y.{c}"))
        .collect()
}

/// `exprs` as WGSL lines at `indent`, one `let` per operation: the tape
/// that reads its parameters (`Tape::compile_reading_parameters`)
/// printed by `model::codegen::print`, the states read at `states`, the clock at
/// `phase`, parameter i at `p.<field>` and switch b's side at `side(p,
/// b)`; gives each expression's value. Each operation on a line of its
/// own also keeps the WGSL compiler's recursion shallow, however deep the
/// tree.
fn lines(
    w: &mut String,
    code: &Code,
    exprs: &[&Expr],
    states: &[String],
    indent: &str,
) -> Result<Vec<String>, Unsupported> {
    let tape = Tape::compile_reading_parameters(exprs.iter().copied(), states.len()).map_err(
        |(_, e)| match e {
            CompileError::Time(_) => Unsupported::Time,
            CompileError::TooLong(n) => Unsupported::Length(n),
        },
    )?;
    let names = &code.model.names;
    let lane = |j: usize| match tape.lane_constants[j] {
        Expr::Var(Var::Param(i)) => format!("p.{}", field(names, i)),
        // The trajectory's side of switch b: its region's bit b.
        Expr::Var(Var::Side(b)) => format!("side(p, {b}u)"),
        _ => unreachable!("a tape that reads its parameters has no other lane constant"),
    };
    let inputs = Inputs {
        states,
        clock: ("phase.x", "phase.y"),
        lane: &lane,
    };
    Ok(print::print(w, &Wgsl, &tape, &inputs, "v", indent))
}

/// WGSL's [`Syntax`]: numbers as `real(…)`; `abs`, `sqrt`, `min`, `max`
/// and `sign` as WGSL's builtins (defined on f64 under Vulkan: docs,
/// NOTES on WGSL f64); every other function the `*_r` wrapper of
/// `shaders/shared/model_functions.wgsl`.
struct Wgsl;

impl Syntax for Wgsl {
    fn literal(&self, v: f64) -> String {
        literal(v)
    }

    fn declare(&self, name: &str, value: &str) -> String {
        format!("let {name}: real = {value};")
    }

    fn call(&self, f: Func, a: &str, b: &str) -> String {
        let name = match f {
            Func::Abs | Func::Sqrt | Func::Min | Func::Max | Func::Sign => f.name(),
            Func::Pow => POW,
            Func::Sin => "sin_r",
            Func::Cos => "cos_r",
            Func::Tan => "tan_r",
            Func::Exp => "exp_r",
            Func::Log => "log_r",
            Func::Tanh => "tanh_r",
            Func::Atan2 => "atan2_r",
        };
        match f.arity() {
            1 => format!("{name}({a})"),
            _ => format!("{name}({a}, {b})"),
        }
    }
}

/// A system's WGSL file for the kernels, with what the emitter put in it:
/// the kernels' defines follow these, not the text.
#[derive(Clone, Copy, Debug)]
pub struct SystemFile {
    pub source: &'static str,
    /// General surfaces (`SURFACES`, events and switches): the kernels'
    /// surface code and the trajectories' region.
    pub surfaces: bool,
    /// A Poincaré section (`SECTION_STATE`): `shaders/section.wgsl` runs
    /// in place of the period-map kernels.
    pub section: bool,
    /// Angles wrapped at the end of each iteration (`wrap_angles`): the
    /// finish kernel's `WRAP`.
    pub wraps_angles: bool,
}

impl SystemFile {
    /// A hand-written file with none of the generated features.
    pub const fn plain(source: &'static str) -> SystemFile {
        SystemFile {
            source,
            surfaces: false,
            section: false,
            wraps_angles: false,
        }
    }
}

/// The system file of `code` for `SystemInfo::wgsl` (kept for the
/// process, as the rest of a model's description is), or `None` when the
/// kernels cannot run it ([`check`] says why).
pub fn system_file(code: &Code) -> Option<SystemFile> {
    let source = system_source(code).ok()?;
    // What `system_source` emitted for each, read from the same model.
    Some(SystemFile {
        source: Box::leak(source.into_boxed_str()),
        surfaces: !code.surfaces.is_empty(),
        section: code.section.is_some(),
        wraps_angles: !code.model.angles.is_empty(),
    })
}

/// The WGSL field of parameter i: `p_<name>`, which no WGSL keyword or
/// reserved word starts with; `p<i>` for a name WGSL may not accept as an
/// identifier (the model table allows any Unicode letter). The two forms
/// cannot clash: only the first has an underscore after the `p`.
pub fn field(names: &crate::model::language::expr::Names, i: usize) -> String {
    let name = &names.parameters[i];
    if name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
        format!("p_{name}")
    } else {
        format!("p{i}")
    }
}

/// The integrator's step program (`model::ir::integrator`) as WGSL
/// functions: the clock's `rotate` and `cos_sin`; for a flow (a system
/// file with `rhs`) RK4's `rk4_stages`, `rk4_update`, `rk4_increment`,
/// `rk4_step` and `sub_step` with their `Stepped` result, the stop
/// test (`may_turn_past`, `may_meet`) and Filippov's sliding field on one
/// switch (`filippov_alpha`, `filippov_field`); with stops (`held`: the
/// kernels' `Stop` and `held_rhs`), RK4 of the held flow (`held_*`) and
/// the stops' functions (`model::ir::events::stops`), and where the
/// location is Newton's (`newton`) its Hermite guess, bracket and Newton
/// (`model::ir::events::location`), else the linear location; with
/// general surfaces (`surfaces`), their regions, tests, sliding and
/// crossing (`model::ir::surfaces`); with stops, the step loop that
/// resolves a step's events (`model::ir::impacts`), and for the integrate
/// kernel (`trajectory`, whose `Trajectory` and `Stepping` it reads) that
/// step resolved and recorded in a trajectory (`model::ir::trajectory`).
pub fn integrator(
    flow: bool,
    held: bool,
    newton: bool,
    surfaces: bool,
    trajectory: bool,
) -> String {
    use crate::model::ir::events;
    let mut program = crate::model::ir::integrator::integrator();
    let c_only = crate::model::ir::integrator::C_ONLY;
    program.functions.retain(|f| !c_only.contains(&f.name));
    if !flow {
        program
            .functions
            .retain(|f| ["rotate", "cos_sin"].contains(&f.name));
    }
    let mut absent: Vec<&str> = Vec::new();
    if !held {
        program.functions.retain(|f| !f.name.starts_with("held_"));
        absent.extend(events::stops().iter().map(|f| f.name));
        absent.extend([events::stop().name, events::hit().name]);
    }
    if !held || !newton {
        absent.extend(events::location().iter().map(|f| f.name));
        absent.extend(events::location_structures().iter().map(|s| s.name));
    }
    if !held || newton {
        absent.extend(events::linear_location().iter().map(|f| f.name));
    }
    if !surfaces {
        use crate::model::ir::surfaces;
        absent.extend(surfaces::functions().iter().map(|f| f.name));
        absent.extend(surfaces::structures().iter().map(|s| s.name));
    }
    program.functions.retain(|f| !absent.contains(&f.name));
    program.structures.retain(|s| !absent.contains(&s.name));
    // The step loop in the variant the kernel needs.
    use crate::model::ir::{impacts, trajectory as on_trajectory};
    let variants: Vec<&str> = impacts::FUNCTIONS
        .into_iter()
        .chain(on_trajectory::FUNCTIONS)
        .collect();
    program.functions.retain(|f| !variants.contains(&f.name));
    program.structures.retain(|s| {
        !impacts::STRUCTURES.contains(&s.name)
            && on_trajectory::structures().iter().all(|t| t.name != s.name)
    });
    if held {
        program
            .functions
            .extend(impacts::functions(surfaces, newton));
        program.structures.extend(impacts::structures(surfaces));
        if trajectory {
            program.functions.extend(on_trajectory::functions(surfaces));
            program.structures.extend(on_trajectory::structures());
        }
    }
    format!(
        "// Generated from the integrator's step program (model::ir::integrator).\n\n{}",
        super::step::wgsl(&program, &Wgsl)
    )
}

/// The finish kernel's step program (`model::ir::finish`) for the
/// variant `options` as WGSL functions, the kernel's `finish_lane` last.
pub fn finish(options: crate::model::ir::finish::Options) -> String {
    format!(
        "// Generated from the finish kernel's step program (model::ir::finish).\n\n{}",
        super::step::wgsl(&crate::model::ir::finish::program(options), &Wgsl)
    )
}

/// The section kernel's step program (`model::ir::section`) as WGSL
/// functions, f32's compensated steps where `compensated`.
pub fn section(compensated: bool) -> String {
    format!(
        "// Generated from the section kernel's step program (model::ir::section).\n\n{}",
        super::step::wgsl(&crate::model::ir::section::program(compensated), &Wgsl)
    )
}

/// The integrator program's functions `names` alone as WGSL, with the
/// structures `structures` they use: a generated function beside its Rust
/// twin in a test kernel (tests/math64.rs).
pub fn step_functions(names: &[&str], structures: &[&str]) -> String {
    let mut program = crate::model::ir::integrator::integrator();
    program.functions.retain(|f| names.contains(&f.name));
    program.structures.retain(|s| structures.contains(&s.name));
    super::step::wgsl(&program, &Wgsl)
}

/// A number as a WGSL `real`: Rust's shortest representation that reads
/// back to the same f64 (`{:?}` always has a `.` or an exponent, so WGSL
/// reads a float, an abstract one that `real(…)` converts exactly in f64).
pub fn literal(v: f64) -> String {
    format!("real({v:?})")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn literals_read_back_to_the_same_bits_and_are_floats() {
        for v in [
            0.1,
            2.0,
            -2.0,
            std::f64::consts::PI,
            1e300,
            1e-7,
            1.0 / 3.0,
            123456789.0,
            5e-324,
        ] {
            let text = literal(v);
            let inner = &text["real(".len()..text.len() - 1];
            assert!(inner.contains('.') || inner.contains('e'), "{text}");
            assert_eq!(inner.parse::<f64>().unwrap().to_bits(), v.to_bits());
        }
    }

    #[test]
    fn every_wrapper_is_named_by_a_function() {
        // `Wgsl::call` maps functions to these names by hand; keep them one list.
        for name in WRAPPERS {
            assert!(calls_wrappers(&format!("x = {name}(y);")));
        }
        assert!(calls_wrappers("pow_r(y.x, real(3.0))"));
        assert!(!calls_wrappers("abs(y.x) + sqrt(y.y)"));
    }

    /// The finish kernel's columns, seeds and measures print as the
    /// kernel wrote them by hand, and a variant prints only what it runs.
    #[test]
    fn finish_prints_its_columns_in_the_reference_order() {
        use crate::model::ir::finish::Options;
        let central = finish(Options {
            lyapunov: true,
            central: true,
            compensated: true,
            wall: true,
            ..Options::default()
        });
        for line in [
            "var plus = r + 1u + i;",
            "let same_plus = (same_impacts(r, plus) && !((counts[plus][2u] & FLAG_BEHIND_WALL) != 0u));",
            "difference = difference - (load_state(plus * TRAJ_STRIDE + DIM) - load_state(minus * TRAJ_STRIDE + DIM));",
            "jac[slot * DIM * DIM + k * DIM + i] = difference[k] / step;",
            "nonlinearity = max(nonlinearity, max(departure(r, plus), departure(r, minus)));",
            "yi[i] = y[i] + delta;",
            "deltas[lane * 2u * DIM + DIM + i] = y[i] - ym[i];",
            "ratio = f32(even / odd);",
            "d = f32(abs(vt - vr) / vr);",
            "write_summary(r, slot, y, cr[1u], flags, nonlinearity);",
        ] {
            assert!(central.contains(line), "{line}\n{central}");
        }
        let plain = finish(Options::default());
        assert!(plain.contains("fn restart(") && plain.contains("fn finish_lane(lane: u32) {"));
        assert!(!plain.contains("fn write_columns") && !plain.contains("crossings"));
        let forward = finish(Options {
            lyapunov: true,
            ..Options::default()
        });
        assert!(forward.contains("let step = deltas[lane * DIM + i];"));
        assert!(!forward.contains("asymmetry") && !forward.contains("departure"));
    }

    #[test]
    fn the_section_s_steps_are_compensated_in_f32_only() {
        let (f32, f64) = (section(true), section(false));
        assert!(f32.contains("let d0 = SECTION_DIRECTION * (before[SECTION_STATE] - at);"));
        assert!(
            f32.contains("let next_comp = after - y - corrected;"),
            "{f32}"
        );
        assert!(f64.contains("after = y + rk4_increment(p, still, still, y, h).y;"));
        assert!(!f64.contains("comp"), "{f64}");
    }
}
