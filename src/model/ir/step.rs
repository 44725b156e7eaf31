//! Step programs: the integrator's arithmetic around a model's field,
//! written once as data and printed to every generated target
//! (`model::codegen::step`): inlined into the C of the CPU's native step
//! loops, and as functions of the GPU's kernels in WGSL.
//!
//! A program is a list of functions, each a straight line of named values
//! over four types (a number, a state vector, a pair of numbers such as a
//! forcing phase or an event's value and rate, a truth value) ending in
//! its results. The operations on states are componentwise, so a target
//! without vectors (C, one scalar per component) and one with them (WGSL)
//! perform the same IEEE operations in the same order. The model's field
//! is an operation of its own ([`Expr::Field`]): each target says how it
//! is evaluated (C prints the field's tape in place, WGSL calls the system
//! file's `rhs`).
//!
//! The Rust reference (`integrate::rk4`, `integrate::clock`,
//! `integrate::wall::may_reach`) stays written by hand: it is the oracle
//! the generated code is tested against, bit for bit (the native library's
//! tests and tests/step_loops.rs on the CPU, tests/gpu.rs and
//! tests/gpu_models.rs on the GPU).

use std::ops::{Add, Div, Mul, Sub};

/// What a value is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    Real,
    /// A state of the model's dimension.
    State,
    /// Two numbers: a forcing phase (cos ωt, sin ωt), or an event's
    /// value and rate.
    Pair,
    Bool,
}

/// A value: an operation of named values and numbers.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Var(&'static str),
    Num(f64),
    /// `+ - * /`; on states componentwise, a number times a state scales it.
    Bin(Op, Box<Expr>, Box<Expr>),
    /// A pair's first number (a phase's cosine).
    First(Box<Expr>),
    /// A pair's second number (a phase's sine).
    Second(Box<Expr>),
    /// The pair of two numbers.
    Pair(Box<Expr>, Box<Expr>),
    /// A comparison of two numbers.
    Cmp(Cmp, Box<Expr>, Box<Expr>),
    /// Truth values: both, either, not (without short circuits: every
    /// operand is computed, as the vectorised C loops do).
    And(Box<Expr>, Box<Expr>),
    Or(Box<Expr>, Box<Expr>),
    Not(Box<Expr>),
    /// The model's field at a phase and a state.
    Field {
        phase: Box<Expr>,
        state: Box<Expr>,
    },
    /// A function of the program defined before this one, with one result.
    Call(&'static str, Vec<Expr>),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Op {
    Add,
    Sub,
    Mul,
    Div,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Cmp {
    Less,
    Greater,
}

impl Cmp {
    pub fn symbol(self) -> &'static str {
        match self {
            Cmp::Less => "<",
            Cmp::Greater => ">",
        }
    }
}

impl Op {
    pub fn symbol(self) -> char {
        match self {
            Op::Add => '+',
            Op::Sub => '-',
            Op::Mul => '*',
            Op::Div => '/',
        }
    }
}

