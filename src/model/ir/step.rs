//! Step programs: the integrator's arithmetic around a model's field,
//! written once as data and printed to every generated target
//! (`model::codegen::step`): inlined into the C of the CPU's native step
//! loops, and as functions of the GPU's kernels in WGSL.
//!
//! A program is a list of functions, each a straight line of named values
//! over three types (a number, a state vector, a forcing phase) ending in
//! its results. The operations on states are componentwise, so a target
//! without vectors (C, one scalar per component) and one with them (WGSL)
//! perform the same IEEE operations in the same order. The model's field
//! is an operation of its own ([`Expr::Field`]): each target says how it
//! is evaluated (C prints the field's tape in place, WGSL calls the system
//! file's `rhs`).
//!
//! The Rust reference (`integrate::rk4`, `integrate::clock`) stays written
//! by hand: it is the oracle the generated code is tested against, bit for
//! bit (tests/step_loops.rs on the CPU, tests/gpu.rs on the GPU).

use std::ops::{Add, Div, Mul, Sub};

/// What a value is.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Ty {
    Real,
    /// A state of the model's dimension.
    State,
    /// A forcing phase (cos ωt, sin ωt).
    Phase,
}

/// A value: an operation of named values and numbers.
#[derive(Clone, Debug, PartialEq)]
pub enum Expr {
    Var(&'static str),
    Num(f64),
    /// `+ - * /`; on states componentwise, a number times a state scales it.
    Bin(Op, Box<Expr>, Box<Expr>),
    /// A phase's cosine.
    Cos(Box<Expr>),
    /// A phase's sine.
    Sin(Box<Expr>),
    /// The phase of a cosine and a sine.
    Phase(Box<Expr>, Box<Expr>),
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
            Expr::Num(_) | Expr::Cos(_) | Expr::Sin(_) => Ty::Real,
            Expr::Phase(..) => Ty::Phase,
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
    Expr::Cos(Box::new(var(phase)))
}

fn sin(phase: &'static str) -> Expr {
    Expr::Sin(Box::new(var(phase)))
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
    use Ty::{Phase, Real, State};
    let rotate = Function {
        name: "rotate",
        params: vec![("phase", Phase), ("by", Phase)],
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
            Expr::Phase(Box::new(var("c") * "scale"), Box::new(var("s") * "scale")),
        )],
        returns: None,
    };
    let stages = Function {
        name: "rk4_stages",
        params: vec![
            ("phase", Phase),
            ("mid", Phase),
            ("end", Phase),
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
    let whole = [("phase", Phase), ("half", Phase), ("y", State), ("h", Real)];
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
    Program {
        functions: vec![rotate, stages, update, increment, step],
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_function_is_well_typed() {
        let program = integrator();
        let expected = [
            ("rotate", vec![Ty::Phase]),
            ("rk4_stages", vec![Ty::State]),
            ("rk4_update", vec![Ty::State]),
            ("rk4_increment", vec![Ty::State, Ty::Phase]),
            ("rk4_step", vec![Ty::State, Ty::Phase]),
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