/// A function of a program: its parameters, its named values in order,
/// and its results, named (a target that returns several values as a
/// structure names it [`Function::returns`] with these fields).
#[derive(Clone, Debug)]
pub struct Function {
    pub name: &'static str,
    pub params: Vec<(&'static str, Ty)>,
    pub body: Vec<(&'static str, Expr)>,
    pub results: Vec<(&'static str, Expr)>,
    /// The structure of several results (`None` with one).
    pub returns: Option<&'static str>,
}

/// Functions in order, each calling only those before it.
#[derive(Clone, Debug, Default)]
pub struct Program {
    pub functions: Vec<Function>,
}

impl Program {
    pub fn function(&self, name: &str) -> &Function {
        self.functions
            .iter()
            .find(|f| f.name == name)
            .unwrap_or_else(|| panic!("no step function {name}"))
    }

    /// The type of `e` where the named values have the types `scope`
    /// gives; panics on an ill-typed program (a program is a constant of
    /// the source, and `tests` type every one).
    pub fn type_of(&self, e: &Expr, scope: &dyn Fn(&str) -> Ty) -> Ty {
        match e {
            Expr::Var(name) => scope(name),
            Expr::Num(_) | Expr::First(_) | Expr::Second(_) => Ty::Real,
            Expr::Pair(..) => Ty::Pair,
            Expr::Cmp(..) | Expr::And(..) | Expr::Or(..) | Expr::Not(_) => Ty::Bool,
            Expr::Field { .. } => Ty::State,
            Expr::Bin(op, a, b) => match (self.type_of(a, scope), self.type_of(b, scope)) {
                (Ty::Real, Ty::Real) => Ty::Real,
                (Ty::State, Ty::State) if matches!(op, Op::Add | Op::Sub) => Ty::State,
                (Ty::Real, Ty::State) if *op == Op::Mul => Ty::State,
                (a, b) => panic!("{a:?} {} {b:?} is not a step operation", op.symbol()),
            },
            Expr::Call(name, _) => {
                let f = self.function(name);
                assert!(f.returns.is_none(), "{name} has several results");
                f.result_types(self)[0]
            }
        }
    }

    /// The type of each named value of `f`, parameters first.
    pub fn types(&self, f: &Function) -> Vec<(&'static str, Ty)> {
        let mut types = f.params.clone();
        for (name, value) in &f.body {
            let ty = self.type_of(value, &|n| lookup(&types, n));
            types.push((name, ty));
        }
        types
    }
}

impl Function {
    /// The type of each result.
    pub fn result_types(&self, program: &Program) -> Vec<Ty> {
        let types = program.types(self);
        self.results
            .iter()
            .map(|(_, e)| program.type_of(e, &|n| lookup(&types, n)))
            .collect()
    }
}

fn lookup(types: &[(&'static str, Ty)], name: &str) -> Ty {
    types
        .iter()
        .rev()
        .find(|(n, _)| *n == name)
        .unwrap_or_else(|| panic!("{name} is not in scope"))
        .1
}

impl<T: Into<Expr>> Add<T> for Expr {
    type Output = Expr;
    fn add(self, b: T) -> Expr {
        Expr::Bin(Op::Add, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Sub<T> for Expr {
    type Output = Expr;
    fn sub(self, b: T) -> Expr {
        Expr::Bin(Op::Sub, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Mul<T> for Expr {
    type Output = Expr;
    fn mul(self, b: T) -> Expr {
        Expr::Bin(Op::Mul, Box::new(self), Box::new(b.into()))
    }
}

impl<T: Into<Expr>> Div<T> for Expr {
    type Output = Expr;
    fn div(self, b: T) -> Expr {
        Expr::Bin(Op::Div, Box::new(self), Box::new(b.into()))
    }
}

impl From<f64> for Expr {
    fn from(v: f64) -> Expr {
        Expr::Num(v)
    }
}

impl From<&'static str> for Expr {
    fn from(name: &'static str) -> Expr {
        Expr::Var(name)
    }
}

fn var(name: &'static str) -> Expr {
    Expr::Var(name)
}

fn num(v: f64) -> Expr {
    Expr::Num(v)
}

fn cos(phase: &'static str) -> Expr {
    Expr::First(Box::new(var(phase)))
}

fn sin(phase: &'static str) -> Expr {
    Expr::Second(Box::new(var(phase)))
}

fn greater(a: Expr, b: Expr) -> Expr {
    Expr::Cmp(Cmp::Greater, Box::new(a), Box::new(b))
}

fn less(a: Expr, b: Expr) -> Expr {
    Expr::Cmp(Cmp::Less, Box::new(a), Box::new(b))
}

fn and(a: Expr, b: Expr) -> Expr {
    Expr::And(Box::new(a), Box::new(b))
}

fn or(a: Expr, b: Expr) -> Expr {
    Expr::Or(Box::new(a), Box::new(b))
}

fn field(phase: &'static str, state: &'static str) -> Expr {
    Expr::Field {
        phase: Box::new(var(phase)),
        state: Box::new(var(state)),
    }
}

fn call(name: &'static str, args: &[&'static str]) -> Expr {
    Expr::Call(name, args.iter().map(|&a| var(a)).collect())
}

/// The integrator's step: the clock's rotation (`integrate::clock::rotate`)
/// and the classical RK4 step (`integrate::rk4`), whose stages take the
/// phases of the step's start, middle and end.
///
/// - `rotate(phase, by)`: the phase turned through the angle whose (cos,
///   sin) is `by`, renormalised to the unit circle by one Newton step for
///   1/√(c² + s²), so rounding cannot make the forcing's amplitude drift.
/// - `rk4_stages(phase, mid, end, y, h)`: the increment y(t + h) - y(t),
///   kept apart from the update so that the f32 kernels can compensate
///   the sum.
/// - `rk4_update(phase, mid, end, y, h)`: the step's end, y + the
///   increment.
/// - `rk4_increment(phase, half, y, h)`: the phases turned through ωh/2
///   twice (`half` is its (cos, sin)), the increment and the end's phase.
/// - `rk4_step(phase, half, y, h)`: the step's end and phase.
pub fn integrator() -> Program {
    use Ty::{Pair, Real, State};
    let rotate = Function {
        name: "rotate",
        params: vec![("phase", Pair), ("by", Pair)],
        body: vec![
            ("c", cos("phase") * cos("by") - sin("phase") * sin("by")),
            ("s", sin("phase") * cos("by") + cos("phase") * sin("by")),
            (
                "scale",
                num(1.5) - num(0.5) * (var("c") * "c" + var("s") * "s"),
            ),
        ],
        results: vec![(
            "phase",
            Expr::Pair(Box::new(var("c") * "scale"), Box::new(var("s") * "scale")),
        )],
        returns: None,
    };
    let stages = Function {
        name: "rk4_stages",
        params: vec![
            ("phase", Pair),
            ("mid", Pair),
            ("end", Pair),
            ("y", State),
            ("h", Real),
        ],
        body: vec![
            ("h2", num(0.5) * "h"),
            ("k1", field("phase", "y")),
            ("y2", var("y") + var("h2") * "k1"),
            ("k2", field("mid", "y2")),
            ("y3", var("y") + var("h2") * "k2"),
            ("k3", field("mid", "y3")),
            ("y4", var("y") + var("h") * "k3"),
            ("k4", field("end", "y4")),
            ("sixth", var("h") / 6.0),
        ],
        results: vec![(
            "increment",
            var("sixth") * (var("k1") + num(2.0) * (var("k2") + "k3") + "k4"),
        )],
        returns: None,
    };
    // The phases of the step's middle and end, and the update: what every
    // step takes, apart from where the phases are turned (the native step
    // loops turn them once for all slots).
    let turned = || {
        vec![
            ("mid", call("rotate", &["phase", "half"])),
            ("end", call("rotate", &["mid", "half"])),
        ]
    };
    let update = Function {
        name: "rk4_update",
        params: stages.params.clone(),
        body: vec![(
            "increment",
            call("rk4_stages", &["phase", "mid", "end", "y", "h"]),
        )],
        results: vec![("y", var("y") + "increment")],
        returns: None,
    };
    let whole = [("phase", Pair), ("half", Pair), ("y", State), ("h", Real)];
    let increment = Function {
        name: "rk4_increment",
        params: whole.to_vec(),
        body: turned(),
        results: vec![
            ("y", call("rk4_stages", &["phase", "mid", "end", "y", "h"])),
            ("phase", var("end")),
        ],
        returns: Some("Stepped"),
    };
    let step = Function {
        name: "rk4_step",
        params: whole.to_vec(),
        body: turned(),
        results: vec![
            ("y", call("rk4_update", &["phase", "mid", "end", "y", "h"])),
            ("phase", var("end")),
        ],
        returns: Some("Stepped"),
    };
    let [turn_past, meet] = crossing_tests();
    Program {
        functions: vec![rotate, stages, update, increment, step, turn_past, meet],
    }
}

/// The stop test of walls and surfaces alike (`integrate::wall::may_reach`,
/// bounded):
///
/// - `may_turn_past(g0, s0, g1, s1, h)`: whether a step of size h turning
///   back inside (rate s0 > 0 to s1 < 0, values g0, g1 short of the
///   surface) may pass it in between: not when both ends fall short by
///   `TURN_REACH`·h·(s0 - s1), twice the most the step's cubic can rise
///   (`integrate::wall::may_turn_past`).
/// - `may_meet(start, end, h)`: whether a step whose (value, rate) goes
///   from `start` to `end` may cross (value > 0 across): it ends across,
///   or turns back within reach.
fn crossing_tests() -> [Function; 2] {
    use Ty::{Pair, Real};
    let turn_past = Function {
        name: "may_turn_past",
        params: vec![
            ("g0", Real),
            ("s0", Real),
            ("g1", Real),
            ("s1", Real),
            ("h", Real),
        ],
        body: vec![(
            "reach",
            num(crate::integrate::wall::TURN_REACH) * "h" * (var("s0") - "s1"),
        )],
        results: vec![(
            "passes",
            Expr::Not(Box::new(and(
                less(var("g0") + "reach", num(0.0)),
                less(var("g1") + "reach", num(0.0)),
            ))),
        )],
        returns: None,
    };
    let meet = Function {
        name: "may_meet",
        params: vec![("start", Pair), ("end", Pair), ("h", Real)],
        body: vec![(
            "turns",
            Expr::Call(
                "may_turn_past",
                vec![cos("start"), sin("start"), cos("end"), sin("end"), var("h")],
            ),
        )],
        results: vec![(
            "meets",
            or(
                greater(cos("end"), num(0.0)),
                and(
                    and(greater(sin("start"), num(0.0)), less(sin("end"), num(0.0))),
                    var("turns"),
                ),
            ),
        )],
        returns: None,
    };
    [turn_past, meet]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_function_is_well_typed() {
        let program = integrator();
        let expected = [
            ("rotate", vec![Ty::Pair]),
            ("rk4_stages", vec![Ty::State]),
            ("rk4_update", vec![Ty::State]),
            ("rk4_increment", vec![Ty::State, Ty::Pair]),
            ("rk4_step", vec![Ty::State, Ty::Pair]),
            ("may_turn_past", vec![Ty::Bool]),
            ("may_meet", vec![Ty::Bool]),
        ];
        for (name, types) in expected {
            assert_eq!(
                program.function(name).result_types(&program),
                types,
                "{name}"
            );
        }
    }

    #[test]
    #[should_panic(expected = "is not a step operation")]
    fn a_state_times_a_state_is_refused() {
        let program = Program::default();
        let scope = |_: &str| Ty::State;
        program.type_of(&(var("y") * "y"), &scope);
    }
}
